"""Layout defects a reader sees in a figure, found from matplotlib's own extents after a draw.

:func:`figure_defects` draws a figure (``canvas.draw()`` on an Agg canvas, so the
constrained layout and every legend's ``loc="best"`` are resolved) and reads the
window extent of each text and legend (``get_window_extent``), in display pixels:

* two tick labels of one axis that overlap (``10^0``, ``0`` and ``-10^0`` on a symlog
  axis too narrow for them);
* a title, an axis label or a tick label that runs into another Axes (a title into
  the colour bar) or into a text of another Axes;
* a legend drawn over data: over a data point or a segment of a curve, a bar, a
  shaded band, an error bar, or an image drawn in data coordinates (horizontal and
  vertical guide lines across the whole Axes, such as the zero line, do not count);
* a legend entry whose series draws nothing (``"boundary (rmse 0 left out)"``).

Extents are shrunk by :data:`SLACK` pixels before they are compared, so texts that
merely touch (a descender on the next line's ascender) do not count, and a legend is
compared with the data of its Axes only where it lies inside the Axes (data is clipped
to its Axes).

:func:`install_notebook_check` checks every figure an IPython kernel displays: a figure
with a defect writes the defects to stderr, which the tutorial test
(tests/test_tutorials.py) rejects as it rejects any output on stderr.
"""

from __future__ import annotations

import itertools
import sys
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import Collection
from matplotlib.container import ErrorbarContainer
from matplotlib.figure import Figure
from matplotlib.image import AxesImage
from matplotlib.legend import Legend
from matplotlib.patches import Rectangle
from matplotlib.path import Path
from matplotlib.text import Text
from matplotlib.transforms import Bbox

SLACK = 1.0
"""Pixels by which every extent is shrunk before two are compared."""


def _shrunk(box: Bbox, by: float = SLACK) -> Bbox:
    return Bbox.from_extents(box.x0 + by, box.y0 + by, box.x1 - by, box.y1 - by)


def _overlap(a: Bbox, b: Bbox) -> bool:
    a, b = _shrunk(a), _shrunk(b)
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def _visible_text(t: Text) -> bool:
    return t.get_visible() and bool(t.get_text().strip()) and t.figure is not None


def _tick_labels(axis: Any, renderer: Any) -> list[tuple[str, Bbox]]:
    """(text, extent) of the tick labels the axis draws (inside its view limits)."""
    low, high = sorted(axis.get_view_interval())
    out = []
    for tick in axis.get_major_ticks() + axis.get_minor_ticks():
        if not low - 1e-9 * abs(high - low) <= tick.get_loc() <= high + 1e-9 * abs(high - low):
            continue
        for label in (tick.label1, tick.label2):
            if _visible_text(label):
                out.append((label.get_text(), label.get_window_extent(renderer)))
    return out


def _axes_texts(ax: Axes, renderer: Any) -> list[tuple[str, Bbox]]:
    """Titles, axis labels and tick labels of ``ax``, with their extents."""
    texts = [ax.title, ax._left_title, ax._right_title, ax.xaxis.label, ax.yaxis.label]
    named = [
        (f"{_name(ax)} {t.get_text()!r}", t.get_window_extent(renderer)) for t in texts if _visible_text(t)
    ]
    for axis in (ax.xaxis, ax.yaxis):
        named += [(f"{_name(ax)} tick {text!r}", box) for text, box in _tick_labels(axis, renderer)]
    return named


def _name(ax: Axes) -> str:
    title = ax.get_title() or ax.get_ylabel() or ax.get_xlabel() or ax.get_label() or "axes"
    return f"[{title[:40]}]"


def tick_overlaps(fig: Figure, renderer: Any) -> list[str]:
    """Overlapping tick labels of one axis: one line per axis, naming up to three pairs."""
    found = []
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        for name, axis in (("x", ax.xaxis), ("y", ax.yaxis)):
            labels = _tick_labels(axis, renderer)
            pairs = [(ta, tb) for (ta, a), (tb, b) in itertools.combinations(labels, 2) if _overlap(a, b)]
            if pairs:
                shown = ", ".join(f"{ta!r} and {tb!r}" for ta, tb in pairs[:3])
                found.append(
                    f"{_name(ax)} {name} tick labels overlap: {shown}" + (" ..." if len(pairs) > 3 else "")
                )
    return found


