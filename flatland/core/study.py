"""Study runner: a grid of methods × options × independent trials, measured against a reference.

A study answers "how biased, how noisy and how fast is each estimator here?" for one
scalar derivative dI/dθ, the numbers behind the bias/variance trade-off of the
convolution kernel (Loubet et al. 2019, Sec. 4.2; DESIGN 2.7) and behind equal-time
comparisons of the methods.

Problems
--------
``{"integral": "two_steps", "theta": 1.0}``
    A textbook integral of :mod:`flatland.integrals`, run through
    :func:`flatland.estimate`; the reference is its closed-form derivative.
``{"scene": "shadow", "param": "occluder.translate.x"}``
    A scene of the package (``flatland`` or ``sphere3d``), run through its
    ``render_gradient``. The scalar studied is a linear functional of the gradient
    image: by default (``"functional": "sum"``) the sum over all pixels, i.e. the
    derivative of the image's total brightness d/dθ Σ_j I_j; with
    ``"pixel": j`` (flatland) or ``"pixel": [row, col]`` (sphere3d) the derivative
    of that one pixel. The per-pixel error is reported as well, as the image error
    metric :func:`~flatland.core.image.relative_error` averaged over the trials.
    The reference is a high-sample run of ``boundary`` (``finite_difference`` where
    the package has no boundary method), cached on disk by a hash of its inputs.

Cells and trials
----------------
Each entry of ``"methods"`` names a method and its options; any option (``kappa``,
``probes``, ``paired``, ``h``, ...) and the sample count (``"n"`` for integrals, ``"spp"``
for scenes) may be a list, and the entry expands to the Cartesian product: one
:class:`Cell` per combination, numbered in order. Trial ``k`` of cell ``c`` runs
with the seed :func:`trial_seed` ``(seed, c, k)``, a function of those three numbers
only, so the same study gives identical estimates serially (``workers=1``), in
worker processes (``workers=2``) or on a Dask cluster (``scheduler=address``); only
the measured times differ.

Statistics per cell (T trials of ``samples`` integrand evaluations each)
------------------------------------------------------------------------
``mean_derivative``      mean of the T trial estimates
``bias``                 mean - reference, with a Student-t interval (T - 1 degrees
                         of freedom) of half-width t · sqrt(s²/T + s_ref²) (plus a
                         floating-point allowance of 64 ε |reference|; a spread of
                         the trials below that counts as zero variance)
``variance_per_sample``  s² · samples (s² the variance of the trial estimates), the
                         variance a single-sample estimate would have
``seconds_per_sample``   measured wall time (time.perf_counter) / (T · samples)
``rmse``                 sqrt(mean_k (d_k - reference)²): the error of one trial
``efficiency``           1 / (variance_per_sample · seconds_per_sample); infinite for
                         a zero-variance estimator
``equal_time_rmse``      sqrt(bias² + variance_per_sample · seconds_per_sample / B):
                         the error expected from a time budget of B seconds
                         (``"time_budget"``, default 1 s), which unlike efficiency
                         counts the bias
For scenes a "sample" is one camera sample: spp × pixels.

Example configuration (JSON)::

    {"name": "kappa", "problem": {"integral": "two_steps", "theta": 1.0},
     "methods": [{"method": "boundary"},
                 {"method": "reparam", "kappa": [1, 10, 100, 1000, 10000]}],
     "n": 50000, "trials": 20, "seed": 3, "level": 0.99}
"""

from __future__ import annotations

import copy
import csv
import hashlib
import importlib
import itertools
import json
import math
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from flatland.core.table import format_table
from flatland.core.validate import (
    ValidationError,
    check_choice,
    check_finite,
    check_int,
    check_positive,
    check_seed,
)

__all__ = [
    "CSV_COLUMNS",
    "Cell",
    "CellResult",
    "Problem",
    "Reference",
    "ReferenceSpec",
    "StudyConfig",
    "StudyResult",
    "load_config",
    "read_csv",
    "resolve_reference",
    "run_study",
    "trial_seed",
]

OPTION_COLUMNS = ("kappa", "probes", "paired", "h")
"""Method options that get their own CSV column (others are written to ``options``)."""

