"""Sampling routines on the line and on the circle S¹, as ``sample_x(u, ...)`` / ``pdf_x(x, ...)`` pairs.

Each ``sample_x`` maps uniform numbers ``u`` in [0, 1) deterministically to samples
(inverse-CDF wherever possible), so a seed fixes the samples and stratified or
common random numbers work unchanged. Each ``pdf_x`` is the density of what the
matching ``sample_x`` produces; a chi-square test per pair checks that claim.

Angles on the circle are in radians; circle densities are with respect to arc
length (they integrate to 1 over any interval of length 2π).

The pixel filters of the 1D film come last, with the names sphere3d uses for its 2D
film: :func:`filter_value` ($k_j$, Dual-aware), :func:`sample_filter` /
:func:`pdf_filter`, and the 2D-only :func:`filter_blurred` ($k_j ⊛ N(0, σ^2)$).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
from scipy import special

from flatland.core.dual import detach
from flatland.core.validate import ValidationError, check_positive

__all__ = [
    "filter_blurred",
    "filter_value",
    "log_pdf_gaussian",
    "log_pdf_von_mises",
    "pdf_circle_direction",
    "pdf_cosine_half_circle",
    "pdf_filter",
    "pdf_gaussian",
    "pdf_segment_direction",
    "pdf_tabulated",
    "pdf_tent",
    "pdf_uniform",
    "pdf_uniform_circle",
    "pdf_von_mises",
    "sample_circle_direction",
    "sample_cosine_half_circle",
    "sample_filter",
    "sample_gaussian",
    "sample_segment_direction",
    "sample_tabulated",
    "sample_tent",
    "sample_uniform",
    "sample_uniform_circle",
    "sample_von_mises",
    "wrap_angle",
]

TWO_PI = 2.0 * np.pi


def wrap_angle(phi: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    r"""Angle(s) wrapped to [-π, π): $\mathrm{remainder}(φ + π, 2π) - π$, numpy's remainder bit for bit.

    Plain arrays with $y = φ + π$ in $[-4π, 6π)$ (every angle difference the renderer wraps) take
    a faster road to the same numbers: numpy's remainder is the exact fmod, plus 2π where that is
    negative. Above 0, fmod is $y - 2π$ or $y - 4π$, exact float subtractions (Sterbenz); below 0 it
    is y, or the exact $y + 2π$ below $-2π$, and the one rounded step adds 2π: one addition of
    $j · 2π$, j in {-2, ..., 2}, gives each. Anything else (Duals, NaN, inf, larger angles) goes
    through ``np.remainder``. ``out`` (a float array shaped like ``phi``, which may be ``phi``
    itself) receives the result on the fast road, saving an array as large as ``phi``.
    """
    if isinstance(phi, np.ndarray) and phi.dtype == np.float64 and phi.ndim and phi.size:
        y = np.add(phi, np.pi, out=out)
        least, most = y.min(), y.max()
        if least >= -2.0 * TWO_PI and most < 3.0 * TWO_PI:  # NaN fails both tests
            # turns of 2π to add, from y as it came (a rounded y + 2π may equal 2π, and stays so, as in
            # remainder); y + 2 (2π) is the same one rounding as (y + 2π, exact) + 2π
            turns = np.zeros(y.shape, np.int8)  # small integers (booleans viewed as int8: no casting loops)
            for bound, sign in ((0.0, 1), (-TWO_PI, 1), (TWO_PI, -1), (2.0 * TWO_PI, -1)):
                if sign > 0 and least < bound:
                    turns += (y < bound).view(np.int8)
                elif sign < 0 and most >= bound:
                    turns -= (y >= bound).view(np.int8)
            y += turns * TWO_PI  # y + 0.0 where no turn: y (a zero's sign is lost to the - π below)
            y -= np.pi
            return y
        y = np.remainder(y, TWO_PI, out=y)  # y is φ + π, as computed below
        y -= np.pi
        return y
    return np.remainder(phi + np.pi, TWO_PI) - np.pi


# ------------------------------------------------------------------ the line
def sample_uniform(u: np.ndarray, a: float, b: float) -> np.ndarray:
    """Uniform on [a, b): $x = a + (b - a) u$."""
    return a + (b - a) * np.asarray(u)


def pdf_uniform(x: np.ndarray, a: float, b: float) -> np.ndarray:
    """$1 / (b - a)$ on [a, b], 0 elsewhere."""
    x = np.asarray(x, dtype=np.float64)
    return np.where((x >= a) & (x <= b), 1.0 / (b - a), 0.0)


def sample_gaussian(u: np.ndarray, mean: float, std: float) -> np.ndarray:
    r"""Normal $N(mean, std^2)$ by the inverse CDF $mean + std\, Φ^{-1}(u)$."""
    std = check_positive("std", std)
    return mean + std * special.ndtri(np.asarray(u))


def log_pdf_gaussian(x: Any, mean: Any, std: float) -> Any:
    r"""log of the normal density: $-(x - mean)^2 / (2 std^2) - \log(std \sqrt{2π})$; ``x`` may be a Dual."""
    z = (x - mean) / std
    return -0.5 * z * z - np.log(std * np.sqrt(TWO_PI))


def pdf_gaussian(x: np.ndarray, mean: float, std: float) -> np.ndarray:
    r"""Normal density $\exp(-(x - mean)^2 / (2 std^2)) / (std \sqrt{2π})$."""
    return np.exp(log_pdf_gaussian(np.asarray(x, dtype=np.float64), mean, std))


def sample_tent(u: np.ndarray, center: float, radius: float) -> np.ndarray:
    """Tent (triangle) density on [center - radius, center + radius] by the inverse CDF."""
    u = np.asarray(u, dtype=np.float64)
    # CDF is 2u² on the left half: x = c - r (1 - sqrt(2u)); mirrored on the right
    left = 1.0 - np.sqrt(2.0 * np.minimum(u, 0.5))
    right = 1.0 - np.sqrt(2.0 * (1.0 - np.maximum(u, 0.5)))
    return np.where(u < 0.5, center - radius * left, center + radius * right)


def pdf_tent(x: np.ndarray, center: float, radius: float) -> np.ndarray:
    r"""$\max(0, 1 - |x - center| / radius) / radius$."""
    x = np.asarray(x, dtype=np.float64)
    return np.maximum(0.0, 1.0 - np.abs(x - center) / radius) / radius


def sample_tabulated(u: np.ndarray, edges: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Piecewise-constant density proportional to ``weights`` on the bins ``edges`` (importance sampling).

    Parameters
    ----------
    u : ndarray
        Uniform numbers in [0, 1).
    edges : ndarray, shape (m + 1,)
        Increasing bin edges.
    weights : ndarray, shape (m,)
        Non-negative bin weights (not all zero); the density in bin i is
        ``weights[i] / (sum(weights) * width_i)``.
    """
    edges = np.asarray(edges, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    cdf = np.concatenate([[0.0], np.cumsum(weights)])
    cdf /= cdf[-1]
    u = np.asarray(u, dtype=np.float64)
    # largest i with cdf[i] <= u; then cdf[i + 1] > u, so empty bins are never chosen
    i = np.clip(np.searchsorted(cdf, u, side="right") - 1, 0, weights.size - 1)
    frac = (u - cdf[i]) / (cdf[i + 1] - cdf[i])
    return edges[i] + frac * (edges[i + 1] - edges[i])


def pdf_tabulated(x: np.ndarray, edges: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Density of :func:`sample_tabulated`."""
    edges = np.asarray(edges, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    density = weights / (weights.sum() * np.diff(edges))
    x = np.asarray(x, dtype=np.float64)
    i = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, weights.size - 1)
    return np.where((x >= edges[0]) & (x <= edges[-1]), density[i], 0.0)


# ---------------------------------------------------------------- the circle
def sample_uniform_circle(u: np.ndarray) -> np.ndarray:
    """Uniform angle on [-π, π)."""
    return -np.pi + TWO_PI * np.asarray(u)


def pdf_uniform_circle(phi: np.ndarray) -> np.ndarray:
    """$1 / (2π)$."""
    return np.full(np.shape(phi), 1.0 / TWO_PI)


def sample_cosine_half_circle(u: np.ndarray, normal_angle: float | np.ndarray = 0.0) -> np.ndarray:
    r"""Cosine-weighted direction about ``normal_angle``: $φ - φ_n = \arcsin(2u - 1)$ (theory/radiometry)."""
    return normal_angle + np.arcsin(2.0 * np.asarray(u) - 1.0)


def pdf_cosine_half_circle(phi: np.ndarray, normal_angle: float | np.ndarray = 0.0) -> np.ndarray:
    r"""$\cos(φ - φ_n) / 2$ on the half circle around the normal, 0 behind it."""
    c = np.cos(np.asarray(phi) - normal_angle)
    return np.where(c > 0.0, 0.5 * c, 0.0)


def log_pdf_von_mises(phi: Any, mu: Any, kappa: float) -> Any:
    r"""log of the von Mises density, $κ (\cos(φ - μ) - 1) - \log(2π\, \mathrm{i0e}(κ))$;
    ``phi`` may be a Dual.

    $I_0(κ) = \mathrm{i0e}(κ) e^κ$ (the scaled Bessel function), so nothing overflows for κ
    up to 1e6 and beyond.
    """
    kappa = check_positive("kappa", kappa)
    return kappa * (np.cos(phi - mu) - 1.0) - np.log(TWO_PI * special.i0e(kappa))


def pdf_von_mises(phi: np.ndarray, mu: float | np.ndarray, kappa: float) -> np.ndarray:
    r"""Von Mises density $\exp(κ \cos(φ - μ)) / (2π I_0(κ))$, stable for large κ (theory/kernels)."""
    return np.exp(log_pdf_von_mises(np.asarray(phi, dtype=np.float64), mu, kappa))


@functools.lru_cache(maxsize=8)
def _von_mises(kappa: float) -> Any:
    """scipy's frozen von Mises distribution of concentration ``kappa``, made once per κ (freezing one
    costs milliseconds, as much as a CDF evaluation over thousands of angles)."""
    from scipy.stats import vonmises  # here, not at module level: scipy.stats is slow to import

    return vonmises(kappa)


def sample_von_mises(u: np.ndarray, mu: float | np.ndarray, kappa: float | np.ndarray) -> np.ndarray:
    """Von Mises samples by numerical inversion of the CDF (safeguarded Newton).

    The CDF is scipy's (Hill's algorithm); Newton steps use :func:`pdf_von_mises`
    and fall back to bisection when a step leaves the bracket, so every sample is
    an inverse-CDF image of its ``u`` to about 1e-12 in probability.

    ``kappa``: one concentration, or one per row of ``u`` (its first axis; a kernel per point): the
    rows of each distinct κ are sampled together, as by one call with that κ (a loop over the
    distinct values, not over samples). Returns angles in ``mu + [-π, π]``.
    """
    if np.ndim(kappa) != 0:
        return _sample_von_mises_rows(
            np.asarray(u, dtype=np.float64), mu, np.asarray(kappa, dtype=np.float64)
        )
    kappa = check_positive("kappa", kappa)
    if not np.all(np.isfinite(mu)):
        raise ValidationError("mu", f"must be finite, got {mu!r}")
    u = np.asarray(u, dtype=np.float64)
    dist = _von_mises(kappa)
    # start from the Gaussian approximation (exact as κ → ∞), clipped into the bracket
    phi = np.clip(special.ndtri(u) / np.sqrt(kappa), -np.pi, np.pi)
    lo = np.full(u.shape, -np.pi)
    hi = np.full(u.shape, np.pi)
    active = np.flatnonzero(np.ones(u.shape, dtype=bool).ravel())
    phi_flat, lo_flat, hi_flat, u_flat = phi.ravel(), lo.ravel(), hi.ravel(), u.ravel()
    angle_tol = 1e-12 / np.sqrt(max(kappa, 1.0))
    for _ in range(64):
        p, a, b, target = phi_flat[active], lo_flat[active], hi_flat[active], u_flat[active]
        err = dist.cdf(p) - target
        a = np.where(err < 0, p, a)
        b = np.where(err > 0, p, b)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            newton = p - err / pdf_von_mises(p, 0.0, kappa)
        # safeguard: bisect when Newton leaves the bracket [a, b]
        new = np.where(np.isfinite(newton) & (newton >= a) & (newton <= b), newton, 0.5 * (a + b))
        phi_flat[active], lo_flat[active], hi_flat[active] = new, a, b
        # converged: CDF matches to rounding, or the step is below the angular tolerance
        done = (np.abs(err) <= 4e-16) | (np.abs(new - p) <= angle_tol) | (b - a <= angle_tol)
        active = active[~done]
        if active.size == 0:
            break
    phi = phi_flat.reshape(u.shape)
    return mu + phi


def _sample_von_mises_rows(u: np.ndarray, mu: float | np.ndarray, kappa: np.ndarray) -> np.ndarray:
    """:func:`sample_von_mises` with a concentration per row of ``u`` (first axis), ``kappa`` (n,)."""
    if kappa.shape != u.shape[:1]:
        raise ValidationError("kappa", f"must have one value per row ({u.shape[0]}), got shape {kappa.shape}")
    mu = np.broadcast_to(np.asarray(mu, dtype=np.float64), u.shape)
    out = np.empty(u.shape)
    for k in np.unique(kappa):  # the distinct concentrations (one per roughness), not the samples
        rows = np.flatnonzero(kappa == k)
        out[rows] = sample_von_mises(u[rows], mu[rows], float(k))
    return out


# --------------------------------------------------------- emitters seen from a point
def sample_segment_direction(u: np.ndarray, x: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Direction from ``x`` to a point uniform (per unit length) on the segment a → b (emitter sampling).

    ``x``, ``a``, ``b`` broadcast against ``u`` with a trailing axis of 2. Returns the
    angle of $y - x$ with $y = a + u (b - a)$.
    """
    u = np.asarray(u, dtype=np.float64)
    a, b, x = (np.asarray(v, dtype=np.float64) for v in (a, b, x))
    y = a + u[..., None] * (b - a)
    return np.arctan2(y[..., 1] - x[..., 1], y[..., 0] - x[..., 0])


