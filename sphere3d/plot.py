r"""Figures of sphere3d results: matplotlib only, no numerics.

A sphere3d film is a (height, width) image. Images are drawn in grey; derivatives on
the diverging map ``RdBu_r`` centred on zero, one symmetric scale shared by all
methods of a figure. The panel puts "primal | naive | reparam | finite differences"
side by side (the demo's methods, :mod:`sphere3d.__main__`). Study figures: RMSE against
wall time per estimate (log-log, a biased method's floor next to the $1/\sqrt{t}$ fall of
the unbiased ones), bias ± CI and standard deviation against κ, and equal-time
efficiency bars (unbiased cells only). The drawing code is shared with flatland
(:mod:`flatland.plotting.films`, :mod:`flatland.plotting.study`), which draws its 1D
films as strips and curves.
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
