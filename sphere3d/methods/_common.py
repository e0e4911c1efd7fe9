"""The method table of sphere3d: every gradient method maps a task to a :class:`~sphere3d.tasks.Tally`.

Each method module registers here; :mod:`sphere3d.methods` imports them in listing order.
"""

from __future__ import annotations

from flatland.core.contract import MethodTable

__all__ = ["GRADIENT_METHODS"]

GRADIENT_METHODS = MethodTable("gradient method")
"""Gradient methods by name: ``func(task, **options) -> Tally`` (see :mod:`flatland.core.contract`)."""
