"""Forward-mode automatic differentiation with numpy-compatible dual arrays.

A :class:`Dual` carries a primal ``value`` and a ``tangent`` (the derivative with
respect to one scalar parameter, usually the scene parameter theta) as two float64
arrays of the same shape. Every numpy ufunc and array function that rendering code
needs has one JVP rule (ufuncs in :mod:`flatland.core.dual_ufuncs`, array functions
in :mod:`flatland.core.dual_functions`), so estimator code reads like plain numpy::

    theta = Dual(0.3, 1.0)            # d theta / d theta = 1
    y = np.sin(theta * x) / np.hypot(x, theta)
    y.value, y.tangent                # f and df/dtheta at every x

Several parameters at once. A Dual built with ``k`` (an int >= 1) carries k tangents
on a leading axis, ``tangent.shape == (k,) + value.shape``: slot i is the derivative
with respect to parameter i, and every rule computes all k slots from the one
primal computation (the rays, probes and samples are shared). :func:`variables`
seeds them, parameter i with the unit tangent e_i::

    theta_x, theta_y = variables(2)   # tangents (1, 0) and (0, 1)
    y = np.sin(theta_x * x) + theta_y
    y.tangent[0], y.tangent[1]        # dy/dtheta_x and dy/dtheta_y at every x

With the tangent axis in front, numpy broadcasting applies the elementwise rules to
every slot unchanged (``t_dot * cos(v)`` broadcasts v over k); rules that take axes
(reductions, reshapes, stacking, indexing) shift them past the k axis. A classic
Dual has ``k = None`` and ``tangent.shape == value.shape``, computed by exactly the
same expressions as before k existed. Slot i of a k-Dual result equals, bit for bit,
the single tangent of the same computation seeded with e_i's slot alone, for every
rule (tests/flatland/test_multi_param.py). Combining a k-Dual with a classic Dual, or
two Duals of different k, raises ``TypeError``: the slots would not mean the same
parameters.

Comparisons act on values and return plain boolean arrays. Piecewise-constant
functions (``floor``, ``sign``, ...) return plain arrays: their derivative is zero
almost everywhere, which is exactly the term a moving discontinuity adds back
(Loubet et al. 2019, Sec. 3.2). Anything without a rule raises ``TypeError`` rather
than silently dropping the tangent; so does converting a Dual to a plain array, use
:func:`detach` for that.
"""

from __future__ import annotations

import operator
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = [
    "Dual",
    "as_dual",
    "detach",
    "is_dual",
    "k_of",
    "take_rows",
    "tangent",
    "variable",
    "variables",
]

_UNARY: dict[np.ufunc, Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]] = {}
_BINARY: dict[np.ufunc, Callable[..., tuple[np.ndarray, np.ndarray]]] = {}
_FUNCTIONS: dict[Callable[..., Any], Callable[..., Any]] = {}

# ufuncs whose result is piecewise constant or boolean: evaluated on values only.
_VALUE_ONLY = {
    np.greater, np.greater_equal, np.less, np.less_equal, np.equal, np.not_equal,
    np.isnan, np.isfinite, np.isinf, np.signbit, np.sign, np.floor, np.ceil,
    np.rint, np.trunc,
}  # fmt: skip


def take_rows(a: np.ndarray, index: Any) -> np.ndarray:
    """``a[index]``; rows by an integer array with ``np.take`` (the same elements, about 4 times faster than
    fancy indexing for (n, 3) arrays)."""
    if isinstance(index, np.ndarray) and index.dtype.kind in "iu" and np.ndim(a):
        return np.take(a, index, axis=0)
    return a[index]


def _is_advanced(item: Any) -> bool:
    return isinstance(item, np.ndarray | list)


def _slot_index(index: Any) -> tuple[Any, ...] | None:
    """The index of a k-Dual's tangent that selects what ``index`` selects of its value, in every slot
    (the k axis kept in front); None when numpy would move the selection's axes in front of k
    (advanced indices apart from each other, as in ``x[rows, :, cols]``)."""
    items = index if isinstance(index, tuple) else (index,)
    arrays = [i for i, e in enumerate(items) if _is_advanced(e)]
    if arrays:
        advanced = [i for i, e in enumerate(items) if _is_advanced(e) or isinstance(e, int | np.integer)]
        if advanced[-1] - advanced[0] + 1 != len(advanced):
            return None
    return (slice(None), *items)


