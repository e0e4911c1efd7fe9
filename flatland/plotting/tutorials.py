"""Figures for the rendering tutorials (3-9): matplotlib only, no numerics.

Like :mod:`flatland.plotting.textbook`, every function draws data computed elsewhere and
returns a :class:`~matplotlib.figure.Figure` created without pyplot (a notebook shows
exactly the figures its cells return; nothing is registered globally). The helpers
take the renderers' results as they come, in either package: a 1D film (flatland) is
drawn over the pixel index, a 2D film (sphere3d) as an image.

=============================  ======================================================
:func:`plot_grid`              an empty row (or grid) of panels, for the ``ax=`` of
                               the other helpers: two figures side by side
:func:`plot_film`              per-pixel series of a 1D film with ± z · stderr bands
:func:`plot_gradient_panel`    primal | derivative | derivative ...: strips (1D) or
                               images (2D) on one shared diverging scale
:func:`plot_descent`           loss and parameter per iteration of gradient descent
:func:`plot_scene`             the sketch of a flatland scene: shapes, emitters,
                               camera frustum, the part a parameter moves
                               (:mod:`flatland.plotting.sketch`)
=============================  ======================================================

Given a flatland ``scene`` (and the ``param`` differentiated), :func:`plot_film` and
:func:`plot_gradient_panel` draw its sketch in a left panel: the geometry beside its film.

A *series* is given as an array, as a ``(values, stderr)`` tuple, or as a result
object: a :class:`~flatland.core.image.GradientImage` stands for its derivative and
its standard error, an :class:`~flatland.core.image.Image` for its value and standard
error. Derivatives use the diverging map ``RdBu_r`` centred on zero, radiance the
grey map, and a series named after a method has the method's colour, as in the
packages' file-writing figures: all come from :mod:`flatland.plotting.style`, and
bands are drawn by :func:`~flatland.plotting.bands.draw_estimate`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import Normalize
from matplotlib.figure import Figure

from flatland.core.validate import ValidationError
from flatland.plotting.bands import draw_estimate
from flatland.plotting.films import grid_beside
from flatland.plotting.sketch import draw_scene, plot_scene
from flatland.plotting.style import (
    DIVERGING,
    FIGSIZE,
    PRIMAL,
    REFERENCE_STYLE,
    integer_ticks,
    method_colour,
    neutral_cycle,
    new_axes,
    radiance_norm,
    series_styles,
    symmetric_limit,
    symmetric_norm,
)

__all__ = [
    "DIVERGING",
    "PRIMAL",
    "REFERENCE_STYLE",
    "plot_descent",
    "plot_film",
    "plot_gradient_panel",
    "plot_grid",
    "plot_scene",
]


def _series(name: str, item: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """(values, stderr or None) of an array, a (values, stderr) tuple, a GradientImage or an Image."""
    if hasattr(item, "derivative") and hasattr(item, "derivative_stderr"):
        values, stderr = item.derivative, item.derivative_stderr
    elif hasattr(item, "value") and hasattr(item, "stderr"):
        values, stderr = item.value, item.stderr
    elif isinstance(item, tuple):
        if len(item) != 2:
            raise ValidationError(name, f"a tuple must be (values, stderr), got {len(item)} entries")
        values, stderr = item
    else:
        values, stderr = item, None
    values = np.asarray(values, dtype=np.float64)
    if stderr is None:
        return values, None
    stderr = np.asarray(stderr, dtype=np.float64)
    if stderr.shape != values.shape:
        raise ValidationError(name, f"stderr has shape {stderr.shape}, values {values.shape}")
    return values, stderr


def _primal(item: Any) -> np.ndarray:
    """The pixel values of an Image, a GradientImage or an array."""
    return np.asarray(getattr(item, "value", item), dtype=np.float64)


def _sketch(scene: Any, param: str | None) -> Any:
    """The sketch of ``scene`` for :func:`~flatland.plotting.films.grid_beside`, or None without a scene."""
    return None if scene is None else lambda ax: draw_scene(ax, scene, param)


def plot_grid(
    ncols: int = 2,
    nrows: int = 1,
    *,
    titles: Sequence[str] = (),
    panel_size: tuple[float, float] = (4.4, 3.3),
    title: str | None = None,
) -> Figure:
    """An empty grid of panels to draw into with the other helpers' ``ax=fig.axes[i]``.

    Parameters
    ----------
    ncols, nrows : int
        Panels per row and rows; ``fig.axes`` lists them row by row.
    titles : sequence of str
        Panel titles, in the same order (fewer is fine).
    panel_size : (float, float)
        Size of one panel in inches.
    title : str, optional
        Figure title.

    Returns
    -------
    Figure
    """
    if ncols < 1 or nrows < 1:
        raise ValidationError("ncols", f"need at least one panel, got {nrows} x {ncols}")
    if len(titles) > ncols * nrows:
        raise ValidationError("titles", f"{len(titles)} titles for {ncols * nrows} panels")
    fig = Figure(figsize=(panel_size[0] * ncols, panel_size[1] * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax in axes:
        neutral_cycle(ax)  # series without a method's colour never take one
    for ax, text in zip(axes, titles, strict=False):
        ax.set_title(text, fontsize=10)
    if title:
        fig.suptitle(title)
    return fig


def plot_film(
    curves: Mapping[str, Any],
    *,
    level: float = 0.99,
    styles: Mapping[str, Mapping[str, Any]] | None = None,
    marks: Sequence[float] = (),
    ax: Axes | None = None,
    title: str | None = None,
    xlabel: str = "pixel",
    ylabel: str = "dI/dθ",
    scene: Any = None,
    param: str | None = None,
) -> Figure:
    """Draw per-pixel series of a 1D film over the pixel index, each with a confidence band.

    Parameters
    ----------
    curves : mapping of str to series
        By legend label: an array, a ``(values, stderr)`` tuple, a GradientImage
        (its derivative) or an Image (its value); all of one length.
    level : float
        Two-sided confidence level of the bands, ± z · stderr (2.58 at 0.99); series
        without a standard error get no band, and neither do pixels whose standard
        error is not finite.
    styles : mapping of str to dict, optional
        Extra matplotlib keywords per label, e.g. ``{"closed form": REFERENCE_STYLE}``.
        Without them a label naming a method has the method's colour, and the
        variants of one method (``"reparam, κ × 4"``) differ by line style.
    marks : sequence of float
        Pixel positions (pixel j spans [j - 0.5, j + 0.5]) to mark with thin lines.
    ax, title, xlabel, ylabel
        Draw into ``ax`` instead of a new figure; axis annotations.
    scene, param : optional
        A flatland scene (and the parameter differentiated) to sketch left of the film
        (:func:`plot_scene`); only in a new figure (into a grid, draw it with
        ``plot_scene(scene, param, ax=...)``).

    Returns
    -------
    Figure
    """
    styles = styles or {}
    if scene is not None:
        if ax is not None:
            raise ValidationError("scene", "a sketch needs a new figure: draw it with plot_scene(..., ax=)")
        fig = Figure(figsize=FIGSIZE, layout="constrained")
        ax = neutral_cycle(fig.add_subplot(grid_beside(fig, _sketch(scene, param), 1, 1)[0]))
    ax = new_axes(ax, title)
    variants = series_styles(curves, vary="linestyle", others=False)  # a method's colour, variants dashed
    length = None
    for label, item in curves.items():
        values, stderr = _series(f"curves[{label!r}]", item)
        if values.ndim != 1:
            raise ValidationError(f"curves[{label!r}]", f"must be a 1D film, got shape {values.shape}")
        if length is not None and values.size != length:
            raise ValidationError(f"curves[{label!r}]", f"has {values.size} pixels, expected {length}")
        length = values.size
        x = np.arange(values.size, dtype=np.float64)
        style = {"linewidth": 1.3, **variants[label], **dict(styles.get(label, {}))}
        where = None if stderr is None else np.isfinite(stderr)
        draw_estimate(ax, x, values, stderr=stderr, level=level, label=label, where=where, **style)
    for m in marks:
        ax.axvline(float(m), color="gray", linestyle=":", linewidth=1.0)
    ax.axhline(0.0, color="0.6", linewidth=0.6)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if curves:
        ax.legend(loc="best", fontsize=8)
    return ax.figure


def _strip(ax: Axes, values: np.ndarray, cmap: str, norm: Normalize, title: str) -> Any:
    """A film as a strip (1D, pixel j centred on x = j) or an image (2D); returns the mappable."""
    if values.ndim == 1:
        image = ax.imshow(values[None, :], cmap=cmap, norm=norm, aspect="auto", interpolation="nearest",
                          extent=(-0.5, values.size - 0.5, 0.0, 1.0))  # fmt: skip
        ax.set_yticks([])
    else:
        image = ax.imshow(values, cmap=cmap, norm=norm, interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
    ax.set_title(title, fontsize=10)
    return image


def plot_gradient_panel(
    primal: Any,
    gradients: Mapping[str, Any],
    *,
    level: float = 0.99,
    title: str | None = None,
    scene: Any = None,
    param: str | None = None,
) -> Figure:
    """The side-by-side panel: the primal image, then each derivative on one shared diverging scale.

    Parameters
    ----------
    primal : array_like, Image or GradientImage
        The rendered film: shape (pixels,) in flatland, (height, width) in sphere3d.
    gradients : mapping of str to series
        Column title to a derivative series (see the module docstring), each of the
        primal's shape. Equal colours mean equal derivatives across columns.
    level : float
        1D films get a second row with every derivative as a curve with a
        ± z · stderr band at this two-sided level (:func:`plot_film`).
    title : str, optional
        Figure title.
    scene, param : optional
        A flatland scene (and the parameter differentiated) to sketch in a first
        column spanning both rows (:func:`plot_scene`).

    Returns
    -------
    Figure
    """
    image = _primal(primal)
    if image.ndim not in (1, 2):
        raise ValidationError("primal", f"must be a 1D or 2D film, got shape {image.shape}")
    series = {label: _series(f"gradients[{label!r}]", g) for label, g in gradients.items()}
    for label, (values, _) in series.items():
        if values.shape != image.shape:
            raise ValidationError(f"gradients[{label!r}]", f"has shape {values.shape}, primal {image.shape}")
    columns = 1 + len(series)
    norm = symmetric_norm(symmetric_limit([v for v, _ in series.values()], percentile=100.0))
    grey = radiance_norm(image)
    if image.ndim == 1:
        fig = Figure(figsize=(max(2.6 * columns, 7.0), 5.0), layout="constrained")
        grid = grid_beside(fig, _sketch(scene, param), 2, columns, height_ratios=(1.0, 2.2))
        axes = [fig.add_subplot(grid[0, i]) for i in range(columns)]
        curves = neutral_cycle(fig.add_subplot(grid[1, :]))
    else:
        aspect = image.shape[0] / max(image.shape[1], 1)
        fig = Figure(figsize=(2.7 * columns + 0.8, 2.7 * aspect + 0.7), layout="constrained")
        axes, curves = (
            list(np.atleast_1d(grid_beside(fig, _sketch(scene, param), 1, columns).subplots())),
            None,
        )
    fig.colorbar(_strip(axes[0], image, PRIMAL, grey, "primal"), ax=axes[0], shrink=0.8)
    mappable = None
    for ax, (label, (values, _)) in zip(axes[1:], series.items(), strict=True):
        mappable = _strip(ax, values, DIVERGING, norm, label)
    if mappable is not None:
        fig.colorbar(mappable, ax=axes[1:], shrink=0.8, label="dI/dθ (shared scale)")
    if curves is not None:
        plot_film({label: (v, s) if s is not None else v for label, (v, s) in series.items()},
                  level=level, ax=curves)  # fmt: skip
        curves.set_xlim(-0.5, image.size - 0.5)
    if title:
        fig.suptitle(title)
    return fig


def plot_descent(
    loss: Mapping[str, Any],
    params: Mapping[str, Any],
    *,
    target: float | None = None,
    logy: bool = True,
    title: str | None = None,
    param_label: str = "θ",
) -> Figure:
    """Two panels over the iterations of gradient descent: the loss, and the parameter.

    Parameters
    ----------
    loss : mapping of str to array_like
        Loss per iteration, by run label.
    params : mapping of str to array_like
        Parameter per iteration, by run label (the same labels and lengths as ``loss``).
    target : float, optional
        The parameter value that produced the target image, drawn as a dashed line.
    logy : bool
        Logarithmic loss axis.
    title, param_label : str
        Figure title; name of the parameter on the right-hand axis.

    Returns
    -------
    Figure
    """
    if set(loss) != set(params):
        raise ValidationError("params", f"labels {sorted(params)} differ from the loss's {sorted(loss)}")
    fig = Figure(figsize=(FIGSIZE[0] * 1.8, FIGSIZE[1]), layout="constrained")
    left, right = (neutral_cycle(ax) for ax in fig.subplots(1, 2))
    for label in loss:
        values = np.asarray(loss[label], dtype=np.float64).ravel()
        theta = np.asarray(params[label], dtype=np.float64).ravel()
        if theta.size != values.size:
            raise ValidationError(
                f"params[{label!r}]", f"has {theta.size} iterations, the loss {values.size}"
            )
        steps = np.arange(values.size)
        (line,) = left.plot(steps, values, marker="o", markersize=3, label=label, color=method_colour(label))
        right.plot(steps, theta, marker="o", markersize=3, color=line.get_color(), label=label)
    if target is not None:
        right.axhline(float(target), label="target", **REFERENCE_STYLE)
    if logy:
        left.set_yscale("log")
    left.set_xlabel("iteration")
    left.set_ylabel("loss Σ (I − I_target)²")
    right.set_xlabel("iteration")
    right.set_ylabel(param_label)
    for ax in (left, right):
        integer_ticks(ax.xaxis)  # iterations are whole numbers
        ax.grid(True, which="both", alpha=0.3)
        if loss:
            ax.legend(loc="best", fontsize=8)
    if title:
        fig.suptitle(title)
    return fig
