"""Film figures written to PNG files, shared by flatland (1D film strips) and sphere3d (2D images).

Gradient images use a diverging colormap centred on zero with one symmetric colour
scale shared by every method in a figure, so equal colours mean equal derivatives.
A 1D film is drawn as a strip (one row of pixels stretched vertically) and, in the
panel, also as curves with bands at the one printed level
(:data:`~flatland.core.stats.LEVEL`, 99 % two-sided, ± 2.58 standard errors; the
legend says it), each method in its colour (:mod:`flatland.plotting.style`), the
legend beside the curves rather than over them.

Every function writes one PNG and returns its path. Given a ``sketch`` (a function that
draws into a matplotlib Axes, e.g. a flatland scene with
:func:`~flatland.plotting.sketch.draw_scene`), a figure gets a left panel, spanning its
rows, for it: the scene beside its film. Figures are made without pyplot, so no
backend is selected or needed and nothing stays open after saving.
"""

from __future__ import annotations

import os
import textwrap
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.gridspec import GridSpecBase

from flatland.core.stats import LEVEL
from flatland.plotting.bands import draw_estimate
from flatland.plotting.style import (
    DIVERGING,
    PRIMAL,
    legend_outside,
    method_colour,
    neutral_cycle,
    radiance_norm,
    symmetric_limit,
    symmetric_norm,
)

__all__ = [
    "DIVERGING",
    "PRIMAL",
    "gradient_figure",
    "grid_beside",
    "image_figure",
    "panel_figure",
    "plot_gradient",
    "plot_image",
    "plot_panel",
    "rare_events_note",
    "save_png",
    "symmetric_limit",
]

DPI = 110
"""Resolution of the written PNGs."""
SKETCH_INCHES = 3.8
"""Width added to a figure for its sketch panel, and the least height of such a figure."""
Sketch = Callable[[Any], Any]
"""A function drawing into the Axes it is given (the scene sketch beside a film)."""


def save_png(fig: Figure, path: str | os.PathLike) -> Path:
    """Write ``fig`` to the PNG ``path`` (making its folder) and return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    return path


def grid_beside(fig: Figure, sketch: Sketch | None, nrows: int, ncols: int, **grid: Any) -> GridSpecBase:
    """The grid of a figure's film panels; with a ``sketch``, right of a panel spanning all rows that it
    draws, the figure widened by :data:`SKETCH_INCHES` (and at least that tall)."""
    if sketch is None:
        return fig.add_gridspec(nrows, ncols, **grid)
    width = fig.get_figwidth()
    fig.set_size_inches(width + SKETCH_INCHES, max(fig.get_figheight(), SKETCH_INCHES))
    outer = fig.add_gridspec(1, 2, width_ratios=(SKETCH_INCHES, width), wspace=0.22)
    sketch(fig.add_subplot(outer[0]))
    return outer[1].subgridspec(nrows, ncols, **grid)


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
    """A film as a curve over pixel centres with its :data:`~flatland.core.stats.LEVEL` band."""
    x = np.arange(np.size(array)) + 0.5
    draw_estimate(ax, x, array, stderr=stderr, level=LEVEL if stderr is not None else None, label=label,
                  color=color, lw=1.2)  # fmt: skip


def _strip_over_curve(
    fig: Figure, sketch: Sketch | None, values: np.ndarray, stderr: np.ndarray | None, cmap: str,
    norm: Normalize, title: str, ylabel: str,
) -> tuple[Any, Any, Any]:  # fmt: skip
    """A 1D film's two panels: its strip over its curve (its band at the printed level, the legend naming
    it), on one pixel axis; returns the strip's and the curve's axes and the strip's image."""
    top, bottom = grid_beside(fig, sketch, 2, 1, height_ratios=(1, 2)).subplots(sharex=True)
    strip = _film(top, values, cmap, norm, title)
    top.set_xlabel("")
    _curve(bottom, values, stderr, ylabel, color="k")
    legend_outside(bottom)  # names the band and its coverage, clear of the curve
    bottom.set_xlabel("pixel")
    bottom.set_ylabel(ylabel)
    bottom.set_xlim(0, values.size)
    return top, bottom, strip


