r"""What a study's table shows, said in words from its numbers: the κ trade-off and the ranking.

:func:`reading` writes the paragraph ``python -m flatland study`` (and sphere3d's) prints under the
table. Nothing in it is fixed in advance: every claim is a test on the rows.

The κ trade-off (Loubet et al. 2019, Sec. 4.2)
    Among the rows of one method that differ only in ``kappa`` (the longest such series; at equal
    length the one with the most samples), the bias of the smallest κ is reported with its interval
    (the table's, simultaneous over the rows) and whether it excludes 0, and the smallest κ from
    which every interval contains 0. The growth of the variance from the smallest to the largest κ
    is the ratio $r = s^2_{\max} / s^2_{\min}$ of the trials' variances (equal sample counts), with
    the two-sided interval $[r / F_{(1+L)/2}, \; r / F_{(1-L)/2}]$ of the F law with $(T - 1, T - 1)$
    degrees of freedom at the study's level L (the trials are independent and, per cell, roughly
    normal). The trade-off is called visible when the smallest κ is flagged and the ratio's interval
    lies above 1; otherwise the sentence says which half is not resolved.
The ranking
    The most efficient unbiased row, the flagged rows (``naive`` drops the jump term of the Leibniz
    rule, so it is flagged wherever that term is resolved), and the most efficient reparam row
    beside the winner as a ratio of efficiencies.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from typing import TYPE_CHECKING

from scipy import special

from flatland.app.table import format_interval, format_level

if TYPE_CHECKING:
    from flatland.app.study_result import CellResult, StudyResult

__all__ = ["kappa_series", "reading", "variance_ratio"]

WIDTH = 100
"""Line width of the printed paragraph."""


def kappa_series(rows: Sequence[CellResult]) -> tuple[CellResult, ...]:
    """The longest series of rows that differ only in ``kappa`` (ties: more samples), by κ; () if none
    has two κ values."""
    groups: dict[tuple, list[CellResult]] = {}
    for r in rows:
        options = r.cell.options_dict
        if options.get("kappa") is None:
            continue
        key = (r.cell.method, r.cell.n, tuple((k, repr(v)) for k, v in r.cell.options if k != "kappa"))
        groups.setdefault(key, []).append(r)
    if not groups:
        return ()
    best = max(groups.values(), key=lambda g: (len({r.cell.options_dict["kappa"] for r in g}), g[0].cell.n))
    series = tuple(sorted(best, key=lambda r: r.cell.options_dict["kappa"]))
    return series if len({r.cell.options_dict["kappa"] for r in series}) >= 2 else ()


def variance_ratio(low: CellResult, high: CellResult, level: float) -> tuple[float, float, float]:
    """``high``'s trial variance over ``low``'s and its F-law interval at ``level`` (module docstring);
    nan when ``low`` has no variance."""
    if not (low.variance_per_sample > 0.0 and low.samples == high.samples):
        return math.nan, math.nan, math.nan
    ratio = high.variance_per_sample / low.variance_per_sample
    dfn, dfd = high.trials - 1, low.trials - 1  # F law quantiles: special.fdtri(dfn, dfd, q)
    upper, lower = special.fdtri(dfn, dfd, 0.5 + level / 2), special.fdtri(dfn, dfd, 0.5 - level / 2)
    return ratio, ratio / upper, ratio / lower


def _two(x: float) -> str:
    """``x`` to two significant digits, without an exponent below 1e6: 100, 390, 0.049."""
    return f"{float(f'{x:.2g}'):g}"


def _kappa(row: CellResult) -> str:
    return f"κ = {row.cell.options_dict['kappa']:g}"


def _bias(row: CellResult) -> str:
    return format_interval(row.bias, row.bias_low, row.bias_high)


def _tradeoff(result: StudyResult) -> list[str]:
    """Sentences on the κ series, or none without one."""
    series = kappa_series(result.rows)
    if not series:
        return []
    level = result.config.level
    first, last = series[0], series[-1]
    where = f"{first.cell.method}, {result.config.problem.count_name}={first.cell.n}"
    out = [f"The κ trade-off ({where}; Loubet et al. 2019, Sec. 4.2):"]
    if first.biased:
        out.append(
            f"at {_kappa(first)} the bias is {_bias(first)}, its interval excludes 0: a wide kernel"
            " lets one transform follow jumps that move differently;"
        )
    else:
        out.append(f"at {_kappa(first)} the bias {_bias(first)} is not resolved (its interval contains 0).")
    clean = [i for i in range(len(series)) if not any(r.biased for r in series[i:])]
    if clean and first.biased:
        out.append(f"from {_kappa(series[clean[0]])} on every interval contains 0.")
    elif not clean:
        out.append(
            f"{'Even' if not first.biased else 'even'} at {_kappa(last)} the bias interval excludes 0."
        )
    ratio, low, high = variance_ratio(first, last, level)
    grows = low > 1.0
    if math.isfinite(ratio):
        verdict = "" if grows else " (not resolved: the interval reaches 1)"
        out.append(
            f"The variance per sample is {_two(ratio)} × as large at {_kappa(last)} as at {_kappa(first)}"
            f" ({format_level(level)} interval {_two(low)} to {_two(high)}){verdict}: a narrow"
            " kernel's weight changes fast."
        )
    best = min(series, key=lambda r: r.equal_time_rmse)
    out.append(
        f"With bias and noise counted at a {result.config.time_budget:g} s budget the best is {_kappa(best)}."
    )
    if first.biased and grows:
        out.append("So a small κ trades variance for bias, a large κ the reverse.")
    else:
        out.append("So the trade-off is not resolved at these settings (more trials or samples would be).")
    return out


def _ranking(result: StudyResult) -> list[str]:
    """Sentences on the winner, the flagged rows and reparam's best row."""
    ranked = result.ranking()
    out = []
    winner = ranked[0] if ranked[0].efficiency is not None else None
    if winner is not None:
        out.append(f"The most efficient unbiased row is {_label(result, winner)}.")
    flagged = [r for r in ranked if r.biased]
    if flagged:
        names = ", ".join(_label(result, r) for r in flagged)
        why = " (naive drops the jump term)" if any(r.cell.method == "naive" for r in flagged) else ""
        out.append(f"Flagged BIASED: {names}{why}.")
    reparam = [r for r in ranked if r.cell.method == "reparam" and r.efficiency is not None]
    if (
        winner is not None
        and reparam
        and winner.cell.method != "reparam"
        and math.isfinite(winner.efficiency)
    ):
        ratio = reparam[0].efficiency / winner.efficiency
        out.append(
            f"reparam's most efficient row, {_label(result, reparam[0])}, has {_two(ratio)} × its efficiency."
        )
        if winner.cell.method == "finite_difference":
            out.append(
                "Finite differences pay two renders per parameter; reparam and boundary give every"
                " parameter's derivative from one render, which a one-parameter study does not count."
            )
    return out


def _label(result: StudyResult, row: CellResult) -> str:
    counts = len(result.sample_counts) > 1
    return row.cell.label + (f" {result.config.problem.count_name}={row.cell.n}" if counts else "")


def reading(result: StudyResult) -> str:
    """The paragraph under a study's table: what the reader should see, from the rows (module docstring)."""
    sentences = ["What to see:", *_tradeoff(result), *_ranking(result)]
    return textwrap.fill(" ".join(sentences), width=WIDTH)
