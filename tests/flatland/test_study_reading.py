"""The paragraph under a study's table (flatland.app.study_reading): every claim follows the rows.

1. The F-law interval of a variance ratio: with equal trial counts it is symmetric in log about the
   ratio (F_q(d, d) = 1 / F_{1-q}(d, d)) and covers the ratio.
2. The κ series is the longest run of rows that differ only in κ; other rows are not in it.
3. The trade-off sentence follows the numbers: a flagged smallest κ and a variance ratio above 1 say
   "trades variance for bias"; the same rows with the smallest κ's interval moved over 0, or with the
   variances swapped, say "not resolved"; the ranking names the winner and the flagged rows.
"""

from __future__ import annotations

import dataclasses
import math

import pytest

from flatland.__main__ import PACKAGE
from flatland.app.study import run_study
from flatland.app.study_config import StudyConfig
from flatland.app.study_reading import kappa_series, reading, variance_ratio


@pytest.fixture(scope="module")
def result():
    """A small real study on the two-step integral (closed-form reference): cheap, every kind of row."""
    config = StudyConfig.from_dict(
        {
            "problem": {"integral": "two_steps", "theta": 1.0},
            "methods": [
                {"method": "naive"},
                {"method": "boundary"},
                {"method": "reparam", "kappa": [1, 100, 10000]},
                {"method": "reparam", "kappa": 100, "paired": True},
            ],
            "n": 2000,
            "trials": 6,
            "seed": 5,
        },
        package=PACKAGE,
    )
    return run_study(config, progress=False)


def test01_the_variance_ratio_interval_is_the_f_law_s(result):
    low, high = kappa_series(result.rows)[0], kappa_series(result.rows)[-1]
    ratio, lo, hi = variance_ratio(low, high, 0.99)
    assert ratio == pytest.approx(high.variance_per_sample / low.variance_per_sample)
    assert lo < ratio < hi and math.log(hi / ratio) == pytest.approx(math.log(ratio / lo), rel=1e-9)
    assert variance_ratio(low, high, 0.5)[1] > lo  # a lower level, a narrower interval


def test02_the_kappa_series_is_one_method_differing_only_in_kappa(result):
    series = kappa_series(result.rows)
    assert [r.cell.options_dict["kappa"] for r in series] == [1, 100, 10000]
    assert not any(r.cell.options_dict["paired"] for r in series)
    assert kappa_series([r for r in result.rows if r.cell.method != "reparam"]) == ()


def _set(rows, kappa, **changes):
    return tuple(
        dataclasses.replace(r, **changes)
        if r.cell.method == "reparam"
        and r.cell.options_dict["kappa"] == kappa
        and not r.cell.options_dict["paired"]
        else r
        for r in rows
    )


def test03_the_tradeoff_sentence_follows_the_numbers(result):
    rows = _set(result.rows, 1, bias=-1.0, bias_low=-1.5, bias_high=-0.5, variance_per_sample=1.0)
    rows = _set(rows, 100, bias=0.0, bias_low=-0.5, bias_high=0.5)
    rows = _set(rows, 10000, bias=0.0, bias_low=-0.5, bias_high=0.5, variance_per_sample=100.0)
    visible = " ".join(reading(dataclasses.replace(result, rows=rows)).split())
    assert "at κ = 1 the bias is -1.00 [-1.50, -0.50], its interval excludes 0" in visible
    assert "from κ = 100 on every interval contains 0" in visible
    assert "100 × as large at κ = 10000" in visible and "trades variance for bias" in visible
    assert "naive" in visible.split("Flagged BIASED:")[1]
    assert f"most efficient unbiased row is {result.ranking()[0].cell.label}" in visible

    hidden = _set(rows, 1, bias_low=-1.5, bias_high=0.5)  # the same bias, its interval over 0
    text = " ".join(reading(dataclasses.replace(result, rows=hidden)).split())
    assert "is not resolved (its interval contains 0)" in text and "trade-off is not resolved" in text
    flat = _set(rows, 10000, variance_per_sample=1.0)  # no growth of the variance
    text = " ".join(reading(dataclasses.replace(result, rows=flat)).split())
    assert "(not resolved: the interval reaches 1)" in text and "trade-off is not resolved" in text