CSV_COLUMNS = (
    "cell", "problem", "method", "label", *OPTION_COLUMNS, "options", "n", "samples", "trials", "seed",
    "reference", "reference_stderr", "mean_derivative", "stderr", "bias", "bias_low", "bias_high", "level",
    "variance_per_sample", "seconds_per_sample", "rmse", "efficiency", "equal_time_rmse", "time_budget",
    "relative_error", "mean_value",
)  # fmt: skip
"""Columns of the study CSV, in order."""

CACHE_VERSION = 1
_ROUNDING = 64 * np.finfo(np.float64).eps  # relative size of floating-point noise in a mean of many terms
_TOP_KEYS = ("name", "problem", "methods", "n", "spp", "trials", "seed", "workers", "scheduler", "level",
             "reference", "time_budget")  # fmt: skip
_PROBLEM_KEYS = ("integral", "theta", "scene", "param", "functional", "pixel")
_REFERENCE_KEYS = ("method", "n", "spp", "seed")


# ------------------------------------------------------------------------------------------ configuration
@dataclass(frozen=True)
class Problem:
    """What is differentiated: a textbook integral at ``theta`` or a scene parameter ``param``.

    ``pixel`` is None for the sum over the image (scene problems) and otherwise the
    index of the pixel studied.
    """

    package: str
    integral: str | None = None
    theta: float | None = None
    scene: str | None = None
    param: str | None = None
    pixel: tuple[int, ...] | None = None

    @property
    def is_scene(self) -> bool:
        """True for a scene problem, False for a textbook integral."""
        return self.scene is not None

    @property
    def label(self) -> str:
        """Short description, e.g. ``two_steps@theta=1.0`` or ``shadow:occluder.translate.x``."""
        if not self.is_scene:
            return f"{self.integral}@theta={self.theta!r}"
        where = "" if self.pixel is None else "[" + ",".join(map(str, self.pixel)) + "]"
        return f"{Path(self.scene).stem}:{self.param}{where}"

    @property
    def count_name(self) -> str:
        """The name of the per-trial sample count: ``n`` (integrals) or ``spp`` (scenes)."""
        return "spp" if self.is_scene else "n"


@dataclass(frozen=True)
class Cell:
    """One point of the grid: a method, its (validated, defaults filled) options and a sample count.

    ``given`` names the options the configuration set (the label shows only those).
    """

    index: int
    method: str
    options: tuple[tuple[str, Any], ...]
    n: int
    given: tuple[str, ...] = ()

    @property
    def options_dict(self) -> dict[str, Any]:
        """The options as a dict."""
        return dict(self.options)

    @property
    def label(self) -> str:
        """``method`` plus the options the configuration set, e.g. ``reparam kappa=100 paired``."""
        parts = [self.method]
        for k, v in self.options:
            if k not in self.given or v is None or v is False:
                continue
            parts.append(k if v is True else f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}")
        return " ".join(parts)


@dataclass(frozen=True)
class ReferenceSpec:
    """How to compute a Monte Carlo reference: method, options, sample count and seed."""

    method: str
    options: tuple[tuple[str, Any], ...]
    n: int
    seed: int


