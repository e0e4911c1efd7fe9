r"""Vertices where discontinuities meet on the film: a fan of affine maps following every edge there.

The film kernel's rotation (:mod:`sphere3d.reparam.film_kernel`) follows one point and turns with
one edge (:func:`~sphere3d.reparam.snaps.line_spin`). At a vertex where several discontinuity
edges meet (a box's corner: two silhouette edges and a crease between two visible faces, or three
creases) their images move differently when the shape turns, scales or recedes, and one rotation
follows one of them (a 2 px triangle turning about an axis in the image plane lost 19 % of its
film derivative).

Where a moving vertex V, at which two or more discontinuity edges seen from the camera meet
(silhouette edges, :meth:`sphere3d.boundary.edges.Edges.silhouette`, and the creases of flat-shaded
shapes, :func:`sphere3d.boundary.camera.camera_candidates`: a smooth shape's interpolated normals
make its creases no discontinuity, and its vertices slide under its silhouette), has its film
image v within the kernel's reach r (:data:`REACH` kernel σ, or the ring of a camera sample's probes
where wider) of its centre, or two of its edges' images pass within r
(near an acute corner, up to $r / \sin(α/2)$ from v for a ring of radius r and a sector of angle
α), the sample's film map is affine on each sector
between two consecutive edges' images about v: $A(u) = u + (θ - θ_0)(\dot v + \dot L_s (u - v))$,
where $\dot L_s$ keeps both of the sector's bounding edges on their moved lines. With $e_i$ the
image of edge i's direction from v and $\dot e_i$ its rate, a point $v + s e_i$ maps onto the moved
line when $(\dot L_s e_i) × e_i = \dot e_i × e_i$ (2D cross products): two linear conditions on the
four entries of $\dot L_s$, solved by least norm (no stretch the turns do not ask for; stable
where the two edges are nearly collinear and turn alike, as along a smooth silhouette). Each
sector goes onto its moved sector, so the pieces tile the film: a change of variables whose
pieces are fixed at θ0 and whose every edge through V stays on its line, to first order in θ,
all the derivative needs. The sample's sector is the one its own film point lies in; the
weight carries $|\det A|$ (:func:`sphere3d.film.affine_directions`). Loubet et al. 2019, Sec. 4.3:
a refinement of the heuristic.

Where the ring also holds a static edge (the corner on the ground's far edge), which the fan would
drag, one field keeping the corner's edges and that edge replaces the fan
(:mod:`sphere3d.reparam.corner_lines`). Biased where the kernel holds another discontinuity not
through V (an edge of another shape), and not applied where the ring holds one edge of V only, nor
along a crease far from its ends, which is followed by a point of one face (the probes pair
different shapes only): a 4 px triangle tilting, seen at 30 degrees, keeps a few per cent (the
atlas). The occluder-motions table gives ``hard_shadow_cube``'s bias with and without the pixels
where its silhouette meets the ground's far edge.

The vertices are found by a k-d tree over their film images (built once per state,
O(V log V)); a vertex hidden behind other geometry is skipped; the mesh edges are
:func:`sphere3d.boundary.edges.mesh_edges` (O(E log E), once per state).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from flatland.core.dual import detach, tangent
from sphere3d.boundary.camera import camera_candidates
from sphere3d.boundary.edges import row_ids, state_edges
from sphere3d.film import AffineFilm
from sphere3d.state import SceneState
from sphere3d.tables import per_state

__all__ = ["REACH", "NearCorners", "corner_table", "nearest_corners", "sectors", "silhouette_corners"]

REACH = 5.0
r"""Film kernel standard deviations σ within which a corner's edges are kept (:func:`nearest_corners`'s
reach in :func:`~sphere3d.reparam.film_kernel.film_transform`, or the probes' ring where wider): the
corners come from the scene's table, not from the probes, so their reach is the kernel's, whose weight
beyond 5 σ is below $e^{-12.5} ≈ 4 \cdot 10^{-6}$ of its peak (a precision, not a scene's fit). Kept
only within the ring (3 σ), a corner between 3 and 5 σ was followed by the probes' rotation about one
point of its edges, which drags the other edge where the shape turns: a smooth sphere turning about its
centre kept a bias of 0.8 of its film gradient's RMS. The inner shapes' maps
(:mod:`sphere3d.reparam.film_affine`), which take precedence, have the same reach: else a corner's fan
reaching a thin triangle's opposite edge drags it (a 4 px triangle seen at 30 degrees lost 10-11 % under
tilt, recession and scaling)."""


@dataclass(frozen=True)
class _Corners:
    """Visible moving vertices where two or more discontinuity edges meet: film images ``point``
    (k, 2), velocity ``a_dot`` (k, 2), the count of their edges ``count`` (k,) and where theirs
    begin in the flat arrays ``start`` (k,); per edge, corner by corner, the angle of its image's
    direction ``angle`` (H,), ascending within a corner, and the map's linear derivative ``b_dot``
    (H, 2, 2) of the sector from that edge to the next; a k-d tree over the images. Ragged: H is
    the sum of the counts, whatever a vertex's valence."""

    point: np.ndarray
    a_dot: np.ndarray
    count: np.ndarray
    start: np.ndarray
    angle: np.ndarray
    b_dot: np.ndarray
    tree: cKDTree | None
    edge: np.ndarray
    """(H, 2): each edge's image from the vertex to its other end."""
    edge_dot: np.ndarray
    """(H, 2), or (H, k, 2): the rate of ``edge`` (its far end's film velocity less the vertex's)."""
    sine: float
    """The sine of half the narrowest sector (below π) of every corner: a kernel disc of radius r
    reaches two edges of a corner only within r / sine of its vertex."""
    longest: float
    """The longest edge image (pixels)."""


