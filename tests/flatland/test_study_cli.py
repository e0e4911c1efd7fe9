"""The κ trade-off (Loubet et al. 2019, Sec. 4.2), asserted from the CSV ``python -m flatland study`` writes.

Study: reparam with a Gaussian kernel on the two-step integral 1[θ < x < 2θ] K(x) at
θ = 1, κ in {1, 10, 100, 1000, 10000}, 20 trials of 50 000 samples, seed 3, 99 %
intervals. One translation cannot follow both steps; the kernel term carries the
rest, leaving a bias that shrinks as the kernel narrows, while the derivative of
log k grows like √κ and with it the variance.

Measured with 10 × 200 000 samples per κ (seeds 0-9): bias -0.092 ± 0.0004,
-0.018 ± 0.001, -0.004 ± 0.003, -0.011 ± 0.009, -0.035 ± 0.028 (the last two
consistent with 0); variance per sample 0.35, 1.95, 16.4, 161, 1580.
"""

from __future__ import annotations

import itertools
import json
import subprocess
import sys

import pytest
from scipy import stats

from flatland.app.study import read_csv
from tests.tiers import HANG

KAPPAS = (1, 10, 100, 1000, 10000)
CONFIG = {
    "name": "kappa_two_steps",
    "problem": {"integral": "two_steps", "theta": 1.0},
    "methods": [{"method": "boundary"}, {"method": "reparam", "kappa": list(KAPPAS)}],
    "n": 50000,
    "trials": 20,
    "seed": 3,
    "level": 0.99,
}


@pytest.fixture(scope="module")
def kappa_study(tmp_path_factory):
    folder = tmp_path_factory.mktemp("kappa")
    config = folder / "kappa_two_steps.json"
    config.write_text(json.dumps(CONFIG))
    out = folder / "out"
    run = subprocess.run(
        [sys.executable, "-m", "flatland", "study", str(config), "--out", str(out), "--quiet"],
        capture_output=True,
        text=True,
        timeout=HANG,
    )
    assert run.returncode == 0, run.stderr
    rows = read_csv(out / "kappa_two_steps.csv")
    return out, run, {r["kappa"]: r for r in rows if r["method"] == "reparam"}, rows


def test01_cli_wrote_the_csv_the_figures_and_the_table(kappa_study):
    out, run, by_kappa, rows = kappa_study
    assert sorted(by_kappa) == list(KAPPAS) and len(rows) == 6
    assert (out / "kappa_two_steps_kappa.png").stat().st_size > 10_000
    assert (out / "kappa_two_steps_efficiency.png").stat().st_size > 10_000
    assert "reparam kappa=10000" in run.stdout and run.stderr == ""
    assert all(r["trials"] == 20 and r["samples"] == 50000 and r["level"] == 0.99 for r in rows)


def test02_bias_falls_as_kappa_grows(kappa_study):
    """Significant negative bias at κ = 1 and 10, smaller at 10 than at 1 (disjoint 99 % intervals);
    for κ >= 100 the intervals contain 0 (true biases, measured above, are far inside them)."""
    _, _, by_kappa, _ = kappa_study
    one, ten = by_kappa[1], by_kappa[10]
    assert one["bias_high"] < 0.0 and ten["bias_high"] < 0.0
    assert one["bias_high"] < ten["bias_low"]  # |bias(10)| < |bias(1)|, intervals disjoint
    for kappa in (100, 1000, 10000):
        assert by_kappa[kappa]["bias_low"] <= 0.0 <= by_kappa[kappa]["bias_high"], kappa


def test03_variance_rises_as_kappa_grows(kappa_study):
    """Each tenfold κ step raises the variance per sample by more than the 99.9 % quantile of the
    F(19, 19) distribution of a ratio of two 20-trial sample variances under equal variances."""
    _, _, by_kappa, _ = kappa_study
    f_crit = stats.f.ppf(0.999, 19, 19)
    for low, high in itertools.pairwise(KAPPAS):
        ratio = by_kappa[high]["variance_per_sample"] / by_kappa[low]["variance_per_sample"]
        assert ratio > f_crit, (low, high, ratio)


def test04_the_boundary_reference_row_is_exact(kappa_study):
    """The boundary estimator adds the exact jump term: no variance, no error beyond rounding."""
    _, _, _, rows = kappa_study
    boundary = next(r for r in rows if r["method"] == "boundary")
    assert boundary["variance_per_sample"] == 0.0 and boundary["rmse"] < 1e-14
    assert boundary["bias_low"] <= 0.0 <= boundary["bias_high"]
