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
from sphere3d.state import SceneState, per_state
from sphere3d.tracing import face_normals
from sphere3d.vector import dot

__all__ = ["COPLANAR_TOL", "Edges", "mesh_edges", "row_ids", "state_edges"]

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
    """Ids of the distinct rows of ``rows`` (N, k), numbered in the rows' lexicographic order: the
    ``return_inverse`` of ``np.unique(rows, axis=0)``, from one ``np.lexsort`` of the k columns
    (O(N log N); ``np.unique`` with an axis sorts the rows as opaque records, several times slower)."""
    n = len(rows)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    order = np.lexsort(rows.T[::-1])  # first column the primary key, as np.unique(axis=0)
    ranked = rows[order]
    new = np.empty(n, dtype=bool)
    new[0] = True
    np.any(ranked[1:] != ranked[:-1], axis=1, out=new[1:])  # by value: -0.0 and 0.0 are one vertex
    ids = np.empty(n, dtype=np.int64)
    ids[order] = np.cumsum(new) - 1
    return ids


def mesh_edges(triangles: object, shape_of: np.ndarray) -> Edges:
    """The unique edges of ``triangles`` (T, 3, 3), welded by exact position (see the module doc).

    Vectorized, O(T log T): vertex ids from one sort of the positions (:func:`row_ids`), edges as
    sorted id pairs (one integer key each), their faces from one stable sort of the three
    half-edges of every face.
    """
    tri = np.asarray(detach(triangles), dtype=np.float64)
    t = len(tri)
    vid = row_ids(tri.reshape(-1, 3)).reshape(t, 3)
    slots = np.array([[0, 1], [1, 2], [2, 0]])
    face = np.repeat(np.arange(t), 3)
    ia, ib = np.tile(slots[:, 0], t), np.tile(slots[:, 1], t)
    ends = np.stack([vid[face, ia], vid[face, ib]], axis=1)
    keep = ends[:, 0] != ends[:, 1]  # zero-length edges (refused earlier by check_world) are dropped
    face, ia, ib, ends = face[keep], ia[keep], ib[keep], np.sort(ends[keep], axis=1)
    # one key per (lower id, higher id): its order is the pairs' lexicographic order
    _, edge, count = np.unique(ends[:, 0] * (3 * t) + ends[:, 1], return_inverse=True, return_counts=True)
    order = np.argsort(edge, kind="stable")  # half-edges grouped by edge, faces in index order
    first = np.searchsorted(edge[order], np.arange(count.size))
    h1 = order[first]
    h2 = order[np.minimum(first + 1, order.size - 1)]
    two = count == 2
    other = np.where(two, face[h2], -1)
    face1 = face[h1]
    normals = face_normals(tri)
    n1 = normals[face1]
    n2 = np.where(two[:, None], normals[np.maximum(other, 0)], n1)
    between_shapes = two & (shape_of[face1] != shape_of[np.maximum(other, 0)])
    crease = two & (1.0 - dot(n1, n2) > COPLANAR_TOL)
    return Edges(
        face=face1,
        ia=ia[h1],
        ib=ib[h1],
        other=other,
        count=count,
        always=~two | between_shapes,
        crease=crease,
        a=tri[face1, ia[h1]],
        b=tri[face1, ib[h1]],
        n1=n1,
        n2=n2,
    )


@per_state
def state_edges(state: SceneState) -> Edges:
    """:func:`mesh_edges` of a state's triangles, once per state (kept while it lives)."""
    return mesh_edges(state.triangles, state.shape_of)