def _least_norm_turns(e: np.ndarray, e_dot: np.ndarray) -> np.ndarray:
    r"""$\dot L$ (..., 2, 2), the least-norm solution of $(\dot L e_i) × e_i = \dot e_i × e_i$, i = 1, 2
    (e, e_dot: (..., 2, 2), edge i in ``[..., i, :]``), each condition divided by $|e_i|^2$ (a turn
    rate)."""
    ex, ey = e[..., 0], e[..., 1]
    length2 = ex * ex + ey * ey
    # (L e) × e = l11 ex ey + l12 ey² - l21 ex² - l22 ex ey, for L = [[l11, l12], [l21, l22]]
    rows = np.stack([ex * ey, ey * ey, -ex * ex, -ex * ey], axis=-1) / length2[..., None]
    rhs = (e_dot[..., 0] * ey - e_dot[..., 1] * ex) / length2
    return np.einsum("...ij,...j->...i", np.linalg.pinv(rows), rhs).reshape(*e.shape[:-2], 2, 2)


@per_state
def _corner_table(state: SceneState) -> _Corners:
    """Once per state: the visible vertices where two or more discontinuity edges seen from the camera
    meet (silhouette edges, and creases between two faces on one side), whose image moves, with
    their fans of maps (module docstring). O(E log E) time, O(E) memory."""
    cam = state.camera
    o = np.asarray(detach(cam.origin), dtype=np.float64)
    edges = state_edges(state)
    to = o - edges.a
    s1, s2 = np.einsum("ek,ek->e", to, edges.n1), np.einsum("ek,ek->e", to, edges.n2)
    # silhouettes, and creases where the radiance jumps (flat-shaded, reflecting) seen between two faces
    jumps = np.flatnonzero(camera_candidates(state, edges) & (edges.silhouette(o) | (s1 * s2 > 0.0)))
    slots = () if state.k is None else (state.k,)
    empty = _Corners(
        np.zeros((0, 2)), np.zeros((0, 2)), *(np.zeros(0, dtype=np.int64),) * 2, np.zeros(0),
        np.zeros((0, 2, 2)), None, np.zeros((0, 2)), np.zeros((0, *slots, 2)), 1.0, 0.0,
    )  # fmt: skip
    if not jumps.size:
        return empty
    a, b = edges.endpoints(state.triangles)
    m = jumps.size
    vid = row_ids(np.concatenate([edges.a[jumps], edges.b[jumps]]))
    counts = np.bincount(vid)
    corner_ids = np.flatnonzero(counts >= 2)
    if not corner_ids.size:
        return empty
    # the half-ends at the corners, grouped by corner: half-end j is edge jumps[j % m] at its a (j < m)
    order = np.argsort(vid, kind="stable")
    at_corner = counts[vid[order]] >= 2
    half = order[at_corner]  # (H,)
    corner = np.repeat(np.arange(corner_ids.size), counts[corner_ids])  # the half-ends' corners
    first = np.concatenate([[0], np.cumsum(counts[corner_ids])[:-1]])
    edge = jumps[half % m]
    at_a = half < m
    lead = edge[first]  # one half-end per corner gives its vertex
    vertex = np.where(at_a[first, None], a[lead], b[lead])  # Dual (k, 3)
    far = np.where(at_a[:, None], b[edge], a[edge])  # Dual (H, 3): the edges' other ends
    vx, vy = cam.film(vertex - cam.origin)
    fx, fy = cam.film(far - cam.origin)
    point = np.stack([np.asarray(detach(vx)), np.asarray(detach(vy))], axis=-1)
    # velocities (rows, 2), or (rows, k, 2) for k parameters: the rows' axis first, then k
    v_dot = _rows_first(np.stack([np.asarray(tangent(vx)), np.asarray(tangent(vy))], axis=-1))
    e = np.stack([np.asarray(detach(fx)), np.asarray(detach(fy))], axis=-1) - point[corner]
    e_dot = _rows_first(np.stack([np.asarray(tangent(fx)), np.asarray(tangent(fy))], axis=-1)) - v_dot[corner]
    forward = np.asarray(cam.forward, dtype=np.float64)
    v0 = np.asarray(detach(vertex)) - o
    far_depth = (np.asarray(detach(far)) - o) @ forward
    per_corner = lambda bad: np.bincount(corner, weights=bad, minlength=corner_ids.size) > 0  # noqa: E731
    moves = np.any(v_dot.reshape(len(v_dot), -1) != 0.0, axis=1) | per_corner(
        np.any(e_dot.reshape(len(e_dot), -1) != 0.0, axis=1)
    )
    ok = (
        moves
        & (v0 @ forward > 0.0)
        & ~per_corner(far_depth <= 0.0)
        & ~per_corner(np.sum(e * e, axis=-1) <= 0.0)
    )
    if ok.any():  # hidden behind other geometry: the ray to the vertex stops short of it
        dist = np.linalg.norm(v0[ok], axis=1)
        hits = state.tracer.intersect(o, v0[ok] / dist[:, None])
        ok[np.flatnonzero(ok)] = hits.t >= dist * (1.0 - 1e-6)
    if not ok.any():
        return empty
    keep = ok[corner]
    renumber = np.cumsum(ok) - 1
    corner, e, e_dot = renumber[corner[keep]], e[keep], e_dot[keep]
    count = counts[corner_ids][ok]
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    # each corner's edges by the angle of their images about the vertex
    angle = np.arctan2(e[:, 1], e[:, 0])
    by_angle = np.lexsort((angle, corner))
    angle, e, e_dot = angle[by_angle], e[by_angle], e_dot[by_angle]
    # sector s lies between edge s and the next (cyclically among the corner's edges)
    position = np.arange(angle.size) - start[corner]
    nxt = start[corner] + (position + 1) % count[corner]
    pair = np.stack([e, e[nxt]], axis=1)  # (H, 2, 2)
    pair_dot = np.stack([e_dot, e_dot[nxt]], axis=1)
    point, v_dot = point[ok], v_dot[ok]
    gap = np.append(angle[1:], 0.0) - angle  # to the next edge; the last of each corner wraps around
    gap = np.where(position + 1 < count[corner], gap, angle[start[corner]] + 2.0 * np.pi - angle)
    narrow = gap[gap < np.pi]
    sine = float(np.sin(0.5 * narrow.min())) if narrow.size else 1.0
    longest = float(np.sqrt(np.max(np.sum(e * e, axis=1))))
    if pair_dot.ndim == 3:
        maps = _least_norm_turns(pair, pair_dot)
    else:  # k parameters: each one's turns as a single parameter's
        maps = np.stack(
            [_least_norm_turns(pair, pair_dot[:, :, i]) for i in range(pair_dot.shape[2])], axis=1
        )
    tree = cKDTree(point)
    return _Corners(point, v_dot, count, start, angle, maps, tree, e, e_dot, max(sine, 1e-6), longest)


