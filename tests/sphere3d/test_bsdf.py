"""sphere3d.bsdf, the glossy BSDF (GGX microfacets, height-correlated Smith G2, constant Fresnel F):
formula, reciprocity, density, visible-normal sampler, energy and derivatives.

Closed forms first: the BSDF against the textbook formula written here in spherical angles (Walter et
al. 2007's D with tan θ, Smith's Λ), the sample weight against G2/G1, the albedo at α = 1 and normal
incidence against 1 - ln 2. Then quadrature: the pdf's integral over the sphere and ∫ f cos dω on a
grid, by Gauss rules in the half vector h (panels graded towards each integrand's own boundary,
where the reflection or the microfacet leaves the visible side, so the integrands are smooth); the
albedo against scipy's adaptive ``nquad`` in the outgoing direction's angles (independent of every
half-vector formula). Then Monte Carlo: 9 cases (α in 0.05, 0.3, 1 times cos θ_i in 1, 0.5, 0.08),
200 000 samples each, fixed seeds, each tested twice: chi-square goodness of fit of the sampler
against its pdf, with h = (w_i + w_o)/|w_i + w_o| binned in (ξ, φ_h) about the normal, ξ = tan² θ_h /
(α² + tan² θ_h) in 15 bins and φ_h in 9 (135, odd; ξ is uniform under D cos θ_h, so the bins follow
the lobe at every α, and ξ = 1, where the density jumps, is an edge), expected counts from pdf_ggx
carried to h by the reflection's Jacobian $dω_o = 4 (w_i·h) dω_h$ (8 × 8 Gauss points per bin, in
sqrt(1 - ξ) and φ_h: the density over ξ grows as (1 - ξ)^(-1/2) at the horizon); and
the mean sample weight against the albedo (z-test on its standard error). The file's 18 statistical
tests together reject a correct BSDF with probability ALPHA = 1e-3 (Šidák level per test). Last, the
albedo table printed in docs/theory/bsdf.md is checked against both packages.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate

from flatland import bsdf as bsdf2d
from flatland.core.dual import Dual, detach, tangent, variables
from flatland.core.microfacet import graded_gauss
from flatland.core.rng import stream
from flatland.core.stats import chi2_gof_counts, normal_quantile, sidak
from flatland.core.validate import ValidationError
from sphere3d import bsdf
from sphere3d.vector import cross, dot, frame, normalize

N = 200_000
ALPHA = 1e-3
NXI, NPHI = 15, 9
AXIS = normalize(np.array([0.3, -0.5, 0.8]))
"""The normal in the tests (not z: the frame is built for real)."""
T, B = frame(AXIS)
CASES = [(alpha, c) for alpha in (0.05, 0.3, 1.0) for c in (1.0, 0.5, 0.08)]
LEVEL = sidak(ALPHA, 2 * len(CASES))
Z = normal_quantile(1.0 - LEVEL)


def _world(x, y, z):
    """Local coordinates in the frame (T, B, AXIS) to world directions."""
    return np.asarray(x)[..., None] * T + np.asarray(y)[..., None] * B + np.asarray(z)[..., None] * AXIS


def _incident(c):
    """The direction at cos θ = c from the normal, in the (T, AXIS) plane (azimuth 0)."""
    return _world(np.sqrt(1.0 - c * c), 0.0, c)


def _textbook(theta_i, phi_i, theta_o, phi_o, alpha, albedo):
    """f = F D G2 / (4 cos θ_i cos θ_o) in spherical angles, D and Λ written with tan θ; and G2/G1(w_i)."""
    wi = np.stack([np.sin(theta_i) * np.cos(phi_i), np.sin(theta_i) * np.sin(phi_i), np.cos(theta_i)], -1)
    wo = np.stack([np.sin(theta_o) * np.cos(phi_o), np.sin(theta_o) * np.sin(phi_o), np.cos(theta_o)], -1)
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    theta_h = np.arccos(h[..., 2])
    d = alpha**2 / (np.pi * np.cos(theta_h) ** 4 * (alpha**2 + np.tan(theta_h) ** 2) ** 2)

    def lam(t):
        return 0.5 * (np.sqrt(1.0 + alpha**2 * np.tan(t) ** 2) - 1.0)

    g2 = 1.0 / (1.0 + lam(theta_i) + lam(theta_o))
    f = albedo * d * g2 / (4.0 * np.cos(theta_i) * np.cos(theta_o))
    return f, g2 * (1.0 + lam(theta_i)), _world(*wi.T), _world(*wo.T)


def _pairs(name, n=2000, limit=1.45):
    g = stream(5, name)
    theta_i, theta_o = g.uniform(0.0, limit, (2, n))
    phi_i, phi_o = g.uniform(0.0, 2 * np.pi, (2, n))
    return theta_i, phi_i, theta_o, phi_o, g.uniform(0.01, 1.0, n), g.uniform(0.0, 1.0, n)


def _uniforms(name, case):
    return stream(3, name, CASES.index(case)).random((N, 2))


def _h_rule(c, alpha, limit, nodes=12):
    """Half vectors h and weights of dω_h over {θ_h < limit(φ_h)}, about AXIS with w_i at azimuth 0.

    tan θ_h = α tan ψ (the nodes follow D for every α; dθ/dψ = α / (cos² ψ + α² sin² ψ), bounded),
    Gauss panels in ψ graded towards the limit and in φ towards ±π/2 (where the limits turn for grazing
    w_i), log2(1 / (c α)) + 4 levels (near the limit the integrands vary on the scale c in θ_h, which ψ
    shrinks by up to α). The integrands are even in φ: the half [0, π] counts twice.
    """
    levels = int(np.ceil(np.log2(1.0 / (c * alpha)))) + 4
    left, w_left = graded_gauss(0.0, 0.5 * np.pi, nodes, levels)
    phi, w_phi = np.concatenate([left, np.pi - left]), 2.0 * np.concatenate([w_left, w_left])
    psi, w_psi = graded_gauss(0.0, np.arctan(np.tan(limit(phi)) / alpha), nodes, levels)
    theta = np.arctan(alpha * np.tan(psi))
    weight = w_phi[:, None] * w_psi * np.sin(theta) * alpha / (np.cos(psi) ** 2 + (alpha * np.sin(psi)) ** 2)
    phi = phi[:, None]
    return _world(np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)), weight


def _reflect(wi, h):
    return 2.0 * dot(wi, h)[..., None] * h - wi


def test01_eval_is_the_textbook_microfacet_formula_and_zero_below_the_surface():
    theta_i, phi_i, theta_o, phi_o, alpha, albedo = _pairs("eval")
    f, _, wi, wo = _textbook(theta_i, phi_i, theta_o, phi_o, alpha, albedo)
    np.testing.assert_allclose(bsdf.eval_ggx(wi, wo, AXIS, alpha, albedo), f, rtol=1e-10)
    below = wo - 2.0 * dot(wo, AXIS)[:, None] * AXIS  # mirrored through the surface
    assert np.all(bsdf.eval_ggx(wi, below, AXIS, alpha, albedo) == 0.0) and np.all(f > 0.0)
    assert np.all(bsdf.eval_ggx(below, wo, AXIS, alpha, albedo) == 0.0)


def test02_reciprocity_holds_bit_for_bit():
    theta_i, phi_i, theta_o, phi_o, alpha, albedo = _pairs("reciprocity", limit=np.pi)
    _, _, wi, wo = _textbook(theta_i, phi_i, theta_o, phi_o, alpha, albedo)
    normals = normalize(AXIS + 0.3 * stream(5, "normals").standard_normal((len(wi), 3)))  # one per row
    f = bsdf.eval_ggx(wi, wo, normals, alpha, albedo)
    assert np.array_equal(f, bsdf.eval_ggx(wo, wi, normals, alpha, albedo))
    assert np.count_nonzero(f) > 400  # about a quarter of the pairs lie above the surface on both sides


@pytest.mark.parametrize("case", CASES)
def test03_pdf_integrates_to_one(case):
    """Over h with $w_i·h > 0$ (the reflection maps it one to one onto the sphere of w_o): θ_h below
    π/2, and below atan(c / (s |cos φ|)) where cos φ < 0. The Gauss rules converge geometrically on
    this smooth integrand; 1e-10 is far above their error and far below any error of the pdf's form."""
    alpha, c = case
    s = np.sqrt(1.0 - c * c)

    def visible(phi):
        with np.errstate(divide="ignore"):
            return np.where(np.cos(phi) < 0.0, np.arctan(c / (s * np.abs(np.cos(phi)))), 0.5 * np.pi)

    h, weight = _h_rule(c, alpha, visible)
    wi = _incident(c)
    density = bsdf.pdf_ggx(_reflect(wi, h), wi, AXIS, alpha) * 4.0 * np.maximum(dot(wi, h), 0.0)
    assert np.sum(density * weight) == pytest.approx(1.0, abs=1e-10)


