r"""Paths of several diffuse vertices (``max_depth``) against the closed form of a white furnace.

The furnace: a closed enclosure (here a non-convex L-shaped polygon) whose every segment emits
$L_e$ on both sides and reflects with albedo ρ. flatland's diffuse BRDF is ρ/2 and the cosine
integrates to 2 over the half circle (theory/radiometry), so a constant radiance L arriving from
every direction gives the irradiance E = 2L and the reflected radiance (ρ/2) 2L = ρL: the same
geometric series as in 3D. With d diffuse vertices per path (``max_depth`` d, 1 being direct
illumination) the radiance leaving every point of the walls is

    $L_d = L_e + ρ L_{d-1}$, $L_0 = L_e$, so $L_d = L_e Σ_{i=0}^{d} ρ^i = L_e (1 - ρ^{d+1}) / (1 - ρ)$

(the issue's "$L_e (1 - ρ^n)/(1 - ρ)$ after n bounces" with n = d + 1 path segments: a
depth-1 path is a camera ray and a shading ray), constant over the walls, so every pixel's
expectation is $L_d$, and the irradiance at any point inside (``irradiance``, whose own point is
vertex 1 and has no albedo) is $E_d = 2 L_{d-1}$. Being constant, $L_d$ has no jump at any corner
seen from anywhere: moving a wall changes no pixel (derivative 0), and the naive estimator is
unbiased for every parameter; $∂L_d/∂ρ = L_e Σ_{i=1}^{d} i ρ^{i-1}$, $∂L_d/∂L_e = Σ_{i=0}^{d} ρ^i$.

Tolerances: $|mean - reference| <= q · stderr$ with the Student-t quantile q of the batch
standard error (16 batches), Šidák-corrected over the comparisons of each test at ALPHA = 1e-3,
fixed seeds. The pixels of a batch are independent (each has its own keyed samples), so the
pixel average of a batch is one estimate per batch.
"""

from __future__ import annotations

import numpy as np
import pytest

from flatland import integrator
from flatland.core.dual import detach
from flatland.core.rng import Draws
from flatland.core.stats import family_quantile
from flatland.core.validate import ValidationError
from flatland.lights import Lights
from flatland.methods import GRADIENT_METHODS
from flatland.render import irradiance, render, render_gradient
from flatland.scene import load_scene
from flatland.state import build_state, parse_parameter
from flatland.tasks import ImageTask, PointTask

ALPHA = 1e-3
BATCHES = 16
LE, RHO = 1.0, 0.6
DEPTHS = (1, 2, 3, 4)
# an L-shaped room: one reflex corner at (0, 0), the camera in the lower arm looking into the corner
ROOM = [[-1.0, -1.0], [2.0, -1.0], [2.0, 0.0], [0.0, 0.0], [0.0, 2.0], [-1.0, 2.0]]


def _furnace(**camera) -> dict:
    return {
        "name": "furnace",
        "camera": {"position": [-0.5, -0.5], "direction": [1.0, 0.6], "fov": 2.0, "pixels": 8, **camera},
        "sky": 0.0,
        "shapes": [{"name": "room", "type": "polygon", "points": ROOM, "albedo": RHO, "emission": LE}],
        "parameters": ["room.albedo", "room.emission", "room.vertex.3.x"],
    }


def _open_room() -> dict:
    """Not closed: a floor, a wall, an occluder and one emitter under a sky (paths escape, are occluded)."""
    return {
        "name": "open_room",
        "camera": {"position": [0.0, 0.6], "direction": [0.2, -1.0], "fov": 1.6, "pixels": 8},
        "sky": 0.3,
        "shapes": [
            {"name": "floor", "type": "segment", "points": [[-3.0, 0.0], [3.0, 0.0]], "albedo": 0.8},
            {"name": "wall", "type": "segment", "points": [[1.5, 0.0], [1.5, 2.0]], "albedo": 0.7},
            {"name": "ball", "type": "circle", "center": [-0.6, 0.8], "radius": 0.3, "albedo": 0.5},
            {"name": "light", "type": "segment", "points": [[0.5, 2.0], [-0.5, 2.0]], "emission": 5.0},
        ],
        "parameters": ["light.emission", "wall.albedo"],
    }


def _series(d: int) -> float:
    """$L_d = L_e Σ_{i=0}^{d} ρ^i$."""
    return LE * sum(RHO**i for i in range(d + 1))


def _pooled(per_batch: np.ndarray) -> tuple[float, float]:
    """Mean and standard error of the pixel averages of independent batches (batches, pixels)."""
    b = np.asarray(per_batch).reshape(BATCHES, -1).mean(axis=1)
    return float(b.mean()), float(b.std(ddof=1) / np.sqrt(b.size))


