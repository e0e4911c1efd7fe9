r"""Paths of several diffuse vertices (``max_depth``) in sphere3d against the closed form of a white furnace.

The furnace: a closed cube room whose every wall faces inward (its triangles wound so their normals
point into the room: sphere3d emits from the front side only, the side the normals face), emits
$L_e$ and reflects with albedo ρ. A constant radiance L arriving from every direction of the
hemisphere gives the irradiance

    $E = ∫_{H} L \cos θ\, dω = L ∫_0^{2π} ∫_0^{π/2} \cos θ \sin θ\, dθ\, dφ = 2π L / 2 = π L$

and the diffuse reflection $(ρ/π) E = ρ L$. With d diffuse vertices per path (``max_depth`` d,
1 being direct illumination: a camera ray and a shading ray) the radiance leaving every point of
the walls is

    $L_d = L_e + ρ L_{d-1}$, $L_0 = L_e$, so $L_d = L_e Σ_{i=0}^{d} ρ^i = L_e (1 - ρ^{d+1}) / (1 - ρ)$

(flatland's convention, theory/radiometry "Paths"), constant over the walls, so every pixel's
expectation is $L_d$, and the irradiance at any point inside (``irradiance``, whose point is vertex 1
and has no albedo) is $E_d = π L_{d-1}$. Being constant, $L_d$ has no jump at any corner: moving the
room changes no pixel (derivative 0) and the naive estimator is unbiased for every parameter;
$∂L_d/∂ρ = L_e Σ_{i=1}^{d} i ρ^{i-1}$, $∂L_d/∂L_e = Σ_{i=0}^{d} ρ^i$.

Tolerances: $|mean - reference| <= q · stderr$ with q the Student-t quantile of the batch standard
error (16 batches, 15 degrees of freedom), Šidák-corrected over the comparisons of each test at
ALPHA = 1e-3, fixed seeds. The pixel film with the box filter has no control variate, so the
batches are independent and the pixel average of a batch is one estimate per batch.
"""

from __future__ import annotations

import numpy as np
import pytest

from flatland.core.stats import family_quantile
from flatland.core.validate import ValidationError
from sphere3d import execution, tasks
from sphere3d.methods import GRADIENT_METHODS
from sphere3d.render import irradiance, render, render_gradient
from sphere3d.scene import load_scene
from sphere3d.shapes import box
from sphere3d.tasks import ImageTask, PointTask

ALPHA = 1e-3
BATCHES = 16
LE, RHO = 1.0, 0.6
DEPTHS = (1, 2, 3, 4)
POINT, NORMAL = (0.3, -0.2, 0.4), (0.6, 0.0, 0.8)


def _furnace() -> dict:
    """The cube [-1, 1]^3, its box mesh's triangles wound the other way round: every normal inward."""
    mesh = box(2.0, 2.0, 2.0)
    room = {
        "name": "room",
        "type": "mesh",
        "vertices": mesh.vertices.tolist(),
        "faces": mesh.faces[:, ::-1].tolist(),
        "albedo": RHO,
        "emission": LE,
    }
    camera = {"position": [-0.4, -0.5, -0.2], "look_at": [1.0, 0.6, 0.5], "up": [0.0, 0.0, 1.0]}
    camera.update({"fov": 1.4, "width": 8, "height": 8, "filter": "box"})
    return {"name": "furnace", "camera": camera, "sky": 0.0, "shapes": [room]}


def _open(width: int = 12) -> dict:
    """hard_shadow, small: a floor, an occluder and one emitter under a black sky (paths escape)."""
    scene = load_scene("hard_shadow").to_dict()
    scene["camera"].update(width=width, height=width)
    return scene


def _series(d: int) -> float:
    """$L_d = L_e Σ_{i=0}^{d} ρ^i$."""
    return LE * sum(RHO**i for i in range(d + 1))


