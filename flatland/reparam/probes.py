"""Choosing the point a reparameterization follows, from probe rays (Loubet et al. 2019, Sec. 4.3).

Where the integrator calls it: not directly. :class:`~flatland.reparam.default.ReparamTransforms`
calls :func:`select_points` from its ``camera`` and ``directions`` transforms, once per chunk
of samples, after tracing the probes and before forming the evaluation points.

The 2D form of the probe heuristic of Loubet et al. 2019, Sec. 4.3. Per sample, a few probe
rays are traced inside the kernel's support from the integral's origin o (the camera, or a shading point), in
angular (film) order:

- probe 0 is paired with the *last* probe that hits a different shape (a miss
  counts as "no shape"); without such a probe, probe 0's hit is used;
- if only one of the pair hits, its hit point is used;
- if both hit, the tangent line (p0, n0) *occludes* p1 when it separates p1 from o:
  $(n_0·(p_1 − p_0)) (n_0·(o − p_0)) < 0$, and likewise for (p1, n1); if exactly one
  occludes the other, the point on the occluder is used;
- otherwise, nearly parallel normals ($|n_0·n_1| > 0.99$) use p0, and else the two
  tangent lines are intersected (a corner where two shapes meet), falling back to
  p0 when they are parallel or the intersection lies behind o;
- no probe hits: no point, the transform is the identity.

Refinements, each measured to matter in flatland and each keeping the choice
θ-free (all of it is made on values, so it stays a valid change of variables):

- *Nothing to follow.* When every probe hits the same primitive (or none hits),
  no discontinuity is in sight and the transform is the identity. Following the
  hit point anyway is unbiased too, but it adds the kernel weight's derivative
  (variance) everywhere a surface moves in the image, e.g. everywhere for a moving
  camera.
- *The hit next to the switch.* When one shape is followed, the hit used is the one
  on that shape adjacent (in probe order) to a probe that sees something else: the
  probe hit nearest the discontinuity the probes bracket. An attached point moves
  like the silhouette only to first order in its distance from it (exactly, under
  translation), so under rotation or vertex motion the far hits are biased.
- *Bisection* (``refine`` steps): the bracket between that hit and its neighbour is
  halved by tracing its midpoint, moving the followed point toward the
  discontinuity; each step costs one ray per sample that has a bracket.
- *A primitive between two probes* (:func:`film_gap_probe`, :func:`angle_gap_probe`): a
  segment or circle whose whole image lies between two neighbouring probes (narrower
  than their spacing: 0.57 px on the film, 0.063 rad for directions at the defaults) is
  seen by none, and the identity would drop both its edges' terms (measured on the
  film: 1 - width / spacing of them, 83 % at 0.1 px). Where the probes chose nothing,
  one more probe is traced at the middle of such a primitive's image (the one nearest
  the kernel centre) and the choice is made again with it.
- *The silhouette's end* (:func:`film_shape_end`, :func:`angle_shape_end`): a shape of
  segments has its silhouette ends at its extreme endpoints' images (film coordinates, or
  angles from the shading point). Where the probes follow a shape next to a switch to another
  and one end of its image lies inside their span, that endpoint is followed instead of the hit
  next to the switch: it moves like the silhouette under every motion, where the attached hit
  does only under translation (measured on the film: 7-16 % of a turning, receding or
  one-end-moved 2-8 px segment's derivative lost).
- *A shape inside the span* (:func:`film_inner_shape`, :func:`angle_inner_shape`): a shape
  whose whole image lies between the first and the last probe has both silhouette ends there.
  The transform then follows both at once by a piecewise-linear map (``_stretch`` in
  :mod:`flatland.reparam.default`), whatever the probes chose: one followed point moves like
  both ends only under translation, and a thin stick turning or scaling about its middle has
  ends moving apart about a middle that stands still (measured: 94-100 % of a 0.2 px stick's
  film derivative, 50-100 % of a 0.01-0.1 rad stick's irradiance derivative lost, the middle
  followed). Circles are left to the probes.

The chosen point is *attached* (:func:`flatland.tracing.attached_points`): it moves
with its shape, and the intersection of two tangent lines is recomputed from the
attached points and normals, so its derivative is the corner's.

Known failure (kept, it is the heuristic's): the occlusion test treats each tangent
line as an infinite surface, so a small blocker whose edge line happens to separate
an emitter from o is taken to occlude it; when the emitter's edge is a discontinuity
(an unfaded emitter) and the blocker moves, that edge is then treated as moving.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import detach
from flatland.sampling import wrap_angle
from flatland.state import SceneState
from flatland.tracing import attached_points, zeros

__all__ = [
    "PARALLEL",
    "Choice",
    "ShapeImage",
    "ShapeImages",
    "Sight",
    "angle_gap_probe",
    "angle_images",
    "angle_inner_shape",
    "angle_shape_end",
    "angle_sight",
    "film_gap_probe",
    "film_images",
    "film_inner_shape",
    "film_shape_end",
    "inner_shape",
    "select_points",
    "shape_end",
]

PARALLEL = 0.99
"""|n0·n1| above which two tangent lines count as parallel (Loubet et al. 2019, Sec. 4.3)."""


@dataclass(frozen=True)
class Choice:
    """Per sample: which rule chose the point (``code``) and the attached point (Dual, (n, 2))."""

    point: Any
    code: np.ndarray  # -1 none, 0 probe 0's point, 1 the partner's point, 2 tangent-line intersection
    followed: np.ndarray | None = None
    """The primitive of the followed point where one shape is followed next to a switch to another
    shape (or to nothing), else -1; None: not recorded."""

    @property
    def ok(self) -> np.ndarray:
        """Whether a point was chosen (else the transform is the identity)."""
        return self.code >= 0

    @property
    def followed_prim(self) -> np.ndarray:
        """:attr:`followed`, -1 throughout where it was not recorded."""
        return np.full(len(self.code), -1) if self.followed is None else self.followed


def _dot(a: Any, b: Any) -> Any:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def _nearest_switch(shape: np.ndarray, chosen: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row, the probe on ``chosen``'s shape that sits next to a probe on another shape.

    Probes are in angular (film) order. Returns that probe's index (``chosen`` itself
    where every probe sees the same shape) and its neighbour across the switch (-1
    where there is none).
    """
    n, n_probes = shape.shape
    rows = np.arange(n)
    same = shape == shape[rows, chosen][:, None]
    best, across = chosen.copy(), np.full(n, -1)
    dist = np.full(n, n_probes + 1)
    for k in range(n_probes):  # a handful of probes, each vectorized over the rows
        for nb in (k - 1, k + 1):
            if 0 <= nb < n_probes:
                ok = same[:, k] & ~same[:, nb]
                closer = ok & (np.abs(k - chosen) < dist)
                best = np.where(closer, k, best)
                across = np.where(closer, nb, across)
                dist = np.where(closer, np.abs(k - chosen), dist)
    return best, across


