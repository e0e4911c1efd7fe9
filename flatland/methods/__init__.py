"""The image gradient methods, one module each, registered in :data:`flatland.integrator.GRADIENT_METHODS`.

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