@dataclass(frozen=True)
class StudyConfig:
    """A validated study: problem, grid of cells, trials, seed and execution settings."""

    name: str
    problem: Problem
    cells: tuple[Cell, ...]
    trials: int
    seed: int
    workers: int = 1
    scheduler: str | None = None
    level: float = 0.95
    time_budget: float = 1.0
    reference: ReferenceSpec | None = None

    @classmethod
    def from_dict(
        cls,
        data: Any,
        *,
        package: str = "flatland",
        base_dir: str | os.PathLike | None = None,
        name: str = "study",
    ) -> StudyConfig:
        """Validate a configuration dict (the JSON file's content); errors name the field.

        Scene paths are resolved relative to ``base_dir`` (the config file's folder).
        """
        if not isinstance(data, Mapping):
            raise ValidationError("config", f"must be a JSON object, got {type(data).__name__}")
        _reject_unknown("", data, _TOP_KEYS)
        name = data.get("name", name)
        if not isinstance(name, str) or not name or any(c in name for c in "/\\"):
            raise ValidationError("name", f"must be a non-empty file-name-safe string, got {name!r}")
        problem = _parse_problem(data.get("problem"), package, base_dir)
        count = problem.count_name
        other = "n" if count == "spp" else "spp"
        if other in data:
            kind = "scene" if problem.is_scene else "integral"
            raise ValidationError(other, f"{kind} problems take {count!r} (samples per trial), not {other!r}")
        default_n = check_int(count, data[count]) if count in data else None
        cells = _expand_cells(data.get("methods"), problem, default_n)
        trials = check_int("trials", data.get("trials", 10), minimum=2)
        seed = check_seed("seed", data.get("seed", 0))
        workers = check_int("workers", data.get("workers", 1))
        scheduler = data.get("scheduler")
        if scheduler is not None and (not isinstance(scheduler, str) or not scheduler):
            raise ValidationError("scheduler", f"must be a scheduler address string, got {scheduler!r}")
        level = check_finite("level", data.get("level", 0.95))
        if not 0.0 < level < 1.0:
            raise ValidationError("level", f"must lie in (0, 1), got {level!r}")
        time_budget = check_positive("time_budget", data.get("time_budget", 1.0))
        reference = _parse_reference(data.get("reference"), problem, cells)
        return cls(name, problem, cells, trials, seed, workers, scheduler, level, time_budget, reference)


def load_config(
    source: str | os.PathLike | Mapping[str, Any],
    *,
    package: str = "flatland",
    seed: int | None = None,
    samples: int | None = None,
    name: str | None = None,
) -> StudyConfig:
    """Read and validate a study configuration: a JSON file (its stem is the default name) or a dict.

    ``seed`` replaces the configuration's seed; ``samples`` replaces every sample
    count of the grid (``n`` or ``spp``, swept or not) with one value.
    """
    if isinstance(source, Mapping):
        data: Any = copy.deepcopy(dict(source))
        base_dir = None
        name = name or "study"
    else:
        path = Path(source)
        text = path.read_text(encoding="utf-8")
        try:
            data = json.loads(text)
        except json.JSONDecodeError as e:
            where = f"line {e.lineno}, column {e.colno}"
            raise ValidationError(str(path), f"invalid JSON: {e.msg} ({where})") from None
        base_dir, name = path.parent, name or path.stem
    if isinstance(data, dict):
        if seed is not None:
            data["seed"] = seed
        if samples is not None:
            count = "spp" if isinstance(data.get("problem"), dict) and "scene" in data["problem"] else "n"
            data[count] = samples
            for entry in data.get("methods") or ():
                if isinstance(entry, dict):
                    entry.pop(count, None)
            if isinstance(data.get("reference"), dict):
                data["reference"].pop(count, None)  # back to its default, 16 × the cells' count
    return StudyConfig.from_dict(data, package=package, base_dir=base_dir, name=name)


def _reject_unknown(prefix: str, data: Mapping[str, Any], known: Iterable[str]) -> None:
    known = tuple(known)
    for key in data:
        if key not in known:
            where = f"{prefix}.{key}" if prefix else str(key)
            raise ValidationError(where, f"unknown key; expected one of {', '.join(known)}")


def _parse_problem(data: Any, package: str, base_dir: Any) -> Problem:
    if not isinstance(data, Mapping):
        raise ValidationError("problem", f"must be an object with 'integral' or 'scene', got {data!r}")
    _reject_unknown("problem", data, _PROBLEM_KEYS)
    if ("integral" in data) == ("scene" in data):
        raise ValidationError("problem", "must name exactly one of 'integral' and 'scene'")
    if "integral" in data:
        from flatland.integrals import INTEGRALS

        for key in ("param", "functional", "pixel"):
            if key in data:
                raise ValidationError(f"problem.{key}", "applies to scene problems only")
        integral = INTEGRALS[check_choice("problem.integral", data["integral"], INTEGRALS)]
        theta = integral.check_theta(data.get("theta", integral.default_theta), "problem.theta")
        return Problem(package, integral=integral.name, theta=theta)
    if "theta" in data:
        raise ValidationError("problem.theta", "applies to integral problems only (scenes take 'param')")
    scene = data["scene"]
    if not isinstance(scene, str) or not scene:
        raise ValidationError("problem.scene", f"must be a scene name or a JSON file path, got {scene!r}")
    if base_dir is not None and not Path(scene).is_absolute() and (Path(base_dir) / scene).is_file():
        scene = str(Path(base_dir) / scene)
    param = data.get("param")
    if not isinstance(param, str) or not param:
        raise ValidationError("problem.param", f"must name a scene parameter, got {param!r}")
    functional = data.get("functional", "pixel" if "pixel" in data else "sum")
    check_choice("problem.functional", functional, ("sum", "pixel"))
    pixel = None
    if functional == "pixel":
        raw = data.get("pixel")
        raw = [raw] if not isinstance(raw, list | tuple) else raw
        if not raw:
            raise ValidationError("problem.pixel", "must be an index or a list of indices")
        pixel = tuple(check_int(f"problem.pixel[{i}]", v, minimum=0) for i, v in enumerate(raw))
    return Problem(package, scene=scene, param=param, pixel=pixel)


