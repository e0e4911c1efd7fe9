r"""The emitter strategy's field: the shadow edges found by probes, kept after the rotation.

The emitter strategy's rotation (:mod:`sphere3d.reparam.emitter_probes`) follows one point of one
shadow edge per shading point. Where the occluder recedes, scales or turns, its shadow's edges across
the light move apart (a triangle's shadow inside the light, a box's corner casting two edges), and
the rotation drags all but the one it follows.

Here, at the shading points whose probes hold a pair of an occluded and a visible probe, the rotation
is followed by a field of the gnomonic chart about the axis from the point to the centre of the
emitters' bounding sphere (:class:`~sphere3d.reparam.chart_field.ChartField`, Loubet et al. 2019,
Sec. 4.3: a refinement of the heuristic) that keeps the shadow edges: the occluder's edges found by
bisection between pairs of an occluded and a visible probe
(:func:`~sphere3d.reparam.bisection.bisect_silhouette`), each moved onto the silhouette edge the
bisection's segment leaves by (:func:`~sphere3d.reparam.snaps.edge_snap`), with the silhouette edges
that follow it along the outline from both its ends (:func:`~sphere3d.reparam.outline.outline_chain`: a
triangle's other two, a box's corner's next edges, a faceted sphere's outline across the light) while
their images reach the light's disc, up to :data:`CHAIN` a side. The first pair is the closest one
(the rotation's); each next one joins
an occluded and a visible probe on the same side of every edge found so far, so another edge lies
between them; at most :data:`PAIRS` pairs. The field's scale is the light's radius in the chart,
$\tan(\arcsin(R / d))$ for its bounding sphere of radius R at distance d: beyond the light it is the
rotation alone. Edges are kept as their images, segments (:func:`~sphere3d.reparam.chart_field.chart_edges`);
those whose image misses the light's disc in the chart, which cannot be a discontinuity there, are left
out (they would only constrain the map, at a cost per sample).

The light's own border is dragged by the whole map as by the rotation alone, and its boundary term
(:mod:`sphere3d.boundary.emitters`) takes the map's velocity at its edge points: the border held
fixed, exactly, whatever the field does. A point on the light's bounding sphere gets no field.

Biased where a shadow edge is neither found by a pair nor on the outline within :data:`CHAIN` edges of
a found one (a thin lit or hidden part between probes, an outline of more edges across the light), and
where the shadow's outline is curved (straight per facet only).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.dual import detach
from sphere3d.reparam.bisection import bisect_silhouette, closest_pair
from sphere3d.reparam.chart_field import ChartField, chart_edges
from sphere3d.reparam.film_lines import FilmLines
from sphere3d.reparam.outline import outline_chain
from sphere3d.reparam.penumbra import emitter_sphere
from sphere3d.reparam.snaps import edge_snap
from sphere3d.rotation import Rotation
from sphere3d.vector import cross, frame, norm

__all__ = ["CHAIN", "PAIRS", "shadow_field"]

PAIRS = 3
"""Pairs of probes bisected per shading point at most, each finding a shadow edge and its next ones: a
triangle's shadow has three edges."""
CHAIN = 8
"""Silhouette edges followed along the outline from each end of a found edge at most, while their images
reach the light's disc: a cost bound per shading point (the field costs O(J) per sample for J lines);
an outline of more edges across the light (a finer mesh's) keeps its further edges only where another
pair finds them."""


