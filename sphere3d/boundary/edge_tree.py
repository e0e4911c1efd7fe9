r"""A hierarchy over mesh edges: the edges that can be silhouettes seen from a point, without scanning all.

The shading integrals' boundary term (:mod:`sphere3d.boundary.shading`) needs, per shading point o,
the edges that are silhouettes seen from o and whose arcs can meet the emitters' image. Testing
every (point, edge) pair costs O(points × edges); on a mesh of 10⁵ triangles that is most of a
render. This module finds a superset of those pairs through a tree, as redner's edge tree does for
edge sampling (Li et al. 2018, its hierarchy of edges): each node bounds its edges by

- a **sphere** (centre c, radius r) holding every edge's own bounding sphere (its midpoint,
  radius half its length), and
- a **normal cone** (unit axis d, half-angle α) holding both face normals $n_1, n_2$ of every
  edge in it (α = π for boundary and non-manifold edges: silhouettes from everywhere).

For a point o outside the sphere, $|o - c| > r$, the directions from the sphere's points to o lie
within $β = \arcsin(r / |o - c|)$ of $v = (o - c)/|o - c|$. With φ the angle between d and v, every
$n·(o - p)$ of the node (n in the cone, p in the sphere) has the sign of $\cos(φ ± (α + β))$:

    all positive if $φ + α + β < π/2$, all negative if $φ - α - β > π/2$,

and then no edge of the node is a silhouette seen from o (both faces on one side). Under a black
sky an edge's arc counts only where it meets the emitters' image (the shading term's arcs are
clipped to it, :mod:`sphere3d.boundary.shading`): the node is dropped when the cone from o around
its sphere misses the cone around the emitters' bounding sphere (centre e, radius R), i.e. when
the angle between $c - o$ and $e - o$ exceeds $β + \arcsin(R / |e - o|)$. Given the emitter
triangles (as many as the shading term clips to), the node is also dropped when its cone misses
the image of every triangle o sees the front of: triangle $L_0 L_1 L_2$ covers the directions w with
$w·\hat c_k ≥ 0$, $c_k = q_{k+1} × q_k$, $q_k = L_k - o$, and the cone about $u = (c - o)/|c - o|$
lies beyond side k when $u·\hat c_k < -\sin β$. On a fine mesh the silhouette arcs near the light's
directions can far outnumber those crossing its image. All tests compare cosines with
a slack of :data:`SLACK` over rounding; a node whose sphere holds o is kept. At a leaf every edge
gets the exact tests: the silhouette test, and the same cone tests with the edge's own sphere
(midpoint, half its length). The culls are conservative (a node's bounds hold its edges' bounds),
so the pairs found are exactly those of the exact tests on every pair; the pairs the image test
drops have arcs wholly outside the emitters' images, which the shading term clips to nothing.

Construction, O(E log E) per state: a complete binary tree over slots of :data:`LEAF` edges (heap
order: node i has children 2i and 2i + 1), filled top down, each node splitting its edges at the
median of their midpoints along the longest side of their bounding box (one selection per node,
O(E) per level: :mod:`sphere3d.boundary.tree_build`), so that leaves are compact patches of about
LEAF edges; each leaf's sphere is centred in the box around its edges' spheres, just wide enough to
hold them, each node's the smallest holding its children's, its cone merged from theirs; each
edge's two planes $n_k·p = n_k·a$ stored in leaf order beside it. The tree's shape changes which
nodes a walk visits, never the pairs it finds, which come sorted by edge index within a point.

Query (:meth:`EdgeTree.silhouettes`): every point walks the tree depth first, dropping the nodes
the culls reject, and at the leaves it reaches runs the exact silhouette test on each edge (the
signs of $n_1·(o - a)$ and $n_2·(o - a)$ differ, or the edge is open). Its cost grows with the nodes
it visits, about the silhouette edges near the emitters' directions (O(√E) on a fine closed mesh,
times log E), not with the mesh. A walk is one branch per node, which array operations over
(point, node) pairs do at tens of ns a test; :func:`walk` is plain Python compiled by Numba
(``nogil``: the render's worker threads walk at once), its pairs written to buffers that grow by
doubling, so memory holds the pairs found, never points × edges. The compiled code is cached on
disk (first use on a machine: about a second to compile).
"""

