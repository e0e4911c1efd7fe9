r"""``reparam``'s BSDF-strategy kernel at glossy points follows the lobe's width
(:mod:`sphere3d.reparam.lobe`).

1. The rule, as a function: the per-point κ is the user's ``kappa`` at diffuse points, with the option
   ``lobe`` None and where the lobe is wide; where it is narrow it is
   $κ_x = \mathrm{spread}^2 / (2 (1 - \cos(λ\, 2 \arctan(α) \cos θ_i)))$, whose probe ring
   (:func:`~sphere3d.reparam.probes.vmf_spread_angle`) lies at exactly λ times the lobe's radius; capped
   at ``KAPPA_MAX`` at grazing incidence; the option checked (one error naming ``lobe``).
2. The lobe's radius at normal incidence is the median deviation of the GGX reflection (sampled).
3. The per-row κ of the vMF sampler, the ring angle and the ring directions are the scalar functions
   applied row by row (vectorized, no loop per sample).
4. Diffuse scenes do not change: ``hard_shadow`` (depth 1 and 2) with the default ``lobe`` and with
   ``lobe=None``, value and derivative bit for bit.
5. The problem and the fix at one glossy point, the case the rule is for: a floor of roughness α = 0.02
   under a uniform sky reflects a moving sphere beside a static box, a gap of 0.1 between them (about
   0.085 rad from the floor point, inside the default kernel's ring of 3/√1000 = 0.095 rad, three times
   the lobe's radius $2 \arctan(α) \cos θ_i$ = 0.027 rad). The reflected radiance's derivative in the sphere's
   x-translation, at the floor point whose mirror direction grazes the sphere's edge (x = 0.40) and at
   the one whose mirror direction meets the box next to the gap (x = 0.48): against central finite
   differences of the primal (common random numbers, h = 1e-3), the fixed kernel (``lobe=None``) is
   biased by many standard errors (its ring sees both edges; at x = 0.48 it follows the moving sphere
   where the lobe sees only the static box, a derivative of the wrong sign), the lobe-following
   kernel agrees within noise.
6. The same scene rendered (32 x 32, depth 1), region sums of the derivative over the floor pixels
   that reflect the gap (slow tier): the fixed kernel's bias, the lobe-following kernel's agreement
   with finite differences.

Tolerances: Student-t quantiles of 16 batches, Šidák-corrected over each test's comparisons at
ALPHA = 1e-3; the bias tests ask for a difference beyond that quantile times the standard error.
"""

from __future__ import annotations

import functools
import hashlib

import numpy as np
import pytest

from flatland.core.dual import tangent, variable
from flatland.core.rng import Draws
from flatland.core.stats import family_quantile
from flatland.core.validate import ValidationError
from sphere3d.bsdf import sample_ggx
from sphere3d.glossy import Lobe, glossy_samples
from sphere3d.integrator import Shading
from sphere3d.methods import GRADIENT_METHODS
from sphere3d.methods.reparam import KAPPA_MAX
from sphere3d.render import render_gradient
from sphere3d.reparam.default import ReparamTransforms
from sphere3d.reparam.lobe import KAPPA_CAP, lobe_kappa, lobe_radius
from sphere3d.reparam.probes import ring_directions, vmf_spread_angle
from sphere3d.sampling import sample_vmf
from sphere3d.scene import load_scene
from sphere3d.state import build_state
from sphere3d.tasks import ImageTask
from tests.tiers import SLOW

ALPHA = 1e-3
BATCHES = 16
N = 1 << 16
PARAM = "occluder.translate.x"
CAMERA = np.array([0.6, -3.6, 2.6])
ROUGHNESS = 0.02
GAP = 0.1
H = 1e-3


def _scene(roughness: float = ROUGHNESS, gap: float = GAP):
    """``glossy_reflection``'s floor (roughness α, F = 1) and occluder (radius 0.3 about x = 0.1) under a
    uniform sky of radiance 1, no light, and a static box whose face x = 0.4 + ``gap`` faces the sphere."""
    d = load_scene("glossy_reflection").to_dict()
    x0 = 0.4 + gap
    box = {"name": "wall", "type": "box", "size": [0.4, 0.6, 1.2], "translate": [x0 + 0.2, 0.0, 0.6]}
    d["sky"] = 1.0
    d["shapes"] = [
        dict(d["shapes"][0], roughness=roughness, albedo=1.0),
        d["shapes"][2],
        dict(box, albedo=0.5),
    ]
    return load_scene(d)


