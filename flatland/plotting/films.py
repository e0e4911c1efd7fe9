"""Figures shared by flatland (1D film strips) and sphere3d (2D images): matplotlib only, no numerics.

Gradient images use a diverging colormap centred on zero with one symmetric colour
scale shared by every method in a figure, so equal colours mean equal derivatives.
A 1D film is drawn as a strip (one row of pixels stretched vertically) and, in the
panel, also as curves with ±2 standard-error bands; a 2D film is drawn as an image.
Study figures read :class:`~flatland.app.study_result.StudyResult` rows as they are.

Every function writes one PNG and returns its path; figures are closed after saving.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only; must precede pyplot
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import Normalize

from flatland.app.table import method_label

__all__ = [
    "DIVERGING",
    "PRIMAL",
    "efficiency_figure",
    "error_time_figure",
    "gradient_figure",
    "has_kappa_series",
    "image_figure",
    "kappa_figure",
    "panel_figure",
    "plot_efficiency",
    "plot_error_time",
    "plot_gradient",
    "plot_image",
    "plot_kappa",
    "plot_panel",
    "plot_study",
    "study_figures",
    "symmetric_limit",
]

DIVERGING = "RdBu_r"
"""Colormap for derivatives: blue negative, white zero, red positive."""
PRIMAL = "gray"
"""Colormap for radiance."""
DPI = 110


def symmetric_limit(arrays: Sequence[np.ndarray], percentile: float = 99.5) -> float:
    """One colour limit for all ``arrays``: the largest ``percentile`` of |a| among them.

    A percentile rather than the maximum, so that a few noisy pixels (finite
    differences) do not wash out every other image; 1.0 when everything is zero.
    """
    limits = [float(np.percentile(np.abs(a), percentile)) for a in arrays if np.size(a)]
    limit = max(limits, default=0.0)
    if limit == 0.0 or not math.isfinite(limit):
        limit = max((float(np.max(np.abs(a))) for a in arrays if np.size(a)), default=0.0)
    return limit if limit > 0.0 and math.isfinite(limit) else 1.0


def _save(fig: Any, path: str | os.PathLike) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return path


def _film(ax: Any, array: np.ndarray, cmap: str, norm: Normalize, title: str = "") -> Any:
    """Draw a 1D film as a strip or a 2D film as an image; returns the mappable."""
    array = np.asarray(array, dtype=np.float64)
    if array.ndim == 1:
        im = ax.imshow(array[None, :], cmap=cmap, norm=norm, aspect="auto", interpolation="nearest",
                       extent=(0, array.size, 0, 1))  # fmt: skip
        ax.set_yticks([])
        ax.set_xlabel("pixel")
    else:
        im = ax.imshow(array, cmap=cmap, norm=norm, interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=10)
    return im


def _curve(ax: Any, array: np.ndarray, stderr: np.ndarray | None, label: str, color: Any = None) -> None:
    x = np.arange(np.size(array)) + 0.5
    (line,) = ax.plot(x, array, lw=1.2, label=label, color=color)
    if stderr is not None:
        ax.fill_between(x, array - 2 * stderr, array + 2 * stderr, color=line.get_color(), alpha=0.2, lw=0)


def image_figure(
    value: np.ndarray, stderr: np.ndarray | None, path: str | os.PathLike, title: str = ""
) -> Path:
    """A rendered image (1D: strip over a curve with ±2 standard errors; 2D: grey image)."""
    value = np.asarray(value)
    norm = Normalize(0.0, max(float(np.max(value)), 1e-12))
    if value.ndim == 1:
        fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 3.2), height_ratios=(1, 2), sharex=True)
        _film(top, value, PRIMAL, norm, title)
        top.set_xlabel("")
        _curve(bottom, value, stderr, "radiance", color="k")
        bottom.set_xlabel("pixel")
        bottom.set_ylabel("radiance")
        bottom.set_xlim(0, value.size)
    else:
        fig, ax = plt.subplots(figsize=(5, 5 * value.shape[0] / max(value.shape[1], 1) + 0.4))
        fig.colorbar(_film(ax, value, PRIMAL, norm, title), ax=ax, shrink=0.8)
    return _save(fig, path)


def gradient_figure(
    derivative: np.ndarray, stderr: np.ndarray | None, path: str | os.PathLike, title: str = "",
    limit: float | None = None,
) -> Path:  # fmt: skip
    """A derivative image on the diverging map centred on zero (1D: strip over a curve)."""
    derivative = np.asarray(derivative)
    limit = symmetric_limit([derivative]) if limit is None else limit
    norm = Normalize(-limit, limit)
    if derivative.ndim == 1:
        fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 3.2), height_ratios=(1, 2), sharex=True)
        fig.colorbar(
            _film(top, derivative, DIVERGING, norm, title), ax=[top, bottom], shrink=0.6, label="dI/dθ"
        )
        top.set_xlabel("")
        _curve(bottom, derivative, stderr, "dI/dθ", color="k")
        bottom.axhline(0.0, color="0.5", lw=0.6)
        bottom.set_xlabel("pixel")
        bottom.set_ylabel("dI/dθ")
        bottom.set_xlim(0, derivative.size)
    else:
        fig, ax = plt.subplots(figsize=(5, 5 * derivative.shape[0] / max(derivative.shape[1], 1) + 0.4))
        fig.colorbar(_film(ax, derivative, DIVERGING, norm, title), ax=ax, shrink=0.8, label="dI/dθ")
    return _save(fig, path)


def panel_figure(
    primal: np.ndarray,
    gradients: Mapping[str, tuple[np.ndarray, np.ndarray | None]],
    path: str | os.PathLike,
    title: str = "",
) -> Path:
    """The side-by-side panel: primal, then each method's derivative on one shared diverging scale.

    ``gradients`` maps a column title to ``(derivative, stderr)``. A 1D film gets a
    second row with all derivatives as curves (±2 standard errors) on one axis.
    """
    primal = np.asarray(primal)
    columns = 1 + len(gradients)
    limit = symmetric_limit([np.asarray(d) for d, _ in gradients.values()])
    norm = Normalize(-limit, limit)
    primal_norm = Normalize(0.0, max(float(np.max(primal)), 1e-12))
    if primal.ndim == 1:
        fig = plt.figure(figsize=(2.6 * columns, 5.2))
        grid = fig.add_gridspec(2, columns, height_ratios=(1, 1.6), hspace=0.45)
        axes = [fig.add_subplot(grid[0, i]) for i in range(columns)]
        curves = fig.add_subplot(grid[1, :])
    else:
        aspect = primal.shape[0] / max(primal.shape[1], 1)
        fig, axes = plt.subplots(
            1, columns, figsize=(2.6 * columns, 2.6 * aspect + 0.9), layout="constrained"
        )
        axes, curves = list(np.atleast_1d(axes)), None
    _film(axes[0], primal, PRIMAL, primal_norm, "primal")
    mappable = None
    for ax, (label, (derivative, _)) in zip(axes[1:], gradients.items(), strict=True):
        mappable = _film(ax, derivative, DIVERGING, norm, label)
    if mappable is not None:
        fig.colorbar(mappable, ax=axes, shrink=0.85, label="dI/dθ (shared scale)", pad=0.02)
    if curves is not None:
        for label, (derivative, stderr) in gradients.items():
            _curve(curves, np.asarray(derivative), None if stderr is None else np.asarray(stderr), label)
        curves.axhline(0.0, color="0.5", lw=0.6)
        curves.set_xlim(0, primal.size)
        curves.set_ylim(-1.15 * limit, 1.15 * limit)
        curves.set_xlabel("pixel")
        curves.set_ylabel("dI/dθ")
        curves.legend(fontsize=8, ncols=min(len(gradients), 5), loc="upper right")
    if title:
        fig.suptitle(title)
    return _save(fig, path)


# ---------------------------------------------------------------------------------------- study figures
def _series(rows: Sequence[Any]) -> dict[str, list[Any]]:
    """Rows that vary ``kappa``, grouped by everything else (method, other options, sample count).

    Keyed by a label showing the method, the other options the configuration set, and n.
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
        labels[key] = f"{method_label(cell.method, shown)} n={cell.n}"
        groups.setdefault(key, []).append(r)
    return {
        labels[k]: sorted(v, key=lambda r: r.cell.options_dict["kappa"])
        for k, v in groups.items()
        if len(v) > 1
    }