from __future__ import annotations

import dataclasses
import functools
import threading
import weakref
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sphere3d.boundary.edges import Edges
from sphere3d.boundary.tree_build import compiled_split, leaf_bounds
from sphere3d.jit import compiled
from sphere3d.vector import dot, norm

__all__ = ["LEAF", "SLACK", "EdgeTree", "edge_tree", "walk"]

LEAF = 32
"""Edges per leaf."""
SLACK = 1e-9
"""Kept in every cull's cosine comparison beyond the bounds (their rounding is about 1e-15)."""
PAIRS_PER_POINT = 64
"""First size of the pair buffers of :meth:`EdgeTree.silhouettes`, per point (doubled when full)."""


def _angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angles between unit vectors (..., 3), by atan2 (accurate near 0 and π)."""
    return np.arctan2(norm(np.cross(u, v)), dot(u, v))


@dataclass(frozen=True)
class EdgeTree:
    """Bounding spheres and normal cones over a subset of a mesh's edges (module docstring).

    Attributes
    ----------
    order : ndarray of int, shape (2^D L,)
        The edges (indices into the full :class:`~sphere3d.boundary.edges.Edges`) in leaf order,
        -1 for padding.
    centre, radius : ndarray, shape (2^(D+1), 3) and (2^(D+1),)
        Node spheres in heap order (node 0 unused); radius -1 for an empty node.
    axis, spread : ndarray, shape (2^(D+1), 3) and (2^(D+1),)
        Node normal cones: unit axis, half-angle (π: no cull by facing).
    depth : int
        D: the leaves are nodes 2^D to 2^(D+1) - 1.
    cos_spread, sin_spread : ndarray, shape (2^(D+1),)
        cos α and sin α.
    planes : ndarray, shape (2^D L, 8)
        Per slot of ``order``: $n_1$, $n_1·a$, $n_2$, $n_2·a$ of its edge (0 for padding).
    always : ndarray of bool, shape (2^D L,)
        Per slot: an open or non-manifold edge (a silhouette from every point).
    spheres : ndarray, shape (2^D L, 4)
        Per slot: its edge's bounding sphere, midpoint and half length.
    live : ndarray of bool, shape (2^(D+1),)
        Per node: it holds an edge the walk tests (:meth:`restrict`; every edge of the tree by default).
    active : ndarray of bool, shape (2^D L,)
        Per slot: an edge the walk tests.
    """

    order: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    axis: np.ndarray
    spread: np.ndarray
    depth: int
    cos_spread: np.ndarray
    sin_spread: np.ndarray
    planes: np.ndarray
    always: np.ndarray
    spheres: np.ndarray
    live: np.ndarray
    active: np.ndarray

    @staticmethod
    def build(edges: Edges, subset: np.ndarray, first: np.ndarray | None = None) -> EdgeTree:
        """The tree over the edges ``subset`` (indices into ``edges``); with a mask ``first`` (E,), its
        edges before the others, each group split on its own (:mod:`~sphere3d.boundary.tree_build`),
        so that only the nodes on the path to the leaf where the groups meet hold both
        (:meth:`restrict`)."""
        n = subset.size
        depth = max(0, int(np.ceil(np.log2(max(n, 1) / LEAF))))
        leaves = 1 << depth
        group = np.zeros(n, dtype=bool) if first is None else ~first[subset]
        ranked = np.argsort(group, kind="stable")  # the first group's edges, then the others
        mid = np.ascontiguousarray((0.5 * (edges.a + edges.b))[subset[ranked]].T)
        placed = compiled_split()(mid, int(np.sum(~group)), depth, LEAF)
        order = np.full(leaves * LEAF, -1, dtype=np.int64)
        order[:n] = subset[ranked[placed]]
        # heap arrays; the leaves' bounds compiled (tree_build.leaf_bounds), the levels above merged
        size = 2 * leaves
        centre, radius = np.zeros((size, 3)), np.full(size, -1.0)
        axis, spread = np.zeros((size, 3)), np.full(size, np.pi)
        leaf = slice(leaves, size)
        compiled(leaf_bounds)(
            order, LEAF, edges.a, edges.b, edges.n1, edges.n2, edges.always,
            centre[leaf], radius[leaf], axis[leaf], spread[leaf],
        )  # fmt: skip
        filled = radius >= 0.0
        for level in range(depth - 1, -1, -1):  # the parents of each level, up to the root
            node = np.arange(1 << level, 2 << level)
            kids = np.stack([2 * node, 2 * node + 1])  # (2, nodes)
            full = filled[kids]
            filled[node] = full[0] | full[1]
            # the sphere about the mean of the children's centres (radius-weighted ends of the span),
            # just wide enough to hold both spheres
            c = np.where(full[..., None], centre[kids], centre[kids[::-1]])
            r = np.where(full, radius[kids], radius[kids[::-1]])
            gap = norm(c[1] - c[0])
            lo = np.minimum(-r[0], gap - r[1])  # the span of both spheres along c0 -> c1, from c0
            hi = np.maximum(r[0], gap + r[1])
            u = (c[1] - c[0]) / np.where(gap > 0.0, gap, 1.0)[:, None]
            centre[node] = c[0] + (0.5 * (lo + hi))[:, None] * u
            radius[node] = np.where(filled[node], 0.5 * (hi - lo) * (1.0 + 1e-12), -1.0)
            # the merged cone: about the children's mean axis, wide enough to hold both cones
            s = axis[kids[0]] * full[0, :, None] + axis[kids[1]] * full[1, :, None]
            length = norm(s)
            merged = s / np.where(length > 0.0, length, 1.0)[:, None]
            reach = np.maximum(
                np.where(full[0], _angle(merged, axis[kids[0]]) + spread[kids[0]], 0.0),
                np.where(full[1], _angle(merged, axis[kids[1]]) + spread[kids[1]], 0.0),
            )
            axis[node] = merged
            spread[node] = np.where(length > 0.0, np.minimum(reach, np.pi), np.pi)
        slot, real = order.clip(0), (order >= 0)[:, None]
        n1, n2, a = edges.n1[slot], edges.n2[slot], edges.a[slot]
        planes = np.concatenate([n1, dot(n1, a)[:, None], n2, dot(n2, a)[:, None]], axis=1)
        planes = np.where(real, planes, 0.0)
        always = edges.always[slot] & (order >= 0)
        spheres = np.concatenate(
            [0.5 * (edges.a + edges.b)[slot], 0.5 * norm(edges.b - edges.a)[slot, None]], axis=1
        )
        return EdgeTree(
            order,
            centre,
            radius,
            axis,
            spread,
            depth,
            np.cos(spread),
            np.sin(spread),
            planes,
            always,
            spheres,
            radius >= 0.0,
            order >= 0,
        )

    def restrict(self, mask: np.ndarray) -> EdgeTree:
        """This tree walking only the edges where ``mask`` (E,) is True: the same bounds (a node's
        sphere and cone hold its edges', hence the subset's), the nodes without such an edge skipped.
        O(nodes), no copy of the bounds."""
        active = (self.order >= 0) & mask[self.order.clip(0)]
        live = np.zeros_like(self.live)
        leaves = 1 << self.depth
        live[leaves:] = active.reshape(leaves, -1).any(axis=1)
        for level in range(self.depth - 1, -1, -1):
            node = np.arange(1 << level, 2 << level)
            live[node] = live[2 * node] | live[2 * node + 1]
        return dataclasses.replace(self, live=live, active=active)

    def silhouettes(
        self,
        o: np.ndarray,
        emitters: tuple[np.ndarray, float] | None = None,
        triangles: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(rows, edges): every pair (point ``o[row]``, edge of the tree) where the edge is a silhouette
        seen from the point and, given the emitters' bounding sphere ``(centre, radius)``, its cone
        from the point meets theirs and, given the emitter ``triangles`` (T, 3, 3), the image of one
        of them the point sees the front of (the exact tests, module docstring); grouped by point, by
        edge index within one.
        Memory: the pairs found (buffers doubled when full)."""
        o = np.ascontiguousarray(o, dtype=np.float64)
        emit = np.array([0.0, 0.0, 0.0, -1.0]) if emitters is None else np.array([*emitters[0], emitters[1]])
        tris = np.zeros((0, 3, 3)) if triangles is None or emitters is None else np.asarray(triangles, float)
        size = max(PAIRS_PER_POINT, PAIRS_PER_POINT * len(o))
        rows, cols = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
        done = 0
        while done < len(o):
            r, c = np.empty(size, dtype=np.int64), np.empty(size, dtype=np.int64)
            stop, count = _compiled()(
                o, done, emit, np.ascontiguousarray(tris), self.centre, self.radius, self.axis,
                self.cos_spread, self.sin_spread, self.depth, self.order, self.planes, self.always,
                self.spheres, self.live, self.active, r, c,
            )  # fmt: skip
            rows.append(r[:count])
            cols.append(c[:count])
            if stop == done:  # one point's pairs do not fit: a larger buffer
                size *= 2
            done = stop
        return np.concatenate(rows), np.concatenate(cols)


