"""Gradients on light paths in sphere3d: max_depth 4 against finite differences and the production anchors.

For ``glossy_reflection`` (``hard_shadow`` with a rough GGX conductor ground, α = 0.15, F = 1) and
``interreflection`` (a box of diffuse walls of albedo 0.7, open at the front and top, around the
same light and occluder) at 64 x 64 pixels, ``max_depth`` 4 (paths of up to four vertices: the
camera ray and three more segments, Mitsuba's ``max_depth`` 4 counting the emitter's segment),
θ = ``occluder.translate.x``.

**Reference** (:mod:`benchmarks.paths_reference`, cached in ``.cache/paths_reference``): per pixel
the Richardson extrapolation (4 D(h/2) - D(h)) / 3 of central finite differences at h = 0.01 with
common random numbers (the four renders of a pass share every sample), unbiased up to O(h⁴),
averaged over :data:`~benchmarks.paths_reference.PASSES` passes of 1024 spp; its spp and
standard error are a row. The same passes at depth 2
give the RMS of (depth 4 - depth 2), what the third and fourth vertices add to the gradient.

**Rows** per scene and method (``reparam``, ``boundary`` where it takes depth 4, ``naive``, whose
error is its missing boundary terms): the RMSE at 16, 64 and 256 spp, sqrt of the mean over
:data:`SEEDS` and pixels of (g - ref)² minus the reference's mean variance (so it estimates the
error against the exact derivative); the bias floor at 256 spp
(:func:`benchmarks.bench_hard_shadow.bias_floor`: the per-pixel mean over the seeds, their noise
and the reference's subtracted); the seconds per image (fastest seed) and their ratio to the
depth-4 primal at the same spp (best of :data:`REPEATS`). Cost rows: the depth-4 primal over the
depth-1 primal (64 spp) and the depth-4 ``reparam`` gradient over the depth-4 primal per spp.
Timings are wall clock on a machine shared with other work: indicative only.

**Anchors** (:data:`ANCHORS`, measured outside this project on scenes built the same way, Mitsuba's
``prb_reparam`` 3.4.1 and ``prb_projective`` 3.9.1): each row's note quotes them and says whether the
goal is met. Goals: ``reparam``'s RMSE below ``prb_reparam``'s at every spp with a bias floor at
most :data:`BIAS_GOAL`; ``boundary``'s RMSE within 1.5 x ``prb_projective``'s at a fifth of its
fastest image time or less; cost: ``reparam`` at most 4 x the primal per spp, the depth-4 primal
at most 3 x depth 1. The anchors' scenes are built like these, not identical (camera, image RMS),
so the comparison is of orders of magnitude and of the ratios to each scene's own gradient.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks import Row, best_seconds
from benchmarks.bench_hard_shadow import bias_floor
from benchmarks.paths_reference import PARAM, SCENES, reference
from flatland.core.validate import ValidationError
from sphere3d import render, render_gradient

__all__ = ["ANCHORS", "rmse_exact", "run"]

DEPTH = 4
SPPS = (16, 64, 256)
SEEDS = (1, 2, 3)
REPEATS = 3
METHODS = ("reparam", "boundary", "naive")
BIAS_GOAL = 0.05
ANCHORS = {
    "glossy_reflection": {
        "reparam": {16: 1.02, 64: 0.49, 256: 0.33, "bias": (0.20, 0.25), "ratio": (7, 13)},
        "projective": {16: 0.17, 64: 0.079, 256: 0.050, "bias": (0.02, 0.03), "seconds": (7, 25)},
        "rms": 0.82,
        "depth_difference": 0.06,
    },
    "interreflection": {
        "reparam": {16: 1.06, 64: 0.62, 256: 0.38, "bias": (0.23, 0.32), "ratio": (14, 21)},
        "projective": {16: 0.18, 64: 0.097, 256: 0.050, "bias": None, "seconds": (13, 41)},
        "rms": 0.93,
        "depth_difference": 0.27,
    },
}
"""Mitsuba 3.4.1 ``prb_reparam`` and 3.9.1 ``prb_projective`` on scenes built like these (64 x 64,
``max_depth`` 4): RMSE per spp, bias range, time (ratio to the primal, or seconds per image), the
gradient image's RMS and the RMS of depth 4 - depth 2."""


def rmse_exact(images: np.ndarray, ref: np.ndarray, ref_stderr: np.ndarray) -> float:
    """sqrt(mean over seeds and pixels of (g - ref)² - mean(se²)): the RMSE against the exact
    derivative, the reference's noise (independent of the images) subtracted; 0 if negative."""
    return float(np.sqrt(max(0.0, np.mean((images - ref) ** 2) - np.mean(ref_stderr**2))))


def _met(ok: bool) -> str:
    return "met" if ok else "not met"


def _primal_seconds(scene: str) -> dict[int, float]:
    return {spp: best_seconds(lambda s=spp: render(scene, spp=s, max_depth=DEPTH), REPEATS) for spp in SPPS}


