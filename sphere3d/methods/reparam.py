"""Reparameterization by rotations on S², with probe rays, vMF convolution and paired samples.

Where the integrator calls it: one ``task.evaluate(variable(0.0), ReparamTransforms(...))``.
``camera`` is called once per chunk for every camera sample, before the camera rays
are traced (the pixel integral's rotations, :mod:`sphere3d.camera_kernel`); ``emitter``
once per set of shading points, before the emitter samples' directions are rotated (the
emitter-sampling strategy);
``bsdf`` estimates the cosine-sampled strategy itself (vMF kernel, probes, paired
samples), calling back ``Shading.trace`` and ``Shading.evaluate_bsdf``. A
:class:`~sphere3d.tasks.PointTask` calls only ``emitter`` and ``bsdf``.

Loubet et al. 2019, Sec. 3.2 (change of variables), 4.1 (one rotation per integral),
4.2 (convolution kernels for integrands of large support), 4.3 (choosing the
rotation by ray tracing), and the paired-sample control variate of the authors'
implementation (theory/kernels).

Bias
----
Measured against the closed forms of :mod:`sphere3d.closed_form` by
``python -m benchmarks --only reparam_bias`` (defaults: κ = 1000, 4 probes (7 around a
kernel), spread 3; seed 11, 16 batches; ± one standard error); tested as biases in
``tests/sphere3d/test_triangle_closed_form.py``.

**Camera**: the film kernel's loss of a small triangle's silhouette term, in
:mod:`sphere3d.camera_kernel` (Bias).

**Shading: the cosine-sampled integral with the vMF kernel.** The irradiance at the origin
(normal +z) under a constant sky with a black triangle above it
(:func:`~sphere3d.closed_form.occluded_sky_irradiance`, Lambert's formula); share of $dE/dθ$
lost, $1 - d / g$. The triangle (-0.2, -0.5, 1), (0.9, 0.1, 1.1), (0.1, 0.6, 0.9) moves about
its centroid; "near the horizon": a large triangle whose lower edge lies 20, 10 or 5 degrees
above the horizon, its apex high (``horizon_triangle`` in the benchmark), moving sideways:

=====================================  ==========  ==================  ==================
case                                   samples     lost                before the snaps
=====================================  ==========  ==================  ==================
z-translation                          2^22        -1.0 % ± 0.9 %      5.4 % ± 0.7 %
x-translation                          2^24        0.0 % ± 1.5 %       4.8 % ± 1.3 %
scale                                  2^22        -1.1 % ± 0.8 %      5.1 % ± 0.6 %
rotation about x                       2^24        0.0 % ± 2.1 %       11.4 % ± 1.5 %
rotation about y                       2^24        2.2 % ± 1.5 %       4.6 % ± 1.3 %
near the horizon: 20°, 10°, 5°         2^22        1.4, 0.4, 0.0 %     4.6, 3.1, 2.9 %
``kappa=None``: z-translation, scale   2^22        100.9 %, 99.5 %     (± 0.1 %)
=====================================  ==========  ==================  ==================

Near the horizon ± 0.8, 0.6, 0.4 % (before ± 0.7, 0.5, 0.4 %). "Before": a ring of 3 probes, no
snap, no turn. Seed 11 is a low draw (z-translation, seeds 12-14: 0.7, 1.7, -0.2 ± 0.8 %); without
the samples' noise 0.5-2.5 % is lost, always short (:mod:`sphere3d.snaps`, Bias: its causes), and
``kappa=None`` (one rotation from cosine-distributed probes) is within 1 % of zero.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np

from flatland.core.contract import Option
from flatland.core.dual import detach, variable
from flatland.core.rng import Draws
from flatland.core.translation import check_continuous_filter, paired_combine, unit_weight
from flatland.core.validate import ValidationError, check_bool, check_int, check_positive
from sphere3d.camera_kernel import KAPPA_FILM, check_kappa_film, film_probes, film_transform
from sphere3d.emitter_probes import emitter_rotation
from sphere3d.film import FilmTransform
from sphere3d.integrator import Shading
from sphere3d.methods._common import GRADIENT_METHODS
from sphere3d.probes import (
    REFINE,
    follow_probes,
    ring_directions,
    vmf_spread_angle,
)
from sphere3d.rotation import Rotation
from sphere3d.sampling import (
    sample_cosine_hemisphere,
    sample_vmf,
    vmf_hemisphere_fraction,
)
from sphere3d.snaps import angle_snap
from sphere3d.state import SceneState
from sphere3d.tasks import ImageTask, PointTask, Tally
from sphere3d.vector import dot, scatter

__all__ = ["KAPPA_MAX", "ReparamTransforms", "reparam"]


@dataclass(frozen=True)
class ReparamTransforms:
    r"""The rotations of the three integrals of :mod:`sphere3d.integrator`.

    Attributes
    ----------
    kappa : float or None
        vMF concentration of the convolution kernel of the cosine-sampled integral, in
        (0, :data:`KAPPA_MAX`];
        None: no kernel, one rotation per sample from probes drawn from the cosine
        density itself (Sec. 4.1 over a support too large for it: biased).
    kappa_film : float
        1 / variance of the Gaussian film kernel of the pixel integral, $\mathrm{pixels}^{-2}$
        (:mod:`sphere3d.camera_kernel`).
    probes : int
        Probe rays per transform, >= 1: around a kernel the centre and a ring of 2 ``probes`` - 2
        (:func:`~sphere3d.camera_kernel.film_probes`); one probe (the centre) has no pair: its
        attached hit is followed, the identity where it misses (:mod:`sphere3d.probes`).
    spread : float
        Radius of the ring of probes around a kernel's centre, in kernel standard
        deviations (:mod:`sphere3d.probes`), >= 0: any value has a ring, whose angle
        grows to π (:func:`~sphere3d.probes.vmf_spread_angle`); on the film, in film
        kernel standard deviations.
    refine : int
        Bisection rays that move a single probe's hit toward the silhouette next to
        it, >= 0 (:func:`~sphere3d.probes.select_points`).
    paired : bool
        Two kernel samples per outer sample share one rotation (theory/kernels).
    emitter_edges : bool
        Add the boundary term of the emitters' sharp edges to the emitter strategy
        (:mod:`sphere3d.emitter_edges`), which holds them fixed under its rotation.
    film_one_plane : bool
        The identity for a camera sample whose film probes all hit one plane of a
        flat-shaded shape (:func:`~sphere3d.camera_kernel.one_plane`; module
        :mod:`sphere3d.camera_kernel`, Noise).
    film_junctions : bool
        Where a camera sample's film probes see a moving silhouette cross a static edge,
        follow their crossing (:mod:`sphere3d.junctions`).
    """

    kappa: float | None
    kappa_film: float
    probes: int
    spread: float
    refine: int
    paired: bool
    emitter_edges: bool = True
    film_one_plane: bool = True
    film_junctions: bool = True

    def camera(self, state: SceneState, x: np.ndarray, y: np.ndarray, draws: Draws) -> FilmTransform:
        """Pixel integral: one rotation per camera sample from probes around its film kernel's centre."""
        return film_transform(
            state, x, y, draws, self.kappa_film, self.probes, self.spread, self.refine, self.film_one_plane,
            self.film_junctions,
        )  # fmt: skip

    def emitter(self, shading: Shading) -> Rotation:
        """Emitter sampling: one rotation per shading point from shadow probes (Sec. 4.3), following
        the occluder's silhouette between a shadowed and a lit probe
        (:func:`~sphere3d.emitter_probes.emitter_rotation`). The emitters' sharp edges are held
        fixed under it (``emitter_edges``)."""
        return emitter_rotation(shading, self.probes)

    def _probe_rotation(self, shading: Shading, centre: np.ndarray) -> Rotation:
        """One rotation per shading point from a ring of probes around the kernel ``centre``.

        Without a kernel (``kappa`` None) the probes are drawn from the cosine lobe instead.
        """
        snap = None
        if self.kappa is None:
            d = sample_cosine_hemisphere(
                shading.draws.uniforms("probes.bsdf", self.probes, 2), detach(shading.n)[:, None]
            )
        else:
            phase = shading.draws.uniforms("probes.bsdf.ring")
            ring = vmf_spread_angle(self.kappa, self.spread)
            # the centre and a ring of 2 probes - 2, as on the film: edges within cos(π/6) of the ring
            d = ring_directions(centre, ring, film_probes(self.probes), phase)
            # onto the edge, or its corner up to twice the ring's radius away (as on the film)
            snap = angle_snap(shading.state, centre, 2.0 * ring)
        hits = shading.state.tracer.intersect(shading.origin[:, None], d)
        # a probe below the horizon sees only the surface it leaves, where the integrand is 0
        # (cos θ < 0), not a discontinuity: it counts as a miss rather than as a point at distance ~ε
        normal = detach(shading.n)
        hits = hits.without(dot(d, normal[:, None]) <= 0.0)
        spin = None if self.kappa is None else (centre, 1.0 / np.sqrt(self.kappa))
        return follow_probes(
            shading.state, shading.x, shading.origin, d, hits, normal, self.refine, snap, spin
        )

    def _kernel_weight(self, rotated: Any, centre: np.ndarray) -> Any:
        r"""$w = k(Rμ, ω) / \mathrm{detach}(k(Rμ, ω))$ in log space: value exactly 1
        (Loubet et al. 2019, Sec. 4.2)."""
        return unit_weight(self.kappa * dot(rotated, centre))  # the vMF normalization cancels in the ratio

    def bsdf(self, shading: Shading, mu: np.ndarray, pdf: np.ndarray) -> Any:
        """Cosine-sampled integral, reparameterized (with a vMF kernel unless ``kappa`` is None)."""
        if self.paired:  # evaluated at the two members only: μ itself is not traced
            return self._paired(shading, mu, pdf)
        hits = shading.trace(mu)
        # samples whose integrand is 0 with zero derivative need no rotation (and no probes)
        live = np.flatnonzero(shading.contributes(mu, hits))
        sub, mu_l, hits_l = shading.take(live), mu[live], hits.take(live)
        if self.kappa is None:
            rotated = self._probe_rotation(sub, mu_l).apply(mu_l)
            est = sub.evaluate_bsdf(mu_l, rotated, hits_l) / pdf[live]
        else:
            # kernel centre ω ~ k(·, μ) around the primary sample μ: the joint density of (μ, ω) is
            # the paper's "ω ~ p, μ ~ k(·, ω)" read the other way (k symmetric), and μ stays the
            # naive sample, so the primal is bit-identical to the naive one
            centre = sample_vmf(sub.draws.uniforms("kernel.bsdf", 2), mu_l, self.kappa)
            rotated = self._probe_rotation(sub, centre).apply(mu_l)
            # f(Rμ) k(Rμ, ω) / (p(μ) k(μ, ω)): value f(μ)/p(μ), derivative with the kernel factor (Sec. 4.2)
            est = sub.evaluate_bsdf(mu_l, rotated, hits_l) * self._kernel_weight(rotated, centre) / pdf[live]
        return scatter(len(mu), live, est, shading.state.dual)

    def _paired(self, shading: Shading, mu: np.ndarray, pdf: np.ndarray) -> Any:
        r"""The paper's order: outer $ω = μ \sim p$, two kernel samples share one rotation
        (theory/kernels)."""
        rotation = self._probe_rotation(shading, mu)
        u = shading.draws.uniforms("kernel.bsdf.pair", 2, 2)
        e, w = [], []
        for j in range(2):  # the two members of each pair (not a loop over samples)
            member = sample_vmf(u[:, j], mu, self.kappa)
            rotated = rotation.apply(member)
            weight = self._kernel_weight(rotated, mu)  # |w| < SMALL_WEIGHT counts as 1 in paired_combine
            w.append(weight)
            # centres ω are cosine samples, confined to the hemisphere: 1 / C(n·Rμ) restores the kernel
            # mass that lies below the horizon, ∫_H k(y, ω) dω = C(n·y)   (sampling.vmf_hemisphere_fraction)
            mass = vmf_hemisphere_fraction(dot(rotated, detach(shading.n)), self.kappa)
            mass = np.where(detach(mass) > 0.0, mass, 1.0)  # C = 0 only far below the horizon, where f = 0
            e.append(shading.evaluate_bsdf(member, rotated, shading.trace(member)) * weight / (pdf * mass))
        # each weight's derivative has zero mean given ω and is independent of the other member:
        # a control variate scaled by the other member's estimate   (paired samples, theory/kernels)
        return paired_combine(e[0], e[1], w[0], w[1])