def _chi2(wi, wo, alpha):
    """Chi-square of the half vectors of (wi, wo) against pdf_ggx carried to h, binned in (ξ, φ_h)."""
    h = normalize(wi + wo)
    cos_h = dot(h, AXIS)
    tan2 = np.maximum(1.0 - cos_h * cos_h, 0.0) / (cos_h * cos_h)
    xi = tan2 / (alpha * alpha + tan2)
    phi = np.arctan2(dot(h, B), dot(h, T)) % (2 * np.pi)
    counts, _, _ = np.histogram2d(xi, phi, bins=(NXI, NPHI), range=((0.0, 1.0), (0.0, 2 * np.pi)))
    x, w = np.polynomial.legendre.leggauss(8)
    # in each ξ bin the nodes are Gauss points in v = sqrt(1 - ξ) (dξ = 2v dv): the density over ξ grows as
    # (1 - ξ)^(-1/2) towards the horizon (w_i·h / cos θ_h ~ tan θ_h), which v makes smooth
    v_edges = np.sqrt(1.0 - np.arange(NXI + 1) / NXI)
    v_mid, v_half = 0.5 * (v_edges[:-1] + v_edges[1:]), 0.5 * (v_edges[:-1] - v_edges[1:])
    v = v_mid[:, None] + v_half[:, None] * x
    xi_nodes, xi_weights = 1.0 - v * v, 2.0 * v * v_half[:, None] * w
    phi_nodes = ((np.arange(NPHI) + 0.5)[:, None] + 0.5 * x) * (2 * np.pi / NPHI)
    g_xi, g_phi = xi_nodes[:, None, :, None], phi_nodes[None, :, None, :]
    # tan θ = α sqrt(ξ / (1 - ξ)); dω_h = dξ dφ / (2π D cos θ) with the textbook D
    tan_h = alpha * np.sqrt(g_xi / (1.0 - g_xi))
    cos_t = 1.0 / np.sqrt(1.0 + tan_h * tan_h)
    sin_t = tan_h * cos_t
    hh = _world(*np.broadcast_arrays(sin_t * np.cos(g_phi), sin_t * np.sin(g_phi), cos_t))
    d = alpha**2 / (np.pi * cos_t**4 * (alpha**2 + tan_h**2) ** 2)
    wi0 = wi[0]
    density = bsdf.pdf_ggx(_reflect(wi0, hh), wi0, AXIS, alpha) * 4.0 * np.maximum(dot(wi0, hh), 0.0)
    mass = np.einsum("ijkl,ik,l->ij", density / (2 * np.pi * d * cos_t), xi_weights, w) * (np.pi / NPHI)
    expected = len(wi) * np.append(mass.ravel(), max(1.0 - mass.sum(), 0.0))
    observed = np.append(counts.ravel(), len(wi) - counts.sum())
    return chi2_gof_counts(observed, expected)


