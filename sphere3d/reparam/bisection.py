"""Between a pair of probes that see different things: the closest such pair, and bisection toward
what separates them (Loubet et al. 2019, Sec. 4.3: the refinement of the probe heuristic that moves a
probe's hit onto the silhouette between it and its partner).

:func:`closest_pair` picks, per row of probe directions, the allowed pair (occluded and visible
shadow probes, a moving and a static film probe, two static probes that see different things) with
the largest cosine; :func:`bisect` halves the angle between them ``refine`` times, keeping the
inside direction's hit, by a side rule; :func:`bisect_silhouette` is the rule "the same shape,
above the horizon". Used by :mod:`sphere3d.reparam.probes`, :mod:`sphere3d.reparam.emitter_probes` and
:mod:`sphere3d.reparam.junctions`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from sphere3d.live import all_rows
from sphere3d.state import SceneState
from sphere3d.tracing import Hits
from sphere3d.vector import dot, norm

__all__ = [
    "PAIR_ENTRY_BYTES",
    "PAIR_MEMORY",
    "PAIR_ROWS",
    "bisect",
    "bisect_silhouette",
    "closest_pair",
    "pair_bytes",
    "pair_rows",
]


PAIR_ROWS = 1024
"""Rows per slice of :func:`closest_pair` at most: the (rows, p, p) cosines of 14 probes (8 of them on the
emitters' edges then) are 1.6 MB and stay in cache; a chunk's at once (up to 25 000 rows, 38 MB,
above the mmap threshold of :func:`sphere3d.execution._heap_for_temporaries`) was mapped and faulted
in anew at every call: 24 ms per call against 4 ms of arithmetic; by slices of 4096 / 1024 rows
11 / 6 ms (the emitter probes of two 64 spp ``hard_shadow`` renders, one thread: 0.24 -> 0.06 s
in all). The same numbers, row by row."""
PAIR_MEMORY = 64 << 20
"""Bytes of one slice of :func:`closest_pair` (:func:`pair_bytes`) beyond which it holds fewer rows than
:data:`PAIR_ROWS`, down to one: the pair tables grow like p², so many probes would otherwise hold a
chunk's rows × p² entries at once."""
PAIR_ENTRY_BYTES = 16
"""Bytes per probe pair of a row in a slice: the float64 cosine, the allowed-pair mask and the
boolean temporaries the callers' rules build it from."""


def pair_rows(p: int) -> int:
    """Rows per slice of :func:`closest_pair` for ``p`` probes per row: as many as :data:`PAIR_MEMORY` holds,
    at least one, at most :data:`PAIR_ROWS`."""
    return max(1, min(PAIR_ROWS, PAIR_MEMORY // (PAIR_ENTRY_BYTES * p * p)))


def pair_bytes(p: int) -> int:
    r"""Memory model of :func:`closest_pair`: the bytes one slice holds at once for ``p`` probes per row,
    $\mathrm{rows}(p) · p^2 · b$ ($b$ = :data:`PAIR_ENTRY_BYTES`, rows from :func:`pair_rows`), at
    most $\max(\mathrm{PAIR\_MEMORY}, p^2 b)$: a row's table is never split, so one row of p² pairs
    is what no slicing bounds."""
    return pair_rows(p) * PAIR_ENTRY_BYTES * p * p


def closest_pair(
    w: np.ndarray, allowed: Callable[[slice], np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per row of probe directions ``w`` (s, p, 3) the closest pair (i, j) allowed by ``allowed(rows)``
    (the (len(rows), p, p) mask of a slice of rows), the largest w_i . w_j, and whether the row has one.

    By slices of :func:`pair_rows` rows, so the p × p tables of the rows are never all held at once
    (:func:`pair_bytes`); every row is computed alone, the same numbers whatever the slices.
    """
    n, p = w.shape[:2]
    best = np.empty(n, dtype=np.intp)
    found = np.empty(n, dtype=bool)
    step = pair_rows(p)
    for a in range(0, n, step):
        rows = slice(a, min(n, a + step))
        best[rows], found[rows] = _closest(w[rows], allowed(rows))
    i, j = np.divmod(best, p)
    return i, j, found


def _closest(w: np.ndarray, allowed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The flat index of each row's allowed pair of largest cosine, and whether it has one (one slice:
    its tables are freed on return, before the next slice's are made)."""
    cosine = np.matmul(w, np.ascontiguousarray(w.transpose(0, 2, 1))).reshape(len(w), -1)  # (rows, p²)
    np.putmask(cosine, ~allowed.reshape(len(w), -1), -2.0)  # allowed pairs only
    best = np.argmax(cosine, axis=1)
    return best, cosine[np.arange(len(w)), best] > -2.0


def bisect(
    state: SceneState,
    trace_origin: np.ndarray,
    inside: np.ndarray,
    outside: np.ndarray,
    hits: Hits,
    side: Callable[[Hits, np.ndarray], tuple[np.ndarray, np.ndarray]],
    refine: int,
) -> tuple[Hits, np.ndarray, np.ndarray, np.ndarray]:
    """``refine`` bisections between directions ``inside`` (with ``hits``) and ``outside`` (m, 3).

    ``side(h, mid) -> (on, off)`` says which bisection rays (directions ``mid``, hits ``h``) replace
    the inside direction (and its hit) and which the outside one. Returns the moved hits, the
    final pair of directions, and which rows stayed valid: every bisection ray on one side or the
    other (a row whose ray is on neither keeps its pair from then on)."""
    valid = np.ones(len(inside), dtype=bool)
    for _ in range(refine):
        mid = inside + outside
        mid = mid / norm(mid)[:, None]
        h = state.tracer.intersect(trace_origin, mid)
        on, off = side(h, mid)
        valid &= on | off
        # contiguous (m, 3) masks: np.where is several times faster than with a broadcast (m, 1) one
        inside = np.where(np.repeat(on[:, None], 3, axis=1), mid, inside)
        outside = np.where(np.repeat(off[:, None], 3, axis=1), mid, outside)
        hits = h.where(on, hits)
    return hits, inside, outside, valid


def bisect_silhouette(
    state: SceneState,
    trace_origin: np.ndarray,
    inside: np.ndarray,
    outside: np.ndarray,
    hits: Hits,
    normal: np.ndarray | None,
    refine: int,
) -> tuple[Hits, np.ndarray, np.ndarray]:
    """Move ``hits`` towards their shape's silhouette: ``refine`` bisections between a direction
    that hits the shape (``inside``, with ``hits``) and one that does not (``outside``); returns
    the moved hits and the final pair of directions. A bisection ray is inside where it hits the
    same shape (above the horizon of ``normal``, if given: (m, 3), or (m, 2, 3) for two planes), else
    outside."""

    def side(h: Hits, mid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        on = h.shape == shape  # the shape never changes: hits are only replaced where it matches
        if normal is not None:  # above the horizon; with two normals (m, 2, 3), above both planes
            on = on & (
                dot(mid, normal) > 0.0 if normal.ndim == 2 else all_rows(dot(mid[:, None], normal) > 0.0)
            )
        return on, ~on

    shape = hits.shape
    hits, inside, outside, _ = bisect(state, trace_origin, inside, outside, hits, side, refine)
    return hits, inside, outside