def _no_corner(rows: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Distances of an edge's ends from the kernel for :func:`~sphere3d.reparam.snaps.edge_snap`: 0 each,
    with a radius of -1, so no corner is ever snapped to (a line is wanted, not a point)."""
    return np.zeros(ends.shape[:2])


def shadow_field(
    state: Any,
    x: Any,
    origin: np.ndarray,
    normal: np.ndarray,
    w: np.ndarray,
    occluded: np.ndarray,
    visible: np.ndarray,
    first: tuple,
    rotation: Rotation,
    refine: int,
    pairs: int = PAIRS,
) -> ChartField:
    """The fields of the points ``x`` (Dual (s, 3); ray origins ``origin``, normals ``normal``) whose probe
    directions ``w`` (s, p, 3) hold an ``occluded`` and a ``visible`` probe each (module docstring), about
    their ``rotation``; ``first``: the closest pair's bisection, ``(hits, inside, outside)``
    (:func:`~sphere3d.reparam.bisection.bisect_silhouette`)."""
    s, k = len(origin), state.k
    if s == 0:
        return ChartField.none(s, k)
    x0 = np.asarray(detach(x))
    centre, radius = emitter_sphere(state)
    axis = centre - x0
    distance = norm(axis)
    ok = distance > radius  # the light inside a cone of half-angle < π/2 about the axis: in the chart
    axis /= np.where(ok, distance, 1.0)[:, None]
    # the light's radius in the chart, tan(asin(R / d)): the field's scale (its prior's weight 1 / scale²)
    scale = radius / np.sqrt(np.maximum(distance * distance - radius * radius, 1e-300))
    t, b = frame(axis)
    snap = edge_snap(state, _no_corner, -1.0)
    plain = np.asarray(detach(state.triangles))
    found_rows, found_m = [], []
    # per point and probe, on which side of each found edge's great circle it lies: 2 bits an edge
    # (sign + 1), so that two probes are on the same side of every edge where their codes are equal
    code, shift = np.zeros(w.shape[:2], dtype=np.int64), 0
    hits, inside, outside = first
    rows, alive = np.arange(s), ok.copy()
    for r in range(pairs):  # a few rounds of bisection, each over every point at once
        if r:
            # a pair on the same side of every edge found: another edge lies between them
            same = code[:, :, None] == code[:, None, :]  # (s, p, p)
            i, j, has = closest_pair(
                w, lambda q, same=same: occluded[q, :, None] & visible[q, None, :] & same[q]
            )
            rows = np.flatnonzero(has & alive)
            if not rows.size:
                break
            a_in, a_out = w[rows, i[rows]], w[rows, j[rows]]
            h0 = state.tracer.intersect(origin[rows], a_in)
            hits, inside, outside = bisect_silhouette(
                state, origin[rows], a_in, a_out, h0, normal[rows], refine
            )
        snapped, _, _, lines = snap(rows, origin[rows], inside, outside, hits)
        good = (lines[:, 0, 0] >= 0) & hits.hit & ok[rows]
        alive[:] = False
        alive[rows[good]] = True  # the next round only where this one found an edge
        g, triangle, slots = rows[good], snapped[good], lines[good, 0]
        # the found edge, and the silhouette edges that meet it at its ends (outline.next_edges); an edge
        # found twice is a line twice (weight doubled, the field unchanged where it matters: on it)
        edges = [(g, triangle, slots[:, 0], slots[:, 1])]
        # and on along the outline while its edges' images reach the light's disc (outline.outline_chain)
        near = _near_light(state, x0, g, axis, t, b, scale)
        for i, face, ia, ib in outline_chain(state, x0[g], triangle, slots, near, CHAIN):
            edges.append((g[i], face, ia, ib))
        # the round's edges at once (one chart conversion a round, not one per step along the outline)
        row, face, ia, ib = (np.concatenate([e[i] for e in edges]) for i in range(4))
        tri, n = state.triangles[face], np.arange(len(face))
        xg = x[row]
        found_rows.append(row)
        found_m.append((tri[n, ia] - xg, tri[n, ib] - xg, rotation.take(row)))
        if r + 1 < pairs and shift < 62:  # the side codes, for the next rounds' pairs
            # each step's edges (one row each) their own 2 bits, while bits are left: all steps at once
            groups = min(len(edges), (62 - shift + 1) // 2)
            sizes = [len(e[0]) for e in edges[:groups]]
            c, used = slice(0, sum(sizes)), shift + 2 * np.repeat(np.arange(groups), sizes)
            plane = cross(plain[face[c], ia[c]] - x0[row[c]], plain[face[c], ib[c]] - x0[row[c]])
            side = np.sign(np.einsum("rpx,rx->rp", w[row[c]], plane)).astype(np.int64) + 1
            np.bitwise_or.at(code, row[c], side << used[:, None])
            shift += 2 * groups
    shadow = np.concatenate(found_rows) if found_rows else np.zeros(0, np.intp)
    fields = np.unique(shadow)
    if not fields.size:
        return ChartField.none(s, k)
    slot = np.full(s, -1, dtype=np.intp)
    slot[fields] = np.arange(fields.size)
    parts = [
        chart_edges(slot[row], p1, p2, base, axis[row], t[row], b[row], scale[row], k)
        for row, (p1, p2, base) in zip(found_rows, found_m, strict=True)  # per round
    ]
    lines = FilmLines(
        *(np.concatenate([getattr(p, f) for p, _ in parts]) for f in FilmLines.__dataclass_fields__)
    )
    segment = np.concatenate([seg for _, seg in parts])
    # only edges whose image reaches the light's disc in the chart (radius 1 in these units) can be a
    # discontinuity there: the others would only constrain the map, at a cost per sample
    keep = _reach_disc(lines, segment)
    lines, segment = lines.take(keep), segment[keep]
    held = np.zeros(fields.size, dtype=bool)
    held[lines.rows] = True
    if not held.all():  # a field without a line is the rotation alone
        renumber = np.cumsum(held) - 1
        slot = np.where(slot >= 0, np.where(held[np.maximum(slot, 0)], renumber[np.maximum(slot, 0)], -1), -1)
        lines = FilmLines(
            renumber[lines.rows], lines.point, lines.direction, lines.point_dot, lines.direction_dot
        )
        fields = fields[held]
    return ChartField(slot, axis[fields], t[fields], b[fields], scale[fields], lines, segment, k)


def _reach_disc(lines: FilmLines, segment: np.ndarray) -> np.ndarray:
    """Which of the ``lines`` (points ``q + s e``; s in [0, 1] where ``segment``) come within 1 of the chart's
    origin."""
    q, e = lines.point, lines.direction
    s = -np.sum(q * e, axis=1) / np.maximum(np.sum(e * e, axis=1), 1e-300)
    s = np.where(segment, np.clip(s, 0.0, 1.0), s)
    return np.hypot(*(q + s[:, None] * e).T) <= 1.0


def _near_light(
    state: Any,
    x0: np.ndarray,
    g: np.ndarray,
    axis: np.ndarray,
    t: np.ndarray,
    b: np.ndarray,
    scale: np.ndarray,
) -> Any:
    """``near(rows, face, ia, ib)`` for :func:`~sphere3d.reparam.outline.outline_chain`: whether the edge's
    image in the gnomonic chart about ``axis`` comes within the light's radius ``scale`` of its origin
    (points ``x0[g[rows]]``); an edge with an end behind the chart's plane counts as near."""
    triangles = np.asarray(detach(state.triangles))

    def near(rows: np.ndarray, face: np.ndarray, ia: np.ndarray, ib: np.ndarray) -> np.ndarray:
        p = g[rows]
        ends = np.stack([triangles[face, ia], triangles[face, ib]], axis=1) - x0[p, None]  # (r, 2, 3)
        depth = np.einsum("rex,rx->re", ends, axis[p])
        behind = np.any(depth <= 0.0, axis=1)
        z = np.where(depth > 0.0, depth, 1.0)
        u = (
            np.stack([np.einsum("rex,rx->re", ends, t[p]), np.einsum("rex,rx->re", ends, b[p])], -1)
            / z[..., None]
        )
        e = u[:, 1] - u[:, 0]
        s = np.clip(-np.sum(u[:, 0] * e, axis=1) / np.maximum(np.sum(e * e, axis=1), 1e-300), 0.0, 1.0)
        return behind | (np.hypot(*(u[:, 0] + s[:, None] * e).T) <= scale[p])

    return near
