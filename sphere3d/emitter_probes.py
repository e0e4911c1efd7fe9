r"""The emitter strategy's rotation: follow the occluder's silhouette between a shadowed and a lit probe.

Per shading point, shadow rays towards :data:`PROBES` points uniform on the emitters' area
and :data:`BOUNDARY` points evenly spaced along their edges (Loubet et al. 2019, Sec. 4.3).
The rotation follows one attached point (:class:`~sphere3d.rotation.Rotation`), chosen by
what the probes saw:

- some probes occluded, some not (the penumbra): of the closest pair of an occluded and
  a visible probe, the occluded one's hit is moved onto the silhouette between the two
  by :data:`REFINE` bisection rays (the refinement of :func:`~sphere3d.probes.select_points`),
  and that attached point is followed: the shadow edge is the occluder's silhouette, so
  the rotation holds it still where it crosses the light (Sec. 4.1: a discontinuity must
  be followed, not dragged);
- all occluded: the mean attached hit of the occluded probes (the authors' rule);
- none occluded, the point or an emitter moving: the mean attached probe point on the
  emitters, so that the samples stay attached to a moving emitter (any rotation is exact
  for a continuous integrand; this one only lowers the variance);
- otherwise the identity. The emitters' own sharp edges are held fixed under any of these by
  :mod:`sphere3d.emitter_edges`.

Near either side of a penumbra the shadow edge cuts a thin part off the light, hidden or
visible, which reaches the light's border: the probes along the edges find it where area
probes alone mostly miss it (a hidden fraction q escapes 4 of them with probability
$(1 - q)^4$).

Bias
----
Measured at single ground points (x, -0.1, 0) of the ``hard_shadow`` scenes (d/d
``occluder.translate.x``, fixed point and normal, :func:`sphere3d.irradiance`) against
``boundary`` (unbiased), and per strategy against central differences (h = 0.004) of the naive
strategy's value at fixed samples (emitter strategy alone; the cosine strategy as the rest).
Before (4 area probes, the mean occluded hit followed, the identity where none was occluded)
the emitter strategy was off by -45 % to +60 % point by point: on the lit side no probe saw
the occluder and its shadow edge was dragged (sphere, x = -0.3: 0.55 of the derivative kept);
elsewhere the mean hit lay nearer the point than the silhouette and the rotation turned too
fast (sphere, x = -0.05: emitter strategy 11.56 ± 0.04 against 9.08 ± 0.11; cube: 11.98 ± 0.05
against 7.42 ± 0.11). Over the penumbra the two errors nearly cancelled (98.4 % / 102.9 %
kept, 8 seeds). Now (reparam against ``boundary``, 3 seeds × 16384 samples, ± 0.7 %; x = -0.05: 2 seeds):

=======================  ==========================  ==========================
point                    sphere                      cube
=======================  ==========================  ==========================
x = -0.3, -0.25 (lit)    -0.1 %, -0.7 %              (x = -0.2) +0.4 %
x = 0.1 (umbra's side)   -2.6 %                      -1.8 %
x = 0.65                                             -1.8 %
x = -0.05                                            +6.7 % (two edges)
=======================  ==========================  ==========================

What remains, by strategy (65536 samples against 262144-524288 of the differences; measured
with 12 edge probes, the totals above with 8):

- the **cosine strategy** loses 20-95 % of its share, always short: its rotation follows the
  occluder where a kernel sees it in front of the light, and drags the light's edge, whose
  term no Leibniz term restores in that strategy (sphere, x = 0.1: 0.02 against 0.29 ± 0.06
  of a total 7.79; x = -0.2: 0.36 against 0.44; cube, x = 0.1: 0.005 against 0.22; x = 0.65:
  -0.08 against -0.22): -1 to -3.5 % of the derivative, the sphere's penumbra deficit;
- the **emitter strategy** within 2-3 % where one silhouette edge crosses the light (sphere,
  x = 0.1: 7.53 ± 0.03 against 7.33 ± 0.05; x = -0.2: 8.87 against 9.03 ± 0.05; cube, x = 0.65:
  -5.27 against -5.23 ± 0.07), too large where the cube's shadow edge is two edges at different
  depths (x = -0.05: the whole +6.7 %, 8.12 ± 0.06 against 7.61): one rotation follows one of them.

Tested in ``tests/sphere3d/test_emitter_probes.py``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.dual import detach, tangent
from sphere3d.emitter_edges import edge_points, edge_table
from sphere3d.live import any_rows, emitters_change, take_rows, triangles_change
from sphere3d.probes import bisect_silhouette, direction_towards, mean_point_direction
from sphere3d.rotation import Rotation
from sphere3d.sampling import sample_mesh, triangle_barycentrics
from sphere3d.tracing import attached_points
from sphere3d.vector import dot, norm, zeros

__all__ = ["PROBES", "REFINE", "emitter_rotation"]

PROBES = 4
"""Shadow probes per shading point uniform on the emitters' area."""
BOUNDARY = 8
"""Shadow probes per shading point evenly spaced along the emitters' edges (random phase)."""
REFINE = 6
"""Bisection rays between the occluded and the visible probe of a pair (to 1/64 of their gap)."""