def _mirror_point(x: float) -> np.ndarray:
    """The floor point whose mirror direction from the camera meets (x, 0, 0.8) (the sphere's height)."""
    image = np.array([x, 0.0, -0.8])  # the target mirrored about z = 0
    t = CAMERA[2] / (CAMERA[2] - image[2])
    return CAMERA + t * (image - CAMERA)


def _lobe(n: int, alpha: float, cos_i: float) -> Lobe:
    wi = np.broadcast_to([np.sqrt(1.0 - cos_i * cos_i), 0.0, cos_i], (n, 3)).copy()
    normal = np.broadcast_to([0.0, 0.0, 1.0], (n, 3)).copy()
    return Lobe(wi, normal, np.full(n, alpha), np.ones(n))


def test01_the_per_point_kappa_is_the_users_at_diffuse_points_and_follows_the_rule_at_glossy_ones():
    transforms = ReparamTransforms()  # kappa 1000, spread 3, lobe 1
    rows = np.arange(4)
    # diffuse points (no lobe) and the option off: the user's κ itself, one float (the scalar code path)
    assert transforms.kernel_kappa(None, rows) == 1000.0 and np.ndim(transforms.kernel_kappa(None, rows)) == 0
    narrow = _lobe(4, 0.02, 0.7)
    assert ReparamTransforms(lobe=None).kernel_kappa(narrow, rows) == 1000.0
    # a wide lobe (α = 0.5): the ring of κ = 1000 (0.095 rad) is well inside it, the user's κ stays
    wide = transforms.kernel_kappa(_lobe(4, 0.5, 0.7), rows)
    np.testing.assert_array_equal(wide, np.full(4, 1000.0))
    # a narrow one: the ring lies at λ r_l, r_l = 2 atan(α) cos θ_i, for λ = 1 and 0.5
    for fraction in (1.0, 0.5):
        kappa = ReparamTransforms(lobe=fraction).kernel_kappa(narrow, rows)
        r = fraction * 2.0 * np.arctan(0.02) * 0.7
        np.testing.assert_allclose(kappa, 9.0 / (2.0 * (1.0 - np.cos(r))), rtol=1e-12)
        assert np.all(kappa > 1000.0)
        np.testing.assert_allclose(vmf_spread_angle(kappa, 3.0), r, rtol=1e-9)
    # per row: the rule row by row, the lower bound where the lobe is wide
    cos_i = np.array([1.0, 0.5, 0.1, 0.9])
    alpha = np.array([0.01, 0.05, 0.3, 0.8])
    wi = np.stack([np.sqrt(1.0 - cos_i**2), 0.0 * cos_i, cos_i], axis=1)
    lobe = Lobe(wi, np.tile([0.0, 0.0, 1.0], (4, 1)), alpha, np.ones(4))
    radius = lobe_radius(lobe.wi, lobe.n, lobe.alpha)
    np.testing.assert_allclose(radius, 2.0 * np.arctan(alpha) * cos_i, rtol=1e-15)
    expected = np.maximum(1000.0, 9.0 / (2.0 * (1.0 - np.cos(radius))))
    np.testing.assert_allclose(transforms.kernel_kappa(lobe, rows), expected, rtol=1e-12)
    # grazing incidence or no lobe: capped at the largest concentration float64 resolves
    assert KAPPA_CAP == KAPPA_MAX
    np.testing.assert_array_equal(
        lobe_kappa(1000.0, 3.0, 1.0, np.array([0.0, 1e-12])), [KAPPA_MAX, KAPPA_MAX]
    )
    np.testing.assert_array_equal(lobe_kappa(1000.0, 0.0, 1.0, np.array([0.01])), [1000.0])  # no ring
    # the option: a fraction > 0 or None, one error naming it; the paper variant has no such option
    for bad in (0.0, -1.0, float("nan"), "wide"):
        with pytest.raises(ValidationError) as err:
            render_gradient("hard_shadow", PARAM, "reparam", spp=1, lobe=bad)
        assert err.value.field == "lobe"
    with pytest.raises(ValidationError) as err:
        render_gradient("hard_shadow", PARAM, "reparam", spp=1, variant="paper", lobe=0.5)
    assert err.value.field == "lobe"


