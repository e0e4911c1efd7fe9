"""Study runner: a grid of methods × options × independent trials, measured against a reference.

A study answers "how biased, how noisy and how fast is each estimator here?" for one
scalar derivative dI/dθ, the numbers behind the bias/variance trade-off of the
convolution kernel (Loubet et al. 2019, Sec. 4.2; DESIGN 2.7) and behind equal-time
comparisons of the methods.

Problems
--------
``{"integral": "two_steps", "theta": 1.0}``
    A textbook integral (flatland's :mod:`flatland.integrals`), run through the
    package's ``estimate`` (:func:`flatland.estimate`); the reference is its
    closed-form derivative.
``{"scene": "shadow", "param": "occluder.translate.x"}``
    A scene of the package (``flatland`` or ``sphere3d``), run through the
    ``render_gradient`` of its description (:class:`~flatland.app.cli.Package`). The
    scalar studied is a linear functional of the gradient
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
``mean_derivative``
    mean of the T trial estimates
``bias``
    mean - reference, with a Student-t interval (T - 1 degrees of freedom) of
    half-width t · sqrt(s²/T + s_ref²) (plus a floating-point allowance of
    :func:`~flatland.core.stats.rounding_floor` (64 ε) of the larger of mean and
    reference; a spread of the trials below that counts as zero variance, the
    policy of :data:`flatland.core.stats.ROUNDING`)
``variance_per_sample``
    s² · samples (s² the variance of the trial estimates), the variance a
    single-sample estimate would have
``seconds_per_sample``
    measured wall time (time.perf_counter) / (T · samples)
``rmse``
    sqrt(mean_k (d_k - reference)²): the error of one trial
``bias_z``, ``biased``
    z = bias / sqrt(stderr² + reference_stderr²) (0 within the floating-point
    allowance, ±inf with no noise at all); ``biased`` when |z| > 3.3 (two-sided
    99.9 %); for scenes the per-pixel test of the mean image over the
    trials flags it (:mod:`flatland.core.bias`: |z_j| above the Student-t
    quantile with T - 1 degrees of freedom at the Sidak-corrected level
    1 - 0.99^(1/m) over the m pixels, the stderr the larger of the trials' scatter
    and their pooled batch stderrs; ``pixels_exceeding`` of ``pixels_tested``: shown, not
    a flag, as heavy-tailed pixels break its t law at 8-16 trials)
``efficiency``
    1 / (variance_per_sample · seconds_per_sample), infinite for a zero-variance
    estimator; only for a cell that is not ``biased`` and whose interval contains
    0, else None (blank in the CSV, "biased" or "-" in the table): efficiency
    ignores bias, so a biased cell has none
``rank``
    1 = best: cells with an efficiency by efficiency, then the others by
    ``equal_time_rmse``, so a biased cell never ranks above an unbiased one
``seconds_per_trial``
    seconds_per_sample · samples, the wall time of one estimate (the x axis of the
    error-versus-time figure)
``equal_time_rmse``
    sqrt(bias² + variance_per_sample · seconds_per_sample / B): the error expected
    from a time budget of B seconds (``"time_budget"``, default 1 s), which unlike
    efficiency counts the bias

For scenes a "sample" is one camera sample: spp × pixels.

Reference rule: a Monte Carlo reference's standard error must be at most 1/4 of
the smallest standard error among the cells it does not flag as biased (a flag
already counts the reference's noise in its z). :func:`run_study` checks this after
the trials and recomputes the reference at (stderr / target)² × its sample count
(× 1.25), or raises with that count (``grow_reference=False``); the table's footer
states the reference's method, sample count, stderr and the ratio.

Configurations are parsed and validated in :mod:`flatland.app.study_config`
(re-exported here) against the package's description (:class:`~flatland.app.cli.Package`,
``load_config(source, package=PACKAGE)`` with the ``PACKAGE`` of ``flatland.__main__`` or
``sphere3d.__main__``). Example (JSON)::

    {"name": "kappa", "problem": {"integral": "two_steps", "theta": 1.0},
     "methods": [{"method": "boundary"},
                 {"method": "reparam", "kappa": [1, 10, 100, 1000, 10000]}],
     "n": 50000, "trials": 20, "seed": 3, "level": 0.99}
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import stats

from flatland.app.study_config import Cell, Problem, ReferenceSpec, StudyConfig, load_config, trial_seed
from flatland.app.table import format_table, method_label, own_method_note
from flatland.core.bias import REFERENCE_RATIO, Z_FLAG, PixelTest, pixel_test, reference_spp_needed
from flatland.core.image import relative_error
from flatland.core.stats import ROUNDING, rounding_floor, spread, z_score
from flatland.core.validate import ValidationError, check_int

if TYPE_CHECKING:
    from flatland.app.cli import Package

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
    "rank", "biased", "bias_z", "pixels_exceeding", "pixels_tested", "pixel_threshold",
    "reference", "reference_stderr", "reference_n", "mean_derivative", "stderr", "bias", "bias_low",
    "bias_high", "level", "variance_per_sample", "seconds_per_sample", "seconds_per_trial", "rmse",
    "efficiency", "equal_time_rmse", "time_budget", "relative_error", "mean_value",
)  # fmt: skip
"""Columns of the study CSV, in order."""

CACHE_VERSION = 1


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


def _compute_reference(calls: _Calls, problem: Problem, spec: ReferenceSpec) -> tuple[np.ndarray, np.ndarray]:
    """(derivative, derivative_stderr) arrays of one high-sample run."""
    cell = Cell(-1, spec.method, spec.options, spec.n)
    run = _run_one(calls, problem, cell, spec.seed)
    return np.asarray(run.derivative_image), np.asarray(run.stderr_image)


def resolve_reference(config: StudyConfig, cache_dir: str | os.PathLike | None = None) -> Reference:
    """The study's reference: the closed form, or a Monte Carlo run (read from / written to the cache).

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
        label += " (cached)"
    else:
        derivative, stderr = _compute_reference(_Calls.of(config.package), problem, spec)
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp.npz")
            with os.fdopen(fd, "wb") as f:
                np.savez(f, derivative=derivative, stderr=stderr)
            os.replace(tmp, path)
    if not problem.is_scene:
        return Reference(float(derivative), float(stderr), label, n=spec.n)
    return Reference(
        _functional(problem, derivative),
        _functional_stderr(problem, stderr),
        label,
        derivative,
        stderr,
        spec.n,
    )


