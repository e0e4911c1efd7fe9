"""flatland.bsdf, the glossy BSDF (GGX microfacets on a profile): formula, reciprocity, density, sampler,
energy and derivatives.

Closed forms first: the BSDF against the textbook microfacet formula written here with tangents
(Walter et al. 2007 in the plane, Smith's Λ with tan θ), the weight against G2/G1, the albedo at
α = 1 and normal incidence against √2 - ln(1 + √2). Then quadrature: scipy's adaptive ``quad`` for
the pdf's integral and the albedo (independent of the module's half-vector rule). Then Monte
Carlo: 12 cases (α in 0.02, 0.1, 0.4, 1 times incidence 0, 0.8, -1.45 rad), 200 000 samples each,
fixed seeds, each tested twice: chi-square goodness of fit of the sampler against its pdf (51
bins, odd, over the lobe; the rest pooled into one cell) and the mean sample weight against the
albedo (a z-test on its standard error). The file's 24 statistical tests together reject a correct
BSDF with probability ALPHA = 1e-3 (Šidák level per test).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate

from flatland import bsdf
from flatland.core.dual import Dual, variables
from flatland.core.microfacet import graded_gauss
from flatland.core.rng import stream
from flatland.core.stats import chi2_gof, normal_quantile, sidak
from flatland.core.validate import ValidationError

N = 200_000
ALPHA = 1e-3
BINS = 51
NORMAL = 0.4
"""The normal's angle in the tests (not 0, so the relative angles are wrapped for real)."""
CASES = [(alpha, a) for alpha in (0.02, 0.1, 0.4, 1.0) for a in (0.0, 0.8, -1.45)]
LEVEL = sidak(ALPHA, 2 * len(CASES))
Z = normal_quantile(1.0 - LEVEL)


def _textbook(a, b, alpha, albedo):
    r"""$F D(θ_h) G_2 \cos((a - b)/2) / (2 \cos a \cos b)$, written with tangents as in the literature."""
    th = 0.5 * (a + b)
    d = alpha**2 / (2.0 * np.cos(th) ** 3 * (alpha**2 + np.tan(th) ** 2) ** 1.5)  # P2(tan θ) / cos³ θ

    def lam(x):
        return 0.5 * (np.sqrt(1.0 + alpha**2 * np.tan(x) ** 2) - 1.0)

    g2 = 1.0 / (1.0 + lam(a) + lam(b))
    return albedo * d * g2 * np.cos(0.5 * (a - b)) / (2.0 * np.cos(a) * np.cos(b)), g2 * (1.0 + lam(a))


def _pairs(name, n=2000, limit=1.5):
    g = stream(5, name)
    a, b = g.uniform(-limit, limit, (2, n))
    return a, b, g.uniform(0.01, 1.0, n), g.uniform(0.0, 1.0, n)


def _uniforms(name, case):
    return stream(3, name, CASES.index(case)).random(N)


def test01_eval_is_the_textbook_microfacet_formula_and_zero_below_the_surface():
    a, b, alpha, albedo = _pairs("eval")
    f = bsdf.eval_ggx(NORMAL + a, NORMAL + b + 2 * np.pi, NORMAL, alpha, albedo)  # a turn apart: the same
    np.testing.assert_allclose(f, _textbook(a, b, alpha, albedo)[0], rtol=1e-12)
    below = bsdf.eval_ggx(NORMAL + a, NORMAL + np.pi - b, NORMAL, alpha, albedo)  # b mirrored below
    assert np.all(below == 0.0) and np.all(f > 0.0)


def test02_reciprocity_holds_bit_for_bit():
    a, b, alpha, albedo = _pairs("reciprocity", limit=np.pi)
    f = bsdf.eval_ggx(NORMAL + a, NORMAL + b, NORMAL, alpha, albedo)
    assert np.array_equal(f, bsdf.eval_ggx(NORMAL + b, NORMAL + a, NORMAL, alpha, albedo))
    assert np.count_nonzero(f) > 400  # a quarter of the pairs lie above the surface on both sides


@pytest.mark.parametrize("case", CASES)
def test03_pdf_integrates_to_one(case):
    """scipy's quad over the support, split at the mirror direction; the density jumps to 0 at one end
    (normals at the horizon), which is an end of the interval, so the integrand is continuous inside."""
    alpha, a = case
    lo, hi = (a - np.pi, np.pi - a) if a >= 0 else (-np.pi - a, np.pi + a)
    total, err = integrate.quad(
        lambda b: float(bsdf.pdf_ggx(NORMAL + b, NORMAL + a, NORMAL, alpha)),
        lo,
        hi,
        points=[-a],
        limit=400,
        epsabs=1e-13,
        epsrel=1e-13,
    )
    assert err < 1e-10
    assert total == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("case", CASES)
