r"""A study's results: per-cell statistics (:class:`CellResult`), their ranking, the table and the CSV.

Statistics per cell (T trials of ``samples`` integrand evaluations each)
------------------------------------------------------------------------
``mean_derivative``
    mean of the T trial estimates
``bias``
    mean - reference, with a Student-t interval (T - 1 degrees of freedom) of
    half-width $t · \sqrt{s^2/T + s_\mathrm{ref}^2}$, t at the per-cell coverage that makes the
    intervals of the study's m cells simultaneous at the configuration's ``level`` (default
    :data:`~flatland.core.stats.LEVEL`, :func:`~flatland.core.stats.family_quantile`), plus a
    floating-point allowance of
    :func:`~flatland.core.stats.rounding_floor` ($64 ε$) of the larger of mean and
    reference; a spread of the trials below that counts as zero variance, the
    policy of :data:`flatland.core.stats.ROUNDING`)
``variance_per_sample``
    $s^2 · \mathrm{samples}$ ($s^2$ the variance of the trial estimates), the variance a
    single-sample estimate would have
``seconds_per_sample``
    measured wall time (time.perf_counter) / (T · samples)
``rmse``
    $\sqrt{\mathrm{mean}_k (d_k - \mathrm{reference})^2}$: the error of one trial
``bias_z``, ``biased``
    $z = \mathrm{bias} / \sqrt{\mathrm{stderr}^2 + \mathrm{reference\_stderr}^2}$ (0 within the floating-point
    allowance, ±inf with no noise at all, printed "—"); ``biased`` exactly when the bias interval
    excludes 0 (so |z| above the interval's t); for scenes the per-pixel test of the mean image over the
    trials flags it (:mod:`flatland.core.bias`: $|z_j|$ above the Student-t
    quantile with T - 1 degrees of freedom at the Sidak-corrected level
    $1 - 0.99^{1/m}$ over the m pixels, the stderr the larger of the trials' scatter
    and their pooled batch stderrs; ``pixels_exceeding`` of ``pixels_tested``: shown, not
    a flag, as heavy-tailed pixels break its t law at 8-16 trials)
``efficiency``
    $1 / (\mathrm{variance\_per\_sample} · \mathrm{seconds\_per\_sample})$, infinite for a zero-variance
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
    $\sqrt{\mathrm{bias}^2 + \mathrm{variance\_per\_sample} · \mathrm{seconds\_per\_sample} / B}$: the error
    expected from a time budget of B seconds (``"time_budget"``, default 1 s), which unlike
    efficiency counts the bias

For scenes a "sample" is one camera sample: spp × pixels. A study is run by
:func:`flatland.app.study.run_study`.
"""

from __future__ import annotations

import csv
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from flatland.app.study_config import Cell, StudyConfig
from flatland.app.study_reference import Reference
from flatland.app.study_trials import _Run
from flatland.app.table import (
    format_exact,
    format_interval,
    format_level,
    format_number,
    format_table,
    format_z,
    own_method_note,
)
from flatland.core.bias import PIXEL_ALPHA, REFERENCE_RATIO, PixelTest, pixel_test
from flatland.core.image import relative_error
from flatland.core.stats import (
    LEVEL,
    ROUNDING,
    family_level,
    family_quantile,
    normal_quantile,
    rounding_floor,
    spread,
    z_score,
)

