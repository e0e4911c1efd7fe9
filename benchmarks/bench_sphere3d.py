"""sphere3d: Embree throughput, seconds per ``reparam`` gradient image of ``shadow``, and memory peaks.

Rows: rays per second of the Embree queries the renderer makes (first hits with
barycentrics, and occlusion), best of 3 batches of 2^20 rays in the ``shadow`` scene;
seconds per 64 × 64 gradient image of ``shadow`` (d/d occluder.translate.x) by
``reparam`` with 4 probes at 16, 64 and 256 samples per pixel (best of 2 below 256,
one run at 256), with ``naive`` and a plain render at 64 spp for scale; the peak of
numpy/Python allocations during one 64-spp ``reparam`` image (tracemalloc), and the
process's peak resident set size (getrusage) after all runs.
"""

from __future__ import annotations

import resource
import sys
import tracemalloc

import numpy as np

from benchmarks import Row, best_seconds
from flatland.core.rng import stream
from sphere3d import load_scene, render, render_gradient
from sphere3d.state import build_state
from sphere3d.vector import normalize

SCENE = "shadow"
PARAM = "occluder.translate.x"
RAYS = 1 << 20
TARGET = "target <= 1 s at 64 spp on 2 cores"


def _rays_per_second() -> list[Row]:
    state = build_state(load_scene(SCENE))
    rng = stream(0, "bench_sphere3d")
    origins = rng.uniform(-2.0, 2.0, (RAYS, 3)) + np.array([0.0, 0.0, 1.5])
    targets = rng.uniform(-1.0, 1.0, (RAYS, 3)) * [2.0, 2.0, 0.5] + [0.0, 0.0, 0.5]
    dirs = normalize(targets - origins)
    tmax = np.linalg.norm(targets - origins, axis=1)
    hit = best_seconds(lambda: state.tracer.intersect(origins, dirs), 3)
    occ = best_seconds(lambda: state.tracer.occluded(origins, dirs, tmax), 3)
    return [
        Row("sphere3d", "Embree first hits (+ barycentrics)", RAYS / hit / 1e6, "M rays/s", SCENE),
        Row("sphere3d", "Embree occlusion", RAYS / occ / 1e6, "M rays/s", SCENE),
    ]


def _image_seconds() -> list[Row]:
    scene = load_scene(SCENE)
    rows = []
    render_gradient(scene, PARAM, method="reparam", spp=1)  # warm-up: imports, Embree, tables
    for spp in (16, 64, 256):
        seconds = best_seconds(
            lambda s=spp: render_gradient(scene, PARAM, method="reparam", spp=s),
            1 if spp == 256 else 2,
        )
        rows.append(
            Row(
                "sphere3d",
                f"reparam gradient 64x64, {spp} spp, 4 probes",
                seconds,
                "s",
                TARGET if spp == 64 else SCENE,
            )
        )
    seconds = best_seconds(lambda: render_gradient(scene, PARAM, method="naive", spp=64), 2)
    rows.append(Row("sphere3d", "naive gradient 64x64, 64 spp", seconds, "s", SCENE))
    seconds = best_seconds(lambda: render(scene, spp=64), 2)
    rows.append(Row("sphere3d", "render 64x64, 64 spp", seconds, "s", SCENE))
    return rows


def _memory() -> list[Row]:
    scene = load_scene(SCENE)
    tracemalloc.start()
    render_gradient(scene, PARAM, method="reparam", spp=64)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    # ru_maxrss is in kilobytes on Linux, bytes on macOS
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * (1 if sys.platform == "darwin" else 1024)
    return [
        Row("sphere3d", "reparam 64x64, 64 spp: allocation peak", peak / 2**20, "MiB", "tracemalloc"),
        Row("sphere3d", "process peak resident set", rss / 2**20, "MiB", "getrusage, after all runs"),
    ]


def run() -> list[Row]:
    """The sphere3d rows of ``make bench``."""
    return _rays_per_second() + _image_seconds() + _memory()
