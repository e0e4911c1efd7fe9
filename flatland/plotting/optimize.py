"""Figures of an optimisation (:func:`flatland.optimize.optimize`): the images, and the loss curves.

:func:`optimize_images` draws, per view, the target, the first and the last recorded image of a run
(1D films as curves, 2D films as images, a row per view); :func:`loss_curves` draws the loss of one
or more runs against the step and against the wall time (a method that renders more per step, such
as finite differences, is slower on the second axis). Both return a Figure (no pyplot);
:func:`~flatland.plotting.films.save_png` writes it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from flatland.core.validate import ValidationError
from flatland.plotting.style import FIGSIZE, integer_ticks, method_colour, neutral_cycle

__all__ = ["loss_curves", "optimize_images"]


def optimize_images(result: Any, title: str | None = None, labels: tuple[str, ...] | None = None) -> Figure:
    """One panel per view: the target, the initial (first recorded) and the optimised (last recorded)
    image of ``result`` (an :class:`~flatland.core.optimize.OptimizeResult` with 1D films as curves;
    with 2D films a row per view of the three images on one grey scale)."""
    if len(result.images) < 2:
        raise ValidationError(
            "result", "needs at least two recorded images (record the first and last steps)"
        )
    first, last = min(result.images), max(result.images)
    views = result.targets.shape[0]
    labels = labels or tuple(f"view {v}" for v in range(views))
    if result.targets.ndim == 3:
        return _image_grid(result, first, last, labels, title)
    fig = Figure(figsize=(FIGSIZE[0] * min(views, 4) * 0.8 + 1.0, FIGSIZE[1]), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, views, sharey=True, squeeze=False)[0])
    for v, ax in enumerate(axes):
        neutral_cycle(ax)
        pixels = np.arange(result.targets.shape[-1])
        ax.plot(pixels, result.targets[v], color="black", lw=2.2, alpha=0.5, label="target")
        ax.plot(pixels, result.images[first][v], ls="--", label=f"initial (step {first})")
        ax.plot(pixels, result.images[last][v], label=f"optimised (step {last})")
        ax.set_title(labels[v])
        ax.set_xlabel("pixel")
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel("pixel value")
    axes[0].legend(loc="best", fontsize=8)
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


def loss_curves(runs: Mapping[str, Any], title: str | None = None, logy: bool = True) -> Figure:
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
