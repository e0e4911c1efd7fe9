"""The image gradient methods, one module each, registered in :data:`GRADIENT_METHODS`.

Data flow of :meth:`~flatland.tasks.ImageTask.evaluate`, where the methods'
:class:`~flatland.integrator.Transforms` come in: primary samples ->
``Transforms.camera`` (film evaluation points) -> radiance along the film -> in
:func:`~flatland.integrator.shade`, ``Transforms.directions`` (direction evaluation
points), then ``Transforms.shading_extra`` -> per-batch, per-pixel sums ->
``Transforms.pixel_extra`` (the two extras: 2D only). A
:class:`~flatland.tasks.PointTask` skips the camera step. Each module's docstring
says which of these it changes; the guide ``docs/guides/add_image_method.md`` says
how to add a method.

==========================  ===========================================================
:mod:`.naive`               differentiate the estimator (Loubet et al. 2019, Sec. 3.1)
:mod:`.finite_difference`   central differences with common random numbers
:mod:`.boundary`            interior term + exact discontinuity terms (edge sampling)
:mod:`.reparam`             translations chosen by probe rays, convolution kernels
==========================  ===========================================================

Each is called as ``func(task, **options) -> Tally`` by :mod:`flatland.render`.
"""

from flatland.methods import boundary, finite_difference, naive, reparam
from flatland.methods._common import GRADIENT_METHODS

__all__ = ["GRADIENT_METHODS", "boundary", "finite_difference", "naive", "reparam"]
