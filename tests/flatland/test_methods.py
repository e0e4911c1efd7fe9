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
from scipy import stats

import flatland.methods.boundary as boundary
import flatland.tasks as tasks
from flatland.core.dual import detach, tangent, variable
from flatland.core.stats import normal_quantile, sidak
from flatland.render import render_gradient
from flatland.reparam.probes import select_points
from flatland.scene import list_scenes, load_scene
from flatland.state import build_state
from tests.tiers import sweep

ALPHA = 1e-3
EPS = np.finfo(np.float64).eps
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
    ("glossy_reflection", "occluder.translate.x", H),
    ("glossy_reflection", "floor.roughness", H),
    ("interreflection", "occluder.translate.y", H),
    ("furnace", "room.albedo", H),
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
        "camera.translate.x", "camera.translate.y", "camera.rotate", "roughness",
    }  # fmt: skip
    assert {n for n, _, _ in FD_CASES} == set(list_scenes())


@pytest.mark.parametrize(
    ("name", "param", "h"),
    sweep(FD_CASES, [("shadow", "occluder.translate.x", H)]),
)
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


# Where the probe heuristic's assumptions hold, reparam agrees with boundary pixel by pixel (test02a);
# elsewhere it is biased, and test02b shows the bias and bounds its size (measured, seed 3, 16 px).
UNBIASED = {
    ("polygon", "polygon.rotate"),
    ("polygon", "polygon.scale"),
    ("polygon", "polygon.vertex.1.y"),
    ("shadow", "occluder.translate.x"),
    ("shadow", "occluder.translate.y"),
    ("shadow", "light.translate.x"),
    ("shadow", "light.emission"),
    ("shadow", "floor.albedo"),
    ("shadow", "camera.translate.y"),
    ("silhouette", "camera.rotate"),
    ("glossy_reflection", "floor.roughness"),
    ("glossy_reflection", "floor.albedo"),
    ("glossy_reflection", "light.emission"),
    ("interreflection", "occluder.translate.x"),
    ("interreflection", "occluder.translate.y"),
    ("interreflection", "box.albedo"),
    ("interreflection", "light.emission"),
    ("furnace", "room.albedo"),
    ("furnace", "room.emission"),
    ("furnace", "room.vertex.3.x"),
}
# bias below the resolution of these tests at 4096 spp (neither claim holds): the error bound only
UNRESOLVED = {("silhouette", "occluder.translate.x"), ("silhouette", "occluder.rotate")}
# per scene: about 1.3x the largest relative error measured for its biased parameters (test02b)
BOUNDS = {
    "glossy_reflection": 0.06,
    "penumbra": 0.13,
    "silhouette": 0.04,
    "two_occluders": 0.06,
}
CASES = [(n, p) for n in sorted(list_scenes()) for p in load_scene(n).parameters]


def _pixel_z(name: str, param: str) -> tuple[np.ndarray, float]:
    """Per-pixel z-scores of reparam (4096 spp, seed 3) against boundary, and the relative error."""
    r = render_gradient(_scene(name), param, method="reparam", spp=SPP_REPARAM, seed=3)
    b = _boundary(name, param)
    s = np.hypot(r.derivative_stderr, b.derivative_stderr)
    diff = r.derivative - b.derivative
    # a pixel where both estimates are exact (zero standard error) must agree to rounding
    z = np.where(s > 0.0, diff / np.where(s > 0.0, s, 1.0), np.where(np.abs(diff) > 1e-12, np.inf, 0.0))
    return z, r.error_vs(b)


def _bias_seen(z: np.ndarray) -> tuple[bool, bool]:
    """Two tests of "no pixel is biased", each at level ALPHA / 2 (Bonferroni over the pair).

    The largest |z| against the two-sided normal quantile, Šidák-corrected over the
    pixels (sees one strongly biased pixel), and Σ z² against the chi-square quantile
    with one degree of freedom per pixel (sees a bias spread thinly over many).
    """
    q = normal_quantile(1.0 - sidak(ALPHA / 2, z.size))
    c = stats.chi2.ppf(1.0 - ALPHA / 2, z.size)
    return bool(np.max(np.abs(z)) > q), bool(np.sum(z * z) > c)


