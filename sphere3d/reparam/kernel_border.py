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
  triangle's three edges, the field then after the identity and replacing the shape's map.

Its scale is the ring's radius in the chart, tan(ring): the kernel's own, as on the film
(:mod:`sphere3d.reparam.corner_lines`). The map depends on the kernel's centre and its probes, not on
the sample: the convolution stays unbiased where these lines hold every discontinuity in the kernel.

Not used (the border dragged, as before): moving emitters (their table holds θ0 positions), lights of
more than :data:`MAX_BORDER` border edges (the cost per kernel grows with them), kernels whose map is an
inner shape's of several triangles (an affine fit, not exact for its edges). Biased where the kernel
holds another moving edge than the kept ones.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.dual import detach
from sphere3d.boundary.emitters import edge_table
from sphere3d.live import any_rows, moves
from sphere3d.reparam.chart_field import ChartField, chart_edges
from sphere3d.reparam.film_lines import FilmLines
from sphere3d.reparam.probes import Followed
from sphere3d.rotation import Rotation
from sphere3d.vector import cross, dot, frame, norm

__all__ = ["MAX_BORDER", "border_field", "near_arcs"]

MAX_BORDER = 8
"""Emitter border edges beyond which no kernel gets the field: each kernel is tested against every one, and
its field weighs every pair of its lines (at most this many and three more) per sample."""


def near_arcs(x: np.ndarray, centre: np.ndarray, a: np.ndarray, b: np.ndarray, reach: Any) -> np.ndarray:
    r"""Whether the arc of directions from the points ``x`` (n, 3) to the segment ``a`` ``b`` (E, 3) passes
    within the angle ``reach`` (one, or (n,)) of the unit ``centre`` (n, 3): (n, E).

    The arc's nearest direction to c is the great circle's (c less its part along the circle's unit
    normal $\hat m$, at the angle $\arcsin |c·\hat m|$) where that lies between the ends, else the
    nearer end."""
    pa, pb = a[None] - x[:, None], b[None] - x[:, None]
    m = cross(pa, pb)
    m_hat = m / np.maximum(norm(m), 1e-300)[..., None]
    c = centre[:, None]
    off = dot(c, m_hat)
    foot = c - off[..., None] * m_hat
    between = (dot(cross(pa, foot), m) >= 0.0) & (dot(cross(foot, pb), m) >= 0.0)
    ends = np.maximum(dot(c, pa) / norm(pa), dot(c, pb) / norm(pb))  # the nearer end's cosine
    angle = np.where(between, np.arcsin(np.minimum(np.abs(off), 1.0)), np.arccos(np.clip(ends, -1.0, 1.0)))
    return angle <= (reach if np.ndim(reach) == 0 else reach[:, None])


def border_field(
    shading: Any,
    centre: np.ndarray,
    ring: Any,
    rotation: Rotation,
    followed: Followed | None,
    triangle: np.ndarray | None = None,
) -> ChartField:
    """The fields of the kernels (one per point of ``shading``, centres ``centre``, ring angle ``ring``: one,
    or one per kernel) whose reach holds an emitter border edge (module docstring), after ``rotation``;
    where ``triangle`` (n,) names a moving triangle whose image the kernel's ring reaches (an inner shape
    of one triangle, :class:`~sphere3d.reparam.shading_affine.ShadingAffine`), after the identity, the
    field keeping that triangle's three edges with the border instead of the followed ones."""
    state, n, k = shading.state, len(centre), shading.state.k
    table = edge_table(state)
    if table is None or len(table.a) > MAX_BORDER or np.any(moves(state.triangles)[state.emitters]):
        return ChartField.none(n, k)
    x0 = np.asarray(detach(shading.x))
    near = near_arcs(x0, centre, table.a, table.b, 2.0 * np.asarray(ring))
    own = np.zeros(n, dtype=bool) if triangle is None else triangle >= 0
    live = rotation.active | any_rows(moves(shading.x)) | own  # else the identity on a static border: v = 0
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
    moving = np.any(moves(shading.x))

    def part(f: np.ndarray, a: Any, c: Any) -> tuple[FilmLines, np.ndarray]:
        """The images of the edges a c (Dual or plain, (len(f), 3)) of the fields ``f``, relative to base."""
        x = shading.x[fields[f]] if moving else x0[fields[f]]
        return chart_edges(f, a - x, c - x, base.take(f), centre[fields[f]], t[f], b[f], scale[f], k)

    # the border edges near each kernel
    row, edge = np.nonzero(near[fields])
    parts = [part(row, table.a[edge], table.b[edge])]
    mine = np.flatnonzero(own[fields])
    if mine.size:  # an inner triangle's three edges
        tri = state.triangles[triangle[fields[mine]]]
        parts += [part(mine, tri[:, j], tri[:, (j + 1) % 3]) for j in range(3)]
    if followed is not None and followed.snapped is not None:
        rows, triangles, lines = followed.snapped
        ok = (lines[:, 0, 0] >= 0) & (slot[rows] >= 0) & ~own[rows]
        for side in range(2):  # the followed edge, or a corner's two (not a loop over samples)
            use = ok & ((side == 0) | np.any(lines[:, 1] != lines[:, 0], axis=1))
            tri, j = state.triangles[triangles[use]], np.arange(use.sum())
            parts.append(part(slot[rows[use]], tri[j, lines[use, side, 0]], tri[j, lines[use, side, 1]]))
    lines = FilmLines(
        *(np.concatenate([getattr(p, f) for p, _ in parts]) for f in FilmLines.__dataclass_fields__)
    )
    segment = np.concatenate([seg for _, seg in parts])
    return ChartField(slot, centre[fields], t, b, scale, lines, segment, k)
