r"""Figures of flatland results: matplotlib only, no numerics.

A flatland film is one row of pixels. Images are drawn as a strip (the row stretched
vertically) above a curve with ±2 standard-error bands; derivatives use the
diverging map ``RdBu_r`` centred on zero, one symmetric scale shared by all methods
of a figure. The panel puts "primal | naive | boundary | reparam | finite
differences" side by side as strips and overlays every method's derivative as
curves below (each method in its fixed colour), where the spike naive
differentiation misses at a moving shadow edge is plain to see. Study figures: RMSE
against wall time per estimate (log-log, a biased method's floor next to the $1/\sqrt{t}$
fall of the unbiased ones), bias ± CI and
standard deviation against κ, and equal-time efficiency bars (unbiased cells
only). The drawing code is shared with sphere3d (:mod:`flatland.plotting.films`,
:mod:`flatland.plotting.study`), which draws its 2D films as images.
"""

from __future__ import annotations

from flatland.plotting.films import plot_gradient, plot_image, plot_panel
from flatland.plotting.study import plot_efficiency, plot_error_time, plot_kappa, plot_study

__all__ = [
    "plot_efficiency",
    "plot_error_time",
    "plot_gradient",
    "plot_image",
    "plot_kappa",
    "plot_panel",
    "plot_study",
]
