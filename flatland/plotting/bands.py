"""The one way an estimate with its uncertainty is drawn: a curve with a shaded band, or error bars.

Every figure that shows Monte Carlo estimates with their confidence interval (the
demo panel's curves, the study's bias against κ, the textbook estimates and κ
trade-off, the tutorials' films) draws them with :func:`draw_estimate`, so a band
always says its coverage in the legend ("reparam ± 99 % interval") and a method
always has its colour (:func:`~flatland.plotting.style.method_colour`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.axes import Axes

from flatland.core.stats import normal_quantile
from flatland.core.validate import ValidationError
from flatland.plotting.style import coverage_label, method_colour

__all__ = ["band_label", "draw_estimate"]


def band_label(label: str | None, level: float) -> str:
    """Legend text of an estimate with a band: ``"reparam ± 99 % interval"``."""
    return f"{label or 'estimate'} ± {coverage_label(level)}"


def draw_estimate(
    ax: Axes,
    x: Any,
    values: Any,
    *,
    stderr: Any = None,
    halfwidth: Any = None,
    bounds: tuple[Any, Any] | None = None,
    level: float | None = None,
    label: str | None = None,
    color: Any = None,
    kind: str = "band",
    where: Any = None,
    band_alpha: float = 0.2,
    **style: Any,
) -> Any:
    """Draw an estimate and, if a spread is given, its confidence interval at coverage ``level``.

    Parameters
    ----------
    ax : Axes
        Where to draw.
    x, values : array_like
        Abscissae and estimates.
    stderr, halfwidth, bounds : array_like, optional
        At most one: the interval is ``values ± z · stderr`` with z the two-sided normal
        quantile of ``level`` (:func:`~flatland.core.stats.normal_quantile`, 2.58 at
        0.99), ``values ± halfwidth``, or ``bounds = (low, high)``. None of them: no
        interval, the legend shows ``label`` alone.
    level : float
        Coverage of the interval (required with one); the legend says it:
        ``"<label> ± 99 % interval"``.
    label : str, optional
        Series name; a method name (``"reparam kappa=10"``) also picks the colour. A
        label starting with "_" keeps the series out of the legend.
    color : optional
        Overrides the method's colour (:func:`~flatland.plotting.style.method_colour`;
        matplotlib's next colour for labels that name no method).
    kind : {"band", "bars"}
        A curve with a shaded band, or markers with error bars.
    where : array_like of bool, optional
        ``kind="band"``: shade only there (e.g. where the standard error is finite).
    band_alpha : float
        Opacity of the shaded band.
    **style
        Further matplotlib keywords of the curve or the error bars.

    Returns
    -------
    Line2D or ErrorbarContainer
        The artist that carries the legend entry.
    """
    if kind not in ("band", "bars"):
        raise ValidationError("kind", f"must be 'band' or 'bars', got {kind!r}")
    given = [
        name
        for name, v in (("stderr", stderr), ("halfwidth", halfwidth), ("bounds", bounds))
        if v is not None
    ]
    if len(given) > 1:
        raise ValidationError(given[1], f"give one of stderr, halfwidth and bounds, got {given}")
    if given and level is None:
        raise ValidationError("level", "an interval needs its coverage level")
    x = np.asarray(x, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    color = method_colour(label, color) if color is None and label is not None else color
    low = high = None
    if stderr is not None:
        z = normal_quantile(level)
        low, high = values - z * np.asarray(stderr), values + z * np.asarray(stderr)
    elif halfwidth is not None:
        low, high = values - np.asarray(halfwidth), values + np.asarray(halfwidth)
    elif bounds is not None:
        low, high = (np.asarray(b, dtype=np.float64) for b in bounds)
    hidden = label is not None and label.startswith("_")  # matplotlib's rule: no legend entry
    text = label if low is None or hidden else band_label(label, level)
    if kind == "bars":
        yerr = None if low is None else np.array([values - low, high - values])
        return ax.errorbar(
            x, values, yerr=yerr, color=color, label=text, **{"fmt": "o", "capsize": 4, **style}
        )
    (line,) = ax.plot(x, values, color=color, label=text, **style)
    if low is not None:
        ax.fill_between(x, low, high, where=where, color=line.get_color(), alpha=band_alpha, linewidth=0,
                        interpolate=False)  # fmt: skip
    return line
