"""The emitter probes' cull (:mod:`sphere3d.reparam.penumbra`): the umbra and penumbra volume, exactly.

A unit square light at z = 1 and a moving square occluder [-a, a]² at z = 0.5, both parallel:
the segment from (x, y, z) to a light point (u, v, 1) crosses z = 0.5 at
``(x, y) (1 - t) + (u, v) t`` with ``t = (0.5 - z) / (1 - z)``, inside the occluder for some
|u|, |v| <= 1/2 exactly when ``|x|, |y| <= (a + t / 2) / (1 - t)`` (z < 0.5). So the points that can
see the occluder in front of the light are that square prism's cross-section at every height
below the occluder (2a + 1/2 at z = 0), and none above it. Points within 0.01 of that boundary
are not judged (the cull keeps a margin of a few ray offsets).
"""

from __future__ import annotations

import numpy as np

import sphere3d as s3
from flatland.core.dual import variable
from sphere3d.reparam.penumbra import (
    HULL_VERTICES,
    cone_may_see_motion,
    cones_overlap,
    may_see_motion,
    moving_occluders,
    separating_planes,
)
from sphere3d.state import build_state

A = 0.15
BAND = 0.01
"""Points this close to the volume's boundary are not judged (the margin is 4e-4 here)."""


def _scene(occluder: dict | None = None) -> dict:
    return {
        "name": "parallel_squares",
        "camera": {"position": [0.0, -3.0, 1.0], "look_at": [0.0, 0.0, 0.5], "fov": 0.8,
                   "width": 8, "height": 8},
        "sky": 0.0,
        "shapes": [
            {"name": "light", "type": "rectangle", "size": [1.0, 1.0], "translate": [0.0, 0.0, 1.0],
             "rotate": [np.pi, 0.0, 0.0], "emission": 1.0, "fade": 0.0, "albedo": 0.0},
            occluder or {"name": "occluder", "type": "rectangle", "size": [2 * A, 2 * A],
                         "translate": [0.0, 0.0, 0.5], "albedo": 0.5},
        ],
    }  # fmt: skip


def _state(occluder: dict | None = None):
    return build_state(s3.load_scene(_scene(occluder)), "occluder.translate.x", variable(0.0))


def _half_width(z: np.ndarray) -> np.ndarray:
    """Half-width of the volume's square cross-section at height z < 0.5 (module docstring)."""
    t = (0.5 - z) / (1.0 - z)
    return (A + t / 2.0) / (1.0 - t)


def test01_the_cull_keeps_exactly_the_penumbra_volume():
    """On a grid of heights below the occluder, every point inside the prism is kept and every point
    outside it ruled out; every point above the occluder, between it and the light, is ruled out.
    The bounding spheres alone keep the points outside (the planes do the ruling out here)."""
    state = _state()
    rng = np.random.default_rng(1)
    z = rng.choice([-1.0, -0.2, 0.0, 0.25, 0.45], size=20000)
    x = np.column_stack([rng.uniform(-2.5, 2.5, z.size), rng.uniform(-2.5, 2.5, z.size), z])
    reach = np.max(np.abs(x[:, :2]), axis=1) - _half_width(z)
    judged = np.abs(reach) > BAND
    kept = may_see_motion(state, x)
    assert np.all(kept[judged & (reach < 0.0)])
    assert not np.any(kept[judged & (reach > 0.0)])
    assert (reach < -BAND).sum() > 1000 and (reach > BAND).sum() > 1000
    above = np.column_stack(
        [rng.uniform(-0.6, 0.6, 2000), rng.uniform(-0.6, 0.6, 2000), rng.uniform(0.51, 0.99, 2000)]
    )
    assert not np.any(may_see_motion(state, above))
    # the bounding spheres alone keep nearly all that lies outside (measured: every point; the light's
    # sphere reaches down to z = 0.29): what is ruled out above, the planes ruled out
    assert np.mean(cones_overlap(state, x)[judged & (reach > 0.0)]) > 0.9


def test02_planes_separate_the_hulls_and_are_kept_per_state():
    """Every plane has the light's four corners on its positive side and the occluder's on its negative
    side (to rounding), the same object is returned for the same state, and a new one for another."""
    state = _state()
    planes = separating_planes(state)
    light = np.array([[u, v, 1.0] for u in (-0.5, 0.5) for v in (-0.5, 0.5)])
    occluder = np.array([[u, v, 0.5] for u in (-A, A) for v in (-A, A)])
    assert len(planes.normals) >= 4
    assert np.allclose(np.linalg.norm(planes.normals, axis=1), 1.0)
    assert np.all(light @ planes.normals.T - planes.offsets >= -1e-12)
    assert np.all(occluder @ planes.normals.T - planes.offsets <= 1e-12)
    assert separating_planes(state) is planes
    assert separating_planes(_state()) is not planes


