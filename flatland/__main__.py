"""``python -m flatland demo | render SCENE | gradient SCENE | study CONFIG`` (see :mod:`flatland.core.cli`).

``demo`` also prints the textbook table (:mod:`flatland.textbook_report`): every
estimator on every textbook integral next to its closed form.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from flatland.core.cli import Package
from flatland.core.cli import main as _main

__all__ = ["PACKAGE", "main"]


def _textbook_section(args: argparse.Namespace) -> str:
    from flatland.textbook_report import textbook_table

    return textbook_table(seed=args.seed)


PACKAGE = Package(
    "flatland",
    demo_scene="shadow",
    demo_param="occluder.translate.x",
    demo_spp=256,
    demo_sections=(_textbook_section,),
)
"""What the shared command line needs to know about flatland."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    return _main(PACKAGE, argv)


if __name__ == "__main__":
    sys.exit(main())
