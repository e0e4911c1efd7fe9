"""Mesh edges with their adjacent faces: where the integrands of the renderer can jump.

The ``boundary`` method (:mod:`sphere3d.methods.boundary`) integrates the jump of an
integrand along the curves where it is discontinuous; with triangle meshes and
direct illumination those curves are images of mesh edges (Li et al. 2018,
"Differentiable Monte Carlo Ray Tracing through Edge Sampling", Sec. 3-4):

- **silhouette edges** seen from a viewpoint o: the two faces of the edge face o on
  opposite sides ($n_1·(o - a)$ and $n_2·(o - a)$ of opposite signs);
- **boundary edges** (one face): a silhouette from every viewpoint;
- **crease edges** (two non-coplanar faces): a flat-shaded face is shaded with its own
  normal, so the reflected radiance of a diffuse shape jumps across them (not on a
  smooth shape, whose interpolated vertex normals are continuous: the camera term
  skips those, :func:`sphere3d.boundary.camera.camera_candidates`).

Edges are found in the scene state's world-space triangles: vertices are welded by
exact position (the built-in shapes and loaded meshes index shared vertices, and a
state computes every vertex once, so equal positions are bit-equal), across shapes
too, so a segment two shapes share is one edge, counted once. An edge shared by
three or more faces (non-manifold) is treated like a boundary edge: a candidate from
every viewpoint. An edge whose two vertices weld together has zero length, which a
state refuses already (its triangle has zero area, :func:`sphere3d.world.check_world`);
such edges would be dropped here. Not handled: an edge that overlaps another edge
only in part (a T-junction) and lines where surfaces cut through each other, along
which visibility also jumps; no built-in scene has either.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flatland.core.dual import detach
from sphere3d.jit import compiled
from sphere3d.state import SceneState
from sphere3d.tables import per_state
from sphere3d.tracing import face_normals
from sphere3d.vector import dot

__all__ = ["COPLANAR_TOL", "Edges", "edge_groups", "mesh_edges", "row_ids", "sort_ties", "state_edges"]

COPLANAR_TOL = 1e-9
"""Two faces are coplanar (their common edge is no crease) when ``1 - n₁·n₂ <= COPLANAR_TOL``."""


@dataclass(frozen=True)
class Edges:
    """Unique edges of the scene's triangles.

    Attributes
    ----------
    face : ndarray of int, shape (E,)
        A triangle containing the edge (global triangle index of the state).
    ia, ib : ndarray of int, shape (E,)
        The edge's endpoints as vertex slots (0, 1, 2) of ``face``.
    other : ndarray of int, shape (E,)
        The second triangle of a two-face edge; -1 for boundary and non-manifold edges.
    count : ndarray of int, shape (E,)
        How many triangles share the edge (1: boundary, 2: manifold, 3+: non-manifold).
    always : ndarray of bool, shape (E,)
        Boundary or non-manifold edges, and edges between two shapes: candidates from
        every viewpoint.
    crease : ndarray of bool, shape (E,)
        Two-face edges between non-coplanar faces.
    a, b : ndarray, shape (E, 3)
        Endpoint positions at θ0.
    n1, n2 : ndarray, shape (E, 3)
        Unit normals of ``face`` and ``other`` (``n2 = n1`` where there is no other face).
    """

    face: np.ndarray
    ia: np.ndarray
    ib: np.ndarray
    other: np.ndarray
    count: np.ndarray
    always: np.ndarray
    crease: np.ndarray
    a: np.ndarray
    b: np.ndarray
    n1: np.ndarray
    n2: np.ndarray

    def __len__(self) -> int:
        return self.face.size

    def silhouette(self, o: np.ndarray) -> np.ndarray:
        """Which edges are silhouettes seen from points ``o`` (..., 3): shape (..., E).

        Boundary and non-manifold edges always are; a two-face edge is when the
        viewpoint lies strictly in front of one face and behind the other.
        """
        to = o[..., None, :] - self.a
        s1 = np.einsum("...ek,ek->...e", to, self.n1)
        s2 = np.einsum("...ek,ek->...e", to, self.n2)
        return self.always | (s1 * s2 < 0.0)

    def endpoints(self, triangles: object) -> tuple[object, object]:
        """The endpoints (A, B) of every edge from the state's triangles (Duals if they are)."""
        return triangles[self.face, self.ia], triangles[self.face, self.ib]

    def take(self, index: np.ndarray) -> Edges:
        """The edges at ``index``."""
        return Edges(*(getattr(self, f)[index] for f in self.__dataclass_fields__))