def walk(
    o: np.ndarray,
    start: int,
    emit: np.ndarray,
    tris: np.ndarray,
    centre: np.ndarray,
    radius: np.ndarray,
    axis: np.ndarray,
    cos_spread: np.ndarray,
    sin_spread: np.ndarray,
    depth: int,
    order: np.ndarray,
    planes: np.ndarray,
    always: np.ndarray,
    spheres: np.ndarray,
    live: np.ndarray,
    active: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
) -> tuple[int, int]:
    """The depth-first walk of :meth:`EdgeTree.silhouettes` for the points ``o[start:]``, written as
    scalar Python for Numba: the pairs found go to ``rows``, ``cols`` until they are full. Returns
    (the first point not walked, the pairs written); a point whose pairs do not all fit is not
    walked. ``emit``: the emitters' sphere (centre, radius), radius < 0 for none; ``tris``: the emitter
    triangles (T, 3, 3), T = 0 for no triangle cull. The culls are those of the module docstring, in
    cosines, each comparison kept by :data:`SLACK`."""
    capacity = rows.shape[0]
    n_tris = tris.shape[0]
    sides = np.empty((n_tris, 3, 3))  # per point: the unit normals ĉ of the triangles' images' sides
    facing = np.empty(n_tris, dtype=np.bool_)
    stack = np.empty(2 * depth + 2, dtype=np.int64)  # depth first: at most one sibling per level waits
    first_leaf = 1 << depth
    count = 0
    for i in range(start, o.shape[0]):
        ox, oy, oz = o[i, 0], o[i, 1], o[i, 2]
        # the emitters' angular radius γ seen from o (the cone cull only where o is outside their sphere)
        tx, ty, tz = emit[0] - ox, emit[1] - oy, emit[2] - oz
        d_to = np.sqrt(tx * tx + ty * ty + tz * tz)
        far = emit[3] >= 0.0 and d_to > emit[3]
        sin_e = emit[3] / d_to if far else 0.0
        cos_e = np.sqrt(max(0.0, 1.0 - sin_e * sin_e))
        # seen from o, triangle L0 L1 L2 covers the directions w with w·(q_{k+1} × q_k) >= 0, q_k = L_k - o,
        # where o sees its front (q0·(q2 × q1) > 0, as in the shading term's clip); else nothing
        for t in range(n_tris):
            for k in range(3):
                k1 = (k + 1) % 3
                ax, ay, az = tris[t, k1, 0] - ox, tris[t, k1, 1] - oy, tris[t, k1, 2] - oz
                bx, by, bz = tris[t, k, 0] - ox, tris[t, k, 1] - oy, tris[t, k, 2] - oz
                cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
                length = np.sqrt(cx * cx + cy * cy + cz * cz)
                length = length if length > 0.0 else 1.0
                sides[t, k, 0], sides[t, k, 1], sides[t, k, 2] = cx / length, cy / length, cz / length
            q0x, q0y, q0z = tris[t, 0, 0] - ox, tris[t, 0, 1] - oy, tris[t, 0, 2] - oz
            facing[t] = q0x * sides[t, 1, 0] + q0y * sides[t, 1, 1] + q0z * sides[t, 1, 2] > 0.0
        begin = count
        stack[0] = 1
        top = 1
        while top > 0:
            top -= 1
            node = stack[top]
            if not live[node]:  # no edge to test below
                continue
            r = radius[node]
            vx, vy, vz = ox - centre[node, 0], oy - centre[node, 1], oz - centre[node, 2]
            dist = np.sqrt(vx * vx + vy * vy + vz * vz)
            if dist > r:  # a node whose sphere holds o is kept
                sin_b = r / dist  # β: the sphere's angular radius
                cos_b = np.sqrt(1.0 - sin_b * sin_b)
                # φ from the cone's axis to the direction to o: |cos φ| > sin(α + β) with α + β < π/2
                # puts every n·(o - p) of the node on one side (no silhouette)
                cos_phi = (axis[node, 0] * vx + axis[node, 1] * vy + axis[node, 2] * vz) / dist
                sin_a, cos_a = sin_spread[node], cos_spread[node]
                narrow = cos_a * cos_b - sin_a * sin_b > 0.0  # α + β < π/2
                if narrow and abs(cos_phi) > sin_a * cos_b + cos_a * sin_b + SLACK:
                    continue
                # the angle from o between the node's and the emitters' centres beyond β + γ
                cos_gap = -(vx * tx + vy * ty + vz * tz) / (dist * d_to) if far else 1.0
                if cos_gap < cos_b * cos_e - sin_b * sin_e - SLACK:
                    continue
                # the cone about u = (c - o)/|c - o| of angular radius β meets no front triangle's image:
                # for each, some side has u·ĉ < -sin β (the whole cone beyond its great circle)
                if n_tris and not _meets(-vx / dist, -vy / dist, -vz / dist, sin_b, sides, facing):
                    continue
            if node < first_leaf:  # the left child first: pairs in leaf order
                stack[top] = 2 * node + 1
                stack[top + 1] = 2 * node
                top += 2
                continue
            base = (node - first_leaf) * LEAF
            for j in range(base, base + LEAF):
                if order[j] < 0:  # padding ends a leaf
                    break
                if not active[j]:
                    continue
                front1 = ox * planes[j, 0] + oy * planes[j, 1] + oz * planes[j, 2] > planes[j, 3]
                front2 = ox * planes[j, 4] + oy * planes[j, 5] + oz * planes[j, 6] > planes[j, 7]
                if not always[j] and front1 == front2:  # n1·(o - a) and n2·(o - a) of one sign
                    continue
                if far:
                    # the edge's cone from o (its sphere: midpoint, half length h) meets the emitters'
                    # (angle between the centres <= β_e + γ, sin β_e = h / |mid|), or o lies in its
                    # sphere; in cosines (β_e + γ <= π, where cos decreases): cos < cos(β_e + γ) culls
                    mx, my, mz = spheres[j, 0] - ox, spheres[j, 1] - oy, spheres[j, 2] - oz
                    d_mid = np.sqrt(mx * mx + my * my + mz * mz)
                    if d_mid > spheres[j, 3]:
                        cos = min(1.0, max(-1.0, (mx * tx + my * ty + mz * tz) / (d_mid * d_to)))
                        sin_h = spheres[j, 3] / d_mid
                        if cos < np.sqrt(1.0 - sin_h * sin_h) * cos_e - sin_h * sin_e:
                            continue
                    if n_tris and not _meets(
                        mx / d_mid, my / d_mid, mz / d_mid, spheres[j, 3] / d_mid, sides, facing
                    ):
                        continue
                if count == capacity:
                    return i, begin  # point i does not fit: resume from it
                rows[count] = i
                cols[count] = order[j]
                count += 1
        cols[begin:count].sort()  # the point's pairs by edge index, whatever the tree's shape
    return o.shape[0], count


