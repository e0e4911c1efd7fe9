"""Ray tracing: detached queries in batches (Embree or brute force), hits re-attached with Duals.

This is the only module that imports ``embreex``. The data flow of theory/architecture:

1. **Trace detached.** A tracer holds the scene's triangles at θ0 (plain float32 for
   Embree) and answers batches of ray queries: which triangle each ray hits first
   (:meth:`EmbreeTracer.intersect`) or whether anything lies before a distance
   (:meth:`EmbreeTracer.occluded`). No tangents here: which triangle is hit is a
   piecewise-constant function of θ.
2. **Re-attach in numpy.** :func:`intersect_triangles` recomputes, in float64 and with
   :class:`~flatland.core.dual.Dual` arithmetic, the intersection of a (possibly
   moving, possibly reparameterized) ray with the hit triangle's θ-dependent vertices:
   distance, barycentrics, point and normal carry their θ-derivatives. This also
   removes Embree's float32 error from the values. :func:`attached_points` gives the
   point that *follows the shape* (fixed, detached barycentrics on moving vertices),
   which the probe heuristic of Sec. 4.3 needs.

:class:`BruteForceTracer` answers the same queries in pure numpy (every ray against
every triangle); the tests use it to check the Embree path on small meshes.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from flatland.core.dual import detach
from flatland.core.validate import check_choice
from sphere3d.vector import cross, dot, normalize

__all__ = [
    "BruteForceTracer",
    "EmbreeTracer",
    "Hits",
    "Intersection",
    "attached_points",
    "face_normals",
    "intersect_triangles",
    "make_tracer",
]

MISS = -1
FAR = np.inf


@dataclass(frozen=True)
class Hits:
    """First hits of a batch of rays (detached).

    Attributes
    ----------
    shape : ndarray of int
        Index of the hit shape, -1 where the ray missed.
    triangle : ndarray of int
        Global index of the hit triangle, -1 where the ray missed.
    t : ndarray
        Hit distance along the (unit) direction; inf for misses. Float32 accuracy
        from Embree: re-attach with :func:`intersect_triangles` for float64 values.
    u, v : ndarray
        Barycentric coordinates of the hit with respect to vertices 1 and 2.
    """

    shape: np.ndarray
    triangle: np.ndarray
    t: np.ndarray
    u: np.ndarray
    v: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        """True where the ray hit something."""
        return self.shape >= 0

    def on(self, flags: np.ndarray) -> np.ndarray:
        """True where the ray hit a triangle whose flag is set (``flags``: one per triangle)."""
        return self.hit & flags[np.maximum(self.triangle, 0)]

    def where(self, mask: np.ndarray, other: Hits) -> Hits:
        """These hits where ``mask`` is True, ``other``'s elsewhere (ray by ray)."""
        return Hits(*(np.where(mask, getattr(self, f), getattr(other, f)) for f in FIELDS))

    def without(self, mask: np.ndarray) -> Hits:
        """The same hits with the rays where ``mask`` is True turned into misses."""
        return Hits(MISS, MISS, FAR, 0.0, 0.0).where(np.asarray(mask, dtype=bool), self)

    def take(self, index: np.ndarray) -> Hits:
        """The hits of the rays at ``index``."""
        return Hits(*(getattr(self, f)[index] for f in FIELDS))

    def reshape(self, *shape: int) -> Hits:
        """The same hits with the ray axis reshaped (e.g. to (samples, probes))."""
        return Hits(*(getattr(self, f).reshape(*shape) for f in FIELDS))


FIELDS = tuple(f.name for f in fields(Hits))


