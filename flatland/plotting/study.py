"""Study figures written to PNG files: error against time, bias and noise against κ, efficiency.

They read :class:`~flatland.app.study_result.StudyResult` rows as they are. Each
method has its fixed colour (:mod:`flatland.plotting.style`) and the variants of one
method (other options) its markers; the bias against κ is drawn with its confidence
interval by :func:`~flatland.plotting.bands.draw_estimate`, whose legend states the
coverage.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter

from flatland.app.table import method_label
from flatland.plotting.bands import draw_estimate
from flatland.plotting.films import save_png
from flatland.plotting.style import legend_outside, log_ticks, series_styles, symlog_axis

__all__ = [
    "efficiency_figure",
    "error_time_figure",
    "has_kappa_series",
    "kappa_figure",
    "plot_efficiency",
    "plot_error_time",
    "plot_kappa",
    "plot_study",
    "study_figures",
]


def _series(rows: Sequence[Any], count: str = "n") -> dict[str, list[Any]]:
    """Rows that vary ``kappa``, grouped by everything else (method, other options, sample count).

    Keyed by a label showing the method, the other options the configuration set, and the
    sample count per trial under its name ``count`` (``n`` for integrals, ``spp`` for scenes).
    """
    groups: dict[tuple[Any, ...], list[Any]] = {}
    labels: dict[tuple[Any, ...], str] = {}
    for r in rows:
        cell = r.cell
        options = cell.options_dict
        if options.get("kappa") is None:
            continue
        key = (cell.method, tuple((k, repr(v)) for k, v in cell.options if k != "kappa"), cell.n)
        shown = [(k, v) for k, v in cell.options if k != "kappa" and k in cell.given]
        labels[key] = f"{method_label(cell.method, shown)} {count}={cell.n}"
        groups.setdefault(key, []).append(r)
    return {
        labels[k]: sorted(v, key=lambda r: r.cell.options_dict["kappa"])
        for k, v in groups.items()
        if len(v) > 1
    }


def has_kappa_series(rows: Sequence[Any]) -> bool:
    """True if some method is run at two or more values of ``kappa``."""
    return bool(_series(rows))


def kappa_figure(rows: Sequence[Any], path: str | os.PathLike, title: str = "", count: str = "n") -> Path:
    """Bias ± confidence interval and standard deviation per sample against κ, on log axes.

    The trade-off of Loubet et al. 2019, Sec. 4.2: a wide kernel (small κ) leaves
    bias, a narrow one (large κ) adds variance. Each series (a method's other options and
    sample count, ``count`` its name in the legend) has its own shade and marker; the
    legend sits under the panels, clear of the data.
    """
    series = _series(rows, count)
    if not series:
        raise ValueError("rows: no method is run at two or more values of kappa")
    fig = Figure(figsize=(11, 4.6 + 0.2 * math.ceil(len(series) / 3)), layout="constrained")
    left, right = fig.subplots(1, 2)
    level = rows[0].level
    styles = series_styles(series)
    for label, group in series.items():
        kappa = [r.cell.options_dict["kappa"] for r in group]
        bias = np.array([r.bias for r in group])
        bounds = (np.array([r.bias_low for r in group]), np.array([r.bias_high for r in group]))
        draw_estimate(left, kappa, bias, bounds=bounds, level=level, kind="bars", label=label, fmt="-",
                      capsize=3, **styles[label])  # fmt: skip
        right.plot(kappa, [math.sqrt(r.variance_per_sample) for r in group], label=label, **styles[label])
    left.axhline(0.0, color="0.4", lw=0.8, ls="--")
    left.set_xscale("log")
    shown = [r for group in series.values() for r in group]
    extent = [v for r in shown for v in (r.bias_low, r.bias_high)]
    symlog_axis(left, extent, _linthresh(shown))
    left.set_xlabel("κ (kernel concentration)")
    left.set_ylabel("bias of dI/dθ")
    left.set_title("bias (wide kernel: transform misses discontinuities)", fontsize=10)
    right.set_xscale("log")
    right.set_yscale("log")
    right.set_xlabel("κ (kernel concentration)")
    right.set_ylabel("standard deviation per sample")
    right.set_title("noise (narrow kernel: large d log k / dθ)", fontsize=10)
    for ax in (left, right):
        ax.grid(True, which="both", alpha=0.3)
    handles, names = left.get_legend_handles_labels()
    fig.legend(handles, names, loc="outside lower center", ncols=min(3, len(names)), fontsize=8)
    if title:
        fig.suptitle(title)
    return save_png(fig, path)


def _linthresh(rows: Sequence[Any]) -> float:
    """Linear range of the symlog bias axis: the smallest interval half-width, so CIs stay readable."""
    widths = [0.5 * (r.bias_high - r.bias_low) for r in rows if r.bias_high > r.bias_low]
    return max(min(widths, default=1e-3), 1e-12)


def efficiency_figure(rows: Sequence[Any], path: str | os.PathLike, title: str = "") -> Path:
    r"""Equal-time comparison: efficiency $1/(\mathrm{variance} × \mathrm{time})$ bars
    and the RMSE a fixed budget buys.

    Efficiency ignores bias, so a cell without one (``efficiency`` None: biased, or
    its interval excludes 0) gets no bar, only the label "biased" or "bias CI ∌ 0";
    a zero-variance unbiased estimator's bar is drawn to the top and labelled
    "σ² = 0". The right-hand bars (``equal_time_rmse``) count the bias.
    """
    labels = [r.cell.label + ("" if len({x.cell.n for x in rows}) == 1 else f" n={r.cell.n}") for r in rows]
    method_styles = series_styles(sorted({r.cell.method for r in rows}))  # one colour per method
    colors = [method_styles[r.cell.method]["color"] for r in rows]
    shown = [r.efficiency for r in rows if r.efficiency is not None]
    finite = [e for e in shown if math.isfinite(e) and e > 0]
    top = 10 * max(finite) if finite else 1.0
    bottom = min(finite) / 10 if finite else 0.1
    y = np.arange(len(rows))
    fig = Figure(figsize=(11, 0.45 * len(rows) + 1.6))
    left, right = fig.subplots(1, 2, sharey=True)
    for yi, r, color in zip(y, rows, colors, strict=True):
        if r.efficiency is None:  # no bar: an efficiency would rank a biased estimator
            text = "biased" if r.biased else "bias CI ∌ 0"
            left.text(bottom, yi, f" {text}", ha="left", va="center", fontsize=8, color="0.3")
            continue
        height = r.efficiency if math.isfinite(r.efficiency) else top
        left.barh(yi, height - bottom, color=color, left=bottom)
        if math.isfinite(r.efficiency):
            left.text(max(height, bottom), yi, f" {height:.2g}", ha="left", va="center", fontsize=7)
        else:
            left.text(top, yi, " σ² = 0 ", ha="right", va="center", fontsize=8, color="white")
    left.set_xscale("log")
    left.set_xlim(bottom, top)
    left.set_yticks(y, labels, fontsize=8)
    left.invert_yaxis()
    left.set_xlabel("efficiency 1 / (variance per sample × seconds per sample), unbiased cells only")
    budget = rows[0].time_budget
    rmse = [r.equal_time_rmse for r in rows]
    # a log axis spanning four decades below the worst RMSE; smaller values sit on its edge, labelled
    floor = max(rmse) * 1e-4 if max(rmse) > 0 else 1e-12
    right.barh(y, [max(v, floor) - floor for v in rmse], color=colors, left=floor)
    for yi, v in zip(y, rmse, strict=True):
        right.text(max(v, floor), yi, f" {v:.2g}", ha="left", va="center", fontsize=7)
    right.set_xscale("log")
    right.set_xlim(floor, max(rmse) * 8 if max(rmse) > 0 else 1.0)
    right.set_xlabel(f"RMSE after {budget:g} s of sampling (bias included)")
    for ax in (left, right):
        ax.grid(True, axis="x", which="both", alpha=0.3)
        # decades only: minor labels (2e-4 beside 1e-4) collide when the data span few decades
        ax.xaxis.set_minor_formatter(NullFormatter())
    if title:
        fig.suptitle(title)
    return save_png(fig, path)


def error_time_figure(rows: Sequence[Any], path: str | os.PathLike, title: str = "") -> Path:
    """RMSE against the reference versus wall time per estimate, log-log, one line per method.

    Each line joins one method's cells (same options) at its sample counts, in the
    method's colour (its variants in shades of it, with their own markers). An
    unbiased estimator's RMSE falls as 1/sqrt(t) (the dotted guide, drawn through
    the geometric centre of the unbiased points); a biased one levels off at its
    |bias| (dashed line, "BIASED" in the legend, its |bias| at the largest count
    drawn as a thin horizontal line). Cells with an RMSE of 0 (an exact estimator)
    cannot sit on a log axis: the legend entry of a series with some says how many
    are not drawn, and a series with nothing else is named under the axis instead of
    in the legend. The legend stands right of the axes, clear of the data.
    """
    groups: dict[str, list[Any]] = {}
    for r in rows:
        groups.setdefault(r.cell.label, []).append(r)
    fig = Figure(figsize=(9.5, 5.2), layout="constrained")
    ax = fig.subplots()
    styles = series_styles(groups)  # a method's colour; its variants (other options) by shade and marker
    unbiased_points = []
    exact = []
    for label, group in groups.items():
        group = sorted(group, key=lambda r: r.cell.n)
        points = [(r.seconds_per_trial, r.rmse) for r in group if r.rmse > 0.0 and r.seconds_per_trial > 0.0]
        biased = any(r.biased for r in group)
        if not points:
            exact.append(label)
            continue
        left_out = len(group) - len(points)
        name = (
            label
            + (" (BIASED)" if biased else "")
            + (f" ({left_out} cells with RMSE 0 not drawn)" if left_out else "")
        )
        color, marker = styles[label]["color"], styles[label]["marker"]
        t, e = np.array(points).T
        ax.plot(t, e, marker=marker, ms=4, lw=1.4, ls="--" if biased else "-", color=color, label=name)
        if biased:
            ax.axhline(abs(group[-1].bias), color=color, lw=0.7, ls=":", alpha=0.8)
        else:
            unbiased_points.extend(points)
    if unbiased_points:
        t, e = np.array(unbiased_points).T
        t0, e0 = math.exp(np.mean(np.log(t))), math.exp(np.mean(np.log(e)))
        guide = np.geomspace(t.min(), t.max(), 20)
        ax.plot(guide, e0 * np.sqrt(t0 / guide), color="0.3", lw=1.0, ls=":", label="∝ 1/√t (guide)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    log_ticks(ax.xaxis)
    log_ticks(ax.yaxis)
    note = f"\nRMSE 0 at every sample count, not on the log axis: {', '.join(exact)}" if exact else ""
    ax.set_xlabel("wall time per estimate (s)" + note)
    ax.set_ylabel("RMSE of dI/dθ vs the reference")
    ax.grid(True, which="both", alpha=0.3)
    legend_outside(ax, fontsize=7)
    if title:
        ax.set_title(title, fontsize=10)
    return save_png(fig, path)


def study_figures(result: Any, out_dir: str | os.PathLike) -> list[Path]:
    """The figures of a study: ``<name>_error_time.png`` (the main one), ``<name>_kappa.png`` (if κ
    is swept) and ``<name>_efficiency.png``."""
    out_dir = Path(out_dir)
    name = result.config.name
    paths = [plot_error_time(result, out_dir / f"{name}_error_time.png")]
    if has_kappa_series(result.rows):
        paths.append(plot_kappa(result, out_dir / f"{name}_kappa.png"))
    paths.append(plot_efficiency(result, out_dir / f"{name}_efficiency.png"))
    return paths


def _study_title(result: Any) -> str:
    """One title for every figure of a study: its name, the scalar studied and the reference."""
    config = result.config
    return f"study {config.name!r}: dI/dθ of {config.problem.label}\n(reference: {result.reference.source})"


def plot_kappa(result: Any, path: str | os.PathLike) -> Path:
    """Bias ± CI and standard deviation against κ for a study result."""
    return kappa_figure(result.rows, path, _study_title(result), result.config.problem.count_name)


def plot_error_time(result: Any, path: str | os.PathLike) -> Path:
    """RMSE versus wall time per estimate for a study result (log-log, one line per method)."""
    return error_time_figure(result.rows, path, _study_title(result))


def plot_efficiency(result: Any, path: str | os.PathLike) -> Path:
    """Equal-time efficiency bars for a study result."""
    return efficiency_figure(result.rows, path, _study_title(result))


plot_study = study_figures
