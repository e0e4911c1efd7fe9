"""flatland: differentiating discontinuous integrals in 2D, a reference for Loubet et al. 2019.

Textbook 1D integrals (:mod:`flatland.integrals`) with the four estimators of
:mod:`flatland.textbook` behind :func:`estimate`; 2D scenes (:mod:`flatland.scene`)
rendered with :func:`render` and differentiated with :func:`render_gradient` by the
same four methods (:mod:`flatland.methods`); all on forward-mode AD (:mod:`flatland.core`).
"""

from flatland.core import (
    Dual,
    Estimate,
    GradientImage,
    Image,
    ValidationError,
    detach,
    relative_error,
    tangent,
    variable,
)
from flatland.integrals import INTEGRALS, get_integral
from flatland.render import GRADIENT_METHODS, irradiance, render, render_gradient
from flatland.scene import Scene, list_scenes, load_scene
from flatland.textbook import METHODS, estimate

__all__ = [
    "GRADIENT_METHODS",
    "INTEGRALS",
    "METHODS",
    "Dual",
    "Estimate",
    "GradientImage",
    "Image",
    "Scene",
    "ValidationError",
    "detach",
    "estimate",
    "get_integral",
    "irradiance",
    "list_scenes",
    "load_scene",
    "relative_error",
    "render",
    "render_gradient",
    "tangent",
    "variable",
]

__version__ = "0.1.0"