def test04_sampler_matches_its_pdf_chi_square(case):
    """51 bins over the lobe, mirror ± min(π, 25α): the far tails pooled, and where the range reaches π
    from the mirror its end is the support's end, where the density jumps."""
    alpha, a = case
    phi = bsdf.sample_ggx(_uniforms("chi2", case), NORMAL + a, NORMAL, alpha)
    width = min(np.pi, 25.0 * alpha)
    mirror = NORMAL - a
    result = chi2_gof(
        phi, lambda x: bsdf.pdf_ggx(x, NORMAL + a, NORMAL, alpha), BINS, (mirror - width, mirror + width)
    )
    assert result.passed(LEVEL), f"{case}: {result} (level {LEVEL:.2e})"
    # the chi-square can fail: the same samples against the lobe of a 10 % smoother surface
    wrong = chi2_gof(
        phi,
        lambda x: bsdf.pdf_ggx(x, NORMAL + a, NORMAL, 0.9 * alpha),
        BINS,
        (mirror - width, mirror + width),
    )
    assert wrong.p_value < 1e-10


def test05_sample_weight_is_f_cos_over_pdf_and_g2_over_g1():
    a, b, alpha, albedo = _pairs("weight")
    phi_i, phi_o = NORMAL + a, NORMAL + b
    w = bsdf.weight_ggx(phi_i, phi_o, NORMAL, alpha, albedo)
    f, pdf = bsdf.eval_ggx(phi_i, phi_o, NORMAL, alpha, albedo), bsdf.pdf_ggx(phi_o, phi_i, NORMAL, alpha)
    np.testing.assert_allclose(w, f * np.cos(b) / pdf, rtol=1e-12)
    np.testing.assert_allclose(w, albedo * _textbook(a, b, alpha, albedo)[1], rtol=1e-12)
    assert np.all(w <= albedo) and np.all(w > 0.0)
    assert np.all(bsdf.weight_ggx(phi_i, NORMAL + np.pi - b, NORMAL, alpha, albedo) == 0.0)


def test06_albedo_at_alpha_one_and_normal_incidence_is_its_closed_form():
    r"""α = 1: D = 1/2 and r = 1, so the albedo is a closed form,
    $A = ∫_{-π/4}^{π/4} \cos 2θ / (2 \cos θ) dθ = \sqrt 2 - \ln(1 + \sqrt 2)$."""
    assert float(bsdf.albedo_ggx(1.0, 1.0)) == pytest.approx(np.sqrt(2.0) - np.log1p(np.sqrt(2.0)), rel=1e-14)
    assert float(bsdf.albedo_ggx(1.0, 1.0, 0.3)) == pytest.approx(
        0.3 * float(bsdf.albedo_ggx(1.0, 1.0)), 1e-15
    )


def test07_albedo_is_scipys_quadrature_of_eval_and_at_most_one_on_a_grid():
    """∫ f cos b db by scipy's quad, split at the mirror direction, at 5 roughnesses × 8 incidences up to
    89°: the module's half-vector rule agrees to 1e-9 (quad's own error estimate is below 1e-11), and
    every albedo lies in (0, 1]: energy is conserved for F = 1."""
    alphas, angles = (0.01, 0.05, 0.2, 0.5, 1.0), np.linspace(0.0, np.radians(89.0), 8)
    table = bsdf.albedo_ggx(np.cos(angles)[:, None], np.array(alphas))
    for i, a in enumerate(angles):
        for j, alpha in enumerate(alphas):
            reference, err = integrate.quad(
                lambda b, a=a, alpha=alpha: float(bsdf.eval_ggx(a, b, 0.0, alpha, 1.0)) * np.cos(b),
                -0.5 * np.pi,
                0.5 * np.pi,
                points=[-a],
                limit=400,
                epsabs=1e-13,
                epsrel=1e-13,
            )
            assert err < 1e-11
            assert table[i, j] == pytest.approx(reference, abs=1e-9), (a, alpha)
    assert np.all(table > 0.0) and np.all(table <= 1.0)
    assert np.array_equal(bsdf.albedo_ggx(np.cos(-angles)[:, None], np.array(alphas)), table)  # |a| only


@pytest.mark.parametrize("case", CASES)
def test08_sample_weights_average_to_the_albedo(case):
    alpha, a = case
    phi = bsdf.sample_ggx(_uniforms("albedo", case), NORMAL + a, NORMAL, alpha)
    w = bsdf.weight_ggx(NORMAL + a, phi, NORMAL, alpha, 1.0)
    exact = float(bsdf.albedo_ggx(np.cos(a), alpha))
    assert abs(w.mean() - exact) <= Z * w.std(ddof=1) / np.sqrt(N), (case, w.mean(), exact)


