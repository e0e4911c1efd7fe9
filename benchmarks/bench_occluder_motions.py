"""sphere3d on the ``hard_shadow`` scenes under every motion of the occluder: bias and RMSE per method.

The ``hard_shadow`` table (:mod:`benchmarks.bench_hard_shadow`) measures one motion, the occluder
translating sideways. Here the occluder of ``hard_shadow`` (an icosphere) and of
``hard_shadow_cube`` (a box) translates along each axis, turns about each axis through its centre
and scales, and ``reparam`` and ``finite_difference`` (default options) are compared pixel by
pixel with ``boundary`` at 4096 spp (seed 100), the unbiased reference of the atlas
(:mod:`benchmarks.atlas`), which carries its own standard error r per pixel.

Rows, per scene, motion and method, relative to the reference's RMS over the image:

- **bias**: from S = 8 seeds at :data:`SPP` spp, per pixel the mean m, the sample variance s², so
  ``sqrt(max(0, mean over pixels of (m - ref)² - s²/S - r²))`` estimates the rms per-pixel bias
  (the estimator of :func:`benchmarks.bench_hard_shadow.bias_floor`); 0 when the noise covers it.
  Finite differences' bias is their truncation at the default step;
- **bias at** :data:`BIAS_SPP` **spp** (``reparam``): the same from S = 8 seeds at :data:`BIAS_SPP`
  spp, where the estimate's own noise, which at :data:`SPP` spp leaves bounds of 6-18 % of the RMS,
  is small enough to say whether a bias floor of a few per cent is there: the floor the RMSE levels
  off at;
- **RMSE at 64 spp**: sqrt of the mean over seeds and pixels of (g - ref)², the reference's own
  noise included (its share is the note's ``ref noise``);
- in the note, the bias's upper bound: the mean squared bias (the mean excess of
  :func:`benchmarks.bench_hard_shadow.bias_excess`) plus its jackknife standard error over the
  seeds times the one-sided Student-t quantile (S - 1 degrees of freedom) at :data:`LEVEL`
  (Šidák over the rows), square-rooted, and whether the bias is resolved (the excess beyond that
  quantile of its error). Where the gradient
  is small against the noise (a smooth sphere turning about its centre), the bias row is noise and
  its bound says how far it reaches.

Each row again **outside junctions**: the same over the pixels more than :data:`JUNCTION_REACH` px
from where the occluder's silhouette meets a static edge on the film (:func:`junction_pixels`: the
ground's far edge against the black sky, here), still relative to the whole image's RMS. There a
film kernel holds two discontinuities with two motions: followed at a T-junction
(:mod:`sphere3d.reparam.junctions`) and where the box's corner lies on the edge
(:mod:`sphere3d.reparam.corner_lines`; tests/sphere3d/test_junctions.py test03 and test06, on
closed forms). The difference of the two rows is what the junctions carry.

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
BIAS_SPP = 512
REFERENCE_SPP, REFERENCE_SEED = 4096, 100
LEVEL = 0.01
"""Family-wise level of the bias bounds, Šidák over the rows."""
JUNCTION_REACH = 2
"""Pixels from a junction left out of the rows "outside junctions": the film filter's reach (a
gaussian's or tent's support, 1.5 px) and a kernel's probe ring about a pixel's samples."""


def junction_pixels(scene: str, reach: int = JUNCTION_REACH) -> np.ndarray:
    """Pixels within ``reach`` px (a square) of both the occluder and two different static things (two
    static shapes, or one and the sky: a miss), from pixel-centre rays at θ0: where the occluder's
    silhouette meets a static edge on the film, a junction (:mod:`sphere3d.reparam.junctions`)."""
    from sphere3d import load_scene
    from sphere3d.state import build_state

    state = build_state(load_scene(scene))
    cam = state.camera
    h, w = cam.height, cam.width
    rows, cols = np.divmod(np.arange(h * w), w)
    d = np.asarray(cam.directions(cols + 0.5, rows + 0.5), dtype=np.float64)
    hits = state.tracer.intersect(np.broadcast_to(np.asarray(cam.origin, dtype=np.float64), d.shape), d)
    seen = np.where(hits.hit, state.shape_of[np.maximum(hits.triangle, 0)], -1).reshape(h, w)
    occluder = [s.name for s in state.scene.shapes].index("occluder")
    size = 2 * reach + 1

    def near(mask: np.ndarray) -> np.ndarray:
        padded = np.pad(mask, reach, mode="edge")
        return np.any([padded[i : i + h, j : j + w] for i in range(size) for j in range(size)], axis=0)

    static = sum(near(seen == thing).astype(int) for thing in np.unique(seen) if thing != occluder)
    return near(seen == occluder) & (static >= 2)


def _rows(
    label: str, images: np.ndarray, ref, scale: float, keep: np.ndarray, count: int
) -> tuple[float, str]:
    """The bias over the pixels ``keep`` (relative to ``scale``) and its note: the bound at the Šidák
    level over ``count`` rows, and whether the bias is resolved."""
    mean, se = bias_excess(images[:, keep], ref.derivative[keep], ref.derivative_stderr[keep])
    q = stats.t.ppf((1.0 - LEVEL) ** (1.0 / count), len(SEEDS) - 1)
    bound = np.sqrt(max(0.0, mean + q * se)) / scale
    bias = bias_floor(images[:, keep], ref.derivative[keep], ref.derivative_stderr[keep]) / scale
    return bias, f"{label}bias <= {bound:.3f} ({'resolved' if mean > q * se else 'not resolved'})"


def measure(scene: str, param: str) -> list[Row]:
    """The rows of one scene and motion (module docstring)."""
    ref = render_gradient(scene, param, method="boundary", spp=REFERENCE_SPP, seed=REFERENCE_SEED)
    scale = float(np.sqrt(np.mean(ref.derivative**2)))
    noise = float(np.sqrt(np.mean(ref.derivative_stderr**2))) / scale
    junctions = junction_pixels(scene)
    everywhere = np.ones_like(junctions)
    count = 2 * len(SCENES) * len(MOTIONS) * (len(METHODS) + 1)  # every row: all pixels, outside junctions
    rows = []
    for method, spp in (*((m, SPP) for m in METHODS), ("reparam", BIAS_SPP)):
        images = np.stack(
            [render_gradient(scene, param, method=method, spp=spp, seed=s).derivative for s in SEEDS]
        )
        if spp != SPP:  # the bias alone, at more samples
            label = f"{scene} {param} {method}: bias / rms at {spp} spp"
            bias, note = _rows("", images, ref, scale, everywhere, count)
            rows.append(Row("occluder motions", label, bias, "", note))
            bias, note = _rows(
                f"{int(junctions.sum())} junction px left out; ", images, ref, scale, ~junctions, count
            )
            rows.append(Row("occluder motions", f"{label} outside junctions", bias, "", note))
            continue
        error = rmse(images, ref.derivative) / scale
        bias, note = _rows("", images, ref, scale, everywhere, count)
        note += f"; RMSE {error:.3f} at {SPP} spp; ref noise {noise:.3f}; gradient rms {scale:.3g}"
        rows.append(Row("occluder motions", f"{scene} {param} {method}: bias / rms", bias, "", note))
        bias, note = _rows(
            f"{int(junctions.sum())} junction px left out; ", images, ref, scale, ~junctions, count
        )
        rows.append(
            Row("occluder motions", f"{scene} {param} {method}: bias / rms outside junctions", bias, "", note)
        )
    return rows


def run() -> list[Row]:
    """Every scene and motion."""
    return [row for scene in SCENES for param in MOTIONS for row in measure(scene, param)]
