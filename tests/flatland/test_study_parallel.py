"""The same study serially, in two worker processes and on a local Dask cluster: identical numbers.

Only the measured times (and what is computed from them) may differ.
"""

from __future__ import annotations

import pytest

from flatland.__main__ import PACKAGE
from flatland.app.study import CSV_COLUMNS, run_study
from flatland.app.study_config import StudyConfig
from tests.tiers import SLOW

TIMED = {
    "seconds_per_sample",
    "seconds_per_trial",
    "efficiency",
    "equal_time_rmse",
    "rank",
}  # rank: by efficiency
CONFIG = {
    "problem": {"integral": "arc_stretch", "theta": 1.0},
    "methods": [
        {"method": "naive"},
        {"method": "finite_difference"},
        {"method": "reparam", "kappa": [10, 1000], "paired": [False, True]},
    ],
    "n": 3000,
    "trials": 4,
    "seed": 12,
}


def _numbers(result):
    columns = [c for c in CSV_COLUMNS if c not in TIMED and hasattr(result.rows[0], c)]
    return [(row.cell, row.derivatives, [getattr(row, c) for c in columns]) for row in result.rows]


@pytest.fixture(scope="module")
def serial():
    return run_study(StudyConfig.from_dict(CONFIG, package=PACKAGE), workers=1, progress=False)


def test01_two_worker_processes_give_identical_numbers(serial):
    config = StudyConfig.from_dict(
        {**CONFIG, "workers": 2}, package=PACKAGE
    )  # the config's setting, not overridden
    assert config.workers == 2
    pooled = run_study(config, progress=False)
    assert _numbers(pooled) == _numbers(serial)
    assert len(serial.rows) == 6 and all(len(r.derivatives) == 4 for r in serial.rows)


@SLOW  # test01 checks the same identity with two worker processes
def test02_a_local_dask_cluster_gives_identical_numbers(serial):
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        on_cluster = run_study(
            StudyConfig.from_dict(CONFIG, package=PACKAGE),
            scheduler=cluster.scheduler_address,
            progress=False,
        )
    assert _numbers(on_cluster) == _numbers(serial)