def _pooled(per_batch: np.ndarray) -> tuple[float, float]:
    """Mean and standard error of the pixel averages of independent batches (batches, pixels...)."""
    b = np.asarray(per_batch).reshape(BATCHES, -1).mean(axis=1)
    return float(b.mean()), float(b.std(ddof=1) / np.sqrt(b.size))


def _within(estimates: list[tuple[float, float]], references: list[float]) -> None:
    q = family_quantile(len(estimates), 1.0 - ALPHA, dof=BATCHES - 1)
    for (mean, se), ref in zip(estimates, references, strict=True):
        assert se > 0.0  # the test can see noise: a zero stderr would make any tolerance vacuous
        assert abs(mean - ref) <= q * se, (mean, ref, se, q)


def _image(param: str | None, spp: int, seed: int, d: int) -> ImageTask:
    return ImageTask(load_scene(_furnace()), param, spp, seed, BATCHES, film="pixel", max_depth=d)


@pytest.mark.parametrize(
    "bad", [0, -1, 1.5, True, "2", None], ids=["zero", "negative", "float", "bool", "str", "none"]
)
def test01_max_depth_is_an_integer_of_at_least_one(bad):
    for call in (
        lambda: render(_furnace(), spp=4, max_depth=bad),
        lambda: render_gradient(_furnace(), "room.albedo", "naive", spp=4, max_depth=bad),
        lambda: irradiance(_furnace(), POINT, NORMAL, n=4, max_depth=bad),
    ):
        with pytest.raises(ValidationError) as err:
            call()
        assert err.value.field == "max_depth"
        assert repr(bad) in str(err.value)


@pytest.mark.parametrize("method", ["naive", "finite_difference", "boundary", "reparam"])
def test02_depth_one_is_the_default_bit_for_bit(method):
    scene = _open(8)
    a = render_gradient(scene, "occluder.translate.x", method, spp=8, seed=2, progress=False)
    b = render_gradient(scene, "occluder.translate.x", method, spp=8, seed=2, progress=False, max_depth=1)
    assert np.array_equal(a.value, b.value) and np.array_equal(a.derivative, b.derivative)
    e0 = irradiance(scene, (0.0, 0.0, 0.01), (0.0, 0.0, 1.0), "occluder.translate.x", method, n=64, seed=2)
    e1 = irradiance(
        scene, (0.0, 0.0, 0.01), (0.0, 0.0, 1.0), "occluder.translate.x", method, n=64, seed=2, max_depth=1
    )
    assert (e0.value, e0.derivative) == (e1.value, e1.derivative)
    if method == "naive":
        assert np.array_equal(render(scene, spp=8, seed=2).value, a.value)
        assert np.array_equal(render(scene, spp=8, seed=2, max_depth=1).value, a.value)


def test03_the_furnace_image_sums_the_series_at_every_depth():
    estimates = [_pooled(_image(None, 256, 7, d).evaluate(0.0).value) for d in DEPTHS]
    _within(estimates, [_series(d) for d in DEPTHS])
    # the depths differ by more than their noise: the test would see a missing vertex
    assert all(estimates[i + 1][0] - estimates[i][0] > 0.05 for i in range(len(DEPTHS) - 1))


def test04_the_furnace_irradiance_at_a_point_is_pi_times_the_series_one_short():
    estimates = []
    for d in DEPTHS:
        task = PointTask(load_scene(_furnace()), None, POINT, NORMAL, 4096, 8, BATCHES, max_depth=d)
        estimates.append(_pooled(task.evaluate(0.0).value))
    _within(estimates, [np.pi * _series(d - 1) for d in DEPTHS])


