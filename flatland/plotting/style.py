"""The one style of every figure: a fixed colour per method, colour maps, colour limits, labels.

Every figure module of both packages (study and demo files, textbook and tutorial
figures) takes its colours from here, so a method looks the same wherever it is
drawn: the reparameterization in blue, the boundary term in orange, naive
differentiation in red, finite differences in purple and closed forms and
references in black. Variants of one method (options such as ``kappa=10`` or
``paired``) share the method's colour and differ by marker or line style
(:func:`series_styles`).
Series that name no method take colours from :data:`OTHER_COLOURS`, none of which a
method uses: it is the colour cycle of every Axes the figure modules make
(:func:`neutral_cycle`). Scene sketches draw with :data:`SKETCH_COLOURS`: emitters in
gold, the camera in cyan and the part a parameter moves in green.

This module imports matplotlib but not pyplot and selects no backend: a notebook's
inline backend stays as it is.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import Normalize
from matplotlib.figure import Figure

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
    "SKETCH_COLOURS",
    "coverage_label",
    "method_colour",
    "method_of",
    "neutral_cycle",
    "new_axes",
    "radiance_norm",
    "same_length",
    "series_styles",
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


def series_styles(
    labels: Iterable[str], vary: str = "marker", others: bool = True
) -> dict[str, dict[str, Any]]:
    """Colour, and the property that tells a method's variants apart, of each series label of a figure.

    A label naming a method gets the method's colour; the k-th distinct label of one
    method (its variants: other options) gets the k-th entry of :data:`MARKERS` or
    :data:`LINESTYLES`, after ``vary``. Labels naming no method take
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
        styles[label] = {"color": METHOD_COLOURS[method], vary: cycle[k % len(cycle)]}
    return styles


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
