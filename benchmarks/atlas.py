r"""The bias atlas: every gradient method against closed forms, over motions, feature sizes, viewing
angles and filters, in both packages (``python -m benchmarks.atlas [--quick]``, or ``make bench``).

Each cell is one case of :mod:`benchmarks.atlas_cases` (a black triangle, convex mesh or segment
under the sky, one motion, one size, one viewing angle, one filter) and one method, rendered in ``BATCHES``
independent batches. It reports the share of the derivative the method loses and its z-score:

film
    $\mathrm{lost} = 1 - Σ_p \mathrm{sign}(g_p) d_p / Σ_p |g_p|$ over the pixels
    (:func:`sphere3d.closed_form.share_lost`; g the closed form, d the estimate), per batch; the
    ± is the batch means' standard error. Positive: the estimate falls short of the derivative.
shading
    $\mathrm{lost} = (g - d) / G$, G the gross boundary flux $∮ |f (v·n)| dl$ (over a mesh's outline:
    :func:`sphere3d.closed_form.boundary_flux`, :func:`flatland.closed_form.boundary_flux`): for a
    motion whose net derivative is a small difference of large parts (a small triangle turning
    about its centre), the error is measured against the moving boundary the method must follow.
    The closed form is taken where the renderer evaluates the integral: sphere3d's ray origin
    (:meth:`benchmarks.atlas_cases.Case.origin`).

z = lost / ±, Student's t with BATCHES - 1 degrees of freedom (a method that draws no random
numbers in a cell, flatland's film ``boundary`` or ``naive`` here, has no ±: it reads ``exact, off``
and is flagged when its share lost exceeds rounding; ``finite_difference`` with every batch exactly
0 reads ``no event``, below); a cell is flagged ``z`` where |z|
exceeds the two-sided quantile at the Šidák-corrected level $1 - (1 - α)^{1/m}$ over the m cells of
the atlas (α = :data:`ALPHA`). ``finite_difference`` is measured against its own expectation, the
closed form's central difference at its step h (its truncation is the column ``trunc``). With
common random numbers its estimate is a sum over the samples whose contribution changes between
θ - h and θ + h, rare events with a probability of order h per sample near a moving edge: when
no sample of any batch changed, every batch is exactly 0, and the cell cannot tell a bias from
no event. It reads ``no event``, is neither flagged nor passed, and the summary counts such
cells (more samples, or a larger h, would measure them).
The goals are flagged as ``> 5 %`` (a feature of at least 2 px on the film or 0.1 rad in shading,
seen at 10 degrees or more, off by more than 5 %) and ``reach`` (a smaller feature off by more than
10 %), where the z flag also holds.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from benchmarks.atlas_cases import FAMILIES, Case, grid
from flatland.core.stats import sidak

__all__ = ["ALPHA", "BATCHES", "METHODS", "Cell", "measure", "run_atlas", "table"]

ALPHA = 0.01
"""Family-wise level of the z flags over all cells of one atlas."""
BATCHES = 16
SEED = 7
METHODS = {
    # label: (method, options, packages)
    "reparam": ("reparam", {}, ("sphere3d", "flatland")),
    "reparam paper": ("reparam", {"variant": "paper"}, ("sphere3d",)),
    "boundary": ("boundary", {}, ("sphere3d", "flatland")),
    "finite_difference": ("finite_difference", {}, ("sphere3d", "flatland")),
}
FD_STEP = {"sphere3d": 1e-2, "flatland": 1e-3}
"""The packages' default finite-difference steps (the methods' documented defaults)."""
SAMPLES = {"film": 1 << 18, "shading": 1 << 20, "light": 1 << 16}
"""Camera samples per film cell (spp times pixels), shading samples per shading cell (full grid); under
the light (``sphere3d light``) fewer: each sample's probes, shadow rays and edge terms cost several
times a sky sample's (the standard errors say what that leaves)."""
QUICK_SAMPLES = {"film": 1 << 16, "shading": 1 << 18, "light": 1 << 14}
ROUNDING = 1e-9
"""A share lost below this, by a method without a spread, is rounding."""
OUT = Path(__file__).resolve().parent.parent / "docs" / "measurements" / "atlas.md"


