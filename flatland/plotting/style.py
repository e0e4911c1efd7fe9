"""The one style of every figure: a fixed colour per method, colour maps, colour limits, labels.

Every figure module of both packages (study and demo files, textbook and tutorial
figures) takes its colours from here, so a method looks the same wherever it is
drawn: the reparameterization in blue, the boundary term in orange, naive
differentiation in red, finite differences in purple and closed forms and
references in black. Variants of one method (options such as ``kappa=10`` or
``paired``) take shades of the method's colour, the first the colour itself, and
differ by marker or line style too (:func:`series_styles`).
Series that name no method take colours from :data:`OTHER_COLOURS`, none of which a
method uses: it is the colour cycle of every Axes the figure modules make
(:func:`neutral_cycle`). Scene sketches draw with :data:`SKETCH_COLOURS`: emitters in
gold, the camera in cyan and the part a parameter moves in green.

This module imports matplotlib but not pyplot and selects no backend: a notebook's
inline backend stays as it is.
"""

from __future__ import annotations

import math
import re
import textwrap
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import Normalize, to_rgb
from matplotlib.figure import Figure
from matplotlib.legend import Legend
from matplotlib.ticker import FixedLocator, LogLocator, MaxNLocator, NullFormatter, NullLocator

from flatland.core.validate import ValidationError

__all__ = [
    "DIVERGING",
    "FIGSIZE",
    "LINESTYLES",
    "MARKERS",
    "METHOD_COLOURS",
    "OTHER_COLOURS",
    "PRIMAL",
    "REFERENCE_STYLE",
    "SHADES",
    "SKETCH_COLOURS",
    "category_ticks",
    "coverage_label",
    "integer_ticks",
    "legend_above_data",
    "legend_outside",
    "log_ticks",
    "method_colour",
    "method_of",
    "neutral_cycle",
    "new_axes",
    "radiance_norm",
    "same_length",
    "series_styles",
    "shade",
    "symlog_axis",
    "symmetric_limit",
    "symmetric_norm",
]

