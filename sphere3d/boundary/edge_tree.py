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
sky an edge's arc counts only where it meets the emitters' image (:func:`sphere3d.boundary.shading._reach`):
the node is dropped when the cone from o around its sphere misses the cone around the emitters'
bounding sphere (centre e, radius R), i.e. when the angle between $c - o$ and $e - o$ exceeds
$β + \arcsin(R / |e - o|)$. Both tests compare cosines with a slack of :data:`SLACK` over rounding;
a node whose sphere holds o is kept. As every edge's own tests (:func:`sphere3d.boundary.shading._pairs`)
are run afterwards on the pairs found here, the tree changes which pairs are tested, never which
pass: it is conservative by construction (a node's bounds hold its edges' bounds).

Construction, O(E log E) per state: the edges sorted by the Morton code of their midpoints (30 bits),
leaves of :data:`LEAF` consecutive edges, a complete binary tree above them (heap order: node i has
children 2i and 2i + 1), each node's bounds merged from its children's. A query walks the tree
breadth first for a block of points at once (vectorized over (point, node) pairs; blocks of
:data:`QUERY_POINTS` points bound the pairs held), so its cost grows with the pairs it keeps at each
level, about the silhouette edges near the emitters' directions, not with the mesh.
"""

from __future__ import annotations

import threading
import weakref
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sphere3d.boundary.edges import Edges
from sphere3d.vector import dot, norm

__all__ = ["LEAF", "QUERY_POINTS", "SLACK", "EdgeTree", "edge_tree"]

LEAF = 8
"""Edges per leaf."""
SLACK = 1e-9
"""Kept in every cull's cosine comparison beyond the bounds (their rounding is about 1e-15)."""
QUERY_POINTS = 1024
"""Points walked down the tree at once."""


