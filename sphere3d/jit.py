"""Scalar-Python kernels compiled by Numba, on first use, their machine code cached on disk.

Where a computation is one branch per element (a tree walk, a clip with early exits, a sort of short
runs), numpy's whole-array operations either cannot express it or do many times the work; such a
kernel is written as plain Python over scalars and arrays, readable and testable as it stands
(each has a test comparing the compiled kernel with its Python), and compiled here.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

__all__ = ["compiled"]


@functools.cache
def compiled(func: Callable) -> Callable:
    """``func`` compiled by Numba (imported here, on first use: the import alone takes a second), its
    machine code cached on disk; ``nogil``: the render's worker threads run it at once."""
    import numba

    return numba.njit(cache=True, nogil=True)(func)
