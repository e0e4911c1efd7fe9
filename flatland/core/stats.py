"""Statistics for Monte Carlo results: standard errors, confidence intervals, chi-square tests.

Tolerances in the test suite come from here: a Monte Carlo estimate ``m`` with
standard error ``s`` agrees with a reference ``r`` when $|m - r| ≤ z s$ for a
stated two-sided normal quantile ``z`` (:func:`normal_quantile`); samplers are
checked with a chi-square goodness-of-fit test (:func:`chi2_gof`) at a level
corrected for the number of tests run (:func:`sidak`).

Every interval the command line, the studies and the tables print is a two-sided
:data:`LEVEL` = 99 % interval; the m rows of one table are judged together
(:func:`family_quantile`), so a table of unbiased estimators shows no flag with
probability 99 %, and a row is flagged exactly when its interval excludes the
reference.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import special  # not scipy.stats: its import costs 20x special's, paid by every CLI start

__all__ = [
    "LEVEL",
    "ROUNDING",
    "Chi2Result",
    "Interval",
    "SampleSummary",
    "batch_interval",
    "chi2_gof",
    "chi2_gof_counts",
    "family_level",
    "family_quantile",
    "normal_quantile",
    "rounding_floor",
    "sidak",
    "spread",
    "summarize",
    "z_score",
]

LEVEL = 0.99
"""The confidence level of every interval the project prints, two-sided.

