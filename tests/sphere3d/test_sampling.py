"""Every sample/pdf pair of sphere3d.sampling, chi-square tested where it lives: on the sphere,
on triangles, on meshes, on the film.

Directions are binned in (s = 1 - cos θ, φ) about an axis (dω = ds dφ), 15 × 9 = 135 bins
(odd); triangles in a 13 × 13 barycentric grid (91 cells with area, odd); the film in 15 ×
15 cells. Expected counts integrate the claimed pdf over each bin (8 × 8 Gauss–Legendre
points), so a wrong normalization or shape fails. 200 000 samples per case, fixed seeds.
The whole file rejects correct samplers with probability ALPHA = 1e-3: each case is
tested at the Šidák level sidak(ALPHA, number of cases).
"""

from __future__ import annotations

import numpy as np
import pytest

from flatland.core.dual import Dual
from flatland.core.rng import stream
from flatland.core.stats import chi2_gof_counts, sidak
from sphere3d import sampling as s
from sphere3d.shapes import inline_mesh
from sphere3d.tracing import face_normals
from sphere3d.vector import frame, normalize

N = 200_000
ALPHA = 1e-3
NS, NPHI = 15, 9
AXIS = normalize(np.array([0.3, -0.5, 0.8]))
KAPPAS = (1.0, 10.0, 100.0, 1e3, 1e4, 1e5)

# an emitter mesh of unequal triangles seen from the origin
MESH = inline_mesh(
    "mesh",
    [[-0.5, -0.4, 1.0], [0.6, -0.5, 1.2], [0.2, 0.5, 0.9], [-0.6, 0.6, 1.1], [0.9, 0.4, 1.4]],
    [[0, 1, 2], [0, 2, 3], [1, 4, 2]],
)
MESH_TRI = MESH.vertices[MESH.faces]


def _sphere_points(axis, s_grid, phi_grid):
    t, b = frame(axis)
    sin_t = np.sqrt(np.maximum(s_grid * (2.0 - s_grid), 0.0))
    return (
        (1.0 - s_grid)[..., None] * axis
        + (sin_t * np.cos(phi_grid))[..., None] * t
        + (sin_t * np.sin(phi_grid))[..., None] * b
    )


def _sphere_test(samples, pdf, axis, s_max):
    """Chi-square of directions against a pdf per steradian, binned in (s, φ) about ``axis``."""
    t, b = frame(axis)
    rel = samples - axis
    s_val = 0.5 * np.einsum("...i,...i->...", rel, rel)  # 1 - cos θ without cancellation
    phi = np.arctan2(samples @ b, samples @ t) % (2 * np.pi)
    inside = s_val < s_max
    counts, _, _ = np.histogram2d(
        s_val[inside], phi[inside], bins=(NS, NPHI), range=((0.0, s_max), (0.0, 2 * np.pi))
    )
    x, w = np.polynomial.legendre.leggauss(8)
    s_edges = np.linspace(0.0, s_max, NS + 1)
    p_edges = np.linspace(0.0, 2 * np.pi, NPHI + 1)
    s_nodes = (0.5 * (s_edges[:-1] + s_edges[1:]))[:, None] + (0.5 * np.diff(s_edges))[:, None] * x
    p_nodes = (0.5 * (p_edges[:-1] + p_edges[1:]))[:, None] + (0.5 * np.diff(p_edges))[:, None] * x
    grid_s = s_nodes[:, None, :, None]
    grid_p = p_nodes[None, :, None, :]
    dens = pdf(_sphere_points(axis, *np.broadcast_arrays(grid_s, grid_p)))
    mass = np.einsum("ijkl,k,l->ij", dens, w, w) * (0.5 * s_max / NS) * (0.5 * 2 * np.pi / NPHI)
    expected = N * np.append(mass.ravel(), max(1.0 - mass.sum(), 0.0))
    observed = np.append(counts.ravel(), (~inside).sum())
    return chi2_gof_counts(observed, expected)


SPHERE_CASES = {
    "uniform_sphere": (s.sample_uniform_sphere, s.pdf_uniform_sphere, AXIS, 2.0),
    "cosine_hemisphere": (
        lambda u: s.sample_cosine_hemisphere(u, AXIS),
        lambda w: s.pdf_cosine_hemisphere(w, AXIS),
        AXIS,
        1.0,
    ),
}
for _k in KAPPAS:
    SPHERE_CASES[f"vmf_{_k:g}"] = (
        lambda u, k=_k: s.sample_vmf(u, AXIS, k),
        lambda w, k=_k: s.pdf_vmf(w, AXIS, k),
        AXIS,
        min(2.0, 12.0 / _k),
    )
FILM_CASES = tuple(s.FILTERS)
LEVEL = sidak(ALPHA, len(SPHERE_CASES) + len(FILM_CASES) + 2)
Z = 4.0
"""Normal quantile for the closed-form expectation tests (two-sided 99.994 %)."""


def _uniforms(name, dim):
    return stream(11, "test_sampling_sphere3d", sum(map(ord, name))).random((N, dim))