@pytest.mark.parametrize("case", CASES)
def test04_visible_normal_sampler_matches_its_pdf_chi_square(case):
    alpha, c = case
    wi = np.broadcast_to(_incident(c), (N, 3))
    wo = bsdf.sample_ggx(_uniforms("chi2", case), wi, AXIS, alpha)
    np.testing.assert_allclose(np.linalg.norm(wo, axis=1), 1.0, atol=1e-14)
    result = _chi2(wi, wo, alpha)
    assert result.passed(LEVEL), f"{case}: {result} (level {LEVEL:.2e})"
    # the chi-square can fail: the same samples against the lobe of a 10 % smoother surface
    assert _chi2(wi, wo, 0.9 * alpha).p_value < 1e-10


def test05_sample_weight_is_f_cos_over_pdf_and_g2_over_g1():
    theta_i, phi_i, theta_o, phi_o, alpha, albedo = _pairs("weight")
    _, g2_over_g1, wi, wo = _textbook(theta_i, phi_i, theta_o, phi_o, alpha, albedo)
    w = bsdf.weight_ggx(wi, wo, AXIS, alpha, albedo)
    f, pdf = bsdf.eval_ggx(wi, wo, AXIS, alpha, albedo), bsdf.pdf_ggx(wo, wi, AXIS, alpha)
    np.testing.assert_allclose(w, f * dot(wo, AXIS) / pdf, rtol=1e-12)
    np.testing.assert_allclose(w, albedo * g2_over_g1, rtol=1e-12)
    assert np.all(w <= albedo) and np.all(w > 0.0)
    below = wo - 2.0 * dot(wo, AXIS)[:, None] * AXIS
    assert np.all(bsdf.weight_ggx(wi, below, AXIS, alpha, albedo) == 0.0)


