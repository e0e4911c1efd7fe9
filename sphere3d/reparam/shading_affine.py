r"""A small shape inside a cosine kernel's ring: the map of the sphere that follows all its edges.

The cosine strategy's rotations (:mod:`sphere3d.reparam.default`) follow one point of one edge,
turning with it. A shape whose image from the shading point lies wholly inside the kernel's ring
of probes, or is thinner than the ring however long, has all its silhouette edges (or both its
long edges) in one kernel, moving apart when it scales, moves in depth or tilts: one rotation
follows one of them, and most of dE/dθ is lost (the bias atlas, ``make bench``). For such a shape
the sample's map is instead, in the gnomonic chart about the kernel's centre ω (frame t, b),

    $g(y) = (y·t, y·b) / (y·ω)$,   $T(μ) = g^{-1}(A(g(μ)))$,

a fan of affine maps about the mean c of the shape's anchor points' charts $u_i$: the chart is cut
into the cones from c through consecutive vertices $u_i$, $u_j$ of the anchors' convex hull, and on
the cone that holds the sample's own chart point

    $A(u) = u + (θ - θ_0)(\dot c + \dot B (u - c))$,
    $\dot B\,[u_i - c,\ u_j - c] = [\dot u_i - \dot c,\ \dot u_j - \dot c]$,

$\dot c$ the mean of the $\dot u_i$: c and the cone's two hull vertices move with their own
velocities, so the hull edge $u_i u_j$ goes onto its moved segment and neighbouring cones agree on
the ray they share (both affine on it, equal at c and at its hull vertex). The gnomonic chart maps
great circles to lines, so the image of a convex shape seen from the point (every anchor in front
of the chart's plane) is the hull of its vertices' charts: with every vertex an anchor, each outline
edge is carried under every motion, and for one triangle the three cones' maps are one, exact. One
affine map fitted to all the anchors by least squares would not do for a mesh: under a turn its
vertices' charts, front and back, move in no affine way, and the fit averages the outline's motion
away. The flat-film counterpart is :mod:`sphere3d.reparam.film_affine`.

A shape of one triangle gets the map wherever a kernel's ring reaches its image, small or not:
its three edges and their corners are then followed together (one rotation follows one edge, or
a corner's two edges by a compromise turn).

A change of variables of the sphere: the sample is evaluated at T(μ) (value μ, tangent
$\dot T(μ)$), its weight carries the Jacobian $|J_T| = \det A\, ((1 + |u|^2)/(1 + |A u|^2))^{3/2}$
(the chart's area element is $du / (1 + |u|^2)^{3/2}$): value 1, derivative
$\mathrm{tr}\,\dot B - 3\, u·\dot u / (1 + |u|^2)$. As with the rotation, the map depends on the
kernel's centre only (the cone is chosen by the sample's own point, a piece of that one map), so the
kernel convolution stays unbiased where that shape's outline edges are the only discontinuities in
the kernel. Biased where another shape's edge lies in it (dragged by the map, as the rotation drags
all but the edge it follows), for a non-convex shape (its image's concave stretches and inner
silhouettes are not hull edges), and for a mesh of more vertices than :data:`MAX_ANCHORS` whose
outline has three vertices in a row turning it by less than $2π/$:data:`MAX_ANCHORS` together
(:mod:`sphere3d.reparam.outline_anchors`). Loubet et al. 2019, Sec. 4.1-4.3: a change of
variables per kernel, chosen by geometry instead of by one probe's point.

Anchors: a shape's vertices when it has at most :data:`MAX_ANCHORS`; else, per kernel, the vertices
of its outline in the kernel's chart (:func:`~sphere3d.reparam.outline_anchors.outline_candidates`:
the vertices extreme along :data:`MAX_ANCHORS` chart directions and their neighbours), so the cost
per kernel stays bounded whatever the mesh. The hull per kernel by Graham's scan over the anchors,
vectorized over the kernels (:func:`_hull_cone`): O(A²) in the worst case per kernel for A anchors.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach, tangent
from sphere3d.live import moves
from sphere3d.reparam.outline_anchors import DIRECTIONS, MeshGraph, mesh_graph, outline_candidates
from sphere3d.state import SceneState
from sphere3d.tables import per_state
from sphere3d.vector import frame

__all__ = ["MAX_ANCHORS", "ShadingAffine", "inner_shape_map"]

MAX_ANCHORS = DIRECTIONS
"""Shapes with at most this many distinct vertices are fitted from all of them (a triangle: exact);
larger ones from as many vertices of their outline seen from the point
(:mod:`sphere3d.reparam.outline_anchors`)."""
DEGENERATE = 1e-12
"""Relative size of the smallest eigenvalue of the anchors' chart scatter below which the image
counts as a segment (a triangle seen edge-on) and no map is fitted."""
_AXES = np.array(
    [[x, y, z] for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1) if (x, y, z) > (0, 0, 0)],
    dtype=np.float64,
)
"""The 13 directions of a cube's faces, edges and corners (one of each ± pair): a large mesh's extreme
vertices along them span its extent, for deciding which kernels take the map."""


@dataclass(frozen=True)
class _Shapes:
    """Per moving shape: its index, bounding sphere at θ0, anchor points (Dual, padded by repeats;
    where ``climb``, found per kernel in mesh ``slot`` of :func:`_graph` instead) and whether it is
    one triangle."""

    shape: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    anchors: Any  # Dual (k, A, 3)
    single: np.ndarray
    triangle: np.ndarray  # the shape's first triangle (its only one where ``single``)
    climb: np.ndarray
    slot: np.ndarray


@per_state
def _moving_shapes(state: SceneState) -> _Shapes:
    """Once per state: the shapes whose vertices carry a tangent (under any parameter), their spheres and
    anchors, and the vertex graphs of those with more than :data:`MAX_ANCHORS` vertices. O(V log V)."""
    moving = np.any(moves(state.triangles), axis=(1, 2))
    k = state.k
    values, tangents, shapes, centres, radii, single, large = [], [], [], [], [], [], []
    for s in np.unique(state.shape_of[moving]):  # a handful of shapes, each vectorized
        corners = state.triangles[state.shape_of == s].reshape(-1, 3)
        plain = np.asarray(detach(corners))
        first = np.arange(len(plain))  # more corners than 8 per anchor: a large mesh, without sorting them
        if len(plain) <= 8 * MAX_ANCHORS:
            _, first = np.unique(plain, axis=0, return_index=True)
        rows = np.ascontiguousarray(plain.T)  # (3, corners): each coordinate contiguous
        large.append(first.size > MAX_ANCHORS)
        if first.size > MAX_ANCHORS:  # for the rule's first pass: the extreme corners along the axes
            proj = _AXES @ rows
            first = np.unique(np.concatenate([proj.argmin(axis=1), proj.argmax(axis=1)]))
        pick = np.resize(first, MAX_ANCHORS)  # padded by repeats: their hull and mean stay
        centre = 0.5 * (rows.min(axis=1) + rows.max(axis=1))
        values.append(plain[pick])
        tangents.append(np.asarray(tangent(corners))[pick] if k is None else corners.tangent[:, pick])
        shapes.append(int(s))
        centres.append(centre)
        radii.append(float(np.sqrt(np.max(np.sum((rows - centre[:, None]) ** 2, axis=0)))))
        single.append(len(corners) == 3)
    if not shapes:
        none = Dual(np.zeros((0, MAX_ANCHORS, 3)), None, k)
        empty, nothing = np.zeros(0, np.int64), np.zeros(0, dtype=bool)
        return _Shapes(empty, np.zeros((0, 3)), np.zeros(0), none, nothing, empty, nothing, empty)
    anchors = Dual(np.array(values), np.array(tangents) if k is None else np.stack(tangents, axis=1), k)
    first = np.array([np.argmax(state.shape_of == s) for s in shapes], dtype=np.int64)  # per shape
    climb = np.array(large)
    return _Shapes(
        np.array(shapes), np.array(centres), np.array(radii), anchors, np.array(single), first,
        climb, np.cumsum(climb) - 1,
    )  # fmt: skip


@per_state
def _graph(state: SceneState) -> MeshGraph:
    """Once per state, when a kernel first needs it: the vertex graphs of the large moving meshes (those
    ``climb`` marks, in its order), O(V log V) (:func:`~sphere3d.reparam.outline_anchors.mesh_graph`)."""
    shapes = _moving_shapes(state)
    corners = [state.triangles[state.shape_of == s].reshape(-1, 3) for s in shapes.shape[shapes.climb]]
    return mesh_graph(corners)


@dataclass(frozen=True)
class ShadingAffine:
    """Where the chart's map replaces the rotation (``mask`` over the kernels), and its tangents:
    ``mu_dot`` (n, 3) the evaluation direction's, ``log_jacobian_dot`` (n,) the weight's; for k
    parameters (k, n, 3) and (k, n)."""

    mask: np.ndarray
    mu_dot: np.ndarray
    log_jacobian_dot: np.ndarray
    triangle: np.ndarray
    """(n,): the shape's triangle where it is one triangle (its map exact), else -1."""


