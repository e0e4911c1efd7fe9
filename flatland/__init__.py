"""flatland: differentiating discontinuous integrals in 2D, a reference for Loubet et al. 2019.

Textbook 1D integrals (:mod:`flatland.integrals`) with the four estimators behind
:func:`estimate`, on forward-mode AD (:mod:`flatland.core`).
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
from flatland.estimators import METHODS, estimate
from flatland.integrals import INTEGRALS, get_integral

__all__ = [
    "INTEGRALS",
    "METHODS",
    "Dual",
    "Estimate",
    "GradientImage",
    "Image",
    "ValidationError",
    "detach",
    "estimate",
    "get_integral",
    "relative_error",
    "tangent",
    "variable",
]

__version__ = "0.1.0"