# ---------------------------------------------------------------------------------------------- trials
@dataclass(frozen=True)
class _Calls:
    """The package functions a trial calls: module-level functions, so a task pickles to worker
    processes and Dask by reference (the whole description need not)."""

    load_scene: Callable[[Any], Any]
    render_gradient: Callable[..., Any]
    estimate: Callable[..., Any] | None

    @classmethod
    def of(cls, package: Package) -> _Calls:
        return cls(package.load_scene, package.render_gradient, package.estimate)


@dataclass(frozen=True)
class _Task:
    calls: _Calls
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


@lru_cache(maxsize=4)
def _load_scene(load_scene: Callable[[Any], Any], source: str) -> Any:
    return load_scene(source)


def _run_one(calls: _Calls, problem: Problem, cell: Cell, seed: int) -> _Run:
    """One estimate of the problem by one cell's method, timed (scene loading excluded)."""
    options = cell.options_dict
    if not problem.is_scene:
        start = time.perf_counter()
        e = calls.estimate(
            problem.integral, problem.theta, method=cell.method, n=cell.n, seed=seed, **options
        )
        seconds = time.perf_counter() - start
        return _Run(e.value, e.derivative, e.n, seconds, e.derivative, e.derivative_stderr)
    scene = _load_scene(calls.load_scene, problem.scene)
    start = time.perf_counter()
    g = calls.render_gradient(scene, problem.param, method=cell.method, spp=cell.n, seed=seed, **options)
    seconds = time.perf_counter() - start
    value = _functional(problem, np.asarray(g.value))
    derivative = _functional(problem, np.asarray(g.derivative))
    return _Run(
        value, derivative, cell.n * int(np.size(g.derivative)), seconds, g.derivative, g.derivative_stderr
    )


def _run_task(task: _Task) -> _Run:
    """Worker entry point (module level, so processes and Dask can import it)."""
    try:
        return _run_one(task.calls, task.problem, task.cell, task.seed)
    except ValidationError as e:  # named by its cell; pickles back from a worker (ValidationError.__reduce__)
        raise ValidationError(f"methods cell {task.cell.index} ({task.cell.label})", str(e)) from None


