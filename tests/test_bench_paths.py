"""The light-path benchmark's error with the reference's noise subtracted
(:func:`benchmarks.bench_paths_sphere3d.rmse_exact`).

1. Closed form: images at a constant offset e from the reference, with a reference standard error
   r, give sqrt(e² - r²), and 0 where r > |e|.
2. Statistics: images of exact derivative plus noise of standard deviation s, against a reference of
   the exact derivative plus independent noise of standard error r (known), estimate s, not
   sqrt(s² + r²): over 64 x 64 pixels and 3 seeds, within 5 standard errors of the mean squared
   error, taken as that of 4096 independent Gaussian squares, (s² + r²) sqrt(2 / 4096) (the seeds
   share the reference's noise, so fewer than 12 288 independent terms; the pixel count is the
   conservative one). Without the subtraction the estimate is off by r², beyond that bound.
"""

from __future__ import annotations

import numpy as np

from benchmarks.bench_paths_sphere3d import rmse_exact


def test01_a_constant_offset_less_the_reference_variance():
    ref = np.zeros((8, 8))
    images = np.full((3, 8, 8), 0.5)
    assert np.isclose(rmse_exact(images, ref, np.full((8, 8), 0.3)), 0.4)
    assert rmse_exact(images, ref, np.full((8, 8), 0.6)) == 0.0


def test02_the_reference_noise_is_subtracted_in_expectation():
    rng = np.random.default_rng(5)
    exact = rng.normal(size=(64, 64))
    s, r = 0.4, 0.3
    images = exact + s * rng.normal(size=(3, 64, 64))
    ref = exact + r * rng.normal(size=(64, 64))
    got = rmse_exact(images, ref, np.full((64, 64), r))
    se = (s**2 + r**2) * np.sqrt(2.0 / ref.size)  # the mean squared error's, conservatively
    assert abs(got**2 - s**2) <= 5.0 * se, (got, s)
    assert abs(np.sqrt(np.mean((images - ref) ** 2)) ** 2 - s**2) > 5.0 * se  # without it: s² + r²