METHOD_COLOURS = {
    "naive": "#d62728",
    "finite_difference": "#9467bd",
    "boundary": "#ff7f0e",
    "reparam": "#1f77b4",
    "reference": "#000000",
}
"""The colour of each gradient method (and of closed forms and references), in every figure."""
OTHER_COLOURS = ("#2ca02c", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f")
"""Colours of series that name no method, in order; no method uses one of them."""
SKETCH_COLOURS = {
    "shape": "#404040",
    "fill": "#e6e6e6",
    "emitter": "#d4a017",
    "camera": "#17becf",
    "moving": "#2ca02c",
}
"""Colours of the scene sketches (:mod:`flatland.plotting.sketch`): shapes, their fill, emitters,
the camera with its frustum and film, and the part the parameter moves; no method uses one of them."""
MARKERS = ("o", "s", "^", "D", "v", "P")
"""Markers of the variants of one method in one figure, in order."""
LINESTYLES = ("-", "--", "-.", ":")
"""Line styles of the variants of one method in one figure, in order."""
DIVERGING = "RdBu_r"
"""Colormap of derivatives: blue negative, white zero, red positive."""
PRIMAL = "gray"
"""Colormap of radiance."""
FIGSIZE = (6.4, 3.6)
"""Default size of a one-panel figure, in inches."""
REFERENCE_STYLE = {"color": METHOD_COLOURS["reference"], "linestyle": "--", "linewidth": 1.0}
"""How closed forms and references are drawn."""
SHADES = (0.0, 0.45, -0.5, 0.7, -0.7, 0.25, -0.25, 0.85)
"""Shade of the k-th variant of one method (:func:`shade`): 0 the method's colour, > 0 toward black,
< 0 toward white; alternating, so neighbouring variants differ most."""

# a label names a method if it starts with one of these words (then a space, "_", "(" or the end)
_NAMES = re.compile(
    r"^\s*(naive|boundary|reparam|finite[ _]differences?|fd|reference|closed[ _]form)(?=$|[\s_(,:=])",
    re.IGNORECASE,
)
_ALIASES = {"fd": "finite_difference", "closed form": "reference", "closed_form": "reference"}


def method_of(label: str) -> str | None:
    """The method a series label names (``"reparam kappa=10"`` -> ``"reparam"``), or None.

    ``"finite differences"``, ``"finite difference"`` and ``"fd"`` name
    ``finite_difference``; ``"closed form ..."`` and ``"reference ..."`` the reference.
    """
    match = _NAMES.match(str(label))
    if match is None:
        return None
    word = match.group(1).lower()
    if word.startswith("finite"):
        return "finite_difference"
    return _ALIASES.get(word, word)


def method_colour(label: str, default: Any = None) -> Any:
    """The fixed colour of the method ``label`` names (see :func:`method_of`); ``default`` if none."""
    method = method_of(label)
    return default if method is None else METHOD_COLOURS[method]


def shade(colour: Any, amount: float) -> tuple[float, float, float]:
    """``colour`` mixed with black (``amount`` > 0) or white (``amount`` < 0) by ``|amount|`` in [0, 1]."""
    rgb = np.array(to_rgb(colour))
    target = np.zeros(3) if amount > 0 else np.ones(3)
    return tuple(float(c) for c in rgb + abs(amount) * (target - rgb))


def series_styles(
    labels: Iterable[str], vary: str = "marker", others: bool = True
) -> dict[str, dict[str, Any]]:
    """Colour, and the property that tells a method's variants apart, of each series label of a figure.

    A label naming a method gets the method's colour; the k-th distinct label of one
    method (its variants: other options) gets the k-th shade of that colour
    (:data:`SHADES`: the first is the colour itself) and the k-th entry of
    :data:`MARKERS` or :data:`LINESTYLES`, after ``vary``, so variants differ by
    colour and by marker or line style. Labels naming no method take
    :data:`OTHER_COLOURS` in order (cycling) when ``others`` is true, and no style
    at all otherwise (they then take the colour cycle of their Axes).
    """
    if vary not in ("marker", "linestyle"):
        raise ValidationError("vary", f"must be 'marker' or 'linestyle', got {vary!r}")
    cycle = MARKERS if vary == "marker" else LINESTYLES
    styles: dict[str, dict[str, Any]] = {}
    variants: dict[str, int] = {}
    count = 0
    for label in labels:
        if label in styles:
            continue
        method = method_of(label)
        if method is None:
            styles[label] = (
                {"color": OTHER_COLOURS[count % len(OTHER_COLOURS)], vary: cycle[0]} if others else {}
            )
            count += others
            continue
        k = variants.get(method, 0)
        variants[method] = k + 1
        colour = METHOD_COLOURS[method] if k == 0 else shade(METHOD_COLOURS[method], SHADES[k % len(SHADES)])
        styles[label] = {"color": colour, vary: cycle[k % len(cycle)]}
    return styles


def legend_outside(ax: Axes, where: str = "right", **options: Any) -> Legend:
    """The legend of ``ax`` outside its frame, so it never covers data: to the ``"right"`` of the Axes
    (top aligned) or ``"below"`` it (under the x label, several columns)."""
    if where == "right":
        placement = {"loc": "upper left", "bbox_to_anchor": (1.02, 1.0), "borderaxespad": 0.0}
    elif where == "below":
        placement = {"loc": "upper center", "bbox_to_anchor": (0.5, -0.18), "borderaxespad": 0.0}
    else:
        raise ValidationError("where", f"must be 'right' or 'below', got {where!r}")
    return ax.legend(**{"fontsize": 8, **placement, **options})


def legend_above_data(ax: Axes, **options: Any) -> Legend:
    """The legend of ``ax`` in its upper right corner, the y range raised so that every artist's data
    (its autoscaled limits) lies below the legend's lower edge: it never covers a marker, whatever the
    values. Linear y axes only (the raise is a fraction of the range)."""
    legend = ax.legend(**{"fontsize": 8, "loc": "upper right", **options})
    bottom = legend.get_window_extent().transformed(ax.transAxes.inverted()).y0  # the figure's renderer
    lo, hi = ax.get_ylim()
    room = bottom - 0.03  # the data's share of the height, a small gap under the legend
    if 0.2 < room < 1.0:
        ax.set_ylim(lo, lo + (hi - lo) / room)
    return legend


def category_ticks(ax: Axes, positions: Sequence[float], labels: Sequence[str]) -> None:
    """Name the x positions of ``ax`` with ``labels`` (methods, integrals), horizontally and wrapped at
    spaces to the width one label has (the Axes' share of its figure's width over the number of
    labels), so that neighbouring labels never run into each other."""
    share = ax.get_position().width * ax.figure.get_figwidth() / max(len(labels), 1)
    width = max(6, int(12 * share))  # about 12 characters of 8 pt text per inch
    wrapped = [textwrap.fill(str(t), width, break_long_words=False) for t in labels]
    ax.set_xticks(list(positions), wrapped, fontsize=8)


def integer_ticks(axis: Any) -> None:
    """Ticks of ``axis`` (``ax.xaxis``) at whole numbers only: counts, iterations."""
    axis.set_major_locator(MaxNLocator(integer=True))


def log_ticks(axis: Any) -> None:
    """Readable ticks on a logarithmic ``axis``: at 1, 2 and 5 times the powers of ten, at most about
    six, written as plain numbers, with unlabelled minor ticks (a short axis otherwise labels every
    minor tick, and the labels run into each other)."""
    axis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0), numticks=6))
    axis.set_major_formatter("{x:g}")
    axis.set_minor_locator(LogLocator(base=10.0, subs=np.arange(2, 10), numticks=12))
    axis.set_minor_formatter(NullFormatter())


