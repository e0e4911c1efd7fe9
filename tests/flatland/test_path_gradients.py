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
    weights' derivatives, multiplied along the path). The derivative is resolved: the pixels' sum of
    |FD| is over 20 of its standard errors."""
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
