"""Progress bars for long runs: one tqdm bar per call, advanced once per chunk of samples.

Every entry point that can run for more than a moment (``render``, ``render_gradient``
and ``irradiance`` of both packages, a study (:func:`flatland.app.study.run_study`), the demo's
textbook table) takes ``progress``:

* ``None`` (the default): a bar when standard error is a terminal, tqdm's own rule for
  ``disable=None``. A script run in a terminal shows it; a notebook (whose stderr is
  no terminal), a pipe, a log file or the test suite gets none;
* ``True``: always, e.g. in a notebook;
* ``False``: never. The command line's ``--quiet`` passes False.

A bar appears only once its call has run for :data:`DELAY` seconds, so short calls print
nothing, and it is erased when its call returns (``leave=False``), so the results printed
after it stay readable. It writes to standard error and only observes: the chunks, their
order and every number are the same with and without it.

One bar per outermost call (:func:`run`): a call made inside another's (a study's trials,
under :func:`silenced`) advances the outer call's bar, or nothing when that call has none.
The code that loops over chunks announces each pass (:func:`start`) and each finished
chunk (:func:`advance`); a method that makes several passes says how many first
(:func:`expect`), so the bar's total is right from the start.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

from flatland.core.validate import ValidationError

__all__ = ["DELAY", "advance", "expect", "run", "show", "silenced", "start", "steps"]

DELAY = 2.0
"""Seconds a call runs before its bar appears: shorter calls print nothing."""


@dataclass
class _Call:
    """The bar of one outermost call (None when it shows none) and what it has been told."""

    bar: Any
    passes: int = 1
    first: int | None = None
    started: int = 0


_CURRENT: ContextVar[_Call | None] = ContextVar("flatland_progress", default=None)


def show(progress: bool | None) -> bool:
    """Whether ``progress`` asks for a bar: None -> when standard error is a terminal."""
    if progress is None:
        isatty = getattr(sys.stderr, "isatty", None)
        return bool(isatty is not None and isatty())
    if not isinstance(progress, bool):
        raise ValidationError("progress", f"must be True, False or None, got {progress!r}")
    return progress


@contextmanager
def run(desc: str, progress: bool | None, unit: str = "chunk") -> Iterator[None]:
    """The bar of one call (see the module docstring); inside another call's, nothing new.

    ``progress`` is checked even inside another call (a bad value is one ValidationError).
    """
    wanted = show(progress)
    if _CURRENT.get() is not None:  # the outer call's bar counts this call's chunks
        yield
        return
    bar = None
    if wanted:
        from tqdm import tqdm  # only once there is a bar to show

        bar = tqdm(
            total=0, desc=desc, unit=unit, file=sys.stderr, delay=DELAY, leave=False, dynamic_ncols=True
        )
    token = _CURRENT.set(_Call(bar))
    try:
        yield
    finally:
        _CURRENT.reset(token)
        if bar is not None:
            bar.close()


@contextmanager
def silenced() -> Iterator[None]:
    """Calls inside show no bar (a study's trials, run under the study's own bar or in a worker)."""
    with run("", False):
        yield


@contextmanager
def steps(desc: str, total: int, progress: bool | None) -> Iterator[Callable[[str], None]]:
    """A bar over the ``total`` steps of an outer loop (an optimisation): yields ``step(text)``, which
    advances it by one step and shows ``text`` (e.g. the loss) beside it. The renders inside show no
    bar of their own (:func:`silenced`); inside another call's bar, nothing new."""
    wanted = show(progress)
    bar = None
    if wanted and _CURRENT.get() is None:
        from tqdm import tqdm

        bar = tqdm(
            total=total, desc=desc, unit="step", file=sys.stderr, delay=DELAY, leave=False, dynamic_ncols=True
        )

    def step(text: str) -> None:
        if bar is not None:
            bar.set_postfix_str(text, refresh=False)
            bar.update(1)

    try:
        with silenced():
            yield step
    finally:
        if bar is not None:
            bar.close()


def expect(passes: int) -> None:
    """The current call will make ``passes`` passes over its chunks (a finite difference: 3)."""
    call = _CURRENT.get()
    if call is not None:
        call.passes = max(int(passes), 1)


def start(chunks: int) -> None:
    """A pass over ``chunks`` chunks begins in the current call: the bar's total counts it."""
    call = _CURRENT.get()
    if call is None or call.bar is None:
        return
    if call.first is None:
        call.first = chunks
    call.started += chunks
    call.bar.total = max(call.started, call.first * call.passes)


def advance(chunks: int = 1) -> None:
    """``chunks`` more chunks of the current call are done."""
    call = _CURRENT.get()
    if call is not None and call.bar is not None:
        call.bar.update(chunks)
