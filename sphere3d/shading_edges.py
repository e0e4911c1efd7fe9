"""The boundary term of the shading integrals: edge sampling on S² at each shading point (secondary edges).

At a shading point x with normal n the renderer integrates ``E = ∫ f(ω) dω`` over
the sphere, ``f = L_i(ω) max(0, n·ω)`` (both MIS strategies together: their weights
sum to 1, so the jumps of the two weighted integrands add up to the jumps of f).
With direct illumination L_i(ω) is what the ray from x along ω meets first: the sky,
the front of an emitter (its radiance times the border fade), or 0. It jumps where
that changes, on the spherical images of the **silhouette edges seen from x**: the
occluders' outlines (shadow edges) and the emitters' own borders (sharp unless they
fade). Creases seen from x are no discontinuity (f does not depend on the normal of
the surface it meets), and f is continuous at the horizon (the cosine is 0 there).

Boundary term (Loubet et al. 2019, Sec. 3; Li et al. 2018, Sec. 4, written on S²
rather than on the edge). An edge AB seen from x is an arc C of the great circle
with unit normal ``m = (A - x) × (B - x) / |…|``. When θ moves the edge (or x), a
point ω(θ) = (P - x)/|P - x| of the arc, P = A + s (B - A) at fixed s, moves with
``ω̇`` and the arc sweeps solid angle at the rate ``m·ω̇`` per unit arc length, so by
the Reynolds transport theorem

    dE/dθ = ∫ ∂f/∂θ dω  +  Σ_edges ∫_C [f(ω⁻) - f(ω⁺)] (m·ω̇) dℓ,

ω∓ = ω ∓ δ m just beside the arc, dℓ its arc length (radians). The first term is the
``naive`` estimator. For the second, each shading point draws **one** edge among its
silhouette edges with probability ∝ the angle γ_e it subtends above the horizon (the
arc clipped to n·(P - x) > 0, a linear condition in s), then a point uniform in angle
on that arc: density ``1/Γ`` per radian, Γ = Σ_e γ_e, and the estimate is
``Γ [f(ω⁻) - f(ω⁺)] (m·ω̇)``. Under a black sky f vanishes outside the emitters'
directions on both sides of every arc, so the arcs are first clipped to the cone around
the emitters' bounding sphere (:func:`_emitter_cone`): the same expectation, 20-27 % less
standard error at the shadow scene's penumbra points. The 3D point P behind ω on the edge is found in the
plane of the arc; ω̇ comes from forward AD of ``normalize(P(θ) - x(θ))`` with the
edge's Dual vertices. Both sides are traced (two rays per shading point); L_i along a
ray is deterministic, so the jump is exact up to the offset δ = :data:`EPS_ANGLE`.

Vectorized over shading points × edges, in blocks of at most :data:`MAX_PAIRS`.
"""

from __future__ import annotations

import numpy as np

from flatland.core.dual import Dual, detach, tangent
from sphere3d.edges import Edges
from sphere3d.tracing import face_normals
from sphere3d.vector import cross, dot, norm

__all__ = ["EPS_ANGLE", "MAX_PAIRS", "shading_edge_term"]

EPS_ANGLE = 1e-5
"""Angle (radians) between the sampled edge direction and the two rays traced beside it."""
MAX_PAIRS = 1 << 16
"""Shading points × edges of one block of the silhouette test (its arrays stay in cache: 5 × faster
than blocks of 2^20 on 65536 points × 1925 edges)."""


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


