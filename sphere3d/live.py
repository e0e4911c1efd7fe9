"""Dual arithmetic on the rows that carry a tangent, plain numpy on the others.

With θ a Dual every scene quantity is one (:func:`~sphere3d.state.build_state`), but
most rows of a batch have zero tangents: a shading point on a static surface, seen
along an unrotated direction, lit by a static emitter. Their derivative is exactly 0
(up to the sign of zero) whatever the estimator computes, so :func:`on_rows` evaluates
such rows with plain arrays and keeps the :class:`~flatland.core.dual.Dual` arithmetic
for the others. Values are those of a whole-array Dual evaluation, row for row (the
Dual rules compute values with the same numpy operations); tangents are +0 on the
plain rows.

A Dual may carry k tangents, one per parameter, on a leading axis
(:mod:`flatland.core.dual`): :func:`moves` and the helpers here then ask whether *any* parameter
moves a row, and :func:`on_rows` fills the rows of every slot.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach, k_of, take_rows, tangent

__all__ = [
    "all_rows",
    "any_rows",
    "emitters_change",
    "moves",
    "moving_rows",
    "on_rows",
    "take_rows",
    "triangles_change",
]


def _fold_columns(mask: np.ndarray, op: np.ufunc) -> np.ndarray:
    """``op`` (``np.logical_or``, ``np.logical_and``) over the k columns of a boolean (n, k) array, column by
    column: a reduction over a short axis is about 6 times slower for k = 3 to 12."""
    out = mask[:, 0].copy()
    for j in range(1, mask.shape[1]):
        op(out, mask[:, j], out=out)
    return out


def any_rows(mask: np.ndarray) -> np.ndarray:
    """``np.any(mask, axis=1)`` of a boolean (n, k) array, as the OR of its columns."""
    return _fold_columns(mask, np.logical_or)


def all_rows(mask: np.ndarray) -> np.ndarray:
    """``np.all(mask, axis=1)`` of a boolean (n, k) array, as the AND of its columns."""
    return _fold_columns(mask, np.logical_and)


def moves(x: Any) -> np.ndarray:
    """Where ``x`` carries a nonzero tangent, a boolean array of its value's shape: for a Dual with k
    tangents, under any of the k parameters (False everywhere for a plain array)."""
    if not isinstance(x, Dual):  # no tangent to compare: O(size) booleans, not a zero tangent first
        return np.zeros(np.shape(x), dtype=bool)
    t = tangent(x) != 0.0
    return np.any(t, axis=0) if x.k is not None else t


def moving_rows(rows: np.ndarray, *sources: Any) -> np.ndarray:
    """Where any of ``sources`` (Duals or plain arrays, one row per item) has a tangent at ``rows`` (under
    any parameter, for k tangents)."""
    out = np.zeros(len(rows), dtype=bool)
    for s in sources:
        if isinstance(s, Dual) and rows.size:
            if s.k is None:
                t = s.tangent[rows]
                out |= any_rows(t.reshape(len(rows), -1) != 0.0)
            else:  # the k slots as more columns of each row
                t = np.moveaxis(s.tangent[:, rows], 0, 1)
                out |= any_rows(t.reshape(len(rows), -1) != 0.0)
    return out


def on_rows(func: Callable[..., Any], rows: np.ndarray, live: np.ndarray, *sources: Any) -> tuple[Dual, ...]:
    """``func(dual, *(s[rows] for s in sources))``, as Duals on the ``live`` rows and plain elsewhere.

    Parameters
    ----------
    func : callable
        ``func(dual, *args)`` returns a tuple of arrays with one row per row of its
        arguments, row by row independent of the others. ``dual`` says whether the
        arguments are Duals; any other θ-dependent quantity ``func`` reads must have a
        zero tangent on the rows that are not ``live`` (the caller's guarantee).
    rows : ndarray of int, shape (k,)
        Rows of ``sources`` to evaluate.
    live : ndarray of bool, shape (k,)
        Which of them are evaluated with tangents.
    sources : Dual or ndarray
        Arrays indexed by ``rows`` (Duals are detached on the plain rows).

    Returns
    -------
    tuple of Dual
        ``func``'s outputs for all ``rows``: tangents +0 where not ``live``.
    """
    on, off = np.flatnonzero(live), np.flatnonzero(~live)  # positions in rows, found once for every output
    li, di = rows[on], rows[off]
    plain = func(False, *(take_rows(detach(s), di) for s in sources)) if di.size or not li.size else None
    dual = func(True, *(s[li] for s in sources)) if li.size else None
    k = k_of(*sources) if dual is None else k_of(*dual)
    outputs = []
    for j in range(len(plain if plain is not None else dual)):
        first = detach(plain[j] if plain is not None else dual[j])
        value = np.empty((len(rows), *np.shape(first)[1:]))
        grad = np.zeros(value.shape if k is None else (k, *value.shape))
        if plain is not None:
            value[off] = detach(plain[j])
        if dual is not None:
            value[on] = detach(dual[j])
            if k is None:
                grad[on] = tangent(dual[j])
            else:
                grad[:, on] = tangent(dual[j], k)
        outputs.append(Dual(value, grad, k))
    return tuple(outputs)


def triangles_change(state: Any) -> np.ndarray:
    """Per triangle: True if its vertices, vertex normals or its shape's emission carry a tangent."""
    if not state.dual:  # a plain state (the boundary term's radiance beside an edge): nothing moves
        return np.zeros(len(state.shape_of), dtype=bool)
    change = np.any(moves(state.triangles), axis=(1, 2)) | np.any(moves(state.normals), axis=(1, 2))
    return change | moves(state.emission)[state.shape_of]


def emitters_change(state: Any) -> bool:
    """True if an emitter's triangles, emission or total area carry a tangent."""
    if not state.dual:
        return False
    return bool(
        np.any(moves(state.triangles)[state.emitters])
        or np.any(moves(state.emission))
        or np.any(moves(state.emitter_area))
    )