def _method_table(problem: Problem) -> Any:
    if not problem.is_scene:
        from flatland.estimators import METHODS

        return METHODS
    return importlib.import_module(f"{problem.package}.render").GRADIENT_METHODS


def _resolve(table: Any, where: str, method: Any, options: Mapping[str, Any]) -> tuple[str, dict[str, Any]]:
    """Method name and validated options, errors re-labelled with the config path ``where``."""
    try:
        spec = table.get(method)
        return spec.name, table.resolve_options(spec.name, options)
    except ValidationError as e:
        message = str(e)[len(e.field) + 2 :] if e.field else str(e)
        raise ValidationError(f"{where}.{e.field}" if e.field else where, message) from None


def _expand_cells(data: Any, problem: Problem, default_n: int | None) -> tuple[Cell, ...]:
    if not isinstance(data, list | tuple) or not data:
        raise ValidationError(
            "methods", f"must be a non-empty list of {{'method': ...}} objects, got {data!r}"
        )
    table = _method_table(problem)
    count = problem.count_name
    cells: list[Cell] = []
    for i, entry in enumerate(data):
        where = f"methods[{i}]"
        if not isinstance(entry, Mapping) or "method" not in entry:
            raise ValidationError(where, f"must be an object with a 'method' key, got {entry!r}")
        other = "n" if count == "spp" else "spp"
        if other in entry:
            raise ValidationError(f"{where}.{other}", f"this problem takes {count!r}, not {other!r}")
        sweeps = {k: v for k, v in entry.items() if k != "method"}
        if count not in sweeps:
            if default_n is None:
                raise ValidationError(count, f"missing: give {count!r} at the top level or in {where}")
            sweeps[count] = default_n
        keys = list(sweeps)
        values = []
        for k in keys:
            v = sweeps[k]
            if isinstance(v, list | tuple):
                if not v:
                    raise ValidationError(f"{where}.{k}", "an empty list sweeps nothing")
                values.append(list(v))
            else:
                values.append([v])
        for combo in itertools.product(*values):
            chosen = dict(zip(keys, combo, strict=True))
            n = check_int(f"{where}.{count}", chosen.pop(count))
            method, options = _resolve(table, where, entry["method"], chosen)
            cells.append(Cell(len(cells), method, tuple(options.items()), n, tuple(sorted(chosen))))
    return tuple(cells)


def _parse_reference(data: Any, problem: Problem, cells: Sequence[Cell]) -> ReferenceSpec | None:
    if data is None:
        if not problem.is_scene:
            return None  # closed form
        data = {}
    if not isinstance(data, Mapping):
        raise ValidationError("reference", f"must be an object like {{'method': 'boundary'}}, got {data!r}")
    table = _method_table(problem)
    count = problem.count_name
    options = {k: v for k, v in data.items() if k not in _REFERENCE_KEYS}
    default_method = "boundary" if "boundary" in table.names else "finite_difference"
    method, options = _resolve(table, "reference", data.get("method", default_method), options)
    other = "n" if count == "spp" else "spp"
    if other in data:
        raise ValidationError(f"reference.{other}", f"this problem takes {count!r}, not {other!r}")
    n = check_int(f"reference.{count}", data.get(count, 16 * max(c.n for c in cells)))
    seed = check_seed("reference.seed", data.get("seed", 2**31 - 1))
    return ReferenceSpec(method, tuple(options.items()), n, seed)


