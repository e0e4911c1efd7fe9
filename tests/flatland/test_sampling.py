"""Every sample/pdf pair of flatland.sampling: the pdf is a density, and the sampler draws from it.

Chi-square goodness of fit with 51 bins (odd) over 200 000 samples per case. The family of
cases rejects a correct sampler with probability ALPHA = 1e-3 overall: each case is tested
at the Šidák level sidak(ALPHA, number of cases). Seeds are fixed, so the outcome is
reproducible; a wrong density (a factor of 2 in a width, a missing normalisation) gives
p-values far below 1e-10.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate

from flatland import sampling as s
from flatland.core.rng import stream
from flatland.core.stats import chi2_gof, sidak

N = 200_000
BINS = 51
ALPHA = 1e-3

EDGES = np.array([-1.0, 0.0, 0.5, 2.0, 2.5])
WEIGHTS = np.array([1.0, 0.0, 3.0, 0.5])

# name: (sampler(u), pdf(x), histogram range)
CASES = {
    "uniform": (lambda u: s.sample_uniform(u, -1.0, 3.0), lambda x: s.pdf_uniform(x, -1.0, 3.0), (-1.0, 3.0)),
    "gaussian": (
        lambda u: s.sample_gaussian(u, 0.5, 2.0),
        lambda x: s.pdf_gaussian(x, 0.5, 2.0),
        (-7.5, 8.5),
    ),
    "tent": (lambda u: s.sample_tent(u, 1.0, 0.5), lambda x: s.pdf_tent(x, 1.0, 0.5), (0.5, 1.5)),
    "tabulated": (
        lambda u: s.sample_tabulated(u, EDGES, WEIGHTS),
        lambda x: s.pdf_tabulated(x, EDGES, WEIGHTS),
        (-1.0, 2.5),
    ),
    "uniform_circle": (s.sample_uniform_circle, s.pdf_uniform_circle, (-np.pi, np.pi)),
    "cosine_half_circle": (
        lambda u: s.sample_cosine_half_circle(u, 0.4),
        lambda x: s.pdf_cosine_half_circle(x, 0.4),
        (0.4 - np.pi / 2, 0.4 + np.pi / 2),
    ),
}
for _kappa in (1.0, 10.0, 100.0, 1e3, 1e4, 1e5):
    _w = min(np.pi, 6.0 / np.sqrt(_kappa))
    CASES[f"von_mises_{_kappa:g}"] = (
        lambda u, k=_kappa: s.sample_von_mises(u, 0.3, k),
        lambda x, k=_kappa: s.pdf_von_mises(x, 0.3, k),
        (0.3 - _w, 0.3 + _w),
    )

# the film's pixel filters, appended last so the cases above keep their streams; the Gaussian
# filter's mass beyond its 4 sigma (= 2 Δt) is pooled into one cell
FILTER_WIDTH = 0.3
"""A pixel width Δt."""
for _kind, _support in (("box", 0.5), ("tent", 1.0), ("gaussian", 2.0)):
    CASES[f"filter_{_kind}"] = (
        lambda u, k=_kind: s.sample_filter(k, u, 0.1, FILTER_WIDTH),
        lambda x, k=_kind: s.pdf_filter(k, x, 0.1, FILTER_WIDTH),
        (0.1 - _support * FILTER_WIDTH, 0.1 + _support * FILTER_WIDTH),
    )

LEVEL = sidak(ALPHA, len(CASES))


@pytest.mark.parametrize("name", list(CASES))
def test01_pdf_integrates_to_one(name):
    _, pdf, (lo, hi) = CASES[name]
    if name.startswith("von_mises"):
        lo, hi = 0.3 - np.pi, 0.3 + np.pi  # the whole circle
    elif name in ("gaussian", "filter_gaussian"):
        lo, hi = -np.inf, np.inf
    breaks = [
        b
        for b in (*EDGES, 0.4 - np.pi / 2, 0.4 + np.pi / 2, 1.0, 0.3, 0.1)
        if lo < b < hi and np.isfinite(lo)
    ]
    total, _ = integrate.quad(lambda x: float(pdf(np.array(x))), lo, hi, points=breaks or None, limit=400)
    assert total == pytest.approx(1.0, abs=1e-7)


@pytest.mark.parametrize("name", list(CASES))
def test02_sampler_matches_pdf_chi_square(name):
    sample, pdf, rng = CASES[name]
    x = sample(stream(7, "test_sampling", list(CASES).index(name)).random(N))
    result = chi2_gof(x, pdf, BINS, rng)
    assert result.passed(LEVEL), f"{name}: {result} (level {LEVEL:.2e})"


@pytest.mark.parametrize("name", ["gaussian", "tent", "von_mises_100", "cosine_half_circle"])
def test03_samplers_are_inverse_cdfs_monotone_in_u(name):
    sample, _, _ = CASES[name]
    u = np.linspace(0.0005, 0.9995, 2001)
    assert np.all(np.diff(sample(u)) > 0)


def test04_chi_square_rejects_a_wrong_density():
    """The test above can fail: a Gaussian sampler checked against a density 10% too wide is rejected."""
    x = s.sample_gaussian(stream(7, "wrong").random(N), 0.0, 1.0)
    result = chi2_gof(x, lambda t: s.pdf_gaussian(t, 0.0, 1.1), BINS, (-5.0, 5.0))
    assert result.p_value < 1e-10


def test05_von_mises_pdf_is_stable_for_huge_kappa():
    x = np.array([0.0, 1e-3, 0.1, np.pi])
    p = s.pdf_von_mises(x, 0.0, 1e6)
    assert np.all(np.isfinite(p))
    assert p[0] == pytest.approx(np.sqrt(1e6 / (2 * np.pi)), rel=1e-6)  # Gaussian limit at the mode
    assert p[3] == 0.0


def test06_bad_parameters_name_the_field():
    with pytest.raises(ValueError, match="kappa"):
        s.sample_von_mises(np.array([0.5]), 0.0, 0.0)
    with pytest.raises(ValueError, match="std"):
        s.sample_gaussian(np.array([0.5]), 0.0, -1.0)


def test07_log_densities_accept_duals_and_match_the_densities():
    """The kernels' log densities (used with reparameterized Dual samples) are the samplers' pdfs."""
    from flatland.core.dual import Dual

    x = np.linspace(-2.0, 2.0, 9)
    lg = s.log_pdf_gaussian(Dual(x, np.ones_like(x)), 0.3, 0.7)
    np.testing.assert_allclose(np.exp(lg.value), s.pdf_gaussian(x, 0.3, 0.7), rtol=1e-14)
    np.testing.assert_allclose(lg.tangent, -(x - 0.3) / 0.49, rtol=1e-14)  # d/dx log N = -(x - m)/σ²
    lv = s.log_pdf_von_mises(Dual(x, np.ones_like(x)), 0.3, 50.0)
    np.testing.assert_allclose(np.exp(lv.value), s.pdf_von_mises(x, 0.3, 50.0), rtol=1e-14)
    np.testing.assert_allclose(lv.tangent, -50.0 * np.sin(x - 0.3), rtol=1e-13)
    with pytest.raises(ValueError, match=r"^mu"):
        s.sample_von_mises(np.array([0.5]), np.nan, 1.0)


@pytest.mark.parametrize("kind", ["box", "tent", "gaussian"])
def test08_film_filter_is_its_own_sampling_density(kind):
    """The integrator divides by pdf_filter where it evaluates the filter at a film sample: the two agree
    on plain samples, and the chi-square check of the pair rejects a filter of another width."""
    t = s.sample_filter(kind, stream(7, "filter_pdf").random(1001), 0.1, FILTER_WIDTH)
    assert np.array_equal(
        s.pdf_filter(kind, t, 0.1, FILTER_WIDTH), s.filter_value(kind, t, 0.1, FILTER_WIDTH)
    )
    x = s.sample_filter(
        kind, stream(7, "filter_wrong", ["box", "tent", "gaussian"].index(kind)).random(N), 0.1, FILTER_WIDTH
    )
    wide = 1.1 * FILTER_WIDTH
    result = chi2_gof(
        x, lambda y: s.pdf_filter(kind, y, 0.1, wide), BINS, (0.1 - 2.0 * wide, 0.1 + 2.0 * wide)
    )
    assert result.p_value < 1e-10


def test09_wrap_angle_is_numpys_remainder_bit_for_bit():
    """wrap_angle's fast road (plain arrays within [-5π, 5π)) gives remainder(φ + π, 2π) - π exactly, signs
    of zero included: at and next to every multiple of π, where a rounded y + 2π reaches 2π, at random;
    and the other inputs (scalars, NaN, wider angles) go the slow road to the same numbers."""

    def reference(phi):
        return np.remainder(phi + np.pi, s.TWO_PI) - np.pi

    near = [k * np.pi + np.arange(-200, 201) * np.spacing(max(abs(k) * np.pi, 1.0)) for k in range(-6, 7)]
    below_pi = [np.nextafter(-np.pi, -4.0), np.nextafter(np.nextafter(-np.pi, -4.0), -4.0)]
    tiny = np.array([*below_pi, -np.pi - 1e-300, np.nextafter(5 * np.pi, 0.0), -5 * np.pi])
    uniform = stream(7, "wrap_angle").uniform(-5.5 * np.pi, 5.5 * np.pi, (400, 7))
    for phi in (np.concatenate([*near, tiny]), uniform, uniform[:, :3] / 5.0, np.array([np.nan, 1.0]), 3.0):
        got, want = s.wrap_angle(phi), reference(phi)
        assert np.array_equal(got, want, equal_nan=True)
        assert np.array_equal(np.signbit(got), np.signbit(want))
        if isinstance(phi, np.ndarray):  # into out, which may be phi itself: the same numbers
            inplace = phi.copy()
            assert s.wrap_angle(inplace, out=inplace) is inplace
            assert np.array_equal(inplace, want, equal_nan=True)
            assert np.array_equal(np.signbit(inplace), np.signbit(want))
    # the test can fail: wrapping in sequence (add 2π below 0, then subtract 2π from what reaches 2π)
    # turns a rounded y + 2π = 2π into 0, where remainder keeps 2π
    y = tiny + np.pi
    y = np.where(y < 0.0, y + s.TWO_PI, y)
    assert not np.array_equal(np.where(y >= s.TWO_PI, y - s.TWO_PI, y) - np.pi, reference(tiny))