def _rows_first(t: np.ndarray) -> np.ndarray:
    """Film velocities (rows, 2), or for k parameters (k, rows, 2) moved to (rows, k, 2)."""
    return t if t.ndim == 2 else np.moveaxis(t, 0, 1)


@dataclass(frozen=True)
class NearCorners:
    """Kernel rows with a corner to follow (:func:`nearest_corners`): the rows ``rows`` (ascending) and
    each one's vertex ``index`` in the state's corner table (:func:`corner_table`)."""

    rows: np.ndarray
    index: np.ndarray


def corner_table(state: SceneState) -> _Corners:
    """The state's moving corners and their fans (built once per state; module docstring)."""
    return _corner_table(state)


def nearest_corners(state: SceneState, centre: np.ndarray, reach: float) -> NearCorners:
    """Per kernel centre (n, 2), pixels: the nearest visible moving vertex where two or more discontinuity
    edges meet, whose film image lies within ``reach`` pixels (the ring's radius) or two of whose
    edges' images pass within ``reach`` of the centre (searched up to ``reach / sine`` of the narrowest
    sector, :class:`_Corners`); the rows that have one.

    One k-d tree query per centre (:func:`_corner_table` builds the tree once per state), and for the
    centres beyond ``reach`` of their vertex a distance to each of its edges.
    """
    corners = _corner_table(state)
    if corners.tree is None or len(centre) == 0:
        return NearCorners(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    # the nearest vertex from which two of its edges can reach the disc (module docstring)
    search = min(reach / corners.sine, reach + corners.longest)
    dist, k = corners.tree.query(centre, distance_upper_bound=search)
    rows = np.flatnonzero(np.isfinite(dist))
    k = k[rows]
    far = dist[rows] > reach
    if far.any():  # beyond reach of the vertex: follow it only where two of its edges pass within reach
        f = np.flatnonzero(far)
        each = np.repeat(f, corners.count[k[f]])
        first = np.repeat(
            corners.start[k[f]] - np.cumsum(np.append(0, corners.count[k[f]][:-1])), corners.count[k[f]]
        )
        idx = first + np.arange(each.size)
        seg = corners.edge[idx]
        rel = centre[rows[each]] - corners.point[k[each]]
        t = np.clip(np.sum(rel * seg, axis=1) / np.maximum(np.sum(seg * seg, axis=1), 1e-300), 0.0, 1.0)
        near = np.hypot(*(rel - t[:, None] * seg).T) <= reach
        two = np.bincount(each, weights=near, minlength=k.size) >= 2
        keep = ~far | two
        rows, k = rows[keep], k[keep]
    return NearCorners(rows, k)


def silhouette_corners(
    state: SceneState, centre: np.ndarray, reach: float, at: np.ndarray, near: NearCorners | None = None
) -> AffineFilm:
    """Per kernel centre (n, 2), pixels: the map of its corner (:func:`nearest_corners`, or ``near``
    when given), in the sector (between two of its edges) that holds the sample's own film point
    ``at`` (n, 2); none elsewhere."""
    n = len(centre)
    out = AffineFilm.none(n, state.k)
    corners = _corner_table(state)
    near = nearest_corners(state, centre, reach) if near is None else near
    rows, k = near.rows, near.index
    if not rows.size:
        return out
    rel = at[rows] - corners.point[k]
    sector = sectors(corners.angle, corners.start[k], corners.count[k], np.arctan2(rel[:, 1], rel[:, 0]))
    out.mask[rows] = True
    out.a_dot[rows], out.centre[rows] = corners.a_dot[k], corners.point[k]
    out.b_dot[rows] = corners.b_dot[corners.start[k] + sector]
    return out


def sectors(angle: np.ndarray, start: np.ndarray, count: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Per row, the sector of a fan that holds the direction of angle ``phi`` (radians): the fan's rays
    are ``angle[start : start + count]``, ascending; sector s lies from ray s to the next, the last
    wrapping round to the first. After the last ray whose angle is <= phi (before the first: the last
    sector), by a binary search in each row's run of angles (O(log count) passes)."""
    lo, hi = start.copy(), start + count
    while np.any(lo < hi):
        mid = (lo + hi) // 2
        right = (lo < hi) & (angle[np.minimum(mid, angle.size - 1)] <= phi)
        lo, hi = np.where(right, mid + 1, lo), np.where(right | (lo >= hi), hi, mid)
    below = lo - start
    return np.where(below > 0, below - 1, count - 1)