One policy for every output (the demo's tables, the studies, the command line, the
figures' bands): an interval "[low, high]" covers the true value with probability
:data:`LEVEL`. Where a table judges m rows at once, each row's interval is widened to
the per-row level :func:`family_level` (Šidák), so the m intervals cover together with
probability :data:`LEVEL`, and a row is flagged BIASED exactly when its interval
excludes the reference. Other quantiles (the per-pixel test's α = 1 - LEVEL) derive
from it.
"""

ROUNDING = 64 * np.finfo(np.float64).eps
"""Relative size of floating-point noise in a mean or standard deviation of many terms.

The one policy for "zero spread": a standard deviation at or below
``ROUNDING * scale`` (:func:`rounding_floor`) is rounding, not variance. The mean of
N identical floats is not always bit-equal to that float (pairwise summation and
the SIMD width differ between CPUs), so the sample standard deviation of a
constant is a few ulps, not 0.0, on some machines. :func:`spread` maps such values
to exactly 0.0, so a zero-variance estimator reports a zero standard error on every
CPU; :func:`summarize`, :func:`flatland.core.image.summarize_batches` and the study
runner all go through it.
"""
LEVEL = 0.99
"""The one confidence level of every printed interval and flag: 99 %, two-sided."""


@dataclass(frozen=True)
class SampleSummary:
    """Mean of i.i.d. samples with its standard error."""

    mean: float
    stderr: float
    n: int


@dataclass(frozen=True)
class Interval:
    """A two-sided confidence interval."""

    low: float
    high: float
    level: float

    def contains(self, x: float) -> bool:
        """True if ``low <= x <= high``."""
        return self.low <= x <= self.high


@dataclass(frozen=True)
class Chi2Result:
    """Outcome of a chi-square goodness-of-fit test."""

    statistic: float
    dof: int
    p_value: float
    bins: int

    def passed(self, alpha: float) -> bool:
        """True if the test does not reject at level ``alpha``."""
        return self.p_value >= alpha


def rounding_floor(scale: np.ndarray | float) -> np.ndarray | float:
    """The largest spread that counts as rounding for values of size ``scale``: ``ROUNDING * |scale|``."""
    return ROUNDING * np.abs(scale)


def spread(std: np.ndarray | float, scale: np.ndarray | float) -> np.ndarray | float:
    """``std`` with rounding-level spread (``std <= rounding_floor(scale)``) set to exactly 0.0.

    Parameters
    ----------
    std : float or ndarray
        Sample standard deviations (or standard errors: the rule is scale-free).
    scale : float or ndarray
        The size of the values whose spread ``std`` measures (their mean, or the
        largest of mean and reference), broadcast against ``std``.
    """
    std = np.asarray(std, dtype=np.float64)
    out = np.where(std <= rounding_floor(np.asarray(scale, dtype=np.float64)), 0.0, std)
    return float(out) if out.ndim == 0 else out


def z_score(estimate: float, reference: float, stderr: float, tolerance: float | None = None) -> float:
    """``(estimate - reference) / stderr``, the error in standard errors, under the rounding policy.

    A difference within ``tolerance`` (default :func:`rounding_floor` of the larger
    magnitude) is rounding: z = 0. With a zero standard error (an exact estimator,
    or rounding-level spread counted as none by :func:`spread`) a larger difference
    is infinitely significant.
    """
    diff = float(estimate) - float(reference)
    if tolerance is None:
        tolerance = float(rounding_floor(max(abs(float(estimate)), abs(float(reference)))))
    if abs(diff) <= tolerance:
        return 0.0
    if stderr > 0.0:
        return diff / float(stderr)
    return math.copysign(math.inf, diff)


def summarize(samples: np.ndarray, axis: int = 0) -> SampleSummary:
    """Mean and standard error ``std(ddof=1) / sqrt(n)`` of i.i.d. samples along ``axis``.

    Rounding-level spread counts as none (:data:`ROUNDING`): the standard error of
    identical samples is exactly 0.0 on every CPU.
    """
    samples = np.asarray(samples, dtype=np.float64)
    n = samples.shape[axis]
    mean = samples.mean(axis=axis)
    if n < 2:
        return SampleSummary(mean=mean, stderr=np.full_like(mean, np.inf), n=n)
    std = spread(samples.std(axis=axis, ddof=1), mean)
    return SampleSummary(mean=mean, stderr=std / np.sqrt(n), n=n)


def normal_quantile(level: float) -> float:
    """Two-sided standard-normal quantile: $P(|Z| ≤ z) = level$ (0.99 -> 2.576)."""
    return float(special.ndtri(0.5 + 0.5 * level))


def sidak(alpha: float, m: int) -> float:
    """Per-test level so that ``m`` independent tests together reject with probability ``alpha``."""
    return 1.0 - (1.0 - alpha) ** (1.0 / m)


def family_level(m: int, level: float = LEVEL) -> float:
    """Per-row coverage so that ``m`` independent intervals all cover with probability ``level``.

    Šidák: ``level ** (1 / m)``, i.e. ``1 - sidak(1 - level, m)`` (0.99 over 4 rows: 0.9975 each).
    """
    if m < 1:
        raise ValueError(f"m: must be >= 1, got {m}")
    return 1.0 - sidak(1.0 - level, m)


def family_quantile(m: int, level: float = LEVEL, dof: int | None = None) -> float:
    """Half-width, in standard errors, of each of ``m`` simultaneous two-sided intervals at ``level``.

    The two-sided normal quantile (``dof=None``) or Student-t quantile with ``dof`` degrees
    of freedom at the per-row coverage :func:`family_level`: 2.58 for one normal row at
    0.99, 3.02 for four.
    """
    per_row = family_level(m, level)
    if dof is None:
        return normal_quantile(per_row)
    return float(special.stdtrit(max(int(dof), 1), 0.5 + 0.5 * per_row))  # Student t quantile


def batch_interval(batch_estimates: np.ndarray, level: float = LEVEL) -> Interval:
    """Student-t confidence interval for the mean from independent batch estimates."""
    b = np.asarray(batch_estimates, dtype=np.float64).ravel()
    if b.size < 2:
        raise ValueError(f"batch_estimates: need at least 2 batches, got {b.size}")
    half = special.stdtrit(b.size - 1, 0.5 + 0.5 * level) * b.std(ddof=1) / np.sqrt(b.size)
    return Interval(float(b.mean() - half), float(b.mean() + half), level)


def chi2_gof_counts(observed: np.ndarray, expected: np.ndarray, min_expected: float = 5.0) -> Chi2Result:
    """Chi-square test of observed against expected counts.

    Cells with fewer than ``min_expected`` expected counts are pooled into one cell
    (the usual validity rule for the chi-square approximation).
    """
    observed = np.asarray(observed, dtype=np.float64).ravel()
    expected = np.asarray(expected, dtype=np.float64).ravel()
    small = expected < min_expected
    obs = np.append(observed[~small], observed[small].sum())
    exp = np.append(expected[~small], expected[small].sum())
    if exp[-1] == 0.0:
        if obs[-1] > 0:
            return Chi2Result(np.inf, max(obs.size - 2, 1), 0.0, observed.size)
        obs, exp = obs[:-1], exp[:-1]
    statistic = float(np.sum((obs - exp) ** 2 / exp))
    dof = obs.size - 1
    p_value = float(special.chdtrc(dof, statistic))  # chi-square survival function
    return Chi2Result(statistic, dof, p_value, observed.size)


def chi2_gof(
    samples: np.ndarray,
    pdf: Callable[[np.ndarray], np.ndarray],
    bins: int,
    range: tuple[float, float],
    *,
    quadrature_points: int = 32,
    min_expected: float = 5.0,
) -> Chi2Result:
    """Chi-square goodness-of-fit test of 1D samples against a density.

    Parameters
    ----------
    samples : ndarray
        Draws from the sampler under test.
    pdf : callable
        The density the sampler claims (vectorized).
    bins : int
        Number of equal-width bins over ``range``; odd, so no bin edge sits on a
        symmetry axis of a density centred in the range.
    range : (float, float)
        Histogram range. Mass of ``pdf`` outside it is pooled into one cell.
    quadrature_points : int
        Gauss-Legendre points per bin for the expected counts.
    """
    if bins % 2 == 0:
        raise ValueError(f"bins must be odd, got {bins}")
    samples = np.asarray(samples, dtype=np.float64)
    edges = np.linspace(range[0], range[1], bins + 1)
    inside, _ = np.histogram(samples, bins=edges)
    outside = samples.size - inside.sum()
    x, w = np.polynomial.legendre.leggauss(quadrature_points)
    half = 0.5 * np.diff(edges)
    mid = 0.5 * (edges[:-1] + edges[1:])
    nodes = mid[:, None] + half[:, None] * x[None, :]
    mass = (pdf(nodes) * w[None, :]).sum(axis=1) * half
    expected = samples.size * np.append(mass, max(1.0 - mass.sum(), 0.0))
    observed = np.append(inside, outside)
    return chi2_gof_counts(observed, expected, min_expected)