Tracer = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def select_points(
    geom: SceneState,
    origins: np.ndarray,
    prim: np.ndarray,
    coord: np.ndarray,
    dirs0: np.ndarray,
    probe_params: np.ndarray | None = None,
    trace: Tracer | None = None,
    refine: int = 0,
) -> Choice:
    """Apply the heuristic to probe hits ``prim``/``coord`` of shape (n, P) from ``origins`` (n, 2).

    ``dirs0`` (n, 2) is a direction inside the kernel's support (the kernel centre),
    used to reject tangent-line intersections behind the origin. Probes must be in
    angular (or film) order. When one shape is to be followed, the hit used is the
    one on that shape *next to the switch* to another shape, the nearest probe to the
    discontinuity the probes bracket; with ``refine`` > 0 the bracket is bisected
    that many times (``trace(rows, params) -> (prim, coord)`` traces probes at the
    parameters ``params`` (film coordinates or angles, like ``probe_params``)).
    """
    n, n_probes = prim.shape
    rows = np.arange(n)
    shape = np.where(prim >= 0, geom.prim_shape[np.maximum(prim, 0)], -1)
    differs = shape != shape[:, :1]
    has_partner = differs.any(axis=1)
    # index of the last probe whose shape differs from probe 0's
    partner = np.where(has_partner, n_probes - 1 - np.argmax(differs[:, ::-1], axis=1), 0)
    prim0, coord0 = prim[:, 0], coord[:, 0]
    prim1, coord1 = prim[rows, partner], coord[rows, partner]
    hit0, hit1 = prim0 >= 0, (prim1 >= 0) & has_partner

    # every probe on one primitive (or none hits): nothing in sight to follow, the identity
    uniform = np.all(prim == prim[:, :1], axis=1)
    code = np.full(n, -1)
    code[hit0 & ~hit1 & ~uniform] = 0
    code[~hit0 & hit1] = 1
    both = np.flatnonzero(hit0 & hit1)
    if both.size:
        geom0 = geom.detached()  # the choice is made on values only
        p0, n0 = attached_points(geom0, prim0[both], coord0[both])
        p1, n1 = attached_points(geom0, prim1[both], coord1[both])
        o = origins[both]
        occludes01 = _dot(n0, p1 - p0) * _dot(n0, o - p0) < 0.0  # line 0 separates p1 from o
        occludes10 = _dot(n1, p0 - p1) * _dot(n1, o - p1) < 0.0
        sub = np.where(occludes01 & ~occludes10, 0, np.where(occludes10 & ~occludes01, 1, 2))
        parallel = np.abs(_dot(n0, n1)) > PARALLEL
        sub = np.where((sub == 2) & parallel, 0, sub)
        # the corner: p0 + s e0 on line 0 with (p0 + s e0 - p1)·n1 = 0, e0 = n0 turned by 90 degrees
        e0 = np.stack([-n0[:, 1], n0[:, 0]], axis=1)
        den = _dot(e0, n1)
        with np.errstate(divide="ignore", invalid="ignore"):  # parallel lines: q not finite, rejected below
            q = p0 + (_dot(p1 - p0, n1) / den)[:, None] * e0
            ahead = _dot(q - o, dirs0[both]) > 0.0
        sub = np.where((sub == 2) & ~(np.isfinite(q).all(axis=1) & ahead), 0, sub)
        code[both] = sub

    # one shape to follow: use its hit next to the switch (nearest the discontinuity), refined by bisection
    single = np.flatnonzero((code == 0) | (code == 1))
    chosen = np.where(code == 1, partner, 0)
    # switch between shapes, or between primitives of one shape (a polygon's faces) without a partner
    key = np.where(has_partner[single][:, None], shape[single], prim[single])
    best, across = _nearest_switch(key, chosen[single])
    prim_f, coord_f = prim[single, best].copy(), coord[single, best].copy()
    followed = np.full(n, -1)
    if refine and trace is not None and probe_params is not None:
        live = np.flatnonzero(across >= 0)
        r = single[live]
        lo = probe_params[r, best[live]]  # on the followed shape
        hi = probe_params[r, across[live]]  # on another shape (or nothing)
        by_shape = has_partner[r]
        target = key[live, best[live]]
        for _ in range(refine):
            mid = 0.5 * (lo + hi)
            p_mid, c_mid = trace(r, mid)
            on = (
                np.where(by_shape, np.where(p_mid >= 0, geom.prim_shape[np.maximum(p_mid, 0)], -1), p_mid)
                == target
            )
            prim_f[live] = np.where(on, p_mid, prim_f[live])
            coord_f[live] = np.where(on, c_mid, coord_f[live])
            lo, hi = np.where(on, mid, lo), np.where(on, hi, mid)

    point = zeros((n, 2), geom.differentiable, geom.k)
    if single.size:
        point[single] = attached_points(geom, prim_f, coord_f, normals=False)[0]
    corner = np.flatnonzero(code == 2)
    if corner.size:
        p0, n0 = attached_points(geom, prim0[corner], coord0[corner])
        p1, n1 = attached_points(geom, prim1[corner], coord1[corner])
        e0 = np.stack([-n0[:, 1], n0[:, 0]], axis=1)
        # attached corner: its derivative follows both moving tangent lines
        point[corner] = p0 + (_dot(p1 - p0, n1) / _dot(e0, n1))[:, None] * e0
    followed[single] = np.where(has_partner[single], prim_f, -1)  # after bisection: same shape
    return Choice(point, code, followed)