def image_figure(
    value: np.ndarray, stderr: np.ndarray | None, path: str | os.PathLike, title: str = "",
    sketch: Sketch | None = None,
) -> Path:  # fmt: skip
    """A rendered image (1D: strip over a curve with its band; 2D: grey image), the ``sketch`` (if given)
    on its left."""
    value = np.asarray(value)
    norm = radiance_norm(value)
    if value.ndim == 1:
        fig = Figure(figsize=(8.5, 3.4), layout="constrained")
        _strip_over_curve(fig, sketch, value, stderr, PRIMAL, norm, title, "radiance")
    else:
        # constrained layout: the title stays over the image, clear of the colour bar
        fig = Figure(figsize=(5, 5 * value.shape[0] / max(value.shape[1], 1) + 0.4), layout="constrained")
        ax = grid_beside(fig, sketch, 1, 1).subplots()
        fig.colorbar(_film(ax, value, PRIMAL, norm, title), ax=ax, shrink=0.8)
    return save_png(fig, path)


def gradient_figure(
    derivative: np.ndarray, stderr: np.ndarray | None, path: str | os.PathLike, title: str = "",
    limit: float | None = None, sketch: Sketch | None = None,
) -> Path:  # fmt: skip
    """A derivative image on the diverging map centred on zero (1D: strip over a curve), the
    ``sketch`` (if given) on its left."""
    derivative = np.asarray(derivative)
    limit = symmetric_limit([derivative]) if limit is None else limit
    norm = symmetric_norm(limit)
    if derivative.ndim == 1:
        fig = Figure(figsize=(8.5, 3.4), layout="constrained")
        top, bottom, strip = _strip_over_curve(
            fig, sketch, derivative, stderr, DIVERGING, norm, title, "dI/dθ"
        )
        fig.colorbar(strip, ax=[top, bottom], shrink=0.6, label="dI/dθ")
        bottom.axhline(0.0, color="0.5", lw=0.6)
    else:
        fig = Figure(
            figsize=(5, 5 * derivative.shape[0] / max(derivative.shape[1], 1) + 0.4), layout="constrained"
        )
        ax = grid_beside(fig, sketch, 1, 1).subplots()
        fig.colorbar(_film(ax, derivative, DIVERGING, norm, title), ax=ax, shrink=0.8, label="dI/dθ")
    return save_png(fig, path)


def panel_figure(
    primal: np.ndarray,
    gradients: Mapping[str, tuple[np.ndarray, np.ndarray | None]],
    path: str | os.PathLike,
    title: str = "",
    sketch: Sketch | None = None,
    notes: Sequence[str] = (),
) -> Path:
    """The side-by-side panel: primal, then each method's derivative on one shared diverging scale.

    ``gradients`` maps a column title to ``(derivative, stderr)``. A 1D film gets a
    second row with all derivatives as curves (bands at the printed level) on one axis,
    each in its method's colour when the title names one (``"finite differences"`` does),
    the legend right of the curves. The ``sketch``, if given, draws a first column
    spanning both rows; ``notes`` are lines printed under the figure.
    """
    primal = np.asarray(primal)
    columns = 1 + len(gradients)
    limit = symmetric_limit([np.asarray(d) for d, _ in gradients.values()])
    norm = symmetric_norm(limit)
    primal_norm = radiance_norm(primal)
    if primal.ndim == 1:
        fig = Figure(figsize=(2.6 * columns + 1.6, 5.2 + 0.25 * len(notes)), layout="constrained")
        grid = grid_beside(fig, sketch, 2, columns, height_ratios=(1, 1.6))
        axes = [fig.add_subplot(grid[0, i]) for i in range(columns)]
        curves = neutral_cycle(fig.add_subplot(grid[1, :]))
    else:
        aspect = primal.shape[0] / max(primal.shape[1], 1)
        fig = Figure(figsize=(2.6 * columns, 2.6 * aspect + 0.9), layout="constrained")
        axes, curves = list(np.atleast_1d(grid_beside(fig, sketch, 1, columns).subplots())), None
    _film(axes[0], primal, PRIMAL, primal_norm, "primal")
    mappable = None
    for ax, (label, (derivative, _)) in zip(axes[1:], gradients.items(), strict=True):
        mappable = _film(ax, derivative, DIVERGING, norm, label)
    if mappable is not None:
        fig.colorbar(mappable, ax=axes, shrink=0.85, label="dI/dθ (shared scale)", pad=0.02)
    if curves is not None:
        for label, (derivative, stderr) in gradients.items():
            stderr = None if stderr is None else np.asarray(stderr)
            _curve(curves, np.asarray(derivative), stderr, label, method_colour(label))
        curves.axhline(0.0, color="0.5", lw=0.6)
        curves.set_xlim(0, primal.size)
        curves.set_ylim(-1.15 * limit, 1.15 * limit)
        curves.set_xlabel("pixel")
        curves.set_ylabel("dI/dθ")
        legend_outside(curves)
    if notes:  # wrapped to the figure's width, about 15 characters of 8 pt text per inch
        width = int(15 * fig.get_figwidth())
        fig.supxlabel("\n".join(textwrap.fill(n, width) for n in notes), fontsize=8, ha="left", x=0.01)
    if title:
        fig.suptitle(title)
    return save_png(fig, path)


