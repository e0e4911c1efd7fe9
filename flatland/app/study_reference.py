"""The reference a study is measured against: a closed form, or a high-sample Monte Carlo run cached on disk.

An integral's reference is its closed-form derivative. A scene's is a run of the
configured reference method (``boundary``, or ``finite_difference`` where the package
has no boundary method) at a high sample count, cached as ``<cache_dir>/<hash>.npz``
where the hash covers the sources it depends on, the problem (scene content included),
the method, its options, the sample count and the seed. The file holds the derivative
image, its per-pixel standard errors and the studied scalar's standard error (for the
film sum, from the per-batch sums: the pixels' errors may be correlated).
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import tempfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from flatland.app.study_config import Cell, Problem, ReferenceSpec, StudyConfig
from flatland.app.study_trials import _Calls, _functional, _load_scene, _run_one
from flatland.app.table import method_label
from flatland.core import progress as _progress

if TYPE_CHECKING:
    from flatland.app.cli import Package

__all__ = ["Reference", "resolve_reference"]

CACHE_VERSION = 2


# ------------------------------------------------------------------------------------------- reference
@dataclass(frozen=True)
class Reference:
    """The reference derivative the cells are compared with.

    ``image``/``image_stderr`` hold the reference gradient image for scene problems
    (None for integrals); ``source`` says where the numbers come from.
    """

    derivative: float
    stderr: float
    source: str
    image: np.ndarray | None = None
    image_stderr: np.ndarray | None = None
    n: int | None = None


@lru_cache(maxsize=1)
def _code_digest(root: Path) -> str:
    """Hash of the Python sources a computation depends on (the package's folder ``root``, flatland's
    core and this application layer)."""
    roots = {root, Path(__file__).parent, Path(__file__).parent.parent / "core"}
    h = hashlib.sha256()
    for root in sorted(roots):
        for path in sorted(root.rglob("*.py")):
            h.update(str(path.relative_to(root.parent)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()


def _package_root(package: Package) -> Path:
    """The folder of the package whose ``render_gradient`` the description holds."""
    top = package.render_gradient.__module__.partition(".")[0]
    return Path(sys.modules[top].__file__).parent


def _scene_fingerprint(package: Package, problem: Problem) -> Any:
    """The scene's content: its ``to_dict()`` if it has one, else the file's bytes' hash, else its name."""
    scene = _load_scene(package.load_scene, problem.scene)
    if hasattr(scene, "to_dict"):
        return scene.to_dict()
    if Path(problem.scene).is_file():
        return hashlib.sha256(Path(problem.scene).read_bytes()).hexdigest()
    return problem.scene


def _cache_key(package: Package, problem: Problem, spec: ReferenceSpec) -> str:
    payload = {
        "version": CACHE_VERSION,
        "code": _code_digest(_package_root(package)),
        "package": problem.package,
        "integral": problem.integral,
        "theta": problem.theta,
        "scene": _scene_fingerprint(package, problem) if problem.is_scene else None,
        "param": problem.param,
        "method": spec.method,
        "options": [[k, v] for k, v in spec.options],
        "n": spec.n,
        "seed": spec.seed,
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=repr).encode()).hexdigest()[:32]


def _compute_reference(
    calls: _Calls, problem: Problem, spec: ReferenceSpec, progress: bool | None = None
) -> tuple[np.ndarray, np.ndarray, float]:
    """(derivative, derivative_stderr) arrays of one high-sample run and the standard error of the
    scalar studied (:func:`~flatland.app.study_trials._functional_stderr`), with its own progress bar
    (:mod:`flatland.core.progress`)."""
    cell = Cell(-1, spec.method, spec.options, spec.n)
    with _progress.run(f"reference {cell.label}", progress):
        run = _run_one(calls, problem, cell, spec.seed)
    return np.asarray(run.derivative_image), np.asarray(run.stderr_image), run.derivative_stderr


def resolve_reference(
    config: StudyConfig, cache_dir: str | os.PathLike | None = None, progress: bool | None = None
) -> Reference:
    """The study's reference: the closed form, or a Monte Carlo run (read from / written to the cache).

    ``progress``: a progress bar while a Monte Carlo reference is computed (None: when stderr is a
    terminal, :mod:`flatland.core.progress`).

    The cache file is ``<cache_dir>/<hash>.npz`` where the hash covers the package's
    source code, the problem (scene file content included), the method, its options,
    the sample count and the seed; it is written atomically.
    """
    problem, spec = config.problem, config.reference
    if spec is None:
        integral = config.package.integrals[problem.integral]
        return Reference(float(integral.derivative(problem.theta)), 0.0, "closed form")
    label = f"{method_label(spec.method, spec.options)} {problem.count_name}={spec.n} seed={spec.seed}"
    path = (
        Path(cache_dir) / f"{_cache_key(config.package, problem, spec)}.npz"
        if cache_dir is not None
        else None
    )
    if path is not None and path.is_file():
        with np.load(path) as data:
            derivative, stderr = data["derivative"], data["stderr"]
            scalar_stderr = float(data["scalar_stderr"])
        label += " (cached)"
    else:
        derivative, stderr, scalar_stderr = _compute_reference(
            _Calls.of(config.package), problem, spec, progress
        )
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp.npz")
            with os.fdopen(fd, "wb") as f:
                np.savez(f, derivative=derivative, stderr=stderr, scalar_stderr=scalar_stderr)
            os.replace(tmp, path)
    if not problem.is_scene:
        return Reference(float(derivative), scalar_stderr, label, n=spec.n)
    return Reference(_functional(problem, derivative), scalar_stderr, label, derivative, stderr, spec.n)
