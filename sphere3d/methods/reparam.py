"""The ``reparam`` method: rotations chosen by probe rays, vMF convolution kernels, paired samples.

Where the integrator calls it: one ``task.evaluate(task.dual_offset(), transforms)`` (``variable(0.0)``,
or ``variables(k)`` for k parameters: the rotations follow the chosen points' motion in all k directions
at once, :mod:`sphere3d.rotation`) with the
variant's :class:`~sphere3d.integrator.Transforms`: :class:`~sphere3d.reparam.paper.PaperTransforms`
(the estimator as published, Loubet et al. 2019, Sec. 4.1-4.3) or
:class:`~sphere3d.reparam.default.ReparamTransforms` (the default: the paper's estimator and the
extensions listed in the theory page *extensions*). ``camera`` is called once per chunk for
every camera sample, ``emitter`` once per set of shading points, ``bsdf`` once per set of
cosine samples; a :class:`~sphere3d.tasks.PointTask` calls only ``emitter`` and ``bsdf``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from functools import partial
from typing import Any

import numpy as np

from flatland.core import progress
from flatland.core.budget import Term
from flatland.core.contract import Option
from flatland.core.translation import check_continuous_filter
from flatland.core.validate import ValidationError, check_bool, check_choice, check_int, check_positive
from sphere3d.boundary.emitters import POINTS
from sphere3d.methods._common import GRADIENT_METHODS, direct_only, memory_model
from sphere3d.reparam.bisection import pair_bytes, pair_rows
from sphere3d.reparam.default import ReparamTransforms
from sphere3d.reparam.emitter_probes import PROBES as EMITTER_PROBES
from sphere3d.reparam.emitter_probes import probe_rays, row_probes
from sphere3d.reparam.film_kernel import KAPPA_FILM, check_kappa_film
from sphere3d.reparam.lobe import LOBE, check_lobe
from sphere3d.reparam.paper import PaperTransforms
from sphere3d.reparam.probes import REFINE
from sphere3d.tasks import ImageTask, PointTask, Tally

__all__ = ["KAPPA_MAX", "PROBES", "VARIANTS", "memory", "reparam"]

VARIANTS = ("default", "paper")
"""``variant`` values: the default (the paper's estimator and its extensions), the paper's as published."""
PROBES = {"default": 7, "paper": 4}
"""Probe rays per kernel when ``probes`` is not given: a centre and a ring of 6 (default variant),
4 drawn from the kernel (the authors')."""
KAPPA_MAX = 1e15
"""Largest vMF concentration: the kernel's width shows in cosines near 1 as 1 - cos σ = 1/(2κ),
which float64 resolves only down to about 1e-16 (κ = 1e15: 5e-16); beyond it the samples and the
weight κ (Rμ·ω - 1) are rounding."""
_DEFAULT_ONLY = {"spread": 3.0, "refine": REFINE, "paired": False, "baseline": True, "lobe": LOBE}
"""Options of the default variant only, with their defaults (the paper variant has none of them)."""


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
    Option("variant", "default", partial(check_choice, choices=VARIANTS)),
    Option("kappa", 1000.0, _check_kappa),
    Option("kappa_film", KAPPA_FILM, check_kappa_film),
    Option("probes", None, check_int, "7; 4 for variant 'paper'"),  # an integer >= 1; None: PROBES[variant]
    Option("emitter_probes", EMITTER_PROBES, check_int),
    Option("spread", 3.0, partial(check_positive, allow_zero=True)),
    Option("refine", REFINE, partial(check_int, minimum=0)),
    Option("paired", False, check_bool),
    Option("baseline", True, check_bool),
    Option("lobe", LOBE, check_lobe),
)
def reparam(
    task: ImageTask | PointTask,
    variant: str,
    kappa: float | None,
    kappa_film: float,
    probes: int | None,
    emitter_probes: int,
    spread: float,
    refine: int,
    paired: bool,
    baseline: bool,
    lobe: float | None,
) -> Tally:
    r"""Rotate the samples of every integral so that the discontinuity they straddle stops moving.

    Each integral's samples ω are evaluated at $R(θ)·ω$, R the identity at θ0 that moves
    like one chosen occluder point (Loubet et al. 2019, Sec. 4.1), $|\det J| = 1$; integrands
    of large support are convolved with narrow kernels first (Sec. 4.2); the point is chosen by
    probe rays (Sec. 4.3). The value is ``naive``'s, bit for bit, except with paired samples
    (the paper variant, or ``paired=True``): their kernel samples are evaluated instead of the
    cosine sample, a different, still unbiased primal.

    Options
    -------
    ====================  =========  =================================================  ======================
    option                default    meaning                                            values
    ====================  =========  =================================================  ======================
    ``variant``           default    ``"paper"``: the estimator as published            ``"default"``,
                                     (:mod:`sphere3d.reparam.paper`); ``"default"``:    ``"paper"``
                                     with the extensions (theory page *extensions*)
    ``kappa``             1000       vMF concentration of the cosine strategy's         (0, 1e15]; None: no
                                     kernel (width about 1/√κ rad)                      kernel (default
                                                                                        variant, for study)
    ``kappa_film``        12.5       1 / variance of the Gaussian film kernel,          (0, 1e12]
                                     px⁻² (the authors' camera kernel, σ ≈ 0.28 px)
    ``probes``            7 / 4      probe rays per kernel (film and cosine             integer >= 1
                                     strategy): a centre and a ring (default), drawn
                                     from the kernel (paper)
    ``emitter_probes``    4          shadow probes per shading point uniform on the     integer >= 1
                                     emitters' area
    ``spread``            3          radius of the probe ring in kernel standard        >= 0
                                     deviations (default variant)
    ``refine``            3          bisection rays moving a single probe's hit         integer >= 0
                                     toward the silhouette (default variant)
    ``paired``            False      two kernel samples share one rotation in the       bool
                                     cosine strategy (default variant; the paper
                                     variant always pairs)
    ``baseline``          True       the cosine strategy's control variate: the         bool
                                     kernel weights' score scaled by the radiance
                                     the kernel's centre sees (theory/kernels;
                                     default variant)
    ``lobe``              1          at glossy points the kernel's κ per point: its     > 0; None:
                                     probe ring within ``lobe`` × the GGX lobe's        ``kappa`` at
                                     median radius (κ the lower bound)                  every point
                                     $r_l = 2 \arctan(α) \cos θ_i$:
                                     $κ_x = \max(κ, κ_l)$,
                                     $κ_l = s^2 / (2 (1 - \cos(λ r_l)))$,
                                     s = ``spread``, λ = ``lobe``
                                     (:mod:`sphere3d.reparam.lobe`; default variant)
    ====================  =========  =================================================  ======================

    Constants of the default variant that change results, each in the module that uses it:
    the emitter strategy's probes along the emitters' edges
    (:data:`~sphere3d.reparam.emitter_probes.BOUNDARY`, 4), its aimed probes
    (:data:`~sphere3d.reparam.emitter_probes.AIM`, 2) and bisection rays
    (:data:`~sphere3d.reparam.emitter_probes.REFINE`, 6); the emitter edges' points per shading
    point (:data:`~sphere3d.boundary.emitters.POINTS`, 2); the probe rule's parallel-normal
    threshold (:data:`~sphere3d.reparam.paper.PARALLEL`, 0.99, the paper's) and its degenerate
    determinant (:data:`~sphere3d.reparam.paper.DEGENERATE`); the one-plane tolerance
    (:data:`~sphere3d.reparam.film_kernel.COPLANAR`). Constants that only skip work whose
    result is known (the penumbra cull's :data:`~sphere3d.reparam.penumbra.MARGIN` and
    :data:`~sphere3d.reparam.penumbra.PLANES`, the film hull's
    :data:`~sphere3d.reparam.film_kernel.HULL_MARGIN`) change no expectation.

    Assumes a continuous pixel filter (``tent``, ``gaussian``): with ``box`` the footprint's
    edge moves under the rotation and biases the gradient (theory/pixel_filters), so it is
    refused. On paths (``max_depth`` > 1) every vertex's shading integral gets the same changes of
    variables at the vertex's points and the path goes on along the rotated sample, its throughput
    carrying the kernel weight, with a control variate of the radiance it carries
    (:mod:`sphere3d.path_changes`; ``baseline=False`` drops it); paired kernel samples (``paired``,
    the paper variant) are refused there. Biased where one rotation cannot follow every discontinuity
    inside a kernel, or the probes miss one: the paper variant's cases are in
    :mod:`sphere3d.reparam.paper`, what each extension removes and what remains in the theory page
    *extensions*, the measured biases in the generated measurement pages (on paths: theory/radiometry).
    """
    if task.max_depth > 1 and (variant == "paper" or paired):
        # paired kernel members are traced along their own directions: no single one for a path to go on
        what = "variant 'paper' (it pairs kernel samples)" if variant == "paper" else "paired=True"
        direct_only(task, f"reparam with {what}", "paired kernel samples")
    if paired and any(shape.roughness is not None for shape in task.scene.shapes):
        raise ValidationError("paired", "is not supported on glossy shapes (roughness), got True")
    if isinstance(task, ImageTask):
        check_continuous_filter(task.scene.camera.filter)
    if paired and kappa is None:
        raise ValidationError("paired", "needs a convolution kernel: pass kappa > 0 as well")
    probes = PROBES[variant] if probes is None else probes
    if variant == "paper":
        given = {"spread": spread, "refine": refine, "paired": paired, "baseline": baseline, "lobe": lobe}
        for name, value in given.items():
            if value != _DEFAULT_ONLY[name]:
                raise ValidationError(name, f"is an option of variant 'default', not 'paper', got {value!r}")
        if kappa is None:
            raise ValidationError("kappa", "the paper variant convolves: pass kappa > 0")
        transforms: Any = PaperTransforms(kappa, kappa_film, probes, emitter_probes)
    else:
        transforms = ReparamTransforms(
            kappa, kappa_film, probes, emitter_probes, spread, refine, paired, baseline=baseline, lobe=lobe
        )
        if task.k is not None:  # the extensions choose by what moves: one pass per moving thing
            return _by_motion(task, transforms)
    return task.evaluate(task.dual_offset(), transforms)


def _moves(name: str) -> str | None:
    """What a parameter moves: its shape (or the camera) for a translation, rotation, scale or shape
    coefficient; None for a radiance (albedo, emission, the sky), which moves no discontinuity."""
    owner, _, rest = name.partition(".")
    return owner if rest.partition(".")[0] in ("translate", "rotate", "scale", "shape") else None


def _by_motion(task: ImageTask | PointTask, transforms: Any) -> Tally:
    """The default variant for k parameters: one pass per shape (or the camera) that the parameters
    move, with all the parameters that move nothing (their slots the same in every pass: they follow
    no motion), so that each parameter gets the changes of variables of its single call.

    The default variant's extensions decide by what moves: a T-junction is a moving silhouette across
    a *static* edge (:mod:`sphere3d.reparam.junctions`), an affine map follows the nearest *moving*
    shape (:mod:`sphere3d.reparam.film_affine`, :mod:`sphere3d.reparam.film_corners`,
    :mod:`sphere3d.reparam.shading_affine`), the aimed emitter probes look at the moving occluders
    (:mod:`sphere3d.reparam.emitter_probes`). Under parameters that move different shapes a single pass
    would take "moving" as "moving under any of them", and a parameter would then follow, or hold
    still, another's motion (its slot would drag its own edge). The parameters of one shape move the
    same triangles, so a list of one shape's parameters (``hard_shadow``'s occluder: translations,
    rotations, scale, albedo) is one pass. The value is the same in every pass (the naive primal).
    """
    names = task.parameters()
    groups: dict[str, list[str]] = {}
    for name in names:
        if _moves(name) is not None:
            groups.setdefault(_moves(name), []).append(name)
    still = [name for name in names if _moves(name) is None]
    passes = [tuple(group + still) for group in groups.values()] or [tuple(still)]
    progress.expect(len(passes))  # every pass: the bar's total counts them all
    derivative: dict[str, Any] = {}
    tallies = []
    for group in passes:
        sub = replace(task, param=group)
        tallies.append(sub.evaluate(sub.dual_offset(), transforms))
        for name, d in zip(group, tallies[-1].derivative, strict=True):
            derivative.setdefault(name, d)
    return Tally(tallies[0].value, np.stack([derivative[name] for name in names]))


@memory_model("reparam")
def memory(task: ImageTask | PointTask, options: Mapping[str, Any]) -> tuple[Term, ...]:
    r"""Memory model of :func:`reparam`: what ``probes`` (P) and ``emitter_probes`` (E) add to a sample.

    Rays per sample beyond its camera ray and two shading rays, each an upper estimate: the film
    kernel's P probes and 3R bisection rays (toward a silhouette, and a junction's two edges,
    :mod:`sphere3d.reparam.junctions`), the cosine strategy's P probes and R bisection rays per kernel
    sample (twice with ``paired``), the emitter strategy's
    :func:`~sphere3d.reparam.emitter_probes.probe_rays` and its
    :data:`~sphere3d.boundary.emitters.POINTS` edge points (R = ``refine``). At once: one slice of
    probe-pair tables (:func:`~sphere3d.reparam.bisection.pair_bytes`), rows of P film probes
    (junctions) and of :func:`~sphere3d.reparam.emitter_probes.row_probes` shadow probes, p² pairs a
    row. The paper variant traces P film probes, P cosine probes and a second kernel sample (it pairs
    every cosine sample) and E shadow probes, and has no pairs, no bisection.
    """
    variant = options.get("variant", "default")
    p = options.get("probes") or PROBES[variant]
    e = options.get("emitter_probes", EMITTER_PROBES)
    if variant == "paper":
        probes = Term("probes", p, "probes per kernel", sample_rays=2 * p + 1)
        return probes, Term("emitter_probes", e, "shadow probes per shading point", sample_rays=e)
    r = options.get("refine", 0)
    film = isinstance(task, ImageTask)
    rays = (p + 3 * r if film else 0) + (p + r) * (2 if options.get("paired") else 1)
    film_pairs = pair_bytes(p) if film else 0.0
    probes = Term(
        "probes", p, "probes per kernel", f"{pair_rows(p)} × {p}² film probe pairs", film_pairs, rays
    )
    q = row_probes(e)
    shadow_pairs = f"{pair_rows(q)} × {q}² shadow probe pairs"
    rays = probe_rays(e) + POINTS
    return probes, Term(
        "emitter_probes", e, "shadow probes per shading point", shadow_pairs, pair_bytes(q), rays
    )
