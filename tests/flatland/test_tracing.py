"""Ray casting against segments and circles, re-attachment to θ, attached points, silhouettes."""

from __future__ import annotations

import numpy as np
import pytest

import flatland.tracing as tracing
from flatland.core.dual import detach, tangent, variable
from flatland.scene import load_scene
from flatland.state import build_state
from flatland.tracing import (
    attach,
    attached_points,
    cast,
    direction,
    film_coordinate,
    film_direction,
    silhouette_angles,
)

SCENE = {
    "name": "g",
    "camera": {"position": [0.0, -3.0], "direction": [0.0, 1.0], "fov": 1.2, "pixels": 8},
    "shapes": [
        {"name": "a", "type": "segment", "points": [[-1.0, 0.0], [1.0, 0.5]]},
        {"name": "b", "type": "polygon", "points": [[-0.5, 1.5], [0.5, 1.2], [0.2, 2.0]]},
        {"name": "c", "type": "circle", "center": [1.5, 1.0], "radius": 0.6},
        {"name": "d", "type": "circle", "center": [-1.5, 2.0], "radius": 0.4},
    ],
}


def _brute_force(geom, o, d):
    """Closest hit of one ray, primitive by primitive (the reference for the vectorized cast)."""
    best, prim = np.inf, -1
    for k in range(geom.n_seg):
        a, b = geom.seg_a[k], geom.seg_b[k]
        m = np.column_stack([d, a - b])
        if abs(np.linalg.det(m)) < 1e-14:
            continue
        s, u = np.linalg.solve(m, a - o)
        if s > 1e-9 and 0 <= u <= 1 and s < best:
            best, prim = s, k
    for j in range(geom.n_circ):
        p = o - geom.circ_c[j]
        roots = np.roots([1.0, 2 * d @ p, p @ p - geom.circ_r[j] ** 2])
        for s in roots[np.isreal(roots)].real:
            if s > 1e-9 and s < best:
                best, prim = s, geom.n_seg + j
    return prim, best


