"""The control variate of the cosine strategy's kernel weights (``Members.baseline``, sphere3d.integrator).

Given the kernel's centre ω, the rotation ``R`` of the reparam estimator depends on ω only, so
$∫ p(Rμ) k(Rμ, ω) dμ = ∫ p(y) k(y, ω) dy$ whatever θ: the tangent of $q = p(Rμ) w$ has zero mean
given ω, and $c(ω) \\dot q / p(μ)$ may be subtracted from each sample's derivative with any $c(ω)$
fixed before θ moves. ``ReparamTransforms`` takes $c(ω) = π L(ω)$, the sky's radiance where the
kernel centre's probe sees it: the integrand $L \\cos$ then differs from $c\\, p$ only where the
sample sees something else than the centre, and the noise of the weights' derivative over the sky
cancels. Predicted and checked here, on a black triangle under a constant sky:

1. the value does not change (bit for bit): the variate's value is 0;
2. it has zero mean: the per-batch difference of the derivative with and without it (same samples)
   is within its Student-t quantile of 0, on a triangle whose kernels hold the whole triangle
   (0.1 rad) and on a large one (0.5 rad), for a translation and a scaling. A variate restricted to
   the samples whose integrand is nonzero fails this (its mean is the derivative of what the
   skipped samples carry);
3. it lowers the variance: the derivative's batch variance with it is below the one without,
   one-sided F test.

Batches are independent (64 per estimate, fixed seeds); the quantiles are Šidák-corrected over the
module's tests at family-wise α = 0.01.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import sphere3d as s3
from flatland.core.dual import variable
from sphere3d.closed_form import sky_triangle_scene
from sphere3d.reparam.default import ReparamTransforms
from sphere3d.tasks import PointTask

BATCHES, N = 64, 1 << 17
CASES = [(0.1, "tri.translate.x"), (0.1, "tri.scale"), (0.5, "tri.translate.x"), (0.5, "tri.scale")]
TESTS = 2 * len(CASES)
ALPHA = 1.0 - (1.0 - 0.01) ** (1.0 / TESTS)
ORIGIN, NORMAL = (0.0, 0.0, 0.0), (0.5, 0.0, np.sqrt(0.75))  # the normal 30 degrees off the zenith


def _scene(size: float) -> dict:
    """A black equilateral triangle ``size`` radians across, face-on, at distance 1 straight above."""
    angles = 2.0 * np.pi * np.arange(3) / 3.0
    r = np.tan(0.5 * size) / np.cos(np.pi / 6.0)  # side length about tan(size / 2) * 2
    return sky_triangle_scene(np.stack([r * np.cos(angles), r * np.sin(angles), np.ones(3)], axis=1))


def _tallies(size: float, param: str):
    scene = s3.load_scene(_scene(size))
    out = []
    for baseline in (True, False):
        task = PointTask(scene, param, ORIGIN, NORMAL, N, 11, BATCHES)
        out.append(task.evaluate(variable(0.0), ReparamTransforms(baseline=baseline)))
    return out


@pytest.fixture(scope="module", params=CASES, ids=lambda c: f"{c[0]}rad-{c[1]}")
def tallies(request):
    return _tallies(*request.param)


def test01_the_value_does_not_change(tallies):
    with_cv, without = tallies
    assert np.array_equal(with_cv.value, without.value)


def test02_the_control_variate_has_zero_mean(tallies):
    with_cv, without = tallies
    diff = np.asarray(with_cv.derivative) - np.asarray(without.derivative)
    assert np.any(diff != 0.0)
    se = diff.std(ddof=1) / np.sqrt(BATCHES)
    q = stats.t.ppf(1.0 - 0.5 * ALPHA, BATCHES - 1)
    assert abs(diff.mean()) <= q * se


def test03_the_control_variate_lowers_the_variance(tallies):
    with_cv, without = tallies
    var_with = np.var(np.asarray(with_cv.derivative), ddof=1)
    var_without = np.var(np.asarray(without.derivative), ddof=1)
    f = stats.f.ppf(1.0 - ALPHA, BATCHES - 1, BATCHES - 1)
    assert var_without > f * var_with  # one-sided F test: the variance falls
