"""Small vector helpers for arrays of 3D vectors (last axis of length 3), Dual or plain.

Each helper is written once with numpy functions that have forward-mode rules
(:mod:`flatland.core.dual`), so the same line computes a plain value or a value
with its θ-tangent. Norms use ``sqrt(einsum)`` in both cases, so a plain and a Dual
evaluation of the same input give bit-identical values. :func:`cross` writes its tangent out (the
same numbers as the rules, without a Dual per product).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach, k_of

__all__ = ["cross", "dot", "frame", "norm", "normalize", "scatter", "zeros"]


def dot(a: Any, b: Any) -> Any:
    """Row-wise dot product over the last axis."""
    return np.einsum("...i,...i->...", a, b)


def cross(a: Any, b: Any) -> Any:
    """Row-wise cross product over the last axis (by components: ``np.cross`` copies its inputs).

    With a Dual operand the tangent is written out: the numbers of the Dual rules for ``*`` and ``-``
    (a plain operand's tangent a scalar 0, as there), without a Dual per product.
    """
    if not (isinstance(a, Dual) or isinstance(b, Dual)):
        return _cross(a, b)
    k = k_of(a, b)
    if k is not None:  # k tangents: each lined up after its k axis to the result's value axes
        ndim = max(np.ndim(detach(a)), np.ndim(detach(b)))
        (a, a_dot), (b, b_dot) = _parts(a, ndim), _parts(b, ndim)
    else:
        (a, a_dot), (b, b_dot) = _parts(a), _parts(b)
    a0, a1, a2 = _columns(a)
    b0, b1, b2 = _columns(b)
    a0_dot, a1_dot, a2_dot = _columns(a_dot)
    b0_dot, b1_dot, b2_dot = _columns(b_dot)
    # (x y)' = x' y + x y' for each product, then (x y - z w)' = (x y)' - (z w)'
    t0 = (a1_dot * b2 + a1 * b2_dot) - (a2_dot * b1 + a2 * b1_dot)
    t1 = (a2_dot * b0 + a2 * b0_dot) - (a0_dot * b2 + a0 * b2_dot)
    t2 = (a0_dot * b1 + a0 * b1_dot) - (a1_dot * b0 + a1 * b0_dot)
    return Dual(_cross(a, b), np.stack(np.broadcast_arrays(t0, t1, t2), axis=-1), k)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a0, a1, a2 = _columns(a)
    b0, b1, b2 = _columns(b)
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _parts(x: Any, ndim: int | None = None) -> tuple[np.ndarray, Any]:
    """(value, tangent) of a Dual; a plain array's tangent is the scalar 0, as in the Dual rules. With
    ``ndim``: a k-Dual's tangent (k, ...) gets axes of length 1 after k up to ``ndim`` value axes, so it
    broadcasts against the other operand's value like the values do (each slot's numbers unchanged)."""
    if not isinstance(x, Dual):
        return np.asarray(x, dtype=np.float64), 0.0
    if ndim is not None and x.ndim < ndim:
        return x.value, x.tangent.reshape((x.k,) + (1,) * (ndim - x.ndim) + x.shape)
    return x.value, x.tangent


def _columns(x: Any) -> tuple[Any, Any, Any]:
    """The three components of vectors (..., 3); a scalar (a constant's tangent) three times."""
    return (x, x, x) if np.ndim(x) == 0 else (x[..., 0], x[..., 1], x[..., 2])


def norm(a: Any) -> Any:
    """Euclidean length over the last axis."""
    return np.sqrt(dot(a, a))


def normalize(a: Any) -> Any:
    """$a / |a|$ over the last axis (the caller guarantees $|a| > 0$)."""
    return a / norm(a)[..., None]


def frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (t, b) completing the unit normal ``n`` to a right-handed basis.

    The branch-free construction of Duff et al. 2017 ("Building an orthonormal basis,
    revisited"), on plain (detached) normals: sampling frames never carry a tangent.
    """
    n = np.asarray(n, dtype=np.float64)
    sign = np.where(n[..., 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    t = np.stack([1.0 + sign * n[..., 0] ** 2 * a, sign * b, -sign * n[..., 0]], axis=-1)
    s = np.stack([b, sign + n[..., 1] ** 2 * a, -n[..., 1]], axis=-1)
    return t, s


def zeros(shape: tuple[int, ...], dual: bool, k: int | None = None) -> Any:
    """Zeros of ``shape``: a Dual (zero tangent; ``k`` of them, or the classic one) when ``dual``, else a
    plain array."""
    return Dual(np.zeros(shape), None, k) if dual else np.zeros(shape)


def scatter(
    n: int,
    index: np.ndarray,
    values: Any,
    dual: bool | None = None,
    tail: tuple[int, ...] = (),
    k: int | None = None,
) -> Any:
    """An array of ``n`` rows (times ``tail``), zero except ``out[index] = values``.

    A Dual when ``dual`` is True (or, if ``dual`` is None, when ``values`` is a Dual), with the k
    tangents of ``values`` if it is a Dual, else ``k`` of them (None: the classic single tangent).
    """
    k = values.k if isinstance(values, Dual) else k
    out = zeros((n, *tail), isinstance(values, Dual) if dual is None else dual, k)
    if isinstance(out, Dual):
        out[index] = values
    else:
        out[index] = detach(values)
    return out
