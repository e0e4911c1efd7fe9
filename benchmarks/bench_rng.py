"""Random numbers: keyed draws (one stream per sample index) against numpy's sequential PCG64.

Keyed draws (:func:`flatland.core.rng.keyed_uniforms`) make images independent of
the memory chunking; their price is the SplitMix64 hashing, vectorized over rows.
"""

from __future__ import annotations

import numpy as np

from benchmarks import Row, best_seconds
from flatland.core.rng import keyed_normals, keyed_uniforms, stream

ROWS, COLUMNS = 1 << 18, 8


def run() -> list[Row]:
    """Millions of uniforms (and normals) per second, keyed and sequential."""
    keys = np.arange(ROWS)
    count = ROWS * COLUMNS
    rows = []
    for label, fn in (
        ("keyed uniforms (SplitMix64)", lambda: keyed_uniforms(1, "bench", keys, COLUMNS)),
        ("keyed normals (SplitMix64 + ndtri)", lambda: keyed_normals(1, "bench", keys, COLUMNS)),
        ("sequential uniforms (PCG64)", lambda: stream(1, "bench").random((ROWS, COLUMNS))),
    ):
        rows.append(
            Row("random numbers", f"{label}, {ROWS} rows x {COLUMNS}", count / best_seconds(fn) / 1e6, "M/s")
        )
    return rows
