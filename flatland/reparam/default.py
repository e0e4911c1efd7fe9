r"""flatland's reparameterization: translations of the film coordinate and of angles, chosen by probes.

:class:`ReparamTransforms` is the ``reparam`` method's :class:`~flatland.integrator.Transforms`
(Loubet et al. 2019, Sec. 4.1-4.3; in 2D a rotation of directions is a translation of the
angle, and the film is a line): ``camera`` translates each film sample, ``directions`` each
cosine and emitter sample, inside convolution kernels, following the point the probe
heuristic of :mod:`flatland.reparam.probes` chooses. The method's entry and options are in
:mod:`flatland.methods.reparam`; sphere3d's counterpart is :mod:`sphere3d.reparam.default`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from flatland.core.dual import as_dual, detach, is_dual, k_of, tangent
from flatland.core.rng import Draws
from flatland.core.translation import translation_offset, unit_weight
from flatland.glossy import Lobe
from flatland.integrator import Context, Identity, Members
from flatland.reparam.lobe import lobe_kappa, lobe_radius
from flatland.reparam.probes import (
    Choice,
    ShapeImage,
    angle_gap_probe,
    angle_images,
    angle_sight,
    film_gap_probe,
    film_images,
    inner_shape,
    select_points,
    shape_end,
)
from flatland.sampling import filter_blurred, sample_von_mises, wrap_angle
from flatland.tracing import EPS_DIST, angle_of, cast, direction, film_coordinate, film_direction, zeros

__all__ = ["ReparamTransforms", "default_kappa_film"]


def default_kappa_film(pixel_width: float) -> float:
    r"""Film kernel concentration $2 / (0.4 Δt)^2$: a Gaussian of $σ ≈ 0.28$ pixel.

    The flat-film form of the authors' camera kernel $κ = 1 / (1 - \cos(0.4 · \mathrm{pixel\ angle}))$
    (Loubet et al. 2019, Sec. 4.2), since $1 - \cos x ≈ x^2 / 2$.
    """
    return 2.0 / (0.4 * pixel_width) ** 2


def _endpoint(geom: Any, index: np.ndarray) -> Any:
    """Segment endpoints ``index`` into ``concatenate([seg_a, seg_b])`` (Dual, (k, 2))."""
    n_seg = np.shape(detach(geom.seg_a))[0]
    return np.where((index < n_seg)[:, None], geom.seg_a[index % n_seg], geom.seg_b[index % n_seg])


def _end_coordinate(geom: Any, index: np.ndarray) -> Any:
    """Film coordinates of segment endpoints ``index`` (Dual)."""
    return film_coordinate(geom, _endpoint(geom, index) - geom.cam_o)


def _stretch(
    inner: ShapeImage, mu: np.ndarray, points: Any,
    trace: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    geom0: Any, coordinate: Callable[[np.ndarray, np.ndarray], Any],
) -> tuple[Any, Any]:  # fmt: skip
    r"""``points`` (n, m) with the rows of ``inner`` moved by the map that follows both ends of a small
    shape's image, and $\log |\det J_T|$ (0 elsewhere).

    With a, b the coordinates (film or angle) of the image's ends, a0, b0 their values, the
    piecewise-linear map $T(y) = y + (a - a_0)$ below $a_0$, $T(y) = a + (y - a_0) s$ on
    $[a_0, b_0]$ and $T(y) = y + (b - b_0)$ above $b_0$, $s = (b - a) / (b_0 - a_0)$, is continuous,
    increasing and the identity at θ0; it carries both discontinuities a, b to fixed points, so
    the shape may translate, turn, scale or move in depth (a translation follows one point only:
    a thin shape turning about its middle has ends moving apart, and its middle, which the probes
    see, does not move). $|\det J_T|$ is s on the image, else 1. Only rows where a ray at the
    image's middle sees the shape (it is not hidden) are moved. ``coordinate(rows, i)`` gives the
    θ-dependent coordinates of endpoints ``i`` for ``rows`` (Dual; only their tangents are used, the
    values ``inner.lo``, ``inner.hi`` are on the probes' branch).
    """
    rows = np.flatnonzero(inner.ok)
    if rows.size:
        prim, _ = trace(rows, 0.5 * (inner.lo[rows] + inner.hi[rows]))
        rows = rows[(prim >= 0) & (geom0.prim_shape[np.maximum(prim, 0)] == inner.shape[rows])]
    if not rows.size:
        return points, 0.0
    a0, b0 = inner.lo[rows][:, None], inner.hi[rows][:, None]
    # T(y) = y + Δ(y), Δ of value exactly 0 (the primal stays the naive one): each end's offset outside
    # the image, inside it Δa + (y - a0) (s - 1), s - 1 = (Δb - Δa) / (b0 - a0)   (the map above)
    left = translation_offset(coordinate(rows, inner.first[rows]))[:, None]
    right = translation_offset(coordinate(rows, inner.last[rows]))[:, None]
    stretch = (right - left) / (b0 - a0)  # s - 1, value exactly 0
    y = mu[rows]
    inside = (y >= a0) & (y <= b0)
    moved = y + np.where(y < a0, left, np.where(inside, left + (y - a0) * stretch, right))
    log_jacobian = zeros(np.shape(mu), is_dual(moved), k_of(moved))
    log_jacobian[rows] = np.where(inside, np.log1p(stretch), 0.0)  # log |det J_T| = log s
    if not is_dual(points) and is_dual(moved):
        points = as_dual(points, k_of(moved))
    points[rows] = moved
    return points, log_jacobian


def _moves(x: Any) -> np.ndarray:
    """Rows of ``x`` (n, 2) with a nonzero tangent (under any of k parameters)."""
    moving = tangent(x) != 0.0
    return np.any(moving if moving.ndim == 2 else np.any(moving, axis=0), axis=-1)


def _may_see_motion(geom: Any, x0: np.ndarray, center: np.ndarray, half: float | np.ndarray) -> np.ndarray:
    r"""Whether the angle interval $[c - h, c + h]$ (``center`` (n,), ``half`` h) seen from ``x0`` (n, 2) may
    meet the image of a moving primitive (one whose geometry has a nonzero tangent), conservatively.

    A segment's image from x is the arc between its endpoints' angles (less than π: a segment through x,
    or nearly, counts as seen); a circle's is its centre's angle ± $\arcsin(r / d)$ (everything from
    inside). Every probe, bisection step, gap probe and followed end of the transform lies in the
    interval, so where this is False every point it may follow is static."""
    n = center.size
    seen = np.zeros(n, dtype=bool)
    margin = 1e-6  # radians of slack: a row kept for nothing costs probes only
    parts = [(geom.seg_a, geom.seg_b)] if geom.n_seg else []
    moving_seg = _moves(geom.seg_a) | _moves(geom.seg_b) if geom.n_seg else np.zeros(0, dtype=bool)
    for i in np.flatnonzero(moving_seg):  # a loop over the few moving primitives, not over samples
        a, b = detach(parts[0][0])[i] - x0, detach(parts[0][1])[i] - x0
        alpha, beta = np.arctan2(a[:, 1], a[:, 0]), np.arctan2(b[:, 1], b[:, 0])
        width = np.abs(wrap_angle(beta - alpha))
        mid = alpha + 0.5 * wrap_angle(beta - alpha)
        seen |= (width > np.pi - 1e-3) | (np.abs(wrap_angle(center - mid)) <= 0.5 * width + half + margin)
    if geom.n_circ:
        moving = _moves(geom.circ_c) | (tangent(geom.circ_r).reshape(-1, geom.n_circ) != 0.0).any(axis=0)
        for i in np.flatnonzero(moving):
            p = detach(geom.circ_c)[i] - x0
            d, r = np.hypot(p[:, 0], p[:, 1]), float(detach(geom.circ_r)[i])
            width = np.arcsin(np.minimum(r / np.maximum(d, 1e-300), 1.0))
            inside = d <= r * (1.0 + 1e-6)
            gap = np.abs(wrap_angle(center - np.arctan2(p[:, 1], p[:, 0])))
            seen |= inside | (gap <= width + half + margin)
    return seen


class ReparamTransforms(Identity):
    r"""Film and angle translations following the point the probes choose, inside convolution kernels.

    Film: kernel $g = N(0, 1/κ_\mathrm{film})$ on t. Directions: von Mises of concentration κ on
    the angle. Unpaired, the kernel is read in the reverse order (the joint density
    $p(y) k(y, ω)$ of Loubet et al. 2019, Sec. 4.2, with y the primary sample,
    $ω \sim k(·, y)$ the centre), which keeps every evaluation point's value that of the
    naive estimator. Probes at $ω + σ · \mathrm{spread} · \mathrm{linspace}(-1, 1, \mathrm{probes})$
    pick an attached point p (Loubet et al. 2019, Sec. 4.3), and
    the sample is evaluated at $T(y) = y + Δ$ with $Δ = c_p(θ) - \mathrm{detach}(c_p(θ))$,
    $c_p$ the film coordinate of p or its angle seen from the (moving) shading point.
    The weight $k(T y, ω) / \mathrm{detach}(k(T y, ω))$ (value 1) carries the kernel's derivative.
    At glossy points (``lobe`` a fraction) the direction kernel's κ is per point, following the GGX
    lobe's width (:mod:`flatland.reparam.lobe`); None: κ at every point.
    Unpaired, a direction sample keeps the identity without probes where nothing it could follow moves
    (a static shading point whose probes' span meets no moving primitive's image,
    :func:`_may_see_motion`) or where it can add nothing (not ``needed``): the same numbers.
    """

    def __init__(
        self, kappa: float, kappa_film: float, probes: int, spread: float, refine: int, paired: bool,
        lobe: float | None = None,
    ):  # fmt: skip
        self.kappa, self.kappa_film, self.paired, self.refine = kappa, kappa_film, paired, refine
        self.spread, self.lobe = spread, lobe
        # probe offsets in kernel standard deviations, evenly spaced over [-spread, spread], in order
        self.offsets = spread * (np.linspace(-1.0, 1.0, probes) if probes > 1 else np.zeros(1))

    def _choose(
        self, ctx: Context, origins: np.ndarray, centre_dirs: np.ndarray, probes: np.ndarray,
        trace: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    ) -> tuple[Choice, tuple[np.ndarray, np.ndarray]]:  # fmt: skip
        """The choice from the ``probes`` (n, P), and their hits (primitive, coordinate), (n, P) each."""
        n, m = probes.shape
        prim, coord = trace(np.repeat(np.arange(n), m), probes.reshape(-1))
        prim, coord = prim.reshape(n, m), coord.reshape(n, m)
        choice = select_points(ctx.geom, origins, prim, coord, centre_dirs, probes, trace, self.refine)
        return choice, (prim, coord)

    def _again(
        self, ctx: Context, choice: Choice, rows: np.ndarray, extra: np.ndarray, origins: np.ndarray,
        centre_dirs: np.ndarray, probes: np.ndarray, hits: tuple[np.ndarray, np.ndarray],
        trace: Callable[[np.ndarray, np.ndarray], Any],
    ) -> Choice:  # fmt: skip
        """``choice`` with ``rows`` chosen again from their probes (``hits``, as traced) plus the probe at
        ``extra`` (NaN: none), the one traced here: a ray's hit does not depend on the rays cast with it."""
        rows, extra = rows[np.isfinite(extra)], extra[np.isfinite(extra)]
        if not rows.size:
            return choice
        params = np.concatenate([probes[rows], extra[:, None]], axis=1)
        again = np.sort(params, axis=1)
        order = np.argsort(params, axis=1, kind="stable")  # where each sorted probe's hit comes from
        extra_prim, extra_coord = trace(rows, extra)
        prim = np.take_along_axis(np.concatenate([hits[0][rows], extra_prim[:, None]], axis=1), order, axis=1)
        coord = np.take_along_axis(
            np.concatenate([hits[1][rows], extra_coord[:, None]], axis=1), order, axis=1
        )

        def trace_rows(r: np.ndarray, params: np.ndarray) -> Any:  # trace's rows index the full chunk
            return trace(rows[r], params)

        sub = select_points(
            ctx.geom, origins[rows], prim, coord, centre_dirs[rows], again, trace_rows, self.refine
        )
        point, code, followed = choice.point, choice.code.copy(), choice.followed_prim.copy()
        point[rows], code[rows], followed[rows] = sub.point, sub.code, sub.followed_prim
        return Choice(point, code, followed)

    def camera(self, ctx: Context, t: np.ndarray, pixel: np.ndarray, draws: Draws) -> Members:
        n, sigma, geom = t.size, 1.0 / np.sqrt(self.kappa_film), ctx.geom
        center = t + sigma * draws.normals("kernel.film")
        density = None
        if self.paired:
            # ω = t + σz has density q = k_j ⊛ N(0, σ²) (closed form); unlike k_j itself it covers the
            # kernel-blurred integrand beyond the filter's support. Members μ_j ~ k(·, ω).
            mu = center[:, None] + sigma * draws.normals("kernel.film.pair", 2)
            cam = geom.camera
            density = filter_blurred(cam.filter, center - cam.pixel_centers()[pixel], cam.pixel_width, sigma)
        else:
            mu = t[:, None]
        o0 = detach(geom.cam_o)

        def trace(rows: np.ndarray, t_probe: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            hits = cast(ctx.geom0, o0, detach(film_direction(ctx.geom0, t_probe)))
            return hits.prim, hits.coord

        probes = center[:, None] + sigma * self.offsets
        origins, dirs0 = np.broadcast_to(o0, (n, 2)), film_direction(ctx.geom0, center)
        choice, hits = self._choose(ctx, origins, dirs0, probes, trace)
        # nothing chosen, but a primitive's whole image lies between two probes: probe it too, choose again
        gap = np.flatnonzero(~choice.ok)
        extra = film_gap_probe(ctx.geom0, probes[gap])
        choice = self._again(ctx, choice, gap, extra, origins, dirs0, probes, hits, trace)
        v = choice.point - geom.cam_o
        ok = choice.ok & (np.sum(detach(v) * detach(geom.cam_f), axis=1) > 0.0)
        t_p = film_coordinate(geom, np.where(ok[:, None], v, detach(geom.cam_f)))
        # the followed shape's silhouette end inside the probes' span: follow that endpoint itself
        images = film_images(ctx.geom0, n)  # the shapes' film images, for the shape's end and a shape inside
        end = shape_end(images, probes, ctx.geom0, np.where(ok, choice.followed_prim, -1))
        rows = np.flatnonzero(end >= 0)
        if rows.size:
            t_p[rows] = _end_coordinate(geom, end[rows])
        # T(t, θ) = t + t_p(θ) - t_p(θ0): value t, derivative t_p'   (Loubet et al. 2019, Sec. 3.2)
        points = mu + translation_offset(t_p, ok)[:, None]
        # a visible shape whose whole image lies inside the probes' span: follow both its ends
        inner = inner_shape(images, probes)
        points, log_jacobian = _stretch(
            inner, mu, points, trace, ctx.geom0, lambda rows, i: _end_coordinate(geom, i)
        )
        sq = (points - center[:, None]) ** 2
        # w = k(T y, ω) |det J_T| / detach(...), log k = -κ/2 x² + const for the Gaussian   (Sec. 4.2)
        log_k = -0.5 * self.kappa_film * sq + log_jacobian
        return Members(points, unit_weight(log_k), self.paired, density)

    def kernel_kappa(self, lobe: Lobe | None) -> float | np.ndarray:
        """The direction kernel's concentration: ``kappa`` (one float) without glossy rows or ``lobe``;
        else per row, :func:`~flatland.reparam.lobe.lobe_kappa` of the detached roughness (θ-free), one
        float where that is κ on every row."""
        if lobe is None or self.lobe is None or not np.any(lobe.glossy):
            return self.kappa
        radius = lobe_radius(detach(lobe.alpha))
        kappa = lobe_kappa(self.kappa, self.spread, self.lobe, radius, lobe.glossy)
        # every lobe wide enough: the user's κ as one float, the scalar code path (bit for bit as without)
        return self.kappa if np.all(kappa == self.kappa) else kappa

    def directions(
        self,
        ctx: Context,
        x: Any,
        ignore: np.ndarray,
        phi: np.ndarray,
        draws: Draws,
        lobe: Lobe | None = None,
    ) -> Members:
        # unpaired, a sample not ``ctx.needed`` adds 0 and moves no path wherever it goes; one whose shading
        # point is static and whose probes' span meets the image of no moving primitive can only follow a
        # static point (a zero derivative): both keep the identity, the first without a kernel draw, neither
        # with a probe. Every other row's numbers are those of the full call (all per row)
        kappa = self.kernel_kappa(lobe)  # fixed at the point, whatever the sample (flatland.reparam.lobe)
        if self.paired or not ctx.geom.differentiable:
            return self._directions(ctx, x, ignore, phi, draws, kappa)
        rows = np.arange(phi.size) if ctx.needed is None else np.flatnonzero(ctx.needed)
        per_row = (lambda r: kappa) if np.ndim(kappa) == 0 else (lambda r: kappa[r])
        center = sample_von_mises(draws.take(rows).uniforms("kernel.directions"), phi[rows], per_row(rows))
        half = np.max(np.abs(self.offsets)) / np.sqrt(per_row(rows))  # the probes' span: centre ± half
        sees = _moves(x[rows]) | _may_see_motion(ctx.geom, detach(x)[rows], center, half)
        rows, center = rows[sees], center[sees]
        if rows.size == phi.size:
            return self._directions(ctx, x, ignore, phi, draws, kappa, center)
        k = ctx.geom.k
        points, weights = as_dual(phi[:, None].copy(), k), as_dual(np.ones((phi.size, 1)), k)
        if rows.size:
            sub = self._directions(
                ctx, x[rows], ignore[rows], phi[rows], draws.take(rows), per_row(rows), center
            )
            points[rows], weights[rows] = sub.points, sub.weights
        return Members(points, weights)

    def _directions(
        self, ctx: Context, x: Any, ignore: np.ndarray, phi: np.ndarray, draws: Draws,
        kappa: float | np.ndarray, center: np.ndarray | None = None,
    ) -> Members:  # fmt: skip
        column = kappa if np.ndim(kappa) == 0 else kappa[:, None]  # per row, against (n, members)
        x0 = detach(x)
        if self.paired:  # ω = φ (the primary sample), members μ_j ~ vM(ω, κ)
            center = phi
            mu = sample_von_mises(draws.uniforms("kernel.directions.pair", 2), phi[:, None], kappa)
        else:  # reverse order: ω ~ vM(φ, κ) (``center``, when drawn already), the member is φ itself
            if center is None:
                center = sample_von_mises(draws.uniforms("kernel.directions"), phi, kappa)
            mu = phi[:, None]

        def trace(rows: np.ndarray, phi_probe: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            hits = cast(ctx.geom0, x0[rows], direction(phi_probe), ignore[rows])
            return hits.prim, hits.coord

        probes = center[:, None] + self.offsets / np.sqrt(column)  # σ = 1/√κ, the von Mises width
        dirs0 = direction(center)
        choice, hits = self._choose(ctx, x0, dirs0, probes, trace)
        # every segment endpoint's angle from x, once for the gap probe and the shapes' images
        sight = angle_sight(ctx.geom0, x0, ignore, probes)
        # nothing chosen, but a primitive's whole image lies between two probes: probe it too, choose again
        gap = np.flatnonzero(~choice.ok)
        extra = angle_gap_probe(ctx.geom0, x0[gap], ignore[gap], probes[gap], sight.take(gap))
        choice = self._again(ctx, choice, gap, extra, x0, dirs0, probes, hits, trace)
        offset = choice.point - x
        # a chosen point on the shading point itself (coincident geometry) defines no direction: the
        # derivative of atan2 there is 0/0, so that sample keeps the identity transform
        ok = choice.ok & (np.hypot(*detach(offset).T) > EPS_DIST)
        angle = angle_of(np.where(ok[:, None], offset, dirs0))

        def end_angle(rows: np.ndarray, i: np.ndarray) -> Any:  # angles of endpoints i seen from x[rows]
            return angle_of(_endpoint(ctx.geom, i) - x[rows])

        # the followed shape's silhouette end inside the probes' span: follow that endpoint itself
        images = angle_images(ctx.geom0, sight)
        end = shape_end(images, probes, ctx.geom0, np.where(ok, choice.followed_prim, -1))
        rows = np.flatnonzero(end >= 0)
        if rows.size:
            angle[rows] = end_angle(rows, end[rows])
        # T(φ, θ) = φ + angle(p(θ) - x(θ)) - its value: a translation of the angle, |det J| = 1   (Sec. 4.1)
        points = mu + translation_offset(angle, ok)[:, None]
        # a visible shape whose whole image lies inside the probes' span: follow both its ends
        inner = inner_shape(images, probes)
        points, log_jacobian = _stretch(inner, mu, points, trace, ctx.geom0, end_angle)
        c = np.cos(points - center[:, None])
        # von Mises weight times |det J_T|, log k = κ cos(T y - ω) + const   (Loubet et al. 2019, Sec. 4.2)
        return Members(points, unit_weight(column * c + log_jacobian), self.paired)