def _execute(tasks: Sequence[_Task], workers: int, scheduler: str | None, progress: Any) -> list[_Run]:
    """Run the tasks serially, in a process pool or on a Dask cluster; runs in task order."""
    if scheduler is not None:
        from dask.distributed import Client
        from distributed.comm import parse_address, parse_host_port

        try:  # a malformed address fails before a Client exists (a half-built one stalls the exit)
            scheme, location = parse_address(scheduler)
            if scheme in ("tcp", "tls"):
                parse_host_port(location)
            client = Client(scheduler, set_as_default=False)
        except (ValueError, OSError) as e:  # a malformed address, or no scheduler there
            raise ValidationError("scheduler", f"cannot connect to {scheduler!r}: {e}") from None
        with client:
            futures = client.map(_run_task, tasks, pure=False)
            for future in futures:  # waited for in submission order; they run in any order
                future.result()
                progress.update(1)
            return [future.result() for future in futures]
    if workers == 1:
        runs = []
        for task in tasks:
            runs.append(_run_task(task))
            progress.update(1)
        return runs
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # spawn: forking a process that may run threads (Dask, BLAS) is unsafe
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = [pool.submit(_run_task, task) for task in tasks]
        for future in as_completed(futures):
            future.result()  # the first failure stops the study
            progress.update(1)
        return [future.result() for future in futures]


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
    efficiency: float | None
    equal_time_rmse: float
    time_budget: float
    relative_error: float
    mean_value: float
    bias_z: float = 0.0
    pixels: PixelTest | None = None
    seconds_per_trial: float = 0.0
    reference_n: int | None = None
    rank: int = 0
    derivatives: tuple[float, ...] = field(repr=False, default=())

    def bias_contains_zero(self) -> bool:
        """True if the bias interval contains 0."""
        return self.bias_low <= 0.0 <= self.bias_high

    @property
    def biased(self) -> bool:
        """True if the bias is significant: |bias_z| > 3.3. The per-pixel test (``pixels``) is shown
        but does not flag: with 8-16 trials its t law fails for heavy-tailed pixels (measured: a
        finite-difference cell against a same-method reference exceeded)."""
        return abs(self.bias_z) > Z_FLAG

    @property
    def pixels_exceeding(self) -> int | None:
        """Pixels whose |z| exceeds the per-pixel threshold (None for integrals)."""
        return None if self.pixels is None else self.pixels.exceeding

    @property
    def pixels_tested(self) -> int | None:
        """Pixels in the per-pixel test (None for integrals)."""
        return None if self.pixels is None else self.pixels.pixels

    @property
    def pixel_threshold(self) -> float | None:
        """The per-pixel |z| threshold (None for integrals)."""
        return None if self.pixels is None else self.pixels.threshold


def _relative_error(run: _Run, reference: Reference) -> float:
    """:func:`~flatland.core.image.relative_error` of the run's derivative image (a scalar for an
    integral: then |d - d_ref| / |d_ref|); NaN against an all-zero reference."""
    target = reference.derivative if reference.image is None else reference.image
    if not np.any(target):
        return math.nan
    return relative_error(run.derivative_image, target)


def _summarize(
    cell: Cell, runs: Sequence[_Run], reference: Reference, level: float, budget: float
) -> CellResult:
    d = np.array([r.derivative for r in runs])
    t = len(runs)
    samples = runs[0].samples
    mean = float(d.mean())
    var = float(d.var(ddof=1))
    # differences at the level of floating-point rounding are not variance or bias
    scale = max(abs(mean), abs(reference.derivative))
    resolution = float(rounding_floor(scale))
    var = float(spread(math.sqrt(var), scale)) ** 2  # one rounding policy (flatland.core.stats.ROUNDING)
    stderr = math.sqrt(var / t)
    half = (
        float(stats.t.ppf(0.5 + 0.5 * level, t - 1)) * math.sqrt(var / t + reference.stderr**2) + resolution
    )
    bias = float(mean - reference.derivative)
    bias_z = z_score(mean, reference.derivative, math.hypot(stderr, reference.stderr), resolution)
    pixels = None
    if reference.image is not None:  # the mean image over the trials against the reference image
        images = np.array([np.asarray(r.derivative_image, dtype=np.float64) for r in runs])
        image = images.mean(axis=0)
        # the larger of two estimates of the mean image's stderr: the scatter of the T trials and the
        # trials' own batch stderrs pooled (T × batches samples: fewer pixels whose rare large samples
        # all missed the T trials); conservative, for a test whose null law is only approximately t
        pooled = np.sqrt(np.sum([np.square(r.stderr_image) for r in runs], axis=0)) / t
        image_se = np.maximum(images.std(axis=0, ddof=1) / math.sqrt(t), pooled)
        # rounding at the scale of the film (a finite difference of radiances ~1 leaves ~ε/h in dark pixels)
        tolerance = ROUNDING * max(float(np.max(np.abs(image))), float(np.max(np.abs(reference.image))))
        pixels = pixel_test(image, image_se, reference.image, reference.image_stderr, t - 1, tolerance)
    var_ps = var * samples
    sec_ps = sum(r.seconds for r in runs) / (t * samples)
    cost = var_ps * sec_ps
    # efficiency ignores bias: defined only for a cell that passes both bias tests and whose interval
    # contains 0 (infinite for a zero-variance estimator), never for a biased one
    unbiased = abs(bias_z) <= Z_FLAG and bias - half <= 0 <= bias + half
    efficiency = (1.0 / cost if cost > 0.0 else math.inf) if unbiased else None
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
        efficiency=efficiency,
        equal_time_rmse=math.sqrt(bias * bias + cost / budget),
        time_budget=budget,
        relative_error=float(np.mean([_relative_error(r, reference) for r in runs])),
        mean_value=float(np.mean([r.value for r in runs])),
        bias_z=bias_z,
        pixels=pixels,
        seconds_per_trial=sec_ps * samples,
        reference_n=reference.n,
        derivatives=tuple(float(x) for x in d),
    )