def _chart(d: Any, centre: np.ndarray, t: np.ndarray, b: np.ndarray) -> tuple[Any, Any]:
    """Gnomonic coordinates of directions ``d`` (..., 3) about unit ``centre`` (frame t, b)."""
    depth = d[..., 0] * centre[..., 0] + d[..., 1] * centre[..., 1] + d[..., 2] * centre[..., 2]
    x = d[..., 0] * t[..., 0] + d[..., 1] * t[..., 1] + d[..., 2] * t[..., 2]
    y = d[..., 0] * b[..., 0] + d[..., 1] * b[..., 1] + d[..., 2] * b[..., 2]
    return x / depth, y / depth


def inner_shape_map(
    shading: Any, mu: np.ndarray, centre: np.ndarray, reach: float | np.ndarray
) -> ShadingAffine:
    """The map of the module docstring for the kernels (centres ``centre`` (n, 3), samples ``mu``)
    whose ring of angular radius ``reach`` (one, or one per kernel) holds a moving shape's image, or a
    thin image reaching into it, or reaches a shape of one triangle (for which the map is exact
    everywhere); the nearest such shape, seen from the point (a ray toward its centre hits it).

    Cost: (kernels × moving shapes) comparisons, then (kernels with a shape × anchors).
    """
    n, params = len(mu), shading.state.k
    slots = () if params is None else (params,)
    out = ShadingAffine(
        np.zeros(n, dtype=bool),
        np.zeros((*slots, n, 3)),
        np.zeros((*slots, n)),
        np.full(n, -1, dtype=np.intp),
    )
    shapes = _moving_shapes(shading.state)
    if not len(shapes.shape) or n == 0:
        return out
    x = np.asarray(detach(shading.x), dtype=np.float64)
    to = shapes.centre[None] - x[:, None]  # (n, k, 3)
    dist = np.linalg.norm(to, axis=-1)
    outside = dist > shapes.radius
    half = np.arcsin(np.minimum(1.0, shapes.radius / np.maximum(dist, 1e-300)))  # angular radius
    cos = np.einsum("nkx,nx->nk", to, centre) / np.maximum(dist, 1e-300)
    gap = np.arccos(np.clip(cos, -1.0, 1.0))
    # inside the ring wholly, or near it and thin (tested on the chart below)
    per_row = np.ndim(reach) != 0
    near = outside & (gap - half < (reach[:, None] if per_row else reach)) & (half < 0.5 * np.pi)
    best = np.argmin(np.where(near, gap, np.inf), axis=1)
    rows = np.flatnonzero(near[np.arange(n), best])
    if not rows.size:
        return out
    k = best[rows]
    c, m = centre[rows], mu[rows]
    t, b = frame(c)
    u, u_dot, front = _anchor_charts(shading, shapes.anchors[k], rows, c, t, b)
    mean = u.mean(axis=1)
    q = u - mean[:, None]
    scatter = np.einsum("rai,raj->rij", q, q)
    extent = np.trace(scatter, axis1=1, axis2=2)
    eig, vec = np.linalg.eigh(scatter)
    fitted = front & (extent > 0.0) & (eig[:, 0] > DEGENERATE * extent)
    # the image inside the ring (every anchor within reach of the centre), or thin: narrower than the
    # ring across its major axis, its core reaching into it
    radius_chart = np.tan(reach[rows]) if per_row else np.tan(reach)
    inside = np.all(
        np.hypot(u[..., 0], u[..., 1]) < (radius_chart[:, None] if per_row else radius_chart), axis=1
    )
    major = vec[:, :, 1]
    across = np.einsum("rai,ri->ra", q, np.stack([-major[:, 1], major[:, 0]], axis=1))
    along = np.einsum("rai,ri->ra", q, major)
    width = across.max(axis=1) - across.min(axis=1)
    s = np.clip(-np.einsum("ri,ri->r", mean, major), along.min(axis=1), along.max(axis=1))
    core = np.hypot(*(mean + s[:, None] * major).T)  # the core segment's nearest point to the centre
    thin = (width < 2.0 * radius_chart) & (core - 0.5 * width < radius_chart)
    # one triangle is followed exactly wherever the ring reaches it
    keep = fitted & (inside | thin | shapes.single[k])
    # seen: the ray toward the shape's centre meets it first
    hits = shading.state.tracer.intersect(shading.origin[rows], to[rows, k] / dist[rows, k, None])
    keep &= hits.hit & (shading.state.shape_of[np.maximum(hits.triangle, 0)] == shapes.shape[k])
    rows, keep_idx = rows[keep], np.flatnonzero(keep)
    if not rows.size:
        return out
    c, m, t, b, k = c[keep_idx], m[keep_idx], t[keep_idx], b[keep_idx], k[keep_idx]
    u, u_dot = u[keep_idx], u_dot[..., keep_idx, :, :]
    climb = np.flatnonzero(shapes.climb[k])
    if climb.size:  # a large mesh: its outline's vertices in this kernel's chart (reparam.outline_anchors)
        graph = _graph(shading.state)
        found = outline_candidates(graph, shapes.slot[k[climb]], x[rows[climb]], c[climb], t[climb], b[climb])
        anchors = shapes.anchors[k][:, np.resize(np.arange(MAX_ANCHORS), found.shape[1])]  # the same hull
        anchors[climb] = graph.vertices[found]
        u, u_dot, _ = _anchor_charts(shading, anchors, rows, c, t, b)
    mean = u.mean(axis=1)
    # the sample's chart point
    depth = np.einsum("rx,rx->r", m, c)
    um = np.stack([np.einsum("rx,rx->r", m, t), np.einsum("rx,rx->r", m, b)], axis=1) / depth[:, None]
    s2 = 1.0 + np.einsum("ri,ri->r", um, um)
    y = (c + um[:, :1] * t + um[:, 1:] * b) / np.sqrt(s2)[:, None]
    out.mask[rows] = True
    out.triangle[rows] = np.where(shapes.single[k], shapes.triangle[k], -1)
    ends, e_inv = _hull_cone(u, mean, um)
    chart = (ends, e_inv, mean, um, s2, y, t, b)
    for i, slot in enumerate([u_dot] if params is None else u_dot):  # each parameter's map as a single one's
        y_dot, log_jacobian_dot = _map_tangents(slot, *chart)
        if params is None:
            out.mu_dot[rows], out.log_jacobian_dot[rows] = y_dot, log_jacobian_dot
        else:
            out.mu_dot[i, rows], out.log_jacobian_dot[i, rows] = y_dot, log_jacobian_dot
    return out


