"""The suite's two tiers.

``make test`` runs every test but those marked ``slow``; ``make test-all`` runs them all. ``make test``
is what CI runs, on 2 shared cores that can be 20-40 times slower than a desk machine, within a
fixed time that also pays for the install and the docs build, so it is a budget: each statistical
sweep keeps representative cases (the rest of the sweep, more scenes, parameters, sizes at the same
statistical level, is slow), and a check that costs minutes there (a whole CLI run in a subprocess,
a reference image, a second estimator on the same closed form) is slow when a cheaper test in
``make test`` runs the same code path. The tutorials run in ``make test``, and hand their outputs
to ``make docs``.
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