KAPPA_MAX = 1e15
"""Largest vMF concentration: the kernel's width shows in cosines near 1 as 1 - cos σ = 1/(2κ),
which float64 resolves only down to about 1e-16 (κ = 1e15: 5e-16). Beyond it the samples and the
weight κ (Rμ·ω - 1) are rounding; at κ = 1e300 the weight's derivatives overflowed the variance."""


def _check_kappa(name: str, value: Any) -> float | None:
    """0 < κ <= :data:`KAPPA_MAX`, or None for no convolution kernel."""
    if value is None:
        return None
    kappa = check_positive(name, value)
    if kappa > KAPPA_MAX:
        raise ValidationError(
            name,
            f"must be <= {KAPPA_MAX:g} (narrower kernels are below float64's resolution), got {value!r}",
        )
    return kappa


@GRADIENT_METHODS.register(
    "reparam",
    Option("kappa", 1000.0, _check_kappa),
    Option("kappa_film", KAPPA_FILM, check_kappa_film),
    Option("probes", 4, check_int),  # an integer >= 1; one probe has no pair and stands alone
    Option("spread", 3.0, partial(check_positive, allow_zero=True)),
    Option("refine", REFINE, partial(check_int, minimum=0)),
    Option("paired", False, check_bool),
    Option("emitter_edges", True, check_bool),
    Option("film_one_plane", True, check_bool),
    Option("film_junctions", True, check_bool),
)
def reparam(
    task: ImageTask | PointTask,
    kappa: float | None,
    kappa_film: float,
    probes: int,
    spread: float,
    refine: int,
    paired: bool,
    emitter_edges: bool,
    film_one_plane: bool,
    film_junctions: bool,
) -> Tally:
    r"""Rotate the samples of every integral so that the discontinuity they straddle stops moving.

    Each integral's samples ω are evaluated at $R(θ)·ω$, R the identity at θ0 that moves
    like one chosen occluder point (Loubet et al. 2019, Sec. 4.1), $|\det J| = 1$:

    - **pixel integral** (support: the filter footprint): the Gaussian film kernel of
      concentration ``kappa_film`` (default the authors' camera kernel, $σ ≈ 0.28$ px),
      an antithetic pair of kernel centres per camera sample, each with its rotation
      from :func:`~sphere3d.camera_kernel.film_probes` probes on a ring around it
      (:mod:`sphere3d.camera_kernel`, Sec. 4.2, 4.3). The filter and kernel weights carry
      the derivative of $k·J·g$ under the rotation, with a zero-mean control variate
      (:class:`~sphere3d.tasks.ImageTask`); it needs a continuous filter (tent,
      gaussian): with ``box`` the footprint's edge would move and bias the gradient
      (theory/pixel_filters), so a box filter is refused, as in flatland.
    - **emitter sampling**: one rotation per shading point from ``probes`` shadow probes on
      the emitters' area and 8 along their edges (:mod:`sphere3d.emitter_probes`): where some
      are occluded and some not, the occluder's silhouette point bisected between the
      closest such pair; where all are, the mean attached occluded hit (the authors'
      implementation); else the mean attached probe point on the emitters. Where the probes
      hold no such pair, two more aimed at where the occluder's shadow first or last covers
      the light look for it (:data:`~sphere3d.emitter_probes.AIM`). The
      emitters' sharp edges are held fixed: ``emitter_edges`` (default True) adds their
      boundary term (:mod:`sphere3d.emitter_edges`, theory/probes), so a 0.6 × 0.4 light
      moving sideways 1.5 above a point gets -0.3003 ± 0.0019 (exact -0.3007; 73 % lost
      without the term, tests/sphere3d/test_closed_forms.py). Still biased where the
      rotation does not hold an occluder's shadow edge still (occluders moving
      differently, or one whose outline lies at several depths).
    - **cosine sampling** (support: the hemisphere): the vMF convolution of Sec. 4.2
      with concentration ``kappa``: a kernel centre $ω \sim \mathrm{vMF}(μ, κ)$ per sample, the
      centre and a ring of 2 ``probes`` - 2 probes ``spread`` kernel widths around it, the hit
      snapped onto its edge or corner and the rotation turned with that edge
      (:mod:`sphere3d.snaps`), weight $k(Rμ, ω) / \mathrm{detach}(k(Rμ, ω))$. Biased where a
      kernel's probes all miss a discontinuity (near corners) or its rotation does not follow it
      (a corner's edges turning differently): 1-2 % lost under a black triangle (Bias); the bias
      falls as κ grows, the variance near an edge grows like $\sqrt{κ}$. ``kappa=None``: no
      kernel, cosine-distributed probes, one rotation for the hemisphere (all but lost, for study).

    ``refine`` (an integer >= 0, default :data:`~sphere3d.probes.REFINE` = 3): where the
    followed point is one probe's hit and its partner sees something else (camera and
    cosine-sampling rotations), ``refine`` bisection rays first move that hit toward
    the silhouette between the two probes (:func:`~sphere3d.probes.select_points`);
    0 follows the probe's own hit. flatland's option of the same name defaults to 2.

    Measured bias on the ``hard_shadow`` benchmark scenes (a sharp, ``fade`` 0 light;
    d/d ``occluder.translate.x``, default options and film, 8 seeds x 128 spp against the
    Richardson finite-difference reference of ``benchmarks/reference``; regions as in
    ``tests/sphere3d/test_hard_shadow.py``), as the least-squares fraction of the
    reference kept, $Σ g·\mathrm{ref} / Σ \mathrm{ref}^2$, and the bias floor (the rms
    per-pixel bias over the image, noise subtracted, ``make bench``: 6 seeds at 256 spp):

    ================  ===========================  ===========================
    region            sphere occluder              cube occluder
    ================  ===========================  ===========================
    penumbra          99.7 ± 0.3 % kept            99.7 ± 0.3 % kept
    silhouette        99.6 ± 0.5 % kept            99.4 ± 0.5 % kept
    occluder          99.2 ± 1.4 % kept            99.3 ± 0.9 % kept
    bias floor        0.027                        0.024
    ================  ===========================  ===========================

    How it got there (bias floor sphere / cube): 0.31 / 0.38 as published, the emitter
    rotation following the occluder and dragging the light's sharp edge (the penumbra kept
    3.2 / 3.3 %); the emitters' edge term (``emitter_edges``) and the per-sample film kernel,
    0.088 / 0.155; the identity on one face of the cube (``film_one_plane``), cube 0.109; the
    emitter rotation following the shadow edge between a shadowed and a lit probe, with probes
    along the light's edges (:mod:`sphere3d.emitter_probes`), 0.035 / 0.018 on the same 2 seeds,
    0.086 / 0.092 on 6 (splatted, the steadier estimate: 0.058 / 0.074); the film kernels following
    the junction where the occluder's silhouette crosses the ground's far edge
    (:mod:`sphere3d.junctions`, ``film_junctions``), 0.028 / 0.025 (splatted; the silhouette kept
    97.0 ± 0.8 / 97.7 ± 0.5 % before). The old rule
    (the mean occluded probe hit) kept 98.4 / 102.9 % of the penumbra only because point-by-point
    errors of -45 % to +60 % cancelled. That rule's replacement costs 60-80 % more CPU time per
    image (process time, old and new alternating in one run: 0.95-1.25 → 1.69-1.96 s per 64 spp)
    and 1.5 % more variance; a 64 spp image now takes 0.73-0.91 / 0.94-0.99 s of wall time on an
    idle 2-core machine (``make bench``, two runs), RMSE at 16 / 64 / 256 spp 0.96 / 0.49 / 0.26 and
    1.21 / 0.60 / 0.30 with the per-pixel film (``film="pixel"``); with the splatted film
    (:mod:`sphere3d.film`, since the default) 0.42 / 0.22 / 0.12 and 0.49 / 0.26 / 0.15. With the
    junctions, the aimed emitter probes and the speed-ups that leave every image bit-identical:
    0.445 / 0.51 s per 64 spp, RMSE 0.41 / 0.21 / 0.10 and 0.49 / 0.24 / 0.13 (``make bench``); with
    4 probes on the light's edges (:mod:`sphere3d.emitter_probes`) and the culls of
    :mod:`sphere3d.penumbra` and of the film rings, 0.40 / 0.42 s, the same RMSE. With the
    per-pixel film, before the junctions, the fractions were 99.0 ± 0.3 / 99.8 ± 0.3 % (penumbra), 98.1 ± 1.4
    / 99.3 ± 1.0 % (silhouette), 109 ± 6 / 98.4 ± 1.9 % (occluder).
    What remains in the penumbra is the cosine strategy's loss near the light's edge (its rotation
    follows the occluder and drags that edge: -1 to -3.5 % of the derivative at penumbra points)
    and, on the cube, two shadow edges at different depths that one rotation cannot both follow
    (+7 % at one point).
    The silhouette loss sat where the occluder's silhouette and the ground's far edge
    share a film kernel, until the kernels followed their crossing (:mod:`sphere3d.junctions`). On
    the cube's faces the error has both signs (the edges between faces inside a footprint); the lit
    ground and the umbra have none. ``tests/sphere3d/test_hard_shadow.py`` tests these
    fractions.

    Samples whose integrand is 0 with a zero derivative whatever the rotation (a
    shadow ray blocked, a cosine ray hitting a dark surface) get no probes. The
    primal is bit-identical to ``naive``'s for the same seed, except with
    ``paired=True`` (needs ``kappa``): then the outer sample is the cosine sample, two
    kernel samples around it share the rotation, and the control variate of the
    authors' implementation (theory/kernels) reduces the variance of the kernel weights; the
    kernel mass below the horizon is restored by :func:`~sphere3d.sampling.vmf_hemisphere_fraction` (a
    different, still unbiased primal, at twice the rays per sample).
    """
    if isinstance(task, ImageTask):
        check_continuous_filter(task.scene.camera.filter)
    if paired and kappa is None:
        raise ValidationError("paired", "needs a convolution kernel: pass kappa > 0 as well")
    return task.evaluate(
        variable(0.0),
        ReparamTransforms(
            kappa, kappa_film, probes, spread, refine, paired, emitter_edges, film_one_plane, film_junctions
        ),
    )
