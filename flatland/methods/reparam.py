r"""Reparameterization of the pixel and shading integrals by translations chosen with probe rays.

Where the integrator calls it: one ``task.evaluate(task.dual_offset(), ReparamTransforms(...))``
(``variable(0.0)``, or ``variables(k)`` for k parameters: one pass whose translations follow the
chosen point's motion in all k directions at once).
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
from flatland.core.translation import check_continuous_filter
from flatland.core.validate import ValidationError, check_bool, check_int, check_positive
from flatland.methods._common import GRADIENT_METHODS
from flatland.reparam.default import ReparamTransforms, default_kappa_film
from flatland.reparam.lobe import LOBE, check_lobe
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
    Option("lobe", LOBE, check_lobe),
)
def reparam(
    task: ImageTask | PointTask,
    kappa: float,
    kappa_film: float | None,
    probes: int,
    spread: float,
    refine: int,
    paired: bool,
    lobe: float | None,
) -> Tally:
    r"""Differentiate after translating every pixel and shading integral so its discontinuities stay put.

    Options
    -------
    ================  ===========  ================================================  ==============
    option            default      meaning                                           values
    ================  ===========  ================================================  ==============
    ``kappa``         1000         von Mises concentration of the shading kernel     > 0
                                   (σ ≈ 1/√κ rad, 1.8° at the default)
    ``kappa_film``    0.28 px      1 / variance of the Gaussian film kernel;         > 0
                                   default :func:`default_kappa_film` (the
                                   authors' camera kernel, σ ≈ 0.28 pixel)
    ``probes``        4            probe rays per kernel, evenly spaced over         integer >= 1
                                   ±``spread`` kernel standard deviations
    ``spread``        3            the probes' span in kernel standard deviations    >= 0
    ``refine``        2            bisection steps toward the discontinuity the      integer >= 0
                                   probes bracket (:mod:`flatland.reparam.probes`)
    ``paired``        False        two evaluations share one transform and serve     bool
                                   as each other's control variate (theory/kernels)
    ``lobe``          1            at glossy points the kernel's κ per point: the    > 0; None:
                                   outermost probe within ``lobe`` × the GGX         ``kappa`` at
                                   lobe's median radius (κ the lower bound)          every point
                                   $r_l = 2 \arctan(α/\sqrt 3)$:
                                   $κ_x = \max(κ, (s / (λ r_l))^2)$,
                                   s = ``spread``, λ = ``lobe``
                                   (:mod:`flatland.reparam.lobe`)
    ================  ===========  ================================================  ==============

    Every film sample (pixel integral, translation of t) and every direction sample,
    cosine- or emitter-sampled (shading integral, translation of the angle), gets its
    own transform, chosen by probe rays inside its kernel (Loubet et al. 2019, Sec. 4.1-4.3);
    the samples, their densities and the MIS weights stay the naive estimator's at θ0
    (θ-free functions of the untransformed sample, which keeps the MIS decomposition exact
    for every θ). Unpaired, the transform's value is the identity: the image value equals the
    naive one bit for bit (Sec. 3.2). Paired, the kernel is used in the paper's order (ω is the
    outer sample), so the value is a different, unbiased estimate; on the film ω = t + σz
    with its closed-form density $k_j ⊛ g$ (sampling ω from $k_j$ itself would miss the
    blurred integrand outside a tent's support); for directions ω is the cosine or emitter
    sample, and the blurred integrand reaching behind the horizon is missed, a bias of order
    $1/κ$ relative.

    Probes span ±``spread`` σ rather than being drawn from the kernel, as the paper does: for a
    lone edge all P random probes land on the side away from it with probability
    $E[Φ(Z)^P] = 1 / (P + 1)$, a loss of that share of the edge's term; a span of $±3σ$ misses an
    isolated edge only beyond it. A primitive whose image is narrower than the probes' spacing
    lies between two probes for most kernel centres: one more probe is then traced at its
    image (:func:`~flatland.reparam.probes.film_gap_probe`,
    :func:`~flatland.reparam.probes.angle_gap_probe`). A shape of segments whose whole image
    (film interval or angle interval) lies inside the probes' span has both its ends followed by
    one piecewise-linear map (:func:`~flatland.reparam.probes.film_inner_shape`,
    :func:`~flatland.reparam.probes.angle_inner_shape`), and where one end of the followed
    shape's image lies inside the span, that endpoint is followed instead of the probes' hit
    (:func:`~flatland.reparam.probes.film_shape_end`,
    :func:`~flatland.reparam.probes.angle_shape_end`): exact whatever the shape's motion.

    Paths (``max_depth`` > 1): every vertex's integral gets the same change of variables (its cosine
    or BSDF sample and its emitter sample, each with its own kernel and probes from that vertex), and
    the path goes on along the BSDF sample where the transform put it: the next vertex is the hit of
    the warped direction re-attached to the θ-dependent scene, and the sample's kernel weight (value 1)
    multiplies the throughput, so everything gathered beyond the vertex carries its derivative, as in
    the authors' path reparameterization. ``paired`` is refused on paths (a path goes on along one
    evaluation point per sample). The weights' derivatives multiply along the path, so the variance
    grows with depth (tests/flatland/test_path_gradients.py measures it); the bias is that of each
    vertex's heuristic, as at depth 1.

    Emitter samples: the authors used one transform per shading point, from the mean of the
    occluded shadow rays' hits, and emitters faded at their ends. Here each emitter sample
    gets its own kernel and probes like a cosine sample; fading still matters where the
    transform follows an occluder while an emitter's end (a discontinuity unless faded)
    lies within the kernel.

    Assumes a continuous pixel filter (a box filter's edges would become moving
    discontinuities, theory/pixel_filters: refused) and that one translation follows every
    discontinuity within a kernel. Biased where it does not: discontinuities moving
    differently inside one kernel (``two_occluders``; a thin shape of segments is followed at
    both ends, but not a circle, nor two shapes in one kernel), a wrong pick by the
    heuristic, an attached point moving unlike the silhouette where the silhouette is not a segment's end (a
    circle's tangent point: first order in its distance from it, exact under translation), an
    edge beyond the probes. The bias falls as the kernels narrow,
    while the variance of the weights' derivatives (about $\sqrt{κ}$ per affected sample)
    grows: the trade-off of Sec. 4.2. The tent filter's log-derivative grows like
    $1 / \mathrm{distance}$ near its support's end (a mildly heavy tail); the Gaussian
    filter's does not. Sizes: the measurement pages.
    """
    if paired and task.max_depth > 1:
        raise ValidationError(
            "paired",
            f"must be False with max_depth > 1 (a path goes on along one evaluation point per sample, a "
            f"pair has two), got {paired!r} with max_depth {task.max_depth!r}",
        )
    if isinstance(task, ImageTask):
        check_continuous_filter(task.scene.camera.filter)
    if kappa_film is None:
        kappa_film = default_kappa_film(task.scene.camera.pixel_width)
    transforms = ReparamTransforms(kappa, kappa_film, probes, spread, refine, paired, lobe)
    return task.evaluate(task.dual_offset(), transforms)
