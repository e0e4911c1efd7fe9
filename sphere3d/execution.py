"""Threads and memory: how a task's chunks run, apart from the maths.

A task (:mod:`sphere3d.tasks`) splits its samples into memory chunks whose random numbers are
keyed on the samples' indices, so its result does not depend on how the chunks are run. This
module runs them: :func:`map_chunks` on up to :data:`WORKERS` threads (numpy and Embree release
the GIL), each in a copy of the caller's context, with the allocator tuned for the chunks'
temporaries on glibc, and reports each finished chunk to the call's progress bar
(:mod:`flatland.core.progress`). Nothing here changes a number.

:data:`WORKERS` defaults to every core (``os.cpu_count()``); the environment variable
``SPHERE3D_THREADS`` (read at import) or an assignment ``sphere3d.execution.WORKERS = n`` limits it.
"""

from __future__ import annotations

import contextvars
import ctypes
import functools
import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from flatland.core import progress
from flatland.core.validate import ValidationError

__all__ = ["TRIM_DELAY", "WORKERS", "map_chunks", "workers"]


def _default_workers() -> int:
    """``SPHERE3D_THREADS`` if set (an integer >= 1), else the number of cores."""
    text = os.environ.get("SPHERE3D_THREADS", "").strip()
    if not text:
        return os.cpu_count() or 1
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise ValidationError("SPHERE3D_THREADS", f"must be an integer >= 1, got {text!r}")
    return value


TRIM_DELAY = 1.0
"""Seconds without a task after which the chunks' memory goes back to the system (:func:`map_chunks`)."""
WORKERS = _default_workers()
"""Threads over memory chunks: every core unless ``SPHERE3D_THREADS`` says fewer."""


def workers() -> int:
    """The number of threads :func:`map_chunks` uses now (:data:`WORKERS`)."""
    return WORKERS


@functools.cache
def _heap_for_temporaries() -> Any:
    """Let glibc's malloc serve a chunk's temporaries (up to 32 MiB each) from its heap and keep them.

    By default glibc maps large arrays with ``mmap`` and unmaps them when freed (and trims
    the heap's free top), so the temporaries of every chunk (hundreds of arrays of 0.1 to
    10 MB) are page-faulted in again at every chunk.
    Raising the mmap and trim thresholds (``mallopt``) reuses the freed memory instead;
    :func:`map_chunks` hands it back with ``malloc_trim`` once no task has run for :data:`TRIM_DELAY`
    seconds. Process-wide, set once, on glibc only (elsewhere a no-op); the arithmetic, hence
    every result, is unchanged. Returns the C library where the thresholds were set, else None.
    """
    try:
        libc = ctypes.CDLL(None)
        mallopt, _ = libc.mallopt, libc.malloc_trim  # both must exist (glibc)
    except (OSError, AttributeError, TypeError):  # no C library by that name, or not glibc
        return None
    m_trim_threshold, m_mmap_threshold = -1, -3  # <malloc.h>
    done = bool(mallopt(m_mmap_threshold, 32 << 20)) and bool(mallopt(m_trim_threshold, 512 << 20))
    return libc if done else None


def map_chunks(func: Callable[[int], Any], items: range, counted: bool = True) -> list[Any]:
    """``[func(i) for i in items]``, on up to :data:`WORKERS` threads (numpy and Embree release the GIL).

    Each chunk draws from its own named streams, so the result does not depend on
    the number of threads or the order they finish in. With ``counted`` (the sample
    chunks; not the short gathers after them) the items are a pass of the call's progress
    bar, advanced as their results arrive, in order (:mod:`flatland.core.progress`).
    The chunks' memory is handed back :data:`TRIM_DELAY` seconds after the last task, not after
    each, and the threads are kept (:func:`_pool`): trimmed after each, every task would
    page-fault its temporaries in again, in every thread's heap.
    """
    if counted:
        progress.start(len(items))
    libc = _heap_for_temporaries()
    if libc is None:
        return _map_threads(func, items, counted)
    _trim_later(libc, None)
    try:
        return _map_threads(func, items, counted)
    finally:
        _trim_later(libc, TRIM_DELAY)


_TRIM: list[threading.Timer] = []
_TRIM_LOCK = threading.Lock()


def _trim_later(libc: Any, delay: float | None) -> None:
    """Cancel the pending ``malloc_trim`` (a task starts), and with a ``delay``, schedule one."""
    with _TRIM_LOCK:
        while _TRIM:
            _TRIM.pop().cancel()
        if delay is not None:
            timer = threading.Timer(delay, libc.malloc_trim, (0,))  # give the chunks' memory back
            timer.daemon = True  # never keeps the interpreter alive
            _TRIM.append(timer)
            timer.start()


@functools.cache
def _pool(workers: int, pid: int) -> ThreadPoolExecutor:
    """One pool per thread count (and process: a forked child has none of its parent's threads), kept:
    its threads keep their malloc heaps (and the memory freed there) from task to task, where new
    threads got whichever heaps and faulted memory in again."""
    return ThreadPoolExecutor(max_workers=workers, thread_name_prefix=f"sphere3d-{pid}")


def _map_threads(func: Callable[[int], Any], items: range, counted: bool = False) -> list[Any]:
    """Each task runs in a copy of the caller's context (one copy per task: a context is entered by one
    thread at a time), so the caller's ``np.errstate``, a context variable, holds in the threads too.
    The progress bar advances in this thread, as each result arrives in order."""
    workers = WORKERS
    if workers <= 1 or len(items) <= 1:
        results = (func(i) for i in items)
    else:
        caller = contextvars.copy_context()
        results = _pool(workers, os.getpid()).map(lambda i: caller.copy().run(func, i), items)
    out = []
    for result in results:
        out.append(result)
        if counted:
            progress.advance()
    return out
