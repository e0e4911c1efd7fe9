"""The bias floor's excess and its error (:func:`benchmarks.bench_hard_shadow.bias_excess`).

On synthetic images whose noise is correlated between neighbouring pixels (as the splat film's),
with a reference that has its own noise: the excess estimates the mean squared bias without bias,
and its jackknife standard error (over the seeds) covers its spread from noise alone. Checked
against the known bias b (none, a smooth field, and a few pixels carrying all of it, as a cube's
corners do): |excess - mean(b²)| <= q · stderr in every one of R independent repetitions, q the
two-sided Student-t quantile (S - 1 degrees of freedom) at family-wise 0.01 (Šidák over the
repetitions and cases), and the standard error agrees with the excess's spread over the
repetitions (a two-sided chi-square test of the variance ratio at the same level). The jackknife
variance of this quadratic statistic errs on the large side (Efron and Stein): the bounds built on
it are conservative.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage, stats

from benchmarks.bench_hard_shadow import bias_excess

SEEDS, SIZE, R = 8, 64, 40
CASES = ("none", "field", "corners")
LEVEL = 1.0 - (1.0 - 0.01) ** (1.0 / (2 * R * len(CASES)))
Q = stats.t.ppf(1.0 - 0.5 * LEVEL, SEEDS - 1)


def _bias(kind: str) -> np.ndarray:
    y, x = np.mgrid[0:SIZE, 0:SIZE] / SIZE
    if kind == "none":
        return np.zeros((SIZE, SIZE))
    if kind == "field":
        return 0.4 * np.sin(2 * np.pi * x) * (y > 0.5)
    out = np.zeros((SIZE, SIZE))
    out[[10, 30, 50], [20, 40, 12]] = 3.0  # three pixels carry it all
    return out


def _case(rng: np.random.Generator, bias: np.ndarray):
    # noise blurred over about 2 px (neighbours correlated), unit variance per pixel, per seed
    noise = ndimage.gaussian_filter(rng.normal(size=(SEEDS, SIZE, SIZE)), sigma=(0, 1.0, 1.0), mode="wrap")
    noise /= noise.std()
    r = np.full((SIZE, SIZE), 0.05)
    reference = r * rng.normal(size=(SIZE, SIZE))
    return noise + bias, reference, r


@pytest.mark.parametrize("kind", CASES)
def test01_the_excess_estimates_the_mean_squared_bias_within_its_error(kind):
    rng = np.random.default_rng(3)
    bias = _bias(kind)
    target = float(np.mean(bias**2))
    means, errors = [], []
    for _ in range(R):
        mean, se = bias_excess(*_case(rng, bias))
        assert abs(mean - target) <= Q * se
        means.append(mean)
        errors.append(se)
    # the error is the excess's spread: var(means) / mean(se²) ~ chi² / (R - 1)
    ratio = np.var(means, ddof=1) / np.mean(np.square(errors))
    lo, hi = stats.chi2.ppf([0.5 * LEVEL * R, 1.0 - 0.5 * LEVEL * R], R - 1) / (R - 1)
    assert lo <= ratio <= hi, ratio
