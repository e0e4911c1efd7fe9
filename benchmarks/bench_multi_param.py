"""flatland and sphere3d: the cost of k = 8 parameters per pass against k = 1, per method (fastest of 3 runs).

flatland: :func:`flatland.render.render_gradient` on the ``shadow`` scene at :data:`PIXELS` pixels and
:data:`SPP` samples per pixel (seed 0, default options), once with the single name
``occluder.translate.x`` (k = 1, the classic path: one tangent) and once with the list
:data:`PARAMS` of eight parameters (k = 8: translations, a rotation, a scale, emission, albedo
and the camera). Each time is the fastest of :data:`REPEATS` calls.

One pass serves every parameter: the rays, probes, kernel draws and samples are shared, and
forward mode carries eight tangents instead of one (:mod:`flatland.core.dual`), so only the
tangents' arithmetic grows with k. ``finite_difference`` shares nothing but the value render:
2k + 1 = 17 renders against 3, about (2k + 1) / 3 = 5.7 times the cost.

Rows per method: seconds at k = 1 and at k = 8, and their ratio, against the goal of the issue
"several parameters per pass": at most 3 for every method but ``finite_difference``. The times
are wall-clock on a machine that may be shared: the fastest of the runs is the least disturbed.

sphere3d (:mod:`benchmarks.multi_param_sphere3d`): the same on ``hard_shadow`` (64 × 64 px, 16 spp),
k = 1 (``occluder.translate.x``) against the occluder's eight parameters, and the case for one pass
against finite differences: with k = 8, the time ``reparam`` takes to reach, on every parameter, the
RMSE ``finite_difference`` has at 16 spp (17 renders), against a goal of a third of FD's time.
"""

from __future__ import annotations

from benchmarks import Row, best_seconds
from benchmarks.multi_param_sphere3d import sphere3d_rows
from flatland.render import render_gradient
from flatland.scene import load_scene

SCENE = "shadow"
PIXELS, SPP = 512, 256
REPEATS = 3
PARAMS = [
    "occluder.translate.x",
    "occluder.translate.y",
    "occluder.rotate",
    "occluder.scale",
    "light.translate.x",
    "light.emission",
    "floor.albedo",
    "camera.translate.y",
]
METHODS = ("naive", "boundary", "reparam", "finite_difference")
GOAL = 3.0
"""Most k = 8 may cost against k = 1 (every method but ``finite_difference``)."""


def run(pixels: int = PIXELS, spp: int = SPP, repeats: int = REPEATS) -> list[Row]:
    """Seconds per gradient image at k = 1 and k = 8 and their ratio, per method (flatland, then
    sphere3d's rows, :func:`benchmarks.multi_param_sphere3d.sphere3d_rows`)."""
    scene = load_scene(SCENE).with_camera(pixels=pixels)
    case = f"{SCENE} {pixels} px x {spp} spp"
    rows = []
    for method in METHODS:

        def call(param, m=method):
            return render_gradient(scene, param, method=m, spp=spp, seed=0, progress=False)

        one = best_seconds(lambda c=call: c(PARAMS[0]), repeats)
        eight = best_seconds(lambda c=call: c(PARAMS), repeats)
        ratio = eight / one
        if method == "finite_difference":
            note = f"2k + 1 = {2 * len(PARAMS) + 1} renders against 3: no goal"
        else:
            note = f"goal <= {GOAL:g}x: {'met' if ratio <= GOAL else 'not met'}"
        rows += [
            Row("multi_param", f"{case}: {method}, k = 1", one, "s"),
            Row("multi_param", f"{case}: {method}, k = {len(PARAMS)}", eight, "s"),
            Row("multi_param", f"{case}: {method}, k = {len(PARAMS)} / k = 1", ratio, "x", note),
        ]
    return rows + sphere3d_rows(repeats)
