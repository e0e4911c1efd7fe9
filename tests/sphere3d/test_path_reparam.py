r"""``reparam`` on light paths (``max_depth`` > 1, :mod:`sphere3d.path_changes`): every vertex's shading
integral under the method's change of variables, the path going on along the rotated sample.

1. The values are naive's, bit for bit, at depths 2 and 3 (diffuse and glossy scenes, images and a
   point); at depth 1 none of the path code runs (so depth 1 is the direct-illumination method as it
   was: its outputs were also compared with the previous commit's, bit for bit).
2. What paths add to the gradient of the occluder's x-translation (depth 2 minus depth 1, each method
   on common seeds across the two depths), by region, against finite differences: ``interreflection``
   (the direct shadow's trailing and leading halves, the occluder, the back, left and right walls
   outside the shadow: indirect shadows and light bouncing between walls); ``glossy_reflection``
   (shadow halves, the occluder's reflection, the occluder). The depth-1 parts keep the method's
   depth-1 biases (the emitter rotation's in the glossy floor's leading half, a derivative in the
   occluder's reflection: tests/sphere3d/test_glossy.py test10, docs/theory/radiometry.md), which
   cancel in the difference.
3. The control variate of the carried radiance (:func:`~sphere3d.path_changes.path_baseline`): without
   it the kernel weights' derivative, times the radiance the path brings back, multiplies the standard
   error on ``interreflection`` by about twenty; the test asks for a variance ratio beyond 16 times the
   F distribution's 1 - ALPHA quantile (standard errors at least 4 times apart, at that level). At
   depth 3 its c is the whole carried path's radiance (:func:`~sphere3d.paths.carrier`): with the
   next vertex's direct light only, the variance is F-significantly larger, and the two differ by
   zero-mean terms only (test09). It is estimated only where its term moves, the image bit for bit
   that of estimating it everywhere (test10).
4. Slow: the same as 2 with 4 times the samples (which sees a path that does not go on along the
   rotated sample), and at depth 3 (depth 3 minus depth 1), where on ``interreflection`` reparam's
   variance is also bounded by finite differences' region by region (F quantile).
5. k parameters at once equal the single-parameter runs bit for bit on paths; the irradiance at a
   fixed point in the box with one further vertex against finite differences (the normal quantile
   of 2^15 samples).

Tolerances: $|a - b| <= q \sqrt{se_a^2 + se_b^2}$, q the Student-t quantile of 16 batches (15 degrees of
freedom) Šidák-corrected over each test's comparisons at ALPHA = 1e-3; fixed seeds, the two methods on
different seeds (independent batches).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from benchmarks.bench_glossy import _primary, shadow_halves
from benchmarks.bench_glossy import regions as regions_of
from flatland.core.stats import family_quantile
from sphere3d import path_changes, paths
from sphere3d.methods import GRADIENT_METHODS
from sphere3d.render import irradiance, render_gradient
from sphere3d.scene import load_scene
from sphere3d.tasks import ImageTask
from tests.tiers import SLOW

ALPHA = 1e-3
BATCHES = 16
PARAM = "occluder.translate.x"


def _scene(name: str, width: int) -> dict:
    d = load_scene(name).to_dict()
    d["camera"].update(width=width, height=width)
    return d


def _regions(scene, width: int) -> dict[str, np.ndarray]:
    """glossy_reflection's four regions (benchmarks.bench_glossy); in the box: the direct shadow's halves,
    the occluder, and the three walls (the indirect shadows and colour bleeding) outside the shadow."""
    if "ground" in [s.name for s in scene.shapes]:
        return regions_of(scene, width)
    trailing, leading = shadow_halves(scene, width)
    shape = _primary(scene, width)[1].reshape(width, width)
    names = [s.name for s in scene.shapes]
    out = {"trailing": trailing, "leading": leading}
    for name in ("occluder", "back", "left", "right"):
        out[name] = (shape == names.index(name)) & ~trailing & ~leading
    return out


def _sums(scene, method: str, spp: int, seed: int, depth: int, regions: dict, **options) -> dict:
    """Per region, the mean and standard error over batches of the derivative's region sum at ``depth``
    minus the same at depth 1 (the same seed: the first vertex's samples are common, so the difference
    is what paths add, with the direct part's noise cancelled); at depth 1 the sum itself."""
    g = 0.0
    for d, sign in ((depth, 1.0), (1, -1.0)) if depth > 1 else ((1, 1.0),):
        task = ImageTask(scene, PARAM, spp, seed, BATCHES, film="pixel", max_depth=d)
        g = g + sign * GRADIENT_METHODS.run(method, task, **options).derivative
    out = {}
    for name, r in regions.items():
        s = g[:, r].sum(axis=1)
        out[name] = (float(s.mean()), float(s.std(ddof=1) / np.sqrt(BATCHES)))
    return out


def _agree(
    name: str, spp: int, depth: int, width: int = 32, seen: bool = True, bounded: bool = False
) -> None:
    """What paths of ``depth`` vertices add to the gradient, region by region: reparam against finite
    differences within the noise of both (the depth-1 biases cancel in the difference; test_glossy
    test10 and docs/theory/radiometry.md have them). With ``seen``, the addition is far from 0 (a
    chi-square of reparam's region sums over their standard errors beyond its 1 - ALPHA quantile):
    a method that dropped what paths add would fail. With ``bounded``, reparam's variance is not
    larger than finite differences' in any region (the ratio of the squared standard errors within
    the F distribution's 1 - ALPHA quantile, Šidák-corrected over the regions)."""
    scene = load_scene(_scene(name, width))
    regions = _regions(scene, width)
    assert all(r.sum() >= 8 for r in regions.values())
    rep = _sums(scene, "reparam", spp, 1, depth, regions)
    fd = _sums(scene, "finite_difference", spp, 2, depth, regions)
    q = family_quantile(len(regions), 1.0 - ALPHA, dof=BATCHES - 1)
    for region in regions:
        (r, se_r), (f, se_f) = rep[region], fd[region]
        assert se_r > 0.0 and se_f > 0.0
        assert abs(r - f) <= q * np.hypot(se_r, se_f), (region, r, f, se_r, se_f)
    if bounded:
        f = stats.f.ppf((1.0 - ALPHA) ** (1.0 / len(regions)), BATCHES - 1, BATCHES - 1)
        for region in regions:
            assert rep[region][1] ** 2 <= f * fd[region][1] ** 2, (region, rep[region], fd[region])
    if seen:
        chi2 = sum((r / se) ** 2 for r, se in rep.values())
        assert chi2 > stats.chi2.ppf(1.0 - ALPHA, len(regions)), rep


@pytest.mark.parametrize(
    ("name", "depth"), [("interreflection", 2), ("interreflection", 3), ("glossy_reflection", 2)]
)
def test01_values_are_naives_bit_for_bit_on_paths(name, depth):
    scene = _scene(name, 10)
    r = render_gradient(scene, PARAM, "reparam", spp=4, seed=3, max_depth=depth, progress=False)
    n = render_gradient(scene, PARAM, "naive", spp=4, seed=3, max_depth=depth, progress=False)
    assert np.array_equal(r.value, n.value)
    assert np.abs(r.derivative).max() > 0.0 and not np.array_equal(r.derivative, n.derivative)
    if name == "interreflection":  # a point on the floor, in the box, with its paths
        point = dict(point=(0.3, 0.2, 0.01), normal=(0.0, 0.0, 1.0), n=64, seed=3, max_depth=depth)
        assert (
            irradiance(scene, param=PARAM, method="reparam", **point).value
            == irradiance(scene, **point).value
        )


def test02_depth_one_runs_none_of_the_path_code(monkeypatch):
    """At depth 1 no recorder is made and no point is :class:`~sphere3d.path_changes.Onward`: the
    direct-illumination method."""

    def refuse(*args, **kwargs):
        raise AssertionError("path code at depth 1")

    for name in ("recorder", "steer", "path_baseline"):
        monkeypatch.setattr(path_changes, name, refuse)
    for name in ("interreflection", "glossy_reflection", "hard_shadow"):
        render_gradient(_scene(name, 6), PARAM, "reparam", spp=2, seed=1, progress=False)


def test03_interreflection_at_depth_two_agrees_with_finite_differences_by_region():
    _agree("interreflection", 512, 2)


def test04_glossy_reflection_at_depth_two_agrees_with_finite_differences_by_region():
    """Under the glossy floor's overhead light the second vertex adds little to the x-derivative (the
    occluder's underside lit by the floor, about 1.6 ± 0.5 in finite differences at 2048 spp): the
    agreement is tested, not that it is seen."""
    _agree("glossy_reflection", 512, 2, seen=False)


def test05_the_carried_radiances_control_variate_lowers_the_noise_on_interreflection():
    scene = load_scene(_scene("interreflection", 16))
    regions = {"all": np.ones((16, 16), dtype=bool)}
    with_cv = _sums(scene, "reparam", 64, 3, 2, regions)["all"][1]
    without = _sums(scene, "reparam", 64, 3, 2, regions, baseline=False)["all"][1]  # the same depth-1 part
    f = stats.f.ppf(1.0 - ALPHA, BATCHES - 1, BATCHES - 1)
    assert (without / with_cv) ** 2 > 16.0 * f, (with_cv, without)


@SLOW
@pytest.mark.parametrize(
    ("name", "spp", "depth"),
    [("interreflection", 2048, 2), ("interreflection", 1024, 3), ("glossy_reflection", 1024, 3)],
)
def test06_more_samples_and_depth_three_agree_with_finite_differences_by_region(name, spp, depth):
    """test03 at 4 times the samples: there a path going on along μ instead of Rμ (its next vertex not
    re-attached along the rotated sample) is about 5 standard errors off on the right wall, and one
    without the kernel weight in its throughput about 5 in the shadow's leading half, beyond q ≈ 5.
    At depth 3 what paths add is within the noise of both methods at these samples (not seen), and on
    ``interreflection`` reparam's variance is bounded by finite differences' region by region: with the
    control variate of the next vertex's direct light only, samples near the box's creases carried
    derivatives 10³ times the typical one (test09, docs/theory/radiometry.md) and its standard errors
    were several times finite differences'."""
    _agree(name, spp, depth, seen=depth == 2, bounded=name == "interreflection" and depth == 3)


def test07_k_parameters_at_once_are_the_single_parameter_runs_bit_for_bit():
    names = ["occluder.translate.x", "occluder.translate.z"]
    for name in ("interreflection", "glossy_reflection"):
        scene = _scene(name, 8)
        both = render_gradient(scene, names, "reparam", spp=4, seed=2, max_depth=2, progress=False)
        for param in names:
            one = render_gradient(scene, param, "reparam", spp=4, seed=2, max_depth=2, progress=False)
            assert np.array_equal(both[param].derivative, one.derivative)
            assert np.abs(one.derivative).max() > 0.0


def test08_the_irradiance_at_a_point_in_the_box_against_finite_differences():
    """A floor point of ``interreflection`` next to the occluder's shadow, with one further vertex: the
    point is fixed, the paths' first weight $π \\cos / \\cos_0$ (:func:`~sphere3d.paths.irradiance_paths`)."""
    scene = _scene("interreflection", 8)
    point = dict(point=(0.5, 0.3, 0.01), normal=(0.0, 0.0, 1.0), param=PARAM, n=2**15, max_depth=2)
    rep = irradiance(scene, method="reparam", seed=1, **point)
    fd = irradiance(scene, method="finite_difference", seed=2, **point)
    q = stats.norm.ppf(1.0 - ALPHA / 2)
    assert abs(fd.derivative) > q * fd.derivative_stderr  # the point sees the occluder move
    assert abs(rep.derivative - fd.derivative) <= q * np.hypot(rep.derivative_stderr, fd.derivative_stderr)


def test09_the_control_variate_carries_the_further_vertices_light_at_depth_three(monkeypatch):
    """At depth 3 the control variate's c is the whole carried path's radiance
    (:func:`~sphere3d.paths.carrier`). With the next vertex's direct light only (``carrier`` giving
    None: the control variate of depth 2) the light the third vertex brings multiplies the kernel
    weights' derivative unchecked, heavy-tailed where a moving point nears a static crease: over the
    whole 16 x 16 image of ``interreflection`` the variance of the gradient's sum over batches is more
    than the F distribution's 1 - ALPHA quantile times the carrier's (heavy tails make the F law
    approximate; the ratio is about 5 here, so 32 batches of 2 spp: the quantile of F(31, 31), about
    3, leaves the test its power). The two differ by zero-mean terms only: their paired difference per
    batch has a mean within the Student-t quantile of its standard error."""
    batches = 2 * BATCHES
    scene = load_scene(_scene("interreflection", 16))
    task = ImageTask(scene, PARAM, 64, 3, batches, film="pixel", max_depth=3)
    carried = GRADIENT_METHODS.run("reparam", task).derivative.sum(axis=(1, 2))
    monkeypatch.setattr(paths, "carrier", lambda depth, last: None)
    direct = GRADIENT_METHODS.run("reparam", task).derivative.sum(axis=(1, 2))
    f = stats.f.ppf(1.0 - ALPHA, batches - 1, batches - 1)
    assert direct.var(ddof=1) > f * carried.var(ddof=1), (direct.var(ddof=1), carried.var(ddof=1))
    diff = carried - direct
    q = stats.t.ppf(1.0 - ALPHA / 2, batches - 1)
    assert abs(diff.mean()) <= q * diff.std(ddof=1) / np.sqrt(batches), (diff.mean(), diff.std(ddof=1))


def test10_the_control_variate_estimates_c_only_where_its_term_moves(monkeypatch):
    """The carried radiance's control variate is $-c\\, \\dot q / p$: where a sample's rotation and kernel
    weight do not move ($\\dot q = 0$, most samples of ``interreflection``, whose kernels see no moving
    triangle) it is 0 whatever c, so c (the centre's ray and its carried path) is estimated only at
    the others. The depth-3 image, every array bit for bit, is that of estimating c at every sample,
    with fewer carried paths."""
    scene = load_scene(_scene("interreflection", 12))
    task = ImageTask(scene, PARAM, 8, 3, 4, max_depth=3)
    carrier, carried = paths.carrier, []

    def counted(depth, last):
        carry = carrier(depth, last)
        if carry is None:
            return None

        def count(at, u):
            carried.append(len(at))
            return carry(at, u)

        return count

    monkeypatch.setattr(paths, "carrier", counted)
    turning = GRADIENT_METHODS.run("reparam", task)
    few = sum(carried)
    carried.clear()
    monkeypatch.setattr(path_changes, "moves", lambda q: np.ones(np.shape(q.value), dtype=bool))
    every = GRADIENT_METHODS.run("reparam", task)
    assert 0 < few < sum(carried), (few, sum(carried))
    assert turning.value.tobytes() == every.value.tobytes()
    assert turning.derivative.tobytes() == every.derivative.tobytes()
    assert np.max(np.abs(every.derivative)) > 0.0


@pytest.mark.parametrize("name", ["interreflection", "glossy_reflection"])
def test11_kernels_that_see_no_moving_triangle_keep_the_identity_without_probes(monkeypatch, name):
    """A static shading point whose BSDF kernel's probes, snaps and shapes (within twice the ring's angle
    of its centre) meet no changing triangle (:func:`~sphere3d.reparam.penumbra.cone_may_see_motion`,
    by their bounding sphere) can only follow static points: its sample keeps the identity, without
    probes. The depth-3 image, every array bit for bit, is that of probing every kernel, and some
    kernels were left out."""
    from sphere3d.reparam import default

    scene = load_scene(_scene(name, 12))
    task = ImageTask(scene, [PARAM, "occluder.translate.y"], 8, 3, 4, max_depth=3)
    rotated, probed = default.ReparamTransforms._rotated, []

    def counted(self, sub, mu, centre, kappa):
        probed.append(len(mu))
        return rotated(self, sub, mu, centre, kappa)

    monkeypatch.setattr(default.ReparamTransforms, "_rotated", counted)
    culled = GRADIENT_METHODS.run("reparam", task)
    few = sum(probed)
    probed.clear()
    monkeypatch.setattr(default, "cone_may_see_motion", lambda state, x, c, h: np.ones(len(x), dtype=bool))
    every = GRADIENT_METHODS.run("reparam", task)
    assert 0 < few < sum(probed), (few, sum(probed))
    assert culled.value.tobytes() == every.value.tobytes()
    assert culled.derivative.tobytes() == every.derivative.tobytes()
    assert np.max(np.abs(every.derivative)) > 0.0
