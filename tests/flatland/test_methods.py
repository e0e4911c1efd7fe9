"""The image methods on the built-in scenes: boundary against finite differences, reparam against boundary.

1. ``boundary`` agrees with ``finite_difference`` pixel by pixel on every built-in scene
   and every parameter kind (translate.x/y, rotate, scale, vertex.K.x/y, emission,
   albedo, camera translate.x/y and rotate; circles and polygons, camera and shading
   discontinuities):
   ``|g_b - g_fd| <= z sqrt(se_b² + se_fd²) + RES max|g_b|``, z the two-sided normal
   quantile at 1 - sidak(ALPHA, pixels) with ALPHA = 1e-3, fixed seeds.
   RES = 1% is the resolution of finite differences with common random numbers: a
   pixel's FD derivative only sees samples that flip within ±h, and where a moving
   shadow leaves a thin sliver of an emitter (or of sky) in view, no sample of any
   batch may flip, leaving an FD estimate and standard error of exactly 0 while the
   boundary term is not (measured: shadow pixel at the umbra's edge, boundary
   -0.0064 ± 0.0008, FD exactly 0 at h = 1e-3, -0.0084 ± 0.003 with 4× the samples
   at h = 1e-2; the largest such gap seen was 1% of max|g|).
   H = 1e-2 keeps enough flips per batch for those shading terms, and moves edges
   by at most 0.2 pixel at 16 pixels. The exception is ``two_occluders`` with
   ``near.translate.x``: its silhouette passes the far polygon's edge 0.006 away
   from θ0, so I(θ) has a kink inside ±1e-2 there (measured: z = 5.1 at h = 1e-2,
   2.7 at h = 2e-3); it uses h = 2e-3.
2. ``reparam`` agrees with ``boundary`` within a per-scene bound on the error
   metric ``mean|g - g_ref| / max|g_ref|`` (reported as the test property
   ``relative_error``). The bias sources are the method's (see
   :mod:`flatland.methods.reparam`); the bounds come from the measured run in
   ``test02``'s docstring.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

import flatland.integrator as integrator
import flatland.methods.boundary as boundary
from flatland.core.dual import detach, tangent, variable
from flatland.core.stats import normal_quantile, sidak
from flatland.methods.heuristic import choose_points
from flatland.render import render_gradient
from flatland.scene import bind, list_scenes, load_scene

ALPHA = 1e-3
RES = 0.01
H = 1e-2
PIXELS = 16
SPP_BOUNDARY, SPP_FD, SPP_REPARAM = 2048, 8192, 4096

FD_CASES = [
    ("shadow", "occluder.translate.x", H),
    ("shadow", "camera.translate.y", H),
    ("shadow", "light.emission", H),
    ("shadow", "floor.albedo", H),
    ("silhouette", "ball.translate.y", H),
    ("silhouette", "camera.rotate", H),
    ("polygon", "polygon.rotate", H),
    ("polygon", "polygon.vertex.1.y", H),
    ("penumbra", "light.scale", H),
    ("penumbra", "blocker.vertex.2.x", H),
    ("penumbra", "camera.translate.x", H),
    ("two_occluders", "near.translate.x", 2e-3),
]


def _scene(name: str):
    return load_scene(name).with_camera(pixels=PIXELS)


@cache
def _boundary(name: str, param: str):
    return render_gradient(_scene(name), param, method="boundary", spp=SPP_BOUNDARY, seed=1)


def test00_the_cases_cover_every_scene_and_parameter_kind():
    kinds = {p.split(".", 1)[1] if not p.startswith("camera") else p for _, p, _ in FD_CASES}
    kinds = {k.replace("vertex.1", "vertex.K").replace("vertex.2", "vertex.K") for k in kinds}
    assert kinds == {
        "translate.x", "translate.y", "rotate", "scale", "vertex.K.x", "vertex.K.y", "emission", "albedo",
        "camera.translate.x", "camera.translate.y", "camera.rotate",
    }  # fmt: skip
    assert {n for n, _, _ in FD_CASES} == set(list_scenes())


@pytest.mark.parametrize(("name", "param", "h"), FD_CASES)
def test01_boundary_agrees_with_finite_differences(name, param, h):
    b = _boundary(name, param)
    f = render_gradient(_scene(name), param, method="finite_difference", spp=SPP_FD, seed=2, h=h)
    z = normal_quantile(1.0 - sidak(ALPHA, PIXELS))
    scale = np.max(np.abs(b.derivative))
    tolerance = z * np.hypot(b.derivative_stderr, f.derivative_stderr) + RES * scale
    assert np.all(np.abs(b.derivative - f.derivative) <= tolerance)
    assert np.array_equal(b.value, _boundary(name, param).value) and scale > 0
    # the comparison has power: where the derivative is large, FD resolves it to better than 20%
    live = np.abs(b.derivative) > 0.2 * scale
    assert np.median(f.derivative_stderr[live] / np.abs(b.derivative[live])) < 0.2


# per scene: about 1.3x the largest error measured over its parameters and seeds 3, 4, 5 (test02)
BOUNDS = {
    "penumbra": 0.14,
    "polygon": 0.05,
    "shadow": 0.07,
    "silhouette": 0.05,
    "two_occluders": 0.06,
}


@pytest.mark.parametrize(
    ("name", "param"), [(n, p) for n in sorted(BOUNDS) for p in load_scene(n).parameters]
)
def test02_reparam_error_against_boundary_is_bounded_per_scene(name, param, record_property):
    """``relative_error(reparam, boundary) <= BOUNDS[scene]`` at 16 pixels, 4096 spp (boundary: 2048 spp).

    Measured run (reparam at seeds 3 / 4 / 5, naive at seed 3, same boundary reference):

    ============= ==================== ===================== =====
    scene         parameter            reparam               naive
    ============= ==================== ===================== =====
    penumbra      blocker.vertex.2.x   0.075 / 0.107 / 0.108 0.051
    penumbra      blocker.vertex.0.y   0.072 / 0.089 / 0.104 0.131
    penumbra      light.scale          0.059 / 0.065 / 0.090 0.569
    penumbra      camera.translate.x   0.063 / 0.065 / 0.065 0.257
    polygon       polygon.rotate       0.033 / 0.039 / 0.039 0.181
    polygon       polygon.scale        0.020 / 0.034 / 0.030 0.316
    polygon       polygon.vertex.1.y   0.009 / 0.009 / 0.013 0.091
    shadow        occluder.translate.x 0.037 / 0.040 / 0.022 0.308
    shadow        occluder.translate.y 0.021 / 0.023 / 0.029 0.200
    shadow        light.translate.x    0.036 / 0.046 / 0.032 0.034
    shadow        light.emission       0.007 / 0.007 / 0.007 0.007
    shadow        floor.albedo         0.007 / 0.006 / 0.007 0.007
    shadow        camera.translate.y   0.053 / 0.050 / 0.037 0.447
    silhouette    occluder.translate.x 0.015 / 0.013 / 0.036 0.211
    silhouette    occluder.rotate      0.020 / 0.015 / 0.021 0.117
    silhouette    ball.translate.y     0.017 / 0.012 / 0.011 0.087
    silhouette    ball.scale           0.022 / 0.012 / 0.018 0.114
    silhouette    camera.rotate        0.026 / 0.020 / 0.027 0.266
    two_occluders near.translate.x     0.033 / 0.042 / 0.047 0.118
    two_occluders far.translate.y      0.021 / 0.019 / 0.021 0.129
    two_occluders near.rotate          0.027 / 0.036 / 0.041 0.120
    ============= ==================== ===================== =====

    Most of each error is still noise at this sample count (it varies with the seed;
    emission and albedo, where naive is exact, show the noise floor, 0.007). The
    penumbra scene is the worst: its emitter is unfaded, and where a blocker's
    tangent line happens to separate the emitter from the floor point the heuristic
    follows the blocker while the emitter's edge stays put (see
    :mod:`flatland.methods.heuristic`); there reparam is worse than naive. A moving
    emitter under a static occluder (``light.translate.x``) gains nothing either:
    its faded ends are continuous and the occluder's edges do not move.
    """
    r = render_gradient(_scene(name), param, method="reparam", spp=SPP_REPARAM, seed=3)
    error = r.error_vs(_boundary(name, param))
    record_property("relative_error", error)
    assert error <= BOUNDS[name], (name, param, error)


def test03_results_do_not_depend_on_memory_chunks(monkeypatch):
    """Smaller work items and candidate blocks change only the order of floating-point sums."""
    scene = load_scene("silhouette").with_camera(pixels=8)
    whole = render_gradient(scene, "ball.translate.y", method="boundary", spp=64, seed=9)
    monkeypatch.setattr(integrator, "CHUNK", 100)
    monkeypatch.setattr(boundary, "MAX_CANDIDATES", 7)
    pieces = render_gradient(scene, "ball.translate.y", method="boundary", spp=64, seed=9)
    assert np.allclose(whole.value, pieces.value, rtol=1e-12, atol=1e-15)
    assert np.allclose(whole.derivative, pieces.derivative, rtol=1e-9, atol=1e-12)


def _segment(name: str, a: list[float], b: list[float]) -> dict:
    return {"name": name, "type": "segment", "points": [a, b]}


HEURISTIC_SCENE = {
    "name": "probes",
    "camera": {"position": [0.0, 0.0], "direction": [0.0, 1.0], "fov": 1.0, "pixels": 4},
    "shapes": [
        _segment("near", [-1.0, 1.0], [1.0, 1.0]),  # primitive 0, in front of 1
        _segment("far", [-1.0, 2.0], [1.0, 2.0]),  # primitive 1
        _segment("left", [-1.0, 1.0], [0.0, 2.0]),  # 2 and 3: a roof seen from below, corner (0, 2)
        _segment("right", [0.0, 2.0], [1.0, 1.0]),
        # 4 and 5: |n0·n1| = 1 / sqrt(1 + 0.05²) = 0.9988 > PARALLEL, though their lines meet at (0, 3)
        _segment("west", [-1.0, 3.0], [0.0, 3.0]),
        _segment("east", [0.0, 3.0], [1.0, 2.95]),
    ],
}


def test04_probe_heuristic_one_configuration_per_rule():
    """Hand-made probe hits from o = (0, 0) looking along +y, four probes in order (DESIGN 2.8).

    Expected points by hand: a segment's hit at barycentric u is a + u (b - a); the roof's
    corner under ``right.translate.x`` = θ is where y = x + 2 meets y = 2 - (x - θ), i.e.
    (θ/2, 2 + θ/2), moving with tangent (1/2, 1/2).
    """
    miss = -1
    cases = [  # (probe primitives, probe coordinates, rule code, chosen point)
        ([0, 0, 0, 0], [0.2, 0.4, 0.6, 0.8], -1, None),  # one primitive in sight: the identity
        ([0, miss, miss, miss], [0.5, 0, 0, 0], 0, [0.0, 1.0]),  # only probe 0 hits
        ([miss, miss, miss, 0], [0, 0, 0, 0.5], 1, [0.0, 1.0]),  # only the partner hits
        ([0, 0, 1, 1], [0.4, 0.5, 0.5, 0.6], 0, [0.0, 1.0]),  # probe 0's line occludes: its hit by the switch
        ([1, 1, 0, 0], [0.4, 0.5, 0.5, 0.6], 1, [0.0, 1.0]),  # the partner's line occludes
        ([4, 4, 5, 5], [0.5, 0.9, 0.1, 0.5], 0, [-0.1, 3.0]),  # nearly parallel lines: probe 0's shape
        ([2, 2, 3, 3], [0.5, 0.8, 0.2, 0.5], 2, [0.0, 2.0]),  # neither occludes: the lines' corner
    ]
    prim = np.array([c[0] for c in cases])
    coord = np.array([c[1] for c in cases], dtype=np.float64)
    n = prim.shape[0]
    geom = bind(load_scene(HEURISTIC_SCENE), "right.translate.x", variable(0.0))
    choice = choose_points(geom, np.zeros((n, 2)), prim, coord, np.tile([0.0, 1.0], (n, 1)))
    assert choice.code.tolist() == [c[2] for c in cases]
    assert choice.ok.tolist() == [c[3] is not None for c in cases]
    for i, (_, _, _, point) in enumerate(cases):
        if point is not None:
            assert np.allclose(detach(choice.point)[i], point), i
    assert np.allclose(tangent(choice.point)[-1], [0.5, 0.5])
