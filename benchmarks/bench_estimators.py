"""Textbook estimators: throughput in samples per second (best of 3 runs of 1e6 samples)."""

from __future__ import annotations

from benchmarks import Row, best_seconds
from flatland import estimate
from flatland.app.table import method_label
from flatland.textbook_report import DEFAULT_METHODS

N = 1_000_000
CASES = DEFAULT_METHODS  # the columns of the textbook table printed by `make demo`


def run() -> list[Row]:
    """Samples per second of every method on a line integral and on a circle integral."""
    rows = []
    for integral, theta in (("two_steps", 1.0), ("arc_stretch", 1.0)):
        for method, options in CASES:
            seconds = best_seconds(
                lambda m=method, o=options, i=integral, t=theta: estimate(i, t, m, n=N, seed=0, **o)
            )
            label = method_label(method, options.items())
            rows.append(Row("textbook estimators", f"{integral}: {label}", N / seconds / 1e6, "M samples/s"))
    return rows