@dataclass(frozen=True)
class Cell:
    """One line of the atlas: a case, a method, the share lost, its standard error and z, the share
    the method is expected to lose (finite differences' truncation; 0 otherwise), seconds taken."""

    case: Case
    method: str
    lost: float
    stderr: float
    expected: float
    seconds: float
    silent: bool = False
    """Finite differences that saw no event: every batch exactly 0 (module docstring)."""

    @property
    def z(self) -> float:
        """(lost - expected) / stderr; without a spread (a method that draws no random numbers here),
        ±inf if it is off by more than rounding (:data:`ROUNDING`), else 0; nan for a silent cell."""
        if self.silent:
            return math.nan
        off = self.lost - self.expected
        if self.stderr > 0.0:
            return off / self.stderr
        return math.copysign(math.inf, off) if abs(off) > ROUNDING else 0.0

    def goal(self) -> float | None:
        """The tolerance this cell is held to (0.05 or 0.10), None below 10 degrees."""
        if self.case.angle < 10.0:
            return None
        large = self.case.size >= (2.0 if self.case.film else 0.1)
        return 0.05 if large else 0.10

    def flags(self, quantile: float) -> str:
        """``z`` beyond the quantile; ``> 5 %`` / ``reach`` beyond the goal's tolerance as well; never
        for a silent cell."""
        if self.silent or abs(self.z) <= quantile:
            return ""
        tolerance = self.goal()
        if tolerance is not None and abs(self.lost) > tolerance:
            return "z, > 5 %" if tolerance == 0.05 else "z, reach"
        return "z"


def _samples(case: Case, quick: bool) -> int:
    kind = "film" if case.film else ("light" if case.family == "sphere3d light" else "shading")
    return (QUICK_SAMPLES if quick else SAMPLES)[kind]


def _tally(case: Case, method: str, options: dict[str, Any], quick: bool) -> np.ndarray:
    """Per-batch derivative estimates: images (B, ...) for the film, numbers (B,) for shading."""
    n = _samples(case, quick)
    if case.package == "sphere3d":
        from sphere3d.methods import GRADIENT_METHODS
        from sphere3d.scene import load_scene
        from sphere3d.tasks import ImageTask, PointTask

        scene = load_scene(case.scene())
        if case.film:
            pixels = scene.camera.width * scene.camera.height
            spp = max(BATCHES, n // pixels // BATCHES * BATCHES)
            task = ImageTask(scene, case.param, spp, SEED, BATCHES)
        else:
            task = PointTask(scene, case.param, case.point, case.normal, n, SEED, BATCHES)
        return np.asarray(GRADIENT_METHODS.run(method, task, **options).derivative)
    from flatland.methods import GRADIENT_METHODS as FLAT_METHODS
    from flatland.scene import load_scene as load_flat
    from flatland.state import parse_parameter
    from flatland.tasks import ImageTask as FlatImage
    from flatland.tasks import PointTask as FlatPoint

    scene = load_flat(case.scene())
    p = parse_parameter(scene, case.param)
    if case.film:
        spp = max(BATCHES, n // scene.camera.pixels // BATCHES * BATCHES)
        task = FlatImage(scene, p, spp, SEED, BATCHES)
    else:
        task = FlatPoint(scene, p, case.point, case.normal, n, SEED, BATCHES)
    derivative = np.asarray(FLAT_METHODS.run(method, task, **options).derivative)
    return derivative if case.film else derivative[:, 0]


def _scale(case: Case, exact: Any) -> float:
    """What the shading integral's error is measured against: the gross boundary flux."""
    return case.flux()


def _lost(case: Case, batches: np.ndarray, exact: Any, scale: float | None) -> np.ndarray:
    """The share lost per batch (module docstring)."""
    if case.film:
        g = np.asarray(exact, dtype=np.float64).ravel()
        d = batches.reshape(len(batches), -1)
        return 1.0 - (d @ np.sign(g)) / np.sum(np.abs(g))
    return (float(exact) - batches.ravel()) / scale


def measure(case: Case, label: str, quick: bool = False) -> Cell:
    """One cell: ``case`` rendered by the method ``label`` of :data:`METHODS`."""
    method, options, _ = METHODS[label]
    options = dict(options)
    exact = case.derivative()
    scale = None if case.film else _scale(case, exact)
    expected = 0.0
    if method == "finite_difference":
        h = FD_STEP[case.package]
        options["h"] = h
        cd = case.central_difference(h)
        expected = float(np.mean(_lost(case, np.asarray(cd)[None], exact, scale)))
    start = time.perf_counter()
    batches = _tally(case, method, options, quick)
    seconds = time.perf_counter() - start
    lost = _lost(case, batches, exact, scale)
    stderr = float(lost.std(ddof=1) / math.sqrt(len(lost)))
    silent = method == "finite_difference" and not np.any(batches)  # no sample changed: no event
    return Cell(case, label, float(lost.mean()), stderr, expected, seconds, silent)


def quantile(cells: int) -> float:
    """The two-sided Student-t quantile at the Šidák level over ``cells`` cells (module docstring)."""
    return float(stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, max(cells, 1)), BATCHES - 1))