def pdf_segment_direction(phi: np.ndarray, x: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    r"""Angular density of :func:`sample_segment_direction`: $|x - y| / (ℓ |\cos θ_y|)$ (theory/radiometry).

    With $d = (\cos φ, \sin φ)$, $e = b - a$, $w = a - x$, the ray $x + s d$ meets the segment at
    $s = (w × e) / (d × e)$, and $dφ = |\cos θ_y| dℓ / s$ in 2D, so the density per radian
    of a point uniform on the length $ℓ = |e|$ is $s / |d × e| = |w × e| / (d × e)^2$. Zero
    where the ray from ``x`` misses the segment.
    """
    phi = np.asarray(phi, dtype=np.float64)
    a, b, x = (np.asarray(v, dtype=np.float64) for v in (a, b, x))
    dx, dy = np.cos(phi), np.sin(phi)
    ex, ey = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    wx, wy = a[..., 0] - x[..., 0], a[..., 1] - x[..., 1]
    den = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (wx * ey - wy * ex) / den
        u = (wx * dy - wy * dx) / den
        density = np.abs(wx * ey - wy * ex) / (den * den)
    inside = (den != 0.0) & (s > 0.0) & (u >= 0.0) & (u <= 1.0)
    return np.where(inside, density, 0.0)


def _circle_cone(x: np.ndarray, c: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""Angle of $c - x$ and the half-angle $\arcsin(\min(r / |c - x|, 1))$ the circle subtends from x."""
    vx, vy = c[..., 0] - x[..., 0], c[..., 1] - x[..., 1]
    dist = np.hypot(vx, vy)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(dist > r, r / np.where(dist > 0.0, dist, 1.0), 1.0)
    return np.arctan2(vy, vx), np.arcsin(ratio)


def sample_circle_direction(u: np.ndarray, x: np.ndarray, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    r"""Direction uniform in the cone of angles a circle (centre ``c``, radius ``r``) subtends from ``x``.

    $φ = \mathrm{angle}(c - x) + β (2u - 1)$ with $β = \arcsin(r / |c - x|)$ ($β = π/2$ from on or
    inside the circle).
    """
    u = np.asarray(u, dtype=np.float64)
    x, c, r = np.asarray(x, np.float64), np.asarray(c, np.float64), np.asarray(r, np.float64)
    base, beta = _circle_cone(x, c, r)
    return base + beta * (2.0 * u - 1.0)


def pdf_circle_direction(phi: np.ndarray, x: np.ndarray, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """$1 / (2β)$ inside the cone of :func:`sample_circle_direction`, 0 outside."""
    phi = np.asarray(phi, dtype=np.float64)
    x, c, r = np.asarray(x, np.float64), np.asarray(c, np.float64), np.asarray(r, np.float64)
    base, beta = _circle_cone(x, c, r)
    inside = np.abs(wrap_angle(phi - base)) <= beta
    return np.where(inside, 0.5 / np.where(beta > 0.0, beta, 1.0), 0.0)


# ------------------------------------------------------------------ pixel filters (the film line)
def filter_value(kind: str, t: Any, center: Any, width: float) -> Any:
    """Pixel filter $k_j(t)$ for pixel centres ``center`` and pixel width Δt (``t`` may be a Dual)."""
    x = t - center
    if kind == "box":
        return np.where(np.abs(detach(x)) <= 0.5 * width, 1.0 / width, 0.0)
    if kind == "tent":
        return np.maximum(1.0 - np.abs(x) / width, 0.0) / width
    sigma = 0.5 * width
    return np.exp(-0.5 * (x / sigma) * (x / sigma)) / (sigma * np.sqrt(2.0 * np.pi))


def filter_blurred(kind: str, y: np.ndarray, width: float, sigma: float) -> np.ndarray:
    r"""Density of $t + σ z$ ($t \sim$ pixel filter centred at 0, $z \sim N(0, 1)$) at offsets ``y``:
    $k ⊛ N(0, σ^2)$.

    Tent of radius w: $(R(y + w) - 2 R(y) + R(y - w)) / w^2$ with $R(y) = y Φ(y/σ) + σ φ(y/σ)$
    (the tent is a sum of ramps, and R is a ramp blurred by the Gaussian); Gaussian
    filter: $N(0, (w/2)^2 + σ^2)$.
    """
    y = np.asarray(y, dtype=np.float64)
    if kind == "gaussian":
        s2 = 0.25 * width * width + sigma * sigma
        return np.exp(-0.5 * y * y / s2) / np.sqrt(2.0 * np.pi * s2)
    if kind != "tent":
        raise ValueError(f"filter_blurred: no closed form for the {kind!r} filter")

    def ramp(z: np.ndarray) -> np.ndarray:
        return z * special.ndtr(z / sigma) + sigma * np.exp(-0.5 * (z / sigma) ** 2) / np.sqrt(2.0 * np.pi)

    return (ramp(y + width) - 2.0 * ramp(y) + ramp(y - width)) / (width * width)


def sample_filter(kind: str, u: np.ndarray, center: np.ndarray, width: float) -> np.ndarray:
    r"""Film samples $t \sim k_j$ from uniforms ``u`` (box: one pixel; tent: radius Δt;
    gaussian: $σ = Δt/2$).
    """
    if kind == "box":
        return sample_uniform(u, center - 0.5 * width, center + 0.5 * width)
    if kind == "tent":
        return sample_tent(u, center, width)
    return sample_gaussian(u, center, 0.5 * width)


def pdf_filter(kind: str, t: np.ndarray, center: np.ndarray, width: float) -> np.ndarray:
    """Density of :func:`sample_filter`'s samples ``t``: the filter $k_j$ itself (plain floats).

    Each pixel integral samples its own filter, so the density is :func:`filter_value`
    at the (θ-free) samples; the pair is checked by a chi-square test like every other.
    """
    return filter_value(kind, np.asarray(t, dtype=np.float64), center, width)
