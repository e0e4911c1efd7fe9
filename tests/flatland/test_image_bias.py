"""Bias of a derivative image (flatland.core.image_bias): exact cases, then a statistical one."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from flatland.core.image_bias import (
    floor_along,
    fractions,
    kept,
    mean_se,
    over_batches,
    sidak_t,
    squared_bias,
)
from flatland.core.validate import ValidationError

RNG = np.random.default_rng(20191117)
REF = np.sin(np.linspace(0.0, 3.0, 200)) + 0.1


def test01_a_scaled_reference_keeps_exactly_its_scale_and_its_floor_is_the_missing_part():
    batches = np.stack([0.8 * REF] * 4)
    mask = np.ones(REF.shape, dtype=bool)
    assert np.allclose(fractions(batches, REF, np.zeros_like(REF), mask), 0.8, rtol=0, atol=1e-12)
    k, se = kept(batches, REF, np.zeros_like(REF), mask)
    assert abs(k - 0.8) < 1e-12 and se == 0.0
    # the bias along the reference is 0.2 r: its RMS over the pixels
    assert abs(floor_along([(k, se)], REF, [mask]) - 0.2 * np.sqrt(np.mean(REF**2))) < 1e-12


def test02_a_constant_offset_has_squared_bias_offset_squared_and_no_spread():
    batches = np.stack([REF + 0.3] * 5)
    b2, se = squared_bias(batches, REF)
    assert abs(b2 - 0.09) < 1e-12 and se == 0.0
    mean, pixel_se = mean_se(batches)
    # identical batches: their mean is the value to a few ulps (summation order), so the spread is
    # rounding, not exactly 0 on every CPU
    assert np.allclose(mean, REF + 0.3) and np.all(pixel_se <= 4.0 * np.finfo(float).eps * np.abs(mean))


def test03_noise_alone_gives_a_squared_bias_within_t_standard_errors_of_zero():
    """16 batches of the reference plus unit normal noise: unbiased, so |b2| <= t se (two-sided 99.9 %,
    15 degrees of freedom), and the mean of per-batch values has its textbook standard error."""
    batches = REF + RNG.standard_normal((16, REF.size))
    b2, se = squared_bias(batches, REF, np.zeros_like(REF))
    assert se > 0.0 and abs(b2) <= sidak_t(1e-3, 1, 15) * se
    values = RNG.standard_normal(16)
    assert over_batches(values) == pytest.approx((values.mean(), values.std(ddof=1) / 4.0))


def test04_the_sidak_t_quantile_and_bad_input():
    assert sidak_t(1e-3, 1, 15) == pytest.approx(stats.t.ppf(1 - 5e-4, 15))
    assert sidak_t(1e-3, 10, 15) == pytest.approx(stats.t.ppf(1 - (1 - (1 - 1e-3) ** 0.1) / 2, 15))
    with pytest.raises(ValidationError, match="batches"):
        mean_se(np.ones((1, 3)))
    with pytest.raises(ValidationError, match="mask"):
        fractions(np.ones((2, 3)), np.zeros(3), np.zeros(3), np.ones(3, dtype=bool))