def _ranked(rows: Sequence[CellResult]) -> tuple[CellResult, ...]:
    """The rows (in their order) with ``rank`` set: cells with an efficiency first, by efficiency
    (largest first), then every other cell (biased, or an interval that excludes 0) by equal-time
    RMSE; a biased cell never ranks above an unbiased one."""
    order = sorted(
        range(len(rows)),
        key=lambda i: (0, -rows[i].efficiency, i) if rows[i].efficiency is not None
        else (1, rows[i].equal_time_rmse, i),
    )  # fmt: skip
    rank = {i: k + 1 for k, i in enumerate(order)}
    return tuple(replace(r, rank=rank[i]) for i, r in enumerate(rows))


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
                writer.writerow(_csv_row(r, self.config))
        return path

    def ranking(self) -> tuple[CellResult, ...]:
        """The rows best first: unbiased cells by efficiency, then the rest (see ``rank``)."""
        return tuple(sorted(self.rows, key=lambda r: r.rank))

    def table(self) -> str:
        """A fixed-width text table, best first; the bias columns lead, the footer states the tests."""
        level = f"{self.config.level:.0%} CI"
        scene = self.config.problem.is_scene
        head = ("method", "rank", "bias z", "flag", *(("px |z|>t",) if scene else ()), f"bias [{level}]",
                "efficiency", "rmse", "var/sample", "s/trial", "mean dI/dθ")  # fmt: skip
        rows = [
            (
                r.cell.label
                + ("" if len(self.sample_counts) == 1 else f" {self.config.problem.count_name}={r.cell.n}"),
                str(r.rank),
                _format_z(r.bias_z),
                "BIASED" if r.biased else "",
                *((r.pixels.summary(),) if r.pixels is not None else ()),
                f"{r.bias:+.3g} [{r.bias_low:+.3g}, {r.bias_high:+.3g}]",
                _format_efficiency(r),
                f"{r.rmse:.3g}",
                f"{r.variance_per_sample:.3g}",
                f"{r.seconds_per_trial:.3g}",
                f"{r.mean_derivative:.5g}",
            )
            for r in self.ranking()
        ]
        ref = self.reference
        title = f"{self.config.problem.label}: reference dI/dθ = {ref.derivative:.6g} ± {ref.stderr:.2g}"
        return format_table(head, rows, title) + "\n" + self.footer()

    @property
    def sample_counts(self) -> tuple[int, ...]:
        """The distinct per-trial sample counts of the grid, ascending."""
        return tuple(sorted({r.cell.n for r in self.rows}))

    def footer(self) -> str:
        """What the bias columns mean and how the reference was made."""
        ref = self.reference
        judged = [r.stderr for r in self.rows if not r.biased and r.stderr > 0.0]
        ratio = f"{ref.stderr / min(judged):.2f}" if judged else "n/a"
        lines = [
            f"reference: {ref.source}, stderr {ref.stderr:.2g} = {ratio} × the smallest unbiased-row stderr"
            f" (required <= {REFERENCE_RATIO:g})",
            f"bias z = bias / sqrt(stderr² + stderr_ref²) of the studied scalar; |z| > {Z_FLAG}"
            " (two-sided 99.9 %) flags BIASED",
        ]
        if self.config.problem.is_scene:
            lines.append(
                "px |z|>t: pixels of the mean image whose |z| exceeds the Student-t quantile (trials - 1 dof)"
                " at the Sidak-corrected level 1-(1-0.01)^(1/m), m pixels; ~0.01 expected if unbiased"
                " (shown, not a flag: heavy-tailed pixels break its t law at these trial counts)"
            )
        lines.append(
            "efficiency = 1/(var/sample × s/sample), shown only for an unbiased row whose interval"
            " contains 0; rank: those by efficiency, then the rest by equal-time RMSE"
        )
        if self.config.reference is not None:
            note = own_method_note((c.method for c in self.config.cells), self.config.reference.method)
            lines += [note] if note else []
        return "\n".join(lines)


