"""Figures of the textbook integrals: integrands, curves, histograms and Leibniz terms.

Every function takes data that was computed elsewhere (arrays,
:class:`~flatland.integrals.Discontinuity` lists), draws it and returns the
:class:`~matplotlib.figure.Figure`. Pass ``ax=`` to draw into an existing Axes
(several curves on one plot); the Axes' figure is returned then.

Figures are created as :class:`matplotlib.figure.Figure` objects, not through
pyplot: nothing is registered in a global figure list, so a notebook displays
exactly the figures its cells return, and a script that makes hundreds of them
leaks nothing. ``fig.savefig(path)`` writes one to a file. Colours come from
:mod:`flatland.plotting.style`: a series whose label names a method has that
method's colour.

==================================  ================================================
:func:`plot_integrand`              f(x, θ) on a grid, discontinuities marked
:func:`plot_curves`                 named series y(x), optionally on log axes
:func:`plot_histogram`              samples against the density they claim
:func:`plot_terms`                  the Leibniz terms of dI/dθ, stacked per case
:func:`plot_estimates`              estimates ± confidence interval vs closed form
:func:`plot_variance`               measured variance vs sample count, log-log
:func:`plot_kappa_tradeoff`         bias ± interval and standard deviation vs κ
:func:`plot_histogram_vs_normal`    repeated estimates vs their predicted normal law
==================================  ================================================

The last four live in :mod:`flatland.plotting.textbook_estimates` and are
importable from here, so ``from flatland.plotting import textbook as pt`` gives
all eight.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from flatland.core.dual import detach, tangent
from flatland.integrals import Discontinuity
from flatland.plotting.style import (
    FIGSIZE,
    REFERENCE_STYLE,
    category_ticks,
    method_colour,
    new_axes,
    same_length,
    series_styles,
)
from flatland.plotting.textbook_estimates import (
    plot_estimates,
    plot_histogram_vs_normal,
    plot_kappa_tradeoff,
    plot_variance,
)

__all__ = [
    "FIGSIZE",
    "REFERENCE_STYLE",
    "plot_curves",
    "plot_estimates",
    "plot_histogram",
    "plot_histogram_vs_normal",
    "plot_integrand",
    "plot_kappa_tradeoff",
    "plot_terms",
    "plot_variance",
]


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
        The grid and $f(x, θ)$ on it (plain numbers: ``detach`` a Dual first).
    discontinuities : sequence of Discontinuity or float
        Where f jumps. A :class:`~flatland.integrals.Discontinuity` is labelled with
        its jump $f(c^-) − f(c^+)$ and velocity $c'(θ)$ when ``annotate`` is true.
    label : str, optional
        Legend entry of the curve.
    annotate : bool
        Write jump and velocity next to each marked discontinuity.
    ax : Axes, optional
        Draw into this Axes (to overlay several integrands) instead of a new figure.
    title, xlabel, ylabel : str
        Axis annotations.
    color : optional
        Matplotlib colour of the curve and its marks; by default the method's colour
        if ``label`` names one (:func:`~flatland.plotting.style.method_colour`).

    Returns
    -------
    Figure
    """
    x = np.asarray(x, dtype=np.float64).ravel()
    values = same_length("values", values, x.size)
    ax = new_axes(ax, title)
    color = method_colour(label) if color is None and label else color
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
        Extra matplotlib keywords per label (``{"closed form": {"linestyle": "--"}}``). A
        label that names a method (``"reparam κ = 10"``) is drawn in the method's colour
        unless its style sets one; a method's variants differ by line style.
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
    ax = new_axes(ax, title)
    variants = series_styles(curves, vary="linestyle", others=False)  # a method's colour, variants dashed
    for label, y in curves.items():
        style = {**variants[label], **dict(styles.get(label, {}))}
        ax.plot(x, same_length(f"curves[{label!r}]", y, x.size), label=label, **style)
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
    density = same_length("density", density, x.size)
    ax = new_axes(ax, title)
    ax.hist(np.asarray(samples, dtype=np.float64).ravel(), bins=bins, range=range, density=True,
            alpha=0.4, label=label)  # fmt: skip
    ax.plot(x, density, color=REFERENCE_STYLE["color"], linewidth=1.2, label=density_label)
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
    ax = new_axes(ax, title)
    positions = np.arange(m, dtype=np.float64)
    up, down = np.zeros(m), np.zeros(m)  # stack tops above and below zero
    for label, values in terms.items():
        values = same_length(f"terms[{label!r}]", values, m)
        base = np.where(values >= 0.0, up, down)
        ax.bar(positions, values, width=0.6, bottom=base, label=label, color=method_colour(label))
        up, down = np.where(values >= 0.0, up + values, up), np.where(values < 0.0, down + values, down)
    if totals is not None:
        ax.plot(positions, same_length("totals", totals, m), "D", color=REFERENCE_STYLE["color"],
                label=total_label)  # fmt: skip
    ax.axhline(0.0, color="gray", linewidth=0.8)
    category_ticks(ax, positions, cases)
    ax.set_ylabel(ylabel)
    ax.legend(loc="best", fontsize=8)
    return ax.figure
