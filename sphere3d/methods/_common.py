"""The method table of sphere3d: every gradient method maps a task to a :class:`~sphere3d.tasks.Tally`.

Each method module registers here; :mod:`sphere3d.methods` imports them in listing order. A method
whose options change what it allocates or traces also registers its memory model
(:func:`memory_model`): one function of the task and the resolved options returning the terms
(:class:`~flatland.core.budget.Term`) that :func:`sphere3d.render.render_gradient` checks before
any work starts (:mod:`flatland.core.budget`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from flatland.core.budget import Term
from flatland.core.contract import MethodTable
from flatland.core.validate import ValidationError

__all__ = ["GRADIENT_METHODS", "MEMORY_MODELS", "direct_only", "memory_model"]

GRADIENT_METHODS = MethodTable("gradient method")
"""Gradient methods by name: ``func(task, **options) -> Tally`` (see :mod:`flatland.core.contract`)."""

MemoryModel = Callable[[Any, Mapping[str, Any]], tuple[Term, ...]]
MEMORY_MODELS: dict[str, MemoryModel] = {}
"""Memory models by method name: ``model(task, options) -> terms``; a method without one costs its
rays (:func:`~flatland.core.budget.rays_per_sample`) and nothing more."""


def memory_model(name: str) -> Callable[[MemoryModel], MemoryModel]:
    """Decorator registering ``model`` as the memory model of method ``name``."""

    def decorate(model: MemoryModel) -> MemoryModel:
        MEMORY_MODELS[name] = model
        return model

    return decorate


def direct_only(task: Any, method: str, missing: str) -> None:
    """Refuse paths (``task.max_depth`` > 1, :mod:`sphere3d.paths`) for a method whose ``missing`` exist at
    vertex 1 only (diffuse or glossy, :mod:`sphere3d.glossy`)."""
    if task.max_depth > 1:
        raise ValidationError(
            "max_depth",
            f"must be 1 for method {method!r} (not yet supported on paths: its {missing} at vertices "
            f"beyond the first are not implemented; naive and finite_difference take any depth), "
            f"got {task.max_depth!r}",
        )
