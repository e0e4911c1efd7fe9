r"""Reparameterization of the pixel and shading integrals by translations chosen with probe rays.

Where the integrator calls it: one ``task.evaluate(variable(0.0), ReparamTransforms(...))``.
``camera`` gets each chunk's film samples
$t \sim k_j$ before the camera rays are traced and returns the translated points $T(t)$ with
kernel weights; ``directions`` gets the cosine and emitter samples φ inside
:func:`~flatland.integrator.shade`, before the shading rays are traced, and returns
$T(φ)$ likewise; both choose the translation with :mod:`flatland.probes`.
The 2D-only extras stay ``None``.

Loubet et al. 2019: Sec. 3.2 (change of variables), 4.1 (in 2D a rotation of
directions is a translation of the angle, and the film is a line), 4.2 (convolution
kernels), 4.3 (choosing the transform by ray tracing,
:mod:`flatland.probes`), and the paired samples of the authors'
implementation (theory/kernels).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np

from flatland.core.contract import Option
from flatland.core.dual import detach, variable
from flatland.core.rng import Draws
from flatland.core.translation import check_continuous_filter, translation_offset, unit_weight
from flatland.core.validate import check_bool, check_int, check_positive
from flatland.integrator import Context, Identity, Members
from flatland.methods._common import GRADIENT_METHODS
from flatland.probes import Choice, angle_gap_probe, film_gap_probe, select_points
from flatland.sampling import filter_blurred, sample_von_mises
from flatland.tasks import ImageTask, PointTask, Tally
from flatland.tracing import EPS_DIST, angle_of, cast, direction, film_coordinate, film_direction

__all__ = ["ReparamTransforms", "default_kappa_film", "reparam"]


def default_kappa_film(pixel_width: float) -> float:
    r"""Film kernel concentration $2 / (0.4 Δt)^2$: a Gaussian of $σ ≈ 0.28$ pixel.

    The flat-film form of the authors' camera kernel $κ = 1 / (1 - \cos(0.4 · \mathrm{pixel\ angle}))$
    (Loubet et al. 2019, Sec. 4.2), since $1 - \cos x ≈ x^2 / 2$.
    """
    return 2.0 / (0.4 * pixel_width) ** 2


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
    """

    def __init__(
        self, kappa: float, kappa_film: float, probes: int, spread: float, refine: int, paired: bool
    ):
        self.kappa, self.kappa_film, self.paired, self.refine = kappa, kappa_film, paired, refine
        # probe offsets in kernel standard deviations, evenly spaced over [-spread, spread], in order
        self.offsets = spread * (np.linspace(-1.0, 1.0, probes) if probes > 1 else np.zeros(1))

    def _choose(
        self, ctx: Context, origins: np.ndarray, centre_dirs: np.ndarray, probes: np.ndarray,
        trace: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    ) -> Choice:  # fmt: skip
        n, m = probes.shape
        prim, coord = trace(np.repeat(np.arange(n), m), probes.reshape(-1))
        return select_points(
            ctx.geom,
            origins,
            prim.reshape(n, m),
            coord.reshape(n, m),
            centre_dirs,
            probes,
            trace,
            self.refine,
        )

    def _again(
        self, ctx: Context, choice: Choice, rows: np.ndarray, extra: np.ndarray, origins: np.ndarray,
        centre_dirs: np.ndarray, probes: np.ndarray, trace: Callable[[np.ndarray, np.ndarray], Any],
    ) -> Choice:  # fmt: skip
        """``choice`` with ``rows`` chosen again from their probes plus the probe at ``extra`` (NaN: none)."""
        rows, extra = rows[np.isfinite(extra)], extra[np.isfinite(extra)]
        if not rows.size:
            return choice
        again = np.sort(np.concatenate([probes[rows], extra[:, None]], axis=1), axis=1)

        def trace_rows(r: np.ndarray, params: np.ndarray) -> Any:  # trace's rows index the full chunk
            return trace(rows[r], params)

        sub = self._choose(ctx, origins[rows], centre_dirs[rows], again, trace_rows)
        point, code = choice.point, choice.code.copy()
        point[rows], code[rows] = sub.point, sub.code
        return Choice(point, code)

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
        choice = self._choose(ctx, origins, dirs0, probes, trace)
        # nothing chosen, but a primitive's whole image lies between two probes: probe it too, choose again
        gap = np.flatnonzero(~choice.ok)
        extra = film_gap_probe(ctx.geom0, probes[gap])
        choice = self._again(ctx, choice, gap, extra, origins, dirs0, probes, trace)
        v = choice.point - geom.cam_o
        ok = choice.ok & (np.sum(detach(v) * detach(geom.cam_f), axis=1) > 0.0)
        t_p = film_coordinate(geom, np.where(ok[:, None], v, detach(geom.cam_f)))
        # T(t, θ) = t + t_p(θ) - t_p(θ0): value t, derivative t_p'   (Loubet et al. 2019, Sec. 3.2)
        points = mu + translation_offset(t_p, ok)[:, None]
        sq = (points - center[:, None]) ** 2
        # w = k(T y, ω) / detach(k(T y, ω)), log k = -κ/2 x² + const for the Gaussian   (Sec. 4.2)
        return Members(points, unit_weight(-0.5 * self.kappa_film * sq), self.paired, density)

    def directions(self, ctx: Context, x: Any, ignore: np.ndarray, phi: np.ndarray, draws: Draws) -> Members:
        kappa = self.kappa
        x0 = detach(x)
        if self.paired:  # ω = φ (the primary sample), members μ_j ~ vM(ω, κ)
            center = phi
            mu = sample_von_mises(draws.uniforms("kernel.directions.pair", 2), phi[:, None], kappa)
        else:  # reverse order: ω ~ vM(φ, κ), the member is φ itself
            center = sample_von_mises(draws.uniforms("kernel.directions"), phi, kappa)
            mu = phi[:, None]

        def trace(rows: np.ndarray, phi_probe: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            hits = cast(ctx.geom0, x0[rows], direction(phi_probe), ignore[rows])
            return hits.prim, hits.coord

        probes = center[:, None] + self.offsets / np.sqrt(kappa)  # σ = 1/√κ, the von Mises width
        dirs0 = direction(center)
        choice = self._choose(ctx, x0, dirs0, probes, trace)
        # nothing chosen, but a primitive's whole image lies between two probes: probe it too, choose again
        gap = np.flatnonzero(~choice.ok)
        extra = angle_gap_probe(ctx.geom0, x0[gap], ignore[gap], probes[gap])
        choice = self._again(ctx, choice, gap, extra, x0, dirs0, probes, trace)
        offset = choice.point - x
        # a chosen point on the shading point itself (coincident geometry) defines no direction: the
        # derivative of atan2 there is 0/0, so that sample keeps the identity transform
        ok = choice.ok & (np.hypot(*detach(offset).T) > EPS_DIST)
        angle = angle_of(np.where(ok[:, None], offset, dirs0))
        # T(φ, θ) = φ + angle(p(θ) - x(θ)) - its value: a translation of the angle, |det J| = 1   (Sec. 4.1)
        points = mu + translation_offset(angle, ok)[:, None]
        c = np.cos(points - center[:, None])
        # von Mises weight, log k = κ cos(T y - ω) + const   (Loubet et al. 2019, Sec. 4.2)
        return Members(points, unit_weight(kappa * c), self.paired)


@GRADIENT_METHODS.register(
    "reparam",
    Option("kappa", 1000.0, check_positive),
    Option("kappa_film", None, check_positive),
    Option("probes", 4, check_int),
    Option("spread", 3.0, partial(check_positive, allow_zero=True)),
    Option("refine", 2, partial(check_int, minimum=0)),
    Option("paired", False, check_bool),
)
def reparam(
    task: ImageTask | PointTask,
    kappa: float,
    kappa_film: float | None,
    probes: int,
    spread: float,
    refine: int,
    paired: bool,
) -> Tally:
    r"""Differentiate after translating every pixel and shading integral so its discontinuities stay put.

    Options
    -------
    kappa : float
        Von Mises concentration of the shading kernel (default 1000, $σ ≈ 1.8°$).
    kappa_film : float, optional
        1 / variance of the Gaussian film kernel; default :func:`default_kappa_film`.
    probes : int
        Probe rays per sample (default 4), evenly spaced over ±``spread`` kernel
        standard deviations around the kernel centre.
    spread : float
        Probe span in kernel standard deviations (default 3). The paper draws probes
        from the kernel itself; then for a lone edge all P probes land on the side
        away from it with probability $E[Φ(Z)^P] = 1 / (P + 1)$, a bias of 20% of the
        edge's term at P = 4 (measured). A span of $±3σ$ misses an isolated edge only
        beyond it, $2 (1 - Φ(3)) = 0.3\%$. Not so a primitive whose image is narrower than
        the probes' spacing ($2 · \mathrm{spread} / (\mathrm{probes} - 1)\, σ$, 0.57 px on the film at the
        defaults): it lies between two probes for most kernel centres, which lost
        $1 - \mathrm{width} / \mathrm{spacing}$ of its edge terms (measured 83 ± 36 % at 0.1 px, 57 ± 10 %
        at 0.2 px). On the film one more probe is then traced at its image
        (:func:`~flatland.probes.film_gap_probe`): a 0.2 px stick keeps its edge terms
        (tests/flatland/test_thin_occluder). Measured loss of a sideways-moving stick's
        derivative, 262144 spp at 8 positions across a pixel (± one standard error): 0.05 px
        -3.6 ± 5.1 %, 0.1 px -1.9 ± 2.6 %, 0.2 px -0.4 ± 1.3 %, 0.5 px -0.1 ± 0.5 %.
        Directions get the same probe (:func:`~flatland.probes.angle_gap_probe`; spacing
        $2 / \sqrt{κ} = 0.063$ rad), but there a thin primitive keeps a bias of another kind:
        seen from the shading point its image *stretches* as well as moves (its ends' angles
        $ψ = \arctan x$ move at different rates $1 / (1 + x^2)$), and one translation per kernel
        follows one rate. For a black stick at height 1 centred at $x = 0.3$ under the sky,
        $dE/dθ = -[\cos ψ\, ψ']_a^b$ owes 2/3 of its value to the ends' different rates and 1/3
        to their different cosines, so a kernel holding both ends loses up to 2/3. Measured
        loss of $dE/dθ$ (irradiance at the point, $2^{24}$ samples), without / with the gap
        probe: 0.02 rad 84 ± 17 / 44 ± 22 %, 0.04 rad 77 ± 14 / 51 ± 11 %; then, as the stick
        outgrows the kernel, 0.1 rad 30 ± 5 %, 0.2 rad 7.1 ± 1.8 %, 0.5 rad 4 ± 3 %, 1 rad 1 ± 2 %.
    refine : int
        Bisection steps toward the discontinuity the probes bracket (default 2;
        see :mod:`flatland.probes`).
    paired : bool
        Two evaluations share one transform and serve as each other's control
        variate (theory/kernels), at twice the cost per level. The kernel is then used in
        the paper's order (ω is the outer sample), so the value is a different
        estimate from the naive one. On the film $ω = t + σz$ with its closed-form
        density $k_j ⊛ g$ (sampling ω from $k_j$ itself would miss the blurred integrand
        outside a tent's support: measured 34% bias). For directions ω is the
        cosine or emitter sample; the blurred integrand reaching behind the horizon
        is then missed, a bias of order $1/κ$ relative ($\cos \sim σ$ there).

    Every film sample (pixel integral, translation of t) and every direction sample,
    cosine- or emitter-sampled (shading integral, translation of the angle), gets its
    own transform; the samples, their densities and the MIS weights stay the naive
    estimator's at θ0 (θ-free functions of the untransformed sample, which keeps the
    MIS decomposition exact for every θ). Unpaired, the transform's value is the
    identity: the image value equals the naive one bit for bit (Loubet et al. 2019, Sec. 3.2).

    Emitter samples: the authors used one transform per shading point, from the mean
    of the occluded shadow rays' hits, and emitters faded at their ends. Here each
    emitter sample gets its own kernel and probes like a cosine sample; fading still
    matters where the transform follows an occluder while an emitter's end (a
    discontinuity unless faded) lies within the kernel.

    Assumes a continuous pixel filter (a box filter's edges would become moving
    discontinuities, theory/pixel_filters: refused) and that one translation follows every
    discontinuity within a kernel. Biased where it does not: discontinuities moving
    differently inside one kernel (``two_occluders``), a wrong pick by the heuristic,
    an attached point moving unlike the silhouette (first order in its distance from
    it, exact under translation), an edge beyond the probes. The bias falls as the
    kernels narrow, while the variance of the weights' derivatives (about $\sqrt{κ}$ per
    affected sample) grows: the trade-off of Loubet et al. 2019, Sec. 4.2. The tent filter's
    log-derivative grows like $1 / \mathrm{distance}$ near its support's end (a mildly heavy
    tail); the Gaussian filter's does not.
    """
    if isinstance(task, ImageTask):
        check_continuous_filter(task.scene.camera.filter)
    if kappa_film is None:
        kappa_film = default_kappa_film(task.scene.camera.pixel_width)
    transforms = ReparamTransforms(kappa, kappa_film, probes, spread, refine, paired)
    return task.evaluate(variable(0.0), transforms)