def test03_no_plane_when_the_occluder_pierces_the_light():
    """A box through the light's plane (z 0.8 to 1.2) leaves no separating plane: the cull falls back
    to the bounding spheres, which keep the points below whose rays to the light pass through it."""
    box = {
        "name": "occluder",
        "type": "box",
        "size": [2 * A, 2 * A, 0.4],
        "translate": [0.0, 0.0, 1.0],
        "albedo": 0.5,
    }
    state = _state(box)
    assert separating_planes(state) is None
    x = np.array([[0.0, 0.0, 0.0], [1.5, 0.0, 0.0], [0.3, -0.2, 0.5]])
    assert may_see_motion(state, x).tolist() == [True, True, True]


def test04_a_fine_occluder_is_culled_through_an_outer_polytope():
    """An icosphere of 642 vertices (more than HULL_VERTICES) is replaced by an outer polytope of
    DIRECTIONS faces: the cull keeps every point whose segments to the light pass within 0.9 R of its
    centre (they meet the mesh, whose faces lie farther than 0.99 R from it), and rules out every point
    whose segments all pass farther than 2 R (the polytope lies within R / cos 35° of the centre, the
    directions' covering angle being below 35°; the rest of the factor for the planes not kept)."""
    radius = 0.15
    occluder = {"name": "occluder", "type": "icosphere", "radius": radius, "subdivisions": 3,
                "translate": [0.0, 0.0, 0.5], "albedo": 0.5}  # fmt: skip
    state = _state(occluder)
    moving = np.asarray(state.triangles.value)[moving_occluders(state)].reshape(-1, 3)
    assert len(np.unique(moving, axis=0)) > HULL_VERTICES
    assert len(separating_planes(state).normals) > 4
    rng = np.random.default_rng(2)
    z = rng.choice([-1.0, -0.2, 0.0, 0.25, 0.45], size=4000)
    x = np.column_stack([rng.uniform(-2.5, 2.5, z.size), rng.uniform(-2.5, 2.5, z.size), z])
    grid = (np.arange(24) + 0.5) / 24 - 0.5
    light = np.array([[u, v, 1.0] for u in grid for v in grid])
    centre = np.array([0.0, 0.0, 0.5])
    d = light[None] - x[:, None]  # segments to the light: 4000 x 576
    t = np.clip(np.sum((centre - x[:, None]) * d, axis=-1) / np.sum(d * d, axis=-1), 0.0, 1.0)
    gap = np.min(np.linalg.norm(x[:, None] + t[..., None] * d - centre, axis=-1), axis=1)
    kept = may_see_motion(state, x)
    assert np.all(kept[gap < 0.9 * radius]) and (gap < 0.9 * radius).sum() > 200
    assert not np.any(kept[gap > 2.0 * radius]) and (gap > 2.0 * radius).sum() > 1000


def test05_a_cone_that_may_meet_the_moving_occluder_is_kept():
    """:func:`cone_may_see_motion` (the BSDF kernels' cull): from random points, cones of random
    half-angles about random directions (half of them towards the square's neighbourhood); of 64 rays
    in each cone (its axis, and directions uniform in the cone's solid angle), any that meets the
    moving square (exactly: the plane z = 0.5 within [-A, A]²) has its cone kept. Cones pointing away
    are ruled out: the cull culls."""
    state = _state()
    rng = np.random.default_rng(5)
    m = 4000
    x = np.column_stack([rng.uniform(-2, 2, m), rng.uniform(-2, 2, m), rng.uniform(-1, 0.45, m)])
    axis = rng.normal(size=(m, 3))  # half of them random, half towards the square's neighbourhood
    aim = np.column_stack(
        [rng.uniform(-0.5, 0.5, m // 2), rng.uniform(-0.5, 0.5, m // 2), np.full(m // 2, 0.5)]
    )
    axis[: m // 2] = aim - x[: m // 2]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    half = rng.uniform(0.0, 0.3, m)
    kept = np.concatenate([cone_may_see_motion(state, x[i : i + 1], axis[i : i + 1], h) for i, h in
                           enumerate(half)])  # fmt: skip
    # directions in each cone: cos θ uniform in [cos h, 1] about the axis (the axis itself first)
    t = np.cross(axis, np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(axis, t)
    cos = 1.0 - rng.random((m, 64)) * (1.0 - np.cos(half))[:, None]
    cos[:, 0] = 1.0
    sin, phi = np.sqrt(1.0 - cos**2), rng.uniform(0.0, 2.0 * np.pi, (m, 64))
    d = cos[..., None] * axis[:, None] + sin[..., None] * (
        np.cos(phi)[..., None] * t[:, None] + np.sin(phi)[..., None] * b[:, None]
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (0.5 - x[:, None, 2]) / d[..., 2]
    hit_xy = x[:, None, :2] + s[..., None] * d[..., :2]
    meets = ((s > 0.0) & np.all(np.abs(hit_xy) <= A, axis=-1)).any(axis=1)
    assert meets.sum() > 100 and (~kept).sum() > 1000, (meets.sum(), (~kept).sum())
    assert np.all(kept[meets])
