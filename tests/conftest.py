"""Shared test configuration: hypothesis profiles and the statistical tolerance."""

from __future__ import annotations

import os
import re

import matplotlib
from hypothesis import HealthCheck, settings

matplotlib.use("Agg")

# deadline=None: forward-mode rules on arrays have no meaningful per-example time budget.
settings.register_profile("dev", deadline=None, max_examples=60)
# CI: fixed examples (derandomized), fewer of them: the forward-mode rules of test_dual alone are
# 83 properties, and CI has 2 slow cores for the whole suite; `HYPOTHESIS_PROFILE=dev` runs 60.
settings.register_profile(
    "ci",
    deadline=None,
    max_examples=5,
    derandomize=True,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE") or ("ci" if os.environ.get("CI") else "dev"))


NOTEBOOK = re.compile(r"tests/test_tutorials\.py::TestNotebook(\d+)")


def pytest_collection_modifyitems(config, items):
    """The tutorial notebooks first, the last tutorial first: they are the suite's longest tests
    (the sphere3d and study tutorials at the end of the course the longest), and pytest-xdist hands
    out test classes in collection order, so the workers run them while the short tests fill in
    around them instead of one worker running the last notebook alone at the end."""

    def notebooks_first(item):
        match = NOTEBOOK.match(item.nodeid)
        return (0, -int(match[1])) if match else (1, 0)

    items.sort(key=notebooks_first)  # stable: every other test keeps its place
