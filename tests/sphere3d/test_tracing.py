"""Tracing: Embree against the brute-force tracer, and the Dual re-attachment against finite differences.

Embree works in float32 and the brute-force tracer in float64, so the two may disagree
on rays that pass within float32 rounding of a triangle edge; everything else must
agree: which triangle, the distance (to float32 precision), occlusion. The
re-attachment (Möller–Trumbore on Duals) must reproduce the float64 hit and have the
derivative of the intersection of a moving ray with a moving triangle.
"""

from __future__ import annotations

import numpy as np
import pytest

from flatland.core.dual import Dual, detach, tangent
from flatland.core.rng import stream
from sphere3d import shapes
from sphere3d.tracing import (
    BruteForceTracer,
    EmbreeTracer,
    attached_points,
    face_normals,
    intersect_triangles,
    make_tracer,
)
from sphere3d.vector import cross, normalize
from tests.tiers import SLOW


def _scene():
    """Three small meshes, grouped by shape: an icosphere, a box and a rectangle."""
    parts = [
        shapes.icosphere(0.5, 1).vertices[shapes.icosphere(0.5, 1).faces] + [0.0, 0.0, 1.0],
        shapes.box(0.6, 0.4, 0.5).vertices[shapes.box(0.6, 0.4, 0.5).faces] + [0.9, 0.2, 0.6],
        shapes.rectangle(3.0, 3.0).vertices[shapes.rectangle(3.0, 3.0).faces],
    ]
    tri = np.concatenate(parts)
    shape_of = np.concatenate([np.full(len(p), i) for i, p in enumerate(parts)])
    return tri, shape_of


def _rays(n, seed):
    rng = stream(seed, "test_tracing")
    origins = rng.uniform(-2.0, 2.0, (n, 3)) + np.array([0.0, 0.0, 1.5])
    targets = rng.uniform(-1.0, 1.0, (n, 3)) * [1.2, 1.2, 0.8] + [0.2, 0.0, 0.6]
    return origins, normalize(targets - origins)


def test01_embree_agrees_with_brute_force():
    tri, shape_of = _scene()
    o, d = _rays(20_000, 1)
    a = EmbreeTracer(tri, shape_of).intersect(o, d)
    b = BruteForceTracer(tri, shape_of).intersect(o, d)
    same = a.triangle == b.triangle
    # disagreements only for rays grazing an edge (float32 vs float64): at most 0.1 % of rays
    assert (~same).mean() <= 1e-3
    both = same & a.hit
    assert both.sum() > 5_000 and (~a.hit).sum() > 1_000  # the test sees hits and misses
    np.testing.assert_allclose(a.t[both], b.t[both], rtol=2e-5, atol=2e-5)
    np.testing.assert_allclose(a.u[both], b.u[both], atol=2e-4)
    np.testing.assert_allclose(a.v[both], b.v[both], atol=2e-4)
    assert np.array_equal(a.shape[both], shape_of[a.triangle[both]])


@SLOW
def test02_occlusion_queries_agree_with_intersection():
    tri, shape_of = _scene()
    o, d = _rays(20_000, 2)
    tmax = stream(3, "tmax").uniform(0.1, 4.0, len(o))
    for tracer in (EmbreeTracer(tri, shape_of), BruteForceTracer(tri, shape_of)):
        hits = tracer.intersect(o, d, tmax)
        occluded = tracer.occluded(o, d, tmax)
        assert (occluded != hits.hit).mean() <= 1e-3
        assert np.all(hits.t[hits.hit] <= tmax[hits.hit] * (1 + 1e-6))


def test03_reattachment_reproduces_the_hit_in_float64():
    tri, shape_of = _scene()
    o, d = _rays(5_000, 4)
    a = make_tracer(tri, shape_of, "embree").intersect(o, d)
    b = BruteForceTracer(tri, shape_of).intersect(o, d)
    ok = a.hit & (a.triangle == b.triangle)
    it = intersect_triangles(o[ok], d[ok], tri[a.triangle[ok]])
    np.testing.assert_allclose(it.t, b.t[ok], rtol=1e-10)
    np.testing.assert_allclose(it.b1, b.u[ok], atol=1e-10)
    np.testing.assert_allclose(it.b2, b.v[ok], atol=1e-10)
    np.testing.assert_allclose(it.point, o[ok] + b.t[ok, None] * d[ok], atol=1e-10)


