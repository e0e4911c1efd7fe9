"""Figures of Monte Carlo estimates of the textbook integrals: intervals, variances, the κ trade-off, and
the histogram of repeated estimates against their predicted normal law.

Like :mod:`flatland.plotting.textbook` (which re-exports them), every function draws
data computed elsewhere and returns a :class:`~matplotlib.figure.Figure` made without
pyplot. Estimates with their confidence intervals are drawn by
:func:`~flatland.plotting.bands.draw_estimate`, so the legend states the coverage
("naive ± 99 % interval") and each method has its fixed colour.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from flatland.core.contract import Estimate
from flatland.core.stats import normal_quantile
from flatland.core.validate import ValidationError, check_finite, check_int, check_positive
from flatland.plotting.bands import draw_estimate
from flatland.plotting.style import (
    FIGSIZE,
    METHOD_COLOURS,
    OTHER_COLOURS,
    REFERENCE_STYLE,
    category_ticks,
    coverage_label,
    legend_above_data,
    method_colour,
    new_axes,
    same_length,
    symlog_axis,
)

__all__ = ["plot_estimates", "plot_histogram_vs_normal", "plot_kappa_tradeoff", "plot_variance"]


def _mean_stderr(name: str, item: Estimate | Sequence[float], of: str) -> tuple[float, float]:
    """(mean, stderr) of an Estimate (its value or derivative) or of a (mean, stderr) pair."""
    if isinstance(item, Estimate):
        if of == "derivative":
            return item.derivative, item.derivative_stderr
        return item.value, item.value_stderr
    pair = tuple(float(v) for v in item)
    if len(pair) != 2:
        raise ValidationError(name, f"must be an Estimate or a (mean, stderr) pair, got {item!r}")
    return pair  # type: ignore[return-value]


def plot_estimates(
    estimates: Mapping[str, Estimate | Sequence[float]],
    reference: float | None = None,
    *,
    of: str = "derivative",
    level: float = 0.99,
    reference_label: str = "closed form",
    ax: Axes | None = None,
    title: str | None = None,
    ylabel: str | None = None,
) -> Figure:
    """Draw one estimate per label with its two-sided confidence interval, against a reference.

    Parameters
    ----------
    estimates : mapping of str to Estimate or (mean, stderr)
        By label (method name, proposal, ...).
    reference : float, optional
        The closed form, drawn as a dashed horizontal line.
    of : {"derivative", "value"}
        Which part of an :class:`Estimate` to draw.
    level : float
        Confidence level of the error bars: ± z · stderr with z the two-sided normal
        quantile (:func:`~flatland.core.stats.normal_quantile`; 2.58 at 0.99). The
        legend states it; a label that names a method gets the method's colour.
    reference_label : str
        Legend entry of the reference line.
    ax, title
        As in :func:`plot_integrand`.
    ylabel : str, optional
        Defaults to "dI/dθ" or "I" after ``of``.

    Returns
    -------
    Figure
    """
    if of not in ("derivative", "value"):
        raise ValidationError("of", f"must be 'derivative' or 'value', got {of!r}")
    labels = list(estimates)
    pairs = [_mean_stderr(f"estimates[{k!r}]", estimates[k], of) for k in labels]
    ax = new_axes(ax, title)
    positions = np.arange(len(labels), dtype=np.float64)
    for i, (position, label, (mean, stderr)) in enumerate(zip(positions, labels, pairs, strict=True)):
        # one legend entry "estimate ± 99 % interval"; each bar in its method's colour
        draw_estimate(ax, [position], [mean], stderr=[stderr], level=level, kind="bars",
                      color=method_colour(label), label=None if i == 0 else "_estimate")  # fmt: skip
    if reference is not None:
        ax.axhline(float(reference), label=reference_label, **REFERENCE_STYLE)
    category_ticks(ax, positions, labels)
    ax.set_xlim(-0.5, len(labels) - 0.5)
    ax.set_ylabel(ylabel or ("dI/dθ" if of == "derivative" else "I"))
    legend_above_data(ax)  # upper right, the values below it: it never covers a bar
    return ax.figure


def plot_variance(
    n: Any,
    variances: Mapping[str, Any],
    *,
    predicted: Mapping[str, Any] | None = None,
    ax: Axes | None = None,
    title: str | None = None,
    xlabel: str = "samples n",
    ylabel: str = "variance of the estimate",
) -> Figure:
    """Draw measured variances against the sample count on log-log axes.

    A Monte Carlo estimate's variance falls like Var/n: a line of slope -1 here.

    Parameters
    ----------
    n : array_like, shape (m,)
        Sample counts.
    variances : mapping of str to array_like, shape (m,)
        Measured variances by label, drawn as markers.
    predicted : mapping of str to array_like, shape (m,), optional
        Predicted variances (e.g. Var_p[f/p] / n), drawn as dashed lines in the
        colour of the measured series with the same label.
    ax, title, xlabel, ylabel
        As in :func:`plot_integrand`.

    Returns
    -------
    Figure
    """
    n = np.asarray(n, dtype=np.float64).ravel()
    predicted = predicted or {}
    ax = new_axes(ax, title)
    for label, v in variances.items():
        values = same_length(f"variances[{label!r}]", v, n.size)
        (line,) = ax.plot(n, values, "o", label=label, color=method_colour(label))
        if label in predicted:
            ax.plot(n, same_length(f"predicted[{label!r}]", predicted[label], n.size), "--",
                    color=line.get_color(), linewidth=1.0, label=f"{label}: predicted")  # fmt: skip
    for label, v in predicted.items():
        if label not in variances:
            ax.plot(n, same_length(f"predicted[{label!r}]", v, n.size), "--", linewidth=1.0, label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    legend_above_data(ax)  # upper right, the values below it: it never covers a bar
    return ax.figure


def plot_kappa_tradeoff(
    kappa: Any,
    bias: Any,
    halfwidth: Any,
    std: Any,
    *,
    predicted_bias: tuple[Any, Any] | None = None,
    predicted_std: tuple[Any, Any] | None = None,
    level: float,
    title: str | None = None,
) -> Figure:
    r"""Two panels over the kernel concentration κ: bias ± interval, and standard deviation.

    The convolution kernel's trade-off (Loubet et al. 2019, Sec. 4.2):
    small κ (a wide kernel) reaches discontinuities one transform cannot follow, so
    the bias is large; large κ makes the derivative of log k large, so the standard
    deviation grows (like $\sqrt{κ}$).

    Parameters
    ----------
    kappa : array_like, shape (m,)
        Kernel concentrations, drawn on a log axis.
    bias, halfwidth : array_like, shape (m,)
        Measured bias (estimate − closed form) and the half-width of its confidence
        interval. The bias axis is symmetric-logarithmic, linear within the
        smallest positive half-width of zero, so signs and orders of magnitude both
        show (:func:`~flatland.plotting.style.symlog_axis`: the linear part gets a
        quarter of the axis, so the labels around zero do not pile up).
    std : array_like, shape (m,)
        Measured standard deviation of one sample's derivative ($\mathrm{stderr} · \sqrt{n}$).
    predicted_bias, predicted_std : (kappa_grid, values), optional
        Predicted curves, drawn as dashed lines.
    level : float
        Coverage of the intervals ``bias ± halfwidth``, stated in the legend.
    title : str, optional
        Figure title.

    Returns
    -------
    Figure
    """
    kappa = np.asarray(kappa, dtype=np.float64).ravel()
    m = kappa.size
    bias = same_length("bias", bias, m)
    halfwidth = same_length("halfwidth", halfwidth, m)
    std = same_length("std", std, m)
    fig = Figure(figsize=(FIGSIZE[0] * 1.8, FIGSIZE[1]), layout="constrained")
    left, right = fig.subplots(1, 2)
    colour = METHOD_COLOURS["reparam"]  # κ is the concentration of the reparameterization's kernel
    draw_estimate(left, kappa, bias, halfwidth=halfwidth, level=level, kind="bars", color=colour,
                  label="measured bias")  # fmt: skip
    if predicted_bias is not None:
        left.plot(*predicted_bias, label="predicted bias", **REFERENCE_STYLE)
    left.axhline(0.0, color="gray", linewidth=0.8)
    positive = halfwidth[halfwidth > 0]
    left.set_xscale("log")
    symlog_axis(left, np.concatenate([bias - halfwidth, bias + halfwidth]),
                float(positive.min()) if positive.size else 1e-3)  # fmt: skip
    left.set_xlabel("κ")
    left.set_ylabel("bias of dI/dθ")
    left.legend(loc="best", fontsize=8)
    right.plot(kappa, std, "o", color=colour, label="measured")
    if predicted_std is not None:
        right.plot(*predicted_std, label="predicted", **REFERENCE_STYLE)
    right.set_xscale("log")
    right.set_yscale("log")
    right.set_xlabel("κ")
    right.set_ylabel("std of one sample's dI/dθ")
    right.legend(loc="best", fontsize=8)
    if title:
        fig.suptitle(title)
    return fig


def plot_histogram_vs_normal(
    estimates: Any,
    mean: float,
    stderr: float,
    *,
    bins: int = 41,
    width: float = 4.0,
    level: float = 0.99,
    label: str = "estimates",
    ax: Axes | None = None,
    title: str | None = None,
    xlabel: str = "estimate",
) -> Figure:
    r"""Draw repeated independent estimates as a histogram over the normal density predicted for them.

    By the central limit theorem a mean of N i.i.d. terms of variance $σ^2$ is nearly
    $N(\mathrm{mean}, \mathrm{stderr}^2)$ with $\mathrm{stderr} = σ/\sqrt{N}$ (theory/monte_carlo):
    the bars should follow the curve.

    Parameters
    ----------
    estimates : array_like
        The repeated estimates, one per independent run, all finite.
    mean, stderr : float
        The predicted mean and standard error (closed forms, not fitted to ``estimates``).
    bins : int
        Equal-width bins over ``mean ± width · stderr``. The bars are densities over all
        estimates, so their area is the fraction of estimates inside that range.
    width : float
        Half-width of the histogram range, in standard errors.
    level : float
        The interval ``mean ± z · stderr`` (z the two-sided normal quantile of ``level``),
        which one estimate falls in with probability ``level``, is marked by two dotted
        lines; the legend states its coverage.
    label : str
        Legend entry of the bars; a label naming a method (``"naive dI/dθ"``) gives the
        bars the method's colour.
    ax, title, xlabel
        As in :func:`~flatland.plotting.textbook.plot_integrand`.

    Returns
    -------
    Figure
    """
    values = np.asarray(estimates, dtype=np.float64).ravel()
    if values.size == 0 or not np.all(np.isfinite(values)):
        raise ValidationError("estimates", f"must be non-empty and finite, got {values.size} entries")
    mean, stderr = check_finite("mean", mean), check_positive("stderr", stderr)
    bins, width = check_int("bins", bins), check_positive("width", width)
    if not 0.0 < level < 1.0:
        raise ValidationError("level", f"must lie in (0, 1), got {level!r}")
    low, high = mean - width * stderr, mean + width * stderr
    ax = new_axes(ax, title)
    counts, edges = np.histogram(values, bins=bins, range=(low, high))
    colour = method_colour(label, OTHER_COLOURS[0])  # a method's bars in its colour
    ax.bar(edges[:-1], counts / (values.size * np.diff(edges)), width=np.diff(edges), align="edge",
           alpha=0.5, color=colour, label=f"{label}, {values.size} runs")  # fmt: skip
    x = np.linspace(low, high, 401)
    density = np.exp(-0.5 * ((x - mean) / stderr) ** 2) / (stderr * np.sqrt(2.0 * np.pi))
    ax.plot(x, density, label="normal, predicted mean and stderr", **REFERENCE_STYLE)
    z = normal_quantile(level)
    for text, side in ((f"mean ± {z:.2f} stderr, {coverage_label(level)}", -1.0), (None, 1.0)):
        ax.axvline(mean + side * z * stderr, color="gray", linestyle=":", linewidth=1.0, label=text)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("density")
    legend_above_data(ax)  # upper right, the values below it: it never covers a bar
    return ax.figure