def _within(estimates: list[tuple[float, float]], references: list[float]) -> None:
    q = family_quantile(len(estimates), 1.0 - ALPHA, dof=BATCHES - 1)
    for (mean, se), ref in zip(estimates, references, strict=True):
        assert se > 0.0  # the test can see noise: a zero stderr would make any tolerance vacuous
        assert abs(mean - ref) <= q * se, (mean, ref, se, q)


@pytest.mark.parametrize(
    "bad", [0, -1, 1.5, True, "2", None], ids=["zero", "negative", "float", "bool", "str", "none"]
)
def test01_max_depth_is_an_integer_of_at_least_one(bad):
    for call in (
        lambda: render(_furnace(), spp=4, max_depth=bad),
        lambda: render_gradient(_furnace(), "room.albedo", "naive", spp=4, max_depth=bad),
        lambda: irradiance(_furnace(), (0.0, -0.5), (0.0, 1.0), n=4, max_depth=bad),
    ):
        with pytest.raises(ValidationError) as err:
            call()
        assert err.value.field == "max_depth"
        assert repr(bad) in str(err.value)


@pytest.mark.parametrize("method", ["naive", "finite_difference", "boundary", "reparam"])
def test02_depth_one_is_the_default_bit_for_bit(method):
    scene = _open_room()
    scene["parameters"] = ["ball.translate.x"]
    a = render_gradient(scene, "ball.translate.x", method, spp=16, seed=2, progress=False)
    b = render_gradient(scene, "ball.translate.x", method, spp=16, seed=2, progress=False, max_depth=1)
    assert np.array_equal(a.value, b.value) and np.array_equal(a.derivative, b.derivative)
    if method == "naive":
        assert np.array_equal(render(scene, spp=16, seed=2).value, a.value)
        assert np.array_equal(render(scene, spp=16, seed=2, max_depth=1).value, a.value)
        e1 = irradiance(scene, (0.3, 0.0), (0.0, 1.0), n=64, seed=2, max_depth=1)
        assert irradiance(scene, (0.3, 0.0), (0.0, 1.0), n=64, seed=2).value == e1.value


def test03_the_furnace_image_sums_the_series_at_every_depth():
    estimates = []
    for d in DEPTHS:
        task = ImageTask(load_scene(_furnace()), None, 1024, 7, BATCHES, d)
        estimates.append(_pooled(task.evaluate(0.0).value))
    _within(estimates, [_series(d) for d in DEPTHS])
    # the depths differ by more than their noise: the test would see a missing vertex
    assert all(estimates[i + 1][0] - estimates[i][0] > 0.05 for i in range(len(DEPTHS) - 1))


def test04_the_furnace_irradiance_at_a_point_is_twice_the_series_one_short():
    estimates = []
    for d in DEPTHS:
        task = PointTask(load_scene(_furnace()), None, (0.5, -0.2), (0.6, 0.8), 4096, 8, BATCHES, d)
        estimates.append(_pooled(task.evaluate(0.0).value))
    _within(estimates, [2.0 * _series(d - 1) for d in DEPTHS])


