r"""The emitter strategy's rotation: follow the occluder's silhouette between a shadowed and a lit probe.

An extension of the paper's emitter rule (theory page *extensions*). Per shading point, shadow
rays towards :data:`PROBES` points uniform on the emitters' area and :data:`BOUNDARY` points
evenly spaced along their edges (Loubet et al. 2019, Sec. 4.3). The rotation follows one
attached point (:class:`~sphere3d.rotation.Rotation`), chosen by what the probes saw:

- some probes occluded, some not (the penumbra): of the closest pair of an occluded and a
  visible probe, the occluded one's hit is moved onto the silhouette between the two by
  :data:`REFINE` bisection rays (:func:`~sphere3d.reparam.bisection.bisect_silhouette`), and
  that attached point is followed: the shadow edge is the occluder's silhouette, so the
  rotation holds it still where it crosses the light (Sec. 4.1: a discontinuity must be
  followed, not dragged);
- all occluded: the mean attached hit of the occluded probes (the authors' rule,
  :class:`~sphere3d.reparam.paper.PaperTransforms`);
- none occluded, the point or an emitter moving: the mean attached probe point on the
  emitters, so that the samples stay attached to a moving emitter (any rotation is exact for
  a continuous integrand; this one only lowers the variance);
- otherwise the identity.

The emitters' own sharp edges, which any of these rotations drags, are held fixed by their
boundary term (:mod:`sphere3d.boundary.emitters`).

Near either side of a penumbra the shadow edge cuts a thin part off the light, hidden or
visible, which reaches the light's border: the probes along the edges find it where area
probes alone mostly miss it (a hidden fraction q escapes n area probes with probability
$(1 - q)^n$). Closer still to the penumbra's outer lit edge, or to the umbra's, the part is
shorter along the border than the edge probes' spacing (perimeter / :data:`BOUNDARY`). Where
the probes found no pair, :data:`AIM` more probes join them (:func:`_aimed_points`): with none
occluded, the emitter points nearest in angle to the moving occluders' centre, where their
shadow first covers the light; with all occluded, the farthest, where the light is last
covered. A point whose probes already hold a pair is untouched; a point with no moving
occluder (a moving light) gets none. Points that cannot see a moving occluder in front of the
lights are not probed at all (:mod:`sphere3d.reparam.penumbra`): their rotation would follow a
static point.

One rotation per shading point follows one point of one shadow edge (Sec. 4.1); where the occluder
recedes, scales or turns, its shadow's edges across the light move apart, and with ``field``
(:func:`emitter_map`) the rotation is followed by a field that keeps every shadow edge the pairs of
probes find (:mod:`sphere3d.reparam.emitter_field`; tests/sphere3d/test_light_occluder.py on the
closed form :func:`~sphere3d.closed_form.occluded_light_irradiance`).

Where it is biased: an edge no pair of probes straddles (at the outermost lit points the hidden part
can lie beside every probe, aimed ones included, and the emitter strategy then keeps the identity), and
the cases of :mod:`sphere3d.reparam.emitter_field`. The measurement pages (``hard_shadow``, the bias
atlas, the occluder's motions) give the sizes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import detach
from sphere3d.boundary.emitters import edge_points, edge_table
from sphere3d.live import any_rows, emitters_change, moves, take_rows
from sphere3d.reparam.bisection import bisect_silhouette, closest_pair
from sphere3d.reparam.chart_field import ChartField
from sphere3d.reparam.emitter_field import PAIRS, shadow_field
from sphere3d.reparam.paper import direction_towards, mean_point_direction
from sphere3d.reparam.penumbra import may_see_motion, moving_occluders, moving_sphere
from sphere3d.rotation import Rotation
from sphere3d.sampling import sample_mesh, triangle_barycentrics
from sphere3d.tracing import attached_points, intersect_triangles
from sphere3d.vector import dot, norm, zeros

__all__ = ["AIM", "BOUNDARY", "PROBES", "REFINE", "EmitterMap", "emitter_map", "probe_rays", "row_probes"]

PROBES = 4
"""Shadow probes per shading point uniform on the emitters' area."""
BOUNDARY = 4
"""Shadow probes per shading point evenly spaced along the emitters' edges (random phase)."""
REFINE = 6
"""Bisection rays between the occluded and the visible probe of a pair (to 1/64 of their gap)."""
AIM = 2
"""Aimed probes per shading point whose probes hold no pair of an occluded and a visible one: the
emitter points nearest to (none occluded) or farthest from (all occluded) the moving occluders'
centre in angle (:func:`_aimed_points`), where a thin hidden or lit part of the light appears
first; 0: none."""


