"""Gradient methods of sphere3d, one module each, registered in :data:`GRADIENT_METHODS`.

Data flow of :meth:`~sphere3d.tasks.ImageTask.evaluate`, where the methods'
:class:`~sphere3d.integrator.Transforms` come in: primary samples ->
``Transforms.camera`` (one rotation per batch and pixel) -> camera rays and the filter
weight -> at each diffuse hit, ``Transforms.emitter`` (the emitter-sampling strategy)
and ``Transforms.bsdf`` (the cosine-sampled strategy, estimated by the method) -> the
per-batch means. A :class:`~sphere3d.tasks.PointTask` skips the camera step. Each
module's docstring says which of these it changes; the guide
``docs/guides/add_image_method.md`` says how to add a method.

========================  =====================================================
``naive``                 differentiate the renderer (biased at moving edges)
``finite_difference``     central difference of renders, common random numbers,
                          option ``h``
``boundary``              edge sampling (Li et al. 2018): naive plus the
                          boundary terms of the pixel integrals
                          (:mod:`sphere3d.boundary.camera`) and of the shading
                          integrals (:mod:`sphere3d.boundary.shading`; on paths
                          :mod:`sphere3d.boundary.indirect`); options
                          ``rate``, ``secondary``, ``indirect``
``reparam``               rotations chosen by probe rays, vMF convolution;
                          options ``kappa``, ``probes``, ``spread``,
                          ``refine``, ``paired``
========================  =====================================================
"""

# importing registers the method; the table lists them in flatland.core.contract.METHOD_ORDER
from sphere3d.methods import naive as _naive  # noqa: F401, I001  (importing registers the method)
from sphere3d.methods import finite_difference as _finite_difference  # noqa: F401
from sphere3d.methods import reparam as _reparam  # noqa: F401
from sphere3d.methods import boundary as _boundary  # noqa: F401
from sphere3d.methods._common import GRADIENT_METHODS

__all__ = ["GRADIENT_METHODS"]
