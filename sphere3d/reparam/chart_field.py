r"""A velocity field of a gnomonic chart about a direction, after a rotation: the map that keeps chosen lines.

Shared by the emitter strategy (:mod:`sphere3d.reparam.emitter_field`: the chart about the light,
the shadow edges) and the cosine strategy's kernels (:mod:`sphere3d.reparam.kernel_border`: the chart
about a kernel's centre, the light's border). Per shading point or kernel, a chart about a θ-free
unit axis a (frame t, b), $g(ω) = (ω·t, ω·b) / (ω·a)$, in which a great circle through the point
of normal m is the line $(m·t) u_1 + (m·b) u_2 + m·a = 0$ (:func:`chart_line`; an edge whose ends
lie in front of the chart is kept as its image, a segment, :func:`chart_edges`: off its ends the field
takes the nearer end's velocity, where a whole line's far points move with its turn times their
distance, without bound for an edge seen nearly end-on), and a rotation R(θ)
already chosen (the probes' rule). The evaluation direction of a sample ω is $R(θ)\, T(θ, ω)$, T
the map of the chart $u \mapsto u + (θ - θ_0)\, v(u)$ with v the moving least-squares field of
:func:`~sphere3d.reparam.corner_lines.line_field` over the lines, their velocities taken relative to
R (:func:`relative_normal`: a great circle turning with R does not move), in units of a scale r per
chart (its prior's weight $1 / r^2$: v falls to 0, the rotation alone, beyond about r from every
line). On each line the normal velocity of R T is the line's own: the lines stay on their moved
lines to first order (Loubet et al. 2019, Sec. 4.3: a refinement of the heuristic).

A change of variables of the sphere: the sample is evaluated at $R T ω$ (value ω, tangent
$\dot R ω + \dot T ω$), its estimate weighted by the Jacobian (value 1, derivative
$\mathrm{tr}\, ∇v - 3\, u·v / (1 + |u|^2)$, the chart's area element being
$du / (1 + |u|^2)^{3/2}$, as in :mod:`sphere3d.reparam.shading_affine`; R's is 1).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach, tangent
from sphere3d.reparam.corner_lines import EPSILON
from sphere3d.reparam.field_kernel import field_trace
from sphere3d.reparam.film_lines import FilmLines
from sphere3d.rotation import Rotation
from sphere3d.vector import cross, dot

__all__ = ["ChartField", "chart_edges", "chart_line", "chart_lines", "relative_normal"]


@dataclass(frozen=True)
class ChartField:
    """Per shading point the row of its field (``slot``, -1: none), and per field its chart (unit ``axis``,
    frame ``t``, ``b``, (F, 3) each) and lines (``lines.rows`` in [0, F), velocities (P, 2) or (P, k, 2))."""

    slot: np.ndarray
    axis: np.ndarray
    t: np.ndarray
    b: np.ndarray
    scale: np.ndarray
    lines: FilmLines
    segment: np.ndarray  # (P,): the line is its edge's image only (s in [0, 1]), else a whole line
    k: int | None = None

    @staticmethod
    def none(n: int, k: int | None = None) -> ChartField:
        """No point has a field."""
        empty = np.zeros((0, 3))
        slots = (0, 2) if k is None else (0, k, 2)
        lines = FilmLines(
            np.zeros(0, np.intp), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(slots), np.zeros(slots)
        )
        no = np.zeros(0, dtype=bool)
        return ChartField(np.full(n, -1, dtype=np.intp), empty, empty, empty, np.zeros(0), lines, no, k)

    def take(self, index: Any) -> ChartField:
        """The points at ``index`` (their fields shared)."""
        return replace(self, slot=self.slot[index])

    def spread(self, rows: np.ndarray, n: int) -> ChartField:
        """These fields as those of rows ``rows`` of n points (the others none)."""
        slot = np.full(n, -1, dtype=np.intp)
        slot[rows] = self.slot
        return replace(self, slot=slot)

    def apply(self, omega: np.ndarray, rotated: Any, jacobian: bool = True) -> tuple[Any, Any]:
        """The evaluation directions of the points' emitter samples ``omega`` (plain, (n, 3)): ``rotated``
        (the rotation's, Dual) with the field's tangent at the points that have one, and the
        Jacobian weight (Dual of value 1; None where no point has a field, or without ``jacobian``:
        a boundary term's points need their velocity only)."""
        on = np.flatnonzero(self.slot >= 0)
        if not on.size:
            return rotated, None
        f = self.slot[on]
        # each sample's lines: the lines of its field (sorted by field), one run per sample
        order = np.argsort(self.lines.rows, kind="stable")
        count = np.bincount(self.lines.rows, minlength=len(self.axis))
        start = np.cumsum(count) - count
        rep = np.repeat(np.arange(on.size), count[f])
        within = np.arange(rep.size) - np.repeat(np.cumsum(count[f]) - count[f], count[f])
        chosen = order[start[f][rep] + within]
        pick, segment = self.lines.take(chosen), self.segment[chosen]
        lines = FilmLines(rep, pick.point, pick.direction, pick.point_dot, pick.direction_dot)
        y, axis, t, b = omega[on], self.axis[f], self.t[f], self.b[f]
        depth = dot(y, axis)
        u = np.stack([dot(y, t), dot(y, b)], axis=1) / depth[:, None]
        # in units of the chart's scale r (prior weight 1 / r²), then back: v = r v_r, tr ∇v = tr ∇_r v_r
        # (line_field's, point by point: field_kernel)
        scale = self.scale[f]
        v, trace = field_trace(u / scale[:, None], lines, segment, 1.0, segment, jacobian, EPSILON)
        k = self.k
        v = v * (scale[:, None] if k is None else scale[:, None, None])
        s2 = 1.0 + dot(u, u)
        shape = omega.shape if k is None else (k, *omega.shape)
        t_dir, log_j = np.zeros(shape) + tangent(rotated), np.zeros(shape[:-1])
        if k is not None:  # the parameters' axis first, as the Duals hold it
            v = np.moveaxis(v, 1, 0)
            trace = None if trace is None else trace.T
        # ω = (a + u_1 t + u_2 b) / sqrt(1 + |u|²) moving with u̇ = v   (shading_affine._map_tangents)
        radial = np.sum(u * v, axis=-1) / s2
        y_dot = (v[..., :1] * t + v[..., 1:] * b) / np.sqrt(s2)[:, None] - y * radial[..., None]
        # the rotation after the field: R(θ) T(θ, ω) moves at Ṙω + Ṫ(ω)
        t_dir[..., on, :] += y_dot
        direction = Dual(np.asarray(detach(rotated)), t_dir, k)
        if not jacobian:
            return direction, None
        # log |J|: tr ∇v - 3 u·v / (1 + |u|²), the chart's area element du / (1 + |u|²)^{3/2}
        log_j[..., on] = trace - 3.0 * radial
        return direction, Dual(np.ones(len(omega)), log_j, k)


def chart_line(m: Any, axis: np.ndarray, t: np.ndarray, b: np.ndarray, k: int | None) -> tuple:
    """The chart line $A u_1 + B u_2 + C = 0$ of the great circle of normal ``m`` (Dual (n, 3)): its
    point nearest the chart's origin, that point's velocity, its direction and the direction's velocity
    (values (n, 2), velocities (n, 2) or (n, k, 2))."""
    a_, b_, c_ = dot(m, t), dot(m, b), dot(m, axis)
    scale = a_ * a_ + b_ * b_
    q = [-c_ * a_ / scale, -c_ * b_ / scale]
    e = [-b_, a_]
    out = []
    for pair in (q, e):
        value = np.stack([np.asarray(detach(p)) for p in pair], axis=-1)
        dots = np.stack(
            [np.broadcast_to(tangent(p, k), (len(value),) if k is None else (k, len(value))) for p in pair],
            axis=-1,
        )
        out += [value, dots if k is None else np.moveaxis(dots, 0, 1)]
    return tuple(out)


def relative_normal(m: Any, rotation: Rotation, k: int | None) -> Dual:
    r"""The great circle's normal ``m`` (Dual (n, 3)) in the frame that turns with ``rotation``: value m,
    tangent $\dot m - Ω × m$ ($Ω × m$ the rotation's tangent of m, linear in m)."""
    value = np.asarray(detach(m))
    return Dual(value, tangent(m, k) - rotation.apply(value).tangent, k)


def chart_edges(
    slot: np.ndarray,
    p1: Any,
    p2: Any,
    base: Rotation,
    axis: np.ndarray,
    t: np.ndarray,
    b: np.ndarray,
    scale: np.ndarray,
    k: int | None,
) -> tuple[FilmLines, np.ndarray]:
    """The images (rows ``slot``) of the edges from the directions ``p1`` to ``p2`` (Dual or plain (n, 3),
    edge ends less the point) in the charts ``axis``, ``t``, ``b`` (n, 3), in units of ``scale`` (n,),
    moving relative to ``base`` (one rotation per row), and which are segments: both ends in front of
    the chart (else the edge's whole great circle, :func:`chart_line`)."""
    ends = [relative_normal(p, base, k) for p in (p1, p2)]  # a direction turns with R as a normal does
    depth = [dot(np.asarray(detach(p)), axis) for p in ends]
    front = (depth[0] > 0.0) & (depth[1] > 0.0)
    unit = scale[:, None]
    per = unit if k is None else unit[:, None]
    lines = chart_lines(slot, cross(ends[0], ends[1]), axis, t, b, scale, k)
    if front.any():
        g = [_chart_point(p, axis, t, b, k) for p in ends]
        q, q_dot = g[0]
        e, e_dot = g[1][0] - q, g[1][1] - q_dot
        f = front[:, None]
        fk = f if k is None else f[:, None]
        lines = FilmLines(
            slot,
            np.where(f, q / unit, lines.point),
            np.where(f, e / unit, lines.direction),
            np.where(fk, q_dot / per, lines.point_dot),
            np.where(fk, e_dot / per, lines.direction_dot),
        )
    return lines, front


def _chart_point(p: Any, axis: np.ndarray, t: np.ndarray, b: np.ndarray, k: int | None) -> tuple:
    """The chart point of the directions ``p`` (Dual (n, 3)): value (n, 2), velocity (n, 2) or (n, k, 2)."""
    depth = dot(p, axis)
    pair = [dot(p, t) / depth, dot(p, b) / depth]
    value = np.stack([np.asarray(detach(c)) for c in pair], axis=-1)
    n = len(value)
    dots = np.stack([np.broadcast_to(tangent(c, k), (n,) if k is None else (k, n)) for c in pair], axis=-1)
    return value, dots if k is None else np.moveaxis(dots, 0, 1)


def chart_lines(
    slot: np.ndarray, m: Any, axis: np.ndarray, t: np.ndarray, b: np.ndarray, scale: np.ndarray, k: int | None
) -> FilmLines:
    """The lines (rows ``slot``) of the great circles of normals ``m`` (Dual (n, 3), relative velocities)
    in the charts ``axis``, ``t``, ``b`` (n, 3), in units of ``scale`` (n,)."""
    q, q_dot, e, e_dot = chart_line(m, axis, t, b, k)
    unit = scale[:, None]
    return FilmLines(slot, q / unit, e, q_dot / (unit if k is None else unit[:, None]), e_dot)
