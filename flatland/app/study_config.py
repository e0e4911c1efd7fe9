"""Study configurations: problem, grid of cells, trials and seeds, validated with errors naming the field.

A configuration is a JSON object (or the same dict)::

    {"name": "kappa",                                   # output file stem (default: the file's)
     "problem": {"integral": "two_steps", "theta": 1.0}  # or {"scene": S, "param": P[, "pixel": j]}
     "methods": [{"method": "boundary"},
                 {"method": "reparam", "kappa": [1, 10, 100], "paired": [false, true]}],
     "n": 50000,            # samples per trial ("spp" for scenes); may be given or swept per method
     "trials": 20,          # independent trials per cell, >= 2
     "seed": 3,             # trial k of cell c runs with trial_seed(seed, c, k)
     "level": 0.99,         # the bias intervals' level, simultaneous over the cells (default LEVEL)
     "workers": 1,          # worker processes (or "scheduler": a dask.distributed address)
     "time_budget": 1.0,    # seconds, for the equal-time RMSE column
     "reference": {"method": "boundary", "spp": 4096, "seed": 7, ...options}}

Lists expand to the Cartesian product, one :class:`Cell` per combination, numbered in
order. Every method name and option is checked against the method table of the
package's description (:class:`~flatland.app.cli.Package`: ``estimators`` for
integrals, ``methods`` for scenes); a bad value raises one :class:`~flatland.core.validate.ValidationError`
naming its path, e.g. ``methods[1].kappa: must be > 0, got -2``.
"""

from __future__ import annotations

import copy
import itertools
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from flatland.app.table import method_label
from flatland.core.stats import LEVEL
from flatland.core.validate import (
    ValidationError,
    check_choice,
    check_depth,
    check_finite,
    check_int,
    check_positive,
    check_seed,
    read_json,
)

if TYPE_CHECKING:
    from flatland.app.cli import Package

__all__ = ["Cell", "Problem", "ReferenceSpec", "StudyConfig", "load_config", "trial_seed"]

_TOP_KEYS = ("name", "problem", "methods", "n", "spp", "trials", "seed", "workers", "scheduler", "level",
             "reference", "time_budget")  # fmt: skip
_PROBLEM_KEYS = ("integral", "theta", "scene", "param", "functional", "pixel")
_REFERENCE_KEYS = ("method", "n", "spp", "seed")


@dataclass(frozen=True)
class Problem:
    """What is differentiated: a textbook integral at ``theta`` or a scene parameter ``param``.

    ``pixel`` is None for the sum over the image (scene problems) and otherwise the
    index of the pixel studied.
    """

    package: str  # the package's name (Package.name)
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
        return method_label(self.method, [(k, v) for k, v in self.options if k in self.given])


@dataclass(frozen=True)
class ReferenceSpec:
    """How to compute a Monte Carlo reference: method, options, sample count and seed."""

    method: str
    options: tuple[tuple[str, Any], ...]
    n: int
    seed: int


@dataclass(frozen=True)
class StudyConfig:
    """A validated study: problem, grid of cells, trials, seed and execution settings.

    ``package`` is the description of the package that runs it (its scene, render and
    method API).
    """

    name: str
    package: Package = field(repr=False)
    problem: Problem
    cells: tuple[Cell, ...]
    trials: int
    seed: int
    workers: int = 1
    scheduler: str | None = None
    level: float = LEVEL
    time_budget: float = 1.0
    reference: ReferenceSpec | None = None

    @classmethod
    def from_dict(
        cls,
        data: Any,
        *,
        package: Package,
        base_dir: str | os.PathLike | None = None,
        name: str = "study",
    ) -> StudyConfig:
        """Validate a configuration dict (the JSON file's content); errors name the field.

        ``package`` describes the package that runs the study (its method tables and
        textbook integrals check the configuration). Scene paths are resolved relative
        to ``base_dir`` (the config file's folder).
        """
        if not isinstance(data, Mapping):
            raise ValidationError("config", f"must be a JSON object, got {type(data).__name__}")
        _reject_unknown("", data, _TOP_KEYS)
        name = data.get("name", name)
        if not isinstance(name, str) or not name or any(c in name for c in "/\\"):
            raise ValidationError("name", f"must be a non-empty file-name-safe string, got {name!r}")
        problem = _parse_problem(data.get("problem"), package, base_dir)
        count = problem.count_name
        _reject_other_count("", data, problem)
        default_n = check_int(count, data[count]) if count in data else None
        cells = _expand_cells(data.get("methods"), package, problem, default_n)
        trials = check_int("trials", data.get("trials", 10), minimum=2)
        seed = check_seed("seed", data.get("seed", 0))
        workers = check_int("workers", data.get("workers", 1))
        scheduler = data.get("scheduler")
        if scheduler is not None and (not isinstance(scheduler, str) or not scheduler):
            raise ValidationError("scheduler", f"must be a scheduler address string, got {scheduler!r}")
        level = check_finite("level", data.get("level", LEVEL))
        if not 0.0 < level < 1.0:
            raise ValidationError("level", f"must lie in (0, 1), got {level!r}")
        time_budget = check_positive("time_budget", data.get("time_budget", 1.0))
        reference = _parse_reference(data.get("reference"), package, problem, cells)
        return cls(
            name, package, problem, cells, trials, seed, workers, scheduler, level, time_budget, reference
        )


