"""The edge tree's construction (:mod:`sphere3d.boundary.edge_tree`): each edge's slot, each leaf's bounds.

Two kernels of scalar Python compiled by Numba (:func:`sphere3d.jit.compiled`), each O(E) per level
of the tree: :func:`median_split` fills the tree's slots top down, every node splitting its edges
at the median of their midpoints along the longest side of their bounding box (quickselect,
:func:`_select`), so that a leaf holds a compact patch of edges; :func:`leaf_bounds` gives each leaf
its bounding sphere and normal cone. The levels above the leaves merge their children's bounds in
:meth:`~sphere3d.boundary.edge_tree.EdgeTree.build`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np

from sphere3d.jit import compiled

__all__ = ["compiled_split", "leaf_bounds", "median_split"]


def median_split(mid: np.ndarray, n_first: int, depth: int, leaf: int) -> np.ndarray:
    """The slots of the edges with midpoints ``mid`` (3, N: coordinates by axis), the first
    ``n_first`` of one group, the rest of another: a permutation ``placed`` (slot p holds edge
    ``placed[p]``), each group in slots of its own, such that every node of the complete tree of
    ``depth`` levels over ``leaf``-edge leaves (slots ``[s, s + size)``, children at its half)
    splits its edges of one group at the median along the longest side of their bounding box
    (:func:`_select`): O(N) per level, O(N log N) in all. Scalar Python for Numba."""
    n = mid.shape[1]
    placed = np.arange(n)
    pts = mid.copy()  # the midpoints in slot order, moved with ``placed``: read in sequence
    for level in range(depth):
        size = (leaf << depth) >> level  # slots per node of this level
        for start in range(0, n, size):
            half = start + size // 2
            end = min(start + size, n)
            if half >= end or half == n_first:  # nothing to split: all left, or the groups' border
                continue
            lo, hi = (start, min(end, n_first)) if half < n_first else (max(start, n_first), end)
            axis, longest = 0, -1.0
            for k in range(3):
                low, high = np.inf, -np.inf
                for i in range(lo, hi):
                    low = min(low, pts[k, i])
                    high = max(high, pts[k, i])
                if high - low > longest:
                    axis, longest = k, high - low
            _select(placed, pts, lo, hi, half, axis)
    return placed


def _select(placed: np.ndarray, pts: np.ndarray, lo: int, hi: int, k: int, axis: int) -> None:
    """Reorder the slots ``lo:hi`` of ``placed`` and of the points ``pts`` (3, N) alike so that slot k
    holds the k-th smallest coordinate ``axis``, the slots before it no larger, the ones after no
    smaller (quickselect, median-of-three pivots, Hoare partition)."""
    key = pts[axis]
    hi -= 1
    while hi > lo:
        a, b, c = key[lo], key[(lo + hi) // 2], key[hi]
        pivot = max(min(a, b), min(max(a, b), c))  # the median of the three
        i, j = lo, hi
        while i <= j:
            while key[i] < pivot:
                i += 1
            while key[j] > pivot:
                j -= 1
            if i <= j:
                placed[i], placed[j] = placed[j], placed[i]
                for d in range(3):
                    pts[d, i], pts[d, j] = pts[d, j], pts[d, i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            return


def leaf_bounds(
    order: np.ndarray,
    leaf: int,
    a: np.ndarray,
    b: np.ndarray,
    n1: np.ndarray,
    n2: np.ndarray,
    always: np.ndarray,
    centre: np.ndarray,
    radius: np.ndarray,
    axis: np.ndarray,
    spread: np.ndarray,
) -> None:
    r"""Each leaf's bounds (module docstring), written to ``centre``, ``radius``, ``axis``, ``spread``
    (one row per leaf): the sphere about the centre of the box around its edges' spheres (midpoint
    m, half length h) with radius $\max |m - c| + h$; the cone about the normalized sum of its
    edges' face normals, to the widest of them (π with an open edge). An empty leaf keeps radius -1.
    Scalar Python for Numba."""
    for node in range(order.shape[0] // leaf):
        low, high, total = np.full(3, np.inf), np.full(3, -np.inf), np.zeros(3)
        wide = False
        count = 0
        for slot in range(node * leaf, (node + 1) * leaf):
            e = order[slot]
            if e < 0:
                break
            count += 1
            dx, dy, dz = b[e, 0] - a[e, 0], b[e, 1] - a[e, 1], b[e, 2] - a[e, 2]
            half = 0.5 * np.sqrt(dx * dx + dy * dy + dz * dz)
            for k in range(3):
                m = 0.5 * (a[e, k] + b[e, k])
                low[k] = min(low[k], m - half)
                high[k] = max(high[k], m + half)
                total[k] += n1[e, k] + n2[e, k]
            wide = wide or always[e]
        if count == 0:
            continue
        cx, cy, cz = 0.5 * (low[0] + high[0]), 0.5 * (low[1] + high[1]), 0.5 * (low[2] + high[2])
        length = np.sqrt(total[0] ** 2 + total[1] ** 2 + total[2] ** 2)
        scale = 1.0 / length if length > 0.0 else 1.0
        ux, uy, uz = total[0] * scale, total[1] * scale, total[2] * scale
        reach, worst = 0.0, 0.0
        for slot in range(node * leaf, node * leaf + count):
            e = order[slot]
            dx, dy, dz = b[e, 0] - a[e, 0], b[e, 1] - a[e, 1], b[e, 2] - a[e, 2]
            mx, my, mz = a[e, 0] + 0.5 * dx - cx, a[e, 1] + 0.5 * dy - cy, a[e, 2] + 0.5 * dz - cz
            far = np.sqrt(mx * mx + my * my + mz * mz) + 0.5 * np.sqrt(dx * dx + dy * dy + dz * dz)
            reach = max(reach, far)
            for nrm in (n1, n2):
                nx, ny, nz = nrm[e, 0], nrm[e, 1], nrm[e, 2]
                sx, sy, sz = ny * uz - nz * uy, nz * ux - nx * uz, nx * uy - ny * ux
                angle = np.arctan2(np.sqrt(sx * sx + sy * sy + sz * sz), nx * ux + ny * uy + nz * uz)
                worst = max(worst, angle)
        centre[node, 0], centre[node, 1], centre[node, 2] = cx, cy, cz
        radius[node] = reach * (1.0 + 1e-12)
        axis[node, 0], axis[node, 1], axis[node, 2] = ux, uy, uz
        spread[node] = np.pi if wide or length == 0.0 else worst


@functools.cache
def compiled_split() -> Callable:
    """:func:`median_split` compiled, with :func:`_select`, which it calls by its global name."""
    globals()["_select"] = compiled(_select)
    return compiled(median_split)
