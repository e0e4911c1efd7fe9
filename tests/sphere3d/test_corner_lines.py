"""The moving least-squares field of :mod:`sphere3d.reparam.corner_lines`, on its own.

A moving corner (two to four edges as rays from its vertex V) and a static line L at a distance h:
the field keeps every line on its moved line (its normal velocity on each equals the line's), is the
meeting point's velocity where two lines meet (V, and an edge crossing L), its gradient matches
central differences of its value, k parameters give each one's field, and its squared strain over a
kernel grows as log(1 / h) as the corner nears the line (the one affine map keeping all three lines
grows as 1 / h²), and off a short segment's ends the field is bounded by their velocities (its whole
line's far points move with its turn times their distance); its trace alone, its value alone, and the
chart fields' compiled kernel (:mod:`sphere3d.reparam.field_kernel`) agree with it to rounding. The
film kernel's use of it is checked pixel by pixel against a closed form in
tests/sphere3d/test_junctions.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from sphere3d.reparam.corner_lines import EPSILON, line_field
from sphere3d.reparam.field_kernel import field_points, field_trace
from sphere3d.reparam.film_lines import FilmLines

REACH = 0.85  # the film kernel's ring radius at the defaults (3 x 0.28 px)


def _corner(rng, edges, h):
    """A corner at (0, h) moving at a random velocity with ``edges`` random edges turning at random
    rates, and the static line y = 0 (point, direction, velocities; ray flags)."""
    vertex, vertex_dot = np.array([0.0, h]), rng.normal(size=2)
    angle = np.sort(rng.uniform(0.0, 2.0 * np.pi, edges))
    e = 3.0 * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    e_dot = rng.normal(size=(edges, 2))
    q = np.vstack([np.tile(vertex, (edges, 1)), [[-5.0, 0.0]]])
    d = np.vstack([e, [[10.0, 0.0]]])
    q_dot = np.vstack([np.tile(vertex_dot, (edges, 1)), [[0.0, 0.0]]])
    d_dot = np.vstack([e_dot, [[0.0, 0.0]]])
    return q, d, q_dot, d_dot, np.arange(edges + 1) < edges


def _field(points, lines, k=None):
    """The field at ``points`` (m, 2) for the lines of :func:`_corner` (every point sees all of them);
    with ``k``, k parameters whose velocities are 1, 2, ... times the first's."""
    q, d, q_dot, d_dot, ray = lines
    m, p = len(points), len(q)
    rows = np.repeat(np.arange(m), p)
    tile = lambda a: np.tile(a, (m, 1))  # noqa: E731
    qd, dd = tile(q_dot), tile(d_dot)
    if k is not None:
        qd = np.stack([(i + 1) * qd for i in range(k)], axis=1)
        dd = np.stack([(i + 1) * dd for i in range(k)], axis=1)
    film = FilmLines(rows, tile(q), tile(d), qd, dd)
    return line_field(points, film, np.tile(ray, m), 1.0 / REACH**2)


def _normal(d):
    return np.array([-d[1], d[0]]) / np.linalg.norm(d)


@pytest.mark.parametrize("edges", [2, 3, 4])
def test01_the_field_keeps_every_line_on_its_moved_line(edges):
    # on each line (a ray's points s >= 0, the static line anywhere) n · v = n · (q_dot + s e_dot)
    rng = np.random.default_rng(edges)
    lines = _corner(rng, edges, 0.1)
    q, d, q_dot, d_dot, ray = lines
    for j in range(len(q)):
        s = rng.uniform(0.0, 0.4, 64) if ray[j] else rng.uniform(0.3, 0.7, 64)
        points = q[j] + s[:, None] * d[j]
        v, _ = _field(points, lines)
        n = _normal(d[j])
        want = (q_dot[j] + s[:, None] * d_dot[j]) @ n
        assert np.abs(v @ n - want).max() <= 1e-12 * (1.0 + np.abs(want).max())