def load_config(
    source: str | os.PathLike | Mapping[str, Any],
    *,
    package: Package,
    seed: int | None = None,
    samples: int | None = None,
    name: str | None = None,
) -> StudyConfig:
    """Read and validate a study configuration: a JSON file (its stem is the default name) or a dict.

    ``package`` describes the package that runs the study (``PACKAGE`` of
    ``flatland.__main__`` or ``sphere3d.__main__``); ``seed`` replaces the configuration's
    seed; ``samples`` replaces every sample count of the grid (``n`` or ``spp``, swept or
    not) with one value.
    """
    if isinstance(source, Mapping):
        data: Any = copy.deepcopy(dict(check_depth("config", source)))  # deepcopy recurses: depth first
        base_dir = None
        name = name or "study"
    else:
        path = Path(source)
        data = read_json(path, "config")
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


def _reject_other_count(prefix: str, data: Mapping[str, Any], problem: Problem) -> None:
    """Integral problems count samples per trial in ``n``, scenes in ``spp``: the other key is an error."""
    count = problem.count_name
    other = "n" if count == "spp" else "spp"
    if other in data:
        kind = "scene" if problem.is_scene else "integral"
        where = f"{prefix}.{other}" if prefix else other
        raise ValidationError(where, f"{kind} problems take {count!r} (samples per trial), not {other!r}")


def _parse_problem(data: Any, package: Package, base_dir: Any) -> Problem:
    if not isinstance(data, Mapping):
        raise ValidationError("problem", f"must be an object with 'integral' or 'scene', got {data!r}")
    _reject_unknown("problem", data, _PROBLEM_KEYS)
    if ("integral" in data) == ("scene" in data):
        raise ValidationError("problem", "must name exactly one of 'integral' and 'scene'")
    if "integral" in data:
        integrals = _integrals(package)
        for key in ("param", "functional", "pixel"):
            if key in data:
                raise ValidationError(f"problem.{key}", "applies to scene problems only")
        integral = integrals[check_choice("problem.integral", data["integral"], integrals)]
        theta = integral.check_theta(data.get("theta", integral.default_theta), "problem.theta")
        return Problem(package.name, integral=integral.name, theta=theta)
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
    return Problem(package.name, scene=scene, param=param, pixel=pixel)


def _integrals(package: Package) -> Mapping[str, Any]:
    if package.integrals is None or package.estimate is None or package.estimators is None:
        raise ValidationError("problem.integral", f"{package.name} has no textbook integrals; give 'scene'")
    return package.integrals


def _method_table(package: Package, problem: Problem) -> Any:
    return package.methods if problem.is_scene else package.estimators


def _resolve(table: Any, where: str, method: Any, options: Mapping[str, Any]) -> tuple[str, dict[str, Any]]:
    """Method name and validated options, errors re-labelled with the config path ``where``."""
    try:
        spec = table.lookup(method)
        return spec.name, table.resolve_options(spec.name, options)
    except ValidationError as e:
        message = str(e)[len(e.field) + 2 :] if e.field else str(e)
        raise ValidationError(f"{where}.{e.field}" if e.field else where, message) from None


def _expand_cells(data: Any, package: Package, problem: Problem, default_n: int | None) -> tuple[Cell, ...]:
    if not isinstance(data, list | tuple) or not data:
        raise ValidationError(
            "methods", f"must be a non-empty list of {{'method': ...}} objects, got {data!r}"
        )
    table = _method_table(package, problem)
    count = problem.count_name
    cells: list[Cell] = []
    for i, entry in enumerate(data):
        where = f"methods[{i}]"
        if not isinstance(entry, Mapping) or "method" not in entry:
            raise ValidationError(where, f"must be an object with a 'method' key, got {entry!r}")
        _reject_other_count(where, entry, problem)
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


def _parse_reference(
    data: Any, package: Package, problem: Problem, cells: Sequence[Cell]
) -> ReferenceSpec | None:
    if data is None:
        if not problem.is_scene:
            return None  # closed form
        data = {}
    if not isinstance(data, Mapping):
        raise ValidationError("reference", f"must be an object like {{'method': 'boundary'}}, got {data!r}")
    table = _method_table(package, problem)
    count = problem.count_name
    options = {k: v for k, v in data.items() if k not in _REFERENCE_KEYS}
    default_method = package.reference_method or (
        "boundary" if "boundary" in table.names else "finite_difference"
    )
    method, options = _resolve(table, "reference", data.get("method", default_method), options)
    _reject_other_count("reference", data, problem)
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
