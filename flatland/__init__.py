"""flatland: differentiating discontinuous integrals in 2D, a reference for Loubet et al. 2019.

Textbook 1D integrals (:mod:`flatland.integrals`) with the four estimators of
:mod:`flatland.textbook` behind :func:`estimate`; 2D scenes (:mod:`flatland.scene`)
rendered with :func:`render` and differentiated with :func:`render_gradient` by the
same four methods (:mod:`flatland.methods`); parameters recovered from target images with
:func:`optimize` (:mod:`flatland.optimize`); all on forward-mode AD (:mod:`flatland.core`).

The names below are imported on first use (PEP 562), so ``import flatland.core.dual``
or ``import sphere3d`` loads the numeric kernel :mod:`flatland.core` without the 2D
renderer.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from flatland.core import (
        Dual,
        Estimate,
        GradientImage,
        GradientImages,
        Image,
        ValidationError,
        detach,
        relative_error,
        tangent,
        variable,
    )
    from flatland.integrals import INTEGRALS, get_integral
    from flatland.optimize import optimize
    from flatland.render import GRADIENT_METHODS, irradiance, render, render_gradient
    from flatland.scene import Scene, list_scenes, load_scene
    from flatland.textbook import METHODS, estimate

_SOURCES = {
    "flatland.core": (
        "Dual", "Estimate", "GradientImage", "GradientImages", "Image", "ValidationError", "detach",
        "relative_error", "tangent", "variable",
    ),
    "flatland.textbook": ("METHODS", "estimate"),
    "flatland.integrals": ("INTEGRALS", "get_integral"),
    "flatland.optimize": ("optimize",),
    "flatland.render": ("GRADIENT_METHODS", "irradiance", "render", "render_gradient"),
    "flatland.scene": ("Scene", "list_scenes", "load_scene"),
}  # fmt: skip
_SOURCE = {name: module for module, names in _SOURCES.items() for name in names}
"""The module each public name is imported from on first use."""

__all__ = [
    "GRADIENT_METHODS",
    "INTEGRALS",
    "METHODS",
    "Dual",
    "Estimate",
    "GradientImage",
    "GradientImages",
    "Image",
    "Scene",
    "ValidationError",
    "detach",
    "estimate",
    "get_integral",
    "irradiance",
    "list_scenes",
    "load_scene",
    "optimize",
    "relative_error",
    "render",
    "render_gradient",
    "tangent",
    "variable",
]

__version__ = "0.1.0"


def __getattr__(name: str) -> Any:
    """A public name, imported from its module on first use and kept as a module attribute."""
    module = _SOURCE.get(name)
    if module is None:
        raise AttributeError(f"module 'flatland' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    """The public names (and ``__version__``), imported or not: not the submodules or helpers (tab completion
    offers what :data:`__all__` promises)."""
    return sorted([*__all__, "__version__"])


class _Flatland(types.ModuleType):
    """The package module: a public name its submodule shares (``render``) stays the function."""

    def __setattr__(self, name: str, value: Any) -> None:
        # importing flatland.render sets the attribute ``render`` to the submodule, which would shadow
        # the function ``flatland.render``; the function is kept instead, as when it was imported eagerly
        if isinstance(value, types.ModuleType) and value.__name__ == _SOURCE.get(name):
            value = getattr(value, name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Flatland