def has_kappa_series(rows: Sequence[Any]) -> bool:
    """True if some method is run at two or more values of ``kappa``."""
    return bool(_series(rows))


def kappa_figure(rows: Sequence[Any], path: str | os.PathLike, title: str = "") -> Path:
    """Bias ± confidence interval and standard deviation per sample against κ, on log axes.

    The trade-off of Loubet et al. 2019, Sec. 4.2: a wide kernel (small κ) leaves
    bias, a narrow one (large κ) adds variance.
    """
    series = _series(rows)
    if not series:
        raise ValueError("rows: no method is run at two or more values of kappa")
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    for label, group in series.items():
        kappa = [r.cell.options_dict["kappa"] for r in group]
        bias = np.array([r.bias for r in group])
        err = np.array([[r.bias - r.bias_low for r in group], [r.bias_high - r.bias for r in group]])
        left.errorbar(kappa, bias, yerr=err, marker="o", capsize=3, label=label)
        right.plot(kappa, [math.sqrt(r.variance_per_sample) for r in group], marker="o", label=label)
    level = rows[0].level
    left.axhline(0.0, color="0.4", lw=0.8, ls="--")
    left.set_xscale("log")
    left.set_yscale("symlog", linthresh=_linthresh([r for group in series.values() for r in group]))
    left.set_xlabel("κ (kernel concentration)")
    left.set_ylabel(f"bias of dI/dθ (±{level:.0%} CI)")
    left.set_title("bias (wide kernel: transform misses discontinuities)", fontsize=10)
    right.set_xscale("log")
    right.set_yscale("log")
    right.set_xlabel("κ (kernel concentration)")
    right.set_ylabel("standard deviation per sample")
    right.set_title("noise (narrow kernel: large d log k / dθ)", fontsize=10)
    for ax in (left, right):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def _linthresh(rows: Sequence[Any]) -> float:
    """Linear range of the symlog bias axis: the smallest interval half-width, so CIs stay readable."""
    widths = [0.5 * (r.bias_high - r.bias_low) for r in rows if r.bias_high > r.bias_low]
    return max(min(widths, default=1e-3), 1e-12)


