"""``python -m flatland demo | render SCENE | gradient SCENE | study CONFIG | optimize SCENE`` (see
:mod:`flatland.app.cli`).

``demo`` also prints the textbook table (:mod:`flatland.textbook_report`): every
estimator on every textbook integral next to its closed form. Every film figure of ``demo``,
``render`` and ``gradient`` has the scene's sketch on its left (:mod:`flatland.plotting.sketch`):
the shapes, the emitter, the camera's view and, for a gradient, the part the parameter moves.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from flatland.app.cli import Package
from flatland.app.cli import main as _main
from flatland.integrals import INTEGRALS as _INTEGRALS
from flatland.optimize import optimize, render_targets
from flatland.render import GRADIENT_METHODS, irradiance, render, render_gradient
from flatland.scene import list_scenes, load_scene, parameter_names
from flatland.textbook import METHODS as _ESTIMATORS
from flatland.textbook import estimate as _estimate

__all__ = ["PACKAGE", "STUDIES", "main"]


def _textbook_section(args: argparse.Namespace) -> str:
    from flatland.textbook_report import textbook_table

    return textbook_table(seed=args.seed, progress=False if args.quiet else None)


def _sketch(ax: Any, scene: Any, param: str | None = None) -> Any:
    """The scene sketch beside every film the command line writes (:mod:`flatland.plotting.sketch`)."""
    from flatland.plotting.sketch import draw_scene  # matplotlib only once there is a figure to draw

    return draw_scene(ax, scene, param)


STUDIES = {
    "kappa": {
        "problem": {"integral": "two_steps", "theta": 1.0},
        "methods": [
            {"method": "naive", "n": [10000, 50000]},
            {"method": "boundary", "n": [10000, 50000]},
            {"method": "finite_difference", "h": [0.01, 0.1], "n": [10000, 50000]},
            {
                "method": "reparam",
                "kappa": [1, 10, 100, 1000, 10000],
                "paired": [False, True],
                "n": [10000, 50000],
            },
        ],
        "trials": 20,
        "seed": 3,
        "level": 0.99,
    },
    "shadow": {
        "problem": {"scene": "shadow", "param": "occluder.translate.x"},
        "methods": [
            {"method": "naive", "spp": [4, 16, 64]},
            {"method": "boundary", "spp": [4, 16, 64]},
            {"method": "finite_difference", "h": 0.01, "spp": [4, 16, 64]},
            {"method": "reparam", "kappa": 1000, "spp": [4, 16, 64]},
        ],
        "trials": 8,
        "seed": 1,
        "reference": {"spp": 12288},
    },
    "penumbra": {
        "problem": {"scene": "penumbra", "param": "blocker.translate.x"},
        "methods": [
            {"method": "naive"},
            {"method": "boundary"},
            {"method": "reparam", "kappa": [3, 30, 300, 3000]},
        ],
        "spp": 16,
        "trials": 16,
        "seed": 1,
        "reference": {"spp": 4096},
    },
}
"""Built-in studies (``python -m flatland study kappa``), each printing under its table what it shows.

``kappa``: the κ trade-off of Loubet et al. 2019, Sec. 4.2, on the two-step integral against its
closed form. ``shadow``: the methods on the shadow scene (the sum of the derivative image) against a
12288-spp boundary reference, whose standard error is then below 1/4 of the boundary cells' at 64 spp
(the smallest); every method runs at several sample counts, the points of the error-versus-time
figure. Its light's edges fade and its occluder, seen from the floor, is wider than the light, so no
shading integral holds two jumps moving differently: κ has no bias to trade there, and the κ sweep
runs on ``penumbra``. There a wide sharp-edged light is seen past a small blocker: from below the
blocker its silhouette lies about 0.08 rad inside the light's edge (half-angles atan(1.5/2.5) and
atan(0.3/0.6)), and a translation that follows the silhouette loses the light edge's jump term
with the von Mises tail beyond half that gap, Φ(-d √κ / 2) (docs/theory/kernels.md). κ = 3 (kernel
width 1/√κ, 0.58 rad) spans both edges over the whole penumbra, κ = 3000 (0.018 rad) only a thin
band, while the kernel weight's derivative, of order √κ, raises the variance: the sweep spans three
decades across that change, with 16 trials so the small κ's bias stands clear of its interval."""

PACKAGE = Package(
    "flatland",
    load_scene=load_scene,
    list_scenes=list_scenes,
    parameter_names=parameter_names,
    render=render,
    render_gradient=render_gradient,
    irradiance=irradiance,
    methods=GRADIENT_METHODS,
    demo_scene="shadow",
    demo_param="occluder.translate.x",
    demo_spp=256,
    demo_sections=(_textbook_section,),
    sketch=_sketch,
    studies=STUDIES,
    integrals=_INTEGRALS,
    estimate=_estimate,
    estimators=_ESTIMATORS,
    optimize=optimize,
    render_targets=render_targets,
)
"""What the command line and the study runner (:mod:`flatland.app`) need to know about flatland."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    return _main(PACKAGE, argv)


if __name__ == "__main__":
    sys.exit(main())