def _meets(ux: float, uy: float, uz: float, sin_b: float, sides: np.ndarray, facing: np.ndarray) -> bool:
    r"""Whether the cone about the unit vector u of angular radius β (``sin_b``) may meet the image of a
    triangle seen from its front, given its sides' unit normals ``sides`` (T, 3, 3): not when for
    every such triangle some side has $u·ĉ < -\sin β$ (beyond :data:`SLACK`)."""
    for t in range(sides.shape[0]):
        if not facing[t]:
            continue
        inside = True
        for k in range(3):
            if ux * sides[t, k, 0] + uy * sides[t, k, 1] + uz * sides[t, k, 2] < -sin_b - SLACK:
                inside = False
                break
        if inside:
            return True
    return False


@functools.cache
def _compiled() -> Callable:
    """:func:`walk` compiled, with :func:`_meets`, which it calls by its global name, compiled first."""
    globals()["_meets"] = compiled(_meets)
    return compiled(walk)


_TREES: dict[int, tuple[weakref.ref, dict[bytes, EdgeTree]]] = {}
_BUILDING: dict[tuple[int, bytes], threading.Event] = {}
_LOCK = threading.Lock()


def edge_tree(edges: Edges, first: np.ndarray, restrict: bool = False) -> EdgeTree:
    """The tree over all of ``edges`` with the mask ``first``'s edges first (:meth:`EdgeTree.build`),
    built once per ``edges`` object and kept while ``edges`` lives, and with ``restrict``, walking only
    ``first``'s edges (:meth:`EdgeTree.restrict`): every slice of shading points of a render, and
    both groups of points (fixed ones testing the moving edges, moving ones all), share one build.
    One thread builds it; threads asking meanwhile wait for it (the render's chunks ask at once:
    each building its own cost the build's time and memory once per thread). Read-only."""
    key, key_edges = first.tobytes(), id(edges)
    mine = None  # the event this thread sets once it has built the whole tree
    while True:
        with _LOCK:
            entry = _TREES.get(key_edges)
            if entry is not None and entry[0]() is edges and (key, restrict) in entry[1]:
                return entry[1][key, restrict]
            whole = entry[1].get((key, False)) if entry is not None and entry[0]() is edges else None
            event = _BUILDING.get((key_edges, key))
            if whole is not None or event is None:  # this thread builds (or only restricts) it
                if whole is None:
                    mine = _BUILDING[key_edges, key] = threading.Event()
                break
        event.wait()  # another thread builds the whole tree; then read it (or build it, had that failed)
    try:
        if whole is None:
            whole = EdgeTree.build(edges, np.arange(len(edges)), first)
        tree = whole.restrict(first) if restrict else whole
        with _LOCK:
            entry = _TREES.get(key_edges)
            if entry is None or entry[0]() is not edges:
                ref = weakref.ref(edges, lambda _: _TREES.pop(key_edges, None))
                entry = _TREES[key_edges] = (ref, {})
            entry[1][key, False] = whole
            entry[1][key, restrict] = tree
        return tree
    finally:
        if mine is not None:
            with _LOCK:
                del _BUILDING[key_edges, key]
            mine.set()