def efficiency_figure(rows: Sequence[Any], path: str | os.PathLike, title: str = "") -> Path:
    """Equal-time comparison: efficiency 1/(variance × time) bars and the RMSE a fixed budget buys.

    Efficiency ignores bias, so a cell without one (``efficiency`` None: biased, or
    its interval excludes 0) gets no bar, only the label "biased" or "bias CI ∌ 0";
    a zero-variance unbiased estimator's bar is drawn to the top and labelled
    "σ² = 0". The right-hand bars (``equal_time_rmse``) count the bias.
    """
    labels = [r.cell.label + ("" if len({x.cell.n for x in rows}) == 1 else f" n={r.cell.n}") for r in rows]
    colors = [f"C{sorted({r.cell.method for r in rows}).index(r.cell.method)}" for r in rows]
    shown = [r.efficiency for r in rows if r.efficiency is not None]
    finite = [e for e in shown if math.isfinite(e) and e > 0]
    top = 10 * max(finite) if finite else 1.0
    bottom = min(finite) / 10 if finite else 0.1
    y = np.arange(len(rows))
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 0.45 * len(rows) + 1.6), sharey=True)
    for yi, r, color in zip(y, rows, colors, strict=True):
        if r.efficiency is None:  # no bar: an efficiency would rank a biased estimator
            text = "biased" if r.biased else "bias CI ∌ 0"
            left.text(bottom, yi, f" {text}", ha="left", va="center", fontsize=8, color="C3")
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
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def error_time_figure(rows: Sequence[Any], path: str | os.PathLike, title: str = "") -> Path:
    """RMSE against the reference versus wall time per estimate, log-log, one line per method.

    Each line joins one method's cells (same options) at its sample counts. An
    unbiased estimator's RMSE falls as 1/sqrt(t) (the dotted guide, drawn through
    the geometric centre of the unbiased points); a biased one levels off at its
    |bias| (dashed line, "BIASED" in the legend, its |bias| at the largest count
    drawn as a thin horizontal line). Cells with an RMSE of 0 cannot sit on a log
    axis and are left out (their method's legend entry says so).
    """
    groups: dict[str, list[Any]] = {}
    for r in rows:
        groups.setdefault(r.cell.label, []).append(r)
    fig, ax = plt.subplots(figsize=(7.5, 5.2), layout="constrained")
    unbiased_points = []
    for i, (label, group) in enumerate(groups.items()):
        group = sorted(group, key=lambda r: r.cell.n)
        points = [(r.seconds_per_trial, r.rmse) for r in group if r.rmse > 0.0 and r.seconds_per_trial > 0.0]
        biased = any(r.biased for r in group)
        name = (
            label
            + (" (BIASED)" if biased else "")
            + ("" if len(points) == len(group) else " (rmse 0 left out)")
        )
        color = f"C{i % 10}"
        if points:
            t, e = np.array(points).T
            ax.plot(t, e, marker="o", ms=4, lw=1.4, ls="--" if biased else "-", color=color, label=name)
        else:
            ax.plot([], [], marker="o", color=color, label=name)
        if biased:
            ax.axhline(abs(group[-1].bias), color=color, lw=0.7, ls=":", alpha=0.8)
        elif points:
            unbiased_points.extend(points)
    if unbiased_points:
        t, e = np.array(unbiased_points).T
        t0, e0 = math.exp(np.mean(np.log(t))), math.exp(np.mean(np.log(e)))
        guide = np.geomspace(t.min(), t.max(), 20)
        ax.plot(guide, e0 * np.sqrt(t0 / guide), color="0.3", lw=1.0, ls=":", label="∝ 1/√t (guide)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time per estimate (s)")
    ax.set_ylabel("RMSE of dI/dθ vs the reference")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    if title:
        ax.set_title(title, fontsize=10)
    return _save(fig, path)


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


