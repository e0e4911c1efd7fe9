"""Per-state tables: what a builder makes of a scene state, computed once per state and kept while it lives.

A render's chunks ask for the same tables of one state (the mesh edges, the film corners, the
penumbra planes, the edge tree); :func:`per_state` wraps a builder so the first thread to ask builds
the table and the others wait for it. Re-exported by :mod:`sphere3d.state`.
"""

from __future__ import annotations

import functools
import threading
import weakref
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["per_state"]

T = TypeVar("T")


def per_state(build: Callable[[Any], T]) -> Callable[[Any], T]:
    """``build(state)`` computed once per state and kept while the state lives (states are immutable;
    every chunk of a render asks for the same tables). Keyed by ``id(state)`` with a weak reference
    that drops the entry with its state. One thread builds it; threads asking meanwhile wait for it
    (the chunks of a render start together: each building its own copy cost the table's time and
    memory once per thread). The value must be treated as read-only."""
    cache: dict[int, tuple[weakref.ref, Any]] = {}
    building: dict[int, threading.Event] = {}
    lock = threading.Lock()

    def cached(state: Any) -> T:
        key = id(state)
        while True:
            with lock:
                hit = cache.get(key)
                if hit is not None and hit[0]() is state:
                    return hit[1]
                event = building.get(key)
                if event is None:  # this thread builds it
                    event = building[key] = threading.Event()
                    break
            event.wait()  # another thread builds it; then read it (or build it, had that failed)
        try:
            value = build(state)
            with lock:
                cache[key] = (weakref.ref(state, lambda _, key=key: cache.pop(key, None)), value)
            return value
        finally:
            with lock:
                del building[key]
            event.set()

    return functools.update_wrapper(cached, build)