def _hull_cone(u: np.ndarray, centre: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""Per row, the cone of the fan about ``centre`` (r, 2) (inside the hull of the anchors' charts
    ``u`` (r, A, 2)) that holds the chart point ``at`` (r, 2): the anchors ``ends`` (r, 2) at its two
    hull vertices, counter-clockwise, and $[u_i - c,\ u_j - c]^{-1}$ (r, 2, 2).

    The hull by Graham's scan, vectorized over the rows (a loop over the A anchors, not the rows): the
    lowest anchor first, the others by angle about it, each popping the stack's last while it makes no
    left turn (repeats and collinear anchors leave). The cone: the hull vertices by angle about c from
    the first, the last whose angle is <= the point's."""
    r, a = u.shape[:2]
    low = u[..., 1] == u[..., 1].min(axis=1, keepdims=True)
    pivot = np.argmin(np.where(low, u[..., 0], np.inf), axis=1)
    rel = u - u[np.arange(r), pivot][:, None]
    dist = np.hypot(rel[..., 0], rel[..., 1])
    angle = np.where(dist > 0.0, np.arctan2(rel[..., 1], rel[..., 0]), -1.0)  # the pivot (and repeats) first
    order = np.lexsort((dist, angle), axis=-1)
    p = np.take_along_axis(u, order[..., None], axis=1)
    stack, top, every = np.zeros((r, a), dtype=np.intp), np.ones(r, dtype=np.intp), np.arange(r)
    for i in range(1, a):
        while True:  # pop while (last - second) x (new - second) <= 0: no left turn
            o, m = p[every, stack[every, np.maximum(top - 2, 0)]], p[every, stack[every, top - 1]]
            cross = (m[:, 0] - o[:, 0]) * (p[:, i, 1] - o[:, 1]) - (m[:, 1] - o[:, 1]) * (
                p[:, i, 0] - o[:, 0]
            )
            pop = (top >= 2) & (cross <= 0.0)
            if not pop.any():
                break
            top -= pop
        stack[every, top] = i
        top += 1
    hull = np.take_along_axis(
        order, stack, axis=1
    )  # anchor indices, counter-clockwise; the first ``top`` valid
    h = np.take_along_axis(u, hull[..., None], axis=1) - centre[:, None]
    phi = np.arctan2(h[..., 1], h[..., 0])
    # angles from the first hull vertex's, ascending along the hull (counter-clockwise about c)
    turned = np.mod(phi - phi[:, :1], 2.0 * np.pi)
    point = np.mod(np.arctan2(at[:, 1] - centre[:, 1], at[:, 0] - centre[:, 0]) - phi[:, 0], 2.0 * np.pi)
    valid = np.arange(a) < top[:, None]
    cone = np.sum(valid & (turned <= point[:, None]), axis=1) - 1
    ends = np.stack([hull[every, cone], hull[every, (cone + 1) % top]], axis=1)
    e = np.stack([u[every, ends[:, 0]], u[every, ends[:, 1]]], axis=-1) - centre[..., None]  # columns
    return ends, np.linalg.inv(e)


def _anchor_charts(shading: Any, anchors: Any, rows: np.ndarray, c, t, b) -> tuple:
    """The gnomonic charts (r, A, 2) about the kernels' centres ``c`` (frame t, b) of the ``anchors``
    (Dual (r, A, 3)) seen from the shading points of ``rows``, their tangents ((k,) r, A, 2), and
    whether every anchor lies in front of the chart's plane (r,)."""
    x = shading.x[rows] if isinstance(shading.x, Dual) else np.asarray(shading.x, dtype=np.float64)[rows]
    p = anchors - x[:, None]
    length = np.sqrt(p[..., 0] * p[..., 0] + p[..., 1] * p[..., 1] + p[..., 2] * p[..., 2])
    d = p / length[..., None]
    front = np.all(np.einsum("rax,rx->ra", np.asarray(detach(d)), c) > 0.0, axis=1)  # in the chart
    ux, uy = _chart(d, c[:, None], t[:, None], b[:, None])
    u = np.stack([np.asarray(detach(ux)), np.asarray(detach(uy))], axis=-1)  # (r, A, 2)
    u_dot = np.stack([np.asarray(tangent(ux)), np.asarray(tangent(uy))], axis=-1)  # ((p,) r, A, 2)
    return u, u_dot, front


def _map_tangents(u_dot: np.ndarray, ends, e_inv, mean, um, s2, y, t, b) -> tuple:
    """One parameter's tangents of the chart's map at the kept samples: the direction's (r, 3) and the
    log Jacobian's (r,), from the anchors' chart velocities ``u_dot`` (r, A, 2) (module docstring)."""
    rate = u_dot.mean(axis=1)
    # the cone's B' [u_i - c, u_j - c] = [u'_i - c', u'_j - c']: c at c', its hull vertices at theirs
    rows = np.arange(len(rate))
    e_dot = np.stack([u_dot[rows, ends[:, 0]], u_dot[rows, ends[:, 1]]], axis=-1) - rate[..., None]
    b_dot = e_dot @ e_inv
    # the sample's chart point's velocity under A
    um_dot = rate + np.einsum("rij,rj->ri", b_dot, um - mean)
    # y = (c + u_x t + u_y b) / sqrt(1 + |u|²): its tangent under u̇
    radial = np.einsum("ri,ri->r", um, um_dot) / s2
    y_dot = (um_dot[:, :1] * t + um_dot[:, 1:] * b) / np.sqrt(s2)[:, None] - y * radial[:, None]
    # log |J_T|: log det A - (3/2) log((1 + |A u|²) / (1 + |u|²)), its derivative at θ0
    return y_dot, np.trace(b_dot, axis1=1, axis2=2) - 3.0 * radial