def test06_albedo_at_alpha_one_and_normal_incidence_is_its_closed_form():
    r"""α = 1: D = 1/π and r = 1, so $A = 2 ∫_0^{π/4} \cos 2θ \tan θ dθ = 1 - \ln 2$."""
    assert float(bsdf.albedo_ggx(1.0, 1.0)) == pytest.approx(1.0 - np.log(2.0), rel=1e-14)
    assert float(bsdf.albedo_ggx(1.0, 1.0, 0.3)) == pytest.approx(0.3 * (1.0 - np.log(2.0)), rel=1e-14)


def test07_eval_integrates_to_the_albedo_which_is_at_most_one_on_a_grid():
    """∫ f(w_i, w_o) (n·w_o) dω_o with eval_ggx at the reflections of a Gauss rule in h (up to the
    horizon of w_o, where θ_h = (δ + π/2)/2, tan δ = tan θ_i cos φ): equal to albedo_ggx to 1e-10 at 5
    roughnesses × 8 incidences up to 89°, and every albedo in (0, 1]: energy is conserved for F = 1."""
    alphas, angles = (0.01, 0.05, 0.2, 0.5, 1.0), np.linspace(0.0, np.radians(89.0), 8)
    table = bsdf.albedo_ggx(np.cos(angles)[:, None], np.array(alphas))
    for i, theta in enumerate(angles):
        c, s = np.cos(theta), np.sin(theta)
        wi = _incident(c)
        for j, alpha in enumerate(alphas):
            h, weight = _h_rule(
                c, alpha, lambda phi, c=c, s=s: 0.5 * (np.arctan2(s * np.cos(phi), c) + 0.5 * np.pi)
            )
            wo = _reflect(wi, h)
            integrand = bsdf.eval_ggx(wi, wo, AXIS, alpha, 1.0) * dot(wo, AXIS) * 4.0 * dot(wi, h)
            assert np.sum(integrand * weight) == pytest.approx(table[i, j], abs=1e-10), (theta, alpha)
    assert np.all(table > 0.0) and np.all(table <= 1.0)


