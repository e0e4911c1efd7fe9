"""The emitter strategy's field (:mod:`sphere3d.reparam.emitter_field`), on its own and on a closed form.

Its pieces first: a great circle through the shading point is a line of the gnomonic chart, and the
chart line's velocity is that of the edge's projected points (central differences); an edge's great
circle turning with the rotation has no velocity relative to it. Then the estimator: the emitter
strategy alone (the cosine strategy's term set to 0) against finite differences of the same strategy
alone, on :func:`~sphere3d.closed_form.light_triangle_scene` where the triangle's shadow crosses the
light with two edges and a corner inside it, under the motions that move those edges apart; the
rotation alone (``emitter_field=False``) misses them. k parameters give each one's single-call
numbers, and the primal is naive's.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from flatland.core.dual import Dual, detach
from flatland.core.stats import sidak
from sphere3d import closed_form as cf
from sphere3d.render import irradiance
from sphere3d.reparam.chart_field import chart_line, relative_normal
from sphere3d.rotation import Rotation
from sphere3d.vector import cross, frame
from tests.sphere3d.helpers import strategy_alone, strategy_z

ALPHA = 1e-3
BATCHES = 16
TRIANGLE = np.array([[-0.25, -0.2, 0.0], [0.3, -0.15, 0.0], [0.0, 0.3, 0.0]]) + np.array([0.22, 0.1, 1.0])
"""Its shadow on the light's plane: two edges across the light, one corner inside it."""
MOTIONS = ("tri.translate.z", "tri.rotate.x", "tri.scale")
AT = dict(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), batches=BATCHES)


def _chart(p, axis, t, b):
    return np.stack([p @ t, p @ b], axis=-1) / (p @ axis)[..., None]


def _edge(rng, h=0.0):
    """A point x, an edge V1 V2 in front of it and their velocities, moved by h; the chart's frame."""
    x, x_dot = rng.normal(size=3) * 0.1, rng.normal(size=3)
    v, v_dot = rng.normal(size=(2, 3)) * 0.3 + np.array([0.0, 0.0, 2.0]), rng.normal(size=(2, 3))
    axis = np.array([0.1, -0.2, 1.0])
    axis /= np.linalg.norm(axis)
    t, b = frame(axis[None])
    return x + h * x_dot, v + h * v_dot, (x, x_dot, v, v_dot), (axis, t[0], b[0])


def test01_a_great_circle_through_the_point_is_a_line_of_the_chart():
    rng = np.random.default_rng(1)
    for _ in range(20):
        x, v, _, (axis, t, b) = _edge(rng)
        m = cross(v[0] - x, v[1] - x)[None]
        q, _, e, _ = chart_line(m, axis[None], t[None], b[None], None)
        n = np.array([-e[0, 1], e[0, 0]]) / np.linalg.norm(e[0])
        for p in v:  # both ends' projections lie on the line
            assert abs(n @ (_chart(p - x, axis, t, b) - q[0])) < 1e-12


def test02_the_chart_line_moves_as_its_projected_points():
    rng = np.random.default_rng(2)
    h = 1e-6
    for _ in range(20):
        _, _, (x, x_dot, v, v_dot), (axis, t, b) = _edge(rng)
        xd, vd = Dual(x, x_dot), Dual(v, v_dot)
        m = cross(vd[0] - xd, vd[1] - xd)
        q, q_dot, e, e_dot = chart_line(
            Dual(m.value[None], m.tangent[None]), axis[None], t[None], b[None], None
        )
        n = np.array([-e[0, 1], e[0, 0]]) / np.linalg.norm(e[0])
        for j in range(2):  # an end's projection stays on the line: n . its velocity = the line's there
            p = _chart(v[j] - x, axis, t, b)
            s = (p - q[0]) @ e[0] / (e[0] @ e[0])
            moved = [_chart(v[j] + d * v_dot[j] - x - d * x_dot, axis, t, b) for d in (h, -h)]
            rate = (moved[0] - moved[1]) / (2.0 * h)
            assert n @ rate == pytest.approx(n @ (q_dot[0] + s * e_dot[0]), rel=1e-6, abs=1e-8)


def test03_an_edge_turning_with_the_rotation_does_not_move_relative_to_it():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(5, 3))
    a /= np.linalg.norm(a, axis=1)[:, None]
    rotation = Rotation.following(Dual(a, rng.normal(size=(5, 3))))
    m0 = rng.normal(size=(5, 3))
    turned = rotation.apply(m0)  # m(θ) = R(θ) m0: tangent Ω × m0
    relative = relative_normal(turned, rotation, None)
    np.testing.assert_array_equal(detach(relative), m0)
    np.testing.assert_allclose(relative.tangent, 0.0, atol=1e-15)
    # a static edge moves against the rotation: -Ω × m
    np.testing.assert_array_equal(
        relative_normal(Dual(m0, np.zeros((5, 3))), rotation, None).tangent, -turned.tangent
    )


def test04_the_emitter_strategy_follows_both_shadow_edges_across_the_light(monkeypatch):
    # the field keeps the two shadow edges (and the light's border): within noise of finite differences
    # of the same strategy under recession, tilt and scaling, which move the edges apart
    strategy_alone(monkeypatch, "emitter")
    q = stats.norm.ppf(1.0 - 0.5 * sidak(ALPHA, len(MOTIONS)))
    for param in MOTIONS:
        z = strategy_z(cf.light_triangle_scene(TRIANGLE), param)
        print(f"{param}: emitter strategy alone, z {z:+.2f} (q {q:.2f})")
        assert abs(z) <= q, param


def test05_the_rotation_alone_misses_them(monkeypatch):
    # one rotation follows one of the two edges: the recession's derivative is missed beyond the noise
    strategy_alone(monkeypatch, "emitter")
    z = strategy_z(cf.light_triangle_scene(TRIANGLE), "tri.translate.z", emitter_field=False)
    print(f"tri.translate.z: the rotation alone, z {z:+.1f}")
    assert abs(z) > stats.norm.ppf(1.0 - 0.5 * ALPHA)


def test06_k_parameters_give_each_one_s_single_call_numbers_and_the_primal_is_naive_s():
    scene = cf.light_triangle_scene(TRIANGLE)
    names = list(MOTIONS)
    at = dict(AT, n=4096, seed=5)
    both = irradiance(scene, param=names, method="reparam", **at)
    for name in names:
        assert both[name] == irradiance(scene, param=name, method="reparam", **at), name
    assert both[names[0]].value == irradiance(scene, method="naive", **at).value