def _index_tangent(t: np.ndarray, index: Any, ndim: int) -> np.ndarray:
    """``index`` applied to every slot of the tangent ``t`` (k, ...) of a value with ``ndim`` axes."""
    if isinstance(index, np.ndarray) and index.dtype.kind in "iu" and ndim:
        return np.take(t, index, axis=1)
    slot = _slot_index(index)
    if slot is None:
        return np.stack([s[index] for s in t])
    return t[slot]


def _check_k(k: Any) -> int:
    k = operator.index(k)
    if k < 1:
        raise ValueError(f"k: a Dual carries k >= 1 tangents, got {k}")
    return k


class Dual(np.lib.mixins.NDArrayOperatorsMixin):
    """A float64 array with a forward-mode tangent, or with k of them.

    Parameters
    ----------
    value : array_like
        Primal value.
    tangent : array_like, optional
        Derivative of ``value`` with respect to the scalar parameter; zeros if
        omitted. ``value`` and ``tangent`` are broadcast to one shape. With ``k``:
        the k derivatives, shape ``(k,) + value.shape`` (a leading axis of k), or a
        scalar for all of them.
    k : int, optional
        The number of parameters (tangent slots, >= 1); None (default): the classic
        single tangent of the value's shape.

    Notes
    -----
    Operators, numpy ufuncs (``np.sin(x)``) and the array functions listed in
    :data:`SUPPORTED_FUNCTIONS` dispatch to JVP rules. Indexing (including fancy
    indexing and boolean masks) and item assignment act on value and tangent alike
    (on every slot of a k-Dual).
    """

    __slots__ = ("k", "tangent", "value")
    __array_priority__ = 1000.0

    value: np.ndarray
    tangent: np.ndarray
    k: int | None

    def __init__(self, value: Any, tangent: Any = None, k: int | None = None) -> None:
        if isinstance(value, Dual) or isinstance(tangent, Dual):
            raise TypeError("Dual(value, tangent) takes plain arrays; got a Dual inside a Dual")
        v = np.asarray(value, dtype=np.float64)
        if k is not None:
            self.value, self.tangent, self.k = _with_slots(v, tangent, _check_k(k))
            return
        if tangent is None:
            t = np.zeros_like(v)
        else:
            t = np.asarray(tangent, dtype=np.float64)
            if t.shape != v.shape:
                v, t = np.broadcast_arrays(v, t)
                v, t = v.copy(), t.copy()
        self.value = v
        self.tangent = t
        self.k = None

    # ----------------------------------------------------------------- array protocol
    @property
    def shape(self) -> tuple[int, ...]:
        return self.value.shape

    @property
    def ndim(self) -> int:
        return self.value.ndim

    @property
    def size(self) -> int:
        return self.value.size

    @property
    def dtype(self) -> np.dtype:
        return self.value.dtype

    @property
    def T(self) -> Dual:  # noqa: N802 - numpy's name
        if self.k is None:
            return Dual(self.value.T, self.tangent.T)
        return self.transpose()

    def __len__(self) -> int:
        return len(self.value)

    def __iter__(self):
        for i in range(len(self)):
            yield self[i]

    def __getitem__(self, index: Any) -> Dual:
        if isinstance(index, Dual) or (isinstance(index, tuple) and any(isinstance(i, Dual) for i in index)):
            raise TypeError("a Dual cannot be used as an index; index with detach(x) instead")
        if self.k is None:
            return Dual(take_rows(self.value, index), take_rows(self.tangent, index))
        return Dual(take_rows(self.value, index), _index_tangent(self.tangent, index, self.ndim), self.k)

    def __setitem__(self, index: Any, item: Any) -> None:
        k_of(self, item)  # a classic Dual and a k-Dual do not mix
        self.value[index] = detach(item)
        if self.k is None:
            self.tangent[index] = tangent(item)
            return
        if not isinstance(item, Dual):
            t_dot: Any = 0.0
        else:  # the item's value axes right after k, aligned with the selection's trailing axes
            extra = np.ndim(self.value[index]) - item.ndim
            t_dot = item.tangent.reshape((self.k,) + (1,) * extra + item.shape) if extra > 0 else item.tangent
        slot = _slot_index(index)
        if slot is None:
            for i, s in enumerate(self.tangent):
                s[index] = t_dot if np.ndim(t_dot) == 0 else t_dot[i]
        else:
            self.tangent[slot] = t_dot

    def __repr__(self) -> str:
        k = "" if self.k is None else f", k={self.k}"
        return f"Dual(value={self.value!r}, tangent={self.tangent!r}{k})"

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        raise TypeError(
            "converting a Dual to a plain numpy array would drop its tangent; "
            "use detach(x) (or x.value) if that is what you mean"
        )

    def __float__(self) -> float:
        raise TypeError("float(Dual) would drop the tangent; use float(detach(x))")

    def __bool__(self) -> bool:
        raise TypeError("the truth value of a Dual is ambiguous; compare values, e.g. x > 0")

    __hash__ = None  # type: ignore[assignment]

    # ------------------------------------------------------------------- methods
    def reshape(self, *shape: Any, **kwargs: Any) -> Dual:
        if self.k is None:
            return Dual(self.value.reshape(*shape, **kwargs), self.tangent.reshape(*shape, **kwargs))
        return np.reshape(self, shape[0] if len(shape) == 1 else shape, **kwargs)

    def transpose(self, *axes: Any) -> Dual:
        if self.k is None:
            return Dual(self.value.transpose(*axes), self.tangent.transpose(*axes))
        return np.transpose(self, (axes[0] if len(axes) == 1 else axes) or None)

    def ravel(self) -> Dual:
        if self.k is None:
            return Dual(self.value.ravel(), self.tangent.ravel())
        return np.ravel(self)

    def copy(self) -> Dual:
        return Dual(self.value.copy(), self.tangent.copy(), self.k)

    def squeeze(self, axis: Any = None) -> Dual:
        if self.k is None:
            return Dual(self.value.squeeze(axis), self.tangent.squeeze(axis))
        return np.squeeze(self, axis)

    def sum(self, axis: Any = None, keepdims: bool = False) -> Dual:
        return np.sum(self, axis=axis, keepdims=keepdims)

    def mean(self, axis: Any = None, keepdims: bool = False) -> Dual:
        return np.mean(self, axis=axis, keepdims=keepdims)

    def max(self, axis: Any = None, keepdims: bool = False) -> Dual:
        return np.max(self, axis=axis, keepdims=keepdims)

    def min(self, axis: Any = None, keepdims: bool = False) -> Dual:
        return np.min(self, axis=axis, keepdims=keepdims)

    def dot(self, other: Any) -> Dual:
        return np.dot(self, other)

    # ------------------------------------------------------------------- dispatch
    def __array_ufunc__(self, ufunc: np.ufunc, method: str, *inputs: Any, **kwargs: Any) -> Any:
        out = kwargs.pop("out", None)
        if kwargs:
            raise TypeError(f"np.{ufunc.__name__}: keyword(s) {sorted(kwargs)} are not supported for Dual")
        if method != "__call__":
            raise TypeError(f"np.{ufunc.__name__}.{method} is not supported for Dual; use np.sum and friends")
        elif ufunc in _VALUE_ONLY:
            result = ufunc(*(detach(x) for x in inputs))
        elif ufunc in _UNARY:
            (x,) = inputs
            result = Dual(*_UNARY[ufunc](x.value, x.tangent), x.k)
        elif ufunc in _BINARY:
            a, b = inputs
            result = Dual(*_BINARY[ufunc](a, b), k_of(a, b))
        else:
            raise TypeError(
                f"np.{ufunc.__name__} has no forward-mode rule for Dual; "
                "apply it to detach(x) if the derivative is not needed"
            )
        if out is None:
            return result
        (target,) = out
        if isinstance(target, Dual):
            target[...] = result
            return target
        if isinstance(result, Dual):
            raise TypeError(
                f"np.{ufunc.__name__}: writing a Dual result into a plain array drops its tangent"
            )
        target[...] = result
        return target

    def __array_function__(self, func: Callable[..., Any], types: Any, args: Any, kwargs: Any) -> Any:
        rule = _FUNCTIONS.get(func)
        if rule is None:
            name = getattr(func, "__name__", str(func))
            raise TypeError(
                f"np.{name} is not supported for Dual (it would drop the tangent); "
                "apply it to detach(x), or add a rule in flatland.core.dual_functions"
            )
        return rule(*args, **kwargs)


