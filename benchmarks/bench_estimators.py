"""Textbook estimators: throughput in samples per second (best of 3 runs of 1e6 samples)."""

from __future__ import annotations

import time

from benchmarks import Row
from flatland import estimate

N = 1_000_000
CASES = [
    ("naive", {}),
    ("finite_difference", {}),
    ("boundary", {}),
    ("reparam", {}),
    ("reparam", {"kappa": 100.0}),
    ("reparam", {"kappa": 100.0, "paired": True}),
]


def _best_seconds(fn, repeats: int = 3) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def run() -> list[Row]:
    """Samples per second of every method on a line integral and on a circle integral."""
    rows = []
    for integral, theta in (("two_steps", 1.0), ("arc_stretch", 1.0)):
        for method, options in CASES:
            seconds = _best_seconds(
                lambda m=method, o=options, i=integral, t=theta: estimate(i, t, m, n=N, seed=0, **o)
            )
            label = method + "".join(f" {k}={v}" for k, v in options.items())
            rows.append(Row("textbook estimators", f"{integral}: {label}", N / seconds / 1e6, "M samples/s"))
    return rows
