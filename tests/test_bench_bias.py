"""The bias floor's excess and its error (:func:`benchmarks.bench_hard_shadow.bias_excess`).

On synthetic images whose noise is correlated between neighbouring pixels (as the splat film's),
with a reference that has its own noise: the excess estimates the mean squared bias without bias,
and its block standard error covers its spread. Checked against the known bias b (0 and a field
varying over the image): |excess - mean(b²)| <= q · stderr in every one of R independent
repetitions, q the two-sided normal quantile at family-wise 0.01 (Šidák over the repetitions), and
the standard error agrees with the excess's spread over the repetitions (a two-sided chi-square
test of the variance ratio at the same level).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage, stats

from benchmarks.bench_hard_shadow import bias_excess

SEEDS, SIZE, R = 8, 64, 40
Q = stats.norm.ppf(1.0 - 0.5 * (1.0 - (1.0 - 0.01) ** (1.0 / (2 * R))))


def _case(rng: np.random.Generator, bias: np.ndarray):
    # noise blurred over about 2 px (neighbours correlated), unit variance per pixel, per seed
    noise = ndimage.gaussian_filter(rng.normal(size=(SEEDS, SIZE, SIZE)), sigma=(0, 1.0, 1.0), mode="wrap")
    noise /= noise.std()
    r = np.full((SIZE, SIZE), 0.05)
    reference = r * rng.normal(size=(SIZE, SIZE))
    return noise + bias, reference, r


@pytest.mark.parametrize("kind", ["none", "field"])
def test01_the_excess_estimates_the_mean_squared_bias_within_its_error(kind):
    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:SIZE, 0:SIZE] / SIZE
    bias = np.zeros((SIZE, SIZE)) if kind == "none" else 0.4 * np.sin(2 * np.pi * x) * (y > 0.5)
    target = float(np.mean(bias**2))
    means, errors = [], []
    for _ in range(R):
        mean, se = bias_excess(*_case(rng, bias))
        assert abs(mean - target) <= Q * se
        means.append(mean)
        errors.append(se)
    # the block error is the spread of the excess: var(means) / mean(se²) ~ chi² / (R - 1)
    ratio = np.var(means, ddof=1) / np.mean(np.square(errors))
    lo, hi = stats.chi2.ppf([0.005, 0.995], R - 1) / (R - 1)
    assert lo <= ratio <= hi