@pytest.mark.parametrize("alpha", [0.02, 0.15])
def test02_the_lobe_radius_is_the_median_deviation_of_the_reflection_at_normal_incidence(alpha):
    """At normal incidence the visible normals are GGX's projected normals, whose slope has median α, and
    the reflection deviates from the normal by twice the tilt: half of :func:`~sphere3d.bsdf.sample_ggx`'s
    directions lie within $r_l = 2 \arctan α$ (binomial standard error of the fraction, normal
    quantile, Šidák over the two α)."""
    n = 1 << 16
    normal = np.array([0.0, 0.0, 1.0])
    wo = sample_ggx(np.random.default_rng(5).random((n, 2)), np.tile(normal, (n, 1)), normal, alpha)
    radius = lobe_radius(np.tile(normal, (1, 1)), np.tile(normal, (1, 1)), np.array([alpha]))[0]
    inside = np.mean(np.arccos(np.clip(wo[:, 2], -1.0, 1.0)) <= radius)
    assert abs(inside - 0.5) <= family_quantile(2, 1.0 - ALPHA) * np.sqrt(0.25 / n), (alpha, inside)


def test03_per_row_concentrations_are_the_scalar_functions_row_by_row():
    kappa = np.array([1.0, 30.0, 1000.0, 5e4, 1e8, KAPPA_MAX])
    u = np.random.default_rng(1).random((kappa.size, 2))
    mu = np.random.default_rng(2).normal(size=(kappa.size, 3))
    mu /= np.linalg.norm(mu, axis=1)[:, None]
    rows = sample_vmf(u, mu, kappa)
    one_by_one = np.concatenate(
        [sample_vmf(u[i : i + 1], mu[i : i + 1], float(k)) for i, k in enumerate(kappa)]
    )
    np.testing.assert_allclose(rows, one_by_one, rtol=0.0, atol=1e-15)
    for spread in (0.0, 1.0, 3.0, 9.0):
        scalar = [vmf_spread_angle(float(k), spread) for k in kappa]
        np.testing.assert_allclose(vmf_spread_angle(kappa, spread), scalar, rtol=1e-14, atol=1e-300)
    angle = vmf_spread_angle(kappa, 3.0)
    phase = np.random.default_rng(3).random(kappa.size)
    ring = ring_directions(mu, angle, 7, phase)
    for i in range(kappa.size):
        one = ring_directions(mu[i : i + 1], float(angle[i]), 7, phase[i : i + 1])[0]
        np.testing.assert_allclose(ring[i], one, rtol=0.0, atol=1e-15)
    with pytest.raises(ValidationError) as err:
        sample_vmf(u, mu, np.where(kappa > 1e3, -1.0, kappa))
    assert err.value.field == "kappa"


@pytest.mark.parametrize("depth", [1, 2])
def test04_diffuse_scenes_are_bit_identical_with_and_without_the_rule(depth):
    d = load_scene("hard_shadow").to_dict()
    d["camera"].update(width=16, height=16)
    digests = set()
    for lobe in (1.0, None, 0.25):
        r = render_gradient(d, PARAM, "reparam", spp=4, seed=2, max_depth=depth, lobe=lobe)
        digests.add(
            hashlib.sha256(np.asarray(r.value).tobytes() + np.asarray(r.derivative).tobytes()).digest()
        )
        assert np.any(np.asarray(r.derivative) != 0.0)
    assert len(digests) == 1


def _samples(state, x: np.ndarray, seed: int, transforms=None):
    """``glossy_samples`` at N copies of the floor point x seen from the camera: the radiance per sample."""
    points = np.broadcast_to(x, (N, 3)).copy()
    normal = np.broadcast_to([0.0, 0.0, 1.0], (N, 3)).copy()
    wi = CAMERA - x
    wi = np.broadcast_to(wi / np.linalg.norm(wi), (N, 3)).copy()
    shading = Shading.at(state, points, normal, Draws.of(seed, np.arange(N)))
    u = np.random.default_rng(seed).random((N, 5))
    return glossy_samples(shading, wi, u, np.full(N, ROUGHNESS), np.ones(N), transforms).radiance


