r"""The boundary term of the emitter-sampling strategy: the light's own edges, held fixed.

The emitter strategy of :mod:`sphere3d.integrator` samples a point y uniformly on the
emitters' area A (at θ0), turns its direction $w(y)$ by one rotation $R(θ)$ per shading
point (:meth:`~sphere3d.integrator.Transforms.emitter`) and re-attaches it to the plane
of the sampled triangle: $T_θ(y)$, the identity at θ0. The re-attachment has no edge
(its barycentrics are not clamped), so the estimator differentiates

    $E_L(θ) = ∫_A F(T_θ(y), θ)\, 1[T_θ(y) ∈ A]\, |J|\, dA(y)$

without the indicator. F is the area-measure integrand
$L_e V \cos θ_x \cos θ_y / d^2 · w_L$ ($w_L$ the balance weight of the emitter strategy).
Where the rotation follows an occluder and the light's edge is sharp (no ``fade``),
the edge moves in the rotated frame, and its term is lost: the soft-shadow gradient.
By Leibniz's rule (Loubet et al. 2019, Sec. 4.3: an emitter's border is a
discontinuity like any other, to be followed or held fixed; theory/leibniz) the
missing term is

    $-∫_{∂A} F_\mathrm{in}(y) (V_T(y) · n_\mathrm{out}(y))\, dl(y)$,

$F_\mathrm{in}$ the integrand just inside, $n_\mathrm{out}$ the outward unit normal of A in its plane, and
$V_T = dT/dθ$ the velocity of the re-attached point relative to the emitter, read from
the tangents of the re-attached barycentrics, $V_T = \dot b_1 e_1 + \dot b_2 e_2$ ($e_1$, $e_2$ the
triangle's edge vectors): it is computed by the same Dual re-attachment
(:func:`~sphere3d.tracing.intersect_triangles`) along the rotated direction of the edge
point. Its value is 0, so the primal is unchanged; with it the emitter strategy's
derivative is unbiased for whatever rotation is chosen (the visibility it treats as
fixed aside, as the interior term does).

The edges are the emitters' **boundary edges** (one face among the emitter triangles),
edges between two emitter shapes and creases (two non-coplanar faces); for a
two-face edge both faces' terms are summed at the same point (each only if its front
faces the shading point). An edge shared by three or more emitter triangles gets the
term of one face only (no built-in scene has one). Each shading point draws
:data:`POINTS` points uniform in length on these edges, an antithetic pair (arc lengths
s and s + P/2 along their loops), one shadow ray each.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from flatland.core.dual import detach, tangent
from sphere3d.boundary.edges import mesh_edges
from sphere3d.live import any_rows, moves, take_rows
from sphere3d.rotation import Rotation
from sphere3d.shapes import FADE_NONE, FADE_RECTANGLE
from sphere3d.tables import per_state
from sphere3d.tracing import intersect_triangles
from sphere3d.vector import cross, dot, norm

__all__ = [
    "POINTS",
    "EdgeTable",
    "EmitterEdgeSamples",
    "edge_points",
    "edge_table",
    "emitter_edge_term",
    "sample_emitter_edges",
]

INV_PI = 1.0 / np.pi
POINTS = 2
"""Points on the edges per shading point, at arc lengths s and s + P/2 (one shadow ray each)."""


@dataclass(frozen=True)
class EdgeTable:
    """The emitters' edges that carry a term, in loop order, with per-face data (small arrays, θ0)."""

    a: np.ndarray  # (E, 3) start, in face 0's winding order
    b: np.ndarray  # (E, 3) end
    faces: np.ndarray  # (E, 2) global triangle indices, -1: no second face
    normals: np.ndarray  # (E, 2, 3) the faces' unit normals
    outward: np.ndarray  # (E, 2, 3) outward unit normal of each face at the edge, in its plane
    cdf: np.ndarray  # (E,) cumulative length in loop order


