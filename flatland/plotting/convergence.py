r"""Error against time of gradient methods measured in a notebook: log-log, one line per method.

The study runner draws the same picture from its result files
(:func:`flatland.plotting.study.error_time_figure`); this helper draws measurements made in
memory, as a tutorial makes them: for each method, the seconds each estimate took and its
root-mean-square error against a reference. Like :mod:`flatland.plotting.tutorials`, it
computes nothing and returns a :class:`~matplotlib.figure.Figure` made without pyplot.

An unbiased method's mean squared error is its variance, which falls as 1/t with the
time t spent on samples, so its RMSE falls as $1/\sqrt{t}$ (a straight line of slope -1/2 on
log-log axes, the dotted guide). A biased method's RMSE levels off at its bias: the
floor, if given, is drawn as a thin horizontal line in the method's colour.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from flatland.core.validate import ValidationError
from flatland.plotting.style import FIGSIZE, legend_outside, log_ticks, new_axes, series_styles

__all__ = ["plot_error_time"]


def _points(label: str, item: tuple[Sequence[float], Sequence[float]]) -> tuple[np.ndarray, np.ndarray]:
    """(seconds, rmse) of one series as float arrays, sorted by time; both positive and finite."""
    try:
        seconds, rmse = (np.asarray(v, dtype=np.float64).ravel() for v in item)
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"series[{label!r}]", f"must be a (seconds, rmse) pair, got {item!r}") from exc
    if seconds.size == 0 or seconds.shape != rmse.shape:
        raise ValidationError(
            f"series[{label!r}]", f"needs as many times as errors (>= 1), got {seconds.size} and {rmse.size}"
        )
    for name, values in (("seconds", seconds), ("rmse", rmse)):
        if not np.all(np.isfinite(values) & (values > 0.0)):
            raise ValidationError(
                f"series[{label!r}]", f"{name} must be finite and > 0 (log axes), got {values}"
            )
    order = np.argsort(seconds)
    return seconds[order], rmse[order]


def plot_error_time(
    series: Mapping[str, tuple[Sequence[float], Sequence[float]]],
    floors: Mapping[str, float] | None = None,
    *,
    ax: Axes | None = None,
    title: str | None = None,
    xlabel: str = "seconds per estimate",
    ylabel: str = "RMSE of dI/dθ",
) -> Figure:
    r"""Draw each method's RMSE against its time per estimate, log-log, with a $1/\sqrt{t}$ guide.

    Parameters
    ----------
    series : mapping of str to (seconds, rmse)
        By label; a label that names a method (``"reparam"``, ``"boundary 2 px"``) gets
        the method's fixed colour (:func:`~flatland.plotting.style.series_styles`). The
        points are joined in order of time.
    floors : mapping of str to float, optional
        A biased method's bias (its RMSE as the time grows), by the label of its series:
        a horizontal line in the series' colour, labelled "bias floor". Zero or negative
        floors are not drawn (nothing to show on a log axis).
    ax, title
        Axes to draw into (a new figure if None) and its title.
    xlabel, ylabel : str
        Axis labels.

    Returns
    -------
    Figure

    Raises
    ------
    ValidationError
        A series without points, with unequal lengths or with a time or error that is
        not finite and positive; a floor for a label that has no series.
    """
    data = {label: _points(label, item) for label, item in series.items()}
    if not data:
        raise ValidationError("series", "needs at least one (seconds, rmse) series")
    floors = dict(floors or {})
    unknown = sorted(set(floors) - set(data))
    if unknown:
        raise ValidationError("floors", f"names no series: {unknown}")
    ax = new_axes(ax, title, (FIGSIZE[0] + 2.4, FIGSIZE[1]))  # room for the legend on the right
    styles = series_styles(data)
    for label, (seconds, rmse) in data.items():
        style = styles[label]
        ax.plot(seconds, rmse, marker=style["marker"], ms=4, lw=1.4, color=style["color"], label=label)
        floor = floors.get(label)
        if floor is not None and floor > 0.0:
            ax.axhline(float(floor), color=style["color"], lw=0.8, ls="--", label=f"{label}: bias floor")
    seconds = np.concatenate([t for t, _ in data.values()])
    errors = np.concatenate([e for _, e in data.values()])
    # the guide passes through the geometric centre of all points: only its slope (-1/2) means anything
    t0, e0 = math.exp(np.mean(np.log(seconds))), math.exp(np.mean(np.log(errors)))
    guide = np.geomspace(seconds.min(), seconds.max(), 16)
    ax.plot(guide, e0 * np.sqrt(t0 / guide), color="0.3", lw=1.0, ls=":", label="∝ 1/√t (guide)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    log_ticks(ax.xaxis)  # a decade or less of seconds: labelled minor ticks would run into each other
    log_ticks(ax.yaxis)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)
    legend_outside(ax, fontsize=7)  # right of the axes, clear of the lines
    return ax.figure