def test09_tangents_of_eval_pdf_and_weight_are_central_differences():
    """d/dα, d/d(albedo) and d/dφ_o against central differences with the step h = 1e-5 s, s the scale on
    which each function varies in that variable (α for α and for φ_o, the lobe's width; 1 for the
    albedo): truncation (h/s)² = 1e-10 and rounding ε s/h ≈ 1e-11, relative to f / s; the tolerance is
    1e-7 of that. d/d(albedo) is f / albedo (f is linear in F). A k-Dual's slots are the single tangents."""
    a, b, alpha, albedo = _pairs("tangents", n=200, limit=1.4)
    alpha, albedo = 0.99 * alpha, 0.01 + 0.98 * albedo  # room for the steps inside (0, 1] and [0, 1]
    phi_i, phi_o = NORMAL + a, NORMAL + b

    def funcs(al, rho, po):
        return (
            bsdf.eval_ggx(phi_i, po, NORMAL, al, rho),
            bsdf.pdf_ggx(po, phi_i, NORMAL, al),
            bsdf.weight_ggx(phi_i, po, NORMAL, al, rho),
        )

    for which, scale in enumerate((alpha, np.ones_like(alpha), alpha)):
        h = 1e-5 * scale
        args = [alpha, albedo, phi_o]
        duals = [Dual(x, float(k == which) * np.ones_like(x)) for k, x in enumerate(args)]
        plus = [x + h * (k == which) for k, x in enumerate(args)]
        minus = [x - h * (k == which) for k, x in enumerate(args)]
        for got, up, down in zip(funcs(*duals), funcs(*plus), funcs(*minus), strict=True):
            fd = (up - down) / (2.0 * h)
            assert np.all(np.abs(got.tangent - fd) <= 1e-7 * (np.abs(fd) + np.abs(got.value) / scale)), which
    f = bsdf.eval_ggx(phi_i, phi_o, NORMAL, alpha, Dual(albedo, np.ones_like(albedo)))
    np.testing.assert_allclose(f.tangent, f.value / albedo, rtol=1e-14)
    t_alpha, t_albedo = variables(2)
    both = bsdf.eval_ggx(phi_i, phi_o, NORMAL, alpha + t_alpha, albedo + t_albedo)
    one = bsdf.eval_ggx(phi_i, phi_o, NORMAL, Dual(alpha, np.ones_like(alpha)), albedo)
    assert np.array_equal(both.tangent[0], one.tangent) and np.array_equal(both.value, one.value)


@pytest.mark.parametrize(
    ("call", "field", "message"),
    [
        (
            lambda: bsdf.eval_ggx(0.1, 0.2, 0.0, 0.0, 1.0),
            "alpha",
            r"got 0\.0.*delta.*no integral to reparameterize",
        ),
        (lambda: bsdf.sample_ggx(np.array([0.5]), 0.1, 0.0, -0.2), "alpha", r"> 0, got -0\.2.*delta"),
        (lambda: bsdf.pdf_ggx(0.1, 0.2, 0.0, 1.5), "alpha", r"in \(0, 1\], got 1\.5"),
        (lambda: bsdf.pdf_ggx(0.1, 0.2, 0.0, np.array([0.3, np.nan])), "alpha", r"got nan"),
        (lambda: bsdf.eval_ggx(0.1, 0.2, 0.0, Dual(0.0, 1.0), 1.0), "alpha", r"got 0\.0.*delta"),
        (lambda: bsdf.weight_ggx(0.1, 0.2, 0.0, 0.3, 1.2), "albedo", r"in \[0, 1\], got 1\.2"),
        (lambda: bsdf.albedo_ggx(0.5, 0.3, -0.1), "albedo", r"got -0\.1"),
        (lambda: bsdf.albedo_ggx(0.0, 0.3), "cos_theta", r"in \(0, 1\], got 0\.0"),
        (lambda: bsdf.albedo_ggx(0.5, 0.3, nodes=1), "nodes", r">= 2, got 1"),
    ],
)
def test10_bad_input_is_one_validation_error_naming_the_field_and_the_value(call, field, message):
    with pytest.raises(ValidationError, match=rf"^{field}: .*{message}") as info:
        call()
    assert info.value.field == field


def test11_graded_gauss_integrates_a_near_singular_function():
    r"""$∫_0^1 dx / (x + d) = \ln((1 + d) / d)$ for d down to 1e-9: panels graded towards 0 (written from 1 to
    0: positive weights either way) reach the singularity's scale, one Gauss rule on [0, 1] does not (its
    error stays above 1 %)."""
    for d in (1e-3, 1e-6, 1e-9):
        exact = np.log((1.0 + d) / d)
        x, w = graded_gauss(1.0, 0.0, 12, int(np.ceil(np.log2(1.0 / d))) + 4)
        assert np.all(w > 0.0) and np.sum(w / (x + d)) == pytest.approx(exact, rel=1e-12)
        x, w = graded_gauss(0.0, 1.0, 12, 0)
        assert abs(np.sum(w / (x + d)) / exact - 1.0) > 1e-2