@pytest.mark.parametrize("method", ["naive", "finite_difference"])
def test05_furnace_derivatives_at_depth_three(method):
    d = 3
    references = {
        "room.albedo": LE * sum(i * RHO ** (i - 1) for i in range(1, d + 1)),
        "room.emission": sum(RHO**i for i in range(d + 1)),
        "room.translate.x": 0.0,  # L is constant over the walls wherever the room is
    }
    estimates = []
    for name, reference in references.items():
        tally = GRADIENT_METHODS.run(method, _image(name, 256, 9, d))
        estimates.append(_pooled(tally.derivative))
        assert _pooled(tally.value)[0] == pytest.approx(_series(d), rel=0.05)
        if reference:  # the moving room's derivative is noise about 0; the others are not small
            assert estimates[-1][0] > 0.5
    _within(estimates, list(references.values()))


def test06_paths_do_not_depend_on_chunks_or_threads(monkeypatch):
    """Every uniform of a path is keyed on (sample, depth): chunks and threads change no number."""
    scene = _open()
    run = lambda: render_gradient(scene, "light.emission", "naive", spp=8, seed=3, max_depth=3)  # noqa: E731
    monkeypatch.setattr(execution, "WORKERS", 1)
    whole = run()
    monkeypatch.setattr(execution, "WORKERS", 2)
    monkeypatch.setattr(tasks, "CHUNK", 8 * 5)  # 5 pixels per chunk: chunks end mid-row
    part = run()
    assert np.array_equal(whole.value, part.value) and np.array_equal(whole.derivative, part.derivative)
    # paths do go deeper than one vertex here: the same direct part (the same uniforms), plus light that
    # came off the floor and the occluder (about 1% of the image under this overhead light)
    direct = render_gradient(scene, "light.emission", "naive", spp=8, seed=3)
    assert np.all(whole.value >= direct.value - 1e-12) and np.mean(whole.value - direct.value) > 1e-3
    point = dict(point=(0.0, 0.0, 0.01), normal=(0.0, 0.0, 1.0), n=256, seed=3, max_depth=3)
    a = irradiance(scene, **point)
    monkeypatch.setattr(tasks, "CHUNK", 48)  # chunks end mid-batch
    assert irradiance(scene, **point).value == a.value


def test07_naive_and_finite_differences_agree_where_the_image_is_affine_in_the_parameter():
    """The open scene's image is affine in the one emitter's radiance, sample by sample (no path depends
    on it: one emitter is drawn with probability 1), so the central difference with common random
    numbers is exact but for rounding, and so must naive be, at depth 2."""
    task = ImageTask(load_scene(_open()), "light.emission", 16, 4, BATCHES, max_depth=2)
    naive = GRADIENT_METHODS.run("naive", task)
    fd = GRADIENT_METHODS.run("finite_difference", task)
    assert np.array_equal(naive.value, fd.value)  # the value render is the same at θ0
    scale = np.max(np.abs(naive.derivative))
    assert scale > 0.01
    np.testing.assert_allclose(naive.derivative, fd.derivative, rtol=0.0, atol=1e-9 * max(1.0, scale))


@pytest.mark.parametrize(
    ("method", "options"),
    [("reparam", {"variant": "paper"}), ("reparam", {"paired": True})],
)
def test08_reparams_paired_samples_refuse_paths_and_say_why(method, options):
    """``reparam`` goes on along its rotated samples (tests/sphere3d/test_path_reparam.py), but its paired
    kernel samples (the paper variant always pairs) have no single direction to go on along.
    (``boundary`` takes paths: tests/sphere3d/test_path_boundary.py.)"""
    with pytest.raises(ValidationError) as err:
        render_gradient(_open(8), "occluder.translate.x", method, spp=4, max_depth=2, **options)
    assert err.value.field == "max_depth"
    assert "not yet supported on paths" in str(err.value) and "2" in str(err.value)
    with pytest.raises(ValidationError, match="not yet supported on paths"):
        irradiance(
            _open(8), (0.0, 0.0, 0.01), (0.0, 0.0, 1.0), "occluder.translate.x", method, n=4, max_depth=3,
            **options,
        )  # fmt: skip
