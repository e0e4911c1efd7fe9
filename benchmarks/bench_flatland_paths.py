"""flatland's paths and glossy surfaces: what ``max_depth`` and each gradient method cost.

The two built-in scenes made for them, ``glossy_reflection`` (a glossy floor, GGX roughness 0.2,
an occluder, its reflection and its shadow on a diffuse wall) and ``interreflection`` (a closed
diffuse box lit through its ceiling), at 128 pixels and 64 samples per pixel: the primal render at
depths 1, 2 and 4 (the goal: depth 4 at most 3x depth 1), and the derivative image of
``occluder.translate.x`` by each method at depths 1, 3 and 4 (``boundary`` traces two paths of the
remaining depth per jump at every vertex), as multiples of the depth-1 primal, and the depth-4
``reparam`` gradient as a multiple of the depth-4 primal (the goal: at most 4x). Wall times are the
best of seven calls, on whatever else the machine was running.
"""

from __future__ import annotations

from benchmarks import Row, best_seconds
from flatland.render import render, render_gradient
from flatland.scene import load_scene

PIXELS, SPP = 128, 64
REPEATS = 7  # calls of tens of milliseconds: the best of seven is the least disturbed by other load
SCENES = ("glossy_reflection", "interreflection")
GRADIENTS = (
    ("naive", 1),
    ("naive", 4),
    ("finite_difference", 4),
    *((method, depth) for method in ("boundary", "reparam") for depth in (1, 3, 4)),
)


def run() -> list[Row]:
    """Seconds per primal render by depth, and each gradient's cost relative to the depth-1 primal."""
    rows = []
    for name in SCENES:
        scene = load_scene(name).with_camera(pixels=PIXELS)
        primal = {}
        for depth in (1, 2, 4):
            primal[depth] = best_seconds(
                lambda d=depth, s=scene: render(s, spp=SPP, seed=1, max_depth=d, progress=False), REPEATS
            )
            case = f"{name}: max_depth {depth}, {PIXELS} px x {SPP} spp"
            rows.append(Row(f"{name} primal", case, primal[depth], "s"))
        ratio = primal[4] / primal[1]
        rows.append(Row(f"{name} primal", f"{name}: depth 4 / depth 1", ratio, "x", "goal <= 3"))
        gradient = {}
        for method, depth in GRADIENTS:
            gradient[method, depth] = seconds = best_seconds(
                lambda m=method, d=depth, s=scene: render_gradient(
                    s, "occluder.translate.x", m, spp=SPP, seed=1, max_depth=d, progress=False
                ),
                REPEATS,
            )
            rows.append(
                Row(f"{name} gradient", f"{name}: {method}, max_depth {depth}", seconds / primal[1],
                    "x primal d1", f"{seconds:.3f} s")
            )  # fmt: skip
        rows.append(
            Row(f"{name} gradient", f"{name}: reparam depth 4 / primal depth 4",
                gradient["reparam", 4] / primal[4], "x", "goal <= 4")
        )  # fmt: skip
    return rows