def text_collisions(fig: Figure, renderer: Any) -> list[str]:
    """Texts of one Axes that run into another Axes' frame or texts, and the figure title into any Axes."""
    found = []
    axes = [ax for ax in fig.axes if ax.get_visible()]
    frames = {ax: ax.get_window_extent(renderer) for ax in axes}
    texts = {ax: _axes_texts(ax, renderer) for ax in axes}
    for ax, other in itertools.permutations(axes, 2):
        for label, box in texts[ax]:
            if _overlap(box, frames[other]):
                found.append(f"{label} runs into the Axes {_name(other)}")
    for ax, other in itertools.combinations(axes, 2):
        for (la, a), (lb, b) in itertools.product(texts[ax], texts[other]):
            if _overlap(a, b):
                found.append(f"{la} overlaps {lb}")
    suptitle = fig._suptitle
    if suptitle is not None and _visible_text(suptitle):
        box = suptitle.get_window_extent(renderer)
        for ax in axes:
            if _overlap(box, frames[ax]) or any(_overlap(box, b) for _, b in texts[ax]):
                found.append(f"the figure title {suptitle.get_text()!r} runs into {_name(ax)}")
    return found


def _data_paths(ax: Axes) -> list[tuple[str, Any, bool]]:
    """(what, display-space path, filled) of everything ``ax`` draws in data coordinates."""
    paths = []
    data = ax.transData
    for line in ax.get_lines():
        if not line.get_visible() or line.get_transform() != data:
            continue  # axhline / axvline: guides across the Axes in axes coordinates
        xy = line.get_xydata()
        if len(xy) == 0:
            continue
        shown = data.transform(np.asarray(xy, dtype=np.float64))
        shown = shown[np.all(np.isfinite(shown), axis=1)]
        if line.get_linestyle() not in ("None", "none", "", " ") and len(shown) > 1:
            paths.append((f"line {line.get_label()!r}", Path(shown), False))
        if line.get_marker() not in (None, "None", "none", "", " "):
            size = line.get_markersize() * fig_dpi(ax) / 72.0 / 2.0
            name = f"marker of {line.get_label()!r}"
            paths += [
                (name, Bbox.from_extents(x - size, y - size, x + size, y + size), True) for x, y in shown
            ]
    for collection in ax.collections:
        if not collection.get_visible():
            continue
        transform = collection.get_transform()
        for path in collection.get_paths():
            shown = transform.transform_path(path)
            if len(shown.vertices):
                paths.append((f"collection {collection.get_label()!r}", shown, _filled(collection)))
    for patch in ax.patches:
        if isinstance(patch, Rectangle) and patch.get_visible():
            paths.append(("bar", patch.get_window_extent(), True))
    for image in ax.images:
        if isinstance(image, AxesImage) and image.get_visible():
            paths.append(("image", image.get_window_extent(), True))
    return paths


def fig_dpi(ax: Axes) -> float:
    return ax.figure.dpi


def _filled(collection: Collection) -> bool:
    faces = collection.get_facecolor()
    return len(faces) > 0 and float(np.max(np.asarray(faces)[:, 3])) > 0.0


def _covers(box: Bbox, what: Any, filled: bool) -> bool:
    inner = _shrunk(box, 2.0)
    if isinstance(what, Bbox):
        return _overlap(inner, what)
    if filled and what.contains_point(((inner.x0 + inner.x1) / 2, (inner.y0 + inner.y1) / 2)):
        return True
    return bool(what.intersects_bbox(inner, filled=filled))


def _legends(fig: Figure) -> list[tuple[Legend, list[Axes]]]:
    found = [(ax.get_legend(), [ax]) for ax in fig.axes if ax.get_legend() is not None]
    found += [(legend, list(fig.axes)) for legend in fig.legends]
    return [(legend, axes) for legend, axes in found if legend.get_visible()]


