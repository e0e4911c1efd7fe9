r"""``reparam``'s direction kernel at glossy points follows the lobe's width (:mod:`flatland.reparam.lobe`).

1. The rule, as a function: the per-row κ is the user's ``kappa`` on diffuse rows, with ``lobe`` None
   and where every lobe is wide (one float: the scalar code path); on glossy rows of a narrow lobe
   $κ_x = (\mathrm{spread} / (λ r_l))^2$, $r_l = 2 \arctan(α / \sqrt 3)$, which puts the outermost
   probe at exactly λ $r_l$; the option checked (one error naming ``lobe``).
2. $r_l$ is the median deviation of the GGX reflection at normal incidence (sampled by
   :func:`~flatland.bsdf.sample_ggx`: the slopes' median is $α / \sqrt 3$).
3. The von Mises sampler with a κ per row is the scalar sampler applied row by row.
4. Diffuse scenes do not change: ``shadow`` with ``lobe`` 1, None and 0.25, bit for bit.
5. The problem and the fix: a floor of roughness α = 0.02 (lobe radius 0.023 rad) under a uniform sky
   reflects a moving segment beside a static one, 0.25 apart (about 0.05 rad from the floor, inside
   the default kernel's probe span of ±3/√1000 = ±0.095 rad): the derivative in the moving segment's
   x-translation, summed over the pixels whose mirror ray passes within 0.3 of the gap's centre,
   against finite differences (h = 0.01, 4 x the samples): the fixed kernel (``lobe=None``) is biased
   by many standard errors (its probes see both segments' ends, and it follows the moving one where
   the lobe sees the static one), the lobe-following kernel agrees within noise.

Tolerances: the per-pixel standard errors of 16 batches summed in quadrature over the region (flatland's
samples stay in their pixel), normal quantiles at ALPHA = 1e-3, Šidák over each test's comparisons.
"""

from __future__ import annotations

import functools
import hashlib

import numpy as np
import pytest

from flatland.bsdf import sample_ggx
from flatland.core.stats import family_quantile
from flatland.core.validate import ValidationError
from flatland.glossy import Lobe
from flatland.render import render_gradient
from flatland.reparam.default import ReparamTransforms
from flatland.reparam.lobe import lobe_kappa, lobe_radius
from flatland.sampling import sample_von_mises
from flatland.scene import load_scene
from flatland.state import build_state
from flatland.tracing import cast, film_direction

ALPHA = 1e-3
BATCHES = 16
PARAM = "occluder.translate.x"
GAP = 0.25
GAP_CENTRE = np.array([2.3 + 0.5 * GAP, 1.6])


def _transforms(lobe: float | None = 1.0) -> ReparamTransforms:
    return ReparamTransforms(1000.0, 10.0, 4, 3.0, 2, False, lobe)


def test01_the_per_row_kappa_is_the_users_on_diffuse_rows_and_follows_the_rule_on_glossy_ones():
    glossy = np.array([True, False, True, True])
    alpha = np.array([0.02, 1.0, 0.05, 0.6])
    lobe = Lobe(glossy, np.zeros(4), alpha, np.ones(4))
    assert _transforms().kernel_kappa(None) == 1000.0
    assert _transforms(None).kernel_kappa(lobe) == 1000.0
    wide = Lobe(glossy, np.zeros(4), np.full(4, 0.6), np.ones(4))
    assert np.ndim(_transforms().kernel_kappa(wide)) == 0  # every lobe wide: one float, the scalar path
    for fraction in (1.0, 0.5):
        kappa = _transforms(fraction).kernel_kappa(lobe)
        r = 2.0 * np.arctan(alpha / np.sqrt(3.0))
        expected = np.where(glossy, np.maximum(1000.0, (3.0 / (fraction * r)) ** 2), 1000.0)
        np.testing.assert_allclose(kappa, expected, rtol=1e-14)
        assert kappa[0] > 1000.0 and kappa[1] == 1000.0 and kappa[3] == 1000.0  # narrow, diffuse, wide
        np.testing.assert_allclose(3.0 / np.sqrt(kappa[0]), fraction * r[0], rtol=1e-14)  # outermost probe
    np.testing.assert_allclose(lobe_radius(alpha), 2.0 * np.arctan(alpha / np.sqrt(3.0)), rtol=1e-15)
    np.testing.assert_array_equal(lobe_kappa(1000.0, 0.0, 1.0, np.array([0.01]), np.array([True])), [1000.0])
    for bad in (0.0, -0.5, float("inf"), "wide"):
        with pytest.raises(ValidationError) as err:
            render_gradient("shadow", PARAM, "reparam", spp=1, progress=False, lobe=bad)
        assert err.value.field == "lobe"


