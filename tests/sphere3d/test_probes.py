"""The probe heuristic of Loubet et al. 2019, Sec. 4.3, on hand-made configurations, one case per rule.

Scene: a big background wall at z = -2 and a small square occluder at z = -1 (both
facing the origin), plus a concave corner of two walls meeting at a right angle at
(x, y) = (6, -2), seen from inside. Probe rays start at the origin. Each test builds probe directions that
hit known surfaces and checks which point the heuristic follows.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from flatland.core.dual import Dual, detach, tangent, variable
from sphere3d import closed_form as cf
from sphere3d.reparam.paper import mean_point_direction, pair_index
from sphere3d.reparam.probes import (
    ring_directions,
    ring_offsets,
    select_points,
    vmf_spread_angle,
)
from sphere3d.reparam.snaps import line_spin
from sphere3d.rotation import Rotation
from sphere3d.scene import load_scene
from sphere3d.state import build_state
from sphere3d.tracing import attached_points
from sphere3d.vector import cross, normalize

CAMERA = {"position": [0, 0, 5], "look_at": [0, 0, 0], "up": [0, 1, 0], "fov": 0.8, "width": 4, "height": 4}
SCENE = {
    "name": "probes",
    "camera": CAMERA,
    "shapes": [
        {"name": "wall", "type": "rectangle", "size": [8, 8], "translate": [0, 0, -2]},
        {"name": "square", "type": "rectangle", "size": [0.5, 0.5], "translate": [0, 0, -1]},
        # a concave corner at x = 6: the floor of the corner (normal +x) and its side (normal +y)
        {
            "name": "left",
            "type": "rectangle",
            "size": [4, 4],
            "translate": [6, 0, -2],
            "rotate": [0, -math.pi / 2, 0],
        },
        {
            "name": "right",
            "type": "rectangle",
            "size": [4, 4],
            "translate": [4, -2, -2],
            "rotate": [math.pi / 2, 0, 0],
        },
    ],
}
WALL, SQUARE, LEFT, RIGHT = 0, 1, 2, 3


def _select(directions, param="square.translate.x"):
    scene = load_scene(SCENE)
    state = build_state(scene, param, variable(0.0))
    d = normalize(np.asarray(directions, dtype=float))[None]
    hits = state.tracer.intersect(np.zeros(3), d)
    point, found = select_points(state, Dual(np.zeros((1, 3))), np.zeros(3), d, hits)
    return state, hits, point, found


def test01_pair_index_is_the_last_probe_with_another_shape():
    shapes = np.array([[0, 0, 1, 1], [0, 0, 0, 0], [-1, 2, -1, 3], [1, -1, 1, 1], [-1, -1, -1, -1]])
    assert pair_index(shapes).tolist() == [3, 0, 3, 1, 0]


def test02_no_hit_means_no_point():
    _, _, _, found = _select([[0.0, 1.0, 0.2], [0.1, 1.0, 0.2]])
    assert not found[0]


def test03_single_hit_is_moved_to_the_silhouette_between_the_pair():
    # probe 0 hits the square (x in [-0.25, 0.25] at z = -1), probe 1 passes beside it and hits the wall:
    # the square occludes the wall, and its point is moved by bisection towards the edge x = 0.25
    _, hits, point, found = _select([[0.1, 0.0, -1.0], [0.3, 0.0, -1.0], [0.1, 0.05, -1.0]])
    assert found[0] and hits.shape[0].tolist() == [SQUARE, WALL, SQUARE]
    p = detach(point)[0]
    assert p[2] == pytest.approx(-1.0) and 0.25 - (0.3 - 0.1) / 8 <= p[0] <= 0.25
    assert tangent(point)[0] == pytest.approx([1.0, 0.0, 0.0])  # attached to the moving square


def test04_the_occluder_wins_whichever_probe_hit_it():
    _, _, point, _ = _select(
        [[0.3, 0.0, -1.0], [0.1, 0.0, -1.0]]
    )  # probe 0 on the wall, probe 1 on the square
    assert detach(point)[0][2] == pytest.approx(-1.0) and 0.2 <= detach(point)[0][0] <= 0.25


def test05_two_surfaces_meeting_give_their_crease():
    # from the origin, inside the corner, neither wall's tangent plane
    # separates the other hit from the origin, the normals are perpendicular, so the heuristic
    # intersects the two planes (x = 6 and y = -2) with the plane of the two probe directions
    _, hits, point, found = _select([[6.0, -1.0, -2.0], [5.0, -2.0, -2.0]])
    assert hits.shape[0].tolist() == [LEFT, RIGHT] and found[0]
    p = detach(point)[0]
    np.testing.assert_allclose(p, [6.0, -2.0, -16.0 / 7.0], atol=1e-12)  # in the plane of the probes
    np.testing.assert_allclose(tangent(point)[0], 0.0, atol=1e-12)  # neither wall moves with the square


def test06_parallel_surfaces_that_do_not_occlude_each_other_give_p0():
    # two coplanar halves of a wall: neither tangent plane separates the other's hit from the origin
    # and the normals are parallel, so the point is p0's, moved by bisection to the seam at x = 0
    halves = [
        {"name": "west", "type": "rectangle", "size": [2, 2], "translate": [-1, 0, -2]},
        {"name": "east", "type": "rectangle", "size": [2, 2], "translate": [1, 0, -2]},
    ]
    state = build_state(load_scene(dict(SCENE, shapes=halves)), "west.translate.x", variable(0.0))
    d = normalize(np.array([[[-0.3, 0.0, -1.0], [0.2, 0.0, -1.0]]]))
    hits = state.tracer.intersect(np.zeros(3), d)
    point, found = select_points(state, Dual(np.zeros((1, 3))), np.zeros(3), d, hits)
    assert hits.shape[0].tolist() == [0, 1] and found[0]
    p = detach(point)[0]
    assert p[2] == pytest.approx(-2.0) and -2 * 0.5 / 8 <= p[0] <= 0.0  # on the west half, near the seam
    assert tangent(point)[0].tolist() == [1.0, 0.0, 0.0]


def test07_the_rotation_follows_the_direction_from_a_moving_origin():
    scene = load_scene(SCENE)
    state = build_state(scene, "square.translate.x", variable(0.0))
    d = normalize(np.array([[[0.1, 0.0, -1.0], [0.3, 0.0, -1.0]]]))
    hits = state.tracer.intersect(np.zeros(3), d)
    origin = Dual(np.zeros((1, 3)), np.array([[0.0, 1.0, 0.0]]))  # the origin moves in y
    point, _ = select_points(state, origin, np.zeros(3), d, hits)
    to = point - origin
    np.testing.assert_allclose(tangent(to)[0], [1.0, -1.0, 0.0])


def test08_probe_patterns_and_mean_points():
    kappa, spread = 1e4, 3.0
    angle = vmf_spread_angle(kappa, spread)
    assert angle == pytest.approx(spread / math.sqrt(kappa), rel=1e-3)
    # the ring holds the Rayleigh probability of ``spread`` σ under the vMF's own angle CDF,
    # P(angle <= r) = (1 - e^{-κ(1 - cos r)}) / (1 - e^{-2κ}), also where the vMF is far from Gaussian
    r = vmf_spread_angle(1.0, spread)
    assert math.expm1(-(1.0 - math.cos(r))) / math.expm1(-2.0) == pytest.approx(-math.expm1(-4.5), rel=1e-12)
    centre = normalize(np.array([[0.2, -0.3, 0.9], [0.0, 0.0, -1.0]]))
    d = ring_directions(centre, angle, 4, np.array([0.1, 0.7]))
    np.testing.assert_allclose(d[:, 0], centre)
    np.testing.assert_allclose(np.einsum("mpk,mk->mp", d[:, 1:], centre), math.cos(angle), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-14)
    offsets = ring_offsets(1.5, 4, np.array([0.0]))
    np.testing.assert_allclose(np.linalg.norm(offsets[0], axis=-1), [0.0, 1.5, 1.5, 1.5])
    points = Dual(np.array([[[1.0, 0.0, 0.0], [3.0, 0.0, 0.0], [9.0, 9.0, 9.0]]]), np.ones((1, 3, 3)))
    direction, found = mean_point_direction(Dual(np.zeros((1, 3))), points, np.array([[True, True, False]]))
    assert found[0] and detach(direction)[0].tolist() == [2.0, 0.0, 0.0]
    assert tangent(direction)[0].tolist() == [1.0, 1.0, 1.0]


def test09_a_single_probe_stands_alone():
    # probes=1: no pair (pair_index of one column is 0), the probe's attached hit is followed where it
    # hits, the identity where it misses; this once raised "argmax of an empty sequence"
    assert pair_index(np.array([[3], [-1]])).tolist() == [0, 0]
    _, hits, point, found = _select([[0.1, 0.0, -1.0]])
    assert found[0] and hits.shape[0].tolist() == [SQUARE]
    np.testing.assert_allclose(detach(point)[0], [0.1, 0.0, -1.0], atol=1e-12)  # the hit, not moved
    assert tangent(point)[0].tolist() == [1.0, 0.0, 0.0]  # attached to the moving square
    _, _, _, found = _select([[0.0, 1.0, 0.2]])
    assert not found[0]
    d = ring_directions(normalize(np.array([[0.0, 0.0, -1.0]])), 0.1, 1, np.array([0.3]))
    assert d.shape == (1, 1, 3) and ring_offsets(2.0, 1, np.array([0.3])).tolist() == [[[0.0, 0.0]]]


@pytest.mark.parametrize("kappa", [1e-3, 1.0, 1000.0, 1e8])
def test10_the_ring_angle_is_defined_for_every_spread(kappa):
    # P(angle > r) = (e^{-κ(1 - cos r)} - e^{-2κ}) / (1 - e^{-2κ}) must be the Rayleigh tail e^{-spread²/2};
    # spread >= 8.7 with κ >= 19 once raised "math domain error" (log1p(-1) of a level rounded to 1)
    previous = 0.0
    for spread in [0.0, 0.5, 3.0, 8.5, 8.7, 9.0, 20.0, 40.0, 60.0, 1e3, 1e200, 1.7e308]:
        r = vmf_spread_angle(kappa, spread)
        assert previous <= r <= math.pi
        previous = r
        s, mass = 1.0 - math.cos(r), -math.expm1(-2.0 * kappa)
        tail = math.exp(-kappa * s) * -math.expm1(-kappa * (1.0 + math.cos(r))) / mass  # e^{-κs} - e^{-2κ}
        expected = math.exp(-0.5 * spread * spread) if spread < 1e100 else 0.0
        # s = 1 - cos r is known to a few ulps of 1 (δs = 1e-15): the tail to |d tail / ds| δs
        slack = kappa * math.exp(-kappa * s) / mass * 1e-15
        assert tail == pytest.approx(expected, rel=1e-12, abs=slack + 1e-300)
    assert vmf_spread_angle(kappa, 0.0) == 0.0
    assert vmf_spread_angle(1000.0, 60.0) == pytest.approx(math.acos(1.0 - 1.8), rel=1e-12)
    assert (
        vmf_spread_angle(1000.0, 1e3) == math.pi
    )  # the mass beyond 1000 σ is below e^{-2κ}: the whole sphere


@pytest.mark.parametrize("param", ["tri.rotate.z", "tri.rotate.x", "tri.translate.z"])
def test11_the_spin_makes_the_rotation_follow_the_edges_great_circle(param):
    """A rotation following a point of an edge, with the turn of :func:`~sphere3d.reparam.snaps.line_spin`,
    moves
    the edge's great circle (unit normal m̂ ∝ V0 × V1 seen from the origin) exactly as the edge moves it:
    Ω × m̂ = dm̂/dθ; without the turn it does not (the image turns: rotations, and perspective under
    z-translation); at a corner the turn is the mean of its two edges' rates."""
    scene = load_scene(cf.sky_triangle_scene([[-0.2, -0.5, 1.0], [0.9, 0.1, 1.1], [0.1, 0.6, 0.9]]))
    state = build_state(scene, param, variable(0.0))
    tri = state.triangles[[0]]
    origin = Dual(np.zeros((1, 3)))
    point = attached_points(tri, np.array([0.3]), np.array([0.0]))  # on the edge V0 V1 (v = 0)
    one = np.array([[[0, 1], [0, 1]]])
    rate = line_spin(tri, origin, point, one)
    m = normalize(cross(tri[:, 0], tri[:, 1]))
    a = normalize(detach(point))
    for spin in (rate, None):
        turn = None if spin is None else Dual(np.zeros(1), spin)
        rotation = Rotation.following(point, spin=turn)
        # the followed direction itself moves exactly, with or without the turn
        np.testing.assert_allclose(tangent(rotation.apply(a)), tangent(normalize(point)), atol=1e-12)
        big_omega = np.cross(a, tangent(normalize(point))) + (0.0 if spin is None else spin[:, None] * a)
        gap = np.abs(np.cross(big_omega, detach(m)) - tangent(m)).max()
        assert gap < 1e-12 if spin is not None else gap > 1e-3, gap
    corner = attached_points(tri, np.array([0.0]), np.array([0.0]))  # V0: on V0 V1 and V0 V2
    both = line_spin(tri, origin, corner, np.array([[[0, 1], [0, 2]]]))
    each = [line_spin(tri, origin, corner, np.array([[e, e]])) for e in ([0, 1], [0, 2])]
    np.testing.assert_allclose(both, 0.5 * (each[0] + each[1]), atol=1e-15)