def _morton(points: np.ndarray) -> np.ndarray:
    """30-bit Morton codes of ``points`` (N, 3) in their bounding box: 10 bits per axis, interleaved."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    cell = ((points - lo) / np.where(hi > lo, hi - lo, 1.0) * 1023.0).astype(np.int64)
    code = np.zeros(len(points), dtype=np.int64)
    for bit in range(10):
        for axis in range(3):
            code |= ((cell[:, axis] >> bit) & 1) << (3 * bit + axis)
    return code


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
    """

    order: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    axis: np.ndarray
    spread: np.ndarray
    depth: int
    cos_spread: np.ndarray
    sin_spread: np.ndarray

    @staticmethod
    def build(edges: Edges, subset: np.ndarray) -> EdgeTree:
        """The tree over the edges ``subset`` (indices into ``edges``)."""
        n = subset.size
        depth = max(0, int(np.ceil(np.log2(max(n, 1) / LEAF))))
        leaves = 1 << depth
        mid = 0.5 * (edges.a + edges.b)[subset]
        by_code = np.argsort(_morton(mid), kind="stable") if n else np.zeros(0, dtype=np.int64)
        order = np.full(leaves * LEAF, -1, dtype=np.int64)
        order[:n] = subset[by_code]
        slots = order.reshape(leaves, LEAF)
        real = slots >= 0
        e = slots.clip(0)
        m, h = 0.5 * (edges.a + edges.b)[e], 0.5 * norm(edges.b - edges.a)[e]
        # heap arrays; an empty node has lo = +inf, hi = -inf, so min / max merge it away
        size = 2 * leaves
        lo, hi = np.full((size, 3), np.inf), np.full((size, 3), -np.inf)
        filled, axis, spread = np.zeros(size, dtype=bool), np.zeros((size, 3)), np.full(size, np.pi)
        leaf = slice(leaves, size)
        lo[leaf] = np.min(np.where(real[..., None], m - h[..., None], np.inf), axis=1)
        hi[leaf] = np.max(np.where(real[..., None], m + h[..., None], -np.inf), axis=1)
        filled[leaf] = real[:, 0]
        total = np.sum(np.where(real[..., None], edges.n1[e] + edges.n2[e], 0.0), axis=1)
        length = norm(total)
        d = total / np.where(length > 0.0, length, 1.0)[:, None]
        worst = np.maximum(_angle(edges.n1[e], d[:, None]), _angle(edges.n2[e], d[:, None]))
        open_edge = np.any(real & edges.always[e], axis=1)  # a silhouette from every point
        axis[leaf] = d
        spread[leaf] = np.where(
            open_edge | (length == 0.0), np.pi, np.max(np.where(real, worst, 0.0), axis=1)
        )
        for level in range(depth - 1, -1, -1):  # the parents of each level, up to the root
            node = np.arange(1 << level, 2 << level)
            left, right = 2 * node, 2 * node + 1
            lo[node] = np.minimum(lo[left], lo[right])
            hi[node] = np.maximum(hi[left], hi[right])
            fl, fr = filled[left], filled[right]
            filled[node] = fl | fr
            # the merged cone: about the children's mean axis, wide enough to hold both cones
            s = axis[left] * fl[:, None] + axis[right] * fr[:, None]
            length = norm(s)
            merged = s / np.where(length > 0.0, length, 1.0)[:, None]
            reach = np.maximum(
                np.where(fl, _angle(merged, axis[left]) + spread[left], 0.0),
                np.where(fr, _angle(merged, axis[right]) + spread[right], 0.0),
            )
            axis[node] = merged
            spread[node] = np.where(length > 0.0, np.minimum(reach, np.pi), np.pi)
        lo, hi = np.where(filled[:, None], lo, 0.0), np.where(filled[:, None], hi, 0.0)
        centre = 0.5 * (lo + hi)
        radius = np.where(filled, 0.5 * norm(hi - lo), -1.0)
        return EdgeTree(order, centre, radius, axis, spread, depth, np.cos(spread), np.sin(spread))

    def _keep(self, o: np.ndarray, node: np.ndarray, emitters: tuple[np.ndarray, float] | None) -> np.ndarray:
        """Whether node ``node`` may hold a pair with point ``o`` (both (n, ...)): the two culls, in
        cosines (module docstring; ``SLACK`` covers their rounding)."""
        v = o - self.centre[node]
        dist = norm(v)
        r = self.radius[node]
        outside = dist > r
        safe = np.where(outside, dist, 1.0)
        sin_b = np.where(outside, np.maximum(r, 0.0), 0.0) / safe  # β: the sphere's angular radius
        cos_b = np.sqrt(1.0 - sin_b * sin_b)
        cos_phi = dot(self.axis[node], v) / safe  # φ: from the cone's axis to the direction to o
        # cos(π/2 - α - β) = sin(α + β): |cos φ| above it puts every n·(o - p) on one side
        sin_a, cos_a = self.sin_spread[node], self.cos_spread[node]
        sin_ab, cos_ab = sin_a * cos_b + cos_a * sin_b, cos_a * cos_b - sin_a * sin_b
        cull = (cos_ab > 0.0) & (np.abs(cos_phi) > sin_ab + SLACK)  # α + β < π/2 and φ clear of π/2 by it
        if emitters is not None:
            centre, radius = emitters
            to = centre - o
            d_to = norm(to)
            far = d_to > radius
            sin_e = radius / np.where(far, d_to, 1.0)
            cos_e = np.sqrt(np.maximum(0.0, 1.0 - sin_e * sin_e))
            # the angle from o between the two spheres' centres beyond β + (the emitters' angular radius)
            cos_gap = -dot(v, to) / (safe * np.where(far, d_to, 1.0))
            cos_sum = cos_b * cos_e - sin_b * sin_e  # cos(β + γ), γ + β < π as both are below π/2
            cull |= far & (cos_gap < cos_sum - SLACK)
        return (r >= 0.0) & ~(outside & cull)

    def candidates(
        self,
        o: np.ndarray,
        emitters: tuple[np.ndarray, float] | None = None,
        test: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """(rows, edges, tests): a superset of the pairs (point ``o[row]``, edge) whose edge may be a
        silhouette seen from the point and, given the emitters' bounding sphere ``(centre, radius)``,
        may reach their image (module docstring), grouped by blocks of points; with ``test`` (rows,
        edges) -> mask, only the pairs it keeps. ``tests`` counts the (point, node) tests of the walk.
        Memory: the pairs of one level of the walk and the candidates of :data:`QUERY_POINTS` points
        at a time."""
        rows, cols = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
        tests = 0
        for lo in range(0, len(o), QUERY_POINTS):
            p = np.arange(lo, min(lo + QUERY_POINTS, len(o)))
            node = np.ones(p.size, dtype=np.int64)
            for level in range(self.depth + 1):
                keep = self._keep(o[p], node, emitters)
                tests += keep.size
                p, node = p[keep], node[keep]
                if level < self.depth:  # both children of every node kept
                    p, node = np.repeat(p, 2), (2 * node[:, None] + np.arange(2)).ravel()
            edge = self.order.reshape(-1, LEAF)[node - (1 << self.depth)]  # (pairs, LEAF)
            real = edge >= 0
            r, c = np.repeat(p, LEAF)[real.ravel()], edge[real]
            if test is not None:
                keep = test(r, c)
                r, c = r[keep], c[keep]
            rows.append(r)
            cols.append(c)
        return np.concatenate(rows), np.concatenate(cols), tests


_TREES: dict[int, tuple[weakref.ref, dict[bytes, EdgeTree]]] = {}
_LOCK = threading.Lock()


def edge_tree(edges: Edges, subset: np.ndarray) -> EdgeTree:
    """:meth:`EdgeTree.build` over the edges where the mask ``subset`` (E,) is True, built once per
    ``edges`` object and mask and kept while ``edges`` lives (every slice of shading points of a
    render asks for the same trees). Read-only."""
    key = subset.tobytes()
    with _LOCK:
        entry = _TREES.get(id(edges))
        if entry is not None and entry[0]() is edges and key in entry[1]:
            return entry[1][key]
    tree = EdgeTree.build(edges, np.flatnonzero(subset))
    with _LOCK:
        key_edges = id(edges)
        entry = _TREES.get(key_edges)
        if entry is None or entry[0]() is not edges:
            ref = weakref.ref(edges, lambda _: _TREES.pop(key_edges, None))
            entry = _TREES[key_edges] = (ref, {})
        entry[1][key] = tree
    return tree
