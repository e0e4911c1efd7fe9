"""Glossy shapes and paths in sphere3d: cost by depth, and the gradients on ``glossy_reflection``.

``glossy_reflection`` is ``hard_shadow`` with its ground a rough GGX conductor (roughness 0.15, F =
1; theory/bsdf); ``interreflection`` a diffuse box open at the front and top around the same light
and occluder. Rows:

- the primal at 64 x 64 and 16 spp for ``max_depth`` 1, 2 and 4 on both scenes (best of
  :data:`REPEATS`; meaningful on an idle machine only), and the ratio of depth 4 to depth 1;
- d/d ``occluder.translate.x`` of ``glossy_reflection`` at depth 1 (depth 4:
  :mod:`benchmarks.bench_paths_sphere3d`): against a ``boundary`` reference of :data:`REF_SPP` spp (its
  own seed; ``boundary`` agrees with finite differences region by region, tests/sphere3d/test_glossy.py
  test09), the RMSE at 16, 64 and 256 spp (mean over :data:`SEEDS`), the bias floor at 256 spp
  (:func:`benchmarks.bench_hard_shadow.bias_floor`: the rms per-pixel bias of the mean over the
  seeds, their noise and the reference's subtracted) and the seconds per image at 64 spp, for
  ``reparam``, ``boundary`` and ``naive`` (naive's error is its missing boundary terms; boundary's
  floor, against a reference of its own, says only that its seeds agree);
- the region sums of that derivative image (32 x 32, 1024 spp, 16 batches) for ``reparam`` and
  ``boundary``: the shadow's trailing and leading halves, the occluder's reflection, the occluder
  (tests/sphere3d/test_glossy.py), mean and standard error over the batches.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks import Row, best_seconds
from benchmarks.bench_hard_shadow import bias_floor, rmse
from sphere3d import render, render_gradient
from sphere3d.methods import GRADIENT_METHODS
from sphere3d.scene import Scene, load_scene
from sphere3d.state import build_state
from sphere3d.tasks import ImageTask

__all__ = ["reflection", "regions", "run", "shadow_halves"]

SCENE = "glossy_reflection"
PARAM = "occluder.translate.x"
REPEATS = 3
REF_SPP = 1024
SPPS = (16, 64, 256)
SEEDS = (1, 2, 3)
METHODS = ("reparam", "boundary", "naive")


def _primary(scene: Scene, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per pixel centre of a width x width film: the primary ray's direction, its hit shape (-1: none)
    and its hit point (the camera's position where it misses)."""
    state = build_state(scene)
    rows, cols = np.mgrid[0:width, 0:width]
    d = state.camera.directions(cols.ravel() + 0.5, rows.ravel() + 0.5)
    origin = np.broadcast_to(np.asarray(state.camera.origin), d.shape).copy()
    hits = state.tracer.intersect(origin, d)
    return d, hits.shape, origin + np.where(hits.hit, hits.t, 0.0)[:, None] * d


def _floor(scene: Scene) -> int:
    names = [s.name for s in scene.shapes]
    return names.index("ground" if "ground" in names else "floor")


def _centre(scene: Scene, name: str) -> np.ndarray:
    return np.array(next(s.translate for s in scene.shapes if s.name == name))


