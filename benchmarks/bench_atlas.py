"""The bias atlas: every gradient method against closed forms over motions, sizes, angles and filters.

The cells are those of :mod:`benchmarks.atlas` (its docstring defines every column) on the grid of
:mod:`benchmarks.atlas_cases`: a black triangle (sphere3d) or segment (flatland) under a constant
sky, on the film and in a shading integral, moved by every parameter the scene formats have. This
module runs the *quick* grid (:data:`benchmarks.atlas_cases.QUICK`), which ``make bench`` can
afford; ``python -m benchmarks.atlas`` runs the full one. Its page is the atlas itself; the rows
printed by ``make bench`` are the summary: per family and method, the cells flagged by their z and
those flagged against the goals.
"""

from __future__ import annotations

from benchmarks import Row
from benchmarks.atlas import Cell, run_atlas, summary, table

_LAST: list[Cell] = []
"""The cells of the last :func:`run` (its page is written from them)."""


QUICK = False
"""Whether ``make bench`` runs the quick grid instead of the full one (module docstring)."""


def run() -> list[Row]:
    """The atlas; one row per family and method with its flagged cells."""
    cells = run_atlas(quick=QUICK)
    _LAST[:] = cells
    rows = []
    for family, label, n, flagged, goal, worst, _silent in summary(cells):
        note = f"{goal} against the goals; worst: " + "; ".join(
            f"{c.case.label().partition(': ')[2]} ({100 * c.lost:+.1f} %)" for c in worst[:2]
        )
        rows.append(
            Row("atlas", f"{family}, {label}: flagged of {n}", flagged, "cells", note if worst else "")
        )
    return rows


def markdown(rows: list[Row]) -> str:
    """The atlas page (:func:`benchmarks.atlas.table`) of the last :func:`run`, with the date, the
    commit and the machine it was generated on."""
    import datetime

    from benchmarks.__main__ import machine, revision

    title, _, rest = table(_LAST, quick=QUICK).partition("\n\n")
    seconds = sum(c.seconds for c in _LAST)
    when = (
        f"Generated on {datetime.date.today().isoformat()} from commit {revision()} ({machine()}, "
        f"{seconds:.0f} s of rendering over {len(_LAST)} cells)."
    )
    return f"{title}\n\n{when}\n\n{rest}"
