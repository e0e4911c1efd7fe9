r"""Where on a probe's triangle a rotation follows: the snap onto an edge or corner, and the turn about it.

An extension of the probe heuristic (Loubet et al. 2019, Sec. 4.1, 4.3; theory page
*extensions*). After bisection (:func:`~sphere3d.reparam.probes.select_points`) a probe's hit
lies up to $1/2^\mathrm{refine}$ of the probe gap inside its triangle T. :func:`edge_snap`
moves it to where the segment of directions from the last direction that hits T to the first
that misses leaves T, or to that edge's corner when the probe ring reaches it; :func:`line_spin`
gives the rotation's third degree of freedom, the turn about the followed direction that keeps
the snapped point's edges on their own motion. On the film (:mod:`sphere3d.reparam.film_kernel`)
the corner's distance is measured in pixels, on the sphere (:func:`angle_snap`, the cosine
strategy of :mod:`sphere3d.reparam.default`) in radians.

Why: a rotation that follows a point inside T drifts from the edge's motion by the point's
distance from the edge times the rate at which the triangle's image scales or turns (motion in
depth, rotation); on the edge's line, with the edge's own turn, it follows the edge exactly
under rigid motion and scaling. At a corner the two edges turn differently: the turn is their
rates weighted by the kernel, exact for neither alone. Divergence theorem form of what is left
(``tests/sphere3d/helpers.py`` ``rotation_loss``): given the rotation chosen in a kernel centred
at ω, the derivative expected over the kernel's samples is
$-q(ω)^{-1} ∫_{∂T} f k\, (Ω × μ)·n\, dl$ (Ω the rotation's angular velocity, n the edges'
outward normal, q the density of ω, f the integrand, k the kernel), where the exact one has
the edges' own velocity $\dot μ$ in place of Ω × μ: the two agree wherever the snapped edge
is the only one in the kernel. Measured on the bias atlas and ``reparam_bias`` pages.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from scipy import special

from flatland.core.dual import detach, tangent
from sphere3d.reparam.outline import outline_table
from sphere3d.state import SceneState
from sphere3d.tracing import Hits
from sphere3d.vector import cross, dot, norm

__all__ = ["Snap", "angle_snap", "edge_snap", "line_spin"]

Snap = Callable[
    [np.ndarray, np.ndarray, np.ndarray, np.ndarray, Hits],
    tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
]
"""``snap(rows, origin, inside, outside, hits) -> (triangle, u, v, lines)``: the triangle to follow a
point of (the bisected hit's, or a face beyond it along the segment), the point's barycentrics there,
and the two edges (pairs of that triangle's vertex slots, (k, 2, 2); the same edge twice for a point on
one edge; -1: the hit's own point, on no edge) whose lines pass through that point
(:func:`~sphere3d.reparam.probes.select_points`)."""
Gap = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``gap(rows, ends) -> (k, 2)``: how far the vertices ``ends - origin`` (k, 2, 3) lie from the rows'
kernel centres, in the unit of the snap's ``radius``."""


def edge_snap(state: SceneState, gap: Gap, radius: float | np.ndarray) -> Snap:
    r"""Move a bisected probe hit onto its triangle's edge, or to that edge's corner near the kernel.

    The hook ``snap`` of :func:`~sphere3d.reparam.probes.select_points`. The point followed is where the
    segment of directions from ``inside`` (hits T) to ``outside`` (misses the shape) leaves T.
    With $e_k(d) = ((V_{k+1} - o) × (V_{k+2} - o)) · d$, linear in d and proportional to the
    barycentric weight of $V_k$ of the hit along d, that exit is the smallest λ in (0, 1] with
    $e_k((1 - λ) a + λ b) = 0$. Where that edge is no silhouette seen from o (two faces turned towards
    it: the bisection ended in a face narrow on the image, next to the one whose edge is the
    silhouette), the segment goes on over the face across it (:func:`_across`), up to the first edge
    that is one (:func:`_silhouette`, by :mod:`sphere3d.reparam.outline`'s table): the discontinuity
    the pair of probes straddles, which an edge between two faces is not where they move apart (a shape
    turning). A rotation that follows a point on a straight edge's line
    follows the whole edge under translation and motion in depth (on the film: the edge's normal
    velocity is affine in the point and constant along the line; on the sphere, with
    :func:`line_spin`, the edge's great circle), while one following a point inside T drifts by
    its distance from the edge times the image's rate of scaling. Where an end of that edge lies
    within ``radius`` of the kernel centre (``gap``) and T's other edge there is a silhouette too, the
    corner is followed instead: it lies on both edges that meet there, so one rotation follows the two
    (where T's other edge is none, the outline turns along another face's edge: a mesh's outline
    corner, or a face seen nearly edge-on whose other edge lies beside the outline on the image and
    moves otherwise; the exit edge alone is followed). ``radius``: one, or one per kernel
    (indexed by the snap's ``rows``).
    """
    triangles = np.asarray(detach(state.triangles))

    def snap(
        rows: np.ndarray, origin: np.ndarray, inside: np.ndarray, outside: np.ndarray, hits: Hits
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        m = np.arange(rows.size)
        triangle = hits.triangle.copy()
        vert = triangles[triangle] - origin[:, None]  # (k, 3, 3): V_j - o
        # row j of c: (V_{j+1} - o) × (V_{j+2} - o), so e_j(d) = c_j · d
        c = cross(np.roll(vert, -1, axis=1), np.roll(vert, -2, axis=1))
        sign = np.where(np.einsum("kjx,kx->k", c, inside) < 0.0, -1.0, 1.0)  # orient: e_j(inside) >= 0
        j, lam, exits = _exit(c, sign, inside, outside, np.full(rows.size, -1))
        d = inside + np.where(exits, lam, 0.0)[:, None] * (outside - inside)
        # across an edge that is no silhouette seen from o, the segment goes on over the next face
        walk = exits.copy()
        for _ in range(len(triangles)):  # each step enters a new face along the segment: it ends
            walk[walk] = ~_silhouette(state, origin[walk], triangle[walk], j[walk])
            r = np.flatnonzero(walk)
            if not r.size:
                break
            face, entry = _across(state, triangle[r], j[r])
            fv = triangles[face] - origin[r, None]
            fc = cross(np.roll(fv, -1, axis=1), np.roll(fv, -2, axis=1))
            fsign = np.where(np.einsum("kx,kx->k", fc[:, 0], fv[:, 0]) < 0.0, -1.0, 1.0)
            fj, flam, ok = _exit(fc, fsign, d[r], outside[r], entry)
            ok &= face >= 0
            r, face, fj, flam, fv, fc, fsign = (a[ok] for a in (r, face, fj, flam, fv, fc, fsign))
            walk[:] = False
            walk[r] = True
            triangle[r], j[r], vert[r], c[r], sign[r] = face, fj, fv, fc, fsign
            d[r] += flam[:, None] * (outside[r] - d[r])
        w = np.maximum(np.einsum("kjx,kx->kj", c, d) * sign[:, None], 0.0)
        w[m, j] = 0.0
        total = w.sum(axis=1)
        exits &= total > 0.0
        w = w / np.where(total > 0.0, total, 1.0)[:, None]
        # the exit edge's ends, the nearer one to the kernel centre if the ring reaches it
        ends = np.stack([(j + 1) % 3, (j + 2) % 3], axis=1)
        away = gap(rows, vert[m[:, None], ends])
        near = np.argmin(away, axis=1)
        corner = exits & (away[m, near] <= (radius if np.ndim(radius) == 0 else radius[rows]))
        # the corner's second edge in T (opposite the exit edge's other end) must be a silhouette too: else
        # (a mesh's outline turns at the corner along another face's edge) its line is no discontinuity,
        # and on a face seen nearly edge-on it lies beside the outline and moves otherwise
        c = np.flatnonzero(corner)
        corner[c] = _silhouette(state, origin[c], triangle[c], ends[c, 1 - near[c]])
        w[corner] = 0.0
        w[m[corner], ends[m, near][corner]] = 1.0
        u = np.where(exits, w[:, 1], hits.u)
        v = np.where(exits, w[:, 2], hits.v)
        triangle = np.where(exits, triangle, hits.triangle)
        # the edges through the point: the exit edge twice, or the corner's two edges
        lines = np.where(exits[:, None, None], ends[:, None, :], -1).repeat(2, axis=1)
        vertex = ends[m, near][:, None]
        at_corner = np.stack(
            [np.hstack([vertex, (vertex + 1) % 3]), np.hstack([vertex, (vertex + 2) % 3])], axis=1
        )
        lines[corner] = at_corner[corner]
        return triangle, u, v, lines

    return snap


def _exit(
    c: np.ndarray, sign: np.ndarray, a: np.ndarray, b: np.ndarray, skip: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the segment of directions from ``a`` (in the face whose edge planes are the rows of ``c``,
    oriented by ``sign``) to ``b`` leaves the face: the vertex slot j opposite the exit edge, the
    fraction λ of the way, and whether it leaves; the edge opposite ``skip`` (the entry edge) is not
    an exit. The smallest λ in [0, 1] with $e_j((1 - λ) a + λ b) = 0$, $e_j$ going from >= 0 to < 0."""
    m = np.arange(len(c))
    ea = np.einsum("kjx,kx->kj", c, a) * sign[:, None]
    eb = np.einsum("kjx,kx->kj", c, b) * sign[:, None]
    leaving = (eb < 0.0) & (ea >= 0.0) & (np.arange(3) != skip[:, None])
    lam = np.where(leaving, ea / np.where(leaving, ea - eb, 1.0), np.inf)
    j = np.argmin(lam, axis=1)  # V_j's weight reaches 0 first: the exit edge is V_{j+1} V_{j+2}
    exits = np.isfinite(lam[m, j])
    return j, np.where(exits, lam[m, j], 0.0), exits


def _silhouette(state: SceneState, origin: np.ndarray, triangle: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Whether the edge opposite slot ``j`` of ``triangle`` is a silhouette edge seen from ``origin``
    (:mod:`sphere3d.reparam.outline`): one face only, or a face turned towards o and one turned away."""
    table = outline_table(state)
    e = table.edge_of[triangle, (j + 1) % 3]
    ok = e >= 0
    e = np.maximum(e, 0)
    to = np.asarray(detach(state.triangles))[triangle, (j + 1) % 3] - origin  # V - o
    s1 = np.einsum("kx,kx->k", table.n1[e], to)
    s2 = np.einsum("kx,kx->k", table.n2[e], to)
    return ~ok | (table.other[e] < 0) | ((s1 > 0.0) != (s2 > 0.0))


def _across(state: SceneState, triangle: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The face across the edge opposite slot ``j`` of ``triangle`` (-1: none), and the slot of that
    face opposite the same edge (its vertex off the edge, by the welded vertex ids)."""
    table = outline_table(state)
    e = np.maximum(table.edge_of[triangle, (j + 1) % 3], 0)
    face = np.where(table.face[e] == triangle, table.other[e], table.face[e])
    ids = table.vid[np.maximum(face, 0)]  # (k, 3)
    own = table.vid[triangle]
    shared = (ids[:, :, None] == own[:, None, :]).any(axis=2)  # (k, 3): the slot's vertex is on T
    return face, np.argmin(shared, axis=1)


def angle_snap(state: SceneState, centre: np.ndarray, radius: float | np.ndarray) -> Snap:
    """:func:`edge_snap` for probes on the sphere around the unit kernel centres ``centre`` (m, 3):
    a corner within the angle ``radius`` (radians; one, or one per kernel) of the centre is followed."""

    def gap(rows: np.ndarray, ends: np.ndarray) -> np.ndarray:
        cosine = dot(ends, centre[rows, None]) / norm(ends)
        return np.arccos(np.clip(cosine, -1.0, 1.0))

    return edge_snap(state, gap, radius)


def line_spin(
    triangles: Any,
    origin: Any,
    point: Any,
    lines: np.ndarray,
    centre: np.ndarray | None = None,
    sigma: float | np.ndarray = 1.0,
) -> np.ndarray:
    r"""Rate of turn about the direction of ``point`` that keeps the great circles of ``lines`` on theirs.

    A rotation with angular velocity $Ω = a × \dot a + λ a$ follows the direction a of a point of
    an edge; the edge's great circle, of unit normal $\hat m ∝ (V_1 - o) × (V_2 - o)$, turns
    with it when also $\dot{\hat m} = Ω × \hat m$, which with $e = \hat m × a$ (a on the circle)
    gives $λ = -\dot{\hat m} · e$. A rotation that follows a point but not its edge's turn
    drags the edge's image by its distance from the point times the turn rate (a triangle
    rotating about the line of sight); one that follows a corner but not its edges misses
    their turns on both sides of it. Loubet et al. 2019, Sec. 4.1, 4.3: a refinement of the
    heuristic, the rotation's third degree of freedom.

    Parameters
    ----------
    triangles : Dual, shape (k, 3, 3)
        The followed points' triangles (θ-dependent).
    origin, point : Dual, shape (k, 3) or (3,)
        The moving ray origin and the followed point on the edges.
    lines : ndarray of int, shape (k, 2, 2)
        Two edges per row as pairs of vertex slots (the same edge twice for a point on one
        edge; at a corner the corner first): their rates' mean, or weighted by ``centre``.
    centre : ndarray, shape (k, 3), optional
        Unit kernel centres: at a corner each edge's rate is weighted by its first moment
        $M_i = ∫ s\, g\, ds$ from the corner under a Gaussian of ``sigma`` (radians) about the
        centre, the λ that zeroes the first-order error $Σ_i (λ_i - λ) M_i$ (:func:`_moment`); one
        σ, or one per row.

    Returns
    -------
    ndarray, shape (k,), or (p, k) for p parameters
        $λ = \dot ψ$, 0 where an edge's line passes through the origin.
    """
    k = np.arange(len(lines))
    a = detach(point - origin)
    a = a / norm(a)[:, None]
    rates, weights = [], []
    for side in range(2):  # the two edges (not a loop over samples)
        p, q = triangles[k, lines[:, side, 0]] - origin, triangles[k, lines[:, side, 1]] - origin
        m = cross(p, q)
        length = norm(detach(m))
        m = m / np.where(length > 0.0, length, 1.0)[:, None]
        e = cross(detach(m), a)
        rates.append(-np.where(length > 0.0, tangent(dot(m, e)), 0.0))
        weights.append(np.ones(len(lines)) if centre is None else _moment(a, detach(q), centre, sigma))
    total = weights[0] + weights[1]
    w = np.where(total > 0.0, weights[0] / np.where(total > 0.0, total, 1.0), 0.5)
    return w * rates[0] + (1.0 - w) * rates[1]


def _moment(a: np.ndarray, q: np.ndarray, centre: np.ndarray, sigma: float | np.ndarray) -> np.ndarray:
    r"""$∫_0^∞ s\, g(s t - x) ds$ along the edge from the corner a towards q, g the Gaussian of ``sigma``
    about the kernel ``centre`` (x: the centre's offset in a's tangent plane, small angles):
    $e^{-b^2/2σ^2} (σ^2 e^{-α^2/2σ^2} + α σ \sqrt{2π}\, Φ(α/σ))$, α = x·t, $b^2 = |x|^2 - α^2$.

    The weight of the edge in the first-order error $Σ_i (λ_i - λ) M_i$ of a turn λ at a corner."""
    t = q - dot(q, a)[:, None] * a
    t = t / np.maximum(norm(t), 1e-300)[:, None]
    x = centre - dot(centre, a)[:, None] * a
    along = dot(x, t)
    b2 = np.maximum(dot(x, x) - along * along, 0.0)
    z = along / sigma
    return (
        np.exp(-0.5 * b2 / sigma**2)
        * sigma**2
        * (np.exp(-0.5 * z * z) + z * np.sqrt(2.0 * np.pi) * special.ndtr(z))
    )