@pytest.mark.parametrize(
    ("name", "param"),
    sweep(sorted(UNBIASED), [("shadow", "camera.translate.y")]),
)
def test02a_reparam_is_unbiased_per_pixel_where_the_heuristic_holds(name, param):
    """Neither test of :func:`_bias_seen` rejects: reparam agrees with boundary pixel by pixel.

    z = (reparam - boundary) / sqrt(s_reparam² + s_boundary²), both from independent
    batches (seed 3, 16 pixels). Measured: max |z| 1.5-3.2 against the quantile 4.16;
    Σ z² 8-22 against 41.3.
    """
    z, _ = _pixel_z(name, param)
    assert _bias_seen(z) == (False, False), (name, param, np.round(z, 2))


@pytest.mark.parametrize(
    ("name", "param"), sweep([c for c in CASES if c not in UNBIASED], [("penumbra", "camera.translate.x")])
)
def test02b_reparam_bias_is_seen_per_pixel_and_bounded(name, param, record_property):
    """Where one translation cannot follow every moving edge, reparam is biased: shown, then bounded.

    Measured (seed 3, 16 pixels, 4096 spp; boundary 2048 spp): the largest |z|, Σ z²
    (the quantiles of :func:`_bias_seen`: 4.16 and 41.3) and
    ``relative_error(reparam, boundary)``:

    ============= ==================== ======== ========= ==========
    scene         parameter            max |z|  Σ z²      rel. error
    ============= ==================== ======== ========= ==========
    penumbra      blocker.vertex.2.x   9.9      238       0.109
    penumbra      blocker.vertex.0.y   124.9    124 748   0.045
    penumbra      light.scale          exact    exact     0.048
    penumbra      camera.translate.x   exact    exact     0.069
    silhouette    occluder.translate.x 4.1      35        0.024
    silhouette    occluder.rotate      3.8      36        0.015
    silhouette    ball.translate.y     8.1      71        0.015
    silhouette    ball.scale           8.4      80        0.030
    two_occluders near.translate.x     11.6     279       0.041
    two_occluders far.translate.y      42.3     1 993     0.017
    two_occluders near.rotate          8.4      98        0.027
    glossy_refl.  occluder.translate.x 7.3      248       0.046
    glossy_refl.  occluder.translate.y 7.2      251       0.043
    ============= ==================== ======== ========= ==========

    ("exact": a pixel where both methods have zero standard error but disagree.)
    The silhouette scene's occluder translation and rotation are not resolved by either
    test at this sample count (:data:`UNRESOLVED`): only their error bound is checked. (The
    rotation read 4.4 and 58 while the film transform followed the probes' hit next to an
    end of the turning occluder instead of the end itself, :func:`flatland.reparam.probes.film_shape_end`.)
    In glossy_reflection (glossy_refl.) the shading integral of the glossy floor has a lobe of
    roughness 0.2, narrower than the angular kernel's width, and the occluder's reflection and its
    shadow on the wall both move: one translation per sample follows one of the edges in the
    kernel, as in two_occluders. The penumbra scene is the worst: its emitter is unfaded, and
    where a blocker's tangent line happens to separate the emitter from the floor point the heuristic
    follows the blocker while the emitter's edge stays put (see
    :mod:`flatland.reparam.probes`). In the others a probe pair straddles two
    edges that move differently (two occluders, the ball behind the occluder), and one
    translation follows only one of them. (The polygon's rotation read 10.5 and 292 while
    the transforms followed the probes' hit next to a corner instead of the corner itself,
    :func:`flatland.reparam.probes.angle_shape_end`: unbiased since.) The bound on the
    relative error is a regression bound on a biased estimator (about 1.3x the
    largest measured per scene), not a statistical tolerance.
    """
    z, error = _pixel_z(name, param)
    record_property("relative_error", error)
    if (name, param) not in UNRESOLVED:
        assert any(_bias_seen(z)), (name, param, "bias no longer seen: move the case to UNBIASED")
    assert error <= BOUNDS[name], (name, param, error)


