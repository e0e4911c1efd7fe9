r"""The emitter strategy's rotation: follow the occluder's silhouette between a shadowed and a lit probe.

Per shading point, shadow rays towards :data:`PROBES` points uniform on the emitters' area
and :data:`BOUNDARY` points evenly spaced along their edges (Loubet et al. 2019, Sec. 4.3).
The rotation follows one attached point (:class:`~sphere3d.rotation.Rotation`), chosen by
what the probes saw:

- some probes occluded, some not (the penumbra): of the closest pair of an occluded and
  a visible probe, the occluded one's hit is moved onto the silhouette between the two
  by :data:`REFINE` bisection rays (the refinement of :func:`~sphere3d.reparam.probes.select_points`),
  and that attached point is followed: the shadow edge is the occluder's silhouette, so
  the rotation holds it still where it crosses the light (Sec. 4.1: a discontinuity must
  be followed, not dragged);
- all occluded: the mean attached hit of the occluded probes (the authors' rule);
- none occluded, the point or an emitter moving: the mean attached probe point on the
  emitters, so that the samples stay attached to a moving emitter (any rotation is exact
  for a continuous integrand; this one only lowers the variance);
- otherwise the identity. The emitters' own sharp edges are held fixed under any of these by
  :mod:`sphere3d.boundary.emitters`.

Near either side of a penumbra the shadow edge cuts a thin part off the light, hidden or
visible, which reaches the light's border: the probes along the edges find it where area
probes alone mostly miss it (a hidden fraction q escapes 4 of them with probability
$(1 - q)^4$). Closer still to the penumbra's outer lit edge, or to the umbra's, the part is
shorter along the border than the edge probes' spacing (perimeter / :data:`BOUNDARY`). Where the probes
found no pair, :data:`AIM` more probes join them (:func:`_aimed_points`): with none occluded,
the emitter points nearest in angle to the moving occluders' centre, where their shadow
first covers the light; with all occluded, the farthest, where the light is last covered. A
point whose probes already hold a pair is untouched (its numbers are bit-identical without
them); a point with no moving occluder (a moving light) gets none.

Bias
----
Measured at single ground points (x, y, 0) of the ``hard_shadow`` scenes (d/d
``occluder.translate.x``, fixed point and normal, :func:`sphere3d.irradiance`) against
``boundary`` (unbiased): a scan of x in steps of 0.01 across the whole penumbra (sphere
-0.34 to 1.13, cube -0.49 to 1.33) at y = -0.1 and y = 0.2, reparam seeds 1-4 × 32768
samples (± 0.3-0.5 % where the derivative is large), ``boundary`` seed 1 × 32768 (± < 0.1 %);
a point counts as biased beyond 3 standard errors. Per strategy against central differences
(h = 0.002) of the naive strategy's value at fixed samples (emitter strategy alone, 2 × 262144
samples; the cosine strategy as the rest), reparam 2 × 65536. Of the 331 points at y = -0.1,
29 were off by more than 10 % before the aimed probes, 10 with them and 8 edge probes, and 8
now (4 edge probes, :data:`BOUNDARY`); at y = 0.2 (b ≠ 0) 55, 29 and 28. Relative bias of the
total ("before": without the aimed probes; "8 edge": with them and 8 edge probes):

===========================  ==============  ===============  ==============  =========================
points (y = -0.1)            before          8 edge           now             cause of what remains
===========================  ==============  ===============  ==============  =========================
sphere, x = -0.34            -46 %           +13 %            +13 %           cosine (0.25 against 0.10)
sphere, 0.12 to 0.16         +9 to +39 %     -2 to -6 %       -1 to -6 %      not split
sphere, 0.48 to 0.51         +13 to -2 %     -10 to -8 %      -10 to -8 %     both strategies (below)
sphere, 0.52 to 1.03         -3 to -5.5 %    -3 to -5.5 %     -2 to -5 %      cosine 0.00 against -0.26
sphere, 1.10 to 1.13         -3 to -62 %     within ± 2 %     within ± 1.5 %
cube, -0.47 to -0.42         -57 to -11 %    +16 to +3 %      +16 to +3 %     emitter (1.56 against 1.45)
cube, -0.48                  -55 %           -55 %            -63 %           aimed probe beside the part
cube, -0.41 to -0.27         +2 to +4 %      +1 to +4 %       -2.5 to +1 %
cube, -0.17 to 0.01          +1 to +10 %     +1 to +10 %      +0.5 to +5 %    two silhouette edges
cube, 0.02                   +26 %           +26 %            +27 %           two silhouette edges
cube, 0.03 to 0.14           -2 to -8 %      -3 to -7.6 %     -3 to -5 %      cosine strategy
cube, 0.48 to 0.52           -7 to -13 %     -4 to -6 %       -4 to -6 %      emitter strategy
cube, 0.53 to 0.61           -4 to -7, +7 %  -4 to -7, +7 %   -2 to -6, +9 %  two silhouette edges
cube, 0.64 to 0.71           -2 to -4 %      -2 to -4 %       -3 to -5.5 %    cosine strategy, emitter
cube, 0.72 to 1.14           -2 to -7.6 %    -2 to -7.6 %     -1 to -5 %      cosine strategy, emitter
cube, 1.27 to 1.30           -13 to -48 %    within ± 1.5 %   within ± 1.2 %
cube, 1.31 to 1.33           -60 to -77 %    -60 to -77 %     -77 to -83 %    as at -0.48
===========================  ==============  ===============  ==============  =========================

At y = 0.2 the same kinds: the outer lit edges lost 10-76 % (sphere x = -0.33 to -0.29 and 1.07
to 1.13, cube -0.47 to -0.37 and 1.19 to 1.25), now +2 to +14 %; the sphere at x = -0.34 went
from -2.7 % to +89 % of a small derivative (0.14): the emitter strategy kept 0.005 of its
0.153 ± 0.013 and the cosine strategy's excess (0.13 against -0.01) hid it; now 0.130. Still
off by more than 10 %: sphere x = 0.29 to 0.39 and cube 0.30 to 0.38, where the derivative
changes sign (-94 to +54 % of 0.08-0.4 in absolute terms near the sign, -10 to -16 % beyond; with
8 edge probes sphere 0.29 to 0.41 and cube 0.30 to 0.35, the cube's 0.35 to 0.37 3-4 points
better), cube -0.14 and 0.44 (+12, +37 %; with 8 edge probes also -0.26 and -0.25, -10 %) and
the cube's outermost lit points -0.49, -0.48 (-50, -77 %). Beyond the penumbra's end at cube
x = 1.27 to 1.33, where ``boundary`` gives 0 (no probe direction meets the cube), reparam gives
-0.009 to -0.019, beyond 3 standard errors, with 8 or 4 edge probes (not isolated). Near the sign
change it is the emitter strategy (sphere x = 0.36: -0.99 against -1.11 ± 0.05; cube x = 0.33:
-1.32 against -1.71 ± 0.06; x = 0.44: -7.21 against -5.32 ± 0.08): there the shadow edge
crosses the light on both of its sides and one rotation follows one crossing (inferred from the
geometry, not isolated).

Where the emitter strategy is now within its noise, what remains is the **cosine strategy**:
its rotation follows the occluder where a kernel sees it in front of the light and drags the
light's edge, whose term no Leibniz term restores in that strategy; short by 20-100 % of its
share in the penumbra (sphere, x = 0.57: -0.01 against -0.26 ± 0.07 of a total -8.03), too
large at the outer lit edge (sphere, x = -0.34: 0.25 against 0.10 ± 0.04 of 1.57). Before, the
emitter strategy's errors partly hid it. At the sphere's umbra edge on the right (x = 0.49 to
0.51) the **emitter strategy** with the aimed probes is 4-6 % short (x = 0.50: -2.01 against
-2.12 ± 0.05, before -2.26; x = 0.51: -2.73 against -2.89 ± 0.06, before -2.92, worse),
likely because the followed silhouette point now lies next to the light's corner, at one end
of the arc that bounds the lit part, where one rotation matches the arc least (inferred, not
isolated; one far aimed point instead of two: -6.3 / -6.5 % in total at x = 0.50 / 0.51, and
the cube's x = 0.49-0.51 worse, -10 to -15 %). At the cube's outer lit edge it is too large
(x = -0.45: 1.56 against 1.45 ± 0.05, the cosine strategy 0.19 against 0.16 ± 0.05; not
isolated further), and where the cube's shadow edge is two edges at different depths
(x = -0.1: 8.04 against 7.62 ± 0.09; x = 0.01: 7.78 against 6.80 ± 0.08): one rotation follows
one of them. At the cube's outermost lit point (x = -0.48) the hidden part, 0.07 long on the
light's edge, lies 0.004 beside the nearest aimed point: 0.06 against 0.47 ± 0.03.

Probe counts
------------
Measured with the aimed probes (2 seeds × 65536, against ``boundary``): :data:`PROBES` = 2
leaves the penumbra's edges as they are and raises the cube corner (x = -0.05) from +6.6 % to
+11.6 % (with 8 edge probes). :data:`BOUNDARY` = 4 (8 shadow rays per point instead of 12) in
the full scan above against 8: the rms over each scan's points of the per-point bias (noise
subtracted) fell from 0.165 to 0.135 (sphere, y = -0.1), 0.186 to 0.151 (sphere, y = 0.2), 0.296 to
0.205 (cube, y = -0.1) and 0.265 to 0.224 (cube, y = 0.2); 87 points moved closer to ``boundary``
(beyond 3 standard errors of the difference and 3 % of the derivative: the cube corner, x = -0.14
to 0.01, from +3.6 to +8 % to +0.5 to +2.3 %, and x = 0.80 to 1.10, from -7 % to -3 %), 13 farther
(cube x = 0.65 to 0.71, -2.4 to -3.6 % to -4 to -5.5 %; its outermost lit points at y = -0.1,
-60 / -71 % to -77 / -82 %; at y = 0.2 x = 0.35 to 0.37 and 0.44 by 3-4 points). The edge probes
choose which pair of probes is closest, hence which silhouette point is followed; why fewer do
better on average is not isolated. :data:`AIM` = 1 misses the cube's outer lit edge at x = 1.3 (-47 %, as with
none) and is worse at cube x = 0.5 (-11.8 % against -4.2 %), but better at sphere x = 0.48
(-6.6 % against -13 %, the far side's second aimed point changing the followed point).

Cost: the aimed probes are traced only where no pair was found and, with none occluded, only
where the light reaches into the moving occluders' bounding cone: :data:`AIM` shadow rays per
such point plus the bisection where they find a pair. A render at 128 samples per pixel took
+2.5 % CPU (``hard_shadow``) and +6.8 % (``hard_shadow_cube``), medians of 6 interleaved runs;
a single point on the outer lit edge (sphere x = -0.34), where 63 % of the points lack a pair,
+60 %.
4 edge probes instead of 8: -8 % wall time for a 64 spp ``hard_shadow_cube`` image (0.477 to
0.440 s, best of 6 interleaved, 2 cores), -2 % for ``hard_shadow``. Points that cannot see a moving
occluder in front of the lights are not probed at all (:mod:`sphere3d.reparam.penumbra`).

Tested in ``tests/sphere3d/test_emitter_probes.py``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.dual import detach, tangent
from sphere3d.boundary.emitters import edge_points, edge_table
from sphere3d.live import any_rows, emitters_change, take_rows
from sphere3d.reparam.bisection import bisect_silhouette, closest_pair
from sphere3d.reparam.paper import direction_towards, mean_point_direction
from sphere3d.reparam.penumbra import bounding_sphere, may_see_motion, moving_occluders
from sphere3d.rotation import Rotation
from sphere3d.sampling import sample_mesh, triangle_barycentrics
from sphere3d.tracing import attached_points, intersect_triangles
from sphere3d.vector import dot, norm, zeros

__all__ = ["AIM", "BOUNDARY", "PROBES", "REFINE", "emitter_rotation"]

PROBES = 4
"""Shadow probes per shading point uniform on the emitters' area."""
BOUNDARY = 4
"""Shadow probes per shading point evenly spaced along the emitters' edges (random phase; 8 before,
module docstring, Probe counts)."""
REFINE = 6
"""Bisection rays between the occluded and the visible probe of a pair (to 1/64 of their gap)."""
AIM = 2
"""Aimed probes per shading point whose probes hold no pair of an occluded and a visible one: the
emitter points nearest to (none occluded) or farthest from (all occluded) the moving occluders'
centre in angle (:func:`_aimed_points`), where a thin hidden or lit part of the light appears
first; 0: none."""


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
    (:func:`~sphere3d.reparam.penumbra.bounding_sphere`), seen along the axis $a = (c - x) / |c - x|$. On an
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
    triangles = np.asarray(detach(state.triangles))
    centre, radius = bounding_sphere(triangles[moving])
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


def emitter_rotation(
    shading: Any, probes: int = PROBES, boundary: int = BOUNDARY, refine: int = REFINE, aim: int = AIM
) -> Rotation:
    """One rotation per shading point for the emitter strategy (module docstring).

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
        return Rotation.identity((m,))
    need = np.full(m, emitters_change(state)) | any_rows(tangent(shading.x) != 0.0)
    rest = np.flatnonzero(~need)  # the cull only where nothing else asks for probes
    need[rest] = may_see_motion(state, take_rows(detach(shading.x), rest))
    if need.all():
        return _probe_rotation(shading, probes, boundary, refine, aim)
    rows = np.flatnonzero(need)
    target, found = zeros((m, 3), True), np.zeros(m, dtype=bool)
    if rows.size:
        sub = _probe_rotation(shading.take(rows), probes, boundary, refine, aim, targets=True)
        target[rows], found[rows] = sub
    return Rotation.following(target, found)


def _probe_rotation(
    shading: Any, probes: int, boundary: int, refine: int, aim: int, targets: bool = False
) -> Any:
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
        i, j, _ = closest_pair(ws, occluded[s][:, :, None] & visible[s][:, None, :])
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
