"""reparam's emitter rotation (:mod:`sphere3d.reparam.emitter_probes`) at single ground points of the
penumbra.

At a fixed point and normal of the ``hard_shadow`` scenes (d/d ``occluder.translate.x``,
:func:`sphere3d.irradiance`) the ``boundary`` method is unbiased and, with the same seed,
nearly noise-free (standard error < 0.1 % here): the reference. The points lie across the
penumbra along y = -0.1 (x = -0.3: the lit side, where a few % of the light is hidden;
x = 0.1: the umbra's side, a few % visible). Before the silhouette rule the emitter
strategy followed the mean occluded hit of 4 area probes, and its derivative was off by
-45 % (sphere, x = -0.3: no probe saw the occluder, the identity dragged its shadow
edge) to +57 % (cube, x = -0.05: the mean hit nearer the point than the silhouette).
The edge points (sphere x = 0.13, 1.12; cube x = -0.43, 1.3) were off by +20 %, -34 %,
-19 %, -49 % (seed 11) before the aimed probes (:data:`sphere3d.reparam.emitter_probes.AIM`), and
test01 failed there: the thin part of the light that the shadow edge cuts off was shorter
along the light's border than the edge probes' spacing (scan: +16 %, -36 %, -23 %, -47 %).

Statistics: z = (reparam - boundary) / sqrt(se_r² + se_b²), Šidák over the file's points at
family-wise level 1e-3 (normal quantile: 16 batches of 1024 samples, the stderr's own noise
is covered by the documented bounds' margin); fixed seeds.
"""

from __future__ import annotations

import numpy as np
import pytest

import sphere3d as s3
from flatland.core.dual import detach, variable
from flatland.core.stats import normal_quantile, sidak
from sphere3d.reparam.emitter_probes import _aimed_points
from sphere3d.reparam.penumbra import may_see_motion
from sphere3d.sampling import sample_mesh
from sphere3d.state import build_state

PARAM = "occluder.translate.x"
N = 16384
BOUND = 0.05
"""Documented |reparam / boundary - 1| at these points (measured -3.6 % to +0.9 %, seeds 11-12):
the cosine strategy's loss near the light's edge (its rotation follows the occluder and drags
the light's edge; up to 3.5 % at x = 0.1) and the silhouette's motion away from the followed
point (:mod:`sphere3d.reparam.emitter_probes`, Bias). The edge points at seed 11: sphere x = 0.13,
1.12: +1.7 %, +3.1 %; cube x = -0.43: +8.9 ± 2.6 % (the scan: +4.5 ± 0.9 %, the cosine
strategy's excess at the outer lit edge), x = 1.3: +3.3 ± 2.9 %."""
POINTS = [
    ("hard_shadow", -0.3),
    ("hard_shadow", 0.0),
    ("hard_shadow", 0.1),
    ("hard_shadow", 0.13),
    ("hard_shadow", 1.12),
    ("hard_shadow_cube", -0.2),
    ("hard_shadow_cube", -0.43),
    ("hard_shadow_cube", 0.65),
    ("hard_shadow_cube", 0.1),
    ("hard_shadow_cube", 1.3),
]
CUBE_CORNER = ("hard_shadow_cube", -0.05)
"""Where the cube's shadow edge is two edges at different depths: +6.2 % / +7.2 % (seeds 12 / 11)
with 8 probes on the light's edges, one rotation following one of them; with 4
(:data:`sphere3d.reparam.emitter_probes.BOUNDARY`) +0.5 ± 0.4 % in the scan, tested below 2 %."""
Q = normal_quantile(1.0 - sidak(1e-3, len(POINTS) + 1))
N_BIAS = 65536
BIASES = [
    ("hard_shadow", -0.34, 0.089, 0.179),
    ("hard_shadow", 0.50, -0.109, -0.067),
    ("hard_shadow", 0.57, -0.058, -0.038),
    ("hard_shadow_cube", -0.48, -0.717, -0.537),
    ("hard_shadow_cube", 0.02, 0.253, 0.287),
    ("hard_shadow_cube", 0.05, -0.050, -0.028),
    ("hard_shadow_cube", 0.68, -0.065, -0.045),
    ("hard_shadow_cube", 0.88, -0.052, -0.026),
]
"""(scene, x, lo, hi): the relative bias reparam / boundary - 1 at (x, -0.1, 0) as measured by the
scan of :mod:`sphere3d.reparam.emitter_probes` (Bias; seeds 1-4 × 32768, the mean ± 3 standard errors)."""
Q_BIAS = normal_quantile(1.0 - sidak(1e-3, len(BIASES)))


def _pair(scene, x, seed=11, n=N, **options):
    point = (x, -0.1, 0.0)
    r = s3.irradiance(scene, point, (0, 0, 1), PARAM, method="reparam", n=n, seed=seed, **options)
    b = s3.irradiance(scene, point, (0, 0, 1), PARAM, method="boundary", n=n, seed=seed)
    return r.derivative, b.derivative, float(np.hypot(r.derivative_stderr, b.derivative_stderr))


@pytest.mark.parametrize(("scene", "x"), POINTS)
def test01_the_emitter_rotation_follows_the_shadow_edge_across_the_penumbra(scene, x):
    r, b, se = _pair(scene, x)
    assert abs(r - b) < BOUND * abs(b) + Q * se, (r, b, se)


def test02_four_edge_probes_keep_the_cube_corner():
    r, b, se = _pair(*CUBE_CORNER)
    assert abs(r - b) < 0.02 * abs(b) + Q * se, (r, b, se)