def run_atlas(
    quick: bool = False,
    families: tuple[str, ...] = FAMILIES,
    methods: tuple[str, ...] = tuple(METHODS),
    progress: bool | None = None,
) -> list[Cell]:
    """Every cell of the (quick) grid of ``families`` for ``methods``, with a progress bar."""
    jobs = [
        (case, label)
        for case in grid(quick, families)
        for label in methods
        if case.package in METHODS[label][2]
    ]
    show = sys.stderr.isatty() if progress is None else progress
    if show:
        from tqdm import tqdm

        jobs = tqdm(jobs, desc="atlas", unit="cell", file=sys.stderr, dynamic_ncols=True)
    return [measure(case, label, quick) for case, label in jobs]


# ------------------------------------------------------------------ the document
def _row(cell: Cell, q: float) -> str:
    c = cell.case
    unit = "px" if c.film else "rad"
    trunc = f"{100 * cell.expected:+.2f}" if cell.method == "finite_difference" else ""
    z = "exact, off" if math.isinf(cell.z) else f"{cell.z:+.1f}"  # no spread, off beyond rounding
    z = "no event" if cell.silent else z
    return (
        f"| {c.motion} | {c.size:g} {unit} | {c.angle:g} | {c.filter or '-'} | {cell.method} | "
        f"{100 * cell.lost:+.2f} | {100 * cell.stderr:.2f} | {z} | {trunc} | {cell.flags(q)} |"
    )


def summary(cells: list[Cell]) -> list[tuple[str, str, int, int, int, list[Cell], int]]:
    """Per family and method: cells, flagged z, flagged against the goals, the flagged cells
    ordered by |lost| (largest first), and the silent cells (no event)."""
    q = quantile(len(cells))
    out = []
    for family in FAMILIES:
        for label in METHODS:
            mine = [c for c in cells if c.case.family == family and c.method == label]
            if not mine:
                continue
            flagged = sorted((c for c in mine if c.flags(q)), key=lambda c: -abs(c.lost))
            goal = sum(1 for c in flagged if c.flags(q) != "z")
            out.append((family, label, len(mine), len(flagged), goal, flagged, sum(c.silent for c in mine)))
    return out


def table(cells: list[Cell], quick: bool) -> str:
    """The atlas as a Markdown page: the summary, then one table per family, one line per cell."""
    q = quantile(len(cells))
    mode = "quick grid (`python -m benchmarks.atlas --quick`)" if quick else "full grid (`make bench`)"
    lines = [
        "# Bias atlas",
        "",
        f"Generated by `benchmarks/atlas.py`, {mode}; do not edit by hand. "
        "What each column means is in the module's docstring ({mod}`benchmarks.atlas`): *lost* is "
        "the share of the exact derivative the method misses (negative: it overshoots), in percent, "
        "*±* its standard error over "
        f"{BATCHES} independent batches, *z* their ratio (for finite differences against the closed "
        "form's own central difference, whose share is *trunc*). Flags: `z` where |z| > "
        f"{q:.2f} (two-sided Student t, {BATCHES - 1} degrees of freedom, Šidák over the {len(cells)} "
        f"cells at family-wise level {ALPHA:g}); `> 5 %` and `reach` where a flagged cell also misses "
        "the goal (features of at least 2 px on the film or 0.1 rad in shading seen at 10 degrees or "
        "more within 5 %; smaller ones within 10 %, else outside the method's reach). `no event`: finite "
        "differences whose every batch is exactly 0 (no sample changed between θ ± h), not measured.",
        "",
        "## Summary",
        "",
        "| family | method | cells | flagged z | flagged goal | worst flagged cells (lost %) | no event |",
        "|---|---|---|---|---|---|---|",
    ]
    for family, label, n, flagged, goal, worst, silent in summary(cells):
        names = "; ".join(f"{c.case.label().partition(': ')[2]} ({100 * c.lost:+.1f})" for c in worst[:3])
        lines.append(f"| {family} | {label} | {n} | {flagged} | {goal} | {names} | {silent} |")
    for family in FAMILIES:
        mine = [c for c in cells if c.case.family == family]
        if not mine:
            continue
        lines += [
            "",
            f"## {family}",
            "",
            "| motion | size | angle (deg) | filter | method | lost % | ± | z | trunc % | flags |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        lines += [_row(c, q) for c in mine]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.atlas", description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="the quick grid, fewer samples")
    parser.add_argument("--family", action="append", choices=FAMILIES, help="only these families")
    parser.add_argument("--method", action="append", choices=tuple(METHODS), help="only these methods")
    parser.add_argument("--out", type=Path, default=OUT, help=f"Markdown output (default {OUT})")
    args = parser.parse_args(argv)
    cells = run_atlas(args.quick, tuple(args.family or FAMILIES), tuple(args.method or METHODS))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(table(cells, args.quick), encoding="utf-8")
    print(f"{len(cells)} cells -> {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
