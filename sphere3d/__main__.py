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
            {"method": "naive"},
            {"method": "finite_difference", "h": 0.05},
            {"method": "reparam", "kappa": [100, 1000, 10000]},
        ],
        "spp": 4,
        "trials": 8,
        "seed": 1,
        "reference": {"method": "finite_difference", "h": 0.05, "spp": 256},
    },
}
"""Built-in studies (``python -m sphere3d study shadow``): the methods and the κ sweep on the
shadow scene (the sum of the derivative image) against a 256-spp finite-difference reference."""

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