@pytest.mark.parametrize("alpha", [0.02, 0.2])
def test02_the_lobe_radius_is_the_median_deviation_of_the_reflection_at_normal_incidence(alpha):
    n = 1 << 16
    b = sample_ggx(np.random.default_rng(4).random(n), np.zeros(n), 0.0, alpha)
    inside = np.mean(np.abs(b) <= lobe_radius(alpha))
    assert abs(inside - 0.5) <= family_quantile(2, 1.0 - ALPHA) * np.sqrt(0.25 / n), (alpha, inside)


def test03_a_kappa_per_row_samples_as_the_scalar_sampler_row_by_row():
    kappa = np.array([1000.0, 20.0, 1000.0, 5e5, 20.0])
    u = np.random.default_rng(6).random((kappa.size, 2))
    mu = np.linspace(-1.0, 1.0, kappa.size)
    rows = sample_von_mises(u, mu[:, None], kappa)
    for i, k in enumerate(kappa):
        np.testing.assert_array_equal(rows[i], sample_von_mises(u[i], mu[i], float(k)))
    with pytest.raises(ValidationError) as err:
        sample_von_mises(u, mu[:, None], kappa[:3])
    assert err.value.field == "kappa"


def test04_diffuse_scenes_are_bit_identical_with_and_without_the_rule():
    digests = set()
    for lobe in (1.0, None, 0.25):
        g = render_gradient("shadow", PARAM, "reparam", spp=16, seed=2, progress=False, lobe=lobe)
        assert np.any(g.derivative != 0.0)
        digests.add(
            hashlib.sha256(np.asarray(g.value).tobytes() + np.asarray(g.derivative).tobytes()).digest()
        )
    assert len(digests) == 1


def _scene():
    """``glossy_reflection``'s camera and floor (roughness 0.02, F = 1) under a uniform sky of radiance 1, its
    occluder (a segment from x = 1.8 to 2.3 at height 1.6) and a static segment of the same height
    ``GAP`` to its right; no light."""
    d = load_scene("glossy_reflection").to_dict()
    floor, occluder = (next(s for s in d["shapes"] if s["name"] == name) for name in ("floor", "occluder"))
    wall = {"name": "wall", "type": "segment", "points": [[2.3 + GAP, 1.6], [2.8 + GAP, 1.6]], "albedo": 0.5}
    d.update(sky=1.0, shapes=[dict(floor, roughness=0.02, albedo=1.0), occluder, wall], parameters=[PARAM])
    return load_scene(d).with_camera(pixels=64)


def _gap_pixels(scene) -> np.ndarray:
    """Pixels whose centre's primary ray meets the floor and whose mirror ray passes within 0.3 of the gap's
    centre."""
    geom = build_state(scene)
    d = film_direction(geom, scene.camera.pixel_centers())
    origin = np.broadcast_to(np.asarray(geom.cam_o, dtype=np.float64), d.shape)
    hits = cast(geom, origin, d)
    floor = hits.prim == 0
    point = origin + np.where(floor, hits.dist, 0.0)[:, None] * d
    mirror = d * np.array([1.0, -1.0])
    to = GAP_CENTRE - point
    along = np.sum(to * mirror, axis=1)
    miss = np.abs(to[:, 0] * mirror[:, 1] - to[:, 1] * mirror[:, 0])
    return floor & (along > 0.0) & (miss < 0.3)


@functools.cache
def _region_sums() -> dict[str, tuple[float, float]]:
    scene = _scene()
    region = _gap_pixels(scene)
    assert region.sum() >= 4
    args = {"seed": 7, "batches": BATCHES, "progress": False}
    out = {}
    for name, method, spp, options in (
        ("fixed", "reparam", 8192, {"lobe": None}),
        ("lobe", "reparam", 8192, {}),
        ("finite_difference", "finite_difference", 1 << 15, {"h": 0.01}),
    ):
        g = render_gradient(scene, PARAM, method, spp=spp, **args, **options)
        out[name] = (
            float(np.sum(g.derivative[region])),
            float(np.sqrt(np.sum(g.derivative_stderr[region] ** 2))),
        )
    return out


def test05_the_fixed_kernel_is_biased_where_the_lobe_is_narrower_than_its_probes():
    sums = _region_sums()
    (fixed, se_f), (fd, se_fd) = sums["fixed"], sums["finite_difference"]
    q = family_quantile(1, 1.0 - ALPHA)
    assert se_f > 0.0 and abs(fd) > q * se_fd  # the reference resolves the region's derivative
    assert abs(fixed - fd) > q * np.hypot(se_f, se_fd), sums


def test06_the_lobe_following_kernel_agrees_with_finite_differences():
    sums = _region_sums()
    (lobe, se_l), (fd, se_fd) = sums["lobe"], sums["finite_difference"]
    assert se_l > 0.0
    assert abs(lobe - fd) <= family_quantile(1, 1.0 - ALPHA) * np.hypot(se_l, se_fd), sums