def test02_where_two_lines_meet_the_field_is_their_meeting_point_s_velocity():
    # at the vertex: its velocity; where an edge crosses the static line y = 0: the crossing's, which
    # slides along the line at the rate that keeps it on the moving edge
    rng = np.random.default_rng(7)
    lines = _corner(rng, 2, 0.2)
    q, d, q_dot, d_dot, _ = lines
    v, _ = _field(q[:1], lines)
    assert np.allclose(v[0], q_dot[0], rtol=0, atol=1e-12)
    below = np.flatnonzero(d[:2, 1] < 0.0)
    for j in below:
        s = -q[j, 1] / d[j, 1]  # the edge reaches y = 0
        x = q[j] + s * d[j]
        v, _ = _field(x[None], lines)
        # the crossing moves along y = 0: v_y = 0, and stays on the edge: n · v = n · (q_dot + s e_dot)
        n = _normal(d[j])
        assert abs(v[0, 1]) <= 1e-10
        assert v[0] @ n == pytest.approx((q_dot[j] + s * d_dot[j]) @ n, abs=1e-10)


@pytest.mark.parametrize("h", [0.3, 0.01])
def test03_the_gradient_matches_central_differences_of_the_value(h):
    rng = np.random.default_rng(3)
    lines = _corner(rng, 3, h)
    points = rng.uniform(-REACH, REACH, (256, 2))
    _, grad = _field(points, lines)
    step = 1e-6
    for axis in range(2):
        offset = np.zeros(2)
        offset[axis] = step
        fd = (_field(points + offset, lines)[0] - _field(points - offset, lines)[0]) / (2.0 * step)
        # central differences' truncation (third derivatives up to ~1 / distance³) and rounding
        scale = 1.0 + np.abs(grad[..., axis])
        assert np.all(np.abs(fd - grad[..., axis]) <= 1e-5 * scale)


def test04_k_parameters_give_each_parameter_s_own_field():
    rng = np.random.default_rng(4)
    lines = _corner(rng, 3, 0.1)
    points = rng.uniform(-REACH, REACH, (128, 2))
    v, grad = _field(points, lines)
    vk, grad_k = _field(points, lines, k=3)
    assert vk.shape == (128, 3, 2) and grad_k.shape == (128, 3, 2, 2)
    for i in range(3):  # velocities (i + 1) times the first's: the field is linear in them
        assert np.allclose(vk[:, i], (i + 1) * v, rtol=1e-13, atol=1e-13)
        assert np.allclose(grad_k[:, i], (i + 1) * grad, rtol=1e-12, atol=1e-12)


def _strain(h):
    """∫ |∇v|² over the kernel disc of radius REACH about the corner's foot, on a polar grid refined
    toward the corner's triangle (radii log-spaced from h / 100)."""
    lines = _corner(np.random.default_rng(5), 2, h)
    radii = np.geomspace(h / 100.0, REACH, 400)
    r = np.sqrt(radii[1:] * radii[:-1])
    dr = np.diff(radii)
    phi = (np.arange(256) + 0.5) * 2.0 * np.pi / 256
    centre = np.array([0.0, 0.5 * h])
    points = centre + (r[:, None, None] * np.stack([np.cos(phi), np.sin(phi)], axis=-1)).reshape(-1, 2)
    _, grad = _field(points, lines)
    area = (r * dr)[:, None] * (2.0 * np.pi / 256) * np.ones((1, 256))
    return float(np.sum(np.sum(grad**2, axis=(1, 2)) * area.ravel()))


def test05_the_strain_grows_as_the_log_of_one_over_the_corner_s_height():
    # a decade nearer the line adds about the same squared strain (log growth); a 1 / h growth would
    # multiply the increment by 10, a 1 / h² by 100 (the one affine map keeping the three lines)
    strain = [_strain(h) for h in (1e-2, 1e-3, 1e-4, 1e-5)]
    steps = np.diff(strain)
    print("strain", np.round(strain, 2), "per decade", np.round(steps, 2))
    assert np.all(steps > 0.0)
    assert steps.max() <= 1.5 * steps.min()


