r"""The boundary term of the shading integrals: edge sampling on S² at each shading point (secondary edges).

At a shading point x with normal n the renderer integrates $E = ∫ f(ω) dω$ over
the sphere, $f = L_i(ω) \max(0, n·ω)$ (both MIS strategies together: their weights
sum to 1, so the jumps of the two weighted integrands add up to the jumps of f).
With direct illumination $L_i(ω)$ is what the ray from x along ω meets first: the sky,
the front of an emitter (its radiance times the border fade), or 0. It jumps where
that changes, on the spherical images of the **silhouette edges seen from x**: the
occluders' outlines (shadow edges) and the emitters' own borders (sharp unless they
fade). Creases seen from x are no discontinuity (f does not depend on the normal of
the surface it meets), and f is continuous at the horizon (the cosine is 0 there).

Boundary term (Loubet et al. 2019, Sec. 3; Li et al. 2018, Sec. 4, written on S²
rather than on the edge). An edge AB seen from x is an arc C of the great circle
with unit normal $m = (A - x) × (B - x) / |…|$. When θ moves the edge (or x), a
point $ω(θ) = (P - x)/|P - x|$ of the arc, $P = A + s (B - A)$ at fixed s, moves with
$\dot ω$ and the arc sweeps solid angle at the rate $m·\dot ω$ per unit arc length, so by
the Reynolds transport theorem

    $dE/dθ = ∫ ∂f/∂θ\, dω + Σ_\mathrm{edges} ∫_C [f(ω^-) - f(ω^+)] (m·\dot ω)\, dℓ$,

$ω^∓ = ω ∓ δ m$ just beside the arc, dℓ its arc length (radians). The first term is the
``naive`` estimator. For the second, only the silhouette edges that can contribute are
candidates (:func:`_found`): an edge that does not move, seen from a point that does not
move, has $m·\dot ω = 0$ exactly (with ``occluder.translate.x`` the emitter's own border, most of
the candidates' length); and under a black sky f
vanishes outside the emitters' directions on both sides of every arc, so an arc counts only
where it crosses an emitter's spherical image: each arc above the horizon ($n·(P - x) > 0$, a
linear condition in s) is clipped to the image of every emitter triangle
(:func:`clip_arcs`; emitters' own edges, whose arcs are the images' borders, are not
clipped). Each shading point draws k sub-arcs among its candidates' with probability ∝ their
angle ($Γ = Σ \mathrm{angles}$), then a point uniform in angle on each: density $c/Γ$ per radian,
c the number of sub-arcs of that arc holding the point (1 unless emitters overlap as seen
from x), and the estimate is the mean over the k draws of $(Γ/c) [f(ω^-) - f(ω^+)] (m·\dot ω)$:
nearly every drawn point has a nonzero jump. The 3D point P
behind ω on the edge is found in the plane of the arc; $\dot ω$ comes from forward AD of
``normalize(P(θ) - x(θ))`` with the edge's Dual vertices. Both sides are traced (four rays
per draw: at δ = :data:`EPS_ANGLE` and at 2δ, extrapolated to δ → 0); $L_i$ along a ray is
deterministic, so the jump is exact up to $O(δ^2)$.

The silhouette pairs come from a tree over the edges (:mod:`sphere3d.boundary.edge_tree`: bounding
spheres and normal cones, culled by facing and by the emitters' cone, then the exact test on the
edges of the leaves reached): exactly the pairs of testing every (point, edge) pair, found in a
time that grows with the silhouette edges each point sees (about the square root of a fine mesh's
edges), not with all of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flatland.core.dual import Dual, detach, tangent
from sphere3d.boundary.edge_tree import edge_tree
from sphere3d.boundary.edges import Edges
from sphere3d.jit import compiled
from sphere3d.live import moves
from sphere3d.tables import per_state
from sphere3d.tracing import face_normals
from sphere3d.vector import cross, dot, norm

__all__ = [
    "EPS_ANGLE",
    "MAX_EMITTER_TRIANGLES",
    "EdgeDraws",
    "clip_arcs",
    "edge_draws",
    "moving_edges",
    "reynolds",
    "shading_edge_term",
]

EPS_ANGLE = 1e-6
"""Angle δ (radians) between the sampled edge direction and the nearer rays traced beside it (the others
at 2δ). One pair alone has a bias of order δ / (feature angle · tan(corner angle)): near a corner the
ray on one side crosses the corner's other edge; the two pairs' extrapolation cancels its first order
(:func:`shading_edge_term`), leaving O(δ²). Below about 1e-7 the rays' float32 rounding (Embree)
takes over."""
MAX_EMITTER_TRIANGLES = 64
"""Emitter triangles up to which the arcs are clipped to the emitters' images (cost: pairs × this)."""