@pytest.mark.parametrize(("scene", "x", "lo", "hi"), BIASES)
def test03_the_remaining_biases_keep_their_documented_size(scene, x, lo, hi):
    """The points of the scan still biased (:mod:`sphere3d.reparam.emitter_probes`, Bias), each asserted
    inside its measured interval widened by Q_BIAS standard errors (Šidák over the points at
    1e-3) and away from 0 by as much, so that a fix fails here and prompts an update:

    - sphere, x = -0.34 (outer lit edge, +13 %): the cosine strategy's rotation follows the
      occluder and drags the light's edge (0.25 against 0.10 ± 0.04 of a total 1.57); the
      emitter strategy is exact there since the aimed probes (it lost 62 % before);
    - sphere, x = 0.50 (-8.8 %), the umbra's right edge: the emitter strategy 5 % short (-2.01
      against -2.12 ± 0.05; the followed silhouette point lies next to the light's corner, at
      one end of the arc bounding the lit part) and the cosine strategy short (0.00 against
      -0.07 ± 0.05); before the aimed probes the emitter strategy's +7 % hid it (total +2.5 %);
    - sphere, x = 0.57 (-4.8 %): the cosine strategy short (-0.01 against -0.26 ± 0.07 of
      -8.03), the emitter strategy -2.5 %;
    - cube, x = -0.48 (outermost lit point, -63 %; -55 % with 8 edge probes): the hidden part,
      0.07 long on the light's edge, lies 0.004 beside the nearest aimed point;
    - cube, x = 0.02 (+27 %) and 0.05 (-3.9 %; -7.2 % with 8 edge probes): the shadow edge is two
      silhouette edges at different depths and one rotation follows one of them (x = 0.01:
      emitter 7.78 against 6.80 ± 0.08; x = 0.05: 9.65 against 9.98 ± 0.11, the cosine strategy
      0.16 against 0.55);
    - cube, x = 0.68 (-5.5 %; -3.5 % with 8 edge probes) and 0.88 (-3.9 %; -7.3 % with 8): the
      cosine strategy short (x = 0.85: -0.11 against -0.29 ± 0.05) and the emitter strategy.
    """
    r, b, se = _pair(scene, x, n=N_BIAS)
    bias, margin = r / b - 1.0, Q_BIAS * se / abs(b)
    assert lo - margin < bias < hi + margin, (bias, margin)
    assert abs(bias) > margin and np.sign(bias) == np.sign(lo), (bias, margin)


@pytest.mark.parametrize("scene", ["hard_shadow", "hard_shadow_cube"])
def test04_points_skipped_without_probes_cannot_see_the_occluder_in_front_of_the_light(scene):
    """The cull of :func:`sphere3d.reparam.penumbra.may_see_motion` is conservative: every ground or
    occluder point from which one of 64 rays to the light meets the moving occluder is kept,
    and the cull skips a good share of the ground (else it would be pointless)."""
    loaded = s3.load_scene(scene)
    state = build_state(loaded, PARAM, variable(0.0))
    rng = np.random.default_rng(5)
    x = np.column_stack([rng.uniform(-2.5, 2.5, 4000), rng.uniform(-2.5, 2.5, 4000), np.zeros(4000)])
    occluder = np.asarray(detach(state.triangles))[state.shape_of == loaded.shape_index("occluder")]
    on_occluder, _ = sample_mesh(rng.uniform(size=(1000, 1, 3)), occluder)
    x = np.concatenate([x + np.array([0.0, 0.0, 1e-6]), on_occluder[:, 0]])
    y, _ = sample_mesh(rng.uniform(size=(len(x), 64, 3)), np.asarray(detach(state.triangles))[state.emitters])
    to = y - x[:, None]
    dist = np.linalg.norm(to, axis=-1)
    hits = state.tracer.intersect(np.broadcast_to(x[:, None], to.shape), to / dist[..., None])
    moving = np.any(np.asarray(state.triangles.tangent) != 0.0, axis=(1, 2))
    sees = np.any(hits.hit & moving[np.maximum(hits.triangle, 0)] & (hits.t < dist), axis=1)
    kept = may_see_motion(state, x)
    assert sees.sum() > 100 and np.all(kept[sees])
    assert 0.2 < np.mean(~kept[:4000]) < 1.0


def test05_aimed_probes_point_where_the_light_is_first_covered():
    """:func:`sphere3d.reparam.emitter_probes._aimed_points` on ``hard_shadow`` (the occluder's bounding
    sphere is centred on the icosphere's centre (0.1, 0, 0.8)): from (0.3, -0.2, 0) the axis meets
    the light inside, at (-0.325, 0.425, 2.5) (2.5 / 0.8 times (-0.2, 0.2, 0.8) on), the nearest
    point; from the outer lit edge (-0.34, -0.1, 0), where the sphere hides 0.13 % of the light and
    the 12 other probes mostly miss it, the nearest point on the border is hidden; from (2, 2, 0) the
    light lies outside the occluder's bounding cone and the point gets no aimed ray."""
    state = build_state(s3.load_scene("hard_shadow"), PARAM, variable(0.0))
    x = np.array([[0.3, -0.2, 0.0], [-0.34, -0.1, 0.0], [2.0, 2.0, 0.0]])
    points, worth = _aimed_points(state, x, np.zeros(3, dtype=bool), 2)
    assert np.allclose(points[0, 0], [-0.325, 0.425, 2.5], atol=1e-9)
    to = points[1, 0] - x[1]
    dist = np.linalg.norm(to)
    origin = x[1:2] + np.array([0.0, 0.0, 1e-6])
    assert state.tracer.occluded(origin, (to / dist)[None], np.array([dist - 1e-4]))[0]
    assert worth.tolist() == [True, True, False]