def _rays(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
    origins = np.asarray(origins, dtype=np.float64)
    directions = np.asarray(directions, dtype=np.float64)
    shape = np.broadcast_shapes(origins.shape, directions.shape)
    o = np.broadcast_to(origins, shape).reshape(-1, 3)
    d = np.broadcast_to(directions, shape).reshape(-1, 3)
    return o, d, shape[:-1]


def _tmax(tmax: Any, shape: tuple[int, ...]) -> np.ndarray:
    if tmax is None:
        return np.full(int(np.prod(shape)), FAR)
    return np.broadcast_to(np.asarray(tmax, dtype=np.float64), shape).reshape(-1)


def _embree_rays(origins: Any, directions: Any, tmax: Any) -> tuple[np.ndarray, ...]:
    """Embree's contiguous float32 origins (N, 3), directions (N, 3) and ray lengths (N,) (at most 3e38),
    and the rays' shape: each written once from the float64 inputs (the same float32 numbers as
    :func:`_rays` and :func:`_tmax` converted, without their float64 copies)."""
    origins = np.asarray(origins, dtype=np.float64)
    directions = np.asarray(directions, dtype=np.float64)
    shape = np.broadcast_shapes(origins.shape, directions.shape)
    o, d = np.empty(shape, dtype=np.float32), np.empty(shape, dtype=np.float32)
    o[...], d[...] = origins, directions
    lengths = np.empty(shape[:-1], dtype=np.float32)
    if tmax is None:
        lengths[...] = 3e38  # min(FAR, 3e38)
    else:
        np.minimum(np.asarray(tmax, dtype=np.float64), 3e38, out=lengths)
    return o.reshape(-1, 3), d.reshape(-1, 3), lengths.reshape(-1), shape[:-1]


class EmbreeTracer:
    """Embree scene of triangles, queried in batches (float32, multithreaded inside Embree).

    Parameters
    ----------
    triangles : ndarray, shape (T, 3, 3)
        Vertex positions at θ0 (detached), grouped by shape: consecutive triangles
        of one shape share a ``shape_of`` index.
    shape_of : ndarray of int, shape (T,)
        Shape index of each triangle, non-decreasing.
    """

    name = "embree"

    def __init__(self, triangles: np.ndarray, shape_of: np.ndarray) -> None:
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        triangles = np.asarray(triangles, dtype=np.float64)
        shape_of = np.asarray(shape_of, dtype=np.int64)
        self._scene = rtcs.EmbreeScene()
        shapes = np.unique(shape_of)
        # one Embree geometry per shape, created in order: geomID g is shapes[g]
        self._shape_of_geom = shapes
        self._offset = np.zeros(len(shapes), dtype=np.int64)
        for g, s in enumerate(shapes):
            idx = np.flatnonzero(shape_of == s)
            self._offset[g] = idx[0]
            TriangleMesh(self._scene, np.ascontiguousarray(triangles[idx], dtype=np.float32))

    def intersect(self, origins: np.ndarray, directions: np.ndarray, tmax: Any = None) -> Hits:
        """First hit along each ray with 0 <= t <= tmax (unit ``directions``)."""
        o, d, lengths, shape = _embree_rays(origins, directions, tmax)
        if o.shape[0] == 0:
            empty = np.zeros(shape, dtype=np.int64)
            return Hits(empty - 1, empty - 1, np.full(shape, FAR), np.zeros(shape), np.zeros(shape))
        out = self._scene.run(o, d, dists=lengths, output=1)
        geom = out["geomID"].astype(np.int64)
        hit = geom >= 0
        g = np.where(hit, geom, 0)
        shape_idx = np.where(hit, self._shape_of_geom[g], MISS)
        triangle = np.where(hit, self._offset[g] + out["primID"].astype(np.int64), MISS)
        t = np.where(hit, out["tfar"].astype(np.float64), FAR)
        u = np.where(hit, out["u"].astype(np.float64), 0.0)
        v = np.where(hit, out["v"].astype(np.float64), 0.0)
        return Hits(
            shape_idx.reshape(shape),
            triangle.reshape(shape),
            t.reshape(shape),
            u.reshape(shape),
            v.reshape(shape),
        )

    def occluded(self, origins: np.ndarray, directions: np.ndarray, tmax: Any) -> np.ndarray:
        """True where something lies along the ray with 0 <= t <= tmax."""
        o, d, lengths, shape = _embree_rays(origins, directions, tmax)
        if o.shape[0] == 0:
            return np.zeros(shape, dtype=bool)
        out = self._scene.run(o, d, dists=lengths, query="OCCLUDED")
        # the occlusion query returns 0 for an occluded ray and -1 for a free one
        return (np.asarray(out) != -1).reshape(shape)


class BruteForceTracer:
    """Every ray against every triangle in float64 numpy (Möller–Trumbore); for tests on small meshes.

    Same constructor and queries as :class:`EmbreeTracer`.
    """

    name = "brute_force"

    def __init__(self, triangles: np.ndarray, shape_of: np.ndarray, chunk: int = 1 << 20) -> None:
        self._tri = np.asarray(triangles, dtype=np.float64)
        self._shape_of = np.asarray(shape_of, dtype=np.int64)
        self._chunk = max(1, chunk // max(1, len(self._tri)))

    def _nearest(self, o: np.ndarray, d: np.ndarray, t_max: np.ndarray) -> tuple[np.ndarray, ...]:
        v0, v1, v2 = self._tri[None, :, 0], self._tri[None, :, 1], self._tri[None, :, 2]
        e1, e2 = v1 - v0, v2 - v0
        dd = d[:, None, :]
        p = np.cross(dd, e2)
        det = np.sum(e1 * p, axis=-1)
        ok = np.abs(det) > 1e-300
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = o[:, None, :] - v0
        u = np.sum(s * p, axis=-1) * inv
        q = np.cross(s, e1)
        v = np.sum(dd * q, axis=-1) * inv
        t = np.sum(e2 * q, axis=-1) * inv
        valid = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t <= t_max[:, None])
        t = np.where(valid, t, FAR)
        best = np.argmin(t, axis=1)
        rows = np.arange(len(o))
        return best, t[rows, best], u[rows, best], v[rows, best]

    def intersect(self, origins: np.ndarray, directions: np.ndarray, tmax: Any = None) -> Hits:
        """First hit along each ray with 0 < t <= tmax (unit ``directions``)."""
        o, d, shape = _rays(origins, directions)
        t_max = _tmax(tmax, shape)
        n = o.shape[0]
        tri = np.full(n, MISS, dtype=np.int64)
        t, u, v = np.full(n, FAR), np.zeros(n), np.zeros(n)
        for start in range(0, n, self._chunk):  # memory chunks of rays
            sl = slice(start, start + self._chunk)
            best, tb, ub, vb = self._nearest(o[sl], d[sl], t_max[sl])
            found = np.isfinite(tb)
            tri[sl] = np.where(found, best, MISS)
            t[sl], u[sl], v[sl] = tb, np.where(found, ub, 0.0), np.where(found, vb, 0.0)
        shape_idx = np.where(tri >= 0, self._shape_of[np.maximum(tri, 0)], MISS)
        return Hits(
            shape_idx.reshape(shape), tri.reshape(shape), t.reshape(shape), u.reshape(shape), v.reshape(shape)
        )

    def occluded(self, origins: np.ndarray, directions: np.ndarray, tmax: Any) -> np.ndarray:
        """True where something lies along the ray with 0 < t <= tmax."""
        return self.intersect(origins, directions, tmax).hit


TRACERS = {"embree": EmbreeTracer, "brute_force": BruteForceTracer}


def make_tracer(
    triangles: np.ndarray, shape_of: np.ndarray, backend: str = "embree"
) -> EmbreeTracer | BruteForceTracer:
    """A tracer of the given ``backend`` ("embree" or "brute_force") for these triangles."""
    backend = check_choice("tracer", backend, tuple(TRACERS))
    return TRACERS[backend](triangles, shape_of)


# ----------------------------------------------------------------- re-attachment
class _once:  # noqa: N801  (a decorator, named like property)
    """A read-only attribute computed on first read and kept in the instance's ``__dict__``.

    ``functools.cached_property`` without its lock, which Python 3.11 shares among all instances
    and holds during the computation: it would serialize the renderer's threads.
    """

    def __init__(self, func: Any) -> None:
        self.func, self.name = func, func.__name__

    def __get__(self, obj: Any, owner: Any = None) -> Any:
        if obj is None:
            return self
        value = obj.__dict__[self.name] = self.func(obj)  # a frozen dataclass's __dict__ is writable
        return value


@dataclass(frozen=True)
class Intersection:
    """A ray–triangle intersection recomputed in float64, Dual where the inputs are.

    Attributes
    ----------
    b1, b2 : barycentrics of vertices 1, 2; t : distance along the direction;
    point : ``origin + t direction``; normal : unit face normal (winding order).
    ``t``, ``point`` and ``normal`` are computed when first read (not every caller needs them).
    """

    b1: Any
    b2: Any
    origin: Any
    direction: Any
    e1: Any  # v1 - v0
    e2: Any  # v2 - v0
    q: Any  # (origin - v0) × e1
    inv: Any  # 1 / det

    @_once
    def t(self) -> Any:
        return dot(self.e2, self.q) * self.inv

    @_once
    def point(self) -> Any:
        return self.origin + self.t[..., None] * self.direction

    @_once
    def normal(self) -> Any:
        return normalize(cross(self.e1, self.e2))


def intersect_triangles(origin: Any, direction: Any, tri: Any) -> Intersection:
    r"""Intersection of rays with the planes of given triangles (Möller–Trumbore), Dual-aware.

    Parameters
    ----------
    origin, direction : array_like or Dual, shape (..., 3)
        Rays; the direction need not be the one Embree traced (a reparameterized
        $R · \mathrm{detach}(ω)$ has the same value but carries $\dot R ω$).
    tri : array_like or Dual, shape (..., 3, 3)
        The hit triangles' vertices at θ (gathered from the scene's Dual vertices).

    Notes
    -----
    The barycentrics are not clamped: differentiating the plane intersection is what
    makes the hit point slide along the moving triangle, and at θ0 the values lie
    inside the triangle that Embree reported (up to float32 error at its edges).
    """
    v0, v1, v2 = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    e1 = v1 - v0
    e2 = v2 - v0
    p = cross(direction, e2)
    det = dot(e1, p)
    # rays parallel to the plane (never the case for a reported hit) get a harmless det = 1
    det = np.where(np.abs(detach(det)) > 1e-300, det, 1.0)
    s = origin - v0
    q = cross(s, e1)
    inv = 1.0 / det
    b1 = dot(s, p) * inv
    b2 = dot(direction, q) * inv
    return Intersection(b1, b2, origin, direction, e1, e2, q, inv)  # t = e2 · q / det (when read)


def attached_points(tri: Any, u: np.ndarray, v: np.ndarray) -> Any:
    """Points that follow the shape: fixed (detached) barycentrics on θ-dependent vertices (Sec. 4.3)."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    weights = np.stack([1.0 - u - v, u, v], axis=-1)
    # (1 - u - v) v0 + u v1 + v v2, linear in the vertices: one einsum for value and tangent each
    return np.einsum("...jk,...j->...k", tri, weights)


def face_normals(tri: Any) -> Any:
    """Unit normals of triangles (right-hand rule on the vertex order), Dual-aware."""
    return normalize(cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :]))
