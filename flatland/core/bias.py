r"""Bias tests behind every error table: a method is flagged BIASED before its error or speed is shown.

Two tests, both against a reference with its own standard error:

film sum (the studies' functional)
    The error $S - S_{ref}$ of the sum over the film (or of the studied scalar) with its
    :data:`~flatland.core.stats.LEVEL` interval $± q \sqrt{se^2 + se_{ref}^2}$
    (:func:`error_interval`), q the quantile of a row of a table of m rows
    (:func:`~flatland.core.stats.family_quantile`: the m intervals cover together with
    probability :data:`~flatland.core.stats.LEVEL`); flagged BIASED exactly when the
    interval excludes 0, i.e. $|z| > q$ with $z = (S - S_{ref}) / \sqrt{se^2 + se_{ref}^2}$
    (:func:`flatland.core.stats.z_score`, the project's one rounding policy). A film
    sum's se is the spread of the per-batch sums
    (:meth:`~flatland.core.image.GradientImage.film_sum`), not the pixels' standard errors in
    quadrature: a splatted film and the edge points of ``boundary`` correlate neighbouring pixels.
per pixel (image outputs)
    $z_j = (g_j - r_j) / \sqrt{se_j^2 + se_{ref,j}^2}$ for each of the m pixels whose
    method standard error is positive (a pixel where every sample of the method
    gave the same value, often the zero of a rare event such as a finite
    difference straddling an edge, has no variance estimate to test against; an
    estimator that is exactly zero everywhere is caught by the film-sum test); a
    pixel exceeds when $|z_j|$ is above the two-sided Student-t quantile (``dof`` degrees of
    freedom: the method's batches or trials minus one, its variance dominating the
    reference's) at the Sidak-corrected level $1 - (1 - α)^{1/m}$, α = :data:`PIXEL_ALPHA`
    = 1 - :data:`~flatland.core.stats.LEVEL`. An unbiased method has no exceeding pixel with
    probability $1 - α$, i.e. $m × level ≈ α = 0.01$ exceeding pixels are expected.
    The count is reported beside the film-sum flag but does not set it: the batch
    standard errors of pixels dominated by rare large samples (a finite difference
    straddling an edge, a boundary sample) are themselves noisy, and unbiased
    methods exceeded in measured runs (boundary 1 of 31 pixels at 16 spp, z = 7.2
    against 6.5; finite differences 12 of 575 in the sphere3d demo). A test that
    can see a per-pixel bias needs more batches than these outputs use.

In both tests a difference within the floating-point allowance ``tolerance`` is no
difference (z = 0); a film sum that differs with zero standard errors is flagged (its
interval is the single point of its error; z is ±inf, printed by the tables as "—").
:data:`PixelTest.flagged` says whether any pixel exceeded, for callers that test one
image with enough batches.

The reference rule (:func:`reference_spp_needed`): a reference's standard error
must be at most :data:`REFERENCE_RATIO` = 1/4 of the smallest method standard
error it judges, so that its own noise moves no z by more than ~3 %.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

from flatland.core.image import DEFAULT_MAX_BATCHES
from flatland.core.stats import LEVEL, normal_quantile, rounding_floor, sidak, z_score

__all__ = [
    "PIXEL_ALPHA",
    "REFERENCE_RATIO",
    "ErrorInterval",
    "PixelTest",
    "error_interval",
    "pixel_test",
    "reference_spp_needed",
]

PIXEL_ALPHA = 1.0 - LEVEL
"""Family-wise level of the per-pixel test: 1 - :data:`~flatland.core.stats.LEVEL`."""
REFERENCE_RATIO = 0.25
"""Largest allowed reference stderr / smallest method stderr."""


@dataclass(frozen=True)
class ErrorInterval:
    r"""An estimate's error against a reference, with its interval (see :func:`error_interval`).

    Attributes
    ----------
    error : float
        estimate - reference.
    halfwidth : float
        q × the combined standard error, plus the floating-point allowance.
    z : float
        error / combined standard error (0 within the allowance; ±inf with no spread).
    spread : float
        The combined standard error $\sqrt{se^2 + se_{ref}^2}$ (0: both exact).
    """

    error: float
    halfwidth: float
    z: float
    spread: float

    @property
    def low(self) -> float:
        """Lower end of the interval."""
        return self.error - self.halfwidth

    @property
    def high(self) -> float:
        """Upper end of the interval."""
        return self.error + self.halfwidth

    @property
    def biased(self) -> bool:
        """True if the interval excludes 0: the table prints BIASED."""
        return not self.low <= 0.0 <= self.high


def error_interval(
    estimate: float,
    reference: float,
    stderr: float,
    reference_stderr: float = 0.0,
    quantile: float | None = None,
    tolerance: float | None = None,
) -> ErrorInterval:
    r"""The error ``estimate - reference`` ± ``quantile`` × $\sqrt{se^2 + se_{ref}^2}$ + ``tolerance``.

    ``quantile`` is the row's half-width in standard errors (default: one row at
    :data:`~flatland.core.stats.LEVEL`; a table passes
    :func:`~flatland.core.stats.family_quantile` of its row count); ``tolerance`` the
    floating-point allowance (default :func:`~flatland.core.stats.rounding_floor` of the
    larger magnitude), so an exact estimator that matches up to rounding is not flagged and
    one that misses is (its interval is a point).
    """
    if tolerance is None:
        tolerance = float(rounding_floor(max(abs(float(estimate)), abs(float(reference)))))
    if quantile is None:
        quantile = normal_quantile(LEVEL)
    spread = math.hypot(float(stderr), float(reference_stderr))
    z = z_score(estimate, reference, spread, tolerance)
    return ErrorInterval(float(estimate) - float(reference), quantile * spread + tolerance, z, spread)


@dataclass(frozen=True)
class PixelTest:
    """Outcome of the per-pixel bias test (see the module docstring).

    Attributes
    ----------
    pixels : int
        m, the number of pixels tested (those with a positive method standard error).
    threshold : float
        The |z| a pixel must exceed (Student-t quantile at the Sidak-corrected level).
    exceeding : int
        Pixels with |z| above the threshold.
    expected : float
        Exceeding pixels expected of an unbiased method, m × per-pixel level (≈ α).
    max_abs_z : float
        The largest |z| over the tested pixels (0 if none).
    """

    pixels: int
    threshold: float
    exceeding: int
    expected: float
    max_abs_z: float

    @property
    def flagged(self) -> bool:
        """True if more pixels exceed than the test allows (one or more)."""
        return self.exceeding > 0

    def summary(self) -> str:
        """``exceeding/pixels`` as shown in the tables, e.g. ``7/64``."""
        return f"{self.exceeding}/{self.pixels}"


def pixel_test(
    image: np.ndarray,
    stderr: np.ndarray,
    reference: np.ndarray,
    reference_stderr: np.ndarray,
    dof: int,
    tolerance: float = 0.0,
    alpha: float = PIXEL_ALPHA,
) -> PixelTest:
    """Per-pixel z of ``image`` against ``reference`` and the count above the Sidak-corrected quantile.

    Parameters
    ----------
    image, stderr : ndarray
        The method's mean image and its per-pixel standard error.
    reference, reference_stderr : ndarray
        The reference image and its per-pixel standard error (same shape).
    dof : int
        Degrees of freedom of the method's standard errors (batches or trials - 1).
    tolerance : float
        Floating-point allowance: smaller differences count as none.
    alpha : float
        Family-wise level over the pixels.
    """
    stderr = np.asarray(stderr, dtype=np.float64)
    tested = np.broadcast_to(stderr > 0.0, np.shape(image))  # pixels with a variance estimate
    diff = (np.asarray(image, dtype=np.float64) - np.asarray(reference, dtype=np.float64))[tested]
    noise = np.hypot(stderr, np.asarray(reference_stderr, dtype=np.float64))[tested]
    tolerance = np.broadcast_to(np.asarray(tolerance, dtype=np.float64), np.shape(image))[tested]
    m = int(diff.size)
    if m == 0:
        return PixelTest(0, math.inf, 0, 0.0, 0.0)
    level = sidak(alpha, m)  # per-pixel two-sided level
    # upper Student t quantile: t.isf(q) = -t.ppf(q) = -stdtrit(dof, q)
    threshold = float(-special.stdtrit(max(int(dof), 1), 0.5 * level))
    abs_z = np.where(np.abs(diff) <= tolerance, 0.0, np.abs(diff) / noise)  # noise > 0 on tested pixels
    return PixelTest(m, threshold, int(np.count_nonzero(abs_z > threshold)), m * level, float(abs_z.max()))


def reference_spp_needed(
    spp: int,
    reference_stderr: float,
    smallest_stderr: float,
    ratio: float = REFERENCE_RATIO,
    margin: float = 1.25,
    multiple: int = DEFAULT_MAX_BATCHES,
) -> int:
    r"""Samples per pixel (or n) that bring a reference's stderr to ``ratio`` × ``smallest_stderr``.

    The stderr falls as $1/\sqrt{spp}$, so the count grows by $(stderr / target)^2$, times
    ``margin`` for the scatter of the estimated standard errors, rounded up to a
    multiple of ``multiple`` so the reference keeps that many equal batches (a count
    without a divisor above 1 would leave one batch and an infinite standard error);
    ``spp`` itself when the reference already meets the target (or there is nothing
    to judge).
    """
    if not math.isfinite(reference_stderr):
        raise ValueError(f"reference_stderr: must be finite (two or more batches), got {reference_stderr}")
    target = ratio * smallest_stderr
    if reference_stderr <= target or target <= 0.0:
        return int(spp)
    needed = math.ceil(margin * spp * (reference_stderr / target) ** 2)
    return -(-needed // multiple) * multiple
