"""Scalar-Python kernels compiled by Numba, on first use, their machine code cached on disk.

Where a computation is one branch per element (a tree walk, a clip with early exits, a sort of short
runs), numpy's whole-array operations either cannot express it or do many times the work; such a
kernel is written as plain Python over scalars and arrays, readable and testable as it stands
(each has a test comparing the compiled kernel with its Python), and compiled here.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

__all__ = ["compiled"]

_COMPILED: dict[Callable, Callable] = {}
_LOCK = threading.Lock()


def compiled(func: Callable) -> Callable:
    """``func`` compiled by Numba (imported here, on first use: the import alone takes a second), its
    machine code cached on disk; ``nogil``: the render's worker threads run it at once. Once per
    function, whichever thread asks first (the others wait); a compiled function is returned as it
    is (a kernel that calls another by its global name replaces that name by the compiled one)."""
    if getattr(func, "py_func", None) is not None:  # compiled already
        return func
    with _LOCK:
        if func not in _COMPILED:
            import numba

            _COMPILED[func] = numba.njit(cache=True, nogil=True)(func)
        return _COMPILED[func]
