"""JVP rules for numpy array functions (``np.sum``, ``np.where``, ``np.cross``, ...).

Linear functions (reductions, reshapes, stacking, gathers) act on value and
tangent alike. Multilinear ones (``dot``, ``cross``, ``einsum``) use the product
rule. Selections (``where``, ``clip``, ``max``, ``sort``) pick the tangent of the
selected entry. The table :data:`SUPPORTED_FUNCTIONS` lists what is covered; any
other numpy function raises ``TypeError`` when given a Dual.

A k-Dual's tangent has a leading axis of k (:mod:`flatland.core.dual`): the rules shift
the axes they are given past it (:func:`_shift`), or apply the function to each slot
(:func:`_per_slot`): the sums, whose rounding depends on the array's shape, and what
rendering code rarely gives a k-Dual (products, ``einsum``, ``tile``, ...). Either way slot
i is, bit for bit, what the rule gives a single tangent.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from flatland.core.dual import _FUNCTIONS, Dual, _implements, detach, k_of, tangent

__all__ = ["SUPPORTED_FUNCTIONS"]


def _any_dual(items: Sequence[Any]) -> bool:
    return any(isinstance(x, Dual) for x in items)


def _shift(axis: Any, ndim: int) -> Any:
    """A value's axis (int, tuple or None) as an axis of its k-slot tangent: non-negative axes move
    one place up, negative ones count from the end as before; None is every value axis."""
    if axis is None:
        return tuple(range(1, ndim + 1))
    if isinstance(axis, tuple | list):
        return tuple(_shift(a, ndim) for a in axis)
    return axis + 1 if axis >= 0 else axis


def _per_slot(func: Callable[..., Any], t: np.ndarray, *args: Any, **kwargs: Any) -> np.ndarray:
    """``func`` applied to each slot of the tangent ``t`` (k, ...), stacked."""
    return np.stack([func(s, *args, **kwargs) for s in t])


def _flat(t: np.ndarray) -> np.ndarray:
    """Each slot flattened: (k, size)."""
    return t.reshape(len(t), -1)


def _modulo(axes: Any, ndim: int) -> Any:
    """Axes (int or sequence) as non-negative axes of an array with ``ndim`` axes."""
    return axes % ndim if np.ndim(axes) == 0 else [x % ndim for x in axes]


def _flat_if_none(func: Callable[..., Any]) -> Callable[..., np.ndarray]:
    """Slots of a function whose ``axis=None`` means the flattened array (cumsum, take, repeat)."""

    def slots(a: Dual, *args: Any, axis: Any = None, **kwargs: Any) -> np.ndarray:
        if axis is None:
            return func(_flat(a.tangent), *args, axis=1, **kwargs)
        return func(a.tangent, *args, axis=_shift(axis, a.ndim), **kwargs)

    return slots


def _reshape(a: Dual, shape: Any = None, *args: Any, **kwargs: Any) -> np.ndarray:
    shape = kwargs.pop("newshape", shape)
    if args or kwargs.get("order", "C") != "C":
        return _per_slot(np.reshape, a.tangent, shape, *args, **kwargs)
    return a.tangent.reshape((len(a.tangent), *np.shape(np.reshape(a.value, shape))))


def _transpose(a: Dual, axes: Any = None) -> np.ndarray:
    order = range(a.ndim - 1, -1, -1) if axes is None else _modulo(axes, a.ndim)
    return np.transpose(a.tangent, (0, *(x + 1 for x in order)))


def _squeeze(a: Dual, axis: Any = None) -> np.ndarray:
    if axis is None:  # the value's axes of length 1, never the k axis (k may be 1)
        axis = tuple(i for i, n in enumerate(a.shape) if n == 1)
    return np.squeeze(a.tangent, _shift(axis, a.ndim))


def _broadcast_to(a: Dual, shape: Any, **kwargs: Any) -> np.ndarray:
    shape = (shape,) if np.ndim(shape) == 0 else tuple(shape)
    t = a.tangent.reshape((len(a.tangent),) + (1,) * (len(shape) - a.ndim) + a.shape)
    return np.broadcast_to(t, (len(t), *shape), **kwargs)


def _axis_pair(func: Callable[..., Any]) -> Callable[..., np.ndarray]:
    """Slots of swapaxes and moveaxis: both axis arguments shifted."""

    def slots(a: Dual, first: Any, second: Any) -> np.ndarray:
        first, second = _modulo(first, a.ndim), _modulo(second, a.ndim)
        return func(a.tangent, _shift(first, a.ndim), _shift(second, a.ndim))

    return slots


_SLOTS: dict[Callable[..., Any], Callable[..., np.ndarray]] = {
    np.flip: lambda a, axis=None: np.flip(a.tangent, _shift(axis, a.ndim)),
    np.expand_dims: lambda a, axis: np.expand_dims(a.tangent, _shift(axis, a.ndim)),
    np.diff: lambda a, n=1, axis=-1: np.diff(a.tangent, n, axis=_shift(axis, a.ndim)),
    np.cumsum: lambda a, axis=None, *args, **kw: _flat_if_none(np.cumsum)(a, *args, axis=axis, **kw),
    np.take: lambda a, indices, axis=None, *args, **kw: _flat_if_none(np.take)(a, indices, axis=axis, **kw),
    np.repeat: lambda a, repeats, axis=None: _flat_if_none(np.repeat)(a, repeats, axis=axis),
    np.reshape: _reshape,
    np.ravel: lambda a, order="C": (
        _flat(a.tangent) if order == "C" else _per_slot(np.ravel, a.tangent, order)
    ),
    np.transpose: _transpose,
    np.squeeze: _squeeze,
    np.swapaxes: _axis_pair(np.swapaxes),
    np.moveaxis: _axis_pair(np.moveaxis),
    np.broadcast_to: _broadcast_to,
    np.copy: lambda a, *args, **kw: a.tangent.copy(),
    np.real: lambda a: a.tangent,
}
"""k-slot tangents of the linear functions that shift their axes; the others apply to each slot
(:func:`_per_slot`): roll, tile, atleast_1d, diagonal, trace, rot90, and the sums (``sum``,
``mean``): numpy adds along an axis in an order that depends on the array's other axes (pairwise
along the inner loop, in sequence along an outer one), so a sum over all k slots at once could
round differently from each slot's own."""


