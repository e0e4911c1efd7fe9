"""Benchmarks: ``python -m benchmarks`` (``make bench``) prints one table of all ``bench_*`` modules."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Row"]


@dataclass(frozen=True)
class Row:
    """One measured number: which section and case, its value and unit, and a note (e.g. a target)."""

    section: str
    case: str
    value: float
    unit: str
    note: str = ""
