"""Forward-mode (JVP) rules of the numpy ufuncs for :class:`~flatland.core.dual.Dual`.

One rule per ufunc, registered in the tables of :mod:`flatland.core.dual` by the
``_unary`` and ``_binary`` decorators: a unary rule maps ``(value, tangent)`` to the
result's ``(value, tangent)``, a binary rule maps the two operands (Duals or
constants) and calls :func:`_operands`, which lines up the tangents of a k-Dual (a leading
axis of k, :mod:`flatland.core.dual`) so that the same expressions broadcast over the k
slots. Derivatives that are infinite where the tangent is zero (``sqrt`` at 0,
``log`` at 0) are reported as 0 there, so a constant never turns into NaN.
:mod:`flatland.core.dual` imports this module, which registers the rules; the
array-function rules are in :mod:`flatland.core.dual_functions`.
"""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

from flatland.core.dual import Dual, _binary, _unary, detach, k_of

__all__: list[str] = []


def _zero_where_no_tangent(t: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """``t * scale`` with 0 wherever ``t == 0`` (so a singular ``scale`` there is harmless)."""
    with np.errstate(invalid="ignore", over="ignore"):
        out = t * scale
    return np.where(t == 0.0, 0.0, out)


def _safe_scale(t: np.ndarray, num: Any, den: np.ndarray) -> np.ndarray:
    """``t * num / den`` with 0 where ``t == 0``, quiet about 0/0 there."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        scale = num / den
    return _zero_where_no_tangent(t, scale)


def _vt(x: Any, ndim: int = 0) -> tuple[Any, Any]:
    """(value, tangent) of a Dual or of a constant (tangent 0 as a scalar, broadcasting); a k-Dual's
    tangent gets axes of length 1 after its k axis up to ``ndim`` value axes, so that it broadcasts
    against the other operand's value and tangent like the values do."""
    if isinstance(x, Dual):
        if x.k is not None and x.ndim < ndim:
            return x.value, x.tangent.reshape((x.k,) + (1,) * (ndim - x.ndim) + x.shape)
        return x.value, x.tangent
    if isinstance(x, numbers.Number):
        return float(x), 0.0
    return np.asarray(x, dtype=np.float64), 0.0


def _same(shape: tuple[int, ...]) -> tuple[int, ...]:
    return shape


def _operands(a: Any, b: Any) -> tuple[tuple[Any, Any], tuple[Any, Any], Any]:
    """:func:`_vt` of both operands, and the map from a result's value shape to its tangent's
    shape: the identity, or ``(k,) + shape`` for k-Duals (mixing a single and a k tangent raises)."""
    k = k_of(a, b)
    if k is None:
        return _vt(a), _vt(b), _same
    ndim = max(np.ndim(detach(a)), np.ndim(detach(b)))
    return _vt(a, ndim), _vt(b, ndim), lambda shape: (k, *shape)


def _shape_like(t: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``t`` as a writable float array of ``shape`` (tangents of constants are scalars)."""
    arr = np.asarray(t, dtype=np.float64)
    return arr if arr.shape == shape else np.broadcast_to(arr, shape).copy()


# ------------------------------------------------------------------- unary rules
_unary(np.negative)(lambda v, t: (-v, -t))
_unary(np.positive)(lambda v, t: (+v, +t))
_unary(np.exp)(lambda v, t: ((e := np.exp(v)), t * e))
_unary(np.expm1)(lambda v, t: (np.expm1(v), t * np.exp(v)))
_unary(np.log)(lambda v, t: (np.log(v), _safe_scale(t, 1.0, v)))
_unary(np.log1p)(lambda v, t: (np.log1p(v), _safe_scale(t, 1.0, 1.0 + v)))
_unary(np.sin)(lambda v, t: (np.sin(v), t * np.cos(v)))
_unary(np.cos)(lambda v, t: (np.cos(v), -t * np.sin(v)))
_unary(np.tan)(lambda v, t: ((y := np.tan(v)), t * (1.0 + y * y)))
_unary(np.sinh)(lambda v, t: (np.sinh(v), t * np.cosh(v)))
_unary(np.cosh)(lambda v, t: (np.cosh(v), t * np.sinh(v)))
_unary(np.tanh)(lambda v, t: ((y := np.tanh(v)), t * (1.0 - y * y)))
_unary(np.arctan)(lambda v, t: (np.arctan(v), t / (1.0 + v * v)))
_unary(np.square)(lambda v, t: (v * v, 2.0 * v * t))
_unary(np.absolute)(lambda v, t: (np.abs(v), t * np.sign(v)))
_unary(np.reciprocal)(lambda v, t: (1.0 / v, _safe_scale(t, -1.0, v * v)))


@_unary(np.sqrt)
def _sqrt(v, t):
    s = np.sqrt(v)
    # d sqrt(v) = t / (2 sqrt v); infinite at v = 0, reported as 0 where t = 0 there
    return s, _safe_scale(t, 0.5, s)


@_unary(np.cbrt)
def _cbrt(v, t):
    c = np.cbrt(v)
    return c, _safe_scale(t, 1.0, 3.0 * c * c)


@_unary(np.arcsin)
def _arcsin(v, t):
    return np.arcsin(v), _safe_scale(t, 1.0, np.sqrt(1.0 - v * v))


@_unary(np.arccos)
def _arccos(v, t):
    return np.arccos(v), _safe_scale(t, -1.0, np.sqrt(1.0 - v * v))


# ------------------------------------------------------------------ binary rules
@_binary(np.add)
def _add(a, b):
    (av, at), (bv, bt), full = _operands(a, b)
    return av + bv, _shape_like(at + bt, full(np.broadcast_shapes(np.shape(av), np.shape(bv))))


@_binary(np.subtract)
def _subtract(a, b):
    (av, at), (bv, bt), full = _operands(a, b)
    return av - bv, _shape_like(at - bt, full(np.broadcast_shapes(np.shape(av), np.shape(bv))))


@_binary(np.multiply)
def _multiply(a, b):
    (av, at), (bv, bt), full = _operands(a, b)
    # product rule: (ab)' = a' b + a b'
    return av * bv, _shape_like(at * bv + av * bt, full(np.broadcast_shapes(np.shape(av), np.shape(bv))))


@_binary(np.divide)
def _divide(a, b):
    (av, at), (bv, bt), full = _operands(a, b)
    q = av / bv
    # quotient rule: (a/b)' = (a' - q b') / b
    return q, _shape_like((at - q * bt) / bv, full(np.shape(q)))


@_binary(np.power)
def _power(a, b):
    (av, at), (bv, bt), full = _operands(a, b)
    y = np.power(av, bv)
    # d a^b = b a^(b-1) a' + a^b log(a) b'
    da = _zero_where_no_tangent(np.broadcast_to(at, full(y.shape)), bv * np.power(av, bv - 1.0))
    db = 0.0
    if isinstance(b, Dual):
        with np.errstate(divide="ignore", invalid="ignore"):
            log_a = np.log(av)
        db = _zero_where_no_tangent(np.broadcast_to(bt, full(y.shape)), y * log_a)
    return y, _shape_like(da + db, full(y.shape))


@_binary(np.arctan2)
def _arctan2(y, x):
    (yv, yt), (xv, xt), full = _operands(y, x)
    r2 = xv * xv + yv * yv
    # d atan2(y, x) = (x y' - y x') / (x^2 + y^2)
    return np.arctan2(yv, xv), _shape_like((xv * yt - yv * xt) / r2, full(np.shape(r2)))


@_binary(np.hypot)
def _hypot(a, b):
    (av, at), (bv, bt), full = _operands(a, b)
    h = np.hypot(av, bv)
    num = _shape_like(av * at + bv * bt, full(h.shape))
    return h, _safe_scale(num, 1.0, h)


@_binary(np.minimum, np.fmin)
def _minimum(a, b):
    (av, at), (bv, bt), _full = _operands(a, b)
    pick_a = av <= bv
    return np.where(pick_a, av, bv), np.where(pick_a, at, bt)


@_binary(np.maximum, np.fmax)
def _maximum(a, b):
    (av, at), (bv, bt), _full = _operands(a, b)
    pick_a = av >= bv
    return np.where(pick_a, av, bv), np.where(pick_a, at, bt)


@_binary(np.remainder)
def _remainder(a, b):
    (av, at), (bv, bt), full = _operands(a, b)
    r = np.remainder(av, bv)
    # a mod b = a - floor(a / b) b: tangent a' - floor(a / b) b'  (a.e.)
    return r, _shape_like(at - np.floor(av / bv) * bt, full(np.shape(r)))


@_binary(np.fmod)
def _fmod(a, b):
    (av, at), (bv, bt), full = _operands(a, b)
    r = np.fmod(av, bv)
    # fmod(a, b) = a - trunc(a / b) b  (a.e.)
    return r, _shape_like(at - np.trunc(av / bv) * bt, full(np.shape(r)))


@_binary(np.matmul)
def _matmul(a, b):
    (av, at), (bv, bt), full = _operands(a, b)
    y = np.matmul(av, bv)
    if full is not _same:  # k slots: each slot's product as for a single tangent
        t = np.zeros(full(y.shape))
        for i in range(len(t)):
            if isinstance(a, Dual):
                t[i] = t[i] + np.matmul(a.tangent[i], bv)
            if isinstance(b, Dual):
                t[i] = t[i] + np.matmul(av, b.tangent[i])
        return y, t
    t = np.zeros_like(y)
    if isinstance(a, Dual):
        t = t + np.matmul(at, bv)
    if isinstance(b, Dual):
        t = t + np.matmul(av, bt)
    return y, t
