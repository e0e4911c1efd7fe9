"""Figures of an optimisation (:func:`flatland.optimize.optimize`): the images, the history, the loss curves.

:func:`plot_optimize_images` draws, per view, the target, the first and the last recorded image of a
run (1D films as curves, 2D films as images, a row per view); :func:`plot_history` draws one run's
loss and each parameter's trajectory against the step, with the values that made the targets when
they are known; :func:`plot_loss_curves` draws the loss of one or more runs against the step and
against the wall time (a method that renders more per step, such as finite differences, is slower on
the second axis). Each returns a Figure (no pyplot); :func:`~flatland.plotting.films.save_png` writes
it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from flatland.core.validate import ValidationError
from flatland.plotting.style import FIGSIZE, OTHER_COLOURS, integer_ticks, method_colour, neutral_cycle

__all__ = ["plot_history", "plot_loss_curves", "plot_optimize_images"]


def plot_optimize_images(
    result: Any, title: str | None = None, labels: Sequence[str] | None = None
) -> Figure:
    """One panel per view: the target, the initial (first recorded) and the optimised (last recorded)
    image of ``result`` (an :class:`~flatland.core.optimize.OptimizeResult`), titled by ``labels``
    (default ``view v``): 1D films as curves, up to three views in a row, more in two rows, the legend
    below; 2D films as a row per view of the three images on one grey scale."""
    if len(result.images) < 2:
        raise ValidationError(
            "result", "needs at least two recorded images (record the first and last steps)"
        )
    first, last = min(result.images), max(result.images)
    views = result.targets.shape[0]
    labels = tuple(labels) if labels is not None else tuple(f"view {v}" for v in range(views))
    if len(labels) != views:
        raise ValidationError("labels", f"must name the {views} views, got {len(labels)} labels")
    if result.targets.ndim == 3:
        return _image_grid(result, first, last, labels, title)
    ncols = views if views <= 3 else math.ceil(views / 2)  # four views: two rows of two
    nrows = math.ceil(views / ncols)
    fig = Figure(figsize=(FIGSIZE[0] * 0.8 * ncols + 1.0, FIGSIZE[1] * nrows), layout="constrained")
    grid = fig.subplots(nrows, ncols, sharey=True, squeeze=False).ravel()
    for ax in grid[views:]:
        fig.delaxes(ax)
    axes = grid[:views]
    pixels = np.arange(result.targets.shape[-1])
    for v, ax in enumerate(axes):
        neutral_cycle(ax)
        ax.plot(pixels, result.targets[v], color="black", lw=2.2, alpha=0.5, label="target")
        ax.plot(pixels, result.images[first][v], ls="--", label=f"initial (step {first})")
        ax.plot(pixels, result.images[last][v], label=f"optimised (step {last})")
        ax.set_title(labels[v])
        ax.set_xlabel("pixel")
        ax.grid(True, alpha=0.3)
        if v % ncols == 0:
            ax.set_ylabel("pixel value")
    # below the panels, never over a silhouette that spans the film
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", ncols=3, fontsize=8)
    if title:
        fig.suptitle(title)
    return fig


def plot_history(
    result: Any,
    truth: Any = None,
    title: str | None = None,
    labels: Sequence[str] | None = None,
    logy: bool = True,
) -> Figure:
    """One run's loss against the step (left) and each parameter's θ against the step (right, row t of
    ``result.theta`` at step t), with ``truth`` (the offsets that made the targets, one per parameter)
    as a dashed line in its parameter's colour; ``labels`` name the parameters (default their names)."""
    theta = np.asarray(result.theta, dtype=np.float64)
    k = theta.shape[1]
    labels = tuple(labels) if labels is not None else tuple(result.params)
    if len(labels) != k:
        raise ValidationError("labels", f"must name the {k} parameters, got {len(labels)} labels")
    if truth is not None:
        truth = np.asarray(truth, dtype=np.float64).ravel()
        if truth.size != k:
            raise ValidationError("truth", f"must hold one value per parameter ({k}), got {truth.size}")
    fig = Figure(figsize=(FIGSIZE[0] * 1.8, FIGSIZE[1]), layout="constrained")
    left, right = (neutral_cycle(ax) for ax in fig.subplots(1, 2))
    steps = np.arange(theta.shape[0])
    left.plot(steps, result.loss, color=method_colour(result.method), label=result.method)
    for i in range(k):
        colour = OTHER_COLOURS[i % len(OTHER_COLOURS)]
        right.plot(steps, theta[:, i], color=colour, label=labels[i])
        if truth is not None:
            right.axhline(truth[i], color=colour, linestyle="--", linewidth=1.0)
    if logy:
        left.set_yscale("log")
    left.set_ylabel("loss Σ (I − I*)²")
    right.set_ylabel("θ (offset)" if truth is None else "θ (offset); dashed: the target's")
    for ax in (left, right):
        ax.set_xlabel("step")
        integer_ticks(ax.xaxis)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    if title:
        fig.suptitle(title)
    return fig


def _image_grid(result: Any, first: int, last: int, labels: tuple[str, ...], title: str | None) -> Figure:
    """Rows of (target, initial, optimised) 2D images, one row per view, one grey scale per row."""
    views = result.targets.shape[0]
    fig = Figure(figsize=(3 * 2.2 + 0.8, views * 2.2 + 0.6), layout="constrained")
    axes = fig.subplots(views, 3, squeeze=False)
    for v in range(views):
        row = (result.targets[v], result.images[first][v], result.images[last][v])
        top = max(float(np.max(im)) for im in row) or 1.0
        names = ("target", f"initial (step {first})", f"optimised (step {last})")
        for ax, image, name in zip(axes[v], row, names, strict=True):
            ax.imshow(image, cmap="gray", vmin=0.0, vmax=top, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(name if v == 0 else "", fontsize=9)
        axes[v][0].set_ylabel(labels[v])
    if title:
        fig.suptitle(title)
    return fig


def plot_loss_curves(runs: Mapping[str, Any], title: str | None = None, logy: bool = True) -> Figure:
    """The loss of each run (by label, e.g. its method) against the step (left) and against the wall
    time since the start (right; row t of the loss after the first t steps' seconds)."""
    if not runs:
        raise ValidationError("runs", "must hold at least one run")
    fig = Figure(figsize=(FIGSIZE[0] * 1.8, FIGSIZE[1]), layout="constrained")
    left, right = (neutral_cycle(ax) for ax in fig.subplots(1, 2, sharey=True))
    for label, result in runs.items():
        loss = np.asarray(result.loss, dtype=np.float64)
        elapsed = np.concatenate([[0.0], np.cumsum(result.seconds)])
        (line,) = left.plot(np.arange(loss.size), loss, label=label, color=method_colour(label))
        right.plot(elapsed, loss, color=line.get_color(), label=label)
    if logy:
        left.set_yscale("log")
    left.set_xlabel("step")
    right.set_xlabel("wall time (s)")
    left.set_ylabel("loss Σ (I − I*)²")
    integer_ticks(left.xaxis)
    for ax in (left, right):
        ax.grid(True, which="both", alpha=0.3)
    left.legend(loc="best", fontsize=8)
    if title:
        fig.suptitle(title)
    return fig