@per_state
def _moving_vertices(state) -> np.ndarray:
    """(T, 3): whether each triangle's vertex has a nonzero tangent, under any parameter (once per state)."""
    return np.any(moves(state.triangles), axis=-1)


def _incident(state, origin: np.ndarray, d: np.ndarray) -> np.ndarray:
    """L_i along unit directions ``d`` from ``origin`` at θ0 (plain): the sky, an emitter's front, or 0."""
    hits = state.tracer.intersect(origin, d)
    out = np.where(hits.hit, 0.0, float(detach(state.sky)))
    e = np.flatnonzero(hits.hit & np.isin(hits.triangle, state.emitters))
    if e.size:
        tri = hits.triangle[e]
        front = dot(face_normals(np.asarray(detach(state.triangles))[tri]), d[e]) < 0.0
        value = np.asarray(detach(state.emitted(tri, hits.u[e], hits.v[e])), dtype=np.float64)
        out[e] = value * front
    return out


def _emitter_bounds(state) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The emitter triangles (T, 3, 3) at θ0, their bounding sphere's centre and radius, or None.

    Only when the sky is black (and not the parameter): then f is 0 outside the emitters'
    directions on both sides of any edge, so the arcs can be restricted to the emitters'
    spherical images without changing any expectation (:func:`_found`, :func:`clip_arcs`).
    None (no restriction) otherwise or without emitters.
    """
    sky = float(detach(state.sky)) != 0.0 or state.sky_varies
    if sky or len(state.emitters) == 0:
        return None
    triangles = np.asarray(detach(state.triangles))[state.emitters]
    centre = triangles.reshape(-1, 3).mean(axis=0)
    radius = 1.001 * float(np.max(norm(triangles.reshape(-1, 3) - centre)))  # margin for rounding
    return triangles, centre, radius


def _found(edges: Edges, o: np.ndarray, moving, point_moves, bounds) -> tuple[np.ndarray, np.ndarray]:
    r"""Every silhouette pair (rows, edges) of the points ``o`` whose edge moves or is seen from a
    moving point and whose arc may meet the emitters (under a black sky), sorted by point, in the
    order of edge index within one: a fixed point walks the tree's moving edges, a moving point every
    edge (a pair of a fixed edge and a fixed point has $m·\dot ω = 0$): one tree, the moving edges in
    subtrees of their own (:func:`~sphere3d.boundary.edge_tree.edge_tree`)."""
    near = None if bounds is None else (bounds[1], bounds[2])
    # the emitters' images: the cull the clip makes exact (clip_arcs), where the arcs are clipped
    triangles = None if bounds is None or len(bounds[0]) > MAX_EMITTER_TRIANGLES else bounds[0]
    rows, cols = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
    for group, restrict in ((~point_moves, True), (point_moves, False)):
        points = np.flatnonzero(group)
        if points.size and (moving.any() or not restrict):
            r, c = edge_tree(edges, moving, restrict).silhouettes(o[points], near, triangles)
            rows.append(points[r])
            cols.append(c)
    if len(rows) == 2:  # one group: already by point
        return rows[1], cols[1]
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    by_point = np.argsort(rows, kind="stable")
    return rows[by_point], cols[by_point]


def _arc_frame(qa: np.ndarray, qb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""Unit vectors $(w_a, w_⊥)$ with the arc from qa to qb at angles $φ ∈ [0, γ]$:
    $\cos φ\, w_a + \sin φ\, w_⊥$."""
    wa = qa / norm(qa)[:, None]
    perp = qb - wa * dot(qb, wa)[:, None]
    length = norm(perp)
    return wa, perp / np.where(length > 0.0, length, 1.0)[:, None]


