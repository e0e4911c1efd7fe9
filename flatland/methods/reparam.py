r"""Reparameterization of the pixel and shading integrals by translations chosen with probe rays.

Where the integrator calls it: one ``task.evaluate(variable(0.0), ReparamTransforms(...))``.
``camera`` gets each chunk's film samples
$t \sim k_j$ before the camera rays are traced and returns the translated points $T(t)$ with
kernel weights; ``directions`` gets the cosine and emitter samples φ inside
:func:`~flatland.integrator.shade`, before the shading rays are traced, and returns
$T(φ)$ likewise; both choose the translation with :mod:`flatland.reparam.probes`.
The 2D-only extras stay ``None``.

Loubet et al. 2019: Sec. 3.2 (change of variables), 4.1 (in 2D a rotation of
directions is a translation of the angle, and the film is a line), 4.2 (convolution
kernels), 4.3 (choosing the transform by ray tracing,
:mod:`flatland.reparam.probes`), and the paired samples of the authors'
implementation (theory/kernels).
"""

from __future__ import annotations

from functools import partial

from flatland.core.contract import Option
from flatland.core.dual import variable
from flatland.core.translation import check_continuous_filter
from flatland.core.validate import check_bool, check_int, check_positive
from flatland.methods._common import GRADIENT_METHODS
from flatland.reparam.default import ReparamTransforms, default_kappa_film
from flatland.tasks import ImageTask, PointTask, Tally

__all__ = ["reparam"]


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
        (:func:`~flatland.reparam.probes.film_gap_probe`): a 0.2 px stick keeps its edge terms
        (tests/flatland/test_thin_occluder). Measured loss of a sideways-moving stick's
        derivative, 262144 spp at 8 positions across a pixel (± one standard error): 0.05 px
        -3.6 ± 5.1 %, 0.1 px -1.9 ± 2.6 %, 0.2 px -0.4 ± 1.3 %, 0.5 px -0.1 ± 0.5 %.
        Directions get the same probe (:func:`~flatland.reparam.probes.angle_gap_probe`; spacing
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
        see :mod:`flatland.reparam.probes`).
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
