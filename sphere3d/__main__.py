"""``python -m sphere3d demo | render SCENE | gradient SCENE | study CONFIG`` (see :mod:`flatland.app.cli`).

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
            {"method": "reparam", "kappa": [100, 10000], "spp": 4},
        ],
        "trials": 8,
        "seed": 1,
        "reference": {"method": "finite_difference", "h": 0.05, "spp": 640},
    },
}
"""Built-in studies (``python -m sphere3d study shadow``): the methods and a κ sweep on the
shadow scene (the sum of the derivative image) against a 640-spp finite-difference reference
(its standard error 1/4 of the 4-spp finite-difference cells' needs 16 × 8 trials × 4 spp = 512
spp; 640 leaves room for the scatter of the estimated errors). Every method runs at several
sample counts, the points of the error-versus-time figure."""

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
)
"""What the command line and the study runner (:mod:`flatland.app`) need to know about sphere3d."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    return _main(PACKAGE, argv)


if __name__ == "__main__":
    sys.exit(main())
