"""Discontinuity lines on the film (:mod:`sphere3d.reparam.film_lines`).

The least-norm affine map that keeps two lines keeps them to first order: the residual of a
moved point off its moved line falls as the square of the step, for random lines, and for k
parameters each column is that parameter's own map. The per-state tables answer a kernel's query
as a brute-force distance to every edge image does: the nearest static edge within reach, and the
count and the nearest of the moving edges within reach.
"""

from __future__ import annotations

import numpy as np
import pytest

from flatland.core.dual import detach, variable
from sphere3d import closed_form as cf
from sphere3d.boundary.camera import camera_candidates
from sphere3d.boundary.edges import mesh_edges
from sphere3d.live import moves
from sphere3d.reparam.film_lines import (
    FilmLines,
    blend_map,
    film_segments,
    line_map,
    moving_edges,
    static_lines,
)
from sphere3d.reparam.junctions import junction_maps
from sphere3d.scene import load_scene
from sphere3d.state import build_state


def _cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _random_lines(rng, m, k=None):
    slots = () if k is None else (k,)
    return FilmLines(
        np.arange(m), rng.normal(size=(m, 2)) * 3.0, rng.normal(size=(m, 2)),
        rng.normal(size=(m, *slots, 2)), rng.normal(size=(m, *slots, 2)),
    )  # fmt: skip


def test01_the_line_map_keeps_both_lines_to_first_order():
    # A(u) = u + h (a' + B' (u - c)) maps points of each line onto the line moved by h: the residual
    # (the moved point's distance off the moved line) is O(h^2): it falls 100-fold from h = 1e-3 to
    # 1e-4 (a first-order error would fall 10-fold), at points on and beyond the kernel
    rng = np.random.default_rng(5)
    m = 64
    centre = rng.normal(size=(m, 2))
    lines = (_random_lines(rng, m), _random_lines(rng, m))
    a_dot, b_dot = line_map(centre, *lines)
    residual = {}
    for h in (1e-3, 1e-4):
        worst = 0.0
        for line in lines:
            for s in (-1.0, 0.5, 3.0):
                u = line.point + s * line.direction
                moved = u + h * (a_dot + np.einsum("mij,mj->mi", b_dot, u - centre))
                q, d = line.point + h * line.point_dot, line.direction + h * line.direction_dot
                worst = max(worst, np.abs(_cross(moved - q, d / np.linalg.norm(d, axis=1)[:, None])).max())
        residual[h] = worst
    assert residual[1e-4] < 0.02 * residual[1e-3]


