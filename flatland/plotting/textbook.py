"""Figures for the textbook integrals and the tutorials: matplotlib only, no numerics.

Every function takes data that was computed elsewhere (arrays, :class:`Estimate`
objects, :class:`~flatland.integrals.Discontinuity` lists), draws it and returns
the :class:`~matplotlib.figure.Figure`. Pass ``ax=`` to draw into an existing
Axes (several curves on one plot); the Axes' figure is returned then.

Figures are created as :class:`matplotlib.figure.Figure` objects, not through
pyplot: nothing is registered in a global figure list, so a notebook displays
exactly the figures its cells return, and a script that makes hundreds of them
leaks nothing. ``fig.savefig(path)`` writes one to a file.

===========================  ==============================================
:func:`plot_integrand`       f(x, θ) on a grid, discontinuities marked
:func:`plot_curves`          named series y(x), optionally on log axes
:func:`plot_histogram`       samples against the density they claim
:func:`plot_terms`           the Leibniz terms of dI/dθ, stacked per case
:func:`plot_estimates`       estimates ± confidence interval vs closed form
:func:`plot_variance`        measured variance vs sample count, log-log
:func:`plot_kappa_tradeoff`  bias ± interval and standard deviation vs κ
===========================  ==============================================
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from flatland.core.contract import Estimate
from flatland.core.dual import detach, tangent
from flatland.core.stats import normal_quantile
from flatland.core.validate import ValidationError
from flatland.integrals import Discontinuity

__all__ = [
    "plot_curves",
    "plot_estimates",
    "plot_histogram",
    "plot_integrand",
    "plot_kappa_tradeoff",
    "plot_terms",
    "plot_variance",
]

FIGSIZE = (6.4, 3.6)
"""Default size of a one-panel figure, in inches."""
REFERENCE_STYLE = {"color": "black", "linestyle": "--", "linewidth": 1.0}
"""How closed forms and references are drawn."""


def _axes(ax: Axes | None, title: str | None, figsize: tuple[float, float] = FIGSIZE) -> Axes:
    """``ax``, or the single Axes of a new figure; sets the title if given."""
    if ax is None:
        ax = Figure(figsize=figsize, layout="constrained").add_subplot()
    if title:
        ax.set_title(title)
    return ax


def _same_length(name: str, array: Any, length: int) -> np.ndarray:
    """``array`` as a 1D float array of ``length`` entries; ValueError naming ``name`` otherwise."""
    a = np.asarray(array, dtype=np.float64).ravel()
    if a.size != length:
        raise ValidationError(name, f"has {a.size} entries, expected {length}")
    return a


def _percent(level: float) -> str:
    """A confidence level as a percentage with the digits it needs: 0.99 -> "99%", 0.999 -> "99.9%"."""
    return f"{100.0 * level:.10g}%"


def _mark(value: Any) -> tuple[float, float | None, float | None]:
    """(location, jump, velocity) of a :class:`Discontinuity` or a bare location."""
    if isinstance(value, Discontinuity):
        return float(detach(value.location)), float(value.jump), float(tangent(value.location))
    return float(value), None, None


def plot_integrand(
    x: Any,
    values: Any,
    discontinuities: Sequence[Discontinuity | float] = (),
    *,
    label: str | None = None,
    annotate: bool = True,
    ax: Axes | None = None,
    title: str | None = None,
    xlabel: str = "x",
    ylabel: str = "f(x, θ)",
    color: Any = None,
) -> Figure:
    """Draw an integrand sampled on a grid, with its discontinuities as dashed vertical lines.

    Parameters
    ----------
    x, values : array_like, shape (m,)
        The grid and f(x, θ) on it (plain numbers: ``detach`` a Dual first).
    discontinuities : sequence of Discontinuity or float
        Where f jumps. A :class:`~flatland.integrals.Discontinuity` is labelled with
        its jump f(c⁻) − f(c⁺) and velocity c'(θ) when ``annotate`` is true.
    label : str, optional
        Legend entry of the curve.
    annotate : bool
        Write jump and velocity next to each marked discontinuity.
    ax : Axes, optional
        Draw into this Axes (to overlay several integrands) instead of a new figure.
    title, xlabel, ylabel : str
        Axis annotations.
    color : optional
        Matplotlib colour of the curve and its marks.

    Returns
    -------
    Figure
    """
    x = np.asarray(x, dtype=np.float64).ravel()
    values = _same_length("values", values, x.size)
    ax = _axes(ax, title)
    (line,) = ax.plot(x, values, label=label, color=color, linewidth=1.5)
    for d in discontinuities:
        c, jump, velocity = _mark(d)
        ax.axvline(c, color=line.get_color(), linestyle=":", linewidth=1.0)
        if annotate and jump is not None:
            ax.annotate(
                f"jump {jump:+.3g}\nc' = {velocity:.3g}",
                xy=(c, 1.0),
                xycoords=("data", "axes fraction"),
                xytext=(3, -3),
                textcoords="offset points",
                va="top",
                fontsize=8,
                color=line.get_color(),
            )
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if label:
        ax.legend(loc="best", fontsize=8)
    return ax.figure


def plot_curves(
    x: Any,
    curves: Mapping[str, Any],
    *,
    logx: bool = False,
    logy: bool = False,
    styles: Mapping[str, Mapping[str, Any]] | None = None,
    marks: Sequence[float] = (),
    ax: Axes | None = None,
    title: str | None = None,
    xlabel: str = "",
    ylabel: str = "",
) -> Figure:
    """Draw named series over one shared x, optionally on logarithmic axes.

    Parameters
    ----------
    x : array_like, shape (m,)
        Abscissae shared by all curves.
    curves : mapping of str to array_like, shape (m,)
        Series by legend label.
    logx, logy : bool
        Logarithmic axes.
    styles : mapping of str to dict, optional
        Extra matplotlib keywords per label (``{"closed form": {"linestyle": "--"}}``).
    marks : sequence of float
        x positions to mark with thin vertical lines.
    ax, title, xlabel, ylabel
        As in :func:`plot_integrand`.

    Returns
    -------
    Figure
    """
    x = np.asarray(x, dtype=np.float64).ravel()
    styles = styles or {}
    ax = _axes(ax, title)
    for label, y in curves.items():
        ax.plot(x, _same_length(f"curves[{label!r}]", y, x.size), label=label, **dict(styles.get(label, {})))
    for m in marks:
        ax.axvline(float(m), color="gray", linestyle=":", linewidth=1.0)
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if curves:
        ax.legend(loc="best", fontsize=8)
    return ax.figure


def plot_histogram(
    samples: Any,
    x: Any,
    density: Any,
    *,
    bins: int = 61,
    range: tuple[float, float] | None = None,
    label: str = "samples",
    density_label: str = "density",
    ax: Axes | None = None,
    title: str | None = None,
    xlabel: str = "x",
) -> Figure:
    """Draw a normalized histogram of ``samples`` over the ``density`` they should follow.

    Parameters
    ----------
    samples : array_like
        Draws of a sampler.
    x, density : array_like, shape (m,)
        The claimed density on a grid.
    bins : int
        Histogram bins.
    range : (float, float), optional
        Histogram range; samples outside it are not drawn (the histogram is then
        normalized over the range, so compare only where the density's mass lies).
    label, density_label : str
        Legend entries.
    ax, title, xlabel
        As in :func:`plot_integrand`.

    Returns
    -------
    Figure
    """
    x = np.asarray(x, dtype=np.float64).ravel()
    density = _same_length("density", density, x.size)
    ax = _axes(ax, title)
    ax.hist(np.asarray(samples, dtype=np.float64).ravel(), bins=bins, range=range, density=True,
            alpha=0.4, label=label)  # fmt: skip
    ax.plot(x, density, color="black", linewidth=1.2, label=density_label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("density")
    ax.legend(loc="best", fontsize=8)
    return ax.figure


def plot_terms(
    cases: Sequence[str],
    terms: Mapping[str, Any],
    *,
    totals: Any = None,
    total_label: str = "closed-form dI/dθ",
    ax: Axes | None = None,
    title: str | None = None,
    ylabel: str = "contribution to dI/dθ",
) -> Figure:
    """Draw additive terms per case as stacked bars, with the total they should reach as a marker.

    Used for the Leibniz rule: per integrand, the interior term and the discontinuity
    term, against the closed-form derivative they must add up to. Positive terms stack
    upwards from zero and negative ones downwards, so a bar's extent is the sum when
    all terms share a sign.

    Parameters
    ----------
    cases : sequence of str
        One group of bars per case (e.g. integrand names).
    terms : mapping of str to array_like, shape (len(cases),)
        Term values by legend label.
    totals : array_like, shape (len(cases),), optional
        The sum the terms should give, drawn as a black diamond per case.
    total_label : str
        Legend entry of ``totals``.
    ax, title, ylabel
        As in :func:`plot_integrand`.

    Returns
    -------
    Figure
    """
    cases = list(cases)
    m = len(cases)
    ax = _axes(ax, title)
    positions = np.arange(m, dtype=np.float64)
    up, down = np.zeros(m), np.zeros(m)  # stack tops above and below zero
    for label, values in terms.items():
        values = _same_length(f"terms[{label!r}]", values, m)
        base = np.where(values >= 0.0, up, down)
        ax.bar(positions, values, width=0.6, bottom=base, label=label)
        up, down = np.where(values >= 0.0, up + values, up), np.where(values < 0.0, down + values, down)
    if totals is not None:
        ax.plot(positions, _same_length("totals", totals, m), "D", color="black", label=total_label)
    ax.axhline(0.0, color="gray", linewidth=0.8)
    ax.set_xticks(positions, cases, rotation=20, ha="right")
    ax.set_ylabel(ylabel)
    ax.legend(loc="best", fontsize=8)
    return ax.figure


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
        quantile (:func:`~flatland.core.stats.normal_quantile`; 2.58 at 0.99).
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
    z = normal_quantile(level)
    labels = list(estimates)
    pairs = [_mean_stderr(f"estimates[{k!r}]", estimates[k], of) for k in labels]
    ax = _axes(ax, title)
    positions = np.arange(len(labels), dtype=np.float64)
    means = np.array([p[0] for p in pairs])
    half = z * np.array([p[1] for p in pairs])
    ax.errorbar(
        positions, means, yerr=half, fmt="o", capsize=4, label=f"estimate ± {_percent(level)} interval"
    )
    if reference is not None:
        ax.axhline(float(reference), label=reference_label, **REFERENCE_STYLE)
    ax.set_xticks(positions, labels, rotation=20, ha="right")
    ax.set_xlim(-0.5, len(labels) - 0.5)
    ax.set_ylabel(ylabel or ("dI/dθ" if of == "derivative" else "I"))
    ax.legend(loc="best", fontsize=8)
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
    ax = _axes(ax, title)
    for label, v in variances.items():
        (line,) = ax.plot(n, _same_length(f"variances[{label!r}]", v, n.size), "o", label=label)
        if label in predicted:
            ax.plot(n, _same_length(f"predicted[{label!r}]", predicted[label], n.size), "--",
                    color=line.get_color(), linewidth=1.0, label=f"{label}: predicted")  # fmt: skip
    for label, v in predicted.items():
        if label not in variances:
            ax.plot(n, _same_length(f"predicted[{label!r}]", v, n.size), "--", linewidth=1.0, label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend(loc="best", fontsize=8)
    return ax.figure


def plot_kappa_tradeoff(
    kappa: Any,
    bias: Any,
    halfwidth: Any,
    std: Any,
    *,
    predicted_bias: tuple[Any, Any] | None = None,
    predicted_std: tuple[Any, Any] | None = None,
    level: float | None = None,
    title: str | None = None,
) -> Figure:
    """Two panels over the kernel concentration κ: bias ± interval, and standard deviation.

    The convolution kernel's trade-off (Loubet et al. 2019, Sec. 4.2; DESIGN 2.7):
    small κ (a wide kernel) reaches discontinuities one transform cannot follow, so
    the bias is large; large κ makes the derivative of log k large, so the standard
    deviation grows (like √κ).

    Parameters
    ----------
    kappa : array_like, shape (m,)
        Kernel concentrations, drawn on a log axis.
    bias, halfwidth : array_like, shape (m,)
        Measured bias (estimate − closed form) and the half-width of its confidence
        interval. The bias axis is symmetric-logarithmic, linear within the
        smallest positive half-width of zero, so signs and orders of magnitude both
        show.
    std : array_like, shape (m,)
        Measured standard deviation of one sample's derivative (stderr · √n).
    predicted_bias, predicted_std : (kappa_grid, values), optional
        Predicted curves, drawn as dashed lines.
    level : float, optional
        Confidence level of the intervals, for the legend.
    title : str, optional
        Figure title.

    Returns
    -------
    Figure
    """
    kappa = np.asarray(kappa, dtype=np.float64).ravel()
    m = kappa.size
    bias = _same_length("bias", bias, m)
    halfwidth = _same_length("halfwidth", halfwidth, m)
    std = _same_length("std", std, m)
    fig = Figure(figsize=(FIGSIZE[0] * 1.8, FIGSIZE[1]), layout="constrained")
    left, right = fig.subplots(1, 2)
    interval = f"{_percent(level)} interval" if level is not None else "interval"
    left.errorbar(kappa, bias, yerr=halfwidth, fmt="o", capsize=4, label=f"measured bias ± {interval}")
    if predicted_bias is not None:
        left.plot(*predicted_bias, label="predicted bias", **REFERENCE_STYLE)
    left.axhline(0.0, color="gray", linewidth=0.8)
    positive = halfwidth[halfwidth > 0]
    left.set_xscale("log")
    left.set_yscale("symlog", linthresh=float(positive.min()) if positive.size else 1e-3)
    left.set_xlabel("κ")
    left.set_ylabel("bias of dI/dθ")
    left.legend(loc="best", fontsize=8)
    right.plot(kappa, std, "o", label="measured")
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