def test05_a_sample_path_depends_on_its_index_alone():
    """Every uniform of a path is keyed on (sample, depth): a chunk of other samples changes nothing."""
    scene = load_scene(_open_room())
    state = build_state(scene, None, 0.0)
    ctx = integrator.Context(state, state, Lights.of(state), integrator.Identity(), 4)
    index = np.arange(0, 4096, dtype=np.int64)

    def estimate(rows: np.ndarray) -> np.ndarray:
        draws = Draws.of(3, rows)
        u = draws.uniforms("samples", integrator.PRIMARY_UNIFORMS)
        return integrator.pixel_samples(ctx, rows // 512, u, draws)

    whole = estimate(index)
    part = estimate(index[1000:1300])
    assert np.array_equal(whole[1000:1300], part)
    # paths do go deeper than one vertex here: depth 4 differs from depth 1
    ctx1 = integrator.Context(state, state, ctx.lights, integrator.Identity(), 1)
    draws = Draws.of(3, index)
    direct = integrator.pixel_samples(ctx1, index // 512, draws.uniforms("samples", 4), draws)
    assert np.mean(whole - direct) > 0.01


@pytest.mark.parametrize("method", ["naive", "finite_difference"])
def test06_furnace_derivatives_at_depth_three(method):
    d = 3
    references = {
        "room.albedo": LE * sum(i * RHO ** (i - 1) for i in range(1, d + 1)),
        "room.emission": sum(RHO**i for i in range(d + 1)),
        "room.vertex.3.x": 0.0,  # L is constant over the walls wherever they are
    }
    scene = load_scene(_furnace())
    estimates = []
    for name in references:
        task = ImageTask(scene, parse_parameter(scene, name), 1024, 9, BATCHES, d)
        tally = GRADIENT_METHODS.run(method, task)
        estimates.append(_pooled(tally.derivative))
        assert _pooled(tally.value)[0] == pytest.approx(_series(d), rel=0.05)
    _within(estimates, list(references.values()))


def test07_naive_and_finite_differences_agree_where_the_image_is_affine_in_the_parameter():
    """The open room's image is affine in the one emitter's radiance, sample by sample (the paths do
    not depend on it: one emitter is chosen with probability 1), so the central difference with common
    random numbers is exact but for rounding, and so must naive be, at every depth."""
    scene = load_scene(_open_room())
    param = parse_parameter(scene, "light.emission")
    for d in (2, 3):
        task = ImageTask(scene, param, 256, 4, BATCHES, d)
        naive = GRADIENT_METHODS.run("naive", task)
        fd = GRADIENT_METHODS.run("finite_difference", task)
        assert np.array_equal(naive.value, fd.value)  # the value render is the same at θ0
        scale = np.max(np.abs(naive.derivative))
        assert scale > 0.05
        np.testing.assert_allclose(naive.derivative, fd.derivative, rtol=0.0, atol=1e-9 * max(1.0, scale))


@pytest.mark.parametrize("method", ["reparam", "boundary"])
def test08_reparam_and_boundary_take_paths(method):
    """Every method runs at every depth (their gradients on paths: tests/flatland/test_path_gradients.py);
    the irradiance at a point too, whose jump terms at vertex 1 see paths of the remaining depth."""
    image = render_gradient(_furnace(), "room.vertex.3.x", method, spp=4, max_depth=2, progress=False)
    assert np.all(np.isfinite(image.derivative))
    e = irradiance(_furnace(), (0.0, -0.5), (0.0, 1.0), "room.vertex.3.x", method, n=4, max_depth=3)
    assert np.isfinite(e.derivative)


def test09_naive_albedo_derivative_is_exact_in_the_furnace_sample_by_sample():
    r"""Per sample the estimate is a polynomial in ρ that naive differentiates exactly: at depth 2,
    $L_e + (ρ/2) \hat E_1 + ρ (ρ/2) \hat E_2$ with emission-only $\hat E$, a quadratic, whose central
    difference is exact but for rounding (about $10^{-16} L / h$)."""
    scene = load_scene(_furnace())
    task = ImageTask(scene, parse_parameter(scene, "room.albedo"), 64, 5, BATCHES, 2)
    naive = GRADIENT_METHODS.run("naive", task).derivative
    h = 1e-4
    plus = detach(task.evaluate(h).value)
    minus = detach(task.evaluate(-h).value)
    assert np.min(naive) > 0.5  # ∂L/∂ρ = L_e (1 + 2ρ) = 2.2 in expectation
    np.testing.assert_allclose(naive, (plus - minus) / (2.0 * h), rtol=0.0, atol=1e-9)


@pytest.mark.parametrize("param", [None, "light.emission", "occluder.translate.x"])
def test10_incident_re_attaches_only_the_kept_hits_and_those_on_emitters(param):
    """``incident`` with ``keep`` (what :func:`~flatland.integrator.shade` passes: the BSDF samples a path
    goes on along) re-attaches the kept hits and those on emitters only, in ray order, and the radiance,
    value and tangent, is the same bit for bit as re-attaching every hit (a wall's emission is 0 and
    static). On ``interreflection``, whose one-sided light is seen from both sides, with the emission
    moving or not."""
    from flatland.core.dual import Dual, tangent
    from flatland.integrator import incident
    from flatland.tracing import cast, direction

    scene = load_scene("interreflection")
    state = build_state(scene, None if param is None else parse_parameter(scene, param), Dual(0.0, 1.0))
    rng = np.random.default_rng(3)
    n = 4000
    origins = np.column_stack([rng.uniform(-1.9, 1.9, n), rng.uniform(0.05, 2.45, n)])
    d = direction(rng.uniform(-np.pi, np.pi, n))
    hits = cast(state.detached(), origins, d)
    keep = rng.random(n) < 0.3
    every, att_all = incident(state, origins, d, hits)
    kept, att = incident(state, origins, d, hits, keep)
    light = np.flatnonzero(detach(state.emission) > 0.0)
    on_light = hits.hit & np.isin(hits.prim, light)
    rows = np.flatnonzero(hits.hit & (keep | on_light))
    assert 0 < rows.size < np.count_nonzero(hits.hit) and on_light.any()
    assert (
        detach(att.point).tobytes()
        == detach(att_all.point)[np.searchsorted(np.flatnonzero(hits.hit), rows)].tobytes()
    )
    assert detach(kept).tobytes() == detach(every).tobytes()
    assert tangent(kept).tobytes() == tangent(every).tobytes()
    assert np.any(detach(every) > 0.0)