def test04_reattachment_derivative_matches_finite_differences():
    # a moving origin, a rotating direction and a moving, deforming triangle
    rng = stream(5, "reattach")
    n = 200
    tri0 = np.array([[-1.0, -1.0, 2.0], [1.5, -0.5, 2.2], [0.0, 1.5, 1.8]])
    tri_dot = rng.normal(size=(n, 3, 3))
    o0, o_dot = rng.normal(scale=0.1, size=(n, 3)), rng.normal(size=(n, 3))
    d0 = normalize(np.array([0.05, 0.1, 1.0]) + rng.normal(scale=0.1, size=(n, 3)))
    d_dot = rng.normal(size=(n, 3))

    def at(theta):
        return (
            Dual(o0 + theta * o_dot, o_dot),
            normalize(Dual(d0 + theta * d_dot, d_dot)),
            Dual(tri0 + theta * tri_dot, tri_dot),
        )

    it = intersect_triangles(*at(0.0))
    h = 1e-6
    plus = intersect_triangles(*(detach(x) for x in at(h)))
    minus = intersect_triangles(*(detach(x) for x in at(-h)))
    for name in ("t", "b1", "b2", "point", "normal"):
        fd = (getattr(plus, name) - getattr(minus, name)) / (2 * h)
        np.testing.assert_allclose(tangent(getattr(it, name)), fd, rtol=1e-5, atol=1e-6, err_msg=name)


def test05_attached_points_follow_the_shape():
    rng = stream(6, "attached")
    tri = Dual(rng.normal(size=(50, 3, 3)), rng.normal(size=(50, 3, 3)))
    u, v = rng.uniform(0, 0.5, 50), rng.uniform(0, 0.5, 50)
    p = attached_points(tri, u, v)
    weights = np.stack([1 - u - v, u, v], axis=-1)
    np.testing.assert_allclose(detach(p), np.einsum("nj,njk->nk", weights, tri.value), atol=1e-14)
    # detached barycentrics: the point moves exactly as the same combination of the vertices
    np.testing.assert_allclose(tangent(p), np.einsum("nj,njk->nk", weights, tri.tangent), atol=1e-14)
    nrm = face_normals(tri)
    np.testing.assert_allclose(np.linalg.norm(detach(nrm), axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(np.einsum("ni,ni->n", detach(nrm), tangent(nrm)), 0.0, atol=1e-12)


def test06_hits_helpers_and_bad_backend():
    tri, shape_of = _scene()
    o, d = _rays(12, 7)
    hits = EmbreeTracer(tri, shape_of).intersect(o, d)
    grid = hits.reshape(3, 4)
    assert grid.shape.shape == (3, 4) and np.array_equal(grid.triangle.ravel(), hits.triangle)
    assert np.array_equal(hits.take(np.array([2, 0])).t, hits.t[[2, 0]])
    gone = hits.without(np.ones(12, dtype=bool))
    assert not gone.hit.any() and np.all(np.isinf(gone.t))
    empty = EmbreeTracer(tri, shape_of).intersect(np.zeros((0, 3)), np.zeros((0, 3)))
    assert empty.hit.shape == (0,)
    with pytest.raises(ValueError, match="tracer"):
        make_tracer(tri, shape_of, "optix")


def _cross_by_dual_rules(a, b):
    """The cross product by components through the Dual rules of ``*`` and ``-`` (a Dual per product)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def test07_cross_of_duals_gives_the_dual_rules_numbers_bit_for_bit():
    rng = stream(3, "test_tracing.cross")
    n = 500
    signed_zero = np.where(rng.uniform(size=(n, 3)) < 0.5, 0.0, -0.0)

    def dual(tangent_zero_rows):
        t = rng.normal(size=(n, 3))
        t[tangent_zero_rows] = signed_zero[tangent_zero_rows]  # zero tangents, both signs of zero
        return Dual(rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-3, 3, (n, 1)), t)

    a, b, plain = dual(slice(0, n, 3)), dual(slice(1, n, 2)), rng.normal(size=(n, 3))
    wide = Dual(rng.normal(size=(n, 4, 3)), rng.normal(size=(n, 4, 3)))
    for x, y in ((a, b), (a, plain), (plain, b), (a[:, None], wide), (wide, plain[:, None]), (a, plain[0])):
        got, want = cross(x, y), _cross_by_dual_rules(x, y)
        for part in (detach, tangent):
            g, w = part(got), part(want)
            assert g.shape == w.shape
            assert np.array_equal(g.view(np.int64), w.view(np.int64))  # the same bits, signs of 0 included