def legend_over_data(fig: Figure, renderer: Any) -> list[str]:
    """Legends drawn over a curve, a marker, a band, a bar or an image of their Axes (or any Axes)."""
    found = []
    for legend, axes in _legends(fig):
        box = legend.get_window_extent(renderer)
        for ax in axes:
            inside = Bbox.intersection(box, ax.get_window_extent(renderer))  # data is clipped to its Axes
            if inside is None or inside.width <= 2 * SLACK or inside.height <= 2 * SLACK:
                continue
            for what, path, filled in _data_paths(ax):
                if _covers(inside, path, filled):
                    found.append(f"{_name(ax)} legend covers the {what}")
                    break
    return found


def empty_legend_entries(fig: Figure) -> list[str]:
    """Legend entries whose series draws nothing (a line without points, an empty collection)."""
    found = []
    for legend, axes in _legends(fig):
        for handle, text in zip(legend.legend_handles, legend.get_texts(), strict=False):
            artists = _artists_of(handle, axes, text.get_text())
            if artists is not None and not artists:
                found.append(f"legend entry {text.get_text()!r} has nothing drawn")
    return found


def _artists_of(handle: Any, axes: list[Axes], label: str) -> list[Any] | None:
    """The drawn data of the series behind a legend entry (None: cannot tell)."""
    for ax in axes:
        for line in ax.get_lines():
            if line.get_label() == label:
                xy = np.asarray(line.get_xydata(), dtype=np.float64)
                return [line] if xy.size and np.isfinite(xy).all(axis=1).any() else []
        for container in ax.containers:
            if container.get_label() == label and isinstance(container, ErrorbarContainer):
                line = container.lines[0]
                return [] if line is not None and len(line.get_xydata()) == 0 else [container]
    return None


def figure_defects(fig: Figure) -> list[str]:
    """Every defect this module finds in ``fig`` (empty if none), after drawing it once."""
    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    return (
        tick_overlaps(fig, renderer)
        + text_collisions(fig, renderer)
        + legend_over_data(fig, renderer)
        + empty_legend_entries(fig)
    )


def install_notebook_check(dump: str | None = None) -> None:
    """Check every figure this IPython kernel displays (a cell's value or ``display(fig)``) and report
    its defects on stderr.

    The check wraps the PNG formatter of :class:`~matplotlib.figure.Figure`, which
    ``%matplotlib inline`` installs in a notebook's first cell: after every cell the wrapper is
    put back if the formatter was replaced. With ``dump`` (a folder), every displayed figure is
    also written there as ``figNN.png``, in order. Called again in the same kernel (the next
    notebook), it replaces the previous check and starts counting at 1 again.
    """
    from pathlib import Path

    from IPython import get_ipython

    shell = get_ipython()
    count = itertools.count(1)

    def checked(original: Any) -> Any:
        def png(fig: Figure, *args: Any, **kwargs: Any) -> Any:
            number = next(count)
            defects = figure_defects(fig)
            if dump:
                Path(dump).mkdir(parents=True, exist_ok=True)
                fig.savefig(Path(dump) / f"fig{number:02d}.png", dpi=80, bbox_inches="tight")
            if defects:
                print(f"figure {number}: layout defects:\n  " + "\n  ".join(defects), file=sys.stderr)
            return original(fig, *args, **kwargs)

        png.installed_by = ensure
        png.original = original
        return png

    def ensure(*_: Any) -> None:
        formatter = shell.display_formatter.formatters["image/png"]
        current = formatter.type_printers.get(Figure)
        if current is not None and getattr(current, "installed_by", None) is not ensure:
            formatter.for_type(Figure, checked(getattr(current, "original", current)))

    previous = getattr(shell, "figure_check", None)  # a previous notebook's, in a shared kernel
    if previous is not None:
        shell.events.unregister("post_run_cell", previous)
    shell.figure_check = ensure
    shell.events.register("post_run_cell", ensure)


__all__ = [
    "empty_legend_entries",
    "figure_defects",
    "install_notebook_check",
    "legend_over_data",
    "text_collisions",
    "tick_overlaps",
]
