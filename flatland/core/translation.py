"""The building blocks of a reparameterized estimator, shared by flatland and sphere3d.

Loubet et al. 2019, "Reparameterizing Discontinuous Integrands for Differentiable
Rendering": the change of variables whose value is the identity (Sec. 3.2), the kernel
weight of a convolution (Sec. 4.2), the fallback to the identity where ray tracing
chose no point (Sec. 4.3), the paired-sample control variate of the authors'
implementation (theory/kernels) and the refusal of a box pixel filter
(theory/pixel_filters); plus the central finite difference the methods are
checked against (not part of the paper).

Dimension-free: every function works on arrays of any shape and on
:class:`~flatland.core.dual.Dual` alike. The expressions are written in the order
the estimators have always evaluated them, so the numbers stay the same bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from flatland.core.dual import detach
from flatland.core.validate import ValidationError

__all__ = [
    "SMALL_WEIGHT",
    "central_difference",
    "check_continuous_filter",
    "control_variate",
    "paired_combine",
    "translation_offset",
    "unit_weight",
]

SMALL_WEIGHT = 1e-5
"""Paired weights with $|w|$ below this count as 1 (the authors' implementation, theory/kernels)."""


def translation_offset(c: Any, ok: Any = None) -> Any:
    r"""The translation offset $Δ = c(θ) - \mathrm{detach}(c(θ))$: value 0, derivative $c'(θ)$.

    A sample y evaluated at $T(y, θ) = y + Δ$ is where it was at θ0 (T is the
    identity there, so the primal is the naive one) and moves like the point c
    (Loubet et al. 2019, Sec. 3.2). The same difference $x - \mathrm{detach}(x)$
    is the zero-value part of a weight in :func:`control_variate`.

    Parameters
    ----------
    c : Dual or ndarray
        The coordinate the transform follows (a film coordinate, an angle, a
        discontinuity's location), one per sample.
    ok : ndarray of bool, optional
        Where a point to follow was found. Elsewhere the offset is an exact 0 (value
        and derivative): the identity transform, which ray tracing falls back to
        when the probes chose nothing (Loubet et al. 2019, Sec. 4.3).

    Returns
    -------
    Dual or ndarray
        Δ, shaped like ``c``.
    """
    if ok is None:
        return c - detach(c)
    return np.where(ok, c - detach(c), 0.0)


def unit_weight(log_k: Any) -> Any:
    r"""The kernel weight $w = k / \mathrm{detach}(k)$ from $\log k$: value exactly 1, derivative $(\log k)'$.

    A convolution kernel $k(T μ, ω)$ evaluated at the transformed sample carries the
    derivative the transform gives the kernel (Loubet et al. 2019, Sec. 4.2). Computed as
    $\exp(\log k - \mathrm{detach}(\log k))$: a kernel value that underflows to 0 cannot make 0/0,
    and any additive constant of $\log k$ (a normalization) cancels, so callers may pass an
    unnormalized log-kernel such as $κ \cos$.

    Parameters
    ----------
    log_k : Dual or ndarray
        $\log k$ at the evaluation points.

    Returns
    -------
    Dual or ndarray
        The weight; its value is exactly 1 wherever ``log_k`` is finite.
    """
    return np.exp(log_k - detach(log_k))


def control_variate(e: Any, scale: Any, w: Any) -> Any:
    r"""$e - scale · (w - \mathrm{detach}(w))$: the estimate e with the weight's derivative as
    control variate.

    $w - \mathrm{detach}(w)$ has value 0 and, for a weight whose derivative has zero mean
    (a kernel or filter weight: its integral is 1 for every θ), zero expectation.
    Subtracting it times a ``scale`` independent of w keeps the expectation of e,
    value and derivative, and cancels the noise $scale · w'$ when scale tracks e
    (theory/monte_carlo; the authors' implementation uses it for paired samples, theory/kernels).
    The value is e's bit for bit: an exact zero is subtracted.

    Parameters
    ----------
    e : Dual or ndarray
        Per-sample estimates.
    scale : Dual or ndarray
        The control variate's coefficient, independent of ``w``'s derivative.
    w : Dual or ndarray
        Weights of value 1 (:func:`unit_weight`).

    Returns
    -------
    Dual or ndarray
        The controlled estimates.
    """
    return e - scale * (w - detach(w))


def paired_combine(e0: Any, e1: Any, w0: Any, w1: Any) -> Any:
    r"""Two members of a pair serve as each other's control variate (authors' implementation, theory/kernels).

    $0.5 (e0 - e1 / w1 (w0 - \mathrm{detach}(w0))) + 0.5 (e1 - e0 / w0 (w1 - \mathrm{detach}(w1)))$:
    both members share one transform and are drawn from one kernel centre
    (Loubet et al. 2019, Sec. 4.2); each weight's derivative has zero mean given the
    centre and is independent of the other member, whose unweighted estimate
    $e / w$ scales it (:func:`control_variate`).

    Weights with ``|w| < SMALL_WEIGHT`` (1e-5) count as 1 (value 1, derivative 0)
    in this formula, as in the authors' implementation: no division by a vanishing
    weight. A weight from :func:`unit_weight` has value exactly 1 (or NaN where the
    kernel's logarithm is not finite), so the guard never changes its numbers.

    Parameters
    ----------
    e0, e1 : Dual or ndarray
        The members' estimates, already multiplied by their weights.
    w0, w1 : Dual or ndarray
        The members' weights (value 1).

    Returns
    -------
    Dual or ndarray
        One estimate per pair.
    """
    w0 = np.where(np.abs(detach(w0)) < SMALL_WEIGHT, 1.0, w0)
    w1 = np.where(np.abs(detach(w1)) < SMALL_WEIGHT, 1.0, w1)
    return 0.5 * control_variate(e0, e1 / w1, w0) + 0.5 * control_variate(e1, e0 / w0, w1)


def check_continuous_filter(kind: str) -> None:
    """Refuse a box pixel filter for a reparameterized pixel integral (theory/pixel_filters).

    Translating or rotating the film samples (Loubet et al. 2019, Sec. 4.1) moves
    them across the pixel's footprint; a box filter's edges then become moving
    discontinuities that no transform follows, and the gradient is biased.

    Parameters
    ----------
    kind : str
        The camera's pixel filter (``"box"``, ``"tent"`` or ``"gaussian"``).

    Raises
    ------
    ValidationError
        For ``"box"``, naming the field ``camera.filter``.
    """
    if kind == "box":
        raise ValidationError(
            "camera.filter",
            "the reparam method needs a continuous pixel filter, got 'box': reparameterizing the film "
            "moves samples across the box's edges, which become moving discontinuities "
            "(docs/theory/pixel_filters); "
            "use 'tent' or 'gaussian'",
        )


def central_difference(f: Callable[[float], Any], theta: float, h: float) -> Any:
    """$[f(θ + h) - f(θ - h)] / 2h$, evaluating f at θ + h first.

    With common random numbers (f draws the same samples at every θ) the difference
    only sees the samples whose integrand changed. Its expectation is exactly
    $[I(θ + h) - I(θ - h)] / 2h = I'(θ) + h^2 I'''(θ) / 6 + O(h^4)$: exact for a
    polynomial of degree <= 2 up to rounding. Not part of the paper: the reference
    the other methods are checked against.

    The default steps are each package's and differ (changing one changes every
    number it produces): flatland's images use h = 1e-3, flatland's textbook
    integrals and sphere3d's renders h = 1e-2. The trade-off is the same everywhere,
    a truncation bias ~ $h^2$ against a variance ~ $1/h$ at discontinuities (common
    random numbers); the image steps were chosen per package, not from one rule.

    Parameters
    ----------
    f : callable
        θ -> estimate (float or array; each call must use the same random numbers).
    theta : float
        Where to differentiate.
    h : float
        The step, > 0.

    Returns
    -------
    float or ndarray
        The central difference, shaped like f's result.
    """
    plus = f(theta + h)
    minus = f(theta - h)
    return (plus - minus) / (2.0 * h)