def symlog_axis(ax: Axes, values: Any, linthresh: float, numticks: int = 6) -> None:
    """A symmetric-logarithmic y axis for signed ``values``: linear within ``linthresh`` of zero.

    The linear part gets a quarter of the axis (matplotlib's default gives it the height of
    one decade), and the ticks are 0 and the powers of ten at or beyond ``linthresh`` on each
    side, at most ``numticks`` in all, without minor ticks: matplotlib's own locator also ticks
    the decades inside the linear part, where ``-10^0``, ``0`` and ``10^0`` pile up.
    """
    values = np.abs(np.asarray(values, dtype=np.float64))
    top = max(float(values[np.isfinite(values)].max(initial=linthresh)), linthresh)
    decades = max(math.log10(top / linthresh), 1.0)
    ax.set_yscale("symlog", linthresh=linthresh, linscale=decades / 3.0)
    powers = np.arange(math.ceil(math.log10(linthresh) - 1e-9), math.floor(math.log10(top) + 1e-9) + 1)
    stride = max(1, math.ceil(len(powers) / max(1, (numticks - 1) // 2)))
    ticks = 10.0 ** powers[::-1][::stride][::-1]
    ax.yaxis.set_major_locator(FixedLocator([*(-ticks[::-1]), 0.0, *ticks]))
    ax.yaxis.set_minor_locator(NullLocator())


def coverage_label(level: float) -> str:
    """A band's coverage as legend text: 0.99 -> ``"99 % interval"``, 0.9545 -> ``"95.45 % interval"``."""
    digits = 4
    text = f"{100.0 * level:.{digits}g}"
    while text == "100" and level < 1.0 and digits < 17:  # 0.99999 must not read 100 %
        digits += 1
        text = f"{100.0 * level:.{digits}g}"
    return f"{text} % interval"


def symmetric_limit(arrays: Sequence[Any], percentile: float = 99.5) -> float:
    """One colour limit for all ``arrays``: the largest ``percentile`` of their finite |a|.

    A percentile below 100 keeps a few noisy pixels (finite differences) from washing
    out every other image; 100 gives the largest finite |a|. When the percentile is 0
    (a derivative that is non-zero on a few pixels only) the largest |a| is used, and
    1.0 when everything is zero or not finite.
    """
    finite = [np.abs(a[np.isfinite(a)]) for a in (np.asarray(a, dtype=np.float64) for a in arrays)]
    finite = [a for a in finite if a.size]
    limit = max((float(np.percentile(a, percentile)) for a in finite), default=0.0)
    if limit == 0.0:
        limit = max((float(a.max()) for a in finite), default=0.0)
    return limit if limit > 0.0 else 1.0


def symmetric_norm(limit: float) -> Normalize:
    """The diverging colour scale ``[-limit, limit]``, centred on zero."""
    return Normalize(-limit, limit)


def radiance_norm(values: Any) -> Normalize:
    """The grey scale of an image: from 0 to its largest finite value (1 if there is none above 0)."""
    values = np.asarray(values, dtype=np.float64)
    top = float(np.max(values[np.isfinite(values)])) if np.isfinite(values).any() else 0.0
    return Normalize(0.0, top if top > 0.0 else 1.0)


def neutral_cycle(ax: Axes) -> Axes:
    """Give ``ax`` the colour cycle :data:`OTHER_COLOURS`: a series drawn without a colour then never
    takes a method's."""
    ax.set_prop_cycle(color=list(OTHER_COLOURS))
    return ax


def new_axes(ax: Axes | None, title: str | None, figsize: tuple[float, float] = FIGSIZE) -> Axes:
    """``ax``, or the single Axes of a new figure (made without pyplot, colour cycle
    :data:`OTHER_COLOURS`); sets the title if given."""
    if ax is None:
        ax = neutral_cycle(Figure(figsize=figsize, layout="constrained").add_subplot())
    if title:
        ax.set_title(title)
    return ax


def same_length(name: str, array: Any, length: int) -> np.ndarray:
    """``array`` as a 1D float array of ``length`` entries; a ValidationError naming ``name`` otherwise."""
    a = np.asarray(array, dtype=np.float64).ravel()
    if a.size != length:
        raise ValidationError(name, f"has {a.size} entries, expected {length}")
    return a
