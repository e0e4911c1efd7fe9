"""All figures of both packages and the tutorials, on one style: matplotlib only, no numerics.

The foundation every figure module draws with:

* :mod:`flatland.plotting.style`: one fixed colour per method
  (:data:`~flatland.plotting.style.METHOD_COLOURS`,
  :func:`~flatland.plotting.style.method_colour`), the colour maps, symmetric colour
  limits for derivative images (:func:`~flatland.plotting.style.symmetric_limit`) and
  the coverage labels of bands;
* :mod:`flatland.plotting.bands`: :func:`~flatland.plotting.bands.draw_estimate`,
  the one way an estimate is drawn with its confidence band or error bars.

The figures:

* :mod:`flatland.plotting.films` and :mod:`flatland.plotting.study`: PNG files of
  images, derivative images, the method panel and study results, behind the
  packages' ``plot`` modules and the command line;
* :mod:`flatland.plotting.textbook` (with
  :mod:`~flatland.plotting.textbook_estimates`), :mod:`flatland.plotting.tutorials` and
  :mod:`flatland.plotting.convergence` (error against time): figures returned to a
  notebook, with :mod:`flatland.plotting.probe_rays` for the probe rays of tutorial 8.
* :mod:`flatland.plotting.sketch`: the sketch of a flatland scene (shapes, emitters,
  camera frustum, the part a parameter moves and its motion), drawn beside every
  flatland film of the command line and the tutorials.

No module here imports pyplot or selects a matplotlib backend (figures are made as
:class:`matplotlib.figure.Figure` objects), so importing any of them leaves a
notebook's inline backend as it is.
"""

from flatland.plotting.bands import draw_estimate
from flatland.plotting.style import METHOD_COLOURS, coverage_label, method_colour, symmetric_limit

__all__ = ["METHOD_COLOURS", "coverage_label", "draw_estimate", "method_colour", "symmetric_limit"]
