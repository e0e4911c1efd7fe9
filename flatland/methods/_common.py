"""The method table of flatland: every image gradient method maps a task to a :class:`~flatland.tasks.Tally`.

Each method module registers here; :mod:`flatland.methods` imports them in listing order.
"""

from __future__ import annotations

from flatland.core.contract import MethodTable

__all__ = ["GRADIENT_METHODS"]

GRADIENT_METHODS = MethodTable("gradient method")
"""Image gradient methods by name: ``func(task, **options) -> Tally`` (see :mod:`flatland.core.contract`)."""
