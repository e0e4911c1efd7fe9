"""Benchmarks: ``python -m benchmarks`` (``make bench``) prints one table of all ``bench_*`` modules."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["Row", "best_seconds"]


@dataclass(frozen=True)
class Row:
    """One measured number: which section and case, its value and unit, and a note (e.g. a target)."""

    section: str
    case: str
    value: float
    unit: str
    note: str = ""


def best_seconds(fn: Callable[[], Any], repeats: int = 3) -> float:
    """Wall time of the fastest of ``repeats`` calls of ``fn`` (the least disturbed by other load)."""
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best
