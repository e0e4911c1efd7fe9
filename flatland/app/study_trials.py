"""One trial of a study: a method's estimate of the studied scalar, timed, and the executors that run many.

A trial calls the package's ``estimate`` (an integral) or ``render_gradient`` (a scene)
once with its own seed; for a scene the scalar studied is a linear functional of the
gradient image (:func:`_functional`: the sum over all pixels, or one pixel; see
:mod:`flatland.app.study`). :func:`_execute` runs a list of trials serially, in worker
processes or on a Dask cluster and returns their results in task order, whatever
order they ran in.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING, Any

import numpy as np

from flatland.app.study_config import Cell, Problem
from flatland.core import progress as _progress
from flatland.core.validate import ValidationError

if TYPE_CHECKING:
    from flatland.app.cli import Package

__all__: list[str] = []


def _functional(problem: Problem, image: np.ndarray) -> float:
    """The scalar studied, from a derivative image (see the module docstring)."""
    if problem.pixel is None:
        return float(np.sum(image))
    if len(problem.pixel) != image.ndim or any(
        p >= s for p, s in zip(problem.pixel, image.shape, strict=False)
    ):
        raise ValidationError(
            "problem.pixel", f"{list(problem.pixel)} is outside the film of shape {image.shape}"
        )
    return float(image[problem.pixel])


def _functional_stderr(problem: Problem, image: Any) -> float:
    """Standard error of :func:`_functional` of a gradient image's derivative: one pixel's, or the
    film sum's from the per-batch sums (:meth:`~flatland.core.image.GradientImage.film_sum`; the
    pixels' errors may be correlated, so not the pixels' standard errors in quadrature)."""
    if problem.pixel is None:
        return image.film_sum().stderr
    return float(np.asarray(image.derivative_stderr)[problem.pixel])  # on the film: _functional checked


@dataclass(frozen=True)
class _Calls:
    """The package functions a trial calls: module-level functions, so a task pickles to worker
    processes and Dask by reference (the whole description need not)."""

    load_scene: Callable[[Any], Any]
    render_gradient: Callable[..., Any]
    estimate: Callable[..., Any] | None

    @classmethod
    def of(cls, package: Package) -> _Calls:
        return cls(package.load_scene, package.render_gradient, package.estimate)


@dataclass(frozen=True)
class _Task:
    calls: _Calls
    problem: Problem
    cell: Cell
    trial: int
    seed: int


@dataclass(frozen=True)
class _Run:
    """One trial: the studied scalar's value and derivative, the derivative's standard error
    (:func:`_functional_stderr`; the estimate's for an integral), the per-pixel images (scalars
    for an integral), the samples and seconds it took."""

    value: float
    derivative: float
    samples: int
    seconds: float
    derivative_image: np.ndarray | float
    stderr_image: np.ndarray | float
    derivative_stderr: float


@lru_cache(maxsize=4)
def _load_scene(load_scene: Callable[[Any], Any], source: str) -> Any:
    return load_scene(source)


def _run_one(calls: _Calls, problem: Problem, cell: Cell, seed: int) -> _Run:
    """One estimate of the problem by one cell's method, timed (scene loading excluded)."""
    options = cell.options_dict
    if not problem.is_scene:
        start = time.perf_counter()
        e = calls.estimate(
            problem.integral, problem.theta, method=cell.method, n=cell.n, seed=seed, **options
        )
        seconds = time.perf_counter() - start
        return _Run(
            e.value, e.derivative, e.n, seconds, e.derivative, e.derivative_stderr, e.derivative_stderr
        )
    scene = _load_scene(calls.load_scene, problem.scene)
    start = time.perf_counter()
    g = calls.render_gradient(scene, problem.param, method=cell.method, spp=cell.n, seed=seed, **options)
    seconds = time.perf_counter() - start
    value = _functional(problem, np.asarray(g.value))
    derivative = _functional(problem, np.asarray(g.derivative))
    return _Run(
        value,
        derivative,
        cell.n * int(np.size(g.derivative)),
        seconds,
        g.derivative,
        g.derivative_stderr,
        _functional_stderr(problem, g),
    )


def _run_task(task: _Task) -> _Run:
    """Worker entry point (module level, so processes and Dask can import it). A trial shows no progress
    bar of its own (the study's counts trials), in this process or a worker."""
    try:
        with _progress.silenced():
            return _run_one(task.calls, task.problem, task.cell, task.seed)
    except ValidationError as e:  # named by its cell; pickles back from a worker (ValidationError.__reduce__)
        raise ValidationError(f"methods cell {task.cell.index} ({task.cell.label})", str(e)) from None


def _execute(tasks: Sequence[_Task], workers: int, scheduler: str | None, progress: Any) -> list[_Run]:
    """Run the tasks serially, in a process pool or on a Dask cluster; runs in task order."""
    if scheduler is not None:
        from dask.distributed import Client
        from distributed.comm import parse_address, parse_host_port

        try:  # a malformed address fails before a Client exists (a half-built one stalls the exit)
            scheme, location = parse_address(scheduler)
            if scheme in ("tcp", "tls"):
                parse_host_port(location)
            client = Client(scheduler, set_as_default=False)
        except (ValueError, OSError) as e:  # a malformed address, or no scheduler there
            raise ValidationError("scheduler", f"cannot connect to {scheduler!r}: {e}") from None
        with client:
            futures = client.map(_run_task, tasks, pure=False)
            for future in futures:  # waited for in submission order; they run in any order
                future.result()
                progress.update(1)
            return [future.result() for future in futures]
    if workers == 1:
        runs = []
        for task in tasks:
            runs.append(_run_task(task))
            progress.update(1)
        return runs
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # spawn: forking a process that may run threads (Dask, BLAS) is unsafe
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = [pool.submit(_run_task, task) for task in tasks]
        for future in as_completed(futures):
            future.result()  # the first failure stops the study
            progress.update(1)
        return [future.result() for future in futures]
