r"""Study runner: a grid of methods × options × independent trials, measured against a reference.

A study answers "how biased, how noisy and how fast is each estimator here?" for one
scalar derivative dI/dθ, the numbers behind the bias/variance trade-off of the
convolution kernel (Loubet et al. 2019, Sec. 4.2) and behind equal-time
comparisons of the methods.

Problems
--------
``{"integral": "two_steps", "theta": 1.0}``
    A textbook integral (flatland's :mod:`flatland.integrals`), run through the
    package's ``estimate`` (:func:`flatland.estimate`); the reference is its
    closed-form derivative.
``{"scene": "shadow", "param": "occluder.translate.x"}``
    A scene of the package (``flatland`` or ``sphere3d``), run through the
    ``render_gradient`` of its description (:class:`~flatland.app.cli.Package`). The
    scalar studied is a linear functional of the gradient
    image: by default (``"functional": "sum"``) the sum over all pixels, i.e. the
    derivative of the image's total brightness $d/dθ\, Σ_j I_j$; with
    ``"pixel": j`` (flatland) or ``"pixel": [row, col]`` (sphere3d) the derivative
    of that one pixel. The per-pixel error is reported as well, as the image error
    metric :func:`~flatland.core.image.relative_error` averaged over the trials.
    The reference is a high-sample run of ``boundary`` (``finite_difference`` where
    the package has no boundary method), cached on disk by a hash of its inputs.

Cells and trials
----------------
Each entry of ``"methods"`` names a method and its options; any option (``kappa``,
``probes``, ``paired``, ``h``, ...) and the sample count (``"n"`` for integrals, ``"spp"``
for scenes) may be a list, and the entry expands to the Cartesian product: one
:class:`~flatland.app.study_config.Cell` per combination, numbered in order. Trial ``k``
of cell ``c`` runs with the seed :func:`~flatland.app.study_config.trial_seed`
``(seed, c, k)``, a function of those three numbers only, so the same study gives
identical estimates serially (``workers=1``), in worker processes (``workers=2``)
or on a Dask cluster (``scheduler=address``); only the measured times differ.

The trials are run by :mod:`flatland.app.study_trials`, the reference is resolved (and
cached) by :mod:`flatland.app.study_reference`, and the statistics, the table and the CSV
(:class:`~flatland.app.study_result.StudyResult`) are defined in
:mod:`flatland.app.study_result`.

Reference rule: a Monte Carlo reference's standard error must be at most 1/4 of
the smallest standard error among the cells it does not flag as biased (a flag
already counts the reference's noise in its z). :func:`run_study` checks this after
the trials and recomputes the reference at $(\mathrm{stderr} / \mathrm{target})^2$ × its sample count
(× 1.25), or raises with that count (``grow_reference=False``); the table's footer
states the reference's method, sample count, stderr and the ratio.

Configurations are parsed and validated in :mod:`flatland.app.study_config`
(its ``load_config`` re-exported here) against the package's description
(:class:`~flatland.app.cli.Package`, ``load_config(source, package=PACKAGE)`` with the
``PACKAGE`` of ``flatland.__main__`` or ``sphere3d.__main__``). Example (JSON)::

    {"name": "kappa", "problem": {"integral": "two_steps", "theta": 1.0},
     "methods": [{"method": "boundary"},
                 {"method": "reparam", "kappa": [1, 10, 100, 1000, 10000]}],
     "n": 50000, "trials": 20, "seed": 3, "level": 0.99}
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

from flatland.app.study_config import StudyConfig, load_config, trial_seed
from flatland.app.study_reference import Reference, resolve_reference
from flatland.app.study_result import CSV_COLUMNS, CellResult, StudyResult, _ranked, _summarize, read_csv
from flatland.app.study_trials import _Calls, _execute, _run_one, _Task
from flatland.core.bias import REFERENCE_RATIO, reference_spp_needed
from flatland.core.progress import show, silenced
from flatland.core.validate import ValidationError, check_int

__all__ = ["CSV_COLUMNS", "load_config", "read_csv", "run_study"]


class _NoProgress:
    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, desc: str, progress: bool | None) -> Any:
    if not show(progress):
        return _NoProgress()
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="trial", file=sys.stderr, dynamic_ncols=True)


def run_study(
    config: StudyConfig,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    cache_dir: str | os.PathLike | None = None,
    progress: bool | None = None,
    on_reference: Callable[[Reference], None] | None = None,
    grow_reference: bool = True,
) -> StudyResult:
    """Run every cell's trials and summarize them against the reference.

    Parameters
    ----------
    config : StudyConfig
        The validated study (:meth:`StudyConfig.from_dict`, :func:`load_config`).
    workers : int, optional
        Worker processes on this machine (overrides ``config.workers``); 1 runs in
        this process.
    scheduler : str, optional
        Address of a ``dask.distributed`` scheduler (overrides ``config.scheduler``);
        the trials then run on that cluster (needs the ``cluster`` extra).
    cache_dir : path, optional
        Where Monte Carlo references are cached; None computes them every time.
    progress : bool, optional
        Show tqdm progress bars (the reference's, then one over the trials; :mod:`flatland.core.progress`);
        default: when stderr is a terminal.
    on_reference : callable, optional
        Called with the reference once it is known (e.g. to print it).
    grow_reference : bool
        What to do when a Monte Carlo reference's standard error exceeds 1/4 of the
        smallest standard error among the cells it does not flag as biased (a flag
        counts the reference's noise in its z, so it stands whatever that noise):
        True recomputes it at the sample count :func:`~flatland.core.bias.reference_spp_needed`
        gives (times 1.25, for the scatter of the estimated standard errors; at most three
        rounds), False raises a ValidationError naming ``reference`` and that count.

    Returns
    -------
    StudyResult
        The same numbers for the same config and seed, however the trials ran
        (except ``seconds_per_sample``, ``efficiency`` and ``equal_time_rmse``).
    """
    workers = check_int("workers", config.workers if workers is None else workers)
    scheduler = config.scheduler if scheduler is None else scheduler
    start = time.perf_counter()
    _preflight(config)
    reference = resolve_reference(config, cache_dir, progress)
    if on_reference is not None:
        on_reference(reference)
    calls = _Calls.of(config.package)
    tasks = [
        _Task(calls, config.problem, cell, k, trial_seed(config.seed, cell.index, k))
        for cell in config.cells
        for k in range(config.trials)
    ]
    bar = _progress(len(tasks), config.name, progress)
    try:
        runs = _execute(tasks, workers, scheduler, bar)
    finally:
        bar.close()
    t = config.trials  # tasks are ordered cell by cell, trial by trial
    m = len(config.cells)  # the bias intervals are simultaneous over the cells

    def summarize(reference: Reference) -> list[CellResult]:
        return [
            _summarize(cell, runs[c * t : (c + 1) * t], reference, config.level, config.time_budget, m)
            for c, cell in enumerate(config.cells)
        ]

    rows = summarize(reference)
    for attempt in range(4):
        needed = _reference_needed(config, reference, rows)
        if needed is None:
            break
        count = f"reference.{config.problem.count_name}"
        if not grow_reference or attempt == 3:
            judged = min(r.stderr for r in rows if not r.biased and r.stderr > 0.0)
            raise ValidationError(
                count,
                f"the reference's standard error {reference.stderr:.3g} is more than {REFERENCE_RATIO:g}"
                f" × the smallest standard error it judges ({judged:.3g}); give at least {needed}",
            )
        spec = replace(config.reference, n=needed)
        reference = resolve_reference(replace(config, reference=spec), cache_dir, progress)
        rows = summarize(reference)
    return StudyResult(config, reference, _ranked(rows), time.perf_counter() - start)


def _reference_needed(config: StudyConfig, reference: Reference, rows: Sequence[CellResult]) -> int | None:
    """The reference sample count the 1/4 rule asks for, or None if the reference meets it."""
    if config.reference is None or reference.n is None:
        return None  # closed form: no noise
    judged = [r.stderr for r in rows if not r.biased and r.stderr > 0.0]
    if not judged or reference.stderr <= REFERENCE_RATIO * min(judged):
        return None
    return reference_spp_needed(reference.n, reference.stderr, min(judged))


def _preflight(config: StudyConfig) -> None:
    """Run every cell once with 2 samples (per pixel), so a bad combination fails here, named."""
    calls = _Calls.of(config.package)
    for cell in config.cells:
        try:
            with silenced():
                _run_one(calls, config.problem, replace(cell, n=min(cell.n, 2)), config.seed)
        except ValidationError as e:
            raise ValidationError(f"methods cell {cell.index} ({cell.label})", str(e)) from None