def _with_slots(v: np.ndarray, tangent: Any, k: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Value and k-slot tangent of ``Dual(v, tangent, k)``, broadcast to ``(k,) + shape``."""
    if tangent is None:
        return v, np.zeros((k, *v.shape)), k
    t = np.asarray(tangent, dtype=np.float64)
    if t.ndim and t.shape[0] != k:
        raise ValueError(f"tangent: a Dual with k={k} needs a leading axis of {k}, got shape {t.shape}")
    shape = np.broadcast_shapes(v.shape, t.shape[1:])
    if v.shape != shape:
        v = np.broadcast_to(v, shape).copy()
    if t.shape != (k, *shape):
        t = np.broadcast_to(t, (k, *shape)).copy()
    return v, t, k


# ----------------------------------------------------------------------- helpers
def detach(x: Any) -> Any:
    """Value of ``x`` with the derivative dropped (plain arrays pass through)."""
    return x.value if isinstance(x, Dual) else x


def tangent(x: Any, k: int | None = None) -> Any:
    """Tangent of ``x``; zeros of the right shape for anything that is not a Dual (with ``k``: of shape
    ``(k,) + shape``, the tangent of a constant among k-Duals)."""
    if isinstance(x, Dual):
        return x.tangent
    if k is not None:
        return np.zeros((k, *np.shape(x)))
    return np.zeros_like(np.asarray(x, dtype=np.float64))


def k_of(*xs: Any) -> int | None:
    """The number of tangents the Duals among ``xs`` carry: their common ``k`` (None: classic single
    tangents, or no Dual at all).

    Raises
    ------
    TypeError
        If a classic Dual meets a k-Dual, or two k-Duals have different k.
    """
    duals = [x for x in xs if isinstance(x, Dual)]
    if not duals:
        return None
    k = duals[0].k
    for x in duals[1:]:
        if x.k != k:
            raise TypeError(
                f"a Dual with {_slots_name(k)} met one with {_slots_name(x.k)}: every Dual of one "
                "computation must carry the tangents of the same parameters"
            )
    return k


def _slots_name(k: int | None) -> str:
    return "a single tangent (k=None)" if k is None else f"k={k} tangents"


def is_dual(x: Any) -> bool:
    """True if ``x`` carries a tangent."""
    return isinstance(x, Dual)


def as_dual(x: Any, k: int | None = None) -> Dual:
    """``x`` as a Dual (a plain array gets a zero tangent; with ``k``: k zero tangents)."""
    if isinstance(x, Dual):
        if x.k != k:
            k_of(x, Dual(0.0, None, k))  # raises: the slots differ
        return x
    return Dual(x, None, k)


def variable(value: float | np.ndarray) -> Dual:
    """The independent variable: ``Dual(value, 1)`` (d value / d value = 1)."""
    return Dual(value, np.ones_like(np.asarray(value, dtype=np.float64)))


def variables(k: int, value: float = 0.0) -> tuple[Dual, ...]:
    """k independent scalar variables at ``value``: variable i has the unit tangent e_i, so slot i of
    anything computed from them is the derivative with respect to variable i."""
    k = _check_k(k)
    return tuple(Dual(value, np.eye(k)[i], k) for i in range(k))


def _unary(*ufuncs: np.ufunc):
    def register(rule):
        for u in ufuncs:
            _UNARY[u] = rule
        return rule

    return register


def _binary(*ufuncs: np.ufunc):
    def register(rule):
        for u in ufuncs:
            _BINARY[u] = rule
        return rule

    return register


def _implements(*funcs: Callable[..., Any]):
    def register(rule):
        for f in funcs:
            _FUNCTIONS[f] = rule
        return rule

    return register


# The rules live in their own modules; importing them fills the tables above.
from flatland.core import dual_functions as _dual_functions  # noqa: E402,F401
from flatland.core import dual_ufuncs as _dual_ufuncs  # noqa: E402,F401