def test06_without_a_prior_parallel_lines_alone_give_the_identity_not_nan():
    # mu = 0 (an absurdly wide ring: (1 / reach)² underflows) and two parallel lines: no pair of
    # conditions determines v anywhere off the lines' common normal; the field is 0, finite
    e = np.array([[1.0, 0.0], [2.0, 0.0]])
    q = np.array([[0.0, 0.0], [0.0, 1.0]])
    lines = FilmLines(np.array([0, 0]), q, e, np.array([[0.0, 1.0], [0.0, 2.0]]), np.zeros((2, 2)))
    v, grad = line_field(np.array([[0.3, 0.4]]), lines, np.zeros(2, dtype=bool), 0.0)
    assert np.all(v == 0.0) and np.all(np.isfinite(grad))


def test07_off_a_segment_s_ends_the_field_is_bounded_by_the_ends_velocities():
    # a short segment turning fast about its middle: its whole line's far points move with the turn times
    # their distance, its ends do not; the field off a segment's ends takes the nearer end's velocity
    length, spin = 1e-3, 1.0
    q = np.array([[-0.5 * length, 0.0]])
    e = np.array([[length, 0.0]])
    q_dot = np.array([[0.0, 0.5 * length * spin]])  # the ends move at ± spin · length / 2, across
    e_dot = np.array([[0.0, -length * spin]])
    lines = FilmLines(np.array([0]), q, e, q_dot, e_dot)
    far = np.array([[3.0, 0.2]])  # beyond the segment's end, near its line
    line, _ = line_field(far, lines, np.zeros(1, dtype=bool), 1.0)
    segment, _ = line_field(far, lines, np.ones(1, dtype=bool), 1.0, np.ones(1, dtype=bool))
    assert np.abs(segment).max() <= 0.5 * length * spin
    assert np.abs(line).max() > 100.0 * np.abs(segment).max()


def test08_the_compiled_field_matches_its_python_and_line_field_s_trace():
    # the chart fields' kernel (sphere3d.reparam.field_kernel): per point, the value and tr ∇v of the
    # whole-array field, to rounding, with and without k parameters, rays, segments and a prior
    rng = np.random.default_rng(8)
    for trial in range(40):
        m, count, k = 30, int(rng.integers(1, 10)), (None, 3)[trial % 2]
        slots = (count, 2) if k is None else (count, k, 2)
        rows = rng.integers(0, m, count)
        lines = FilmLines(rows, *rng.normal(size=(2, count, 2)), *rng.normal(size=(2, *slots)))
        ray = rng.random(count) < 0.5
        end = ray & (rng.random(count) < 0.5)
        at, mu = rng.normal(size=(m, 2)) * 2.0, (0.0, 1.0, 0.3)[trial % 3]
        v, trace = line_field(at, lines, ray, mu, end, "trace")
        v_full, grad = line_field(at, lines, ray, mu, end)
        np.testing.assert_allclose(trace, np.trace(grad, axis1=-2, axis2=-1), rtol=1e-10, atol=1e-12)
        np.testing.assert_array_equal(v, v_full)
        fast, fast_trace = field_trace(at, lines, ray, mu, end, True, EPSILON)
        np.testing.assert_allclose(fast, v, rtol=1e-9, atol=1e-12 * max(1.0, np.abs(v).max()))
        np.testing.assert_allclose(fast_trace, trace, rtol=1e-9, atol=1e-12 * max(1.0, np.abs(trace).max()))
        if trial < 4:  # the kernel as plain Python (its compiled form above)
            order = np.argsort(rows, kind="stable")
            start = np.searchsorted(rows[order], np.arange(m + 1))
            q_dot = lines.point_dot[order] if k else lines.point_dot[order][:, None]
            e_dot = lines.direction_dot[order] if k else lines.direction_dot[order][:, None]
            out_v, out_t = np.empty((m, q_dot.shape[1], 2)), np.empty((m, q_dot.shape[1]))
            field_points(
                at, start, lines.point[order], lines.direction[order], q_dot, e_dot, ray[order], end[order],
                mu, EPSILON**2, True, out_v, out_t,
            )  # fmt: skip
            np.testing.assert_allclose(out_v.reshape(fast.shape), fast, rtol=1e-12, atol=1e-300)
            np.testing.assert_allclose(out_t.reshape(fast_trace.shape), fast_trace, rtol=1e-12, atol=1e-300)
