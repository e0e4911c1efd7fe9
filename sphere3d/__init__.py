"""sphere3d: differentiating rendering integrals on the sphere S², a reference for Loubet et al. 2019.

The same API as flatland's renderer, in 3D: triangle meshes traced with Embree and
re-attached to θ with forward-mode Duals (:mod:`sphere3d.tracing`), rotations as the
change of variables (:mod:`sphere3d.rotation`), von Mises–Fisher kernels
(:mod:`sphere3d.sampling`), and the gradient methods ``naive``,
``finite_difference``, ``reparam`` and ``boundary`` (:mod:`sphere3d.methods`)::

    import sphere3d as s3

    g = s3.render_gradient("shadow", "occluder.translate.x", method="reparam", spp=64)
    g.derivative, g.derivative_stderr      # (height, width) arrays
"""

from flatland.core import Dual, Estimate, GradientImage, Image, detach, relative_error, variable
from sphere3d.optimize import optimize, render_targets
from sphere3d.render import GRADIENT_METHODS, irradiance, render, render_gradient
from sphere3d.scene import list_scenes, load_scene

__all__ = [
    "GRADIENT_METHODS",
    "Dual",
    "Estimate",
    "GradientImage",
    "Image",
    "detach",
    "irradiance",
    "list_scenes",
    "load_scene",
    "optimize",
    "relative_error",
    "render",
    "render_gradient",
    "render_targets",
    "variable",
]

__version__ = "0.1.0"


def __dir__() -> list[str]:
    """The public names (and ``__version__``): not the submodules, which stay importable by name."""
    return sorted([*__all__, "__version__"])