def _emitter_cone(state, o: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Per point, the cone (unit axis, cos of the half-angle) holding every emitter, or None.

    Only when the sky is black (and not the parameter): then f is 0 outside the emitters'
    directions on both sides of any edge, so the arcs can be restricted to the cone around the
    emitters' bounding sphere without bias. None (no restriction) when the point lies within
    twice that sphere's radius, or there is no emitter.
    """
    sky = float(detach(state.sky)) != 0.0 or state.param == "sky.emission"
    if sky or len(state.emitters) == 0:
        return None
    vertices = np.asarray(detach(state.triangles))[state.emitters].reshape(-1, 3)
    centre = vertices.mean(axis=0)
    radius = 1.001 * float(np.max(norm(vertices - centre)))  # margin: the side rays lie 1e-5 off the arc
    to = centre - o
    dist = norm(to)
    far = dist > 2.0 * radius
    if not far.all():
        return None
    return to / dist[:, None], np.sqrt(1.0 - (radius / dist) ** 2)


def _pairs(edges: Edges, o: np.ndarray, n0: np.ndarray, cone) -> tuple[np.ndarray, ...]:
    """The (point, edge) pairs where the edge is a silhouette seen from the point and rises above its
    horizon: their rows, edges, clipped ends (relative to ``o``), parameters s0 and s1, and the arc
    of each to sample, its start angle and length γ (inside ``cone``, per point, if given).

    The silhouette test is two matrix products per block of points; everything else is computed
    on the pairs that pass it only (a few per cent of a fine mesh's edges).
    """
    rows, cols = [], []
    step = max(1, MAX_PAIRS // len(edges))
    c1, c2 = dot(edges.a, edges.n1), dot(edges.a, edges.n2)
    n1, n2 = np.ascontiguousarray(edges.n1.T), np.ascontiguousarray(edges.n2.T)
    for lo in range(0, len(o), step):  # blocks of points: (points x edges) stays bounded
        blk = o[lo : lo + step]
        s1, s2 = blk @ n1, blk @ n2
        s1 -= c1  # n₁·(o - a)
        s2 -= c2
        r, c = np.nonzero(edges.always | ((s1 > 0.0) != (s2 > 0.0)))
        rows.append(r + lo)
        cols.append(c)
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    qa_all, e = edges.a[cols] - o[rows], (edges.b - edges.a)[cols]
    ha = dot(qa_all, n0[rows])
    hb = ha + dot(e, n0[rows])
    # clip to the part above the horizon: h(s) = ha + s (hb - ha) > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        s_cross = ha / (ha - hb)
    s0 = np.where(ha > 0.0, 0.0, np.where(hb > ha, s_cross, 1.0))
    s1 = np.where(hb > 0.0, 1.0, np.where(ha > hb, s_cross, 0.0))
    qa = qa_all + s0[:, None] * e
    qb = qa_all + s1[:, None] * e
    gamma = np.where(s1 > s0, np.arctan2(norm(cross(qa, qb)), dot(qa, qb)), 0.0)
    start = np.zeros_like(gamma)
    if cone is not None:  # keep the part of each arc inside the emitters' cone seen from its point
        start, gamma = _clip_to_cone(qa, qb, gamma, cone[0][rows], cone[1][rows])
    return rows, cols, qa, qb, s0, s1, start, gamma


def _arc_frame(qa: np.ndarray, qb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (w_a, w_⊥) with the arc from qa to qb at angles φ ∈ [0, γ]: cos φ w_a + sin φ w_⊥."""
    wa = qa / norm(qa)[:, None]
    perp = qb - wa * dot(qb, wa)[:, None]
    return wa, perp / np.where(norm(perp) > 0.0, norm(perp), 1.0)[:, None]


def _clip_to_cone(qa, qb, gamma, axis, cos_half) -> tuple[np.ndarray, np.ndarray]:
    """The sub-arc [start, start + length] of [0, γ] inside the cone (unit ``axis``, ``cos_half``).

    On the arc, ``w(φ)·axis = R cos(φ - φ₀)``: inside for |φ - φ₀| <= acos(cos_half / R)
    (a cone of half-angle below π/2 meets a great circle in one arc).
    """
    wa, perp = _arc_frame(qa, qb)
    a, b = dot(wa, axis), dot(perp, axis)
    r = np.hypot(a, b)
    phi0 = np.arctan2(b, a)
    half = np.arccos(np.clip(cos_half / np.where(r > 0.0, r, 1.0), -1.0, 1.0))
    lo = np.clip(phi0 - half, 0.0, gamma)
    hi = np.clip(phi0 + half, 0.0, gamma)
    length = np.where(r > cos_half, hi - lo, 0.0)
    return lo, length


def _choose(edges: Edges, o: np.ndarray, n0: np.ndarray, u: np.ndarray, cone) -> tuple[np.ndarray, ...]:
    """The points with a silhouette edge above the horizon, and for each: one such edge drawn ∝ its
    angle γ, its clipped ends, s0, s1, γ, and Γ = Σ γ."""
    m = len(o)
    rows, cols, qa, qb, s0, s1, start, gamma = _pairs(edges, o, n0, cone)
    if rows.size == 0:
        return (np.zeros(0, dtype=np.int64),) * 2 + (np.zeros((0, 3)),) * 2 + (np.zeros(0),) * 5
    total = np.bincount(rows, weights=gamma, minlength=m)
    cdf = np.cumsum(gamma)
    first = np.concatenate([[0.0], cdf])[np.searchsorted(rows, np.arange(m))]  # pairs are sorted by row
    # the pair whose cdf interval holds first + u Γ (zero-angle pairs are never chosen)
    j = np.minimum(np.searchsorted(cdf, first + u * total, side="right"), len(cdf) - 1)
    live = np.flatnonzero((total > 0.0) & (rows[j] == np.arange(m)))
    j = j[live]
    return live, cols[j], qa[j], qb[j], s0[j], s1[j], start[j], gamma[j], total[live]


def shading_edge_term(shading, edges: Edges, u: np.ndarray) -> np.ndarray:
    """One estimate per shading point of the boundary term of E (see the module docstring).

    Parameters
    ----------
    shading : sphere3d.integrator.Shading
        Shading points of a state with θ as a Dual.
    edges : Edges
        The scene's edges at θ0.
    u : ndarray, shape (m, 2)
        Uniforms: the edge, the point on its arc.

    Returns
    -------
    ndarray, shape (m,)
        The tangent to add to the points' irradiance estimates.
    """
    state = shading.state
    m = len(shading)
    out = np.zeros(m)
    if m == 0 or len(edges) == 0:
        return out
    o = shading.origin
    n0 = np.asarray(detach(shading.n), dtype=np.float64)
    live, k, qa, qb, s0, s1, start, gamma, total = _choose(edges, o, n0, u[:, 0], _emitter_cone(state, o))
    if live.size == 0:
        return out
    # a direction uniform in angle on the arc from qa to qb
    wa, perp = _arc_frame(qa, qb)
    phi = start + u[live, 1] * gamma
    w = np.cos(phi)[:, None] * wa + np.sin(phi)[:, None] * perp
    normal = cross(qa, qb)
    normal = normal / norm(normal)[:, None]  # m: the arc's normal on S²
    # the point of the edge seen along w: qa + t (qb - qa) parallel to w
    den = dot(cross(qb - qa, w), normal)  # 0 only for an arc of zero angle, never drawn (rounding aside)
    t = -dot(cross(qa, w), normal) / np.where(den != 0.0, den, 1.0)
    s = s0 + np.clip(t, 0.0, 1.0) * (s1 - s0)
    a, b = edges.endpoints(state.triangles)
    point = a[k] + s[:, None] * (b[k] - a[k])
    x = shading.x[live]
    # from the ray origin o = x + ε n (value), moving with x (tangent)
    seen = point - (x + Dual(o[live] - detach(x)) if isinstance(x, Dual) else o[live])
    omega = seen / norm(seen)[..., None]
    speed = dot(tangent(omega), normal)  # m·ω̇: the arc's normal velocity
    side = np.concatenate([w - EPS_ANGLE * normal, w + EPS_ANGLE * normal])
    side = side / norm(side)[:, None]
    f = _incident(state, np.concatenate([o[live], o[live]]), side)
    jump = f[: live.size] - f[live.size :]
    cos = np.maximum(dot(n0[live], w), 0.0)
    # Reynolds on S²: the side ω⁻ grows into ω⁺ at m·ω̇, density 1/Γ per radian of arc
    out[live] = total * jump * cos * speed
    return out