def _linear_single(func: Callable[..., Any]) -> Callable[..., Any]:
    """Rule for a function linear in its first argument: $f(x)' = f(x')$."""

    def rule(a: Any, *args: Any, **kwargs: Any) -> Dual:
        if isinstance(a, Dual) and a.k is not None:
            slots = _SLOTS.get(func)
            t = slots(a, *args, **kwargs) if slots else _per_slot(func, a.tangent, *args, **kwargs)
            return Dual(func(a.value, *args, **kwargs), t, a.k)
        return Dual(func(detach(a), *args, **kwargs), func(tangent(a), *args, **kwargs))

    return rule


def _sequence_slots(func: Callable[..., Any], arrays: list, k: int, args: tuple, kwargs: dict) -> np.ndarray:
    """The tangent of ``func(arrays, ...)`` (stack, concatenate, ...) for k-Duals among ``arrays``."""
    tangents = [tangent(a, k) for a in arrays]
    if func in (np.stack, np.concatenate) and len(args) <= 1 and set(kwargs) <= {"axis"}:
        axis = args[0] if args else kwargs.get("axis", 0)
        if func is np.concatenate and axis is None:
            return np.concatenate([_flat(t) for t in tangents], axis=1)
        return func(tangents, axis=_shift(axis, 0))
    return np.stack([func([t[i] for t in tangents], *args, **kwargs) for i in range(k)])


def _linear_sequence(func: Callable[..., Any]) -> Callable[..., Any]:
    """Rule for a function linear in a sequence of arrays (stack, concatenate, ...)."""

    def rule(arrays: Sequence[Any], *args: Any, **kwargs: Any) -> Dual:
        arrays = list(arrays)
        values = [detach(a) for a in arrays]
        k = k_of(*arrays)
        if k is not None:
            return Dual(func(values, *args, **kwargs), _sequence_slots(func, arrays, k, args, kwargs), k)
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