def _boundary_refusal(scene: str) -> str | None:
    """None if ``boundary`` takes ``max_depth`` 4 on ``scene``, else its refusal's message."""
    try:
        render_gradient(scene, PARAM, method="boundary", spp=1, seed=0, max_depth=DEPTH)
    except ValidationError as e:
        return str(e)
    return None


def _measure(scene: str, method: str) -> tuple[dict[int, np.ndarray], dict[int, float]]:
    images, seconds = {}, {}
    for spp in SPPS:
        runs, times = [], []
        for seed in SEEDS:
            start = time.perf_counter()
            runs.append(
                render_gradient(scene, PARAM, method=method, spp=spp, seed=seed, max_depth=DEPTH).derivative
            )
            times.append(time.perf_counter() - start)
        images[spp], seconds[spp] = np.stack(runs), min(times)
    return images, seconds


def _reference_rows(scene: str, ref: dict) -> list[Row]:
    anchor = ANCHORS[scene]
    rms = float(np.sqrt(np.mean(ref["depth4"] ** 2)))
    noise = float(np.sqrt(np.mean(ref["stderr4"] ** 2)))
    diff = float(np.sqrt(max(0.0, np.mean(ref["difference"] ** 2 - ref["difference_stderr"] ** 2))))
    spp = int(ref["spp"])
    return [
        Row("paths", f"{scene} reference: rms of d/dx", rms, "", f"anchor scene {anchor['rms']}"),
        Row("paths", f"{scene} reference: rms standard error", noise, "", f"FD Richardson h=0.01, {spp} spp"),
        Row(
            "paths",
            f"{scene} reference: rms of depth 4 - depth 2",
            diff,
            "",
            f"{diff / rms:.0%} of the rms; anchor scene {anchor['depth_difference']} of {anchor['rms']}",
        ),
    ]


def _method_rows(scene: str, method: str, ref: dict, primal: dict[int, float]) -> list[Row]:
    anchor = ANCHORS[scene]
    images, seconds = _measure(scene, method)
    rows = []
    for spp in SPPS:
        error = rmse_exact(images[spp], ref["depth4"], ref["stderr4"])
        if method == "reparam":
            target = anchor["reparam"][spp]
            note = f"prb_reparam {target}: {_met(error < target)}"
        elif method == "boundary":
            target = anchor["projective"][spp]
            note = f"prb_projective {target}, goal <= {1.5 * target:.3g}: {_met(error <= 1.5 * target)}"
        else:
            note = "baseline: no boundary terms"
        rows.append(Row("paths", f"{scene} {method} {spp} spp: RMSE", error, "", note))
    floor = bias_floor(images[SPPS[-1]], ref["depth4"], ref["stderr4"])
    if method == "reparam":
        low, high = anchor["reparam"]["bias"]
        note = f"prb_reparam {low}-{high}; goal <= {BIAS_GOAL}: {_met(floor <= BIAS_GOAL)}"
    else:
        note = f"{len(SEEDS)} seeds, {SPPS[-1]} spp"
    rows.append(Row("paths", f"{scene} {method}: bias floor", floor, "rms", note))
    for spp in SPPS:
        ratio = seconds[spp] / primal[spp]
        if method == "boundary":
            fastest = anchor["projective"]["seconds"][0]
            goal = fastest / 5
            note = f"prb_projective {fastest}+ s, goal <= {goal:.3g} s: {_met(seconds[spp] <= goal)}"
        elif method == "reparam":
            low, high = anchor["reparam"]["ratio"]
            note = f"prb_reparam {low}-{high} x its primal"
        else:
            note = f"{ratio:.1f} x primal"
        rows.append(Row("paths", f"{scene} {method} {spp} spp: seconds", seconds[spp], "s", note))
        if method == "reparam":  # the cost row: gradient / primal at the same depth and spp
            case = f"{scene} reparam / primal, depth {DEPTH}, {spp} spp"
            rows.append(Row("paths", case, ratio, "x", f"goal <= 4: {_met(ratio <= 4.0)}"))
    return rows


def _cost_rows(scene: str, primal: dict[int, float]) -> list[Row]:
    one = best_seconds(lambda: render(scene, spp=64, max_depth=1), REPEATS)
    ratio = primal[64] / one
    return [
        Row("paths", f"{scene} primal 64 spp, depth 1", one, "s"),
        *(Row("paths", f"{scene} primal {spp} spp, depth {DEPTH}", primal[spp], "s") for spp in SPPS),
        Row("paths", f"{scene} primal: depth 4 / depth 1", ratio, "x", f"goal <= 3: {_met(ratio <= 3.0)}"),
    ]


def run() -> list[Row]:
    """The rows of this page: per scene the reference, the methods' errors and times, the cost ratios."""
    rows = []
    for scene in SCENES:
        ref = reference(scene)
        primal = _primal_seconds(scene)
        rows += _reference_rows(scene, ref) + _cost_rows(scene, primal)
        refusal = _boundary_refusal(scene)
        for method in METHODS:
            if method == "boundary" and refusal is not None:
                note = f"refused: {refusal}"
                rows.append(Row("paths", f"{scene} boundary: skipped", float("nan"), "", note))
                continue
            rows += _method_rows(scene, method, ref, primal)
    return rows