@pytest.mark.parametrize("case", [(0.3, 1.0), (0.3, 0.5), (1.0, 0.5), (0.3, 0.08)])
def test08_albedo_is_scipys_quadrature_of_the_textbook_brdf(case):
    """scipy's nquad over θ_o in [0, π/2] (a break at the mirror's θ_i) and φ_o in [0, π] (doubled), of the
    textbook f cos θ_o sin θ_o: independent of every half-vector formula. The albedo must lie within
    nquad's own error estimate (asserted below 1e-7; it is conservative, the two agree to about 1e-15)."""
    alpha, c = case
    theta_i = np.arccos(c)

    def integrand(phi_o, theta_o):
        f = _textbook(theta_i, 0.0, theta_o, phi_o, alpha, 1.0)[0]
        return float(f) * np.cos(theta_o) * np.sin(theta_o) * 2.0

    value, err = integrate.nquad(
        integrand,
        [(0.0, np.pi), (0.0, 0.5 * np.pi)],
        opts=[{"epsabs": 1e-11, "limit": 200}, {"epsabs": 1e-11, "limit": 200, "points": [theta_i]}],
    )
    assert err < 1e-7
    assert abs(float(bsdf.albedo_ggx(c, alpha)) - value) <= err + 1e-15


@pytest.mark.parametrize("case", CASES)
def test09_sample_weights_average_to_the_albedo(case):
    alpha, c = case
    wi = np.broadcast_to(_incident(c), (N, 3))
    wo = bsdf.sample_ggx(_uniforms("albedo", case), wi, AXIS, alpha)
    w = bsdf.weight_ggx(wi, wo, AXIS, alpha, 1.0)
    exact = float(bsdf.albedo_ggx(c, alpha))
    assert abs(w.mean() - exact) <= Z * w.std(ddof=1) / np.sqrt(N), (case, w.mean(), exact)


def _rotate(v, axis, angle):
    """Rodrigues: v turned by ``angle`` about the unit ``axis`` (rows)."""
    k, c, s = np.asarray(axis), np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + cross(k, v) * s + k * dot(k, v)[:, None] * (1.0 - c)


def test10_tangents_of_eval_pdf_and_weight_are_central_differences():
    """d/dα, d/d(albedo) and d/dt of w_o turned by t about a fixed axis, against central differences with
    the step h = 1e-5 s, s the scale on which each function varies (α for α and for directions, the
    lobe's width; 1 for the albedo): truncation (h/s)² = 1e-10 and rounding ε s/h ≈ 1e-11 relative to
    f / s; the tolerance is 1e-7 of that. d/d(albedo) is f / albedo. A k-Dual's slots are the single
    tangents. The normal may carry a tangent too (moving geometry): checked the same way."""
    theta_i, phi_i, theta_o, phi_o, alpha, albedo = _pairs("tangents", n=200, limit=1.4)
    alpha, albedo = 0.99 * alpha, 0.01 + 0.98 * albedo  # room for the steps inside (0, 1] and [0, 1]
    _, _, wi, wo = _textbook(theta_i, phi_i, theta_o, phi_o, alpha, albedo)
    spin = normalize(stream(5, "spin").standard_normal((len(wi), 3)))
    normal = np.broadcast_to(AXIS, wi.shape)

    def funcs(al, rho, w, n):
        return (
            bsdf.eval_ggx(wi, w, n, al, rho),
            bsdf.pdf_ggx(w, wi, n, al),
            bsdf.weight_ggx(wi, w, n, al, rho),
        )

    for which, scale in enumerate((alpha, np.ones_like(alpha), alpha, alpha)):
        h = 1e-5 * scale
        base = [alpha, albedo, wo, normal]

        def moved(t, which=which, base=base):
            out = list(base)
            if which < 2:
                out[which] = base[which] + t
            else:
                out[which] = _rotate(base[which], spin, t)
            return out

        duals = list(base)
        if which < 2:
            duals[which] = Dual(base[which], np.ones_like(base[which]))
        else:
            duals[which] = Dual(base[which], cross(spin, base[which]))
        for got, up, down in zip(funcs(*duals), funcs(*moved(h)), funcs(*moved(-h)), strict=True):
            fd = (up - down) / (2.0 * h)
            bound = 1e-7 * (np.abs(fd) + np.abs(detach(got)) / scale)
            assert np.all(np.abs(tangent(got) - fd) <= bound), which  # pdf_ggx is plain in the albedo
    f = bsdf.eval_ggx(wi, wo, AXIS, alpha, Dual(albedo, np.ones_like(albedo)))
    np.testing.assert_allclose(f.tangent, f.value / albedo, rtol=1e-14)
    t_alpha, t_albedo = variables(2)
    both = bsdf.eval_ggx(wi, wo, AXIS, alpha + t_alpha, albedo + t_albedo)
    one = bsdf.eval_ggx(wi, wo, AXIS, Dual(alpha, np.ones_like(alpha)), albedo)
    assert np.array_equal(both.tangent[0], one.tangent) and np.array_equal(both.value, one.value)