def _gap_probe(lo: np.ndarray, hi: np.ndarray, probes: np.ndarray) -> np.ndarray:
    """Per row, the middle (clipped to the probes' span) of the interval [lo, hi] (rows × primitives,
    NaN: none) that overlaps the span and holds no probe, the one nearest the span's centre; else NaN."""
    if not lo.size:
        return np.full(len(probes), np.nan)
    first, last = probes[:, :1], probes[:, -1:]
    with np.errstate(invalid="ignore"):  # NaN bounds (no interval) compare False
        gap = (hi > first) & (lo < last)
        for k in range(probes.shape[1]):  # a handful of probes, each over rows × primitives: none inside
            p = probes[:, k : k + 1]
            gap &= ~((p >= lo) & (p <= hi))
    mid = 0.5 * (np.maximum(lo, first) + np.minimum(hi, last))
    dist = np.where(gap, np.abs(mid - 0.5 * (first + last)), np.inf)
    rows, best = np.arange(len(probes)), np.argmin(dist, axis=1)
    return np.where(np.isfinite(dist[rows, best]), mid[rows, best], np.nan)


def _circle_tangents(c: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The two tangent directions cos α u ± sin α n (sin α = r / |c|) from the origin to circles at
    ``c`` (..., 2), and whether the origin lies outside each circle."""
    dist = np.hypot(c[..., 0], c[..., 1])
    outside = dist > radius
    sin_a = np.where(outside, radius / np.where(outside, dist, 1.0), 0.0)
    cos_a = np.sqrt(1.0 - sin_a**2)
    u = c / np.where(dist > 0.0, dist, 1.0)[..., None]
    normal = np.stack([-u[..., 1], u[..., 0]], axis=-1)
    return (
        cos_a[..., None] * u + sin_a[..., None] * normal,
        cos_a[..., None] * u - sin_a[..., None] * normal,
        outside,
    )


def film_gap_probe(geom: SceneState, probes: np.ndarray) -> np.ndarray:
    """Per row, a film coordinate inside a primitive's image that lies wholly between two probes.

    Film coordinates (θ-free, from the detached ``geom``) of every segment's endpoints and
    every circle's two tangent directions give each primitive's image [lo, hi] on the
    film (primitives reaching behind the camera are skipped: their image is not thin).
    A row's candidate overlaps the probes' span [probes[0], probes[-1]] and contains no
    probe; the one whose middle is nearest the span's centre is returned, its middle
    clipped to the span. NaN where a row has none.

    Parameters
    ----------
    geom : SceneState
        The scene (values only).
    probes : ndarray, shape (n, P)
        The rows' probe film coordinates, in film order.

    Returns
    -------
    ndarray, shape (n,)
    """
    o, f, r = (np.asarray(detach(v), dtype=np.float64) for v in (geom.cam_o, geom.cam_f, geom.cam_r))
    plus, minus, outside = _circle_tangents(
        np.asarray(detach(geom.circ_c)) - o, np.asarray(detach(geom.circ_r))
    )
    a = np.concatenate([np.asarray(detach(geom.seg_a)) - o, plus])
    b = np.concatenate([np.asarray(detach(geom.seg_b)) - o, minus])
    depth_a, depth_b = a @ f, b @ f
    ahead = (depth_a > 0.0) & (depth_b > 0.0) & np.concatenate([np.ones(geom.n_seg, bool), outside])
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (a @ r) / depth_a, (b @ r) / depth_b
    lo, hi = np.minimum(ta, tb)[ahead], np.maximum(ta, tb)[ahead]
    return _gap_probe(
        np.broadcast_to(lo, (len(probes), lo.size)), np.broadcast_to(hi, (len(probes), hi.size)), probes
    )


def angle_gap_probe(
    geom: SceneState, x: np.ndarray, ignore: np.ndarray, probes: np.ndarray, sight: Sight | None = None
) -> np.ndarray:
    """Per row, an angle inside a primitive's image seen from ``x`` that lies wholly between two probes.

    The angular form of :func:`film_gap_probe` for the shading integral: each primitive's
    image from the row's point x is the interval between its endpoints' (a circle's
    tangents') angles, taken relative to the probes' centre in (-π, π]; primitives seen
    under π or more (x on or inside them) and the row's own primitive ``ignore`` are skipped.

    Parameters
    ----------
    geom : SceneState
        The scene (values only).
    x : ndarray, shape (n, 2)
        The shading points.
    ignore : ndarray of int, shape (n,)
        The primitive each row's point lies on (-1: none).
    probes : ndarray, shape (n, P)
        The rows' probe angles, in increasing order.
    sight : Sight, optional
        :func:`angle_sight` of these rows, when already computed (the segments' angles are taken
        from it, the same numbers).

    Returns
    -------
    ndarray, shape (n,)
        An angle (on the probes' branch), or NaN.
    """
    sight = angle_sight(geom, x, ignore, probes) if sight is None else sight
    centre, n_seg = sight.centre, geom.n_seg
    plus, minus, outside = _circle_tangents(
        np.asarray(detach(geom.circ_c))[None] - x[:, None], np.asarray(detach(geom.circ_r))
    )
    # segments' ends from the sight (its rel is [ends of seg_a, ends of seg_b]), then the circles' tangents
    rel_a, rel_b = (
        np.concatenate([seg, wrap_angle(np.arctan2(v[..., 1], v[..., 0]) - centre)], axis=1)
        for seg, v in ((sight.rel[:, :n_seg], plus), (sight.rel[:, n_seg:], minus))
    )  # [-π, π)
    ok = np.abs(rel_a - rel_b) < np.pi - 1e-9
    ok[:, n_seg:] &= outside
    ok &= np.arange(ok.shape[1]) != ignore[:, None]
    lo = np.where(ok, np.minimum(rel_a, rel_b), np.nan)
    hi = np.where(ok, np.maximum(rel_a, rel_b), np.nan)
    return centre[:, 0] + _gap_probe(lo, hi, probes - centre)


@dataclass(frozen=True)
class ShapeImage:
    """Per row, a shape whose whole image (film coordinates or angles) lies inside the probes' span
    (-1 where none), its two ends' coordinates on the probes' branch, and the indices of the
    segment endpoints at those ends, into ``concatenate([seg_a, seg_b])``."""

    shape: np.ndarray
    first: np.ndarray
    last: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        """Whether the row has such a shape."""
        return self.shape >= 0


@dataclass(frozen=True)
class ShapeImages:
    """Per row and shape of segments (K of them): its image's ends' coordinates ``lo``, ``hi`` (n, K),
    their endpoints ``first``, ``last`` (n, K) and whether the image is usable (``valid``)."""

    shape: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    first: np.ndarray
    last: np.ndarray
    valid: np.ndarray


def _images(geom: SceneState, coords: np.ndarray, usable: np.ndarray, widest: float = np.inf) -> ShapeImages:
    """Each shape of segments' image per row from its endpoints' coordinates ``coords`` (n, 2S): the
    interval between the extremes. Shapes with a circle, with an endpoint not ``usable`` (n, 2S)
    or with an image of zero width, or not narrower than ``widest``, are not valid."""
    n = len(coords)
    seg_shape = geom.prim_shape[: geom.n_seg]
    end_shape = np.concatenate([seg_shape, seg_shape])
    with_circle = set(geom.prim_shape[geom.n_seg :].tolist())
    shapes = [k for k in np.unique(seg_shape) if k not in with_circle]
    lo, hi = np.zeros((n, len(shapes))), np.zeros((n, len(shapes)))
    first, last = np.zeros((n, len(shapes)), np.int64), np.zeros((n, len(shapes)), np.int64)
    valid = np.zeros((n, len(shapes)), bool)
    for j, k in enumerate(shapes):  # a handful of shapes and endpoints, each vectorized over the rows
        lo_j, hi_j, first_j, last_j, ok = lo[:, j], hi[:, j], first[:, j], last[:, j], valid[:, j]
        # the extremes by a running minimum and maximum over the shape's endpoints (the first of equals,
        # as argmin and argmax pick it); an endpoint not usable counts as 0 (the image is not valid)
        for m, i in enumerate(np.flatnonzero(end_shape == k)):
            c = np.where(usable[:, i], coords[:, i], 0.0)
            if m == 0:
                lo_j[:], hi_j[:], first_j[:], last_j[:], ok[:] = c, c, i, i, usable[:, i]
                continue
            below, above = c < lo_j, c > hi_j
            np.copyto(lo_j, c, where=below)
            np.copyto(first_j, i, where=below)
            np.copyto(hi_j, c, where=above)
            np.copyto(last_j, i, where=above)
            ok &= usable[:, i]
        ok &= (hi_j > lo_j) & (hi_j - lo_j < widest)
    return ShapeImages(np.array(shapes, dtype=np.int64), lo, hi, first, last, valid)


def inner_shape(images: ShapeImages, probes: np.ndarray) -> ShapeImage:
    """Per row, the valid image lying strictly inside (probes[0], probes[-1]) whose middle is nearest
    the span's centre (:func:`film_inner_shape`, :func:`angle_inner_shape` from the shapes' ``images``)."""
    n = len(probes)
    inside = images.valid & (images.lo > probes[:, :1]) & (images.hi < probes[:, -1:])
    centre = 0.5 * (probes[:, :1] + probes[:, -1:])
    dist = np.where(inside, np.abs(0.5 * (images.lo + images.hi) - centre), np.inf)
    rows = np.arange(n)
    best = np.argmin(dist, axis=1) if dist.shape[1] else np.zeros(n, np.int64)
    found = np.isfinite(dist[rows, best]) if dist.shape[1] else np.zeros(n, bool)

    def pick(a: np.ndarray, fill: float) -> np.ndarray:
        return np.where(found, a[rows, best], fill) if a.shape[1] else np.full(n, fill)

    shape = np.where(found, images.shape[best], -1) if len(images.shape) else np.full(n, -1)
    return ShapeImage(
        shape, pick(images.first, -1), pick(images.last, -1), pick(images.lo, np.nan), pick(images.hi, np.nan)
    )


def shape_end(images: ShapeImages, probes: np.ndarray, geom: SceneState, followed: np.ndarray) -> np.ndarray:
    """Per row, the endpoint at the one end of the ``followed`` primitive's shape image inside the
    probes' span, -1 where none or both are (:func:`film_shape_end`, :func:`angle_shape_end` from the
    shapes' ``images``)."""
    end = np.full(len(probes), -1)
    shape = np.where(followed >= 0, geom.prim_shape[np.maximum(followed, 0)], -1)
    for j, k in enumerate(images.shape):  # a handful of shapes
        rows = np.flatnonzero((shape == k) & images.valid[:, j])
        lo, hi = images.lo[rows, j], images.hi[rows, j]
        lo_in = (lo > probes[rows, 0]) & (lo < probes[rows, -1])
        hi_in = (hi > probes[rows, 0]) & (hi < probes[rows, -1])
        end[rows] = np.where(
            lo_in & ~hi_in, images.first[rows, j], np.where(hi_in & ~lo_in, images.last[rows, j], -1)
        )
    return end


def _film_coordinates(geom: SceneState, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Every segment endpoint's film coordinate (θ-free) and whether it lies ahead of the camera,
    as (n, 2S) (the same for every row)."""
    o, f, r = (np.asarray(detach(v), dtype=np.float64) for v in (geom.cam_o, geom.cam_f, geom.cam_r))
    ends = np.concatenate([np.asarray(detach(geom.seg_a)), np.asarray(detach(geom.seg_b))]) - o
    depth = ends @ f
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ends @ r) / depth
    return np.broadcast_to(t, (n, t.size)), np.broadcast_to(depth > 0.0, (n, t.size))


@dataclass(frozen=True)
class Sight:
    """Every segment endpoint seen from the rows' shading points (:func:`angle_sight`): its angle
    relative to the probes' centre ``rel`` (n, 2S) in [-π, π), that centre (n, 1), and whether the
    endpoint is ``usable`` (n, 2S): not on the shape the row's point lies on, nor at the point."""

    centre: np.ndarray
    rel: np.ndarray
    usable: np.ndarray

    def take(self, rows: np.ndarray) -> Sight:
        """The sight of ``rows`` only (the same numbers as computing it for them)."""
        return Sight(self.centre[rows], self.rel[rows], self.usable[rows])


def angle_sight(geom: SceneState, x: np.ndarray, ignore: np.ndarray, probes: np.ndarray) -> Sight:
    """Every segment endpoint's angle seen from the rows' points ``x`` (n, 2) relative to the probes'
    centre (the probes' branch), in [-π, π); endpoints of the shape a row's point lies on
    (``ignore``'s) are not usable. Computed once per set of probes, it serves the gap probe and both
    shape images (:func:`angle_gap_probe`, :func:`angle_images`)."""
    centre = 0.5 * (probes[:, :1] + probes[:, -1:])
    ends = np.concatenate([np.asarray(detach(geom.seg_a)), np.asarray(detach(geom.seg_b))])
    # computed as (2S, n), endpoints first, so every operation runs along the rows; stored transposed
    vx, vy = ends[:, 0:1] - x[:, 0], ends[:, 1:2] - x[:, 1]
    seg_shape = geom.prim_shape[: geom.n_seg]
    end_shape = np.concatenate([seg_shape, seg_shape])
    own = np.where(ignore >= 0, geom.prim_shape[np.maximum(ignore, 0)], -1)
    usable = (end_shape[:, None] != own[None, :]) & ((vx != 0.0) | (vy != 0.0))  # |v| > 0
    rel = np.arctan2(vy, vx, out=vy)  # in place: arrays this size cost more to allocate than to fill
    rel -= centre[:, 0]
    rel = wrap_angle(rel, out=rel)
    return Sight(centre, rel.T, usable.T)


def film_images(geom: SceneState, n: int) -> ShapeImages:
    """Each shape of segments' image on the film for ``n`` rows (the same for every row): the input of
    :func:`inner_shape` and :func:`shape_end` (:func:`film_inner_shape`, :func:`film_shape_end`)."""
    return _images(geom, *_film_coordinates(geom, n))


def angle_images(geom: SceneState, sight: Sight) -> ShapeImages:
    """Each shape of segments' image seen from the rows' points, on the probes' branch, from their
    :func:`angle_sight` (:func:`angle_inner_shape`, :func:`angle_shape_end`)."""
    return _images(geom, sight.centre + sight.rel, sight.usable, widest=np.pi - 1e-9)


def film_inner_shape(geom: SceneState, probes: np.ndarray) -> ShapeImage:
    """Per row, a shape made of segments whose whole film image lies strictly inside the probes' span.

    A shape's image on the film is the interval between its endpoints' extreme film coordinates
    (θ-free, from the detached ``geom``); shapes with a circle, with a point behind the camera or
    with an image of zero width (a segment seen end-on) are skipped. Of the shapes whose image
    lies inside (probes[0], probes[-1]), the one whose middle is nearest the span's centre is
    returned. Its two extreme endpoints are the ends of its silhouette on the film, which the
    camera transform follows exactly (:class:`~flatland.reparam.default.ReparamTransforms`).

    Parameters
    ----------
    geom : SceneState
        The scene (values only).
    probes : ndarray, shape (n, P)
        The rows' probe film coordinates, in film order.

    Returns
    -------
    ShapeImage
    """
    return inner_shape(film_images(geom, len(probes)), probes)


def film_shape_end(geom: SceneState, probes: np.ndarray, followed: np.ndarray) -> np.ndarray:
    """Per row, the endpoint at the one end of the ``followed`` primitive's shape image that lies
    inside the probes' span (index into ``concatenate([seg_a, seg_b])``), -1 where none or both do.

    The probes chose to follow a point of that shape next to a switch to another shape; a
    silhouette end of the shape inside the span is that switch, and its endpoint moves like it
    under every motion, where the followed hit point does only under translation (to first order
    in its distance from the end otherwise).

    Parameters
    ----------
    geom : SceneState
        The scene (values only).
    probes : ndarray, shape (n, P)
        The rows' probe film coordinates, in film order.
    followed : ndarray of int, shape (n,)
        The primitive followed per row (:attr:`Choice.followed`, -1: none).

    Returns
    -------
    ndarray of int, shape (n,)
    """
    return shape_end(film_images(geom, len(probes)), probes, geom, followed)


def angle_inner_shape(geom: SceneState, x: np.ndarray, ignore: np.ndarray, probes: np.ndarray) -> ShapeImage:
    """:func:`film_inner_shape` for the shading integral: images are the intervals between a shape's
    endpoints' extreme angles seen from the rows' points ``x`` (n, 2), on the probes' branch; the
    shape a row's point lies on (``ignore`` (n,), its primitive) is skipped."""
    return inner_shape(angle_images(geom, angle_sight(geom, x, ignore, probes)), probes)


def angle_shape_end(
    geom: SceneState, x: np.ndarray, ignore: np.ndarray, probes: np.ndarray, followed: np.ndarray
) -> np.ndarray:
    """:func:`film_shape_end` for the shading integral, angles seen from the rows' points ``x``."""
    return shape_end(angle_images(geom, angle_sight(geom, x, ignore, probes)), probes, geom, followed)
