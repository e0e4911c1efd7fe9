"""sphere3d accuracy on the ``hard_shadow`` scenes: bias floor, RMSE and time per method, per pixel.

For ``hard_shadow`` (icosphere occluder) and ``hard_shadow_cube`` and the methods ``naive``,
``finite_difference``, ``reparam`` (the default variant, and ``variant="paper"``, the estimator as
published) and ``boundary`` (default options), the derivative image d/d ``occluder.translate.x`` is
compared pixel by pixel with the stored reference (:mod:`benchmarks.hard_shadow_reference`:
Richardson-extrapolated finite differences).

Rows, per scene and method, bias first (a method with a bias floor above its noise is never to be
ranked above an unbiased one by its RMSE alone):

- **bias floor** from S = 6 seeds at 256 spp: per pixel the mean over seeds m, the sample
  variance over seeds s² and the reference's standard error r,
  ``E[(m - ref)²] = b² + σ²/S + r²``, so ``sqrt(max(0, mean over pixels of
  (m - ref)² - s²/S - r²))`` estimates the rms per-pixel bias b (s² is unbiased for σ²; the
  estimate is unbiased for b² but heavy-tailed at few seeds, hence 6);
- **RMSE** at 16, 64 and 256 spp: sqrt of the mean over seeds and pixels of (g - ref)² (4 seeds
  at 16 and 64 spp, 6 at 256); it includes the reference's own noise r², the reference row;
- **seconds per 64 spp** image: wall clock, best of the seeds' runs, all the cores the renderer
  uses; meaningful on an idle machine only.

Every method renders with the default film, ``film="splat"`` (:mod:`sphere3d.film`: every sample
in every pixel its filter covers, as Mitsuba's film); ``reparam (pixel film)`` is ``reparam`` with
``film="pixel"`` (each sample in the pixel that drew it). The notes quote Mitsuba 3.4.1's
``direct_reparam`` on the same scenes (RMSE at 16 / 64 / 256 spp and its bias floor), measured
outside this project.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks import Row
from benchmarks.hard_shadow_reference import PARAM, SCENES, load_reference, path_of
from sphere3d import render_gradient

SEEDS = {16: (1, 2, 3, 4), 64: (1, 2, 3, 4), 256: (1, 2, 3, 4, 5, 6)}
SPPS = tuple(SEEDS)
BIAS_SPP = 256
METHODS = (
    ("naive", "naive", {}),
    ("finite_difference", "finite_difference", {}),
    ("reparam", "reparam", {}),
    ("reparam (paper)", "reparam", {"variant": "paper"}),
    ("reparam (pixel film)", "reparam", {"film": "pixel"}),
    ("boundary", "boundary", {}),
)
"""(row label, method, options), each with the default film (splatted, :mod:`sphere3d.film`, as
Mitsuba's film) but ``reparam (pixel film)``: each sample in the pixel that drew it."""
MITSUBA = {
    "hard_shadow": {16: 0.73, 64: 0.43, 256: 0.27, "bias": 0.21},
    "hard_shadow_cube": {16: 0.83, 64: 0.48, 256: 0.32, "bias": 0.25},
}
"""Mitsuba 3.4.1 ``direct_reparam`` on the same scenes (measured outside this project)."""


def bias_floor(images: np.ndarray, reference: np.ndarray, reference_stderr: np.ndarray) -> float:
    """rms per-pixel bias of the mean of ``images`` (seeds, height, width), noise subtracted (module doc)."""
    s = images.shape[0]
    m = images.mean(axis=0)
    var = images.var(axis=0, ddof=1)
    excess = (m - reference) ** 2 - var / s - reference_stderr**2
    return float(np.sqrt(max(0.0, excess.mean())))


def _excess(images: np.ndarray, reference: np.ndarray, reference_stderr: np.ndarray) -> float:
    s = images.shape[0]
    excess = (images.mean(axis=0) - reference) ** 2 - images.var(axis=0, ddof=1) / s - reference_stderr**2
    return float(excess.mean())


def bias_excess(
    images: np.ndarray, reference: np.ndarray, reference_stderr: np.ndarray
) -> tuple[float, float]:
    """The mean over pixels of the noise-subtracted squared error of :func:`bias_floor` (an unbiased
    estimate of the mean squared per-pixel bias, possibly negative) and its standard error: the
    jackknife over the seeds (each left out in turn), so it measures the noise of the estimate,
    whatever the pixels' correlations, and not how the bias varies over the image. The reference's
    own noise enters every replicate alike and is not in it (the rows give its size)."""
    s = images.shape[0]
    full = _excess(images, reference, reference_stderr)
    keep = ~np.eye(s, dtype=bool)
    loo = np.array([_excess(images[keep[i]], reference, reference_stderr) for i in range(s)])
    return full, float(np.sqrt((s - 1) / s * np.sum((loo - loo.mean()) ** 2)))


def rmse(images: np.ndarray, reference: np.ndarray) -> float:
    """sqrt of the mean over seeds and pixels of the squared error."""
    return float(np.sqrt(np.mean((images - reference) ** 2)))


def measure(scene: str, method: str, ref: dict, **options: object) -> dict:
    """Derivative images for every seed and spp, their RMSE against the reference ``ref``, the bias
    floor and the wall-clock time per 64 spp (``options``: of :func:`~sphere3d.render_gradient`)."""
    images, seconds = {}, []
    for spp in SPPS:
        runs = []
        for seed in SEEDS[spp]:
            start = time.perf_counter()
            runs.append(
                render_gradient(scene, PARAM, method=method, spp=spp, seed=seed, **options).derivative
            )
            if spp == 64:
                seconds.append(time.perf_counter() - start)
        images[spp] = np.stack(runs)
    return {
        "rmse": {spp: rmse(images[spp], ref["derivative"]) for spp in SPPS},
        "bias": bias_floor(images[BIAS_SPP], ref["derivative"], ref["stderr"]),
        "seconds": min(seconds),
        "images": images,
    }


def run() -> list[Row]:
    """The hard_shadow rows of ``make bench``."""
    rows = []
    for scene in SCENES:
        if not path_of(scene).exists():
            rows.append(Row("hard_shadow", f"{scene}: no reference", float("nan"), "", "run the generator"))
            continue
        ref = load_reference(scene)
        rows.append(
            Row(
                "hard_shadow",
                f"{scene} reference noise",
                float(np.sqrt(np.mean(ref["stderr"] ** 2))),
                "rms se",
                f"FD Richardson h={float(ref['h']):g}, {int(ref['spp'])} spp, {int(ref['batches'])} batches",
            )
        )
        target = MITSUBA[scene]
        for label, method, options in METHODS:
            result = measure(scene, method, ref, **options)
            case = f"{scene} {label}"
            rows.append(
                Row("hard_shadow", f"{case}: bias floor", result["bias"], "rms", f"Mitsuba {target['bias']}")
            )
            for spp in SPPS:
                rows.append(
                    Row(
                        "hard_shadow",
                        f"{case}: RMSE {spp} spp",
                        result["rmse"][spp],
                        "rms",
                        f"Mitsuba {target[spp]}",
                    )
                )
            rows.append(Row("hard_shadow", f"{case}: 64 spp", result["seconds"], "s"))
    return rows
