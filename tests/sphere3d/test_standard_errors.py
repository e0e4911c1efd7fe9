"""Honest standard errors: sphere3d ``boundary``'s per-pixel z-scores follow their law over many seeds.

A method's standard error is the spread of its independent batches; if something is shared between
the batches (the same stratification, the same keyed draws), the spread understates the error and
single pixels sit tens of standard errors off while the image sums look right. The test renders the
closed-form triangle image (:func:`sphere3d.closed_form.triangle_image`) for SEEDS seeds and checks,
per motion:

1. the number of pixel z-scores beyond 3 is inside its two-sided binomial interval, p = P(|t15| > 3)
   (16 batches: Student t with 15 degrees of freedom), Šidák over the motions at α = 1e-3;
2. in every seed, every pixel's |z| is below the t15 quantile at the Šidák level over all pixels of
   all seeds and motions (the defect this guards against had single pixels at |z| 20-47).

Pixels whose exact derivative is below 1 % of the image's largest are left out: they lie at the
filter's tail, where a batch's estimate comes from the one or two edge points that fall in a sliver
of the support, a sum of rare events far from normal (its t statistic has heavier tails than t15,
while at a high rate of edge points, where the tail pixels receive many, they are within their
intervals too: test03).

The same two claims beside a T-junction on the film (test04), where a jump of the integrand along an
edge once made whole seeds' spreads miss its share. Claim 1 for ``reparam`` and ``boundary`` against
their own expectation, each seed against the others' mean (test05: honest errors whatever the bias);
``finite_difference``'s z-scores have significantly heavier tails than the law at this sample count
(test06: each batch's difference is a sum of rare samples in the strip an edge sweeps); ``naive``'s
derivative of this image is 0 in every sample (a black triangle: no interior term), no spread to test.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from scipy import stats

import sphere3d as s3
from flatland.core.dual import variable
from flatland.core.stats import sidak
from sphere3d import closed_form as cf
from sphere3d.boundary.camera import camera_edge_term
from sphere3d.boundary.edges import mesh_edges
from sphere3d.methods import GRADIENT_METHODS
from sphere3d.methods.boundary import RATE
from sphere3d.state import build_state
from sphere3d.tasks import ImageTask
from tests.tiers import SLOW, sweep

ALPHA = 1e-3
BATCHES = 16
SEEDS = 24
MOTIONS = ["tri.translate.x", "tri.rotate.z"]
SCENE = cf.pinhole_triangle_scene(12.0, width=16, filter="gaussian")
P_BEYOND_3 = 2.0 * stats.t.sf(3.0, BATCHES - 1)


@functools.cache
def _z_scores(param: str) -> tuple[np.ndarray, ...]:
    """Per seed, the z-scores of the tested pixels (module docstring)."""
    scene = s3.load_scene(SCENE)
    exact = cf.triangle_image(SCENE, param).derivative
    tested = np.abs(exact) >= 0.01 * np.abs(exact).max()
    out = []
    for seed in range(SEEDS):
        d = GRADIENT_METHODS.run("boundary", ImageTask(scene, param, 64, 100 + seed, BATCHES)).derivative
        mean, stderr = d.mean(axis=0), d.std(axis=0, ddof=1) / np.sqrt(BATCHES)
        assert np.all(stderr[tested] > 0.0)
        out.append(((mean - exact) / np.where(tested, stderr, 1.0))[tested])
    return tuple(out)


@SLOW
@pytest.mark.parametrize("param", MOTIONS)
def test01_the_share_beyond_3_is_inside_its_binomial_interval(param):
    z = np.concatenate(_z_scores(param))
    beyond = int(np.count_nonzero(np.abs(z) > 3.0))
    level = sidak(ALPHA, len(MOTIONS))
    lo, hi = stats.binom.ppf([0.5 * level, 1.0 - 0.5 * level], z.size, P_BEYOND_3)
    expected = P_BEYOND_3 * z.size
    print(f"{param}: {beyond} of {z.size} beyond 3, expected {expected:.1f}, interval [{lo:g}, {hi:g}]")
    assert lo <= beyond <= hi


@SLOW
@pytest.mark.parametrize("param", MOTIONS)
def test02_no_pixel_of_any_seed_is_far_off(param):
    per_seed = _z_scores(param)
    m = sum(z.size for z in per_seed) * len(MOTIONS)
    q = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, m), BATCHES - 1)
    worst = [float(np.abs(z).max()) for z in per_seed]
    assert max(worst) <= q, (max(worst), q)


@SLOW
def test03_the_tail_pixels_converge_to_the_closed_form_as_the_rate_grows():
    """The pixels left out above are not biased: at 4 000 edge points per pixel of edge length, where
    each of them receives many points, the three tail pixels below the triangle's lowest vertex
    (derivatives below 1e-6 of the image's largest) are within their Student-t intervals of 8 batches
    (Šidák over the 3 pixels), and so is every tested pixel of the image."""
    scene = s3.load_scene(SCENE)
    param = "tri.translate.x"
    state, plain = build_state(scene, param, variable(0.0)), build_state(scene, param, 0.0)
    edges = mesh_edges(plain.triangles, plain.shape_of)
    exact = cf.triangle_image(SCENE, param).derivative
    d = np.array([camera_edge_term(state, plain, edges, 1, b, 4000.0) for b in range(8)])
    mean, stderr = d.mean(axis=0), d.std(axis=0, ddof=1) / np.sqrt(len(d))
    tail = (14, slice(12, 15))
    assert np.all(np.abs(exact[tail]) < 1e-6 * np.abs(exact).max())
    q = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, 3), len(d) - 1)
    assert np.all(np.abs(mean[tail] - exact[tail]) <= q * stderr[tail])
    tested = np.abs(exact) >= 0.01 * np.abs(exact).max()
    q = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, int(tested.sum())), len(d) - 1)
    assert np.all(np.abs(mean - exact)[tested] <= q * stderr[tested])


JUNCTION_MOTIONS = ["tri.translate.x", "tri.translate.z"]


@functools.cache
def _junction_z_scores(param: str) -> np.ndarray:
    """Per seed (rows), the z-scores of the film term's tested pixels beside a T-junction, at the rate
    of 2 048 spp in 16 batches (the film term alone: the interior term is 0 for black triangles)."""
    scene = cf.junction_scene()
    loaded = s3.load_scene(scene)
    state, plain = build_state(loaded, param, variable(0.0)), build_state(loaded, param, 0.0)
    edges = mesh_edges(plain.triangles, plain.shape_of)
    exact = cf.junction_image(scene, param).derivative
    tested = np.abs(exact) >= 0.01 * np.abs(exact).max()
    rows = []
    for seed in range(SEEDS):
        rate = RATE * 2048 / BATCHES
        d = np.array([camera_edge_term(state, plain, edges, 100 + seed, b, rate) for b in range(BATCHES)])
        mean, stderr = d.mean(axis=0), d.std(axis=0, ddof=1) / np.sqrt(BATCHES)
        rows.append(((mean - exact) / np.where(tested, stderr, 1.0))[tested])
    return np.array(rows)


@pytest.mark.parametrize("param", sweep(JUNCTION_MOTIONS, ["tri.translate.x"]))
def test04_beside_a_t_junction_the_law_holds_in_every_seed(param):
    """Where the moving triangle's edge passes in front of a static one's (the film image of
    :func:`~sphere3d.closed_form.junction_scene`), the integrand along the moving edge jumps. With
    the same strata in every batch, a jump near a stratum's end is crossed with one small
    probability in every batch, and in the seeds where no batch crosses it the spread misses its
    share: single pixels sat tens of standard errors off. The strata's rotation per batch and edge
    (:mod:`sphere3d.boundary.camera`) puts the jump anywhere in its stratum: claims 1 and 2 of the
    module docstring, at a rate where each batch draws 256 points per pixel of edge length."""
    z = _junction_z_scores(param)
    beyond = int(np.count_nonzero(np.abs(z) > 3.0))
    level = sidak(ALPHA, 2 * len(JUNCTION_MOTIONS))
    lo, hi = stats.binom.ppf([0.5 * level, 1.0 - 0.5 * level], z.size, P_BEYOND_3)
    q = stats.t.ppf(1.0 - 0.5 * sidak(level, z.size), BATCHES - 1)
    print(
        f"{param}: {beyond} of {z.size} beyond 3 in [{lo:g}, {hi:g}];"
        f" max |z| {np.abs(z).max():.2f} <= {q:.2f}?"
    )
    assert lo <= beyond <= hi
    assert np.abs(z).max() <= q


HONEST_METHODS = ["reparam", "boundary"]


@functools.cache
def _loo_z_scores(param: str, method: str) -> np.ndarray:
    """Per seed (rows) and tested pixel with spread in every seed, the z-score of the seed's mean
    against the mean of the other SEEDS - 1 seeds, over their combined standard errors: the law of
    claim 1 whatever the method's bias (the method's own expectation is the reference)."""
    scene = s3.load_scene(SCENE)
    exact = cf.triangle_image(SCENE, param).derivative
    tested = np.abs(exact) >= 0.01 * np.abs(exact).max()
    means, errors = [], []
    for seed in range(SEEDS):
        d = GRADIENT_METHODS.run(method, ImageTask(scene, param, 64, 100 + seed, BATCHES)).derivative
        means.append(d.mean(axis=0)[tested])
        errors.append(d.std(axis=0, ddof=1)[tested] / np.sqrt(BATCHES))
    m, se = np.array(means), np.array(errors)
    live = np.all(se > 0.0, axis=0)
    rows = []
    for s in range(SEEDS):
        others = np.arange(SEEDS) != s
        ref, ref_se = m[others].mean(axis=0), np.sqrt(np.sum(se[others] ** 2, axis=0)) / (SEEDS - 1)
        rows.append(((m[s] - ref) / np.sqrt(se[s] ** 2 + ref_se**2))[live])
    return np.array(rows)


@pytest.mark.parametrize(
    ("param", "method"),
    sweep(
        [(p, m) for p in MOTIONS for m in HONEST_METHODS],
        [("tri.translate.x", "reparam"), ("tri.translate.x", "boundary")],
    ),
)
def test05_every_method_s_standard_error_covers_its_own_spread(param, method):
    """Claim 1 for ``reparam`` and ``boundary`` against their own expectation (a seed against the
    others' mean): a biased method's errors must still be honest. The share beyond 3 within its
    two-sided binomial interval (Šidák over the motions and methods)."""
    z = _loo_z_scores(param, method)
    beyond = int(np.count_nonzero(np.abs(z) > 3.0))
    level = sidak(ALPHA, len(MOTIONS) * 2)
    lo, hi = stats.binom.ppf([0.5 * level, 1.0 - 0.5 * level], z.size, P_BEYOND_3)
    print(f"{param} {method}: {beyond} of {z.size} beyond 3 in [{lo:g}, {hi:g}]")
    assert lo <= beyond <= hi


@pytest.mark.parametrize("param", sweep(MOTIONS, ["tri.translate.x"]))
def test06_finite_differences_errors_have_heavier_tails_than_the_law(param):
    """``finite_difference``'s batches are independent too, but at a pixel an edge moves across, a
    batch's difference (I(θ + h) - I(θ - h)) / 2h is nonzero only for the few samples in the strip
    the edge sweeps (about 2h |v| pixels wide): a sum of rare events, far from normal, so its
    z-scores exceed 3 significantly more often than Student's t says (one-sided binomial test),
    whatever the seed count: its error bars are not reliable per pixel at this sample count."""
    z = _loo_z_scores(param, "finite_difference")
    beyond = int(np.count_nonzero(np.abs(z) > 3.0))
    level = sidak(ALPHA, len(MOTIONS))
    hi = stats.binom.ppf(1.0 - level, z.size, P_BEYOND_3)
    print(f"{param} finite_difference: {beyond} of {z.size} beyond 3 > {hi:g}")
    assert beyond > hi