def _batches(values: np.ndarray) -> tuple[float, float]:
    per_batch = np.asarray(values, dtype=np.float64).reshape(BATCHES, -1).mean(axis=1)
    return float(per_batch.mean()), float(per_batch.std(ddof=1) / np.sqrt(BATCHES))


@functools.cache
def _point_derivatives(x: float) -> dict[str, tuple[float, float]]:
    """d L_r / dθ at the floor point mirroring (x, 0, 0.8): the fixed kernel, the lobe-following one and
    the central difference (common random numbers), mean and standard error over 16 batches."""
    scene, point = _scene(), _mirror_point(x)
    dual = build_state(scene, PARAM, variable(0.0))
    out = {}
    for name, transforms in (("fixed", ReparamTransforms(lobe=None)), ("lobe", ReparamTransforms())):
        out[name] = _batches(tangent(_samples(dual, point, 3, transforms)))
    plus = np.asarray(_samples(build_state(scene, PARAM, H), point, 4))
    minus = np.asarray(_samples(build_state(scene, PARAM, -H), point, 4))
    out["finite_difference"] = _batches((plus - minus) / (2.0 * H))
    return out


POINTS = (0.40, 0.48)
"""Mirror directions through the sphere's edge (x = 0.4) and through the box beside the gap (x = 0.48)."""


def test05_the_fixed_kernel_is_biased_where_the_lobe_is_narrower_than_its_ring():
    q = family_quantile(len(POINTS), 1.0 - ALPHA, dof=BATCHES - 1)
    for x in POINTS:
        d = _point_derivatives(x)
        (fixed, se_f), (fd, se_fd) = d["fixed"], d["finite_difference"]
        assert se_f > 0.0 and se_fd > 0.0 and abs(fd) > q * se_fd  # the reference sees the motion
        assert abs(fixed - fd) > q * np.hypot(se_f, se_fd), (x, fixed, fd, se_f, se_fd)


def test06_the_lobe_following_kernel_agrees_with_finite_differences():
    q = family_quantile(len(POINTS), 1.0 - ALPHA, dof=BATCHES - 1)
    for x in POINTS:
        d = _point_derivatives(x)
        (lobe, se_l), (fd, se_fd) = d["lobe"], d["finite_difference"]
        assert se_l > 0.0
        assert abs(lobe - fd) <= q * np.hypot(se_l, se_fd), (x, lobe, fd, se_l, se_fd)


@SLOW
def test07_region_sums_of_the_rendered_glossy_floor():
    """The floor pixels (their 3 x 3 neighbourhood all floor: not the film's own silhouettes) whose mirror
    ray passes within 0.15 of the gap's centre: fixed kernel biased, lobe-following kernel within noise
    of finite differences, Šidák over the 2 comparisons."""
    from scipy import ndimage

    from benchmarks.bench_glossy import _primary

    width = 32
    d = _scene().to_dict()
    d["camera"].update(width=width, height=width)
    scene = load_scene(d)
    direction, shape, point = _primary(scene, width)
    mirror = direction * np.array([1.0, 1.0, -1.0])
    to = np.array([0.4 + 0.5 * GAP, 0.0, 0.8]) - point
    miss = np.linalg.norm(to - np.sum(to * mirror, axis=1)[:, None] * mirror, axis=1)
    floor = ndimage.binary_erosion((shape == 0).reshape(width, width), np.ones((3, 3)))
    region = floor & (miss < 0.15).reshape(width, width)
    assert region.sum() >= 8
    sums = {}
    for key, method, seed, options in (
        ("fixed", "reparam", 1, {"lobe": None}),
        ("lobe", "reparam", 1, {}),
        ("finite_difference", "finite_difference", 2, {}),
    ):
        g = GRADIENT_METHODS.run(method, ImageTask(scene, PARAM, 1024, seed, BATCHES), **options).derivative
        sums[key] = _batches(g[:, region].sum(axis=1))
    q = family_quantile(2, 1.0 - ALPHA, dof=BATCHES - 1)
    (fd, se_fd) = sums["finite_difference"]
    assert abs(fd) > q * se_fd
    assert abs(sums["fixed"][0] - fd) > q * np.hypot(sums["fixed"][1], se_fd), sums
    assert abs(sums["lobe"][0] - fd) <= q * np.hypot(sums["lobe"][1], se_fd), sums
