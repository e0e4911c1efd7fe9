"""The film kernel of the pixel integral (:mod:`sphere3d.reparam.film_kernel`), piece by piece.

The snap that moves a bisected probe hit onto its triangle's edge or corner, the antithetic
pair of kernel centres and the option's checks; the kernel's effect on the derivative is
measured against the closed form in ``test_triangle_closed_form.py`` (test10).
"""

from __future__ import annotations

import numpy as np
import pytest

from flatland.core.dual import detach, tangent, variable
from flatland.core.rng import Draws
from flatland.core.validate import ValidationError
from sphere3d import closed_form as cf
from sphere3d.reparam.film_kernel import (
    KAPPA_FILM,
    _film_hull,
    _reaching_motion,
    check_kappa_film,
    film_transform,
    silhouette_snap,
)
from sphere3d.reparam.probes import ring_offsets
from sphere3d.scene import load_scene
from sphere3d.state import build_state
from sphere3d.tracing import attached_points
from sphere3d.vector import normalize
from tests.tiers import sweep


def _state(param="tri.translate.x"):
    return build_state(load_scene(cf.pinhole_triangle_scene(4, 8)), param, variable(0.0))


def test01_the_snap_moves_a_bisected_hit_onto_the_edge_or_its_corner_and_names_their_lines():
    state = _state()
    o = np.asarray(detach(state.camera.origin))
    tri = np.asarray(detach(state.triangles))[0]
    centroid, mid = tri.mean(axis=0), 0.5 * (tri[0] + tri[1])
    # inside: towards the centroid; outside: past the middle of edge V0 V1 on the same line, so the
    # plane of the two directions meets that edge at its middle
    inside = normalize(centroid - o)[None]
    outside = normalize(centroid + 1.5 * (mid - centroid) - o)[None]
    hits = state.tracer.intersect(o, inside)
    assert hits.triangle.tolist() == [0]
    far = np.array([[1e6, 1e6]])  # no corner within reach: the exit point on the edge
    t, u, v, lines = silhouette_snap(state, far, 1.0)(np.array([0]), o[None], inside, outside, hits)
    assert t.tolist() == [0]
    np.testing.assert_allclose(attached_points(tri, u, v)[0], mid, atol=1e-12)
    assert lines.tolist() == [[[0, 1], [0, 1]]]  # on the edge V0 V1 (twice: one line)
    fx, fy = state.camera.film(tri[0] - o)  # a kernel centred on V0's image: the corner V0
    _, u, v, corner = silhouette_snap(state, np.array([[fx, fy]]), 1.0)(
        np.array([0]), o[None], inside, outside, hits
    )
    assert (u.tolist(), v.tolist()) == ([0.0], [0.0])
    assert corner.tolist() == [[[0, 1], [0, 2]]]  # the corner V0 lies on its two edges


def test02_the_snap_walks_over_faces_to_the_edge_that_is_a_silhouette():
    # A square of two triangles facing the camera, split along V0 V2: a segment from inside the first
    # triangle to past the square's left side crosses the diagonal (an edge between two faces turned
    # towards the camera: no discontinuity) and leaves the square through V3 V0, its silhouette. The
    # snap follows V3 V0, on the second face, where the segment crosses it.
    scene = cf.pinhole_triangle_scene(4, 8)
    square = [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]]
    scene["shapes"][0].update(vertices=square, faces=[[0, 1, 2], [0, 2, 3]], translate=[0.0, 0.0, 0.0])
    state = build_state(load_scene(scene), "tri.translate.x", variable(0.0))
    o = np.asarray(detach(state.camera.origin))
    inside = normalize(np.array([0.5, -0.5, 0.0]) - o)[None]
    outside = normalize(np.array([-1.5, 0.5, 0.0]) - o)[None]
    hits = state.tracer.intersect(o, inside)
    assert hits.triangle.tolist() == [0]
    far = np.array([[1e6, 1e6]])
    t, u, v, lines = silhouette_snap(state, far, 1.0)(np.array([0]), o[None], inside, outside, hits)
    assert t.tolist() == [1]
    tri = np.asarray(detach(state.triangles))[1]
    np.testing.assert_allclose(attached_points(tri, u, v)[0], [-1.0, 0.25, 0.0], atol=1e-12)
    assert lines.tolist() == [[[2, 0], [2, 0]]]  # slots of V3 and V0 in the face (V0, V2, V3)


def test03_the_centres_are_an_antithetic_pair_and_rotations_follow_the_moving_triangle():
    state = _state()
    n = 400
    rng = np.random.default_rng(3)
    x, y = rng.uniform(2.0, 6.0, n), rng.uniform(2.0, 6.0, n)
    film = film_transform(state, x, y, Draws.of(5, np.arange(n)), KAPPA_FILM, 7, 3.0, 3)
    first, second = film.centres
    np.testing.assert_allclose(first + second, 2.0 * np.stack([x, y], axis=-1), atol=1e-12)
    assert len(film.rotations) == 2 and film.kappa == KAPPA_FILM
    # some kernels reach the moving triangle, whose rotations move; the others stay the identity
    for rotation in film.rotations:
        moving = np.any(tangent(rotation.target) != 0.0, axis=1)
        assert 0 < moving.sum() < n and np.all(rotation.active[moving])


def test04_the_options_checks():
    assert check_kappa_film("kappa_film", KAPPA_FILM) == 2.0 / 0.4**2  # σ = 0.4 px / √2, the same expression
    assert check_kappa_film("kappa_film", 3) == 3.0
    for bad, message in [(0.0, "must be > 0"), (1e13, r"must be <= 1e\+12"), (None, "kappa_film")]:
        with pytest.raises(ValidationError, match=message) as info:
            check_kappa_film("kappa_film", bad)
        assert str(info.value).startswith("kappa_film")


@pytest.mark.parametrize("scene", sweep(["hard_shadow", "hard_shadow_cube"], ["hard_shadow_cube"]))
def test05_rings_skipped_by_the_film_hull_cannot_see_the_moving_occluder(scene):
    """:func:`sphere3d.reparam.film_kernel._reaching_motion` is conservative: of 20000 film centres, every one
    whose centre or any of 64 points on its ring (radius 1.5 px) sees a moving triangle is kept; and
    the hull rules out a share of what its box keeps (else it would be pointless)."""
    state = build_state(load_scene(scene), "occluder.translate.x", variable(0.0))
    cam = state.camera
    moving = np.any(np.asarray(tangent(state.triangles)) != 0.0, axis=(1, 2))
    rng = np.random.default_rng(4)
    centre = rng.uniform(0.0, 64.0, size=(20000, 2))
    reach = 1.5
    ring = centre[:, None] + ring_offsets(reach, 65, rng.uniform(size=len(centre)))
    hits = state.tracer.intersect(detach(cam.origin), cam.directions(ring[..., 0], ring[..., 1]))
    sees = np.any(hits.on(moving), axis=1)
    kept = np.zeros(len(centre), dtype=bool)
    kept[_reaching_motion(state, centre, reach)] = True
    assert sees.sum() > 500 and np.all(kept[sees])
    (x0, x1, y0, y1), _ = _film_hull(state)
    box = (centre[:, 0] + reach >= x0) & (centre[:, 0] - reach <= x1)
    box &= (centre[:, 1] + reach >= y0) & (centre[:, 1] - reach <= y1)
    assert kept.sum() < 0.9 * box.sum()