@pytest.mark.parametrize(
    ("method", "options"),
    sweep(
        [
            ("naive", {}),
            ("boundary", {}),
            ("finite_difference", {}),
            ("reparam", {}),
            ("reparam", {"paired": True}),
        ],
        [("naive", {}), ("reparam", {"paired": True})],
    ),
)
def test03_results_do_not_depend_on_memory_chunks_or_batches(monkeypatch, method, options):
    """Every draw is keyed on the sample's index, so chunks and batches change only the order of sums.

    Chunks of 2^15, 100 and 7 samples (and candidate blocks of 7 edges) give the same
    image; so do 1 and 8 batches (pixel p's samples are ``p * spp + j`` whatever the
    batching). Sums of the same 64 numbers per pixel in another order differ by at
    most 64 ε times the sum of their magnitudes: the bound is that, with the
    magnitudes bounded by 1e3 times the value's scale.
    """
    scene = load_scene("silhouette").with_camera(pixels=8)
    param = "ball.translate.y"
    whole = render_gradient(scene, param, method=method, spp=64, seed=9, batches=8, **options)
    one = render_gradient(scene, param, method=method, spp=64, seed=9, batches=1, **options)
    monkeypatch.setattr(tasks, "CHUNK", 100)
    monkeypatch.setattr(boundary, "MAX_CANDIDATES", 7)
    pieces = render_gradient(scene, param, method=method, spp=64, seed=9, batches=8, **options)
    monkeypatch.setattr(tasks, "CHUNK", 7)
    tiny = render_gradient(scene, param, method=method, spp=64, seed=9, batches=8, **options)
    scale = 1e3 * max(np.max(np.abs(whole.value)), np.max(np.abs(whole.derivative)))
    others = (pieces, tiny) if method == "boundary" else (pieces, tiny, one)
    for other in others:  # boundary's edge samples are drawn per batch, not per camera sample
        np.testing.assert_allclose(whole.value, other.value, rtol=0, atol=64 * EPS * scale)
        np.testing.assert_allclose(whole.derivative, other.derivative, rtol=0, atol=64 * EPS * scale)


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
    """Hand-made probe hits from o = (0, 0) looking along +y, four probes in order (theory/probes).

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
    geom = build_state(load_scene(HEURISTIC_SCENE), "right.translate.x", variable(0.0))
    choice = select_points(geom, np.zeros((n, 2)), prim, coord, np.tile([0.0, 1.0], (n, 1)))
    assert choice.code.tolist() == [c[2] for c in cases]
    assert choice.ok.tolist() == [c[3] is not None for c in cases]
    for i, (_, _, _, point) in enumerate(cases):
        if point is not None:
            assert np.allclose(detach(choice.point)[i], point), i
    assert np.allclose(tangent(choice.point)[-1], [0.5, 0.5])


def test05_a_chosen_point_on_the_shading_point_keeps_the_identity(monkeypatch):
    """Coincident geometry can make the heuristic choose the shading point itself: no direction, no NaN.

    The probe rule is replaced by one that always returns the ray origin (the
    degenerate case); the derivative of atan2 at the zero offset is 0/0, so those
    samples must fall back to the identity: the image is then the naive one.
    """
    import flatland.reparam.default as reparam_module  # where the method's transforms call the rule
    from flatland.reparam.probes import Choice

    def at_origin(geom, origins, *args, **kwargs):
        return Choice(np.array(origins, dtype=float), np.zeros(len(origins), dtype=int))

    monkeypatch.setattr(reparam_module, "select_points", at_origin)
    scene = load_scene("shadow").with_camera(pixels=8)
    g = render_gradient(scene, "occluder.translate.x", method="reparam", spp=16, seed=1, kappa_film=1e12)
    assert np.all(np.isfinite(g.derivative))
    naive = render_gradient(scene, "occluder.translate.x", method="naive", spp=16, seed=1)
    np.testing.assert_allclose(
        g.derivative, naive.derivative, rtol=0, atol=1e-9 * np.abs(naive.derivative).max()
    )
