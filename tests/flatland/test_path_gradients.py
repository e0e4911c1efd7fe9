r"""boundary and reparam on paths (``max_depth`` > 1): moving occluders seen through further bounces.

``occluder.translate.x`` of the built-in ``interreflection`` (indirect shadows in a closed box) and
``glossy_reflection`` (the occluder's reflection in a glossy floor), 16 pixels, against central
finite differences (h = 0.05, 8192 spp, common random numbers).

Tolerances: per pixel $|a - b| <= q · \sqrt{s_a^2 + s_b^2}$ with the Student-t quantile q of the
batch standard errors (16 independent batches, 15 degrees of freedom), Šidák-corrected over every
comparison of a test at ALPHA = 1e-3, fixed seeds; a pixel where both estimates are exact (standard
error 0) must agree to rounding.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from flatland.core.stats import family_quantile
from flatland.core.validate import ValidationError
from flatland.integrator import incident
from flatland.methods import boundary
from flatland.render import irradiance, render_gradient
from flatland.scene import load_scene
from flatland.tracing import cast
from tests.tiers import SLOW

ALPHA = 1e-3
BATCHES = 16
PARAM = "occluder.translate.x"
CASES = [(name, depth) for name in ("interreflection", "glossy_reflection") for depth in (2, 3)]


def _args(depth: int) -> dict:
    return {"seed": 5, "progress": False, "max_depth": depth, "batches": BATCHES}


@cache
def _reference(name: str, depth: int):
    scene = load_scene(name).with_camera(pixels=16)
    return render_gradient(scene, PARAM, "finite_difference", spp=8192, h=0.05, **_args(depth))


def _gradient(name: str, depth: int, method: str, spp: int):
    scene = load_scene(name).with_camera(pixels=16)
    return render_gradient(scene, PARAM, method, spp=spp, **_args(depth))


def _z(a, b) -> np.ndarray:
    """Per-pixel z-scores of two independent-batch derivative images (0 where both are exact)."""
    s = np.hypot(a.derivative_stderr, b.derivative_stderr)
    diff = a.derivative - b.derivative
    return np.where(s > 0.0, diff / np.where(s > 0.0, s, 1.0), np.where(np.abs(diff) > 1e-12, np.inf, 0.0))


def test01_at_depth_one_no_side_path_is_traced(monkeypatch):
    """Depth 1 runs the direct-only jump terms as before (their output is bit for bit the parent
    commit's, checked when the paths were added): the side-path estimator is never called, and at
    depth 2 it is."""
    calls = []
    real = boundary.radiance_along_rays

    def spy(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(boundary, "radiance_along_rays", spy)
    for name in ("interreflection", "glossy_reflection"):
        _gradient(name, 1, "boundary", 16)
    irradiance(load_scene("interreflection"), (0.0, 0.5), (0.0, 1.0), PARAM, "boundary", n=16, seed=2)
    assert not calls
    _gradient("interreflection", 2, "boundary", 16)
    assert calls


@pytest.mark.parametrize(("name", "depth"), CASES)
def test02_boundary_and_reparam_agree_with_finite_differences_pixel_by_pixel(name, depth):
    """boundary (1024 spp) and reparam (2048 spp) against finite differences, and reparam against
    boundary: Šidák over the 3 x 16 comparisons. Measured at seed 5, depth 2 and 3: max |z| 2.9 and
    2.3 (boundary vs FD in interreflection), 2.7 and 2.7 (glossy_reflection); reparam vs FD 2.5, 1.9,
    2.9, 2.9. reparam's standard errors are 5-10 times boundary's at twice the samples (the kernel
    weights' derivatives, multiplied along the path); at these samples they hide reparam's bias at
    the direct shadow's ends, which test07 shows with 16 times more. The derivative is resolved: the
    pixels' sum of |FD| is over 20 of its standard errors."""
    fd = _reference(name, depth)
    bd = _gradient(name, depth, "boundary", 1024)
    rp = _gradient(name, depth, "reparam", 2048)
    q = family_quantile(3 * fd.derivative.size, 1.0 - ALPHA, dof=BATCHES - 1)
    for label, a, b in (("boundary-fd", bd, fd), ("reparam-fd", rp, fd), ("reparam-boundary", rp, bd)):
        z = _z(a, b)
        assert np.max(np.abs(z)) <= q, (label, name, depth, np.round(z, 1))
    assert np.sum(np.abs(fd.derivative)) > 20.0 * np.sqrt(np.sum(fd.derivative_stderr**2))


def _direct_sides(ctx, origins, d, ignore, u, draws):
    """The jump's sides as at depth 1: the emission the side ray meets, nothing reflected beyond it."""
    return incident(ctx.geom0, origins, d, cast(ctx.geom0, origins, d, ignore))[0]


def test03_without_the_side_paths_boundary_misses_the_indirect_shadows(monkeypatch):
    """The side paths are what recovers the second bounce: with each jump's sides seen as at depth 1
    (emission only), boundary at depth 2 in interreflection misses the moving indirect shadow, beyond
    the quantile in some pixel (a test that the statistical comparison of test02 can fail)."""
    fd = _reference("interreflection", 2)
    monkeypatch.setattr(boundary, "radiance_along_rays", _direct_sides)
    z = _z(_gradient("interreflection", 2, "boundary", 1024), fd)
    q = family_quantile(fd.derivative.size, 1.0 - ALPHA, dof=BATCHES - 1)
    assert np.max(np.abs(z)) > q, np.round(z, 1)


@pytest.mark.parametrize("method", ["boundary", "reparam"])
def test04_the_furnace_moves_nothing_at_depth_three(method):
    """A closed emitting, reflecting room is a closed form: L is the same everywhere on the walls at
    every depth, so moving a corner changes no pixel (derivative 0): every jump's sides carry the same
    radiance in expectation, and every reparameterized integrand is constant. Student t, Šidák over
    the 8 pixels."""
    scene = load_scene("furnace").with_camera(pixels=8)
    param = next(p for p in scene.parameters if ".vertex." in p or ".translate." in p)
    g = render_gradient(scene, param, method, spp=512, **_args(3))
    q = family_quantile(g.derivative.size, 1.0 - ALPHA, dof=BATCHES - 1)
    se = g.derivative_stderr
    assert np.all(np.abs(g.derivative) <= q * se + 1e-12), (np.round(g.derivative, 3), np.round(se, 3))


def test05_paired_reparam_refuses_paths_and_says_why():
    with pytest.raises(ValidationError) as err:
        render_gradient(load_scene("interreflection"), PARAM, "reparam", spp=4, paired=True, max_depth=2)
    assert err.value.field == "paired"
    assert "one evaluation point per sample" in str(err.value)


@pytest.mark.parametrize("method", ["boundary", "reparam"])
def test06_paths_do_not_depend_on_memory_chunks(monkeypatch, method):
    """Every number a path draws, its side paths' included, is keyed on the primary sample, the vertex
    and the candidate: chunks of 2^15, 100 and 7 samples (and candidate blocks of 7 edges) give the
    same depth-3 image but for the order of sums (at most 16 ε times 1e3 the value's scale per pixel)."""
    from flatland import tasks

    scene = load_scene("interreflection").with_camera(pixels=8)
    args = {"spp": 16, "seed": 9, "progress": False, "max_depth": 3}
    whole = render_gradient(scene, PARAM, method, **args)
    monkeypatch.setattr(tasks, "CHUNK", 100)
    monkeypatch.setattr(boundary, "MAX_CANDIDATES", 7)
    pieces = render_gradient(scene, PARAM, method, **args)
    monkeypatch.setattr(tasks, "CHUNK", 7)
    tiny = render_gradient(scene, PARAM, method, **args)
    scale = 1e3 * max(np.max(np.abs(whole.value)), np.max(np.abs(whole.derivative)))
    for other in (pieces, tiny):
        np.testing.assert_allclose(whole.value, other.value, rtol=0, atol=16 * np.finfo(float).eps * scale)
        np.testing.assert_allclose(
            whole.derivative, other.derivative, rtol=0, atol=16 * np.finfo(float).eps * scale
        )
    assert np.max(np.abs(whole.derivative)) > 0.05  # the image has a derivative to compare


# the pixels of interreflection (16 px) where the occluder's direct shadow ends on the floor: reparam's
# probe heuristic at the camera's hit is biased there at depth 1 already
SHADOW_EDGES = np.array([4, 5, 6])


@SLOW
def test07_reparam_on_paths_carries_its_first_vertex_bias_and_adds_none():
    """A test of a bias, not a loosened tolerance. reparam (32768 spp) against boundary (4096 spp) on
    interreflection: at depth 1 and at depth 2 reparam is off in some pixel of the direct shadow's
    ends beyond the Student-t quantile (Šidák over the 2 x 3 pixels, q = 4.97). Measured: reparam -
    boundary = -0.074, -0.105, 0.167 (z -3.8, -7.5, 9.5) against boundary's 0.214, 0.471, -0.348 at
    depth 1 (seed 11), -0.061, -0.117, 0.136 (z -2.9, -7.1, 4.9) at depth 2 (seed 12), every other
    pixel within |z| 1.7. What the further vertices add, the depth-2 image minus the depth-1 image,
    agrees between the two methods in every pixel (Šidák over 16, q = 5.49; measured max |z| 1.7;
    the depths use different seeds, so the four images are independent): the bias on paths is the
    first vertex's."""
    scene = load_scene("interreflection").with_camera(pixels=16)
    images = {}
    for depth, seed in ((1, 11), (2, 12)):
        args = {"seed": seed, "progress": False, "max_depth": depth, "batches": BATCHES}
        images[depth] = (
            render_gradient(scene, PARAM, "boundary", spp=4096, **args),
            render_gradient(scene, PARAM, "reparam", spp=1 << 15, **args),
        )
    q_seen = family_quantile(2 * SHADOW_EDGES.size, 1.0 - ALPHA, dof=BATCHES - 1)
    for depth, (bd, rp) in images.items():
        z = _z(rp, bd)
        assert np.max(np.abs(z[SHADOW_EDGES])) > q_seen, (depth, np.round(z, 1), "the bias is no longer seen")
    (bd1, rp1), (bd2, rp2) = images[1], images[2]
    added = (rp2.derivative - rp1.derivative) - (bd2.derivative - bd1.derivative)
    se = np.sqrt(sum(g.derivative_stderr**2 for g in (bd1, rp1, bd2, rp2)))
    q = family_quantile(added.size, 1.0 - ALPHA, dof=BATCHES - 1)
    assert np.all(np.abs(added) <= q * se), np.round(added / se, 1)
    # depth 2 adds a derivative beyond the noise: the comparison of what it adds has something to compare
    s = np.hypot(bd1.derivative_stderr, bd2.derivative_stderr)
    assert np.max(np.abs(bd2.derivative - bd1.derivative) / np.where(s > 0.0, s, np.inf)) > q


def test08_boundary_at_a_point_sees_the_indirect_shadow_move():
    """``irradiance`` at a floor point of interreflection (0, 0.05), facing up, at depth 2: the point is
    vertex 1, its jump terms see paths of one further vertex. boundary (2^15 samples) against finite
    differences (h = 0.05, 2^18): Student t over 16 batches. Measured at seed 5: 0.0343 ± 0.0014
    against 0.0359 ± 0.0008 (h = 0.02: 0.0316 ± 0.0013)."""
    scene = load_scene("interreflection")
    args = {"seed": 5, "max_depth": 2, "batches": BATCHES}
    point, normal = (0.0, 0.05), (0.0, 1.0)
    fd = irradiance(scene, point, normal, PARAM, "finite_difference", n=1 << 18, h=0.05, **args)
    bd = irradiance(scene, point, normal, PARAM, "boundary", n=1 << 15, **args)
    q = family_quantile(1, 1.0 - ALPHA, dof=BATCHES - 1)
    s = np.hypot(float(fd.derivative_stderr), float(bd.derivative_stderr))
    assert abs(float(bd.derivative) - float(fd.derivative)) <= q * s, (bd.derivative, fd.derivative, s)
    assert abs(float(fd.derivative)) > 10.0 * s  # the derivative is resolved


@pytest.mark.parametrize(
    ("name", "params", "cull"),
    [
        ("interreflection", PARAM, "needed"),
        ("interreflection", PARAM, "motion"),
        ("glossy_reflection", ["occluder.translate.x", "floor.roughness"], "needed"),
        ("glossy_reflection", ["occluder.translate.x", "floor.roughness"], "motion"),
    ],
)
def test09_reparam_moves_only_the_samples_that_can_add_something_and_the_image_is_the_same(
    monkeypatch, name, params, cull
):
    """Under ``reparam`` a direction sample keeps the identity, without probes, where its ray meets no
    emitter (a wall, an emitter's back, the black sky) and no path goes on along it (``ctx.needed`` of
    :func:`~flatland.integrator.shade`: its term and derivative are 0 wherever it goes), or where its
    shading point is static and its probes' span meets the image of no moving primitive (every point it
    may follow is static: a zero derivative). With either cull alone (the other off), the depth-3 image,
    every array bit for bit, is that of transforming every sample, and some samples were left out."""
    from dataclasses import replace

    from flatland.reparam import default
    from flatland.reparam.default import ReparamTransforms

    scene = load_scene(name).with_camera(pixels=8)
    args = {"spp": 16, "seed": 4, "progress": False, "max_depth": 3}
    rows = {"given": 0, "moved": 0, "all": True}
    directions, full, sees = (
        ReparamTransforms._directions,
        ReparamTransforms.directions,
        default._may_see_motion,
    )

    def counted(self, ctx, x, ignore, phi, draws, kappa, center=None):
        rows["moved"] += phi.size
        return directions(self, ctx, x, ignore, phi, draws, kappa, center)

    def given(self, ctx, x, ignore, phi, draws, lobe=None):
        rows["given"] += phi.size
        told = replace(ctx, needed=None) if rows["all"] or cull != "needed" else ctx
        return full(self, told, x, ignore, phi, draws, lobe)

    def motion(geom, x0, center, half):
        return (
            sees(geom, x0, center, half)
            if cull == "motion" and not rows["all"]
            else np.ones(len(center), bool)
        )

    monkeypatch.setattr(ReparamTransforms, "_directions", counted)
    monkeypatch.setattr(ReparamTransforms, "directions", given)
    monkeypatch.setattr(default, "_may_see_motion", motion)
    everything = render_gradient(scene, params, "reparam", **args)
    assert rows["moved"] == rows["given"]
    rows.update(given=0, moved=0, all=False)
    culled = render_gradient(scene, params, "reparam", **args)
    assert rows["moved"] < rows["given"], rows
    for field in ("value", "derivative", "value_stderr", "derivative_stderr"):
        assert getattr(culled, field).tobytes() == getattr(everything, field).tobytes(), field
    assert np.max(np.abs(everything.derivative)) > 0.0
