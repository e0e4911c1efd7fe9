"""Flatland renderer: ray-caster throughput and seconds per image (best of 3 runs).

Targets: the ``reparam`` gradient image of ``shadow`` at 512 pixels × 64 spp
in at most 1 s on a 2-core machine, and no method slower than 5× the primal render.
"""

from __future__ import annotations

import numpy as np

from benchmarks import Row, best_seconds
from flatland.render import render, render_gradient
from flatland.scene import load_scene
from flatland.state import build_state
from flatland.tracing import cast, direction

RAYS = 1 << 20
PIXELS, SPP = 512, 64
PARAM = "occluder.translate.x"
METHODS = [
    ("naive", {}),
    ("finite_difference", {}),
    ("boundary", {}),
    ("reparam", {}),
    ("reparam", {"paired": True}),
]


def run() -> list[Row]:
    """Rays per second of :func:`flatland.tracing.cast`, and seconds per image per method."""
    rows = []
    rng = np.random.default_rng(0)
    origins = rng.uniform(-2.0, 2.0, (RAYS, 2))
    dirs = direction(rng.uniform(-np.pi, np.pi, RAYS))
    for name in ("shadow", "silhouette", "polygon"):
        geom = build_state(load_scene(name))
        prims = geom.n_seg + geom.n_circ
        seconds = best_seconds(lambda g=geom: cast(g, origins, dirs))
        rows.append(
            Row("flatland ray caster", f"{name} ({prims} primitives)", RAYS / seconds / 1e6, "M rays/s")
        )

    scene = load_scene("shadow").with_camera(pixels=PIXELS)
    primal = best_seconds(lambda: render(scene, spp=SPP, seed=0))
    case = f"shadow {PIXELS} px x {SPP} spp"
    rows.append(Row("flatland images", f"{case}: render (primal)", primal, "s", "1.00x primal"))
    for method, options in METHODS:
        seconds = best_seconds(
            lambda m=method, o=options: render_gradient(scene, PARAM, method=m, spp=SPP, seed=0, **o)
        )
        label = method + "".join(f" {k}={v}" for k, v in options.items())
        target = " (target <= 1 s)" if (method, options) == ("reparam", {}) else ""
        rows.append(
            Row(
                "flatland images", f"{case}: {label}", seconds, "s", f"{seconds / primal:.2f}x primal{target}"
            )
        )
    return rows