def row_ids(rows: np.ndarray) -> np.ndarray:
    """Ids of the distinct rows of ``rows`` (N, 3), numbered in the rows' lexicographic order (the
    ``return_inverse`` of ``np.unique(rows, axis=0)``; equal by value: -0.0 and 0.0 are one vertex),
    from one sort of the first column and :func:`sort_ties`."""
    rows = np.ascontiguousarray(rows, dtype=np.float64)
    if len(rows) == 0:
        return np.zeros(0, dtype=np.int64)
    order = np.argsort(rows[:, 0])  # numpy's sort of one column (vectorized), its ties then in order
    compiled(sort_ties)(order, rows)
    ranked = rows[order]
    new = np.empty(len(rows), dtype=bool)
    new[0] = True
    np.any(ranked[1:] != ranked[:-1], axis=1, out=new[1:])
    ids = np.empty(len(rows), dtype=np.int64)
    ids[order] = np.cumsum(new) - 1
    return ids


def _vertex_ids(tri: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """:func:`row_ids` of the corners ``tri`` (T, 3, 3) from one corner per vertex number of ``corners``
    (T, 3): the distinct positions and their ranks are those of the corners, since every corner of a
    number holds the same position."""
    flat = corners.ravel()
    count = int(flat.max()) + 1 if flat.size else 0
    one = np.full(count, -1, dtype=np.int64)
    one[flat] = np.arange(flat.size)  # some corner of each numbered vertex (the last written)
    used = one >= 0
    ids = np.zeros(count, dtype=np.int64)
    ids[used] = row_ids(tri.reshape(-1, 3)[one[used]])
    return ids[corners]


def sort_ties(order: np.ndarray, rows: np.ndarray) -> None:
    """Complete ``order``, a permutation sorting ``rows`` (N, 3) by their first column, into a
    lexicographic one (ties in any order), in place: each run of rows equal in the columns before c
    sorted by column c, for c = 1, 2. Runs are short (a vertex's copies, one per triangle corner), so
    this and one sort of a column are several times faster than a stable sort by each column in turn
    (``np.lexsort``). Scalar Python for Numba (:func:`sphere3d.jit.compiled`)."""
    n = rows.shape[0]
    for col in range(1, rows.shape[1]):
        i = 0
        while i < n:
            j = i + 1
            while j < n:
                equal = True
                for c in range(col):
                    equal = equal and rows[order[j], c] == rows[order[i], c]
                if not equal:
                    break
                j += 1
            if j - i > 32:  # a long run (a grid's vertices share coordinates): a sort, O(r log r)
                run = order[i:j].copy()
                keys = np.empty(j - i)
                for a in range(j - i):
                    keys[a] = rows[run[a], col]
                order[i:j] = run[np.argsort(keys, kind="mergesort")]  # stable: as the insertion sort
            elif j - i > 1:  # insertion sort of the run by column col (runs of a few rows)
                for a in range(i + 1, j):
                    moving, b = order[a], a
                    while b > i and rows[order[b - 1], col] > rows[moving, col]:
                        order[b] = order[b - 1]
                        b -= 1
                    order[b] = moving
            i = j


def mesh_edges(triangles: object, shape_of: np.ndarray, corners: np.ndarray | None = None) -> Edges:
    """The unique edges of ``triangles`` (T, 3, 3), welded by exact position (see the module doc).

    O(T log T): vertex ids from one sort of the positions (:func:`row_ids`), then the half-edges
    grouped into edges by their id pairs (:func:`edge_groups`). ``corners`` (T, 3), optional: each
    corner's vertex number, corners of one number at one position (:attr:`SceneState.corners
    <sphere3d.state.SceneState>`); the sort then ranks one corner per vertex (a closed mesh has about
    a sixth as many vertices as corners), and the ids are the same: the distinct positions, ranked.
    """
    tri = np.asarray(detach(triangles), dtype=np.float64)
    vid = row_ids(tri.reshape(-1, 3)).reshape(len(tri), 3) if corners is None else _vertex_ids(tri, corners)
    face1, slot1, other, count = compiled(edge_groups)(vid)
    two = count == 2
    ia, ib = slot1, (slot1 + 1) % 3
    normals = face_normals(tri)
    n1 = normals[face1]
    n2 = np.where(two[:, None], normals[np.maximum(other, 0)], n1)
    between_shapes = two & (shape_of[face1] != shape_of[np.maximum(other, 0)])
    crease = two & (1.0 - dot(n1, n2) > COPLANAR_TOL)
    return Edges(
        face=face1,
        ia=ia,
        ib=ib,
        other=other,
        count=count,
        always=~two | between_shapes,
        crease=crease,
        a=tri[face1, ia],
        b=tri[face1, ib],
        n1=n1,
        n2=n2,
    )


def edge_groups(vid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The edges of triangles with vertex ids ``vid`` (T, 3), in the lexicographic order of their id pairs
    (lower, higher): per edge the first face holding it and the slot j of its half-edge there (from
    vertex slot j to slot (j + 1) mod 3), the second face (-1 unless exactly two share it) and the
    number of faces. A half-edge whose two ids are equal (zero length) is dropped. The half-edges of
    one edge in the order of their faces (face index, then slot).

    O(T) plus short sorts: a stable counting sort of the half-edges by their lower id, then each
    bucket (the edges of one vertex) stably by the higher id. Scalar Python for Numba
    (:func:`sphere3d.jit.compiled`).
    """
    t = vid.shape[0]
    low, high = np.empty(3 * t, dtype=np.int64), np.empty(3 * t, dtype=np.int64)
    ids = 0
    for h in range(3 * t):
        a, b = vid[h // 3, h % 3], vid[h // 3, (h % 3 + 1) % 3]
        low[h], high[h] = min(a, b), max(a, b)
        ids = max(ids, b + 1)
    start = np.zeros(ids + 1, dtype=np.int64)
    for h in range(3 * t):
        if low[h] != high[h]:
            start[low[h] + 1] += 1
    for i in range(ids):
        start[i + 1] += start[i]
    fill = start.copy()
    by_low = np.empty(start[ids], dtype=np.int64)
    for h in range(3 * t):  # in half-edge order: stable
        if low[h] != high[h]:
            by_low[fill[low[h]]] = h
            fill[low[h]] += 1
    for i in range(ids):  # each vertex's half-edges by the higher id, stably
        bucket = by_low[start[i] : start[i + 1]]
        if bucket.size > 1:
            by_low[start[i] : start[i + 1]] = bucket[np.argsort(high[bucket], kind="mergesort")]
    m = by_low.size
    first = np.empty(m, dtype=np.int64)
    edges = 0
    for p in range(m):  # a new edge where the id pair changes
        h = by_low[p]
        if p == 0 or low[h] != low[by_low[p - 1]] or high[h] != high[by_low[p - 1]]:
            first[edges] = p
            edges += 1
    face, slot = np.empty(edges, dtype=np.int64), np.empty(edges, dtype=np.int64)
    other, count = np.full(edges, -1, dtype=np.int64), np.empty(edges, dtype=np.int64)
    for e in range(edges):
        p = first[e]
        count[e] = (first[e + 1] if e + 1 < edges else m) - p
        face[e], slot[e] = by_low[p] // 3, by_low[p] % 3
        if count[e] == 2:
            other[e] = by_low[p + 1] // 3
    return face, slot, other, count


@per_state
def state_edges(state: SceneState) -> Edges:
    """:func:`mesh_edges` of a state's triangles, once per state (kept while it lives)."""
    return mesh_edges(state.triangles, state.shape_of, state.corners)