def trial_seed(seed: int, cell: int, trial: int) -> int:
    """The seed of trial ``trial`` of cell ``cell``: a deterministic function of the three numbers.

    Derived through :class:`numpy.random.SeedSequence`, so neighbouring cells and
    trials get statistically independent streams.
    """
    state = np.random.SeedSequence([check_seed("seed", seed), int(cell), int(trial)]).generate_state(1)
    return int(state[0])


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


def _functional(problem: Problem, image: np.ndarray) -> float:
    """The scalar studied, from a derivative image (see the module docstring)."""
    if problem.pixel is None:
        return float(np.sum(image))
    if len(problem.pixel) != image.ndim or any(
        p >= s for p, s in zip(problem.pixel, image.shape, strict=False)
    ):
        raise ValidationError(
            "problem.pixel", f"{list(problem.pixel)} is outside the film of shape {image.shape}"
        )
    return float(image[problem.pixel])


def _functional_stderr(problem: Problem, stderr: np.ndarray) -> float:
    """Standard error of :func:`_functional`, pixels being estimated independently."""
    if problem.pixel is None:
        return float(np.sqrt(np.sum(np.square(stderr))))
    return float(stderr[problem.pixel])


@lru_cache(maxsize=1)
def _code_digest(package: str) -> str:
    """Hash of the Python sources a computation depends on (the package and flatland's core)."""
    roots = {Path(importlib.import_module(package).__file__).parent, Path(__file__).parent}
    h = hashlib.sha256()
    for root in sorted(roots):
        for path in sorted(root.rglob("*.py")):
            h.update(str(path.relative_to(root.parent)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()


def _scene_fingerprint(problem: Problem) -> Any:
    """The scene's content: its ``to_dict()`` if it has one, else the file's bytes' hash, else its name."""
    scene = _load_scene(problem.package, problem.scene)
    if hasattr(scene, "to_dict"):
        return scene.to_dict()
    if Path(problem.scene).is_file():
        return hashlib.sha256(Path(problem.scene).read_bytes()).hexdigest()
    return problem.scene


def _cache_key(problem: Problem, spec: ReferenceSpec) -> str:
    payload = {
        "version": CACHE_VERSION,
        "code": _code_digest(problem.package),
        "package": problem.package,
        "integral": problem.integral,
        "theta": problem.theta,
        "scene": _scene_fingerprint(problem) if problem.is_scene else None,
        "param": problem.param,
        "method": spec.method,
        "options": [[k, v] for k, v in spec.options],
        "n": spec.n,
        "seed": spec.seed,
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=repr).encode()).hexdigest()[:32]


def _compute_reference(problem: Problem, spec: ReferenceSpec) -> tuple[np.ndarray, np.ndarray]:
    """(derivative, derivative_stderr) arrays of one high-sample run."""
    cell = Cell(-1, spec.method, spec.options, spec.n)
    run = _run_one(problem, cell, spec.seed)
    return np.asarray(run.derivative_image), np.asarray(run.stderr_image)


def resolve_reference(config: StudyConfig, cache_dir: str | os.PathLike | None = None) -> Reference:
    """The study's reference: the closed form, or a Monte Carlo run (read from / written to the cache).

    The cache file is ``<cache_dir>/<hash>.npz`` where the hash covers the package's
    source code, the problem (scene file content included), the method, its options,
    the sample count and the seed; it is written atomically.
    """
    problem, spec = config.problem, config.reference
    if spec is None:
        from flatland.integrals import get_integral

        return Reference(float(get_integral(problem.integral).derivative(problem.theta)), 0.0, "closed form")
    options = "".join(f" {k}={v}" for k, v in spec.options if v is not None)
    label = f"{spec.method}{options} {problem.count_name}={spec.n} seed={spec.seed}"
    path = Path(cache_dir) / f"{_cache_key(problem, spec)}.npz" if cache_dir is not None else None
    if path is not None and path.is_file():
        with np.load(path) as data:
            derivative, stderr = data["derivative"], data["stderr"]
        label += " (cached)"
    else:
        derivative, stderr = _compute_reference(problem, spec)
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp.npz")
            with os.fdopen(fd, "wb") as f:
                np.savez(f, derivative=derivative, stderr=stderr)
            os.replace(tmp, path)
    if not problem.is_scene:
        return Reference(float(derivative), float(stderr), label)
    return Reference(
        _functional(problem, derivative), _functional_stderr(problem, stderr), label, derivative, stderr
    )


# ---------------------------------------------------------------------------------------------- trials
@dataclass(frozen=True)
class _Task:
    problem: Problem
    cell: Cell
    trial: int
    seed: int


@dataclass(frozen=True)
class _Run:
    value: float
    derivative: float
    samples: int
    seconds: float
    derivative_image: np.ndarray | float
    stderr_image: np.ndarray | float


@dataclass(frozen=True)
class _Outcome:
    cell: int
    trial: int
    run: _Run


@lru_cache(maxsize=4)
def _load_scene(package: str, source: str) -> Any:
    return importlib.import_module(f"{package}.scene").load_scene(source)


def _run_one(problem: Problem, cell: Cell, seed: int) -> _Run:
    """One estimate of the problem by one cell's method, timed (scene loading excluded)."""
    options = cell.options_dict
    if not problem.is_scene:
        from flatland.estimators import estimate

        start = time.perf_counter()
        e = estimate(problem.integral, problem.theta, method=cell.method, n=cell.n, seed=seed, **options)
        seconds = time.perf_counter() - start
        return _Run(e.value, e.derivative, e.n, seconds, e.derivative, e.derivative_stderr)
    scene = _load_scene(problem.package, problem.scene)
    render = importlib.import_module(f"{problem.package}.render")
    start = time.perf_counter()
    g = render.render_gradient(scene, problem.param, method=cell.method, spp=cell.n, seed=seed, **options)
    seconds = time.perf_counter() - start
    value = _functional(problem, np.asarray(g.value))
    derivative = _functional(problem, np.asarray(g.derivative))
    return _Run(
        value, derivative, cell.n * int(np.size(g.derivative)), seconds, g.derivative, g.derivative_stderr
    )


def _run_task(task: _Task) -> _Outcome:
    """Worker entry point (module level, so processes and Dask can import it)."""
    try:
        return _Outcome(task.cell.index, task.trial, _run_one(task.problem, task.cell, task.seed))
    except ValidationError as e:  # its two-argument constructor does not survive pickling
        raise ValueError(f"methods cell {task.cell.index} ({task.cell.label}): {e}") from None


def _execute(tasks: Sequence[_Task], workers: int, scheduler: str | None, progress: Any) -> list[_Outcome]:
    """Run the tasks serially, in a process pool or on a Dask cluster; outcomes in task order."""
    outcomes: list[_Outcome] = []
    if scheduler is not None:
        from dask.distributed import Client

        with Client(scheduler, set_as_default=False) as client:
            futures = client.map(_run_task, tasks, pure=False)
            for future in futures:  # collected in submission order; they run in any order
                outcomes.append(future.result())
                progress.update(1)
    elif workers == 1:
        for task in tasks:
            outcomes.append(_run_task(task))
            progress.update(1)
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        # spawn: forking a process that may run threads (Dask, BLAS) is unsafe
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
            futures = [pool.submit(_run_task, task) for task in tasks]
            for future in as_completed(futures):
                outcomes.append(future.result())
                progress.update(1)
    outcomes.sort(key=lambda o: (o.cell, o.trial))
    return outcomes


# ---------------------------------------------------------------------------------------------- results
@dataclass(frozen=True)
class CellResult:
    """Statistics of one cell over its trials (see the module docstring for the definitions)."""

    cell: Cell
    trials: int
    samples: int
    reference: float
    reference_stderr: float
    mean_derivative: float
    stderr: float
    bias: float
    bias_low: float
    bias_high: float
    level: float
    variance_per_sample: float
    seconds_per_sample: float
    rmse: float
    efficiency: float
    equal_time_rmse: float
    time_budget: float
    relative_error: float
    mean_value: float
    derivatives: tuple[float, ...] = field(repr=False, default=())

    def bias_contains_zero(self) -> bool:
        """True if the bias interval contains 0."""
        return self.bias_low <= 0.0 <= self.bias_high


def _relative_error(run: _Run, reference: Reference) -> float:
    if reference.image is not None:
        scale = float(np.max(np.abs(reference.image)))
        if scale == 0.0:
            return math.nan
        return float(np.mean(np.abs(np.asarray(run.derivative_image) - reference.image)) / scale)
    if reference.derivative == 0.0:
        return math.nan
    return abs(run.derivative - reference.derivative) / abs(reference.derivative)


def _summarize(
    cell: Cell, runs: Sequence[_Run], reference: Reference, level: float, budget: float
) -> CellResult:
    d = np.array([r.derivative for r in runs])
    t = len(runs)
    samples = runs[0].samples
    mean = float(d.mean())
    var = float(d.var(ddof=1))
    # differences at the level of floating-point rounding are not variance or bias
    resolution = _ROUNDING * max(abs(mean), abs(reference.derivative))
    if math.sqrt(var) <= resolution:
        var = 0.0
    stderr = math.sqrt(var / t)
    half = (
        float(stats.t.ppf(0.5 + 0.5 * level, t - 1)) * math.sqrt(var / t + reference.stderr**2) + resolution
    )
    bias = float(mean - reference.derivative)
    var_ps = var * samples
    sec_ps = sum(r.seconds for r in runs) / (t * samples)
    cost = var_ps * sec_ps
    return CellResult(
        cell=cell,
        trials=t,
        samples=samples,
        reference=reference.derivative,
        reference_stderr=reference.stderr,
        mean_derivative=mean,
        stderr=stderr,
        bias=bias,
        bias_low=bias - half,
        bias_high=bias + half,
        level=level,
        variance_per_sample=var_ps,
        seconds_per_sample=sec_ps,
        rmse=float(np.sqrt(np.mean(np.square(d - reference.derivative)))),
        efficiency=1.0 / cost if cost > 0.0 else math.inf,
        equal_time_rmse=math.sqrt(bias * bias + cost / budget),
        time_budget=budget,
        relative_error=float(np.mean([_relative_error(r, reference) for r in runs])),
        mean_value=float(np.mean([r.value for r in runs])),
        derivatives=tuple(float(x) for x in d),
    )


@dataclass(frozen=True)
class StudyResult:
    """A finished study: its configuration, its reference and one :class:`CellResult` per cell."""

    config: StudyConfig
    reference: Reference
    rows: tuple[CellResult, ...]
    seconds: float

    def row(self, method: str, **options: Any) -> CellResult:
        """The single row of ``method`` whose options include ``options`` (ValueError otherwise)."""
        found = [
            r for r in self.rows
            if r.cell.method == method and all(r.cell.options_dict.get(k) == v for k, v in options.items())
        ]  # fmt: skip
        if len(found) != 1:
            raise ValueError(f"{len(found)} rows match method={method!r} {options}")
        return found[0]

    def to_csv(self, path: str | os.PathLike) -> Path:
        """Write the table (columns :data:`CSV_COLUMNS`, floats at full precision); returns the path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("w", newline="", encoding="utf-8") as f:
            writer = csv.writer(f)
            writer.writerow(CSV_COLUMNS)
            for r in self.rows:
                writer.writerow([_csv_value(r, c, self.config) for c in CSV_COLUMNS])
        return path

    def table(self) -> str:
        """A fixed-width text table of the main columns."""
        level = f"{self.config.level:.0%} CI"
        head = ("method", "mean dI/dθ", "bias", level, "var/sample", "s/sample", "rmse", "efficiency")
        rows = [
            (
                r.cell.label,
                f"{r.mean_derivative:.5g}",
                f"{r.bias:+.3g}",
                f"[{r.bias_low:+.3g}, {r.bias_high:+.3g}]",
                f"{r.variance_per_sample:.3g}",
                f"{r.seconds_per_sample:.3g}",
                f"{r.rmse:.3g}",
                f"{r.efficiency:.3g}",
            )
            for r in self.rows
        ]
        ref = self.reference
        title = f"{self.config.problem.label}: reference dI/dθ = {ref.derivative:.6g} ({ref.source})"
        return format_table(head, rows, title)


def _csv_value(row: CellResult, column: str, config: StudyConfig) -> Any:
    cell = row.cell
    options = cell.options_dict
    if column in OPTION_COLUMNS:
        v = options.get(column)
        return "" if v is None else v
    special_cases = {
        "cell": cell.index,
        "problem": config.problem.label,
        "method": cell.method,
        "label": cell.label,
        "options": json.dumps({k: v for k, v in options.items() if k not in OPTION_COLUMNS}, sort_keys=True),
        "n": cell.n,
        "seed": config.seed,
    }
    if column in special_cases:
        return special_cases[column]
    v = getattr(row, column)
    return repr(float(v)) if isinstance(v, float) else v


def read_csv(path: str | os.PathLike) -> list[dict[str, Any]]:
    """Read a study CSV back; numeric columns as int/float/bool, empty cells as None."""

    def parse(text: str) -> Any:
        if text == "":
            return None
        if text in ("True", "False"):
            return text == "True"
        for kind in (int, float):
            try:
                return kind(text)
            except ValueError:
                pass
        return text

    with Path(path).open(newline="", encoding="utf-8") as f:
        return [{k: parse(v) for k, v in row.items()} for row in csv.DictReader(f)]


# ----------------------------------------------------------------------------------------------- runner
class _NoProgress:
    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, desc: str, progress: bool | None) -> Any:
    show = sys.stderr.isatty() if progress is None else progress
    if not show:
        return _NoProgress()
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="trial", file=sys.stderr, dynamic_ncols=True)


def run_study(
    config: StudyConfig,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    cache_dir: str | os.PathLike | None = None,
    progress: bool | None = None,
    on_reference: Callable[[Reference], None] | None = None,
) -> StudyResult:
    """Run every cell's trials and summarize them against the reference.

    Parameters
    ----------
    config : StudyConfig
        The validated study (:meth:`StudyConfig.from_dict`, :func:`load_config`).
    workers : int, optional
        Worker processes on this machine (overrides ``config.workers``); 1 runs in
        this process.
    scheduler : str, optional
        Address of a ``dask.distributed`` scheduler (overrides ``config.scheduler``);
        the trials then run on that cluster (needs the ``cluster`` extra).
    cache_dir : path, optional
        Where Monte Carlo references are cached; None computes them every time.
    progress : bool, optional
        Show a tqdm progress bar over the trials; default: when stderr is a terminal.
    on_reference : callable, optional
        Called with the reference once it is known (e.g. to print it).

    Returns
    -------
    StudyResult
        The same numbers for the same config and seed, however the trials ran
        (except ``seconds_per_sample``, ``efficiency`` and ``equal_time_rmse``).
    """
    workers = check_int("workers", config.workers if workers is None else workers)
    scheduler = config.scheduler if scheduler is None else scheduler
    start = time.perf_counter()
    _preflight(config)
    reference = resolve_reference(config, cache_dir)
    if on_reference is not None:
        on_reference(reference)
    tasks = [
        _Task(config.problem, cell, k, trial_seed(config.seed, cell.index, k))
        for cell in config.cells
        for k in range(config.trials)
    ]
    bar = _progress(len(tasks), config.name, progress)
    try:
        outcomes = _execute(tasks, workers, scheduler, bar)
    finally:
        bar.close()
    rows = []
    for cell in config.cells:
        runs = [o.run for o in outcomes if o.cell == cell.index]
        rows.append(_summarize(cell, runs, reference, config.level, config.time_budget))
    return StudyResult(config, reference, tuple(rows), time.perf_counter() - start)


def _preflight(config: StudyConfig) -> None:
    """Run every cell once with few samples, so a bad combination fails here with its field named."""
    for cell in config.cells:
        small = replace(cell, n=min(cell.n, 2 if not config.problem.is_scene else cell.n))
        if config.problem.is_scene and cell.index > 0 and cell.method == config.cells[cell.index - 1].method:
            continue
        try:
            _run_one(config.problem, small, config.seed)
        except ValidationError as e:
            raise ValidationError(f"methods cell {cell.index} ({cell.label})", str(e)) from None