__all__ = ["CSV_COLUMNS", "CellResult", "StudyResult", "read_csv"]

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
        """True if the bias interval excludes 0 (the table prints BIASED). The per-pixel test
        (``pixels``) is shown but does not flag: with 8-16 trials its t law fails for heavy-tailed
        pixels (a finite-difference cell against a same-method reference exceeded)."""
        return not self.bias_contains_zero()

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
    cell: Cell, runs: Sequence[_Run], reference: Reference, level: float, budget: float, cells: int = 1
) -> CellResult:
    """One cell's statistics; its bias interval is one of ``cells`` simultaneous ones at ``level``."""
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
    half = family_quantile(cells, level, dof=t - 1) * math.sqrt(var / t + reference.stderr**2) + resolution
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
    # efficiency ignores bias: defined only for a cell whose interval contains 0 (infinite for a
    # zero-variance estimator), never for a biased one
    unbiased = bias - half <= 0 <= bias + half
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
        """A fixed-width text table, best first; the bias columns lead, the legend under it says what
        every column counts."""
        level = format_level(self.config.level)
        scene = self.config.problem.is_scene
        head = ("method", "rank", "bias z", "flag", *(("px |z|>t",) if scene else ()),
                f"bias [{level} interval]", "efficiency", "rmse", "var/sample", "s/trial",
                "mean dI/dθ")  # fmt: skip
        rows = [
            (
                r.cell.label
                + ("" if len(self.sample_counts) == 1 else f" {self.config.problem.count_name}={r.cell.n}"),
                str(r.rank),
                format_z(r.bias_z),
                "BIASED" if r.biased else "",
                *((r.pixels.summary(),) if r.pixels is not None else ()),
                _format_bias(r),
                _format_efficiency(r),
                f"{r.rmse:.3g}",
                f"{r.variance_per_sample:.3g}",
                f"{r.seconds_per_trial:.3g}",
                _format_mean(r),
            )
            for r in self.ranking()
        ]
        title = f"{self.config.problem.label}: reference dI/dθ = {_format_reference(self.reference)}"
        return format_table(head, rows, title) + "\n" + self.footer()

    @property
    def sample_counts(self) -> tuple[int, ...]:
        """The distinct per-trial sample counts of the grid, ascending."""
        return tuple(sorted({r.cell.n for r in self.rows}))

    def footer(self) -> str:
        """The legend: what every column counts, the tests behind the flag, how the reference was made."""
        ref = self.reference
        judged = [r.stderr for r in self.rows if not r.biased and r.stderr > 0.0]
        ratio = f"{ref.stderr / min(judged):.2f}" if judged else "n/a"
        m, trials, level = len(self.rows), self.config.trials, self.config.level
        q = family_quantile(m, level, dof=trials - 1)
        count = "pixel samples (spp × pixels)" if self.config.problem.is_scene else "samples"
        lines = [
            f"reference: {ref.source}, stderr {ref.stderr:.2g} = {ratio} × the smallest unbiased-row stderr"
            f" (required <= {REFERENCE_RATIO:g})",
            f"bias [{format_level(level)} interval]: mean of the {trials} trials - reference, its interval"
            f" simultaneous over the {m} rows: ± {q:.2f} sqrt(stderr² + stderr_ref²)",
            f"  (Student-t, {trials - 1} dof, per row {family_level(m, level):.2%}); BIASED exactly when the"
            " interval excludes 0; (σ = 0): every trial gave the same number",
            "bias z: bias / sqrt(stderr² + stderr_ref²) (stderr of the mean of the trials); BIASED when"
            f" |z| > {q:.2f}; — : no spread, no z",
        ]
        if self.config.problem.is_scene:
            lines += [
                "px |z|>t: k/m, k the pixels of the mean image whose |z| exceeds t (Student-t, trials - 1"
                f" dof, level 1-{1 - PIXEL_ALPHA:g}^(1/m)), m the pixels",
                "  with a positive stderr (the others have no variance to test); about"
                f" {PIXEL_ALPHA:g} expected if unbiased; shown, not a flag (heavy-tailed pixels)",
            ]
        lines += [
            f"efficiency = 1/(var/sample × s/sample), unbiased rows only (σ²=0: no variance); var/sample: the"
            f" trials' variance × {count} per trial",
            "rmse: root mean square error of one trial (bias and noise); s/trial: seconds per trial;"
            " mean dI/dθ: mean of the trials",
            "rank: unbiased rows by efficiency, then the rest by equal-time RMSE",
        ]
        if self.config.reference is not None:
            note = own_method_note((c.method for c in self.config.cells), self.config.reference.method)
            lines += [note] if note else []
        return "\n".join(lines)


def _format_reference(ref: Reference) -> str:
    """The reference value: a closed form, or a Monte Carlo estimate with its LEVEL interval."""
    if ref.n is None:
        return f"{ref.derivative:+.6g} (closed form)"
    if not ref.stderr > 0.0:
        return format_exact(ref.derivative)
    half = normal_quantile(LEVEL) * ref.stderr
    interval = format_interval(ref.derivative, ref.derivative - half, ref.derivative + half)
    return f"{interval} ({format_level(LEVEL)} interval)"


def _format_bias(row: CellResult) -> str:
    """The bias and its interval; a bias without any spread (trials and reference exact) is exact."""
    if row.stderr > 0.0 or row.reference_stderr > 0.0:
        return format_interval(row.bias, row.bias_low, row.bias_high)
    return format_exact(row.bias)


def _format_mean(row: CellResult) -> str:
    """The mean of the trials to two significant digits of its standard error."""
    if not row.stderr > 0.0:
        return f"{row.mean_derivative:+.6g}"
    return format_number(row.mean_derivative, row.stderr)


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