def test02_for_k_parameters_each_column_is_that_parameter_s_map():
    rng = np.random.default_rng(6)
    m, k = 16, 3
    centre = rng.normal(size=(m, 2))
    first, second = _random_lines(rng, m, k), _random_lines(rng, m, k)
    a_dot, b_dot = line_map(centre, first, second)
    assert a_dot.shape == (m, k, 2) and b_dot.shape == (m, k, 2, 2)

    def column(line, j):
        return FilmLines(
            line.rows, line.point, line.direction, line.point_dot[:, j], line.direction_dot[:, j]
        )

    empty = line_map(
        centre[:0], *(FilmLines(*(part[:0] for part in vars(x).values())) for x in (first, second))
    )
    assert empty[0].shape == (0, k, 2) and empty[1].shape == (0, k, 2, 2)  # no rows: still k columns
    for j in range(k):
        a_j, b_j = line_map(centre, column(first, j), column(second, j))
        np.testing.assert_allclose(a_dot[:, j], a_j, rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(b_dot[:, j], b_j, rtol=0.0, atol=1e-12)


def _segment_distance(p, a, d):
    """Distances (m, S) from points p (m, 2) to segments a + t d, t in [0, 1] (S, 2)."""
    rel = p[:, None] - a[None]
    t = np.clip(np.sum(rel * d[None], axis=-1) / np.sum(d * d, axis=-1)[None], 0.0, 1.0)
    return np.hypot(*np.moveaxis(rel - t[..., None] * d[None], -1, 0))


@pytest.mark.parametrize("scene", [cf.corner_junction_scene(0.3), cf.sliver_scene()])
def test03_the_tables_answer_as_distances_to_every_edge_image(scene):
    # brute force over every candidate edge (a few here): its clipped film segment, and each kernel
    # centre's distance to it; the tables' answers are the same (the film is widened by the filter's
    # radius in the tables, so the centres stay inside the film)
    loaded = load_scene(scene)
    state = build_state(loaded, "tri.translate.y", variable(0.0))
    edges = mesh_edges(state.triangles, state.shape_of, state.corners)
    a, b = edges.endpoints(state.triangles)
    candidate = camera_candidates(state, edges)
    moving = np.any(moves(a), axis=-1) | np.any(moves(b), axis=-1)
    reach = 0.85
    rng = np.random.default_rng(7)
    centre = rng.uniform(0.0, 16.0, size=(4000, 2))
    for still in (True, False):
        keep = np.flatnonzero(candidate & (moving != still))
        p, d, _, _ = film_segments(state, a[keep], b[keep])
        dist = _segment_distance(centre, p, d)
        near = dist <= reach
        if still:
            got = static_lines(state, centre, reach)
            rows = np.flatnonzero(near.any(axis=1))
            nearest = np.argmin(np.where(near, dist, np.inf), axis=1)[rows]
        else:
            moving = moving_edges(state, centre, reach)
            np.testing.assert_array_equal(moving.count, near.sum(axis=1))
            got = moving.first
            rows = np.flatnonzero(near.any(axis=1))
            nearest = np.argmin(np.where(near, dist, np.inf), axis=1)[rows]
        assert rows.size > 50 and np.array_equal(got.rows, rows)
        # the same line: its direction parallel to the edge's, its point on the edge's line
        d_n = d[nearest] / np.linalg.norm(d[nearest], axis=1)[:, None]
        assert (
            np.abs(_cross(got.direction / np.linalg.norm(got.direction, axis=1)[:, None], d_n)).max() < 1e-9
        )
        assert np.abs(_cross(got.point - p[nearest], d_n)).max() < 1e-9


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test04_a_kernel_on_a_turning_crease_keeps_its_line(axis):
    # The box of hard_shadow_cube turning about each axis: kernels at the middle of each visible crease
    # (two front faces meeting, far from the corners) get a map (junctions.junction_maps), and it moves
    # points of the crease's image along the crease's own moved image: the crease's ends projected at
    # θ = ±h give the moved line; the residual of a mapped point off it is O(h^2) (100-fold from
    # h = 1e-3 to 1e-4; a rotation following one point of the crease drifts off it at O(h))
    scene = load_scene("hard_shadow_cube")
    param = f"occluder.rotate.{axis}"
    state = build_state(scene, param, variable(0.0))
    edges = mesh_edges(state.triangles, state.shape_of, state.corners)
    o = np.asarray(detach(state.camera.origin))
    a, b = edges.endpoints(state.triangles)
    s1 = np.einsum("ek,ek->e", o - edges.a, edges.n1)
    s2 = np.einsum("ek,ek->e", o - edges.a, edges.n2)
    seen = np.flatnonzero(edges.crease & (s1 > 0.0) & (s2 > 0.0))  # creases between two front faces
    p, d, _, _ = film_segments(state, a[seen], b[seen])
    centre = p + 0.5 * d
    rows, maps = junction_maps(state, centre, centre, 0.85)
    assert rows.size >= 2  # at least two of the box's three front creases have one in sight here
    residual = {}
    for h in (1e-3, 1e-4):
        worst = 0.0
        ends = []
        for sign in (1.0, -1.0):
            moved = build_state(scene, param, sign * h)
            tri = np.asarray(moved.triangles)
            am, bm = tri[edges.face[seen], edges.ia[seen]], tri[edges.face[seen], edges.ib[seen]]
            fa = np.stack(moved.camera.film(am - moved.camera.origin), axis=-1)
            fb = np.stack(moved.camera.film(bm - moved.camera.origin), axis=-1)
            ends.append((fa, fb))
        for (fa, fb), sign in zip(ends, (1.0, -1.0), strict=True):
            for s in (0.3, 0.5, 0.7):
                u = p[rows] + s * d[rows]
                mapped = u + sign * h * (maps.a_dot + np.einsum("mij,mj->mi", maps.b_dot, u - maps.centre))
                line = fb[rows] - fa[rows]
                unit = line / np.linalg.norm(line, axis=1)[:, None]
                worst = max(worst, np.abs(_cross(mapped - fa[rows], unit)).max())
        residual[h] = worst
    assert residual[1e-4] < 0.02 * residual[1e-3]


def _line(point, direction, point_dot, direction_dot):
    return FilmLines(np.zeros(1, dtype=np.int64), *(np.array([v], dtype=np.float64) for v in
                     (point, direction, point_dot, direction_dot)))  # fmt: skip


def test05_the_blended_field_keeps_both_lines_and_confines_a_sliver_s_strain():
    # (a) at points of each line the field's normal component is that line's normal velocity (a line
    # q + s l moving at q' + s l': (v - q' - s l') x l = 0), for crossing and for nearly parallel lines;
    # (b) near a crossing within reach (pinned to J's velocity) the gradient stays bounded: the same
    # at 1e-3 and 1e-7 px from J; (c) beside a sliver of gap g between nearly parallel lines (one
    # moving across, one static) the strain 1 / g is confined: 10 g beyond both lines at most a tenth
    # of its value inside, where the one affine map keeping both lines strains alike everywhere
    rng = np.random.default_rng(8)
    still = ((0.0, 0.0), (0.0, 0.0))
    cases = {
        "crossing": (
            _line((0.0, 0.0), (1.0, 0.3), (0.4, -1.0), (0.1, 0.2)),
            _line((0.2, -0.5), (0.2, 1.0), *still),
        ),
        "sliver": (
            _line((0.0, 0.01), (1.0, 0.002), (0.0, 1.0), (0.0, 0.0)),
            _line((0.0, 0.0), (1.0, 0.0), *still),
        ),
    }
    for name, (first, second) in cases.items():
        for line in (first, second):
            s = rng.uniform(-0.8, 0.8, size=64)
            at = line.point + s[:, None] * line.direction
            centre = np.zeros((64, 2))
            parts = [(x.point, x.direction, x.point_dot, x.direction_dot) for x in (first, second)]
            rep = [FilmLines(np.arange(64), *(np.repeat(p, 64, axis=0) for p in part)) for part in parts]
            v, _ = blend_map(centre, at, *rep, 0.85)
            moved = v - line.point_dot - s[:, None] * line.direction_dot
            np.testing.assert_allclose(_cross(moved, line.direction), 0.0, atol=1e-9, err_msg=name)
    first, second = cases["crossing"]
    den = _cross(first.direction, second.direction)
    j = first.point + (_cross(second.point - first.point, second.direction) / den)[:, None] * first.direction
    near = [
        blend_map(np.zeros((1, 2)), j + rho * np.array([[0.6, 0.8]]), first, second, 0.85)[1]
        for rho in (1e-3, 1e-7)
    ]
    assert np.abs(near[1]).max() <= 2.0 * np.abs(near[0]).max() + 1e-9
    first, second = cases["sliver"]
    inside = blend_map(np.zeros((1, 2)), np.array([[0.0, 0.005]]), first, second, 0.85)[1]
    beyond = blend_map(np.zeros((1, 2)), np.array([[0.0, 0.01 + 0.1]]), first, second, 0.85)[1]
    assert np.abs(beyond).max() <= 0.1 * np.abs(inside).max()