def row_probes(probes: int) -> int:
    """Shadow probes per shading point at most, ``probes`` + :data:`BOUNDARY` + :data:`AIM`: the rows of
    the pair tables of :func:`~sphere3d.reparam.bisection.closest_pair` are this long."""
    return probes + BOUNDARY + AIM


def probe_rays(probes: int) -> int:
    """Rays per shading point of :func:`emitter_map` at most: its :func:`row_probes` shadow probes,
    traced again where all are occluded, then per pair of probes bisected (the closest one, and up to
    :data:`~sphere3d.reparam.emitter_field.PAIRS` in all for the field) an inside ray and :data:`REFINE`
    bisection rays."""
    return 2 * row_probes(probes) + PAIRS * (1 + REFINE)


def _border_points(state: Any, u: np.ndarray, count: int) -> np.ndarray | None:
    """``count`` points per row evenly spaced in arc length along the emitters' edges (random phase
    ``u``), as :func:`~sphere3d.boundary.emitters.sample_emitter_edges` places its pair; None without
    edges."""
    table = edge_table(state)
    if table is None or count == 0:
        return None
    return edge_points(table, u, count)[1]


def _aimed_points(
    state: Any, x: np.ndarray, far: np.ndarray, count: int = AIM
) -> tuple[np.ndarray, np.ndarray] | None:
    r"""Per point of ``x`` (plain, (m, 3)) ``count`` emitter points nearest in angle to the moving
    occluders' centre, or farthest from it in the rows ``far``: (m, count, 3), and which rows are
    worth their rays (m,): the rows ``far``, and the others whose nearest point lies in the
    occluders' bounding cone (else nothing moving can hide the light); None without a moving
    non-emitter triangle or emitter edges.

    The centre c is that of the moving non-emitter triangles' bounding sphere
    (:func:`~sphere3d.reparam.penumbra.moving_sphere`), seen along the axis $a = (c - x) / |c - x|$. On an
    edge
    $p(t) = p_0 + t e$, $t \in [0, 1]$, the cosine $a \cdot v / |v|$ with $v = p(t) - x$ has one
    critical point (its derivative's numerator is linear in t), so the extremes over the border lie
    at its vertices (each edge's start, the loops being closed) or at those critical points; the
    candidates are ranked by their cosine. Where the axis meets an emitter inside, that hit is the
    nearest point. For a sphere in front of a convex light these are where its shadow first covers
    the light (the penumbra's outer lit edge) and where the light is last covered (the umbra's
    edge); for other occluders near them (a cube at its outermost lit point: 0.004 beside the
    hidden part, module docstring, Bias).
    """
    table = edge_table(state)
    moving = moving_occluders(state)
    if table is None or not moving.any():
        return None
    centre, radius = moving_sphere(state)
    triangles = np.asarray(detach(state.triangles))
    to = centre - x
    length = norm(to)
    axis = to / np.where(length > 0.0, length, 1.0)[:, None]
    p0, e = table.a, table.b - table.a  # (E, 3)
    # with v = p0 - x (m, E): a = axis.v, b = axis.e, v2 = |v|^2, ve = v.e, e2 = |e|^2, by products of
    # (m, 3) and (E, 3) arrays
    ax = dot(axis, x)[:, None]
    a, b = axis @ p0.T - ax, axis @ e.T
    v2 = dot(p0, p0)[None] - 2.0 * (x @ p0.T) + dot(x, x)[:, None]
    ve = dot(p0, e)[None] - x @ e.T
    e2 = dot(e, e)[None]
    # d/dt [(a + b t) / sqrt(v2 + 2 ve t + e2 t^2)] = 0  <=>  t (b ve - a e2) = a ve - b v2
    den = b * ve - a * e2
    t = np.divide(a * ve - b * v2, den, out=np.zeros_like(a), where=den != 0.0)
    # candidates: each edge's start (each vertex of a loop once) and its critical point, if inside it
    off = (t <= 0.0) | (t >= 1.0)
    t = np.concatenate([np.zeros_like(a), t], axis=1)  # (m, 2E)
    a, b, v2, ve = (np.concatenate([c, c], axis=1) for c in (a, b, v2, ve))
    e2 = np.concatenate([e2, e2], axis=1)
    cosine = (a + b * t) / np.sqrt(np.maximum(v2 + t * (2.0 * ve + t * e2), 1e-300))
    k = min(count, len(e))
    off = np.concatenate([np.zeros_like(off), off], axis=1)
    # rows ``far``: the k candidates farthest from the axis in angle, else the k nearest (critical
    # points off their edge excluded)
    at = np.argsort(np.where(off, 2.0, np.where(far[:, None], cosine, -cosine)), axis=1)[:, :k]
    nearest = np.max(np.where(off, -2.0, cosine), axis=1)
    rows = np.arange(len(x))[:, None]
    edge = np.concatenate([np.arange(len(e)), np.arange(len(e))])[at]
    points = p0[edge] + t[rows, at][..., None] * e[edge]  # (m, k, 3)
    # the axis through an emitter's inside: that hit is the nearest point (angle 0)
    for tri in triangles[state.emitters]:  # a loop over the few emitter triangles
        it = intersect_triangles(x, axis, tri)  # plain: no tangents
        crosses = np.abs(axis @ np.cross(tri[1] - tri[0], tri[2] - tri[0])) > 1e-300  # not parallel
        inside = (it.b1 >= 0.0) & (it.b2 >= 0.0) & (it.b1 + it.b2 <= 1.0)
        hit = inside & crosses & (it.t > 0.0) & ~far
        points[hit, 0] = it.point[hit]
        nearest[hit] = 1.0
    # a light that lies wholly outside the occluders' bounding cone (half-angle arcsin(r / |c - x|))
    # cannot be hidden by them: no ray for those rows
    with np.errstate(divide="ignore"):
        cone = np.sqrt(np.maximum(1.0 - np.minimum(radius / length, 1.0) ** 2, 0.0))  # cos of the half-angle
    return points, far | (nearest >= cone * (1.0 - 1e-9)) | (length <= radius)


