"""Choosing the rotation by ray tracing: the probe heuristic of Loubet et al. 2019, Sec. 4.3.

Inside the support of an integrand a few probe rays (default 4) are traced, and one
point p is picked whose motion the rotation should follow. The probes form a
pattern (:func:`ring_directions`, :func:`ring_offsets`): probe 0 at the kernel's
centre, the others evenly spaced in azimuth (random phase) on a ring ``spread``
kernel standard deviations away. Probes drawn at random from the kernel itself
leave a discontinuity a kernel width away undetected too often: on a spherical cap
moving rigidly under a κ = 100 or 1000 kernel, random probes lost about a quarter of
the boundary term (0.057 ± 0.002 and 0.062 ± 0.003 against the exact 0.0787),
the ring with spread 3 did not (0.074 ± 0.003, 0.084 ± 0.005; 16 M samples each).
Then:

- pair probe 0 with the *last* probe that hits a different shape (a miss counts as
  its own "shape"); if there is none, probe 0 stands alone (always so with
  ``probes=1``: its hit point is followed, the identity where it misses; flatland's
  heuristic has an extra rule, the identity when every probe sees one primitive,
  which makes its single probe the identity everywhere);
- only one of the pair hits: its hit point, moved to the silhouette between the
  two probes by bisection (``refine`` rays, default :data:`REFINE`, the option
  ``refine`` of the ``reparam`` method; a refinement argued in :func:`select_points`);
- both hit: the tangent plane $(p_k, n_k)$ of one *occludes* the other when it
  separates that point from the ray origin o,
  $(n_0·(p_1 - p_0)) (n_0·(o - p_0)) < 0$; if exactly one occludes the other, the point
  on the occluder (moved to its silhouette in the same way);
- otherwise, nearly parallel normals ($|n_0·n_1| > 0.99$): p0;
- otherwise the intersection of the two tangent planes with the plane through o
  spanned by the two probe directions (where the two surfaces would meet between
  the probes: a silhouette or crease), falling back to p0 when that 3×3 system is
  degenerate; a departure from Sec. 4.3, argued in :func:`select_points`: the
  fallback also applies when the point does not lie in front of o;
- no probe hits: the identity.

The chosen point is *attached* (detached barycentrics on the θ-dependent vertices),
so it moves with its shape; its direction from the (possibly moving) origin gives
the rotation (:class:`~sphere3d.rotation.Rotation`). For emitter sampling the point
is instead the mean of the attached hits of the occluded shadow probes
(:func:`mean_point_direction`), one transform for all light samples of a point.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach
from sphere3d.bisection import bisect_silhouette
from sphere3d.rotation import Rotation
from sphere3d.snaps import Snap, line_spin
from sphere3d.state import SceneState
from sphere3d.tracing import Hits, attached_points, face_normals
from sphere3d.vector import cross, dot, frame, norm

__all__ = [
    "PARALLEL",
    "direction_towards",
    "follow_probes",
    "mean_point_direction",
    "pair_index",
    "ring_directions",
    "ring_offsets",
    "select_points",
    "vmf_spread_angle",
]

PARALLEL = 0.99
"""|n0·n1| above which the two tangent planes count as parallel (Loubet et al. 2019, Sec. 4.3)."""
DEGENERATE = 1e-6
"""|det| of the plane system below which the intersection is ill-conditioned."""
REFINE = 3
"""Default bisection rays that move a single probe's hit towards the silhouette next to it (3: to
1/8 of the gap); the default of the ``reparam`` option ``refine``."""


def vmf_spread_angle(kappa: float, spread: float) -> float:
    r"""Polar angle of the ring of probes: ``spread`` standard deviations of a $\mathrm{vMF}(κ)$ kernel.

    The angle r with $P(\mathrm{angle} ≤ r)$ equal to the Rayleigh probability $1 - e^{-\mathrm{spread}^2/2}$
    of ``spread`` σ (a vMF is a 2D Gaussian of $σ = 1/\sqrt{κ}$ for large κ): from the vMF's
    radial inverse CDF, $1 - \cos r = -\mathrm{log1p}(P\, \mathrm{expm1}(-2κ)) / κ$;
    $r ≈ \mathrm{spread} / \sqrt{κ}$.
    Defined for every spread >= 0: r grows from 0 to π (the ring closes on the
    antipode once the vMF's mass beyond the Rayleigh level is below $e^{-2κ}$).
    """
    tail = -0.5 * spread * spread  # log(1 - P), the Rayleigh tail beyond ``spread`` σ (-inf: none)
    level = -math.expm1(tail)
    x = level * math.expm1(-2.0 * kappa)
    if x > -0.5:
        s = -math.log1p(x) / kappa
    else:
        # 1 + x = e^tail + P e^{-2κ} rounds to 0 once both terms are below the float resolution
        # (spread >= 8.7 with κ >= 19): taken in log space instead of log1p(-1) = -inf
        s = -float(np.logaddexp(tail, -2.0 * kappa + math.log(level))) / kappa
    return math.acos(1.0 - min(2.0, max(s, 0.0)))


def ring_directions(centre: np.ndarray, angle: float, count: int, u: np.ndarray) -> np.ndarray:
    """``count`` probe directions around unit ``centre`` (m, 3): the centre, then a ring at ``angle``.

    Ring probes are evenly spaced in azimuth from the phase $2π u$ (m,). Returns (m, count, 3).
    """
    t, b = frame(centre)
    phi = 2.0 * np.pi * (u[:, None] + np.arange(count - 1)[None, :] / max(count - 1, 1))
    ring = math.cos(angle) * centre[:, None] + math.sin(angle) * (
        np.cos(phi)[..., None] * t[:, None] + np.sin(phi)[..., None] * b[:, None]
    )
    return np.concatenate([centre[:, None], ring], axis=1)


def ring_offsets(radius: float, count: int, u: np.ndarray) -> np.ndarray:
    """Film offsets (m, count, 2) in pixels: the pixel centre, then a ring of ``radius`` (phase $2π u$)."""
    phi = 2.0 * np.pi * (u[:, None] + np.arange(count - 1)[None, :] / max(count - 1, 1))
    out = np.zeros((len(u), count, 2))  # written in place: row 0 the centre, then radius (cos φ, sin φ)
    np.multiply(np.cos(phi), radius, out=out[:, 1:, 0])
    np.multiply(np.sin(phi), radius, out=out[:, 1:, 1])
    return out


def pair_index(shape: np.ndarray) -> np.ndarray:
    """Per row, the last probe whose shape differs from probe 0's (0 if none, as always with one probe).

    Parameters
    ----------
    shape : ndarray of int, shape (m, P)
        Hit shape per probe, -1 for a miss.
    """
    if shape.shape[1] < 2:  # a single probe has no partner: it stands alone (argmax of nothing fails)
        return np.zeros(shape.shape[0], dtype=np.intp)
    different = shape[:, 1:] != shape[:, :1]
    last = shape.shape[1] - 1 - np.argmax(different[:, ::-1], axis=1)
    return np.where(different.any(axis=1), last, 0)


def direction_towards(point: Any, origin: Any, found: np.ndarray) -> tuple[Any, np.ndarray]:
    """point - origin (Dual), and ``found`` cleared where its direction is undefined."""
    to = point - origin
    length = norm(detach(to))  # the value only
    return to, found & (length > 0.0) & np.isfinite(length)


def select_points(
    state: SceneState,
    origin: Any,
    trace_origin: np.ndarray,
    directions: np.ndarray,
    hits: Hits,
    normal: np.ndarray | None = None,
    refine: int = REFINE,
    snap: Snap | None = None,
) -> tuple[Any, np.ndarray]:
    """The point to follow per row of probes, and whether there is one (see the module docstring).

    Parameters
    ----------
    state : SceneState
        For the θ-dependent triangles and the tracer.
    origin : Dual or ndarray, shape (m, 3) or (3,)
        Probe ray origin (re-attached: it may move with θ).
    trace_origin : ndarray, shape (m, 3) or (3,)
        Where the probe rays were traced from (the detached origin, offset off a surface).
    directions : ndarray, shape (m, P, 3)
        Probe directions (θ-free).
    hits : Hits, shape (m, P)
        Their first hits; probes below a shading point's horizon must count as misses.
    normal : ndarray, shape (m, 3), optional
        The shading normal: bisection rays below the horizon count as misses too.
    refine : int, optional
        Bisection rays toward the silhouette per single-probe point (default
        :data:`REFINE`; 0: the probe's own hit).
    snap : callable, optional
        ``snap(rows, origin, inside, outside, hits) -> (u, v, lines)``: the barycentrics to follow
        on the bisected hits' triangles instead of the hits' own (rows: the rows of the
        single-probe points; the final bisection directions), and the edges through that
        point (:data:`Snap`, :func:`edge_snap`).

    Returns
    -------
    point : Dual, shape (m, 3)
    found : ndarray of bool, shape (m,)

    Notes
    -----
    Two refinements of Loubet et al. 2019, Sec. 4.3, both measured:

    - When the point comes from one probe of a pair whose other probe sees something
      else, that probe's hit is first moved towards the silhouette between the two
      by ``refine`` bisection rays (:func:`~sphere3d.bisection.bisect_silhouette`). A rotation that follows a
      point on a moving object matches the silhouette's motion only to first order
      in their distance, and the apparent motion of a translating object changes by
      about its own size per radian: following a ring probe's hit, up to $3 σ$ inside
      the shape, cost 14 % of the boundary term under a translating triangle
      ($κ = 1000$; -0.0106 ± 0.0002 of 0.077, the difference of 12 M paired samples).
    - The plane-intersection point is replaced by p0 when it lies behind the
      origin: a tangent-plane line crossing the probe plane behind o says nothing
      about the silhouette between the two probes, and its direction would be
      reversed.
    """
    point, found, _ = _choose(state, origin, trace_origin, directions, hits, normal, refine, snap)
    return point, found


def _choose(
    state: SceneState,
    origin: Any,
    trace_origin: np.ndarray,
    directions: np.ndarray,
    hits: Hits,
    normal: np.ndarray | None,
    refine: int,
    snap: Snap | None,
) -> tuple[Any, np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray] | None]:
    """:func:`select_points`, and for the snapped rows (rows, their triangles, the edges through their
    points: :data:`Snap`), None without a snap."""
    m = directions.shape[0]
    rows = np.arange(m)
    j = pair_index(hits.shape)
    hit0 = hits.shape[:, 0] >= 0
    hit1 = (hits.shape[rows, j] >= 0) & (j != 0)
    d0, d1 = directions[:, 0], directions[rows, j]
    h0, h1 = hits.take((rows, 0)), hits.take((rows, j))
    t0 = state.triangles[np.maximum(h0.triangle, 0)]
    t1 = state.triangles[np.maximum(h1.triangle, 0)]
    p0 = attached_points(t0, h0.u, h0.v)
    p1 = attached_points(t1, h1.u, h1.v)
    # the normals' values for every row; their tangents only where the crossing is used (below)
    n0v, n1v = face_normals(detach(t0)), face_normals(detach(t1))
    o = origin + 0.0 * p0  # broadcast to (m, 3)
    p0v, p1v, ov = detach(p0), detach(p1), detach(o)
    # tangent plane k separates the other hit from the origin: shape k occludes the other   (Sec. 4.3)
    occ0 = dot(n0v, p1v - p0v) * dot(n0v, ov - p0v) < 0.0
    occ1 = dot(n1v, p0v - p1v) * dot(n1v, ov - p1v) < 0.0
    parallel = np.abs(dot(n0v, n1v)) > PARALLEL
    # the two tangent planes and the plane through o spanned by the probe directions:
    # x = (h0 (n1 × m) + h1 (m × n0) + h2 (n0 × n1)) / (n0 · (n1 × m)),  h_k = n_k · p_k, h2 = m · o
    mv = cross(d0, d1)
    m_len = norm(mv)
    mv = mv / np.where(m_len > 0.0, m_len, 1.0)[:, None]

    def crossing_of(n0, n1, p0, p1, o, mv):  # the same expression on values (all rows) and Duals (used rows)
        n1xm = cross(n1, mv)
        det = dot(n0, n1xm)
        safe_det = np.where(np.abs(detach(det)) > DEGENERATE, det, 1.0)
        return (dot(n0, p0)[:, None] * n1xm + dot(n1, p1)[:, None] * cross(mv, n0)
                + dot(mv, o)[:, None] * cross(n0, n1)) / safe_det[:, None], det  # fmt: skip

    crossing, det = crossing_of(n0v, n1v, p0v, p1v, ov, mv)
    ok = (np.abs(det) > DEGENERATE) & (m_len > 1e-12)
    ok = ok & (dot(crossing - ov, d0 + d1) > 0.0)

    both = hit0 & hit1
    use_cross = both & ~(occ0 ^ occ1) & ~parallel & ok
    use_p1 = (hit1 & ~hit0) | (both & occ1 & ~occ0)
    use_p0 = hit0 & ~use_p1 & ~use_cross
    # a single probe's point with a partner that sees something else: move it to the silhouette
    single = np.flatnonzero((use_p0 | use_p1) & (j != 0))
    snapped = None
    if single.size and refine:
        first = use_p0[single]
        first3 = np.repeat(first[:, None], 3, axis=1)  # contiguous masks: np.where is faster with them
        inside = np.where(first3, d0[single], d1[single])
        outside = np.where(first3, d1[single], d0[single])
        start = h0.take(single).where(first, h1.take(single))
        tro = np.broadcast_to(trace_origin, (m, 3))[single]
        nrm = None if normal is None else np.broadcast_to(normal, (m, 3))[single]
        edge, inside, outside = bisect_silhouette(state, tro, inside, outside, start, nrm, refine)
        if snap is None:
            u, v = edge.u, edge.v
        else:
            u, v, lines = snap(single, tro, inside, outside, edge)
            snapped = (single, edge.triangle, lines)
        moved = attached_points(state.triangles[edge.triangle], u, v)
        p0[single] = np.where(first3, moved, p0[single])
        p1[single] = np.where(first3, p1[single], moved)
    point = np.where(np.repeat(use_p1[:, None], 3, axis=1), p1, p0)
    c = np.flatnonzero(use_cross)
    if c.size:  # with tangents only where the crossing is used (row by row the same numbers)
        point[c] = crossing_of(face_normals(t0[c]), face_normals(t1[c]), p0[c], p1[c], o[c], mv[c])[0]
    return point, hit0 | hit1, snapped


def follow_probes(
    state: SceneState,
    origin: Any,
    trace_origin: np.ndarray,
    directions: np.ndarray,
    hits: Hits,
    normal: np.ndarray | None = None,
    refine: int = REFINE,
    snap: Snap | None = None,
    spin: tuple[np.ndarray, float] | None = None,
) -> Rotation:
    """The rotation following the point chosen by :func:`select_points` (identity where none).

    With ``spin`` = (kernel centres (m, 3), kernel σ in radians) and a ``snap``, where the point
    was snapped onto an edge the rotation also turns about it so that the edge's great circle
    follows its own (:func:`~sphere3d.snaps.line_spin`); at a corner, by its two edges' rates
    weighted by the kernel.
    """
    point, found, snapped = _choose(state, origin, trace_origin, directions, hits, normal, refine, snap)
    to, found = direction_towards(point, origin, found)
    if spin is None or snapped is None:
        return Rotation.following(to, found)
    rows, triangle, lines = snapped
    turn = np.zeros(len(found))
    ok = lines[:, 0, 0] >= 0
    if ok.any():
        r = rows[ok]
        o = origin if np.ndim(detach(origin)) == 1 else origin[r]
        turn[r] = line_spin(state.triangles[triangle[ok]], o, point[r], lines[ok], spin[0][r], spin[1])
    return Rotation.following(to, found, Dual(np.zeros(len(found)), turn))


def mean_point_direction(origin: Any, points: Any, mask: np.ndarray) -> tuple[Any, np.ndarray]:
    """Direction (not normalized) from ``origin`` to the mean of the attached ``points`` where ``mask``.

    Parameters
    ----------
    origin : Dual, shape (m, 3)
        The shading points.
    points : Dual, shape (m, P, 3)
        Attached points, one per probe.
    mask : ndarray of bool, shape (m, P)
        Which probes count.

    Returns
    -------
    direction : Dual, shape (m, 3)
        For :meth:`Rotation.following`.
    found : ndarray of bool, shape (m,)
        False where no probe counts (the rotation is then the identity).
    """
    count = mask.sum(axis=1)
    total = np.einsum("mpk,mp->mk", points, mask.astype(np.float64))
    return direction_towards(total / np.maximum(count, 1)[:, None], origin, count > 0)
