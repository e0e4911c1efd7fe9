"""JVP rules for numpy array functions (``np.sum``, ``np.where``, ``np.cross``, ...).

Linear functions (reductions, reshapes, stacking, gathers) act on value and
tangent alike. Multilinear ones (``dot``, ``cross``, ``einsum``) use the product
rule. Selections (``where``, ``clip``, ``max``, ``sort``) pick the tangent of the
selected entry. The table :data:`SUPPORTED_FUNCTIONS` lists what is covered; any
other numpy function raises ``TypeError`` when given a Dual.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from flatland.core.dual import _FUNCTIONS, Dual, _implements, detach, tangent

__all__ = ["SUPPORTED_FUNCTIONS"]


def _any_dual(items: Sequence[Any]) -> bool:
    return any(isinstance(x, Dual) for x in items)


def _linear_single(func: Callable[..., Any]) -> Callable[..., Any]:
    """Rule for a function linear in its first argument: $f(x)' = f(x')$."""

    def rule(a: Any, *args: Any, **kwargs: Any) -> Dual:
        return Dual(func(detach(a), *args, **kwargs), func(tangent(a), *args, **kwargs))

    return rule


def _linear_sequence(func: Callable[..., Any]) -> Callable[..., Any]:
    """Rule for a function linear in a sequence of arrays (stack, concatenate, ...)."""

    def rule(arrays: Sequence[Any], *args: Any, **kwargs: Any) -> Dual:
        arrays = list(arrays)
        values = [detach(a) for a in arrays]
        tangents = [tangent(a) for a in arrays]
        return Dual(func(values, *args, **kwargs), func(tangents, *args, **kwargs))

    return rule


for _f in (
    np.sum, np.mean, np.cumsum, np.diff, np.reshape, np.transpose, np.swapaxes,
    np.moveaxis, np.expand_dims, np.squeeze, np.ravel, np.flip, np.roll, np.repeat,
    np.tile, np.broadcast_to, np.atleast_1d, np.take, np.diagonal, np.trace, np.copy,
    np.real, np.rot90,
):  # fmt: skip
    _implements(_f)(_linear_single(_f))

for _f in (np.stack, np.concatenate, np.hstack, np.vstack, np.column_stack):
    _implements(_f)(_linear_sequence(_f))


@_implements(np.take_along_axis)
def _take_along_axis(arr: Any, indices: Any, axis: Any) -> Dual:
    return Dual(
        np.take_along_axis(detach(arr), indices, axis), np.take_along_axis(tangent(arr), indices, axis)
    )


@_implements(np.shape)
def _shape(a: Any) -> tuple[int, ...]:
    return np.shape(detach(a))


@_implements(np.ndim)
def _ndim(a: Any) -> int:
    return np.ndim(detach(a))


@_implements(np.size)
def _size(a: Any, axis: Any = None) -> int:
    return np.size(detach(a), axis)


def _values_only(func: Callable[..., Any]) -> Callable[..., Any]:
    """Rule for functions of values alone (index results, booleans, new arrays)."""

    def rule(*args: Any, **kwargs: Any) -> Any:
        args = tuple(detach(a) for a in args)
        kwargs = {k: detach(v) for k, v in kwargs.items()}
        return func(*args, **kwargs)

    return rule


for _f in (
    np.argmax, np.argmin, np.argsort, np.argpartition, np.searchsorted, np.nonzero,
    np.isclose, np.allclose, np.all, np.any, np.zeros_like, np.ones_like, np.empty_like,
    np.full_like, np.count_nonzero, np.flatnonzero, np.array_equal, np.result_type,
):  # fmt: skip
    _implements(_f)(_values_only(_f))


@_implements(np.broadcast_arrays)
def _broadcast_arrays(*arrays: Any) -> list[Any]:
    shape = np.broadcast_shapes(*(np.shape(detach(a)) for a in arrays))
    return [np.broadcast_to(a, shape) for a in arrays]


@_implements(np.where)
def _where(condition: Any, x: Any = None, y: Any = None) -> Any:
    if isinstance(condition, Dual):
        raise TypeError("np.where: the condition is a Dual; compare values first, e.g. np.where(x > 0, ...)")
    if x is None and y is None:
        return np.where(condition)
    return Dual(np.where(condition, detach(x), detach(y)), np.where(condition, tangent(x), tangent(y)))


@_implements(np.clip)
def _clip(a: Any, a_min: Any = None, a_max: Any = None, **kwargs: Any) -> Dual:
    if kwargs:
        raise TypeError(f"np.clip: keyword(s) {sorted(kwargs)} are not supported for Dual")
    out = Dual(detach(a), tangent(a))
    if a_min is not None:
        out = np.maximum(out, a_min)
    if a_max is not None:
        out = np.minimum(out, a_max)
    return out


def _select_reduction(arg: Callable[..., Any]) -> Callable[..., Any]:
    """max/min: the tangent of the selected entry."""

    def rule(a: Any, axis: Any = None, keepdims: bool = False, **kwargs: Any) -> Dual:
        if kwargs:
            raise TypeError(f"keyword(s) {sorted(kwargs)} are not supported for Dual")
        v, t = detach(a), tangent(a)
        if axis is None:
            v, t, axis = v.ravel(), t.ravel(), 0
        idx = np.expand_dims(arg(v, axis=axis), axis)
        out = Dual(np.take_along_axis(v, idx, axis), np.take_along_axis(t, idx, axis))
        return out if keepdims else out.squeeze(axis)

    return rule


_implements(np.max, np.amax)(_select_reduction(np.argmax))
_implements(np.min, np.amin)(_select_reduction(np.argmin))


@_implements(np.sort)
def _sort(a: Any, axis: int = -1) -> Dual:
    order = np.argsort(detach(a), axis=axis)
    return Dual(np.take_along_axis(detach(a), order, axis), np.take_along_axis(tangent(a), order, axis))


def _product_rule(func: Callable[..., Any]) -> Callable[..., Any]:
    """Rule for a function linear in each of its two leading arguments."""

    def rule(a: Any, b: Any, *args: Any, **kwargs: Any) -> Dual:
        av, bv = detach(a), detach(b)
        value = func(av, bv, *args, **kwargs)
        t = np.zeros_like(value, dtype=np.float64)
        if isinstance(a, Dual):
            t = t + func(a.tangent, bv, *args, **kwargs)
        if isinstance(b, Dual):
            t = t + func(av, b.tangent, *args, **kwargs)
        return Dual(value, t)

    return rule


for _f in (np.dot, np.cross, np.inner, np.outer, np.vdot, np.tensordot, np.kron):
    _implements(_f)(_product_rule(_f))


@_implements(np.einsum)
def _einsum(subscripts: str, *operands: Any, **kwargs: Any) -> Dual:
    values = [detach(x) for x in operands]
    value = np.einsum(subscripts, *values, **kwargs)
    t = np.zeros_like(value, dtype=np.float64)
    # multilinear: sum over operands of einsum with that operand replaced by its tangent
    for i, x in enumerate(operands):
        if isinstance(x, Dual):
            t = t + np.einsum(subscripts, *values[:i], x.tangent, *values[i + 1 :], **kwargs)
    return Dual(value, t)


@_implements(np.linalg.norm)
def _norm(x: Any, ord: Any = None, axis: Any = None, keepdims: bool = False) -> Dual:
    if ord not in (None, 2, "fro") or (ord == 2 and axis is None and np.ndim(detach(x)) > 1):
        raise TypeError(f"np.linalg.norm: only the Euclidean norm is supported for Dual (got ord={ord!r})")
    return np.sqrt(np.sum(x * x, axis=axis, keepdims=keepdims))


@_implements(np.interp)
def _interp(x: Any, xp: Any, fp: Any, left: Any = None, right: Any = None, period: Any = None) -> Dual:
    if isinstance(xp, Dual) or isinstance(fp, Dual):
        raise TypeError("np.interp: only x may be a Dual (the table xp, fp must be constant)")
    xv = detach(x)
    value = np.interp(xv, xp, fp, left, right, period)
    xp, fp = np.asarray(xp, np.float64), np.asarray(fp, np.float64)
    slopes = np.diff(fp) / np.diff(xp)
    seg = np.clip(np.searchsorted(xp, xv, side="right") - 1, 0, len(slopes) - 1)
    inside = (xv >= xp[0]) & (xv <= xp[-1])
    # piecewise linear: derivative is the slope of the segment x falls in, 0 outside the table
    return Dual(value, np.where(inside, slopes[seg], 0.0) * tangent(x))


SUPPORTED_FUNCTIONS: tuple[str, ...] = tuple(sorted({getattr(f, "__name__", str(f)) for f in _FUNCTIONS}))
"""Names of the numpy array functions that accept a :class:`Dual`."""
