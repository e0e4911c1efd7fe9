r"""Discontinuity lines on the film, from the scene: what a film kernel's affine map keeps.

Per state, the edges that may carry a jump of the camera's radiance (silhouettes, and the creases of
flat-shaded shapes: :func:`~sphere3d.boundary.camera.camera_candidates`) split into those whose ends
move and those whose ends do not, clipped to depth > ε (:func:`film_segments`) and to the film
widened by the filter's radius, their images sampled every :data:`SPACING` px into a k-d tree
(O(E log E) time, O(E + L / SPACING) memory for a total clipped image length L; no array of kernels
× edges). A kernel's query returns the segments passing within its ring: the nearest static one
(:func:`static_lines`), and the count and the two nearest of the moving ones
(:func:`moving_edges`). The lines' film motion comes from their attached ends (Duals: the camera's
motion included).

An affine map of the film $\dot A(u) = \dot a + \dot B (u - c)$ has six degrees of freedom; each line
it keeps on its moved line takes two (:func:`line_map`, the least-norm map keeping one or two). Two
lines a gap g apart make that map strain the whole kernel at 1 / g; :func:`blend_map` keeps both
with a field that strains the gap only (:mod:`sphere3d.reparam.junctions`, Loubet et al. 2019,
Sec. 4.3: a refinement of the heuristic).

Not used at a moving corner on a static line (the box's corner on the ground's far edge): the affine
map keeping the corner's two edges and the line has a $\dot B$ growing as 1 / h over the whole kernel
for the corner's distance h to the line; :mod:`sphere3d.reparam.corner_lines` keeps them all with a
field whose strain is confined to the triangle the lines cut.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from flatland.core.dual import detach, tangent
from sphere3d.boundary.camera import camera_candidates
from sphere3d.boundary.edges import state_edges
from sphere3d.live import moves
from sphere3d.sampling import filter_radius
from sphere3d.state import SceneState
from sphere3d.tables import per_state

__all__ = [
    "SPACING",
    "FilmLines",
    "MovingEdges",
    "blend_map",
    "film_segments",
    "line_map",
    "moving_edges",
    "near_creases",
    "static_lines",
]

SPACING = 1.0
"""Pixels between the k-d tree's points along a static edge's image; a query within r of a centre
searches r + SPACING / 2 and measures the segments' distances exactly (the result does not depend on
it, the count of points does)."""


@dataclass(frozen=True)
class FilmLines:
    r"""Per kernel row ``rows`` (m,): an edge's image on the film (pixels), a point ``point`` (m, 2) of its
    line and its direction ``direction`` (m, 2), with their velocities ``point_dot`` and
    ``direction_dot`` ((m, 2), or (m, k, 2) for k parameters)."""

    rows: np.ndarray
    point: np.ndarray
    direction: np.ndarray
    point_dot: np.ndarray
    direction_dot: np.ndarray

    def take(self, index: Any) -> FilmLines:
        """The lines at ``index``."""
        parts = (self.rows, self.point, self.direction, self.point_dot, self.direction_dot)
        return FilmLines(*(part[index] for part in parts))


@dataclass(frozen=True)
class _Table:
    """Per state: the static edges' clipped film segments ``a`` + t ``d``, t in [0, 1] ((S, 2) each), the
    velocities ``a_dot``, ``d_dot`` of their lines' points, and a k-d tree over points along them
    (``segment`` gives each point's)."""

    a: np.ndarray
    d: np.ndarray
    a_dot: np.ndarray
    d_dot: np.ndarray
    crease: np.ndarray
    """(S,): the edge is a crease between two faces seen from the camera, not a silhouette."""
    tree: cKDTree | None
    segment: np.ndarray


def _velocity(x: Any, y: Any) -> np.ndarray:
    """Film velocity (m, 2) of Dual film coordinates, or (m, k, 2) for k parameters."""
    t = np.stack([np.asarray(tangent(x)), np.asarray(tangent(y))], axis=-1)
    return t if t.ndim == 2 else np.moveaxis(t, 0, 1)


def film_segments(state: SceneState, a: Any, b: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The film images of the edges from a to b (Duals (m, 3)) clipped in 3D to depth > ε (depth is
    linear along an edge, as the boundary method's film edges): per edge a point ``p`` (m, 2), the
    segment ``d`` (m, 2) to the other clipped end, and their velocities (m, 2) (or (m, k, 2); attached
    points: the ends' clipping parameters held); a zero segment where the whole edge lies behind."""
    cam = state.camera
    o = np.asarray(detach(cam.origin), dtype=np.float64)
    forward = np.asarray(detach(cam.forward), dtype=np.float64)
    za, zb = (np.asarray(detach(a)) - o) @ forward, (np.asarray(detach(b)) - o) @ forward
    near = state.epsilon
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = (near - za) / (zb - za)
    s0 = np.where(za >= near, 0.0, np.where(zb > za, cross, 1.0))
    s1 = np.where(zb >= near, 1.0, np.maximum(np.where(za > zb, cross, 0.0), s0))
    e = b - a
    (x0, y0), (x1, y1) = (
        cam.film(a + s0[:, None] * e - cam.origin),
        cam.film(a + s1[:, None] * e - cam.origin),
    )
    p = np.stack([np.asarray(detach(x0)), np.asarray(detach(y0))], axis=-1).reshape(-1, 2)
    d = np.stack([np.asarray(detach(x1)), np.asarray(detach(y1))], axis=-1).reshape(-1, 2) - p
    p_dot = _velocity(x0, y0)
    return p, d, p_dot, _velocity(x1, y1) - p_dot


@per_state
def _kinds(state: SceneState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Once per state: the edges (:func:`~sphere3d.boundary.edges.state_edges`) that may carry a jump seen
    from the camera, whose ends stay still, whose ends move, and of those the creases (indices)."""
    edges = state_edges(state)
    o = np.asarray(detach(state.camera.origin), dtype=np.float64)
    silhouette = edges.silhouette(o)
    candidate = camera_candidates(state, edges)
    # an edge moves where either end's vertex has a tangent (under any parameter)
    t = np.asarray(moves(state.triangles))  # (T, 3, 3): which coordinates have a tangent
    move = np.any(t[edges.face, edges.ia] | t[edges.face, edges.ib], axis=-1)
    return (
        np.flatnonzero(candidate & ~move),
        np.flatnonzero(candidate & move),
        np.flatnonzero(candidate & move & ~silhouette),
    )


@per_state
def _static_table(state: SceneState) -> _Table:
    """Once per state: the static discontinuity edges (module docstring)."""
    return _table(state, _kinds(state)[0])


@per_state
def _moving_table(state: SceneState) -> _Table:
    """Once per state: the moving discontinuity edges (module docstring)."""
    return _table(state, _kinds(state)[1])


@per_state
def _crease_table(state: SceneState) -> _Table:
    """Once per state: the moving creases alone (a subset of :func:`_moving_table`)."""
    return _table(state, _kinds(state)[2])


def _table(state: SceneState, keep: np.ndarray) -> _Table:
    """The edges ``keep`` of :func:`~sphere3d.boundary.edges.state_edges`: O(E log E) time, O(E + L /
    SPACING) memory for a total clipped image length L."""
    edges = state_edges(state)
    tri = state.triangles
    a, b = tri[edges.face[keep], edges.ia[keep]], tri[edges.face[keep], edges.ib[keep]]  # attached
    fa, fd, fa_dot, fd_dot = film_segments(state, a, b)
    o = np.asarray(detach(state.camera.origin), dtype=np.float64)
    cam = state.camera
    crease = ~edges.take(keep).silhouette(o)
    # the part inside the film widened by the filter's radius (Liang-Barsky): the segments kept
    r = filter_radius(cam.filter)
    lo, hi = np.array([-r, -r]), np.array([cam.width + r, cam.height + r])
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (lo - fa) / fd, (hi - fa) / fd
    t0 = np.max(np.where(fd != 0.0, np.minimum(ta, tb), 0.0), axis=1, initial=0.0)
    t1 = np.min(np.where(fd != 0.0, np.maximum(ta, tb), 1.0), axis=1, initial=1.0)
    inside = np.all((fd != 0.0) | ((fa >= lo) & (fa <= hi)), axis=1)
    seen = np.flatnonzero(inside & (t1 > t0) & np.any(fd != 0.0, axis=1))
    k_slots = fa_dot.shape[1:-1]
    t0, t1 = t0[seen], t1[seen]
    span = (t1 - t0)[:, None]
    t0k = t0.reshape(-1, *(1,) * len(k_slots), 1)
    spank = span.reshape(-1, *(1,) * len(k_slots), 1)
    # the clipped segment a + t d, t in [0, 1], and its points' velocities (attached to the line)
    a_seg = fa[seen] + t0[:, None] * fd[seen]
    d_seg = span * fd[seen]
    a_dot = fa_dot[seen] + t0k * fd_dot[seen]
    d_dot = spank * fd_dot[seen]
    if not seen.size:
        return _Table(a_seg, d_seg, a_dot, d_dot, crease[seen], None, np.zeros(0, dtype=np.int64))
    # points every SPACING px along each segment, both ends included
    count = np.ceil(np.hypot(d_seg[:, 0], d_seg[:, 1]) / SPACING).astype(np.int64) + 1
    segment = np.repeat(np.arange(seen.size), count)
    first = np.cumsum(count) - count
    t = (np.arange(segment.size) - first[segment]) / np.maximum(count[segment] - 1, 1)
    points = a_seg[segment] + t[:, None] * d_seg[segment]
    return _Table(a_seg, d_seg, a_dot, d_dot, crease[seen], cKDTree(points), segment)


def _near(table: _Table, centre: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every (row, segment) pair of ``centre`` (m, 2) and ``table`` whose segment passes within ``reach``
    px, sorted by row then distance: rows, segments, distances. One k-d tree query, then the exact
    segment distances of the pairs it returns."""
    empty = np.zeros(0, dtype=np.int64)
    if table.tree is None or len(centre) == 0:
        return empty, empty, np.zeros(0)
    pairs = cKDTree(centre).sparse_distance_matrix(table.tree, reach + 0.5 * SPACING, output_type="ndarray")
    row, seg = pairs["i"].astype(np.int64), table.segment[pairs["j"]]
    rel = centre[row] - table.a[seg]
    d = table.d[seg]
    t = np.clip(np.sum(rel * d, axis=1) / np.maximum(np.sum(d * d, axis=1), 1e-300), 0.0, 1.0)
    dist = np.hypot(*(rel - t[:, None] * d).T)
    order = np.lexsort((seg, dist, row))
    row, seg, dist = row[order], seg[order], dist[order]
    # a segment holds several of the tree's points: each (row, segment) pair once
    first = np.ones(row.size, dtype=bool)
    first[1:] = (row[1:] != row[:-1]) | (seg[1:] != seg[:-1])
    near = first & (dist <= reach)
    return row[near], seg[near], dist[near]


def _lines(table: _Table, rows: np.ndarray, seg: np.ndarray) -> FilmLines:
    return FilmLines(rows, table.a[seg], table.d[seg], table.a_dot[seg], table.d_dot[seg])


def near_creases(state: SceneState, centre: np.ndarray, reach: float) -> np.ndarray:
    """The rows of ``centre`` (m, 2) within ``reach`` px of a moving crease's image, ascending."""
    row, _, _ = _near(_crease_table(state), centre, reach)
    return np.unique(row)


def static_lines(state: SceneState, centre: np.ndarray, reach: float) -> FilmLines:
    """Per kernel centre (m, 2): the nearest static edge whose clipped film image passes within ``reach``
    px (module docstring); the rows that have one."""
    row, seg, _ = _near(_static_table(state), centre, reach)
    first = np.ones(row.size, dtype=bool)
    first[1:] = row[1:] != row[:-1]
    return _lines(_static_table(state), row[first], seg[first])


@dataclass(frozen=True)
class MovingEdges:
    """The moving discontinuity edges near kernel centres (:func:`moving_edges`): per centre their
    ``count`` (m,) within reach (seen or hidden), the nearest (``first``, the rows with one or more)
    and the next (``second``, the rows with two or more), and whether the nearest is a crease between
    two faces seen from the camera (``crease``, per row of ``first``)."""

    count: np.ndarray
    first: FilmLines
    second: FilmLines
    crease: np.ndarray


def moving_edges(state: SceneState, centre: np.ndarray, reach: float) -> MovingEdges:
    """Per kernel centre (m, 2): how many moving discontinuity edges' clipped film images pass within
    ``reach`` px, and the two nearest (:class:`MovingEdges`)."""
    table = _moving_table(state)
    row, seg, _ = _near(table, centre, reach)
    count = np.bincount(row, minlength=len(centre))
    rank = np.arange(row.size) - np.searchsorted(row, row)  # 0 for a row's nearest, 1 for the next
    first, second = rank == 0, rank == 1
    return MovingEdges(
        count,
        _lines(table, row[first], seg[first]),
        _lines(table, row[second], seg[second]),
        table.crease[seg[first]],
    )


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """2D cross products over the last axis."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def line_map(centre: np.ndarray, *lines: FilmLines) -> tuple[np.ndarray, np.ndarray]:
    r"""$(\dot a, \dot B)$, (m, 2) and (m, 2, 2) (or (m, k, 2), (m, k, 2, 2)), of the least-norm affine film
    map $\dot A(u) = \dot a + \dot B (u - c)$ about the kernel centres c (m, 2) that keeps one or two
    lines, each on its moved line: a film kernel holding a moving silhouette and a static edge, or a
    crease alone (:mod:`sphere3d.reparam.junctions`).

    A line $q + s l$ moving at $\dot q + s \dot l$ stays on itself when
    $(\dot a + \dot B (q - c) - \dot q) × l = 0$ and $(\dot B l) × l = \dot l × l$ (2D cross products,
    first order in θ), q the line's point nearest c: two linear conditions per line on six unknowns,
    solved by least norm (a pseudo-inverse). Where two lines cross inside the kernel this holds their
    crossing's motion to first order (the translation by $\dot J$ is another solution); where they
    are nearly parallel (a silhouette along a static edge) it follows both, which no translation
    does; one line turning (a crease of a turning box) is followed along its length, where a rotation
    following one point of it drifts off the line with the distance from that point. Exact to first
    order for straight lines; where two lines are parallel and turn apart, or move apart across a gap
    g, $\dot B$ grows as 1 / g (the variance, not the bias).
    """
    first = lines[0]
    k = first.point_dot.ndim == 3
    rows, rhs = [], []
    for line in lines:
        lx, ly = line.direction[:, 0], line.direction[:, 1]
        l2 = lx * lx + ly * ly
        length = np.sqrt(l2)
        t = np.sum((centre - line.point) * line.direction, axis=1) / l2
        r = line.point + t[:, None] * line.direction - centre
        q_dot = line.point_dot + (t[:, None, None] if k else t[:, None]) * line.direction_dot
        zero = np.zeros_like(lx)
        rows.append(
            np.stack([ly, -lx, r[:, 0] * ly, r[:, 1] * ly, -r[:, 0] * lx, -r[:, 1] * lx], -1)
            / length[:, None]
        )
        rows.append(np.stack([zero, zero, lx * ly, ly * ly, -lx * lx, -lx * ly], axis=-1) / l2[:, None])
        lk = line.direction[:, None] if k else line.direction
        rhs.append(_cross(q_dot, lk) / (length[:, None] if k else length))
        rhs.append(_cross(line.direction_dot, lk) / (l2[:, None] if k else l2))
    z = np.einsum("mij,mj...->mi...", np.linalg.pinv(np.stack(rows, axis=1)), np.stack(rhs, axis=1))
    if not k:
        return z[:, :2], z[:, 2:].reshape(-1, 2, 2)
    z = np.moveaxis(z, 2, 1)  # (m, k, 6)
    return z[..., :2], z[..., 2:].reshape(*z.shape[:2], 2, 2)


def blend_map(
    centre: np.ndarray, at: np.ndarray, first: FilmLines, second: FilmLines, reach: float
) -> tuple[np.ndarray, np.ndarray]:
    r"""Per sample, the velocity $v$ (m, 2) and its gradient $\nabla v$ (m, 2, 2) at its film point ``at``
    (or (m, k, 2), (m, k, 2, 2)) of a field that keeps two lines: the blend
    $v = t v_1 + (1 - t) v_2$, $t = d_2 / (d_1 + d_2)$, of the least-norm one-line maps $v_i$
    (:func:`line_map`, about the kernel centres c) by the distances $d_i$ to the lines: on line 1
    $t = 1$ and on line 2 $t = 0$, so each is kept, to first order, as by :func:`line_map` with both.

    Unlike the one affine map keeping both lines, whose $\dot B$ grows as 1 / g over the whole kernel for
    two lines a gap g apart (a silhouette beside a static edge), the blend strains only where the
    distances are comparable: $\nabla v = t \dot B_1 + (1 - t) \dot B_2 + (v_1 - v_2) ⊗ \nabla t$ with
    $|\nabla t| \le 1 / (d_1 + d_2)$, so the strain 1 / g is confined to the sliver and its
    neighbourhood, a variance growing as 1 / g instead of $1 / g^2$. Where the lines cross within
    ``reach`` of c, at J, both one-line maps are shifted along their own lines (which keeps each) to
    J's velocity $\dot J$ there (the value of :func:`line_map` with both lines at J), so $v_1 - v_2$
    vanishes at J and the gradient stays bounded: a translation by $\dot J$ where the lines only
    translate. The field is Lipschitz, the change of variables it makes valid; each sample carries its
    value and gradient (:class:`~sphere3d.film.AffineFilm` about its own point).
    """
    k = first.point_dot.ndim == 3
    maps = [list(line_map(centre, line)) for line in (first, second)]
    # the crossing J of the two lines, where it lies within reach of the kernel's centre
    d1, d2 = first.direction, second.direction
    den = _cross(d1, d2)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = _cross(second.point - first.point, d2) / den
    cross_at = first.point + s[:, None] * d1
    pin = np.flatnonzero((den != 0.0) & (np.hypot(*(cross_at - centre).T) <= 2.0 * reach))
    if pin.size:
        a12, b12 = line_map(centre[pin], first.take(pin), second.take(pin))
        rel = cross_at[pin] - centre[pin]
        j_dot = a12 + _apply(b12, rel, k)
        for a, b in maps:  # shift each one-line map along its line: its value at J becomes J's
            a[pin] = a[pin] + j_dot - (a[pin] + _apply(b[pin], rel, k))
    rel = at - centre
    v1, v2 = (a + _apply(b, rel, k) for a, b in maps)
    # distances to the lines and their gradients (unit normals, signed by the side)
    dist, grad = [], []
    for line in (first, second):
        n = np.stack([-line.direction[:, 1], line.direction[:, 0]], axis=1)
        n /= np.linalg.norm(n, axis=1)[:, None]
        signed = np.sum((at - line.point) * n, axis=1)
        dist.append(np.abs(signed))
        grad.append(np.where(signed[:, None] < 0.0, -n, n))
    total = dist[0] + dist[1]
    on = total > 0.0
    safe = np.where(on, total, 1.0)
    t = np.where(on, dist[1] / safe, 0.5)
    grad_t = np.where(
        on[:, None], (dist[0][:, None] * grad[1] - dist[1][:, None] * grad[0]) / safe[:, None] ** 2, 0.0
    )
    tk = t[:, None] if not k else t[:, None, None]
    v = tk * v1 + (1.0 - tk) * v2
    tb = tk[..., None]
    b = tb * maps[0][1] + (1.0 - tb) * maps[1][1]
    outer = (v1 - v2)[..., :, None] * (grad_t[:, None, None, :] if k else grad_t[:, None, :])
    return v, b + outer


def _apply(b: np.ndarray, rel: np.ndarray, k: bool) -> np.ndarray:
    r"""$\dot B\, r$ for maps (m, 2, 2) or (m, k, 2, 2) and offsets r (m, 2)."""
    return np.einsum("mkij,mj->mki", b, rel) if k else np.einsum("mij,mj->mi", b, rel)
