"""``python -m sphere3d demo | render SCENE | gradient SCENE | study CONFIG`` (see :mod:`flatland.core.cli`).

The same verbs, options and error behaviour as ``python -m flatland``. The demo's
reference is a finite-difference image (step h = 0.05: less variance than the
default step for an O(h²) bias) at 8 × the demo's samples per pixel; sphere3d has no
boundary method.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from flatland.core.cli import Package
from flatland.core.cli import main as _main

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
    demo_scene="shadow",
    demo_param="occluder.translate.x",
    demo_spp=32,
    reference_factor=8,
    reference_options=(("h", 0.05),),
    studies=STUDIES,
)
"""What the shared command line needs to know about sphere3d."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    return _main(PACKAGE, argv)


if __name__ == "__main__":
    sys.exit(main())
