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

__all__ = ["PACKAGE", "main"]

PACKAGE = Package(
    "sphere3d",
    demo_scene="shadow",
    demo_param="occluder.translate.x",
    demo_spp=32,
    reference_factor=8,
    reference_options=(("h", 0.05),),
)
"""What the shared command line needs to know about sphere3d."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    return _main(PACKAGE, argv)


if __name__ == "__main__":
    sys.exit(main())