def _along(t: np.ndarray, indices: Any, axis: Any) -> np.ndarray:
    """``np.take_along_axis`` on every slot of a k-slot tangent."""
    if axis is None:
        return np.take_along_axis(_flat(t), np.asarray(indices)[None], 1)
    return np.take_along_axis(t, np.asarray(indices)[None], _shift(axis, 0))


@_implements(np.take_along_axis)
def _take_along_axis(arr: Any, indices: Any, axis: Any) -> Dual:
    if isinstance(arr, Dual) and arr.k is not None:
        return Dual(np.take_along_axis(arr.value, indices, axis), _along(arr.tangent, indices, axis), arr.k)
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
    k = k_of(x, y)
    if k is not None:
        value = np.where(condition, detach(x), detach(y))
        return Dual(value, np.where(condition, _lined_up(x, value.ndim), _lined_up(y, value.ndim)), k)
    return Dual(np.where(condition, detach(x), detach(y)), np.where(condition, tangent(x), tangent(y)))


def _lined_up(x: Any, ndim: int) -> Any:
    """A k-Dual's tangent with axes of length 1 after k up to ``ndim`` value axes (broadcasting like
    the values); 0 for a constant."""
    if not isinstance(x, Dual):
        return 0.0
    return x.tangent.reshape((x.k,) + (1,) * (ndim - x.ndim) + x.shape)


@_implements(np.clip)
def _clip(a: Any, a_min: Any = None, a_max: Any = None, **kwargs: Any) -> Dual:
    if kwargs:
        raise TypeError(f"np.clip: keyword(s) {sorted(kwargs)} are not supported for Dual")
    k = k_of(a, a_min, a_max)
    out = Dual(detach(a), tangent(a, k), k)
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
        k = a.k if isinstance(a, Dual) else None
        if axis is None:
            v, t, axis = v.ravel(), (t.ravel() if k is None else _flat(t)), 0
        idx = np.expand_dims(arg(v, axis=axis), axis)
        if k is not None:
            out = Dual(np.take_along_axis(v, idx, axis), _along(t, idx, axis), k)
        else:
            out = Dual(np.take_along_axis(v, idx, axis), np.take_along_axis(t, idx, axis))
        return out if keepdims else out.squeeze(axis)

    return rule


_implements(np.max, np.amax)(_select_reduction(np.argmax))
_implements(np.min, np.amin)(_select_reduction(np.argmin))


@_implements(np.sort)
def _sort(a: Any, axis: int = -1) -> Dual:
    order = np.argsort(detach(a), axis=axis)
    if isinstance(a, Dual) and a.k is not None:
        return Dual(np.take_along_axis(a.value, order, axis), _along(a.tangent, order, axis), a.k)
    return Dual(np.take_along_axis(detach(a), order, axis), np.take_along_axis(tangent(a), order, axis))


def _product_rule(func: Callable[..., Any]) -> Callable[..., Any]:
    """Rule for a function linear in each of its two leading arguments."""

    def rule(a: Any, b: Any, *args: Any, **kwargs: Any) -> Dual:
        av, bv = detach(a), detach(b)
        value = func(av, bv, *args, **kwargs)
        k = k_of(a, b)
        if k is not None:  # each slot as for a single tangent
            t = np.zeros((k, *np.shape(value)))
            for i in range(k):
                if isinstance(a, Dual):
                    t[i] = t[i] + func(a.tangent[i], bv, *args, **kwargs)
                if isinstance(b, Dual):
                    t[i] = t[i] + func(av, b.tangent[i], *args, **kwargs)
            return Dual(value, t, k)
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
    k = k_of(*operands)
    if k is not None:  # each slot as for a single tangent
        t = np.zeros((k, *np.shape(value)))
        for j in range(k):
            for i, x in enumerate(operands):
                if isinstance(x, Dual):
                    t[j] = t[j] + np.einsum(subscripts, *values[:i], x.tangent[j], *values[i + 1 :], **kwargs)
        return Dual(value, t, k)
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
    return Dual(value, np.where(inside, slopes[seg], 0.0) * tangent(x), getattr(x, "k", None))


SUPPORTED_FUNCTIONS: tuple[str, ...] = tuple(sorted({getattr(f, "__name__", str(f)) for f in _FUNCTIONS}))
"""Names of the numpy array functions that accept a :class:`Dual`."""