@pytest.mark.parametrize("name", list(SPHERE_CASES))
def test01_direction_samplers_match_their_pdf_chi_square(name):
    sample, pdf, axis, s_max = SPHERE_CASES[name]
    result = _sphere_test(sample(_uniforms(name, 2)), pdf, axis, s_max)
    assert result.passed(LEVEL), f"{name}: {result} (level {LEVEL:.2e})"


def test02_triangle_sampler_matches_pdf_chi_square():
    v0, v1, v2 = np.array([0.2, -1.0, 0.5]), np.array([2.0, 0.3, 0.1]), np.array([-0.4, 1.2, 0.9])
    x = s.sample_triangle(_uniforms("triangle", 2), v0, v1, v2)
    # barycentrics of v1, v2 by least squares on the triangle's plane
    basis = np.stack([v1 - v0, v2 - v0], axis=1)
    b = np.linalg.lstsq(basis, (x - v0).T, rcond=None)[0].T
    k = 13
    counts, _, _ = np.histogram2d(b[:, 0], b[:, 1], bins=k, range=((0, 1), (0, 1)))
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    overlap = np.where(i + j + 2 <= k, 1.0, np.where(i + j + 1 == k, 0.5, 0.0)) / k**2  # area in (b1, b2)
    density = (
        s.pdf_triangle(x[:1], v0, v1, v2)[0] * 2.0 * s.triangle_area(v0, v1, v2)
    )  # per unit (b1, b2) area
    cells = overlap > 0
    assert cells.sum() % 2 == 1
    result = chi2_gof_counts(counts[cells], N * density * overlap[cells])
    assert result.passed(LEVEL), f"{result} (level {LEVEL:.2e})"


def test03_mesh_sampler_picks_triangles_by_area_chi_square():
    u = _uniforms("mesh", 3)
    x, index = s.sample_mesh(u, MESH_TRI)
    # the point is sample_triangle's on the picked triangle, bit for bit (also with two sample axes): both
    # share one barycentric combination, so this checks sample_mesh's per-coordinate gather of the corners
    tri = MESH_TRI[index]
    assert np.array_equal(x, s.sample_triangle(u[:, 1:3], tri[:, 0], tri[:, 1], tri[:, 2]))
    assert np.array_equal(s.sample_mesh(u.reshape(-1, 4, 3), MESH_TRI)[0], x.reshape(-1, 4, 3))
    areas = s.triangle_area(MESH_TRI[:, 0], MESH_TRI[:, 1], MESH_TRI[:, 2])
    assert len(areas) % 2 == 1
    expected = N * areas * s.pdf_mesh(x[:1], MESH_TRI)[0]  # ∫_triangle pdf dA
    result = chi2_gof_counts(np.bincount(index, minlength=len(areas)), expected)
    assert result.passed(LEVEL), f"{result} (level {LEVEL:.2e})"
    # every point lies on the triangle it reports
    n = face_normals(MESH_TRI[index])
    assert np.max(np.abs(np.einsum("ij,ij->i", x - MESH_TRI[index, 0], n))) < 1e-12


@pytest.mark.parametrize("kind", FILM_CASES)
def test04_film_filter_sampler_matches_pdf_chi_square(kind):
    r = s.filter_radius(kind)
    x = s.sample_filter(_uniforms(kind, 2), kind)
    assert np.all(np.abs(x) <= r)
    k = 15
    counts, _, _ = np.histogram2d(x[:, 0], x[:, 1], bins=k, range=((-r, r), (-r, r)))
    g, w = np.polynomial.legendre.leggauss(8)
    edges = np.linspace(-r, r, k + 1)
    nodes = (0.5 * (edges[:-1] + edges[1:]))[:, None] + (0.5 * np.diff(edges))[:, None] * g
    px = (
        s.pdf_filter(np.stack([nodes, np.zeros_like(nodes)], -1), kind)
        / s.pdf_filter(np.zeros((1, 2)), kind)[0]
    )
    # the pdf is a product of 1D densities: per-cell mass = product of 1D masses
    m1 = (px * w).sum(axis=1) * 0.5 * np.diff(edges) * np.sqrt(s.pdf_filter(np.zeros((1, 2)), kind)[0])
    result = chi2_gof_counts(counts.ravel(), N * np.outer(m1, m1).ravel())
    assert result.passed(LEVEL), f"{kind}: {result} (level {LEVEL:.2e})"


@pytest.mark.parametrize("kind", FILM_CASES)
def test05_filter_and_its_pdf_integrate_to_one(kind):
    r = s.filter_radius(kind)
    x = np.linspace(-r, r, 1601)
    xx, yy = np.meshgrid(x, x)
    pts = np.stack([xx, yy], -1)
    dx = x[1] - x[0]
    assert np.trapezoid(np.trapezoid(s.filter_value(pts, kind), dx=dx), dx=dx) == pytest.approx(1.0, abs=2e-3)
    assert np.trapezoid(np.trapezoid(s.pdf_filter(pts, kind), dx=dx), dx=dx) == pytest.approx(1.0, abs=2e-3)


