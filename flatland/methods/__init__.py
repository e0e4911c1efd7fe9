"""The image gradient methods, one module each, registered in :data:`flatland.integrator.GRADIENT_METHODS`.

Data flow of :func:`flatland.integrator.run`, where the methods' hooks come in:
primary samples -> ``Hooks.film`` (film evaluation points) -> radiance along the film
-> in :func:`~flatland.integrator.shade`, ``Hooks.directions`` (direction evaluation
points), then ``Hooks.shading_extra`` -> per-batch, per-pixel sums ->
``Hooks.pixel_extra``. Each module's docstring says which of these it changes; the
guide ``docs/guides/add_image_method.md`` says how to add a method.

==========================  ===========================================================
:mod:`.naive`               differentiate the estimator (Loubet et al. 2019, Sec. 3.1)
:mod:`.finite_difference`   central differences with common random numbers
:mod:`.boundary`            interior term + exact discontinuity terms (edge sampling)
:mod:`.reparam`             translations chosen by probe rays, convolution kernels
==========================  ===========================================================

Each is called as ``func(job, **options) -> BatchResult`` by :mod:`flatland.render`.
"""

from flatland.methods import boundary, finite_difference, naive, reparam

__all__ = ["boundary", "finite_difference", "naive", "reparam"]