def _random_rays(seed: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` rays with origins uniform in [-3, 3]² (around the scene) and uniform directions."""
    rng = np.random.default_rng(seed)
    return rng.uniform(-3, 3, (n, 2)), direction(rng.uniform(-np.pi, np.pi, n))


def test01_cast_matches_a_brute_force_reference():
    geom = build_state(load_scene(SCENE))
    origins, dirs = _random_rays(1, 300)
    hits = cast(geom, origins, dirs)
    for i in range(300):
        prim, dist = _brute_force(geom, origins[i], dirs[i])
        assert hits.prim[i] == prim
        if prim >= 0:
            assert np.isclose(hits.dist[i], dist)
    assert 50 < np.count_nonzero(hits.hit) < 300


def test02_hit_coordinates_locate_the_hit_point():
    geom = build_state(load_scene(SCENE))
    origins, dirs = _random_rays(2, 500)
    hits = cast(geom, origins, dirs)
    rows = np.flatnonzero(hits.hit)
    point = origins[rows] + hits.dist[rows, None] * dirs[rows]
    located, _ = attached_points(geom, hits.prim[rows], hits.coord[rows])
    assert np.allclose(point, located)
    seg = hits.prim[rows] < geom.n_seg
    assert np.all((hits.coord[rows][seg] >= 0) & (hits.coord[rows][seg] <= 1))


def test03_chunking_and_ignore(monkeypatch):
    geom = build_state(load_scene(SCENE))
    origins, dirs = _random_rays(3, 400)
    whole = cast(geom, origins, dirs)
    monkeypatch.setattr(tracing, "MAX_PAIRS", 13)  # two rays per chunk
    chunked = cast(geom, origins, dirs)
    assert np.array_equal(whole.prim, chunked.prim) and np.array_equal(whole.dist, chunked.dist)
    ignored = cast(geom, origins, dirs, ignore=whole.prim)
    assert not np.any((ignored.prim == whole.prim) & whole.hit)
    # a ray leaving a segment from its surface does not hit it again
    x = np.array([[0.0, 0.25]])
    assert cast(geom, x, direction(np.array([1.3])), ignore=np.array([0])).prim[0] != 0


def test04_attach_gives_the_hit_and_its_derivative():
    """The re-attached hit equals the cast one; its tangent equals a central difference of the moved hit."""
    scene = load_scene(SCENE)
    rng = np.random.default_rng(4)
    origins = np.tile([0.1, -2.5], (200, 1))
    dirs = direction(rng.uniform(0.9, 2.2, 200))
    for param in ("a.rotate", "b.vertex.2.x", "c.translate.y", "c.scale", "d.translate.x"):
        geom = build_state(scene, param, variable(0.0))
        hits = cast(geom, origins, dirs)
        rows = np.flatnonzero(hits.hit)
        att = attach(geom, hits, rows, origins[rows], dirs[rows])
        assert np.allclose(detach(att.point), origins[rows] + hits.dist[rows, None] * dirs[rows])
        h = 1e-6
        moved = []
        for sign in (1, -1):
            g = build_state(scene, param, sign * h)
            hh = cast(g, origins[rows], dirs[rows])
            same = hh.prim == hits.prim[rows]
            moved.append((origins[rows] + hh.dist[:, None] * dirs[rows], same))
        same = moved[0][1] & moved[1][1]
        fd = (moved[0][0] - moved[1][0]) / (2 * h)
        assert np.allclose(tangent(att.point)[same], fd[same], atol=1e-5), param


def test05_attached_points_move_with_the_shape():
    scene = load_scene(SCENE)
    prim = np.array([0, 1, 2, 4, 5])
    coord = np.array([0.3, 0.8, 0.5, 0.7, -2.0])
    for param in ("a.translate.x", "b.rotate", "c.scale", "d.translate.y"):
        p, n = attached_points(build_state(scene, param, variable(0.0)), prim, coord)
        h = 1e-6
        fd = (
            attached_points(build_state(scene, param, h), prim, coord)[0]
            - attached_points(build_state(scene, param, -h), prim, coord)[0]
        ) / (2 * h)
        assert np.allclose(tangent(p), fd, atol=1e-6), param
        assert np.allclose(np.linalg.norm(detach(n), axis=1), 1.0)


def test06_silhouette_angles_point_at_vertices_and_circle_tangents():
    scene = load_scene(SCENE)
    geom = build_state(scene, "c.translate.x", variable(0.0))
    o = np.array([[0.0, -3.0], [2.5, 3.0], [1.5, 1.0]])  # the last one is inside circle c
    phi, exists = silhouette_angles(geom, o)
    v = detach(geom.vertices)
    n_v = v.shape[0]
    assert np.allclose(
        phi.value[:, :n_v], np.arctan2(v[None, :, 1] - o[:, None, 1], v[None, :, 0] - o[:, None, 0])
    )
    # tangent directions are perpendicular to the radius at the tangent point
    c, r = detach(geom.circ_c), detach(geom.circ_r)
    for side in (0, 1):
        cols = n_v + side * 2 + np.arange(2)
        d = direction(phi.value[:, cols])
        w = c[None] - o[:, None]
        along = np.sum(w * d, axis=2)
        foot = o[:, None] + along[..., None] * d
        dist = np.linalg.norm(foot - c[None], axis=2)
        ok = exists[:, cols]
        assert np.allclose(dist[ok], np.broadcast_to(r, dist.shape)[ok])
    assert not exists[2, n_v] and not exists[2, n_v + 2] and exists[2, n_v + 1]
    # circle c moves with θ: its tangent angles do, by the derivative of base ± arcsin(r / |c - o|)
    h = 1e-6
    fd = (
        silhouette_angles(build_state(scene, "c.translate.x", h), o)[0]
        - silhouette_angles(build_state(scene, "c.translate.x", -h), o)[0]
    ) / (2 * h)
    assert np.allclose(tangent(phi)[exists], fd[exists], atol=1e-6)


@pytest.mark.parametrize("param", ["camera.rotate", "camera.translate.x"])
def test07_film_coordinate_inverts_film_direction(param):
    geom = build_state(load_scene(SCENE), param, variable(0.0))
    t = np.linspace(-0.6, 0.6, 7)
    d = film_direction(geom, t)
    back = film_coordinate(geom, d)
    assert np.allclose(detach(back), t)
    # a fixed world point: its film coordinate moves with the camera
    p = np.array([[0.3, 1.0]])
    tp = film_coordinate(geom, p - geom.cam_o)
    assert abs(float(tangent(tp)[0])) > 0.1
