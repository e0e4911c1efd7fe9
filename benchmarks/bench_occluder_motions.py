"""sphere3d on the ``hard_shadow`` scenes under every motion of the occluder: bias and RMSE per method.

The ``hard_shadow`` table (:mod:`benchmarks.bench_hard_shadow`) measures one motion, the occluder
translating sideways. Here the occluder of ``hard_shadow`` (an icosphere) and of
``hard_shadow_cube`` (a box) translates along each axis, turns about each axis through its centre
and scales, and ``reparam`` and ``finite_difference`` (default options) are compared pixel by
pixel with ``boundary`` at 1024 spp (seed 100), the unbiased reference of the atlas
(:mod:`benchmarks.atlas`), which carries its own standard error r per pixel.

Rows, per scene, motion and method, relative to the reference's RMS over the image:

- **bias**: from S = 8 seeds at 64 spp, per pixel the mean m, the sample variance s², so
  ``sqrt(max(0, mean over pixels of (m - ref)² - s²/S - r²))`` estimates the rms per-pixel bias
  (the estimator of :func:`benchmarks.bench_hard_shadow.bias_floor`); 0 when the noise covers it.
  Finite differences' bias is their truncation at the default step;
- **RMSE at 64 spp**: sqrt of the mean over seeds and pixels of (g - ref)², the reference's own
  noise included (its share is the note's ``ref noise``);
- in the note, the bias's upper bound: the mean squared bias (the mean excess of
  :func:`benchmarks.bench_hard_shadow.bias_excess`) plus its jackknife standard error over the
  seeds times the one-sided Student-t quantile (S - 1 degrees of freedom) at :data:`LEVEL`
  (Šidák over the rows), square-rooted, and whether the bias is resolved (the excess beyond that
  quantile of its error). Where the gradient
  is small against the noise (a smooth sphere turning about its centre), the bias row is noise and
  its bound says how far it reaches.

A bias row above a few percent of the RMS is a method missing part of that motion's derivative
where its RMSE stops falling with more samples; ``finite_difference`` is the control whose bias is
its truncation only.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from benchmarks import Row
from benchmarks.bench_hard_shadow import bias_excess, bias_floor, rmse
from sphere3d import render_gradient

SCENES = ("hard_shadow", "hard_shadow_cube")
AXES = "xyz"
MOTIONS = (
    *(f"occluder.translate.{a}" for a in AXES),
    *(f"occluder.rotate.{a}" for a in AXES),
    "occluder.scale",
)
METHODS = ("reparam", "finite_difference")
SEEDS = tuple(range(1, 9))
SPP = 64
REFERENCE_SPP, REFERENCE_SEED = 1024, 100
LEVEL = 0.01
"""Family-wise level of the bias bounds, Šidák over the rows."""


def measure(scene: str, param: str) -> list[Row]:
    """The rows of one scene and motion (module docstring)."""
    ref = render_gradient(scene, param, method="boundary", spp=REFERENCE_SPP, seed=REFERENCE_SEED)
    scale = float(np.sqrt(np.mean(ref.derivative**2)))
    noise = float(np.sqrt(np.mean(ref.derivative_stderr**2))) / scale
    rows = []
    for method in METHODS:
        images = np.stack(
            [render_gradient(scene, param, method=method, spp=SPP, seed=s).derivative for s in SEEDS]
        )
        bias = bias_floor(images, ref.derivative, ref.derivative_stderr) / scale
        error = rmse(images, ref.derivative) / scale
        mean, se = bias_excess(images, ref.derivative, ref.derivative_stderr)
        q = stats.t.ppf((1.0 - LEVEL) ** (1.0 / (len(SCENES) * len(MOTIONS) * len(METHODS))), len(SEEDS) - 1)
        bound = np.sqrt(max(0.0, mean + q * se)) / scale
        resolved = "resolved" if mean > q * se else "not resolved"
        note = (
            f"bias <= {bound:.3f} ({resolved}); RMSE {error:.3f} at {SPP} spp; ref noise {noise:.3f};"
            f" gradient rms {scale:.3g}"
        )
        rows.append(Row("occluder motions", f"{scene} {param} {method}: bias / rms", bias, "", note))
    return rows


def run() -> list[Row]:
    """Every scene and motion."""
    return [row for scene in SCENES for param in MOTIONS for row in measure(scene, param)]
