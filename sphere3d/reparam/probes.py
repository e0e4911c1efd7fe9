r"""The probe heuristic as the default variant runs it: probes on a ring, hits moved to the silhouette.

The rule that picks the point a rotation follows is the paper's (Loubet et al. 2019, Sec. 4.3,
:func:`~sphere3d.reparam.paper.choose`). Two extensions change what it is given and what it
returns (theory page *extensions*):

- **a ring of probes** (:func:`ring_directions`, :func:`ring_offsets`): probe 0 at the kernel's
  centre, the others evenly spaced in azimuth (random phase) ``spread`` kernel standard
  deviations away, instead of probes drawn at random from the kernel. A ring of n probes at
  radius r finds every straight edge within $r \cos(π/n)$ of the centre; random probes leave
  a discontinuity a kernel width away undetected with a probability that does not shrink;
- **bisection to the silhouette** (``refine``, :func:`select_points`): where the rule follows
  one probe's hit while its partner sees something else, that hit is moved toward the
  silhouette between the two (:mod:`sphere3d.reparam.bisection`), optionally snapped onto the
  hit triangle's edge or corner and the rotation turned with that edge
  (:mod:`sphere3d.reparam.snaps`, :func:`follow_probes`).

The chosen point is attached (detached barycentrics on the θ-dependent vertices), so it moves
with its shape; its direction from the (possibly moving) origin gives the rotation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach
from sphere3d.reparam.bisection import bisect_silhouette
from sphere3d.reparam.paper import choose, direction_towards
from sphere3d.reparam.snaps import Snap, line_spin
from sphere3d.rotation import Rotation
from sphere3d.state import SceneState
from sphere3d.tracing import Hits, attached_points
from sphere3d.vector import frame

__all__ = [
    "REFINE",
    "Followed",
    "follow_probes",
    "ring_directions",
    "ring_offsets",
    "select_points",
    "vmf_spread_angle",
]

REFINE = 3
"""Default bisection rays that move a single probe's hit towards the silhouette next to it (3: to
1/8 of the gap); the default of the ``reparam`` option ``refine``."""


def vmf_spread_angle(kappa: float | np.ndarray, spread: float) -> float | np.ndarray:
    r"""Polar angle of the ring of probes: ``spread`` standard deviations of a $\mathrm{vMF}(κ)$ kernel.

    The angle r with $P(\mathrm{angle} ≤ r)$ equal to the Rayleigh probability $1 - e^{-\mathrm{spread}^2/2}$
    of ``spread`` σ (a vMF is a 2D Gaussian of $σ = 1/\sqrt{κ}$ for large κ): from the vMF's
    radial inverse CDF, $1 - \cos r = -\mathrm{log1p}(P\, \mathrm{expm1}(-2κ)) / κ$;
    $r ≈ \mathrm{spread} / \sqrt{κ}$.
    Defined for every spread >= 0: r grows from 0 to π (the ring closes on the
    antipode once the vMF's mass beyond the Rayleigh level is below $e^{-2κ}$). ``kappa`` may be
    an array (a kernel per point): the same formula element by element.
    """
    if np.ndim(kappa) != 0:
        return _spread_angles(np.asarray(kappa, dtype=np.float64), spread)
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


def _spread_angles(kappa: np.ndarray, spread: float) -> np.ndarray:
    """:func:`vmf_spread_angle` element by element over an array of concentrations (its two branches)."""
    tail = -0.5 * spread * spread
    level = -math.expm1(tail)
    x = level * np.expm1(-2.0 * kappa)
    with np.errstate(divide="ignore"):
        logged = -np.logaddexp(tail, -2.0 * kappa + (math.log(level) if level > 0.0 else -np.inf)) / kappa
    s = np.where(x > -0.5, -np.log1p(np.maximum(x, -0.5)) / kappa, logged)
    return np.arccos(1.0 - np.clip(s, 0.0, 2.0))


def ring_directions(centre: np.ndarray, angle: float | np.ndarray, count: int, u: np.ndarray) -> np.ndarray:
    """``count`` probe directions around unit ``centre`` (m, 3): the centre, then a ring at ``angle``
    (radians; one, or one per row).

    Ring probes are evenly spaced in azimuth from the phase $2π u$ (m,). Returns (m, count, 3).
    """
    t, b = frame(centre)
    phi = 2.0 * np.pi * (u[:, None] + np.arange(count - 1)[None, :] / max(count - 1, 1))
    if np.ndim(angle) == 0:
        cos_r, sin_r = math.cos(angle), math.sin(angle)
    else:
        cos_r, sin_r = np.cos(angle)[:, None, None], np.sin(angle)[:, None, None]
    ring = cos_r * centre[:, None] + sin_r * (
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
    """The point to follow per row of probes, and whether there is one: the rule of
    :func:`~sphere3d.reparam.paper.choose`, its single-probe points moved to the silhouette.

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
    normal : ndarray, shape (m, 3) or (m, 2, 3), optional
        The shading normal (and the face's): bisection rays below the horizon (or below either
        plane) count as misses too.
    refine : int, optional
        Bisection rays toward the silhouette per single-probe point (default
        :data:`REFINE`; 0: the probe's own hit, the paper's rule).
    snap : callable, optional
        ``snap(rows, origin, inside, outside, hits) -> (triangle, u, v, lines)``: the triangles and
        barycentrics to follow instead of the bisected hits' own (rows: the rows of the
        single-probe points; the final bisection directions), and the edges through that
        point (:data:`~sphere3d.reparam.snaps.Snap`, :func:`~sphere3d.reparam.snaps.edge_snap`).

    Returns
    -------
    point : Dual, shape (m, 3)
    found : ndarray of bool, shape (m,)

    Notes
    -----
    Where the point comes from one probe of a pair whose other probe sees something else,
    that probe's hit is first moved towards the silhouette between the two by ``refine``
    bisection rays (:func:`~sphere3d.reparam.bisection.bisect_silhouette`). A rotation that
    follows a point on a moving object matches the silhouette's motion only to first order in
    their distance, and the apparent motion of a translating object changes by about its own
    size per radian (theory page *extensions*).
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
    points: :data:`~sphere3d.reparam.snaps.Snap`), None without a snap."""
    choice = choose(state, origin, directions, hits)
    single, m = choice.single, directions.shape[0]
    snapped = None
    if single.size and refine:  # a single probe's point with a partner that sees something else
        first3 = np.repeat(choice.first[:, None], 3, axis=1)  # contiguous masks: np.where is faster
        inside = np.where(first3, choice.d0[single], choice.d1[single])
        outside = np.where(first3, choice.d1[single], choice.d0[single])
        start = choice.h0.take(single).where(choice.first, choice.h1.take(single))
        tro = np.broadcast_to(trace_origin, (m, 3))[single]
        nrm = (
            None
            if normal is None
            else np.broadcast_to(normal, (m, *np.shape(normal)[-1 - (np.ndim(normal) > 2) :]))[single]
        )
        edge, inside, outside = bisect_silhouette(state, tro, inside, outside, start, nrm, refine)
        if snap is None:
            triangle, u, v = edge.triangle, edge.u, edge.v
        else:
            triangle, u, v, lines = snap(single, tro, inside, outside, edge)
            snapped = (single, triangle, lines)
        moved = attached_points(state.triangles[triangle], u, v)
        choice.p0[single] = np.where(first3, moved, choice.p0[single])
        choice.p1[single] = np.where(first3, choice.p1[single], moved)
    return choice.point(), choice.found, snapped


@dataclass(frozen=True)
class Followed:
    """The rotation of :func:`follow_probes`, and the edges it follows: ``snapped`` = (rows, their hit
    triangles, the edges through the followed points as vertex slots (rows, 2, 2), -1: none), None
    without a snap or a snapped row (:data:`~sphere3d.reparam.snaps.Snap`)."""

    rotation: Rotation
    snapped: tuple[np.ndarray, np.ndarray, np.ndarray] | None


def follow_probes(
    state: SceneState,
    origin: Any,
    trace_origin: np.ndarray,
    directions: np.ndarray,
    hits: Hits,
    normal: np.ndarray | None = None,
    refine: int = REFINE,
    snap: Snap | None = None,
    spin: tuple[np.ndarray, float | np.ndarray] | None = None,
) -> Followed:
    """The rotation following the point chosen by :func:`select_points` (identity where none), and the
    edges it follows (:class:`Followed`).

    With ``spin`` = (kernel centres (m, 3), kernel σ in radians: one, or one per row) and a ``snap``,
    where the point was snapped onto an edge the rotation also turns about it so that the edge's great circle
    follows its own (:func:`~sphere3d.reparam.snaps.line_spin`); at a corner, by its two edges' rates
    weighted by the kernel.
    """
    point, found, snapped = _choose(state, origin, trace_origin, directions, hits, normal, refine, snap)
    to, found = direction_towards(point, origin, found)
    if spin is None or snapped is None:
        return Followed(Rotation.following(to, found), snapped)
    rows, triangle, lines = snapped
    k = state.k  # None, or k parameters: a turn rate for each
    turn = np.zeros(len(found) if k is None else (k, len(found)))
    ok = lines[:, 0, 0] >= 0
    if ok.any():
        r = rows[ok]
        o = origin if np.ndim(detach(origin)) == 1 else origin[r]
        sigma = spin[1] if np.ndim(spin[1]) == 0 else spin[1][r]
        rate = line_spin(state.triangles[triangle[ok]], o, point[r], lines[ok], spin[0][r], sigma)
        turn[..., r] = rate
    return Followed(Rotation.following(to, found, Dual(np.zeros(len(found)), turn, k)), snapped)