@dataclass(frozen=True)
class EmitterEdgeSamples:
    r"""Points on the emitters' edges, :data:`POINTS` per shading point (plain arrays, θ0).

    Attributes
    ----------
    index : ndarray of int, shape (k,)
        The shading point (row of the :class:`~sphere3d.integrator.Shading`) of each edge
        point above its surface and in front of a face of the edge (a shading point
        appears up to :data:`POINTS` times); visibility is traced by :meth:`term`.
    w : ndarray, shape (k, 3)
        Unit direction from the shading point to the edge point.
    edge : ndarray of int, shape (k,)
        The edge each point lies on (a row of ``table``).
    front : ndarray of bool, shape (k, 2)
        Which of the edge's (up to two) emitter triangles faces the shading point (the
        emitter strategy samples only those).
    dist, cos_x : ndarray, shape (k,)
        Distance to the edge point and $\cos θ_x$ there.
    table : EdgeTable
        The edges: endpoints, triangles, normals, outward normals in the triangles' planes.
    weight : float
        The edges' total length P over :data:`POINTS`: each point's weight.
    """

    index: np.ndarray
    w: np.ndarray
    edge: np.ndarray
    front: np.ndarray
    dist: np.ndarray
    cos_x: np.ndarray
    table: EdgeTable
    weight: float

    def take(self, rows: np.ndarray) -> EmitterEdgeSamples:
        """The edge points at ``rows``."""
        names = [f for f in self.__dataclass_fields__ if f not in ("table", "weight")]
        fields = [take_rows(getattr(self, f), rows) for f in names]  # rows by np.take (live.take_rows)
        return EmitterEdgeSamples(*fields, self.table, self.weight)

    def term(
        self, state: Any, shading: Any, rotation: Rotation, bsdf: Any = None, field: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The shading points and the boundary term's tangents, given one emitter rotation per shading point.

        Every edge point gets its shadow ray, and the visible ones the estimate of
        :meth:`tangent_term`; the points whose V_T is exactly 0 are left out before the draw
        (:func:`emitter_edge_term`).
        """
        tmax = self.dist - 2.0 * state.epsilon
        k = np.flatnonzero(~state.tracer.occluded(take_rows(shading.origin, self.index), self.w, tmax))
        sub = self.take(k)
        fields = None if field is None else field.take(sub.index)
        return sub.index, sub.tangent_term(
            state, shading.x[sub.index], rotation.take(sub.index), bsdf, fields
        )

    def tangent_term(
        self, state: Any, x: Any, rotation: Rotation, bsdf: Any = None, field: Any = None
    ) -> np.ndarray:
        r"""The boundary term's estimate (a tangent, shape (n,), or (p, n) for p parameters) given one
        rotation per point.

        ``x``: the points ``index`` (Dual positions); ``rotation``: their emitter rotations, followed by
        ``field`` (one per point) where it has one.
        Estimate $-P/\mathrm{POINTS} · Σ_\mathrm{faces} F_\mathrm{in} (V_T · n_\mathrm{out})$ per edge point
        (module docstring).
        """
        rotated = rotation.apply(self.w)
        if field is not None:  # the edge point moves with the whole map: V_T from its direction's tangent
            rotated = field.apply(self.w, rotated, jacobian=False)[0]
        area = float(detach(state.emitter_area))
        tri0 = np.asarray(detach(state.triangles))
        # operands without a tangent enter plain: the Dual rules give the same nonzero tangents
        # (a constant's tangent is a scalar 0), and a zero one ends as +0 in ``out`` either way
        faces_move = np.any(moves(state.triangles)[self.table.faces[self.table.faces >= 0]])
        tri = state.triangles if faces_move else tri0
        x = x if np.any(moves(x)) else detach(x)
        p = state.k  # None, or p parameters: each one's term from the same edge points
        out = np.zeros(len(self.index) if p is None else (p, len(self.index)))
        for j in range(2):  # the edge's two faces (not a loop over samples)
            s = np.flatnonzero(self.front[:, j])
            if s.size == 0:
                continue
            f = self.table.faces[self.edge[s], j]
            it = intersect_triangles(x[s], rotated[s], tri[f])
            t0 = tri0[f]
            # velocity of the re-attached point relative to the emitter, V_T = ḃ₁ e₁ + ḃ₂ e₂
            b1_dots, b2_dots = ([tangent(b)] if p is None else list(tangent(b, p)) for b in (it.b1, it.b2))
            speeds = []
            for b1_dot, b2_dot in zip(b1_dots, b2_dots, strict=True):
                v = b1_dot[:, None] * (t0[:, 1] - t0[:, 0]) + b2_dot[:, None] * (t0[:, 2] - t0[:, 0])
                speeds.append(dot(v, self.table.outward[self.edge[s], j]))
            speed = speeds[0] if p is None else np.stack(speeds)
            cos_y = -dot(self.table.normals[self.edge[s], j], self.w[s])  # the face's unit normal, tabled
            d = self.dist[s]
            p_light = d * d / (area * cos_y)  # solid-angle density of the emitter strategy
            p_cos = self.cos_x[s] * INV_PI if bsdf is None else bsdf.pdf(self.index[s], self.w[s])
            # F_in: L_e (just inside: the border fade, if any, is 0 there) cos_x cos_y / d² w_L
            emitted = np.asarray(detach(state.emitted(f, detach(it.b1), detach(it.b2))), dtype=np.float64)
            f_in = emitted * self.cos_x[s] * cos_y / (d * d) * (p_light / (p_light + p_cos))
            if bsdf is not None:  # a glossy point: its BSDF at the edge point's direction
                f_in = f_in * bsdf.value(self.index[s], self.w[s])
            out[..., s] -= self.weight * f_in * speed
        return out


@dataclass(frozen=True)
class _Rows:
    """A lobe (``value``, ``pdf`` by row) read at rows ``rows`` of the shading points it was made for."""

    lobe: Any
    rows: np.ndarray

    def value(self, r: np.ndarray, w: np.ndarray) -> np.ndarray:
        return self.lobe.value(self.rows[r], w)

    def pdf(self, r: np.ndarray, w: np.ndarray) -> np.ndarray:
        return self.lobe.pdf(self.rows[r], w)


def _faded_out(state: Any, edges: Any) -> np.ndarray:
    """Boundary edges along which the emitted radiance is 0 (a ``fade`` border): no term there.

    The fade factor (:func:`~sphere3d.shapes.fade_weight`) is 0 where a fade coordinate has
    |c| >= 1; along an edge the coordinates interpolate linearly, so it is 0 on the whole
    edge when one coordinate (u for both kinds, v too for rectangles) has the same value,
    of modulus >= 1, at both ends. Two-face edges are kept (their other face may glow).
    """
    face = state.emitters[edges.face]
    ua, ub = state.uv[face, edges.ia], state.uv[face, edges.ib]
    flat = (ua == ub) & (np.abs(ua) >= 1.0)
    kind = state.fade_kind[face]
    zero = flat[:, 0] | ((kind == FADE_RECTANGLE) & flat[:, 1])
    return (edges.other < 0) & (state.fade[face] > 0.0) & (kind != FADE_NONE) & zero


@per_state
def edge_table(state: Any) -> EdgeTable | None:
    """Boundary edges, edges between emitter shapes and creases of the emitter triangles.

    Ordered along their loops (each edge followed by the one starting where it ends, a
    walk over the few edges, not over samples) so that arc length ``s`` and ``s + P/2``
    are opposite points of a loop: on a parallelogram light, reflections through its
    centre (the antithetic pair of :func:`sample_emitter_edges`).

    Built once per state (:func:`~sphere3d.state.per_state`: every chunk of a render asks for
    it; ``edge_table.__wrapped__`` builds it anew) and read-only.
    """
    emitters = np.asarray(detach(state.triangles))[state.emitters]
    edges = mesh_edges(emitters, state.shape_of[state.emitters])
    keep = np.flatnonzero((edges.always | edges.crease) & ~_faded_out(state, edges))
    if keep.size == 0:
        return None
    edges = edges.take(keep)
    starts = {tuple(p): i for i, p in enumerate(edges.a)}
    order, seen, i = [], np.zeros(len(edges), dtype=bool), 0
    while len(order) < len(edges):
        order.append(i)
        seen[i] = True
        i = starts.get(tuple(edges.b[i]), -1)
        if i < 0 or seen[i]:  # a loop closed (or a chain ended): start the next one
            i = int(np.argmin(seen))
    edges = edges.take(np.array(order))
    local = np.stack([edges.face, edges.other], axis=1)
    tri = emitters[np.maximum(local, 0)]  # (E, 2, 3, 3)
    normals = np.stack([edges.n1, edges.n2], axis=1)
    outward = cross((edges.b - edges.a)[:, None], normals)
    outward = outward / norm(outward)[..., None]
    away = dot(outward, edges.a[:, None] - tri.mean(axis=2)) > 0.0  # away from the face's centroid
    table = EdgeTable(
        a=edges.a,
        b=edges.b,
        faces=np.where(local >= 0, state.emitters[np.maximum(local, 0)], -1),
        normals=normals,
        outward=np.where(away[..., None], outward, -outward),
        cdf=np.cumsum(norm(edges.b - edges.a)),
    )
    for f in fields(table):  # shared by every caller: read-only
        getattr(table, f.name).setflags(write=False)
    return table


def edge_points(table: EdgeTable, u: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` points per row evenly spaced in arc length along the edges, random phase ``u`` (m,):
    their edges (m, count) and positions (m, count, 3)."""
    cdf = table.cdf
    arc = np.add.outer(u, np.arange(count) / count)
    np.subtract(arc, 1.0, out=arc, where=arc >= 1.0)  # in [0, 2): that is arc % 1.0, exactly (Sterbenz)
    arc *= float(cdf[-1])
    e = np.searchsorted(cdf, arc, side="right")
    np.minimum(e, len(cdf) - 1, out=e)
    # per edge, then gathered: the same numbers as computing them per point (elementwise operations)
    length = cdf - np.concatenate([[0.0], cdf[:-1]])
    along = arc - np.take(cdf - length, e)
    along /= np.take(length, e)
    np.clip(along, 0.0, 1.0, out=along)
    point = along[..., None] * np.take(table.b - table.a, e, axis=0)
    point += np.take(table.a, e, axis=0)
    return e, point


def sample_emitter_edges(state: Any, shading: Any) -> EmitterEdgeSamples | None:
    """:data:`POINTS` points per shading point on the emitters' edges (module docstring).

    Each is uniform in length (density 1 / perimeter P): arc lengths ``s`` and
    ``s + P/2`` along the loops (antithetic: the terms of opposite edges nearly cancel
    when the light's image moves as a whole, and the pair samples them together).
    ``shading``: a :class:`~sphere3d.integrator.Shading`; random numbers from its draws
    (stream ``"emitter.edge"``), so the primary samples are untouched. None when the
    emitters have no such edge (a closed mesh without creases) or no point faces one.
    No ray is traced here (:meth:`EmitterEdgeSamples.term` traces the shadow rays).
    """
    table = edge_table(state)
    if table is None:
        return None
    perimeter = float(table.cdf[-1])
    e, y = edge_points(table, shading.draws.uniforms("emitter.edge"), POINTS)
    e, y = e.ravel(), y.reshape(-1, 3)
    point = np.repeat(np.arange(len(shading)), POINTS)
    to = y - take_rows(detach(shading.x), point)
    dist = norm(to)
    w = to / np.where(dist > 0.0, dist, 1.0)[:, None]
    cos_x = dot(take_rows(detach(shading.n), point), w)
    front = np.zeros((len(e), 2), dtype=bool)
    for j in np.flatnonzero(np.any(table.faces >= 0, axis=0)):  # the edges' one or two faces
        # facing the point: the emitter strategy's own test, cos θ_y > 1e-9
        front[:, j] = (-dot(table.normals[e, j], w) > 1e-9) & (table.faces[e, j] >= 0)
    valid = any_rows(front) & (cos_x > 0.0) & (dist > 4.0 * state.epsilon)
    idx = np.flatnonzero(valid)
    if idx.size == 0:
        return None
    return EmitterEdgeSamples(
        point[idx], take_rows(w, idx), e[idx], front[idx], dist[idx], cos_x[idx], table, perimeter / POINTS
    )


def emitter_edge_term(
    state: Any, shading: Any, rotation: Rotation, bsdf: Any = None, field: Any = None
) -> tuple[np.ndarray, np.ndarray]:
    r"""The boundary term's shading points and tangents, given one emitter rotation per shading point.

    V_T is exactly 0 where the rotation is the identity (no point followed) and neither
    the shading point nor an emitter moves (on ``hard_shadow`` the lit ground): those
    points get no edge samples. The others' are drawn by :func:`sample_emitter_edges` (the
    numbers they would get among all points: draws are keyed on the samples) and traced
    by :meth:`EmitterEdgeSamples.term`. ``bsdf``: at glossy points their lobe at θ0
    (:class:`~sphere3d.glossy.Lobe`, rows of ``shading``): $F_\mathrm{in}$ then holds $f(w_i, w)$ for
    ρ/π's place and the BSDF density in the balance weight (the reflected radiance's term, not E's).
    ``field``: a map per point after the rotation (:class:`~sphere3d.reparam.chart_field.ChartField`;
    its points' rotations are active), whose velocity the edge points then take.
    """
    x_moves = any_rows(moves(shading.x))
    emitters_move = np.any(moves(state.triangles)[state.emitters])
    rows = np.flatnonzero(rotation.active | x_moves | emitters_move)
    sub = shading if rows.size == len(shading) else shading.take(rows)
    edge = sample_emitter_edges(state, sub) if rows.size else None
    if edge is None:
        return rows[:0], np.zeros(0 if state.k is None else (state.k, 0))
    lobe = None if bsdf is None else _Rows(bsdf, rows)
    every = rows.size == len(shading)
    fields = None if field is None else (field if every else field.take(rows))
    index, term = edge.term(state, sub, rotation if every else rotation.take(rows), lobe, fields)
    return rows[index], term