def plot_image(image: Any, path: str | os.PathLike, title: str = "", sketch: Sketch | None = None) -> Path:
    """PNG of an :class:`~flatland.core.image.Image` (the ``sketch`` on its left, if given)."""
    return image_figure(image.value, image.stderr, path, title or image.scene, sketch)


def plot_gradient(
    gradient: Any, path: str | os.PathLike, title: str = "", limit: float | None = None,
    sketch: Sketch | None = None,
) -> Path:  # fmt: skip
    """PNG of a :class:`~flatland.core.image.GradientImage`'s derivative, diverging map centred on 0
    (the ``sketch`` on its left, if given)."""
    title = title or f"{gradient.scene}: d/d {gradient.param} ({gradient.method})"
    return gradient_figure(gradient.derivative, gradient.derivative_stderr, path, title, limit, sketch)


def plot_panel(
    primal: Any, gradients: Mapping[str, Any], path: str | os.PathLike, title: str = "",
    sketch: Sketch | None = None,
) -> Path:  # fmt: skip
    """The side-by-side panel from an Image and GradientImages keyed by column title (the ``sketch``
    first, if given), with a note under it for each finite-difference column (:func:`rare_events_note`)."""
    columns = {label: (g.derivative, g.derivative_stderr) for label, g in gradients.items()}
    notes = [rare_events_note(label, g) for label, g in gradients.items() if g.method == "finite_difference"]
    return panel_figure(primal.value, columns, path, title, sketch, notes)


def rare_events_note(label: str, gradient: Any) -> str:
    """Why a finite-difference film can zig-zag between 0 and large values, as a note under a figure.

    With common random numbers, $[Î(θ_0 + h) - Î(θ_0 - h)] / 2h$ is non-zero in a pixel only where
    one of its rays (camera or shadow) hits something else at $θ_0 + h$ than at $θ_0 - h$: a ray
    within about $h |c'|$ of a moving edge. With a small step that is a rare event per pixel, so
    in a penumbra some pixels have none (exactly 0, and a zero standard error) and their neighbours
    one or two (a large value): noise of a few rare events, not the shape of the derivative.
    """
    h = dict(gradient.options).get("h")
    step = "" if h is None else f", h = {h:g}"
    return (
        f"{label}{step}: a pixel is non-zero only if one of its rays hits something else at θ + h than "
        "at θ − h, a rare event for a small h: in a penumbra some pixels have none (exactly 0, zero "
        "standard error) and their neighbours a few (large values). That zig-zag is noise, not the "
        "derivative; more samples or a larger h smooth it."
    )