def _shadow_rays(
    state: Any, x: np.ndarray, n: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit directions (m, p, 3) from the points ``x`` to the probe points ``y`` (m, p, 3), the shadow
    rays' lengths, and which probes are light samples the strategy could use: above the surface
    (normals ``n``), far enough."""
    to = y - x[:, None]
    dist = norm(to)
    w = np.divide(to, np.where(dist > 0.0, dist, 1.0)[..., None], out=to)  # in place: ``to`` not used again
    usable = (dot(w, n[:, None]) > 0.0) & (dist > 4.0 * state.epsilon)
    return w, np.maximum(dist - 2.0 * state.epsilon, 0.0), usable


def _rows(rows: np.ndarray, values: np.ndarray, shape: tuple, fill: Any) -> np.ndarray:
    """An array of ``shape`` filled with ``fill``, ``values`` at ``rows``."""
    out = np.full(shape, fill, dtype=values.dtype)
    out[rows] = values
    return out


@dataclass(frozen=True)
class EmitterMap:
    """Per shading point the emitter strategy's rotation, and the field that replaces it where the probes
    found shadow edges (:mod:`sphere3d.reparam.emitter_field`)."""

    rotation: Rotation
    field: ChartField


def emitter_map(
    shading: Any,
    probes: int = PROBES,
    boundary: int = BOUNDARY,
    refine: int = REFINE,
    aim: int = AIM,
    field: bool = True,
) -> EmitterMap:
    """One rotation per shading point for the emitter strategy (module docstring), and with ``field`` the
    field of :func:`~sphere3d.reparam.emitter_field.shadow_field` where a pair was found.

    ``shading``: a :class:`~sphere3d.integrator.Shading`; random numbers from its draws
    (stream ``"probes.emitter"``, keyed on each point's sample), so the primary samples are
    untouched. Points that are static, under static emitters, and whose shadow rays cannot
    meet a moving triangle (:func:`~sphere3d.reparam.penumbra.may_see_motion`) get the identity without
    probes: any
    rotation the probes chose there would follow a static point, with a zero derivative.
    """
    state = shading.state
    m = len(shading)
    if not state.dual:
        return EmitterMap(Rotation.identity((m,)), ChartField.none(m))
    need = np.full(m, emitters_change(state)) | any_rows(moves(shading.x))
    rest = np.flatnonzero(~need)  # the cull only where nothing else asks for probes
    need[rest] = may_see_motion(state, take_rows(detach(shading.x), rest))
    if need.all():
        target, found, fields = _probe_rotation(shading, probes, boundary, refine, aim, field)
        return EmitterMap(Rotation.following(target, found), fields)
    rows = np.flatnonzero(need)
    target, found = zeros((m, 3), True, state.k), np.zeros(m, dtype=bool)
    fields = ChartField.none(m, state.k)
    if rows.size:
        target[rows], found[rows], sub = _probe_rotation(
            shading.take(rows), probes, boundary, refine, aim, field
        )
        fields = sub.spread(rows, m)
    return EmitterMap(Rotation.following(target, found), fields)


def _probe_rotation(
    shading: Any, probes: int, boundary: int, refine: int, aim: int, field: bool
) -> tuple[Any, np.ndarray, ChartField]:
    """The probes' rotation for every point of ``shading``: its attached target, where it was found, and
    the fields (with ``field``)."""
    state = shading.state
    m = len(shading)
    u = shading.draws.uniforms("probes.emitter", probes, 3)
    emitters = np.asarray(detach(state.triangles))[state.emitters]
    y, k = sample_mesh(u, emitters)
    border = _border_points(state, shading.draws.uniforms("probes.emitter.border"), boundary)
    inner = probes
    if border is not None:
        y = np.concatenate([y, border], axis=1)
    x0, n0 = detach(shading.x), detach(shading.n)
    w, tmax, usable = _shadow_rays(state, x0, n0, y)
    occluded = state.tracer.occluded(shading.origin[:, None], w, tmax) & usable
    lack = np.flatnonzero(~(occluded.any(axis=1) & (usable & ~occluded).any(axis=1)))
    # no pair of an occluded and a visible probe: where all are occluded, ``aim`` more probes where the
    # light is last covered, else where it is first covered
    far = occluded[lack].any(axis=1)
    aimed = _aimed_points(state, x0[lack], far, aim) if aim and lack.size else None
    if aimed is not None:
        aimed, worth = aimed
        lack, aimed = lack[worth], aimed[worth]
    if aimed is not None and lack.size:
        w_a, tmax_a, usable_a = _shadow_rays(state, x0[lack], n0[lack], aimed)
        occluded_a = state.tracer.occluded(shading.origin[lack, None], w_a, tmax_a) & usable_a
        extra = (m, aimed.shape[1])
        w = np.concatenate([w, _rows(lack, w_a, (*extra, 3), 0.0)], axis=1)
        tmax = np.concatenate([tmax, _rows(lack, tmax_a, extra, 0.0)], axis=1)
        usable = np.concatenate([usable, _rows(lack, usable_a, extra, False)], axis=1)
        occluded = np.concatenate([occluded, _rows(lack, occluded_a, extra, False)], axis=1)
    visible = usable & ~occluded
    some_occluded, some_visible = any_rows(occluded), any_rows(visible)
    target = zeros((m, 3), state.dual, state.k)
    found = np.zeros(m, dtype=bool)
    fields = ChartField.none(m, state.k)
    s = np.flatnonzero(some_occluded & ~some_visible)
    if s.size:  # all occluded: the mean attached hit of the occluded probes (the authors' rule)
        hits = state.tracer.intersect(shading.origin[s, None], w[s], tmax[s])
        points = attached_points(state.triangles[np.where(occluded[s], hits.triangle, 0)], hits.u, hits.v)
        target[s], found[s] = mean_point_direction(shading.x[s], points, occluded[s])
    s = np.flatnonzero(some_occluded & some_visible)
    if s.size:  # a shadow edge crosses the light: its silhouette point between the closest pair
        ws, origin = take_rows(w, s), take_rows(shading.origin, s)
        occ, vis = occluded[s], visible[s]
        i, j, _ = closest_pair(ws, lambda r: occ[r, :, None] & vis[r, None, :])
        rows = np.arange(s.size)
        inside, outside = ws[rows, i], ws[rows, j]
        hits = state.tracer.intersect(origin, inside)
        normal = take_rows(detach(shading.n), s)
        edge, a_in, a_out = bisect_silhouette(state, origin, inside, outside, hits, normal, refine)
        point = attached_points(state.triangles[edge.triangle], edge.u, edge.v)
        target[s], found[s] = direction_towards(point, shading.x[s], np.ones(s.size, dtype=bool))
        if field:  # every shadow edge the probes can find, and the light's border, kept by one field
            first = (edge, a_in, a_out)
            turn = Rotation.following(target[s], found[s])  # these rows' rotations, as in the whole one
            fields = shadow_field(state, shading.x[s], origin, normal, ws, occ, vis, first, turn, refine)
            fields = fields.spread(s, m)
    # where neither the shading point nor an emitter moves, that rotation would have a zero derivative
    emitters_move = np.any(moves(state.triangles)[state.emitters])
    moving = any_rows(moves(shading.x)) | emitters_move
    f = np.flatnonzero(~some_occluded & any_rows(usable) & moving)
    if f.size:  # no shadow edge: the mean attached probe point on the emitters
        b1, b2 = triangle_barycentrics(u[f, :, 1:3])
        points = attached_points(state.triangles[state.emitters[k[f]]], b1, b2)
        target[f], found[f] = mean_point_direction(shading.x[f], points, usable[f, :inner])
    return target, found, fields