def _format_z(z: float) -> str:
    return f"{z:+.1f}" if math.isfinite(z) else ("+inf" if z > 0 else "-inf") + " (σ=0)"


def _format_efficiency(row: CellResult) -> str:
    if row.efficiency is None:
        return "biased" if row.biased else "-"
    return f"{row.efficiency:.3g}" if math.isfinite(row.efficiency) else "σ²=0"


def _csv_row(row: CellResult, config: StudyConfig) -> list[Any]:
    """One CSV line: the cell's description, then the statistics (floats as repr: full precision)."""
    cell = row.cell
    options = cell.options_dict
    described = {
        "cell": cell.index,
        "problem": config.problem.label,
        "method": cell.method,
        "label": cell.label,
        **{k: "" if options.get(k) is None else options[k] for k in OPTION_COLUMNS},
        "options": json.dumps({k: v for k, v in options.items() if k not in OPTION_COLUMNS}, sort_keys=True),
        "n": cell.n,
        "seed": config.seed,
    }
    values = [described[c] if c in described else getattr(row, c) for c in CSV_COLUMNS]
    return [repr(float(v)) if isinstance(v, float) else v for v in values]


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
    grow_reference: bool = True,
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
    grow_reference : bool
        What to do when a Monte Carlo reference's standard error exceeds 1/4 of the
        smallest standard error among the cells it does not flag as biased (a flag
        counts the reference's noise in its z, so it stands whatever that noise):
        True recomputes it at the sample count :func:`~flatland.core.bias.reference_spp_needed`
        gives (times 1.25, for the scatter of the estimated standard errors; at most three
        rounds), False raises a ValidationError naming ``reference`` and that count.

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
    calls = _Calls.of(config.package)
    tasks = [
        _Task(calls, config.problem, cell, k, trial_seed(config.seed, cell.index, k))
        for cell in config.cells
        for k in range(config.trials)
    ]
    bar = _progress(len(tasks), config.name, progress)
    try:
        runs = _execute(tasks, workers, scheduler, bar)
    finally:
        bar.close()
    t = config.trials  # tasks are ordered cell by cell, trial by trial

    def summarize(reference: Reference) -> list[CellResult]:
        return [
            _summarize(cell, runs[c * t : (c + 1) * t], reference, config.level, config.time_budget)
            for c, cell in enumerate(config.cells)
        ]

    rows = summarize(reference)
    for attempt in range(4):
        needed = _reference_needed(config, reference, rows)
        if needed is None:
            break
        count = f"reference.{config.problem.count_name}"
        if not grow_reference or attempt == 3:
            judged = min(r.stderr for r in rows if not r.biased and r.stderr > 0.0)
            raise ValidationError(
                count,
                f"the reference's standard error {reference.stderr:.3g} is more than {REFERENCE_RATIO:g}"
                f" × the smallest standard error it judges ({judged:.3g}); give at least {needed}",
            )
        spec = replace(config.reference, n=needed)
        reference = resolve_reference(replace(config, reference=spec), cache_dir)
        rows = summarize(reference)
    return StudyResult(config, reference, _ranked(rows), time.perf_counter() - start)


def _reference_needed(config: StudyConfig, reference: Reference, rows: Sequence[CellResult]) -> int | None:
    """The reference sample count the 1/4 rule asks for, or None if the reference meets it."""
    if config.reference is None or reference.n is None:
        return None  # closed form: no noise
    judged = [r.stderr for r in rows if not r.biased and r.stderr > 0.0]
    if not judged or reference.stderr <= REFERENCE_RATIO * min(judged):
        return None
    return reference_spp_needed(reference.n, reference.stderr, min(judged))


def _preflight(config: StudyConfig) -> None:
    """Run every cell once with 2 samples (per pixel), so a bad combination fails here, named."""
    calls = _Calls.of(config.package)
    for cell in config.cells:
        try:
            _run_one(calls, config.problem, replace(cell, n=min(cell.n, 2)), config.seed)
        except ValidationError as e:
            raise ValidationError(f"methods cell {cell.index} ({cell.label})", str(e)) from None
