"""The cosine strategy's kernels beside the light's border (:mod:`sphere3d.reparam.kernel_border`).

Which kernels get the field: an arc of directions from a point to an edge passes within a given angle
of a kernel's centre exactly where a dense sampling of the arc says so. Then the estimator: the cosine
strategy alone (the emitter strategy's term set to 0) against finite differences of the same strategy
alone, on :func:`~sphere3d.closed_form.light_triangle_scene` with the triangle's shadow crossing the
light and beside it, under the motions that move its edges apart; without the field
(``shading_border=False``) the kernels follow the triangle and drag the light's border, a bias beyond
the noise. A faceted occluder (a 320-face ball) holds several outline edges in one kernel: the field keeps
the outline through the followed edge and, where the rotation follows the light's border, the outline
its probes see (:func:`~sphere3d.reparam.kernel_border.border_field`); the cosine strategy alone and
unweighted is then measured against the closed form of E.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

import sphere3d as s3
from flatland.core.dual import variable
from flatland.core.image import summarize_batches
from flatland.core.stats import sidak
from sphere3d import closed_form as cf
from sphere3d.reparam import kernel_border
from sphere3d.reparam.default import ReparamTransforms
from sphere3d.reparam.kernel_border import near_arcs
from sphere3d.state import build_state
from sphere3d.tasks import PointTask
from tests.sphere3d.helpers import cosine_only, strategy_alone, strategy_z

ALPHA = 1e-3
TRIANGLE = np.array([[-0.25, -0.2, 0.0], [0.3, -0.15, 0.0], [0.0, 0.3, 0.0]]) + np.array([0.22, 0.1, 1.0])
"""Its shadow on the light's plane: two edges across the light, one corner inside it."""
BESIDE = TRIANGLE - TRIANGLE.mean(axis=0) + np.array([0.55, 0.0, 1.0])
"""Beside the light: its shadow misses it (derivative 0), its image next to the light's border."""
MOTIONS = ("tri.translate.z", "tri.rotate.x", "tri.scale")


def test01_an_arc_is_near_a_centre_where_its_sampled_directions_are():
    rng = np.random.default_rng(7)
    n, edges = 400, 5
    x = rng.normal(size=(n, 3)) * 0.2
    a, b = rng.normal(size=(2, edges, 3)) + np.array([0.0, 0.0, 2.0])
    centre = rng.normal(size=(n, 3)) * 0.5 + [0.0, 0.0, 1.0]
    centre /= np.linalg.norm(centre, axis=1)[:, None]
    reach = 0.3
    near = near_arcs(x, centre, a, b, reach)
    # the arc's directions, densely: the least angle to the centre against the reach
    s = np.linspace(0.0, 1.0, 4001)[:, None, None, None]
    p = a[None, None] + s * (b - a)[None, None] - x[None, :, None]  # (S, n, E, 3)
    cosine = np.einsum("snex,nx->sne", p, centre) / np.linalg.norm(p, axis=-1)
    least = np.arccos(np.clip(cosine.max(axis=0), -1.0, 1.0))
    clear = np.abs(least - reach) > 1e-3  # the sampling's resolution aside
    assert clear.mean() > 0.95 and 0.1 < near.mean() < 0.9
    np.testing.assert_array_equal(near[clear], (least <= reach)[clear])


def test02_the_cosine_strategy_keeps_the_light_s_border_and_the_triangle_s_edges(monkeypatch):
    # within noise of finite differences of the same strategy, the shadow across the light and beside it
    strategy_alone(monkeypatch, "bsdf")
    cases = [(v, p) for v in (TRIANGLE, BESIDE) for p in MOTIONS]
    q = stats.norm.ppf(1.0 - 0.5 * sidak(ALPHA, len(cases)))
    for vertices, param in cases:
        z = strategy_z(cf.light_triangle_scene(vertices), param)
        print(f"{param}: cosine strategy alone, z {z:+.2f} (q {q:.2f})")
        assert abs(z) <= q, param


def test03_without_the_field_its_kernels_drag_the_border(monkeypatch):
    strategy_alone(monkeypatch, "bsdf")
    z = strategy_z(cf.light_triangle_scene(TRIANGLE), "tri.translate.z", shading_border=False)
    print(f"tri.translate.z: without the border's field, z {z:+.1f}")
    assert abs(z) > stats.norm.ppf(1.0 - 0.5 * ALPHA)


BALL = {"name": "ball", "type": "icosphere", "radius": 0.3, "subdivisions": 2, "smooth": True, "albedo": 0.0,
        "translate": [0.45, 0.2, 1.0]}  # fmt: skip
"""A black 320-face icosphere whose shadow on the light's plane covers the light's right part: about ten
outline edges across the light, two crossing its border."""
BALL_MOTIONS = ("ball.translate.x", "ball.scale")


def _ball_z(param: str) -> tuple[float, float]:
    """The cosine strategy alone (:func:`~tests.sphere3d.helpers.cosine_only`): (mean - exact) / standard
    error of dE/dθ at the origin, 2^20 samples in 16 batches, and the relative error."""
    scene = cf.light_triangle_scene(TRIANGLE)
    scene["shapes"] = [scene["shapes"][0], BALL]
    loaded = s3.load_scene(scene)
    _, exact = cf.occluded_light_irradiance(scene, param, build_state(loaded).epsilon)
    task = PointTask(loaded, param, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1 << 20, 3, 16)
    summary = summarize_batches(np.asarray(task.evaluate(variable(0.0), ReparamTransforms()).derivative))
    return float((summary.mean - exact) / summary.stderr), float((summary.mean - exact) / exact)


def test04_a_faceted_ball_s_outline_across_the_light_is_kept(monkeypatch):
    # the field keeps the light's border, the outline through the followed edge and, in kernels whose
    # rotation follows the border, the outline their probes see; Šidák over the motions
    cosine_only(monkeypatch)
    q = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, len(BALL_MOTIONS)), 15)
    for param in BALL_MOTIONS:
        z, relative = _ball_z(param)
        print(f"{param}: cosine strategy alone, z {z:+.2f} (q {q:.2f}), {relative:+.1%} of dE/dθ")
        assert abs(z) <= q, param


def test05_with_the_followed_edge_alone_the_outline_is_dragged(monkeypatch):
    # the field keeping only the followed edge and the border: the outline's other edges move by the
    # field's blend of the two (the rotation's motion near the edge, the border's rest near it)
    cosine_only(monkeypatch)
    monkeypatch.setattr(kernel_border, "CHAIN", 0)
    monkeypatch.setattr(kernel_border, "_seen_outline", lambda *args: [])
    q = stats.t.ppf(1.0 - 0.5 * ALPHA, 15)
    z, relative = _ball_z("ball.translate.x")
    print(f"ball.translate.x: followed edge alone, z {z:+.1f}, {relative:+.1%} of dE/dθ")
    assert z < -q and relative < -0.1
