"""Threads, memory and machines: how a task's chunks run, apart from the maths.

A task (:mod:`sphere3d.tasks`) splits its samples into memory chunks whose random numbers are
keyed on the samples' indices, so its result does not depend on how the chunks are run. This
module runs them: :func:`map_chunks` on up to :data:`WORKERS` threads (numpy and Embree release
the GIL), each in a copy of the caller's context, with the allocator tuned for the chunks'
temporaries on glibc, and reports each finished chunk to the call's progress bar
(:mod:`flatland.core.progress`). Nothing here changes a number.

:data:`WORKERS` defaults to every core (``os.cpu_count()``); the environment variable
``SPHERE3D_THREADS`` (read at import) or an assignment ``sphere3d.execution.WORKERS = n`` limits it.

Beyond one machine: inside :func:`cluster` (``render(..., scheduler=address)``), a task sends tiles
of its chunks to the workers of a ``dask.distributed`` scheduler through :func:`map_tiles`, each
tile run there by :func:`map_chunks` on that machine's threads (the optional ``cluster`` extra,
``pip install 'reparam-lab[cluster]'``). The address is checked and the client made as for a study's trials
(``flatland.app.study_trials``); workers started with one thread each
(``dask worker ADDRESS --nthreads 1``) leave a machine's cores to its tiles' chunks.
"""

from __future__ import annotations

import contextvars
import ctypes
import functools
import itertools
import os
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Any

from flatland.core import progress
from flatland.core.validate import ValidationError

__all__ = [
    "CHUNKS_PER_THREAD",
    "MIN_CHUNK",
    "TILES_PER_THREAD",
    "TRIM_DELAY",
    "WORKERS",
    "chunk_size",
    "client",
    "cluster",
    "connect",
    "map_chunks",
    "map_tiles",
    "prepare",
    "tile_count",
    "tile_ranges",
    "workers",
]


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


CHUNKS_PER_THREAD = 4
"""Chunks a task's items are split into per thread, at least, when they are many (:func:`chunk_size`):
the chunks' costs differ (a shadow's penumbra lies in a few of them), and threads that take the next
chunk as they finish leave at most about one chunk's work idle at the end, a 1/4 share of a thread's."""
MIN_CHUNK = 1 << 12
"""Samples below which a chunk is not split further for balance (:func:`chunk_size`): a chunk's fixed
cost (Python calls, tens of numpy calls) is about a millisecond, a few percent of 4 096 samples' work."""


