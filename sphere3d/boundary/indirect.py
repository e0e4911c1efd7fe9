r"""The boundary term of the shading integrals on paths: the jump of the reflected radiance behind edges.

On a path of up to d vertices (:mod:`sphere3d.paths`) the integrand of the shading integral at vertex
v (of a diffuse point $E = ∫ L_i \cos θ\, dω$, of a glossy one $∫ L_i f(w_i, ω) \cos θ\, dω$) is the
whole radiance arriving along ω,

    $L_i(ω) = L_e(ω) + L_r(y(ω))$,

$L_e$ the emission (or sky) the ray from x along ω meets and $L_r$ the radiance its first hit y reflects
back along paths of up to r = d - v further vertices (y the first of them). Both jump across the
spherical images of edges seen from x; the jump of $L_e$ is :mod:`sphere3d.boundary.shading`'s term
(arcs clipped to the emitters' images). This module adds the jump of $L_r$:

    $\sum_\mathrm{edges} ∫_C [L_r(ω^-) - L_r(ω^+)]\, w(ω) \cos θ\, (m·\dot ω)\, dℓ$,

w = 1 at a diffuse point, the BSDF $f(w_i, ω)$ at θ0 at a glossy one (continuous across the arcs).

**Where $L_r$ jumps.** Where the surface seen changes (silhouettes seen from x, among them the open
edges and those between shapes), and across the creases of flat-shaded shapes that reflect: $L_r$
depends on the normal of the surface met, which jumps there (shading is two-sided, so from either
side). Creases of smooth shapes are continuous. The candidates are therefore the silhouettes seen
from x plus those creases, every one of them treated as always a silhouette (:func:`side_edges`: the
same edge tree, :mod:`sphere3d.boundary.edge_tree`, with the creases marked like open edges, so the
walk finds them without any (points × edges) array); there is no clip to the emitters' images (the
reflected light comes from every direction). As for the emission term, an edge that does not move,
seen from a point that does not move, has $m·\dot ω = 0$ and is not drawn.

**Draws.** k = ``indirect`` per point among the candidates' arcs above the horizon, ∝ angle
($Γ = Σ$ angles of the point's arcs, density 1/Γ per radian, arcs not clipped so c = 1), a point
uniform in angle on the drawn arc (:func:`~sphere3d.boundary.shading.edge_draws`, uniforms
``"boundary.indirect"``). The estimate is the mean over the draws of

    $Γ\, [\hat L_r(ω^-) - \hat L_r(ω^+)]\, w(ω) \cos θ\, (m·\dot ω)$,

each side's $\hat L_r$ one path of r vertices from the hit of the side ray at angle δ =
:data:`~sphere3d.boundary.shading.EPS_ANGLE` beside the arc (:func:`side_radiance`: on the detached
scene, identity transforms, the MIS estimate at each vertex), both sides from the same random numbers
(keyed on the vertex's sample, the vertex and the draw, apart from the primary paths' keys by
:data:`SIDE_PATHS`): where both side rays meet the same surface the two estimates nearly cancel.
Each side's estimate is unbiased for its $L_r$, so the term is unbiased up to the offset δ (one
pair, not extrapolated as the emission term's: an $O(δ)$ bias near the corners of arcs, far below the
Monte Carlo noise at δ = 1e-6). The path multiplies the term by the value of its throughput into x
(the Dual product of :mod:`sphere3d.paths`: the vertex's $β\, ρ/π$, or its glossy throughput); the side
paths carry no tangent, so nothing is counted twice with the naive interior term.

Cost per shading point: the silhouette walk (without the emitters' cull) and, per draw, two side rays
and two paths of r vertices (about 3r rays each).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from flatland.core.dual import detach
from flatland.core.rng import Draws
from sphere3d.boundary.edges import Edges
from sphere3d.boundary.shading import EPS_ANGLE, edge_draws, reynolds
from sphere3d.integrator import Identity, Shading, direct
from sphere3d.paths import Paths, reflected
from sphere3d.state import SceneState
from sphere3d.tracing import intersect_triangles
from sphere3d.vector import dot, norm

__all__ = ["SIDE_PATHS", "VERTICES", "indirect_edge_term", "side_edges", "side_radiance"]

SIDE_PATHS = 1 << 40
"""Offset of the key words (:class:`~flatland.core.rng.Draws` ``path``) of the side paths, above every
word of the primary paths: their random numbers are their own."""
VERTICES = 64
"""Vertex numbers a key word holds apart (more than any ``max_depth`` a task takes)."""


def side_edges(state: SceneState, edges: Edges) -> Edges:
    """``edges`` with the creases of flat-shaded shapes that reflect (albedo > 0, or the albedo is the
    parameter) marked ``always``: candidates of the jump of $L_r$ from every point (module docstring)."""
    albedo = np.asarray(detach(state.albedo))
    shape = state.shape_of[edges.face]
    reflects = (albedo[shape] > 0.0) | np.asarray(state.albedo_varies)[shape]
    flat = ~np.asarray(state.smooth)[edges.face]
    return dataclasses.replace(edges, always=edges.always | (edges.crease & reflects & flat))


def side_radiance(
    plain: SceneState, origin: np.ndarray, d: np.ndarray, u: np.ndarray, draws: Draws, depth: int
) -> np.ndarray:
    r"""$\hat L_r$: the radiance the first hits of the rays (``origin``, unit ``d``) reflect back along
    $-d$ by paths of up to ``depth`` vertices, the hit the first (its uniforms ``u`` (n, 5), the further
    vertices' from ``draws``), on the plain state ``plain`` with identity transforms; 0 where a ray
    misses or meets a surface of albedo 0. Its emission is not included (the emission term's)."""
    hits = plain.tracer.intersect(origin, d)
    shape = plain.shape_of[np.where(hits.hit, hits.triangle, 0)]
    albedo = np.asarray(detach(plain.albedo), dtype=np.float64)[shape]
    out = np.zeros(len(d))
    keep = np.flatnonzero(hits.hit & (albedo > 0.0))
    if not keep.size:
        return out
    tri, dk = hits.triangle[keep], d[keep]
    it = intersect_triangles(origin[keep], dk, plain.triangles[tri])
    # shade the side the ray arrives on, as the camera's and the paths' vertices do
    side = np.where((dot(it.normal, dk) < 0.0)[:, None], 1.0, -1.0)
    normal = plain.shading_normals(tri, it.b1, it.b2, it.normal)
    geometric = it.normal * side
    shade_n = geometric if normal is it.normal else normal * side
    at = Shading.at(plain, it.point, shade_n, draws.take(keep), geometric)
    if plain.glossy.any():
        value = reflected(at, -dk, u[keep], shape[keep], albedo[keep], Identity(), depth)
    else:
        value = (Paths(depth) if depth > 1 else direct)(at, u[keep], albedo[keep], Identity())
    out[keep] = np.asarray(detach(value), dtype=np.float64)
    return out


def indirect_edge_term(
    shading: Shading, edges: Edges, u: np.ndarray, further: int, vertex: int, weight: Any = None
) -> np.ndarray:
    r"""One estimate per shading point of the jump term of $L_r$ (module docstring): the tangent to add
    to the points' E (or, with ``weight(rows, ω)``, a glossy point's BSDF at θ0, to their $L_r$).

    Parameters
    ----------
    shading : Shading
        Vertex ``vertex`` of paths (θ as a Dual), whose side paths have up to ``further`` vertices.
    edges : Edges
        :func:`side_edges` of the scene's edges.
    u : ndarray, shape (m, 2, k)
        Uniforms of k edge samples per point.

    Returns
    -------
    ndarray, shape (m,), or (p, m) for p parameters
        The mean of the k samples' terms; for p parameters the same draws times each one's $m·\dot ω$.
    """
    state = shading.state
    m, k = len(shading), u.shape[2]
    out = np.zeros(m if state.k is None else (state.k, m))
    if m == 0 or further < 1 or len(edges) == 0:
        return out
    draws = edge_draws(shading, edges, u, None, np.zeros(len(edges), dtype=bool))
    if draws is None:
        return out
    live, w, normal = draws.live, draws.w, draws.normal
    side = (w[None] + EPS_ANGLE * np.array([-1.0, 1.0])[:, None, None] * normal[None]).reshape(-1, 3)
    side = side / norm(side)[:, None]  # ω⁻ then ω⁺
    # both sides from the same numbers: keyed on (sample, vertex, draw), apart from the primary paths
    rows = shading.draws.take(live)
    key = SIDE_PATHS + (rows.path * VERTICES + vertex) * k + draws.draw % k
    keyed = Draws(rows.seed, np.tile(rows.sample, 2), np.tile(key, 2))
    f = side_radiance(
        state.detached(), np.tile(shading.origin[live], (2, 1)), side, keyed.uniforms("boundary.side", 5),
        keyed, further,
    ).reshape(2, live.size)  # fmt: skip
    cos = draws.cos if weight is None else draws.cos * weight(live, w)
    return reynolds(draws, f[0] - f[1], cos, m, k, state.k)
