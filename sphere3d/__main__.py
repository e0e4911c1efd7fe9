"""``python -m sphere3d demo | render SCENE | gradient SCENE | study CONFIG | optimize SCENE`` (see
:mod:`flatland.app.cli`).

The same verbs, options and error behaviour as ``python -m flatland``. The demo's
panel shows ``naive``, ``boundary`` (edge sampling), ``reparam`` and ``finite_difference``;
its reference is ``boundary`` (unbiased, and on a whole film the most precise of the four)
at 20 × the demo's samples per pixel: a reference must have at most 1/4 of the standard
error of the most precise unbiased method it judges, here boundary itself (20, not 16: at 16
the expected ratio is 1/4 exactly, and half the runs would grow the reference further).

A study's default reference stays a finite-difference one (``Package.reference_method``,
separate from the demo's ``Package.demo_reference``): a pixel study judges one pixel's
derivative, where boundary's edge samples are spread over the whole film and a study's
reference grew to 314,352 spp (5.5 minutes) to reach the required precision.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from flatland.app.cli import Package
from flatland.app.cli import main as _main
from flatland.integrals import INTEGRALS as _INTEGRALS
from flatland.textbook import METHODS as _ESTIMATORS
from flatland.textbook import estimate as _estimate
from sphere3d.film import FILMS
from sphere3d.optimize import optimize, render_targets
from sphere3d.render import GRADIENT_METHODS, irradiance, render, render_gradient
from sphere3d.scene import list_scenes, load_scene, parameter_names

__all__ = ["PACKAGE", "STUDIES", "main"]

STUDIES = {
    "shadow": {
        "problem": {"scene": "shadow", "param": "occluder.translate.x"},
        "methods": [
            {"method": "naive", "spp": [1, 4, 16]},
            {"method": "finite_difference", "h": 0.05, "spp": [1, 2, 4]},
            {"method": "reparam", "kappa": 1000, "spp": [1, 4, 16]},
        ],
        "trials": 8,
        "seed": 1,
        "reference": {"method": "finite_difference", "h": 0.05, "spp": 640},
    },
    "soft_shadow": {
        "problem": {"scene": "soft_shadow", "param": "occluder.translate.z"},
        "methods": [
            {"method": "naive"},
            {"method": "boundary"},
            {"method": "finite_difference", "h": 0.02},
            {"method": "reparam", "kappa": [3, 30, 300, 3000]},
        ],
        "spp": 16,
        "trials": 16,
        "seed": 1,
        "reference": {"method": "boundary", "spp": 8192},
    },
}
r"""Built-in studies (``python -m sphere3d study shadow``), each printing under its table what it shows.

``shadow``: the methods on the shadow scene (the sum of the derivative image) against a 640-spp
finite-difference reference (its standard error 1/4 of the 4-spp finite-difference cells' needs
16 × 8 trials × 4 spp = 512 spp; 640 leaves room for the scatter of the estimated errors). Every
method runs at several sample counts, the points of the error-versus-time figure. κ acts on the
cosine-sampled integral only (the emitter-sampled one follows the shadow edge by its own probes), and
there the small light weighs little under the balance heuristic (a cosine pdf near 0.3 against the
light's 1 / solid angle, about 8), its edges fading besides: κ has no bias to trade on this scene,
and the κ sweep runs on ``soft_shadow``.

``soft_shadow``: the κ trade-off of Loubet et al. 2019, Sec. 4.2, on the sphere. The camera looks
straight down at the floor beside a box under a constant sky (the box itself out of the frame), so
the derivative image is the shading integral's alone: the floor's irradiance
$E = ∫ L V(ω) \cos θ\, dω$ changes only through the visibility of the sky past the box as the
box rises (``occluder.translate.z``). Seen from the floor the box's lower and upper edges lie at
different distances, so they sweep across the hemisphere at different angular speeds: one
rotation per sample follows them only where the vMF kernel holds one of them. κ = 3 (kernel
width 1/√κ, 0.58 rad, wider than the box seen from the floor) drags every edge alike; κ = 3000
(0.018 rad) holds one edge at a time while the kernel weight's derivative, of order √κ, raises
the variance. ``naive`` has no derivative here at all (the jump term is the whole derivative);
the reference is ``boundary`` at 8192 spp (its standard error about 1/5 of the boundary row's)."""

PACKAGE = Package(
    "sphere3d",
    load_scene=load_scene,
    list_scenes=list_scenes,
    parameter_names=parameter_names,
    render=render,
    render_gradient=render_gradient,
    irradiance=irradiance,
    methods=GRADIENT_METHODS,
    demo_scene="shadow",
    demo_param="occluder.translate.x",
    demo_spp=32,
    reference_factor=20,
    demo_methods=("naive", "boundary", "reparam", "finite_difference"),
    reference_method="finite_difference",
    demo_reference="boundary",
    studies=STUDIES,
    integrals=_INTEGRALS,  # study problems {"integral": ...}: flatland's textbook, as before
    estimate=_estimate,
    estimators=_ESTIMATORS,
    films=FILMS,  # --film for render and gradient, "splat" (the default) first
    cluster=True,  # --scheduler for render and gradient: tiles on a dask.distributed cluster
    optimize=optimize,
    render_targets=render_targets,
)
"""What the command line and the study runner (:mod:`flatland.app`) need to know about sphere3d."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    return _main(PACKAGE, argv)


if __name__ == "__main__":
    sys.exit(main())
