"""Reparameterization of the pixel and shading integrals by translations chosen with probe rays.

Loubet et al. 2019: Sec. 3.2 (change of variables), 4.1 (in 2D a rotation of
directions is a translation of the angle, and the film is a line), 4.2 (convolution
kernels), 4.3 (choosing the transform by ray tracing, DESIGN 2.8), and the paired
samples of the authors' implementation (DESIGN 2.9).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.contract import Option
from flatland.core.dual import detach, variable
from flatland.core.validate import ValidationError, check_bool, check_int, check_positive
from flatland.geometry import angle_of, cast, direction, film_coordinate, film_direction
from flatland.integrator import (
    GRADIENT_METHODS,
    BatchResult,
    Context,
    Hooks,
    Job,
    Members,
    filter_blurred,
    run,
)
from flatland.methods.heuristic import choose_points
from flatland.sampling import sample_von_mises

__all__ = ["ReparamHooks", "default_kappa_film", "reparam"]


def default_kappa_film(pixel_width: float) -> float:
    """Film kernel concentration 2 / (0.4 Δt)²: a Gaussian of σ ≈ 0.28 pixel.

    The flat-film form of the authors' camera kernel κ = 1 / (1 - cos(0.4 · pixel
    angle)) (DESIGN 2.7), since 1 - cos x ≈ x² / 2.
    """
    return 2.0 / (0.4 * pixel_width) ** 2


class ReparamHooks(Hooks):
    """Film and direction translations that follow the point chosen by probe rays (DESIGN 2.8).

    Film (kernel: Gaussian of variance 1/κ_film on t): the kernel centre ω ~ N(t, 1/κ_film)
    is drawn around the film sample t (the joint density p(t) k(t, ω) read in the
    reverse order, which keeps the primal samples the naive ones), probes ~ N(ω,
    1/κ_film) pick an attached point p, and t is evaluated at ``T(t) = t + Δ`` with
    ``Δ = t_p(θ) - detach(t_p(θ))``, t_p the film coordinate of p. Directions (kernel:
    von Mises of concentration κ on the angle) the same way around each direction
    sample φ, with ``Δ = angle(p - x(θ)) - detach(...)`` from the moving shading point.
    The weight ``k(T y, ω) / detach(k(T y, ω))`` (value 1) carries the kernel's derivative.
    """

    def __init__(
        self, kappa: float, kappa_film: float, probes: int, spread: float, refine: int, paired: bool
    ) -> None:
        self.kappa, self.kappa_film, self.probes, self.paired = kappa, kappa_film, probes, paired
        self.refine = refine
        # probe offsets in kernel standard deviations, evenly spaced over [-spread, spread]
        self.offsets = spread * (np.linspace(-1.0, 1.0, probes) if probes > 1 else np.zeros(1))

    # --------------------------------------------------------------------- film
    def film(self, ctx: Context, t: np.ndarray, pixel: np.ndarray) -> Members:
        n, sigma = t.size, 1.0 / np.sqrt(self.kappa_film)
        geom = ctx.geom
        density = None
        if self.paired:
            # the pair's kernel centre ω = t + σz has density q = k_j ⊛ N(0, σ²) (closed form), which
            # covers the kernel-blurred integrand beyond the filter's support; members μ_j ~ k(·, ω)
            center = t + sigma * ctx.rng("kernel").standard_normal(n)
            mu = center[:, None] + sigma * ctx.rng("kernel").standard_normal((n, 2))
            cam = geom.camera
            density = filter_blurred(cam.filter, center - cam.pixel_centers()[pixel], cam.pixel_width, sigma)
        else:  # reverse order: the member is the primary sample, the centre ω ~ k(·, t)
            center = t + sigma * ctx.rng("kernel").standard_normal(n)
            mu = t[:, None]
        probes = center[:, None] + sigma * self.offsets
        o0 = detach(geom.cam_o)
        d = detach(film_direction(ctx.geom0, probes.reshape(-1)))
        hits = cast(ctx.geom0, o0, d)
        origins = np.broadcast_to(o0, (n, 2))
        dir_c = detach(film_direction(ctx.geom0, center))

        def trace(rows: np.ndarray, t_probe: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            h = cast(ctx.geom0, o0, detach(film_direction(ctx.geom0, t_probe)))
            return h.prim, h.coord

        choice = choose_points(
            geom,
            origins,
            hits.prim.reshape(n, -1),
            hits.coord.reshape(n, -1),
            dir_c,
            probes,
            trace,
            self.refine,
        )
        v = choice.point - geom.cam_o
        ok = choice.ok & (np.sum(detach(v) * detach(geom.cam_f), axis=1) > 0.0)
        t_p = film_coordinate(geom, np.where(ok[:, None], v, detach(geom.cam_f)))
        # T(t, θ) = t + t_p(θ) - t_p(θ0): value t, derivative t_p'   (DESIGN 2.5)
        shift = np.where(ok, t_p - detach(t_p), 0.0)
        points = mu + shift[:, None]
        offset = points - center[:, None]
        # w = k(T y, ω) / detach(k(T y, ω)), Gaussian kernel: exp(-κ/2 (x² - detach(x²)))   (DESIGN 2.7)
        sq = offset * offset
        weights = np.exp(-0.5 * self.kappa_film * (sq - detach(sq)))
        return Members(points, weights, self.paired, density)

    # --------------------------------------------------------------- directions
    def directions(self, ctx: Context, x: Any, ignore: np.ndarray, phi: np.ndarray) -> Members:
        n, kappa = phi.size, self.kappa
        x0 = detach(x)
        if self.paired:
            center = phi
            u = ctx.rng("kernel").random((n, 2))
            mu = sample_von_mises(u, phi[:, None], kappa)
        else:
            center = sample_von_mises(ctx.rng("kernel").random(n), phi, kappa)
            mu = phi[:, None]
        probes = center[:, None] + self.offsets / np.sqrt(kappa)  # σ = 1/√κ: the von Mises width
        hits = cast(
            ctx.geom0,
            np.repeat(x0, self.probes, axis=0),
            direction(probes.reshape(-1)),
            np.repeat(ignore, self.probes),
        )

        def trace(rows: np.ndarray, phi_probe: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            h = cast(ctx.geom0, x0[rows], direction(phi_probe), ignore[rows])
            return h.prim, h.coord

        choice = choose_points(
            ctx.geom,
            x0,
            hits.prim.reshape(n, -1),
            hits.coord.reshape(n, -1),
            direction(center),
            probes,
            trace,
            self.refine,
        )
        v = choice.point - x
        v_safe = np.where(choice.ok[:, None], v, direction(center))
        angle = angle_of(v_safe)
        # T(φ, θ) = φ + angle(p(θ) - x(θ)) - its value: a translation of the angle, |det J| = 1   (DESIGN 2.6)
        shift = np.where(choice.ok, angle - detach(angle), 0.0)
        points = mu + shift[:, None]
        c = np.cos(points - center[:, None])
        # von Mises weight exp(κ (cos(T y - ω) - detach(cos(T y - ω))))   (DESIGN 2.7)
        weights = np.exp(kappa * (c - detach(c)))
        return Members(points, weights, self.paired)


def _check_kappa_film(name: str, value: Any) -> float:
    return check_positive(name, value)


def _check_probes(name: str, value: Any) -> int:
    return check_int(name, value, minimum=1)


def _check_refine(name: str, value: Any) -> int:
    return check_int(name, value, minimum=0)


def _check_spread(name: str, value: Any) -> float:
    return check_positive(name, value, allow_zero=True)


@GRADIENT_METHODS.register(
    "reparam",
    Option("kappa", 1000.0, check_positive),
    Option("kappa_film", None, _check_kappa_film),
    Option("probes", 4, _check_probes),
    Option("spread", 3.0, _check_spread),
    Option("refine", 0, _check_refine),
    Option("paired", False, check_bool),
)
def reparam(
    job: Job, kappa: float, kappa_film: float | None, probes: int, spread: float, refine: int, paired: bool
) -> BatchResult:
    """Differentiate after translating every pixel and shading integral so its discontinuities stay put.

    Options
    -------
    kappa : float
        Von Mises concentration of the kernel on shading directions (default 1000,
        about 1.8 degrees wide; the authors' BSDF value).
    kappa_film : float, optional
        Concentration (1 / variance) of the Gaussian kernel on the film coordinate;
        default :func:`default_kappa_film` of the pixel width.
    probes : int
        Probe rays per sample (default 4).
    paired : bool
        Two evaluations per sample share one transform and serve as each other's
        control variate (DESIGN 2.9). The kernel is then used in the paper's order
        (the primary sample is the kernel centre), so the value is a different,
        still unbiased, estimate than the naive one, at twice the cost per level.

    Every film sample t (pixel integral, translation of t) and every direction
    sample φ, cosine- or emitter-sampled (shading integral, translation of the
    angle), gets its own transform from :class:`ReparamHooks`; the samples, their
    densities and the MIS weights stay those of the naive estimator at θ0 (θ-free
    functions of the untransformed sample), which keeps the MIS decomposition exact
    for every θ. Without ``paired`` the transform's value is the identity, so the
    image value is bit-identical to the naive one for the same seed (DESIGN 2.5).

    Emitter samples: the authors used one transform per shading point, from the mean
    of the occluded shadow rays' hits, for all light samples, and faded emitters.
    Here every emitter sample is reparameterized like a cosine sample, by its own
    kernel and probes; fading (``fade`` on segment emitters) still matters, because a
    transform that follows an occluder leaves the emitter's own edge moving.

    Assumes the pixel filter is continuous (a box filter's edges would become moving
    discontinuities, DESIGN 2.11: refused) and that one translation follows every
    discontinuity within a kernel's reach. Biased where it does not: two
    discontinuities moving differently inside one kernel (the ``two_occluders``
    scene, an occluder's shadow edge near an emitter's unfaded edge), a probe pair
    that picks the wrong point, or an attached point whose motion differs from the
    silhouette's (first order in the kernel width; exact at the tangent point). The
    bias falls as κ grows, while the variance of the kernel weight's derivative
    (κ sin(y - ω) Δ', about √κ per sample) rises: the trade-off of DESIGN 2.7. The
    tent filter's log-derivative grows like 1 / distance at its support edge, a
    mildly heavy tail; the Gaussian filter has none.
    """
    if job.point is None and job.scene.camera.filter == "box":
        raise ValidationError(
            "camera.filter",
            "the reparam method needs a continuous pixel filter, got 'box': reparameterizing the film "
            "moves samples across the box's edges, which become moving discontinuities (DESIGN 2.11); "
            "use 'tent' or 'gaussian'",
        )
    if kappa_film is None:
        kappa_film = default_kappa_film(job.scene.camera.pixel_width)
    hooks = ReparamHooks(kappa, kappa_film, probes, spread, refine, paired)
    return run(job, job.geometry(variable(0.0)), hooks)
