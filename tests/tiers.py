"""The suite's two tiers.

``make test`` runs every test but those marked ``slow``: each property is checked, each statistical
sweep on representative cases. ``make test-all`` adds the ``slow`` ones: the remaining cases of the
sweeps (more scenes, parameters, sizes at the same statistical level) and the long runs. A case is
marked slow when it costs several times its sweep's representative case and checks the same code
path. The tutorials run in ``make test``, and hand their outputs to ``make docs``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import pytest

SLOW = pytest.mark.slow

HANG = 1800
"""Seconds after which a test's subprocess (a CLI command, a notebook cell) counts as hung: a guard,
not a speed requirement (speed is measured by ``make bench``), wide enough for slow shared machines."""


def sweep(cases: Iterable[Any], fast: Sequence[Any]) -> list[Any]:
    """``cases`` for ``pytest.mark.parametrize``; those not in ``fast`` are marked slow."""
    cases = list(cases)
    missing = [c for c in fast if c not in cases]
    assert not missing, f"fast cases not in the sweep: {missing}"
    return [
        c if c in fast else pytest.param(*(c if isinstance(c, tuple) else (c,)), marks=SLOW) for c in cases
    ]