# ------------------------------------------------------------------- result-level API (package plot modules)
def plot_image(image: Any, path: str | os.PathLike, title: str = "") -> Path:
    """PNG of an :class:`~flatland.core.image.Image`."""
    return image_figure(image.value, image.stderr, path, title or image.scene)


def plot_gradient(
    gradient: Any, path: str | os.PathLike, title: str = "", limit: float | None = None
) -> Path:
    """PNG of a :class:`~flatland.core.image.GradientImage`'s derivative, diverging map centred on 0."""
    title = title or f"{gradient.scene}: d/d {gradient.param} ({gradient.method})"
    return gradient_figure(gradient.derivative, gradient.derivative_stderr, path, title, limit)


def plot_panel(primal: Any, gradients: Mapping[str, Any], path: str | os.PathLike, title: str = "") -> Path:
    """The side-by-side panel from an Image and GradientImages keyed by column title."""
    columns = {label: (g.derivative, g.derivative_stderr) for label, g in gradients.items()}
    return panel_figure(primal.value, columns, path, title)


def _study_title(result: Any) -> str:
    """One title for every figure of a study: its name, the scalar studied and the reference."""
    config = result.config
    return f"study {config.name!r}: dI/dθ of {config.problem.label}\n(reference: {result.reference.source})"


def plot_kappa(result: Any, path: str | os.PathLike) -> Path:
    """Bias ± CI and standard deviation against κ for a study result."""
    return kappa_figure(result.rows, path, _study_title(result))


def plot_error_time(result: Any, path: str | os.PathLike) -> Path:
    """RMSE versus wall time per estimate for a study result (log-log, one line per method)."""
    return error_time_figure(result.rows, path, _study_title(result))


def plot_efficiency(result: Any, path: str | os.PathLike) -> Path:
    """Equal-time efficiency bars for a study result."""
    return efficiency_figure(result.rows, path, _study_title(result))


plot_study = study_figures