@pytest.mark.parametrize("kappa", (*KAPPAS, 1e6))
def test06_vmf_pdf_integrates_to_one_and_sampling_is_stable(kappa):
    # ∫ pdf dω = 2π ∫_0^2 pdf(s) ds, on a grid fine at the scale 1/κ
    s_grid = np.concatenate(
        [np.linspace(0.0, 40.0 / kappa, 20001)[:-1], np.linspace(min(40.0 / kappa, 2.0), 2.0, 2001)]
    )
    s_grid = np.unique(np.clip(s_grid, 0.0, 2.0))
    dens = s.pdf_vmf(_sphere_points(AXIS, s_grid, np.zeros_like(s_grid)), AXIS, kappa)
    assert 2 * np.pi * np.trapezoid(dens, s_grid) == pytest.approx(1.0, rel=1e-4)
    w = s.sample_vmf(_uniforms(f"stable{kappa}", 2), AXIS, kappa)
    assert np.all(np.isfinite(w))
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, atol=1e-14)
    rel = w - AXIS
    mean_s = 0.5 * np.mean(np.einsum("ij,ij->i", rel, rel))
    # E[1 - cos θ] = 1/κ - 2 e^{-2κ} / (1 - e^{-2κ}); the sample mean of an exponential has
    # relative standard error 1/√N: 6 of them is far beyond any fluctuation
    exact = 1.0 / kappa - 2.0 * np.exp(-2.0 * kappa) / (-np.expm1(-2.0 * kappa))
    assert mean_s == pytest.approx(exact, rel=6.0 / np.sqrt(N))


def test07_vmf_hemisphere_fraction_matches_sampling():
    # C(z): the vMF mass above the horizon, tabulated; compared with the fraction of samples
    # (binomial standard error; 5 standard errors at each of 8 points: a correct table fails with
    # probability ~5e-6; the table's own error, ~6e-6 against adaptive quadrature, is far below)
    for kappa in (3.0, 300.0):
        for z in (-0.05, 0.0, 0.03, 0.3):
            y = np.array([np.sqrt(1 - z * z), 0.0, z])
            frac = (s.sample_vmf(_uniforms(f"hemi{kappa}{z}", 2), y, kappa)[:, 2] > 0).mean()
            c = s.vmf_hemisphere_fraction(np.array(z), kappa)
            assert abs(frac - c) <= 5 * np.sqrt(c * (1 - c) / N)


def _solid_angle(tri):
    """Solid angle of a triangle seen from the origin (Van Oosterom & Strackee 1983)."""
    a, b, c = tri
    la, lb, lc = np.linalg.norm(a), np.linalg.norm(b), np.linalg.norm(c)
    num = abs(a @ np.cross(b, c))
    den = la * lb * lc + (a @ b) * lc + (a @ c) * lb + (b @ c) * la
    return 2.0 * np.arctan2(num, den)


def test08_emitter_solid_angle_density_integrates_the_solid_angle():
    # directions towards uniform points on the mesh have the solid-angle density p_A d² / |cos θ_y|;
    # E[1 / p_ω] over them is the solid angle the mesh subtends (closed form, triangles not
    # overlapping as seen from the origin). A density off by any factor or power of d fails.
    y, index = s.sample_mesh(_uniforms("emitter_directions", 3), MESH_TRI)
    d = np.linalg.norm(y, axis=1)
    cos_y = np.abs(np.einsum("ij,ij->i", face_normals(MESH_TRI[index]), y / d[:, None]))
    p = s.solid_angle_pdf(s.pdf_mesh(y, MESH_TRI), d, cos_y)
    inverse = 1.0 / p
    exact = sum(_solid_angle(t) for t in MESH_TRI)
    assert abs(inverse.mean() - exact) <= Z * inverse.std(ddof=1) / np.sqrt(N)


@pytest.mark.parametrize("kind", FILM_CASES)
def test09_filter_is_the_product_of_its_1d_factors_bit_for_bit(kind):
    # sphere3d.film evaluates k and p once per column and row and multiplies: the same numbers as the
    # 2D functions (bit-identity is the claim); log k is the sum of the axes' terms, tangents included
    r = s.filter_radius(kind)
    pts = np.random.default_rng(9).uniform(-1.2 * r, 1.2 * r, (500, 2))
    x, y = pts[:, 0], pts[:, 1]
    assert np.array_equal(s.filter_value(pts, kind), s.filter_value_1d(x, kind) * s.filter_value_1d(y, kind))
    assert np.array_equal(s.pdf_filter(pts, kind), s.pdf_filter_1d(x, kind) * s.pdf_filter_1d(y, kind))
    inside = np.all(np.abs(pts) < r, axis=1)
    d = Dual(pts[inside], np.ones_like(pts[inside]))
    both = s.log_filter_value(d, kind)
    terms = s.log_filter_value_1d(d[:, 0], kind) + s.log_filter_value_1d(d[:, 1], kind)
    assert np.array_equal(both.value, terms.value) and np.array_equal(both.tangent, terms.tangent)