def chunk_size(items: int, per_item: int, limit: int) -> int:
    r"""Items per chunk of a task of ``items`` items of ``per_item`` samples each: at most ``limit``
    (the memory ceiling), at least one, and small enough for :data:`CHUNKS_PER_THREAD` chunks per
    thread (:func:`workers`) unless that makes chunks of fewer than :data:`MIN_CHUNK` samples:

        $\max(1, \min(\mathrm{limit}, \max(\lceil n / (4 W) \rceil, \lceil \mathrm{MIN\_CHUNK} / s \rceil)))$.

    Results never depend on it (every draw is keyed on its sample's index); the time does."""
    balanced = max(-(-items // (CHUNKS_PER_THREAD * workers())), -(-MIN_CHUNK // per_item))
    return max(1, min(limit, balanced))


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


def prepare(transforms: Any, state: Any, jobs: Sequence[Callable[[], Any]] = ()) -> list[Any]:
    """Build the per-state tables a method names, ``transforms.tables(state)`` (an optional hook of
    :class:`~sphere3d.integrator.Transforms`: builders :func:`~sphere3d.tables.per_state` keeps), on the
    threads at once, before the chunks: otherwise the first chunks ask for them one after the other,
    each thread waiting for the one building. ``jobs``, work that needs no chunk (a method's per-image
    term, batch by batch), run after them in the same pass: a thread done with the tables takes the
    jobs while another still builds (a table can take as long as several jobs). Returns the jobs'
    results, in order. Changes no number (a table is what its builder makes, a job is independent)."""
    builders = tuple(getattr(transforms, "tables", lambda _: ())(state))
    work = [functools.partial(b, state) for b in builders] + list(jobs)
    if not work:
        return []
    return map_chunks(lambda i: work[i](), range(len(work)), counted=False)[len(builders) :]


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


TILES_PER_THREAD = 4
"""Tiles a task sends to a cluster per worker thread (:func:`tile_count`): enough that a slow or late
worker leaves little idle time at the end; each tile builds the scene's state (and tracer) once."""

_CLIENT: contextvars.ContextVar[Any] = contextvars.ContextVar("sphere3d_cluster", default=None)


def connect(scheduler: Any) -> Any:
    """A ``dask.distributed`` client of the scheduler at address ``scheduler`` (not the default client).

    Raises
    ------
    ValidationError
        Naming ``scheduler``: not a string, dask.distributed not installed, a malformed address, or
        no scheduler answering there (after dask's connect timeout).
    """
    if not isinstance(scheduler, str):
        raise ValidationError(
            "scheduler",
            f"must be a dask.distributed scheduler address such as 'tcp://host:8786', got {scheduler!r}",
        )
    try:
        from dask.distributed import Client
        from distributed.comm import parse_address, parse_host_port
    except ImportError:  # the optional 'cluster' extra
        raise ValidationError(
            "scheduler", "needs dask.distributed, the 'cluster' extra: pip install 'reparam-lab[cluster]'"
        ) from None
    try:  # a malformed address fails before a Client exists (a half-built one stalls the exit)
        scheme, location = parse_address(scheduler)
        if scheme in ("tcp", "tls"):
            parse_host_port(location)
        return Client(scheduler, set_as_default=False)
    except (ValueError, OSError) as e:  # a malformed address, or no scheduler there
        raise ValidationError("scheduler", f"cannot connect to {scheduler!r}: {e}") from None


@contextmanager
def cluster(scheduler: str | None) -> Iterator[None]:
    """Within, tasks run their chunks on the Dask cluster at ``scheduler`` (:func:`map_tiles`).

    The client connects on entry (:func:`connect`) and closes on exit. None changes nothing: the
    chunks run where the enclosing call runs them (this machine's threads, unless an outer
    ``cluster`` is active).
    """
    if scheduler is None:
        yield
        return
    dask_client = connect(scheduler)
    token = _CLIENT.set(dask_client)
    try:
        yield
    finally:
        _CLIENT.reset(token)
        dask_client.close()


def client() -> Any:
    """The Dask client of the enclosing :func:`cluster`, or None: chunks run on this machine."""
    return _CLIENT.get()


def tile_count(chunks: int) -> int:
    """Tiles to cut ``chunks`` memory chunks into on the current cluster: :data:`TILES_PER_THREAD` per
    worker thread it has now (at least one tile, at most one per chunk)."""
    threads = sum(client().nthreads().values())
    return max(1, min(chunks, TILES_PER_THREAD * threads))


def tile_ranges(chunks: int) -> list[tuple[int, int]]:
    """``chunks`` memory chunks cut into :func:`tile_count` tiles of whole chunks, as (first, stop) pairs in
    order (stop exclusive), their sizes differing by one chunk at most."""
    tiles = tile_count(chunks)
    return list(itertools.pairwise([k * chunks // tiles for k in range(tiles)] + [chunks]))


def map_tiles(func: Callable[[Any, Any], Any], shared: Any, items: Sequence[Any]) -> list[Any]:
    """``[func(shared, item) for item in items]``, each call a task on the workers of :func:`client`.

    ``shared`` (the scene, the transforms: what every tile needs) is sent to the cluster once; ``func``
    must be importable by the workers (a module-level function). The call's progress bar advances as
    each task finishes, in any order; the results come back in the order of ``items``. The first
    failure is raised (a :class:`ValidationError` raised on a worker comes back as one) and the other
    tasks are cancelled.
    """
    from distributed import as_completed

    dask_client = client()
    progress.start(len(items))
    [data] = dask_client.scatter([shared], hash=False)
    futures = [dask_client.submit(func, data, item, pure=False) for item in items]
    try:
        for future in as_completed(futures, loop=dask_client.loop):  # this client, not a default one
            future.result()  # raises the task's exception
            progress.advance()
        return [future.result() for future in futures]
    except BaseException:
        dask_client.cancel(futures)
        raise
