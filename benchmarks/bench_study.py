"""Study runner: wall time of one κ study serially, in two worker processes and on a local Dask cluster.

The grid is the two-step κ sweep of the test suite (6 cells × 20 trials × 50 000
samples). Worker processes start by importing numpy and scipy (about a second each),
so parallel runs pay off only when the grid takes longer than that.
"""

from __future__ import annotations

import time

from benchmarks import Row
from flatland.__main__ import PACKAGE
from flatland.app.study import run_study
from flatland.app.study_config import StudyConfig

CONFIG = {
    "problem": {"integral": "two_steps", "theta": 1.0},
    "methods": [{"method": "boundary"}, {"method": "reparam", "kappa": [1, 10, 100, 1000, 10000]}],
    "n": 50000,
    "trials": 20,
    "seed": 3,
}


def _seconds(**kwargs) -> float:
    """Wall time of the whole study, as the runner measures it (reference, trials and summaries)."""
    return run_study(StudyConfig.from_dict(CONFIG, package=PACKAGE), progress=False, **kwargs).seconds


def run() -> list[Row]:
    """Seconds for the whole study, by execution mode."""
    trials = 6 * CONFIG["trials"]
    rows = [
        Row("study runner", "κ study, serial", _seconds(workers=1), "s", f"{trials} trials"),
        Row("study runner", "κ study, 2 processes", _seconds(workers=2), "s", "incl. worker start-up"),
    ]
    try:
        from dask.distributed import LocalCluster
    except ImportError:  # the optional 'cluster' extra
        return rows
    start = time.perf_counter()
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        up = time.perf_counter() - start
        seconds = _seconds(scheduler=cluster.scheduler_address)
    rows.append(
        Row("study runner", "κ study, local Dask (2 workers)", seconds, "s", f"cluster start {up:.1f} s")
    )
    return rows