def _image_sides(o: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""Per point and emitter triangle $L_0 L_1 L_2$ ($q_i = L_i - o$): the sides' normals
    $c_i = q_{i+1} × q_i$ (points, T, 3, 3) and whether o sees the triangle's front (points, T):
    $\det(q_0, q_1, q_2) < 0$, the side ``face_normals`` points to. Seen from o the triangle covers
    the directions with $w·c_i ≥ 0$ for i = 0, 1, 2."""
    q = triangles[None] - o[:, None, None, :]  # (points, T, 3 vertices, 3)
    sides = cross(q[:, :, [1, 2, 0]], q)  # c_i = q_{i+1} × q_i
    return sides, np.einsum("ptk,ptk->pt", q[:, :, 0], sides[:, :, 1]) > 0.0  # q₀·(q₂ × q₁) = -det


def clip_arcs(
    o: np.ndarray,
    n0: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    clip: np.ndarray,
    sides: np.ndarray,
    front: np.ndarray,
    s0: np.ndarray,
    s1: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
) -> None:
    r"""Each pair (point ``o[rows[p]]``, edge ``cols[p]`` from ``a`` to ``b``): its arc clipped to the
    point's horizon, written to ``s0``, ``s1`` (the edge parameters of its ends), and its sub-arcs
    $[lo, hi]$ of $[0, γ]$ in the images of the emitter triangles, written to ``lo``, ``hi`` (P, T);
    where ``clip[cols[p]]`` is False or T = 0, one sub-arc, the whole arc, in column 0. Scalar Python
    compiled by Numba (:func:`sphere3d.jit.compiled`).

    Horizon: $h(s) = n·(a + s (b - a) - o)$ is linear in s; the part with h > 0 is kept.
    Images (``sides``, ``front``: :func:`_image_sides` per point): on the arc
    $w(φ) = \cos φ\, w_a + \sin φ\, w_⊥$ (:func:`_arc_frame`), $w(φ)·c = R \cos(φ - φ_c)$, so each side
    keeps the half-circle $|φ - φ_c| ≤ π/2$; as $γ ≤ π$ the arc meets it in one interval, found with $φ_c$
    taken in $(-π/2, 3π/2]$ (for $φ_c ≤ -π/2$ the half-circle around $φ_c$ meets $[0, π]$ in
    $\{0\}$ at most, the one around $φ_c + 2π$ in the rest). A triangle seen from behind: empty
    (hi = lo). Shortcuts, exact as $γ ≤ π$ (a sinusoid $R \cos(φ - φ_c)$ of one sign at both ends of
    $[0, γ]$ keeps it between them): both ends beyond one side, empty; both strictly within every
    side, the whole arc; most arcs are one or the other, and skip the angles."""
    n_tris = sides.shape[1]
    for p in range(rows.shape[0]):
        i, k = rows[p], cols[p]
        ax, ay, az = a[k, 0] - o[i, 0], a[k, 1] - o[i, 1], a[k, 2] - o[i, 2]
        ex, ey, ez = b[k, 0] - a[k, 0], b[k, 1] - a[k, 1], b[k, 2] - a[k, 2]
        ha = ax * n0[i, 0] + ay * n0[i, 1] + az * n0[i, 2]
        hb = ha + ex * n0[i, 0] + ey * n0[i, 1] + ez * n0[i, 2]
        # the part above the horizon: h(s) = ha + s (hb - ha) > 0
        cross_s = ha / (ha - hb) if ha != hb else 0.0
        lo_s = 0.0 if ha > 0.0 else (cross_s if hb > ha else 1.0)
        hi_s = 1.0 if hb > 0.0 else (cross_s if ha > hb else 0.0)
        s0[p], s1[p] = lo_s, hi_s
        for t in range(lo.shape[1]):
            lo[p, t], hi[p, t] = 0.0, 0.0
        if hi_s <= lo_s:
            continue
        qax, qay, qaz = ax + lo_s * ex, ay + lo_s * ey, az + lo_s * ez
        qbx, qby, qbz = ax + hi_s * ex, ay + hi_s * ey, az + hi_s * ez
        cx, cy, cz = qay * qbz - qaz * qby, qaz * qbx - qax * qbz, qax * qby - qay * qbx
        gamma = np.arctan2(np.sqrt(cx * cx + cy * cy + cz * cz), qax * qbx + qay * qby + qaz * qbz)
        if n_tris == 0 or not clip[k]:
            hi[p, 0] = gamma
            continue
        length = np.sqrt(qax * qax + qay * qay + qaz * qaz)
        wx, wy, wz = qax / length, qay / length, qaz / length
        along = qbx * wx + qby * wy + qbz * wz
        px, py, pz = qbx - along * wx, qby - along * wy, qbz - along * wz
        length = np.sqrt(px * px + py * py + pz * pz)
        length = length if length > 0.0 else 1.0
        px, py, pz = px / length, py / length, pz / length
        for t in range(n_tris):
            start, stop = 0.0, gamma
            if not front[i, t]:
                lo[p, t], hi[p, t] = 0.0, 0.0
                continue
            # both ends beyond one side: the arc (γ <= π) lies beyond it; both within every side: inside
            outside, inside = False, True
            for j in range(3):
                c0, c1, c2 = sides[i, t, j, 0], sides[i, t, j, 1], sides[i, t, j, 2]
                da, db = qax * c0 + qay * c1 + qaz * c2, qbx * c0 + qby * c1 + qbz * c2
                outside = outside or (da < 0.0 and db < 0.0)
                inside = inside and da > 0.0 and db > 0.0
            if outside or inside:
                lo[p, t], hi[p, t] = 0.0, 0.0 if outside else gamma
                continue
            for j in range(3):
                c0, c1, c2 = sides[i, t, j, 0], sides[i, t, j, 1], sides[i, t, j, 2]
                phi_c = np.arctan2(px * c0 + py * c1 + pz * c2, wx * c0 + wy * c1 + wz * c2)
                if phi_c <= -0.5 * np.pi:
                    phi_c += 2.0 * np.pi
                start = max(start, phi_c - 0.5 * np.pi)
                stop = min(stop, phi_c + 0.5 * np.pi)
            lo[p, t], hi[p, t] = start, stop


def _choose(edges, o, n0, u, moving, point_moves, bounds, unclipped) -> tuple[np.ndarray, ...]:
    r"""The draws (flat index ``i k + c`` for column c of ``u``, shape (m, k)) of the points with a
    moving silhouette edge above the horizon, and for each: one sub-arc of such an edge drawn ∝ its
    angle, its edge, its arc's ends and s0, s1, the sub-arc's start and angle, the ends ``lo``,
    ``hi`` of all sub-arcs of its arc (draws, T), and the point's $Γ = Σ \mathrm{angles}$.

    A sub-arc is the part of an arc inside one emitter triangle's image under a black sky with at
    most :data:`MAX_EMITTER_TRIANGLES` of them, except on the emitters' own edges (whose arcs lie
    on their images' borders: ``unclipped``); otherwise the whole arc above the horizon.
    """
    m = len(o)
    rows, cols = _found(edges, o, moving, point_moves, bounds)
    clipped = bounds is not None and len(bounds[0]) <= MAX_EMITTER_TRIANGLES
    sides, front = _image_sides(o, bounds[0] if clipped else np.zeros((0, 3, 3)))
    s0, s1 = np.empty(rows.size), np.empty(rows.size)
    lo, hi = np.empty((rows.size, sides.shape[1] or 1)), np.empty((rows.size, sides.shape[1] or 1))
    compiled(clip_arcs)(o, n0, rows, cols, edges.a, edges.b, ~unclipped, sides, front, s0, s1, lo, hi)
    pair, sub = np.nonzero(hi > lo)  # sub-arcs, sorted by pair, hence by row
    angle = (hi - lo)[pair, sub]
    owner = rows[pair]
    if pair.size == 0:
        return (
            (np.zeros(0, dtype=np.int64),) * 2
            + (np.zeros(0),) * 4
            + (np.zeros((0, lo.shape[1])),) * 2
            + (np.zeros(0),)
        )
    total = np.bincount(owner, weights=angle, minlength=m)
    cdf = np.cumsum(angle)
    first = np.concatenate([[0.0], cdf])[np.searchsorted(owner, np.arange(m))]
    # per draw (point i, column c: flat index i k + c), the sub-arc whose cdf interval holds
    # first + u Γ (zero-angle sub-arcs are never chosen)
    target = (first[:, None] + u * total[:, None]).ravel()
    j = np.minimum(np.searchsorted(cdf, target, side="right"), len(cdf) - 1)
    row = np.repeat(np.arange(m), u.shape[1])
    live = np.flatnonzero((total[row] > 0.0) & (owner[j] == row))
    j = j[live]
    p = pair[j]
    return live, cols[p], s0[p], s1[p], lo[p, sub[j]], angle[j], lo[p], hi[p], total[row[live]]


def moving_edges(state, edges: Edges) -> np.ndarray:
    """Per edge: whether an end of it moves under any parameter (the edges the tree puts first)."""
    vertex_moves = _moving_vertices(state)
    return vertex_moves[edges.face, edges.ia] | vertex_moves[edges.face, edges.ib]


@dataclass(frozen=True)
class EdgeDraws:
    r"""Edge samples of shading points (:func:`edge_draws`): per draw its flat index ``draw`` (i k + c for
    column c of point i's k), its point's row ``live``, the
    direction ``w`` on the drawn arc (plain, unit), the arc's normal ``normal`` on S², the normal
    velocities ``speeds`` $m·\dot ω$ (one array per parameter), ``scale`` = Γ / c (the inverse density per
    radian) and ``cos`` = $\max(0, n·w)$ at θ0."""

    draw: np.ndarray
    live: np.ndarray
    w: np.ndarray
    normal: np.ndarray
    speeds: list
    scale: np.ndarray
    cos: np.ndarray


def edge_draws(shading, edges: Edges, u: np.ndarray, bounds, unclipped: np.ndarray) -> EdgeDraws | None:
    r"""The k = ``u.shape[2]`` edge samples per shading point of the module docstring (None if none):
    sub-arcs drawn ∝ angle among the silhouette arcs above the horizon of the edges that move or are
    seen from a moving point, clipped to the emitters' images given ``bounds``
    (:func:`_emitter_bounds`; None: the whole arcs), a point uniform in angle on each, and the 3D point
    behind it on the edge, whose direction's tangent gives the normal velocity."""
    state = shading.state
    o = shading.origin
    n0 = np.asarray(detach(shading.n), dtype=np.float64)
    moving = moving_edges(state, edges)
    point_moves = np.any(moves(shading.x), axis=-1)
    draw, k, s0, s1, start, angle, lo, hi, total = _choose(
        edges, o, n0, u[:, 0], moving, point_moves, bounds, unclipped
    )
    if draw.size == 0:
        return None
    live = draw // u.shape[2]  # the draws' shading points
    # the drawn arcs' ends above the horizon, relative to o: a + s (b - a) - o at s0 and s1
    qa_all, e = edges.a[k] - o[live], (edges.b - edges.a)[k]
    qa, qb = qa_all + s0[:, None] * e, qa_all + s1[:, None] * e
    # a direction uniform in angle on the drawn sub-arc of the arc from qa to qb
    wa, perp = _arc_frame(qa, qb)
    phi = start + u[:, 1].ravel()[draw] * angle
    # density of φ: (number of the arc's sub-arcs holding it) / Γ; sub-arcs of two emitter
    # triangles overlap where one emitter is seen behind another, else they only touch
    overlap = np.maximum(np.sum((lo <= phi[:, None]) & (phi[:, None] <= hi) & (hi > lo), axis=1), 1)
    w = np.cos(phi)[:, None] * wa + np.sin(phi)[:, None] * perp
    normal = cross(qa, qb)
    normal = normal / norm(normal)[:, None]  # m: the arc's normal on S²
    # the point of the edge seen along w: qa + t (qb - qa) parallel to w
    den = dot(cross(qb - qa, w), normal)  # 0 only for an arc of zero angle, never drawn (rounding aside)
    t = -dot(cross(qa, w), normal) / np.where(den != 0.0, den, 1.0)
    s = s0 + np.clip(t, 0.0, 1.0) * (s1 - s0)
    a, b = edges.take(k).endpoints(state.triangles)
    point = a + s[:, None] * (b - a)
    x = shading.x[live]
    # from the ray origin o = x + ε n (value), moving with x (tangent)
    seen = point - (x + Dual(o[live] - detach(x), None, state.k) if isinstance(x, Dual) else o[live])
    omega = seen / norm(seen)[..., None]
    speeds = [dot(t, normal) for t in _slots(omega)]  # m·ω̇: the arc's normal velocity
    cos = np.maximum(dot(n0[live], w), 0.0)
    return EdgeDraws(draw, live, w, normal, speeds, total / overlap, cos)


def reynolds(draws: EdgeDraws, jump: np.ndarray, cos: np.ndarray, m: int, per_point: int, k) -> np.ndarray:
    r"""The mean over each point's ``per_point`` draws of $(Γ/c)\, \mathrm{jump} \cos\, (m·\dot ω)$,
    shape (m,) or (k, m): Reynolds on S², the side ω⁻ growing into ω⁺ at $m·\dot ω$, density c/Γ per
    radian."""
    terms = [
        np.bincount(draws.live, weights=draws.scale * jump * cos * s, minlength=m) / per_point
        for s in draws.speeds
    ]
    return terms[0] if k is None else np.stack(terms)


def shading_edge_term(shading, edges: Edges, u: np.ndarray, weight=None) -> np.ndarray:
    r"""One estimate per shading point of the boundary term of E (see the module docstring).

    With ``weight(rows, ω)``, plain values per draw (its shading point's row, its direction), the
    boundary term of $∫ L_i(ω)\, weight(ω) \max(0, n·ω)\, dω$ instead: a glossy point's BSDF
    $f(w_i, ω)$ at θ0 (:mod:`sphere3d.glossy`), continuous across every arc, so the jump is
    $[L_i(ω^-) - L_i(ω^+)]\, f(w_i, ω) \cos θ$. $L_i$ here is the emission (and sky) the side rays meet:
    on paths the radiance the surfaces they meet reflect has its own term
    (:mod:`sphere3d.boundary.indirect`).

    Parameters
    ----------
    shading : sphere3d.integrator.Shading
        Shading points of a state with θ as a Dual.
    edges : Edges
        The scene's edges at θ0.
    u : ndarray, shape (m, 2, k)
        Uniforms of k edge samples per point: the sub-arc, the point on it.

    Returns
    -------
    ndarray, shape (m,), or (p, m) for p parameters
        The tangent to add to the points' irradiance estimates: the mean of the k samples'. For p
        parameters the same draws, among the edges that move under any of them, times each one's
        normal velocity (a parameter that does not move an edge gives it 0: unbiased for each).
    """
    state = shading.state
    m = len(shading)
    out = np.zeros(m if state.k is None else (state.k, m))
    if m == 0 or len(edges) == 0:
        return out
    unclipped = np.isin(edges.face, state.emitters) | np.isin(edges.other, state.emitters) | (edges.count > 2)
    draws = edge_draws(shading, edges, u, _emitter_bounds(state), unclipped)
    if draws is None:
        return out
    live, w, normal, o = draws.live, draws.w, draws.normal, shading.origin
    # the jump f(ω⁻) - f(ω⁺) from rays at δ and 2δ beside the arc, extrapolated to δ → 0 (Richardson):
    # an offset ray crosses another edge near a corner on a length ∝ δ, so J(δ) = J + aδ + O(δ²)
    # and 2 J(δ) - J(2δ) = J + O(δ²)
    offsets = EPS_ANGLE * np.array([-1.0, 1.0, -2.0, 2.0])
    side = (w[None] + offsets[:, None, None] * normal[None]).reshape(-1, 3)
    side = side / norm(side)[:, None]
    f = _incident(state, np.tile(o[live], (4, 1)), side).reshape(4, live.size)
    jump = 2.0 * (f[0] - f[1]) - (f[2] - f[3])
    cos = draws.cos
    if weight is not None:  # a glossy point: its BSDF at the edge direction, the same on both sides
        cos = cos * weight(live, w)
    # Reynolds on S²: the side ω⁻ grows into ω⁺ at m·ω̇, density overlap/Γ per radian of arc
    return reynolds(draws, jump, cos, m, u.shape[2], state.k)


def _slots(x) -> list[np.ndarray]:
    """The tangent of ``x``, or its k slots (k parameters), as a list."""
    return [tangent(x)] if not isinstance(x, Dual) or x.k is None else list(x.tangent)
