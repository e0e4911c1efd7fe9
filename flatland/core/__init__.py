"""Dimension-free numeric kernel shared by flatland and sphere3d (numpy and scipy only).

Forward-mode AD (:class:`Dual`, :func:`detach`; k tangents at once with :func:`variables`),
named results (:class:`Estimate`, :class:`Image`, :class:`GradientImage`,
:class:`GradientImages`), the estimator contract
(:class:`MethodTable`, :class:`Option`), statistics and input validation.
"""

from flatland.core.contract import Estimate, MethodTable, Option
from flatland.core.dual import Dual, as_dual, detach, is_dual, tangent, variable, variables
from flatland.core.dual_functions import SUPPORTED_FUNCTIONS
from flatland.core.image import GradientImage, GradientImages, Image, relative_error
from flatland.core.rng import stream
from flatland.core.validate import ValidationError

__all__ = [
    "SUPPORTED_FUNCTIONS",
    "Dual",
    "Estimate",
    "GradientImage",
    "GradientImages",
    "Image",
    "MethodTable",
    "Option",
    "ValidationError",
    "as_dual",
    "detach",
    "is_dual",
    "relative_error",
    "stream",
    "tangent",
    "variable",
    "variables",
]
