r"""The cosine strategy's kernels beside the light's border: the border kept after the rotation.

A kernel of the cosine-sampled integral (:mod:`sphere3d.reparam.default`) whose rotation follows a
moving occluder's edge drags everything else in the kernel with it. Where the kernel also holds the
light's sharp border, seen from the point, the border moves with the occluder: the emitted radiance
jumps there, and its Leibniz term is lost. The emitter strategy holds its border by a boundary term
(:mod:`sphere3d.boundary.emitters`); this strategy's rotations change per kernel, and the light's
border is kept instead by a field after the rotation (:class:`~sphere3d.reparam.chart_field.ChartField`,
Loubet et al. 2019, Sec. 4.3: a refinement of the heuristic) in the gnomonic chart about the kernel's
centre, over the lines of

- the emitters' border edges (:func:`~sphere3d.boundary.emitters.edge_table`) whose arc from the point
  passes within the ring's reach of the centre (twice its angle, as the snaps reach), moving at their
  own velocity (the point's motion; the emitters static) relative to the rotation's, and
- the edges the rotation follows (the snap's one edge, or a corner's two,
  :class:`~sphere3d.reparam.probes.Followed`), which it already turns with (relative velocity about 0):
  the field keeps them where they are; or, where the kernel's map is an inner shape's of one triangle
  (:mod:`sphere3d.reparam.shading_affine`: exact for its three edges, dragging the border), that
  triangle's three edges, the field then after the identity and replacing the shape's map;
- the moving occluder's outline: from the followed edge's silhouette edge (a mesh's corner snap holds
  the triangle's two edges at the corner, of which the outline often takes one or none:
  :func:`~sphere3d.reparam.outline.outline_edges`), the next silhouette edges one step at a time from
  both its ends while their arcs pass within the reach (:func:`~sphere3d.reparam.outline.outline_chain`,
  up to :data:`CHAIN` a side): a faceted occluder holds several outline edges in one kernel, and an edge
  the field does not keep moves by its blend of the kept ones', between the rotation's motion near the
  followed edge and the border's rest;
- where the rotation follows no moving shape (the pair of probes it follows straddles the light's
  border, or none) but a probe sees one, that shape's outline, from the silhouette edge found between
  the closest pair of a probe on it and one off it (``refine`` bisections and the walk to the silhouette,
  :func:`~sphere3d.reparam.snaps.edge_snap`, as the emitter field's shadow edges): the rotation, static,
  would leave it where it is.

Its scale is the ring's radius in the chart, tan(ring): the kernel's own, as on the film
(:mod:`sphere3d.reparam.corner_lines`). The map depends on the kernel's centre and its probes, not on
the sample: the convolution stays unbiased where these lines hold every discontinuity in the kernel.

Not used (the border dragged, as before): moving emitters (their table holds θ0 positions), lights of
more than :data:`MAX_BORDER` border edges (the cost per kernel grows with them), kernels whose map is an
inner shape's of several triangles (an affine fit, not exact for its edges). Biased where the kernel
holds another moving edge than the kept ones: a moving shape's outline that no probe sees within the
reach (beyond the ring), a second moving shape, an outline longer than :data:`CHAIN` edges a side
within the reach. Measured: tests/sphere3d/test_kernel_border.py test04, test05 (a 320-face ball's
shadow across the light, the cosine strategy alone against the closed form).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from flatland.core.dual import detach
from sphere3d.boundary.emitters import edge_table
from sphere3d.live import any_rows, moves
from sphere3d.reparam.bisection import bisect_silhouette, closest_pair
from sphere3d.reparam.chart_field import ChartField, chart_edges
from sphere3d.reparam.film_kernel import _moving_vertices
from sphere3d.reparam.film_lines import FilmLines
from sphere3d.reparam.outline import outline_chain, outline_edges
from sphere3d.reparam.probes import REFINE, Followed
from sphere3d.reparam.snaps import edge_snap
from sphere3d.rotation import Rotation
from sphere3d.tracing import Hits
from sphere3d.vector import cross, dot, frame, norm

__all__ = ["CHAIN", "MAX_BORDER", "border_field", "near_arcs"]

CHAIN = 8
"""Outline edges kept on from each end of the followed silhouette edge, at most (:func:`_outline`; a cost
bound: the walk stops where the outline leaves the kernel's reach)."""
MAX_BORDER = 8
"""Emitter border edges beyond which no kernel gets the field: each kernel is tested against every one, and
its field weighs every pair of its lines (at most this many and three more) per sample."""


def near_arcs(x: np.ndarray, centre: np.ndarray, a: np.ndarray, b: np.ndarray, reach: Any) -> np.ndarray:
    r"""Whether the arc of directions from the points ``x`` (n, 3) to the segment ``a`` ``b`` (E, 3) passes
    within the angle ``reach`` (one, or (n,)) of the unit ``centre`` (n, 3): (n, E) (:func:`_arc_angle`)."""
    angle = _arc_angle(a[None] - x[:, None], b[None] - x[:, None], centre[:, None])
    return angle <= (reach if np.ndim(reach) == 0 else reach[:, None])


def _arc_angle(pa: np.ndarray, pb: np.ndarray, c: np.ndarray) -> np.ndarray:
    r"""The angle from the unit directions ``c`` to the arc of directions from ``pa`` to ``pb`` (broadcast,
    (..., 3)): the great circle's nearest direction (c less its part along the circle's unit normal
    $\hat m$, at the angle $\arcsin |c·\hat m|$) where that lies between the ends, else the nearer end's."""
    m = cross(pa, pb)
    m_hat = m / np.maximum(norm(m), 1e-300)[..., None]
    off = dot(c, m_hat)
    foot = c - off[..., None] * m_hat
    between = (dot(cross(pa, foot), m) >= 0.0) & (dot(cross(foot, pb), m) >= 0.0)
    ends = np.maximum(dot(c, pa) / norm(pa), dot(c, pb) / norm(pb))  # the nearer end's cosine
    return np.where(between, np.arcsin(np.minimum(np.abs(off), 1.0)), np.arccos(np.clip(ends, -1.0, 1.0)))


def border_field(
    shading: Any,
    centre: np.ndarray,
    ring: Any,
    rotation: Rotation,
    followed: Followed | None,
    triangle: np.ndarray | None = None,
    probes: tuple[np.ndarray, Hits] | None = None,
    refine: int = REFINE,
) -> ChartField:
    """The fields of the kernels (one per point of ``shading``, centres ``centre``, ring angle ``ring``: one,
    or one per kernel) whose reach holds an emitter border edge (module docstring), after ``rotation``;
    where ``triangle`` (n,) names a moving triangle whose image the kernel's ring reaches (an inner shape
    of one triangle, :class:`~sphere3d.reparam.shading_affine.ShadingAffine`), after the identity, the
    field keeping that triangle's three edges with the border instead of the followed ones; with the
    followed edges on a moving shape, the occluder's outline through them (:func:`_outline`); where the
    rotation follows no moving shape but a probe of ``probes`` (directions (n, P, 3), hits) sees one,
    that shape's outline found between the probes by ``refine`` bisections (:func:`_seen_outline`)."""
    state, n, k = shading.state, len(centre), shading.state.k
    table = edge_table(state)
    if table is None or len(table.a) > MAX_BORDER or np.any(moves(state.triangles)[state.emitters]):
        return ChartField.none(n, k)
    x0 = np.asarray(detach(shading.x))
    near = near_arcs(x0, centre, table.a, table.b, 2.0 * np.asarray(ring))
    own = np.zeros(n, dtype=bool) if triangle is None else triangle >= 0
    moving = _moving_vertices(state)
    seen = (
        np.zeros(n, dtype=bool)
        if probes is None
        else any_rows(probes[1].hit & moving[np.maximum(probes[1].triangle, 0)])
    )
    # else the identity on a static border: v = 0
    live = rotation.active | any_rows(moves(shading.x)) | own | seen
    fields = np.flatnonzero(near.any(axis=1) & live)
    if not fields.size:
        return ChartField.none(n, k)
    slot = np.full(n, -1, dtype=np.intp)
    slot[fields] = np.arange(fields.size)
    t, b = frame(centre[fields])
    scale = np.tan(np.broadcast_to(ring, (n,))[fields])
    # the base map: the rotation, or the identity where the triangle's own edges are kept
    base = rotation.take(fields)
    base = Rotation(base.target, base.active & ~own[fields], base.spin)
    moving_x = np.any(moves(shading.x))

    def part(f: np.ndarray, a: Any, c: Any) -> tuple[FilmLines, np.ndarray]:
        """The images of the edges a c (Dual or plain, (len(f), 3)) of the fields ``f``, relative to base."""
        x = shading.x[fields[f]] if moving_x else x0[fields[f]]
        return chart_edges(f, a - x, c - x, base.take(f), centre[fields[f]], t[f], b[f], scale[f], k)

    # the border edges near each kernel
    row, edge = np.nonzero(near[fields])
    parts = [part(row, table.a[edge], table.b[edge])]
    mine = np.flatnonzero(own[fields])
    if mine.size:  # an inner triangle's three edges
        tri = state.triangles[triangle[fields[mine]]]
        parts += [part(mine, tri[:, j], tri[:, (j + 1) % 3]) for j in range(3)]
    follows = np.zeros(n, dtype=bool)  # kernels whose rotation follows a moving shape's snapped edge
    if followed is not None and followed.snapped is not None:
        rows, triangles, lines = followed.snapped
        ok = (lines[:, 0, 0] >= 0) & (slot[rows] >= 0) & ~own[rows]
        for side in range(2):  # the followed edge, or a corner's two (not a loop over samples)
            use = ok & ((side == 0) | np.any(lines[:, 1] != lines[:, 0], axis=1))
            tri, j = state.triangles[triangles[use]], np.arange(use.sum())
            parts.append(part(slot[rows[use]], tri[j, lines[use, side, 0]], tri[j, lines[use, side, 1]]))
        ok &= moving[triangles]  # and the occluder's outline through the followed point, while in reach
        parts += _outline(state, x0, centre, ring, rows[ok], triangles[ok], lines[ok], slot, part)
        follows[rows[ok]] = True
    # a moving shape seen by a probe, its outline not followed (the rotation follows the static border)
    other = np.flatnonzero((slot >= 0) & seen & ~follows & ~own)
    if other.size:
        parts += _seen_outline(shading, centre, ring, other, probes, moving, refine, slot, part)
    lines = FilmLines(
        *(np.concatenate([getattr(p, f) for p, _ in parts]) for f in FilmLines.__dataclass_fields__)
    )
    segment = np.concatenate([seg for _, seg in parts])
    return ChartField(slot, centre[fields], t, b, scale, lines, segment, k)


def _outline(
    state: Any,
    x0: np.ndarray,
    centre: np.ndarray,
    ring: Any,
    rows: np.ndarray,
    triangle: np.ndarray,
    lines: np.ndarray,
    slot: np.ndarray,
    part: Callable[[np.ndarray, Any, Any], tuple[FilmLines, np.ndarray]],
) -> list[tuple[FilmLines, np.ndarray]]:
    """The lines of the occluder's outline through the followed snaps ``lines`` of ``triangle`` at the
    kernels ``rows``: the silhouette edge there (:func:`~sphere3d.reparam.outline.outline_edges`) and the
    next ones from both its ends (:func:`~sphere3d.reparam.outline.outline_chain`), one step at a time
    while the edge's arc passes within twice the ring of the kernel's centre (the snaps' reach), up to
    :data:`CHAIN` a side. A faceted occluder's outline holds several edges in one kernel; one the field
    does not keep moves by its blend of the kept ones', between the followed edge's motion and the
    border's rest (the cosine strategy alone lost 26 % of a 320-face ball's shadow across the light)."""
    start = outline_edges(state, x0[rows], triangle, lines)
    rows = rows[start.found]
    if not rows.size:
        return []
    face, ia, ib = start.face[start.found], start.ia[start.found], start.ib[start.found]
    reach = 2.0 * np.broadcast_to(ring, (len(centre),))
    plain = np.asarray(detach(state.triangles))

    def near(i: np.ndarray, f: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        p = rows[i]
        return _arc_angle(plain[f, a] - x0[p], plain[f, b] - x0[p], centre[p]) <= reach[p]

    steps = [(np.arange(rows.size), face, ia, ib)]
    steps += outline_chain(state, x0[rows], face, np.stack([ia, ib], axis=1), near, CHAIN)
    # every step's edges at once (one chart conversion, not one per step along the outline)
    i, f, a, b = (np.concatenate([step[c] for step in steps]) for c in range(4))
    return [part(slot[rows[i]], state.triangles[f, a], state.triangles[f, b])]


def _seen_outline(
    shading: Any,
    centre: np.ndarray,
    ring: Any,
    rows: np.ndarray,
    probes: tuple[np.ndarray, Hits],
    moving: np.ndarray,
    refine: int,
    slot: np.ndarray,
    part: Callable[[np.ndarray, Any, Any], tuple[FilmLines, np.ndarray]],
) -> list[tuple[FilmLines, np.ndarray]]:
    """The outline of a moving shape that the probes of the kernels ``rows`` see but their rotation does
    not follow (it follows the light's border, or nothing): between the closest pair of a probe on a
    moving triangle and one off every moving triangle, ``refine`` bisections toward the silhouette and
    the walk to the silhouette edge (:func:`~sphere3d.reparam.snaps.edge_snap`, as the emitter field's
    shadow edges), then that edge's outline (:func:`_outline`). Loubet et al. 2019, Sec. 4.3: a kernel
    holding the light's border and an occluder's edge, two discontinuities with two motions."""
    state = shading.state
    d, hits = probes
    d, hits = d[rows], hits.take(rows)
    on = hits.hit & moving[np.maximum(hits.triangle, 0)]
    i, j, has = closest_pair(d, lambda q: on[q, :, None] & ~on[q, None, :])
    rows, d, i, j = rows[has], d[has], i[has], j[has]
    if not rows.size:
        return []
    r = np.arange(rows.size)
    origin, normal = shading.origin[rows], np.asarray(detach(shading.n))[rows]
    h0 = state.tracer.intersect(origin, d[r, i])
    found, inside, outside = bisect_silhouette(state, origin, d[r, i], d[r, j], h0, normal, refine)
    triangle, _, _, lines = edge_snap(state, _no_corner, -1.0)(r, origin, inside, outside, found)
    good = (lines[:, 0, 0] >= 0) & found.hit
    good[good] = moving[triangle[good]]
    rows, triangle, lines = rows[good], triangle[good], lines[good]
    x0 = np.asarray(detach(shading.x))
    return _outline(state, x0, centre, ring, rows, triangle, lines, slot, part)


def _no_corner(rows: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Distances of an edge's ends for :func:`~sphere3d.reparam.snaps.edge_snap`: 0 each, with a radius of
    -1, so no corner is snapped to (an edge is wanted, its outline walked from both ends)."""
    return np.zeros(ends.shape[:2])