def shadow_halves(scene: Scene, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixels whose centre's primary ray meets the floor within 0.6 of the occluder's shadow centre (the
    light's centre projected through the occluder's centre onto z = 0), on its trailing (x below the
    centre) and leading side for a move along +x."""
    _, shape, point = _primary(scene, width)
    light, occluder = _centre(scene, "light"), _centre(scene, "occluder")
    centre = light + (occluder - light) * light[2] / (light[2] - occluder[2])
    shadow = (shape == _floor(scene)) & (np.linalg.norm(point - centre, axis=1) < 0.6)
    trailing = shadow & (point[:, 0] < centre[0])
    return trailing.reshape(width, width), (shadow & ~trailing).reshape(width, width)


def reflection(scene: Scene, width: int) -> np.ndarray:
    """Floor pixels (pixel centres) whose mirror ray (about +z) passes within 0.5 of the occluder's centre,
    off its shadow: where the glossy floor reflects the occluder (and, at depth 1, the occluder hides
    part of the light's reflection)."""
    d, shape, point = _primary(scene, width)
    mirror = d * np.array([1.0, 1.0, -1.0])
    to = _centre(scene, "occluder") - point
    miss = np.linalg.norm(to - np.sum(to * mirror, axis=1)[:, None] * mirror, axis=1)
    trailing, leading = shadow_halves(scene, width)
    return ((shape == _floor(scene)) & (miss < 0.5)).reshape(width, width) & ~trailing & ~leading


def regions(scene: Scene, width: int) -> dict[str, np.ndarray]:
    """The shadow's halves (:func:`shadow_halves`), the occluder's reflection (:func:`reflection`) and the
    occluder's own pixels, as boolean (width, width) masks by name."""
    trailing, leading = shadow_halves(scene, width)
    occluder = _primary(scene, width)[1] == [s.name for s in scene.shapes].index("occluder")
    return {
        "trailing": trailing,
        "leading": leading,
        "reflection": reflection(scene, width),
        "occluder": occluder.reshape(width, width),
    }


def _cost() -> list[Row]:
    rows = []
    for scene in (SCENE, "interreflection"):
        seconds = {}
        for d in (1, 2, 4):
            seconds[d] = best_seconds(lambda d=d, scene=scene: render(scene, spp=16, max_depth=d), REPEATS)
        for d, s in seconds.items():
            rows.append(Row("glossy", f"{scene} primal, 64 x 64, 16 spp, max_depth {d}", s, "s"))
        rows.append(
            Row("glossy", f"{scene} primal: depth 4 / depth 1", seconds[4] / seconds[1], "x", "goal <= 3")
        )
    return rows


def _gradients() -> list[Row]:
    ref = render_gradient(SCENE, PARAM, method="boundary", spp=REF_SPP, seed=100)
    rms = float(np.sqrt(np.mean(ref.derivative**2)))
    rows = [Row("glossy", f"{SCENE} d/dx reference (boundary, {REF_SPP} spp): rms", rms, "", "depth 1")]
    for method in METHODS:
        images, seconds = {}, []
        for spp in SPPS:
            runs = []
            for seed in SEEDS:
                start = time.perf_counter()
                runs.append(render_gradient(SCENE, PARAM, method=method, spp=spp, seed=seed).derivative)
                if spp == 64:
                    seconds.append(time.perf_counter() - start)
            images[spp] = np.stack(runs)
            rows.append(
                Row("glossy", f"{SCENE} {method} {spp} spp: RMSE", rmse(images[spp], ref.derivative), "")
            )
        floor = bias_floor(images[SPPS[-1]], ref.derivative, ref.derivative_stderr)
        rows.append(
            Row("glossy", f"{SCENE} {method}: bias floor", floor, "rms", f"{len(SEEDS)} seeds, 256 spp")
        )
        rows.append(Row("glossy", f"{SCENE} {method}: seconds at 64 spp", min(seconds), "s"))
    return rows


def _region_sums() -> list[Row]:
    d = load_scene(SCENE).to_dict()
    d["camera"].update(width=32, height=32)
    scene = load_scene(d)
    parts = regions(scene, 32)
    rows = []
    for method, seed in (("reparam", 1), ("boundary", 4)):
        g = GRADIENT_METHODS.run(method, ImageTask(scene, PARAM, 1024, seed, 16)).derivative
        for name, r in parts.items():
            sums = g[:, r].sum(axis=1)
            se = float(sums.std(ddof=1) / np.sqrt(sums.size))
            rows.append(
                Row("glossy", f"{SCENE} {method}: {name} region sum", float(sums.mean()), "", f"± {se:.3g}")
            )
    return rows


def run() -> list[Row]:
    """The rows of this page: the cost by depth, the gradients' errors and the region sums."""
    return _cost() + _gradients() + _region_sums()