def test11_incidence_below_the_surface_samples_finite_directions_of_zero_weight():
    wi = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.6, 0.0, -0.8]])
    n = np.array([0.0, 0.0, 1.0])
    wo = bsdf.sample_ggx(stream(5, "below").random((3, 2)), wi, n, 0.4)
    assert np.all(np.isfinite(wo))
    assert np.all(bsdf.pdf_ggx(wo, wi, n, 0.4) == 0.0) and np.all(bsdf.weight_ggx(wi, wo, n, 0.4, 1.0) == 0.0)


@pytest.mark.parametrize(
    ("call", "field", "message"),
    [
        (
            lambda: bsdf.eval_ggx(AXIS, AXIS, AXIS, 0.0, 1.0),
            "alpha",
            r"got 0\.0.*delta.*no integral to reparameterize",
        ),
        (
            lambda: bsdf.sample_ggx(np.array([[0.5, 0.5]]), AXIS, AXIS, -0.2),
            "alpha",
            r"> 0, got -0\.2.*delta",
        ),
        (lambda: bsdf.pdf_ggx(AXIS, AXIS, AXIS, 1.5), "alpha", r"in \(0, 1\], got 1\.5"),
        (lambda: bsdf.pdf_ggx(AXIS, AXIS, AXIS, np.array([0.3, np.nan])), "alpha", r"got nan"),
        (lambda: bsdf.eval_ggx(AXIS, AXIS, AXIS, Dual(0.0, 1.0), 1.0), "alpha", r"got 0\.0.*delta"),
        (lambda: bsdf.weight_ggx(AXIS, AXIS, AXIS, 0.3, 1.2), "albedo", r"in \[0, 1\], got 1\.2"),
        (lambda: bsdf.albedo_ggx(0.5, 0.3, -0.1), "albedo", r"got -0\.1"),
        (lambda: bsdf.albedo_ggx(1.5, 0.3), "cos_theta", r"in \(0, 1\], got 1\.5"),
        (lambda: bsdf.albedo_ggx(0.5, 0.3, nodes=1), "nodes", r">= 2, got 1"),
    ],
)
def test12_bad_input_is_one_validation_error_naming_the_field_and_the_value(call, field, message):
    with pytest.raises(ValidationError, match=rf"^{field}: .*{message}") as info:
        call()
    assert info.value.field == field


def test13_the_theory_pages_albedo_table_is_what_both_packages_compute():
    """docs/theory/bsdf.md prints albedos of both packages to 4 decimals: each is the rounded albedo_ggx."""
    page = (Path(__file__).resolve().parents[2] / "docs" / "theory" / "bsdf.md").read_text(encoding="utf-8")
    rows = [line for line in page.splitlines() if re.match(r"^\| \d+° \|", line)]
    assert len(rows) == 4
    alphas = np.array([0.05, 0.2, 0.5, 1.0])
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        c = np.cos(np.radians(float(cells[0].rstrip("°"))))
        printed = np.array([float(x) for x in cells[1:]])
        computed = np.concatenate([bsdf.albedo_ggx(c, alphas), bsdf2d.albedo_ggx(c, alphas)])
        assert np.array_equal(printed, np.round(computed, 4)), row
