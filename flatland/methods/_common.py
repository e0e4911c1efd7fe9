"""The method table of flatland: every image gradient method maps a task to a :class:`~flatland.tasks.Tally`.

Each method module registers here; :mod:`flatland.methods` imports them in listing order.
"""

from __future__ import annotations

from typing import Any

from flatland.core.contract import MethodTable
from flatland.core.validate import ValidationError

__all__ = ["GRADIENT_METHODS", "direct_only"]

GRADIENT_METHODS = MethodTable("gradient method")
"""Image gradient methods by name: ``func(task, **options) -> Tally`` (see :mod:`flatland.core.contract`)."""


def direct_only(task: Any, method: str, missing: str) -> None:
    """Refuse paths (``task.max_depth`` > 1) for a method whose ``missing`` exist at vertex 1 only."""
    if task.max_depth > 1:
        raise ValidationError(
            "max_depth",
            f"must be 1 for method {method!r} (not yet supported on paths: its {missing} at vertices "
            f"beyond the first are not implemented; naive and finite_difference take any depth), "
            f"got {task.max_depth!r}",
        )