def _border_points(state: Any, u: np.ndarray, count: int) -> np.ndarray | None:
    """``count`` points per row evenly spaced in arc length along the emitters' edges (random phase
    ``u``), as :func:`~sphere3d.emitter_edges.sample_emitter_edges` places its pair; None without edges."""
    table = edge_table(state)
    if table is None or count == 0:
        return None
    return edge_points(table, u, count)[1]


def _bounding_sphere(vertices: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius of a sphere holding every vertex (k, 3, 3): the box's centre, a safe radius."""
    v = vertices.reshape(-1, 3)
    centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
    return centre, float(np.sqrt(np.max(np.sum((v - centre) ** 2, axis=1)))) * (1.0 + 1e-9)


def _may_see_motion(state: Any, x: np.ndarray) -> np.ndarray:
    r"""Rows of the points ``x`` (plain, (m, 3)) whose shadow rays to the emitters may meet a moving triangle.

    Conservative, by bounding spheres: a ray from x to the emitters lies within the angle
    $β_L = \arcsin(r_L / d_L)$ of the direction to their sphere's centre, one that meets the
    moving triangles within $β_M$ of theirs, so the two cones must overlap, $α < β_L + β_M$,
    and the moving sphere must begin before the emitters' sphere ends. A point inside either
    sphere counts.
    """
    moving = triangles_change(state)
    if not moving.any():
        return np.zeros(len(x), dtype=bool)
    triangles = np.asarray(detach(state.triangles))
    (c_m, r_m), (c_l, r_l) = _bounding_sphere(triangles[moving]), _bounding_sphere(triangles[state.emitters])
    to_m, to_l = c_m - x, c_l - x
    d_m, d_l = norm(to_m), norm(to_l)
    inside = (d_m <= r_m) | (d_l <= r_l)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_a = np.clip(dot(to_m, to_l) / (d_m * d_l), -1.0, 1.0)
        reach = np.arcsin(np.minimum(1.0, r_l / d_l)) + np.arcsin(np.minimum(1.0, r_m / d_m))
    overlap = np.arccos(cos_a) < reach * (1.0 + 1e-9) + 1e-9
    return inside | (overlap & (d_m - r_m < d_l + r_l))


def emitter_rotation(
    shading: Any, probes: int = PROBES, boundary: int = BOUNDARY, refine: int = REFINE
) -> Rotation:
    """One rotation per shading point for the emitter strategy (module docstring).

    ``shading``: a :class:`~sphere3d.integrator.Shading`; random numbers from its draws
    (stream ``"probes.emitter"``, keyed on each point's sample), so the primary samples are
    untouched. Points that are static, under static emitters, and whose shadow rays cannot
    meet a moving triangle (:func:`_may_see_motion`) get the identity without probes: any
    rotation the probes chose there would follow a static point, with a zero derivative.
    """
    state = shading.state
    m = len(shading)
    if not state.dual:
        return Rotation.identity((m,))
    x0 = detach(shading.x)
    need = any_rows(tangent(shading.x) != 0.0) | emitters_change(state) | _may_see_motion(state, x0)
    if need.all():
        return _probe_rotation(shading, probes, boundary, refine)
    rows = np.flatnonzero(need)
    target, found = zeros((m, 3), True), np.zeros(m, dtype=bool)
    if rows.size:
        sub = _probe_rotation(shading.take(rows), probes, boundary, refine, targets=True)
        target[rows], found[rows] = sub
    return Rotation.following(target, found)


def _probe_rotation(shading: Any, probes: int, boundary: int, refine: int, targets: bool = False) -> Any:
    """The probes' rotation for every point of ``shading`` (its attached target and where it was
    found, if ``targets``)."""
    state = shading.state
    m = len(shading)
    u = shading.draws.uniforms("probes.emitter", probes, 3)
    emitters = np.asarray(detach(state.triangles))[state.emitters]
    y, k = sample_mesh(u, emitters)
    border = _border_points(state, shading.draws.uniforms("probes.emitter.border"), boundary)
    inner = probes
    if border is not None:
        y = np.concatenate([y, border], axis=1)
        probes = y.shape[1]
    to = y - detach(shading.x)[:, None]
    dist = norm(to)
    w = to / np.where(dist > 0.0, dist, 1.0)[..., None]
    tmax = np.maximum(dist - 2.0 * state.epsilon, 0.0)
    # only probes that are light samples the strategy could use: above the surface, far enough
    usable = (dot(w, detach(shading.n)[:, None]) > 0.0) & (dist > 4.0 * state.epsilon)
    occluded = state.tracer.occluded(shading.origin[:, None], w, tmax) & usable
    visible = usable & ~occluded
    some_occluded, some_visible = any_rows(occluded), any_rows(visible)
    target = zeros((m, 3), state.dual)
    found = np.zeros(m, dtype=bool)
    s = np.flatnonzero(some_occluded & ~some_visible)
    if s.size:  # all occluded: the mean attached hit of the occluded probes (the authors' rule)
        hits = state.tracer.intersect(shading.origin[s, None], w[s], tmax[s])
        points = attached_points(state.triangles[np.where(occluded[s], hits.triangle, 0)], hits.u, hits.v)
        target[s], found[s] = mean_point_direction(shading.x[s], points, occluded[s])
    s = np.flatnonzero(some_occluded & some_visible)
    if s.size:  # a shadow edge crosses the light: its silhouette point between the closest pair
        ws, origin = take_rows(w, s), take_rows(shading.origin, s)
        cosine = np.matmul(ws, np.ascontiguousarray(ws.transpose(0, 2, 1)))  # (s, p, p): w_i . w_j
        np.putmask(cosine, ~(occluded[s][:, :, None] & visible[s][:, None, :]), -2.0)  # pairs only
        i, j = np.divmod(np.argmax(cosine.reshape(len(s), -1), axis=1), probes)
        rows = np.arange(s.size)
        inside, outside = ws[rows, i], ws[rows, j]
        hits = state.tracer.intersect(origin, inside)
        normal = take_rows(detach(shading.n), s)
        edge, _, _ = bisect_silhouette(state, origin, inside, outside, hits, normal, refine)
        point = attached_points(state.triangles[edge.triangle], edge.u, edge.v)
        target[s], found[s] = direction_towards(point, shading.x[s], np.ones(s.size, dtype=bool))
    # where neither the shading point nor an emitter moves, that rotation would have a zero derivative
    emitters_move = np.any(tangent(state.triangles)[state.emitters] != 0.0)
    moving = any_rows(tangent(shading.x) != 0.0) | emitters_move
    f = np.flatnonzero(~some_occluded & any_rows(usable) & moving)
    if f.size:  # no shadow edge: the mean attached probe point on the emitters
        b1, b2 = triangle_barycentrics(u[f, :, 1:3])
        points = attached_points(state.triangles[state.emitters[k[f]]], b1, b2)
        target[f], found[f] = mean_point_direction(shading.x[f], points, usable[f, :inner])
    return (target, found) if targets else Rotation.following(target, found)
