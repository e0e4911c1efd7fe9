"""The textbook integrals' closed forms, checked independently by quadrature and differences.

Every closed form is compared with adaptive quadrature of the integrand itself (break
points at the discontinuities), every derivative with a central difference of that
quadrature, and every listed jump with the integrand evaluated just beside the
discontinuity. Finally the Leibniz decomposition: interior term (quadrature of the AD
derivative of f) plus the listed discontinuity term equals the closed-form derivative.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import integrate

from flatland.core.dual import detach, tangent, variable
from flatland.integrals import INTEGRALS, Circle

NAMES = list(INTEGRALS)


def thetas(name):
    lo, hi = INTEGRALS[name].theta_range
    return [INTEGRALS[name].default_theta, lo + 0.3 * (hi - lo), lo + 0.8 * (hi - lo)]


def quad_of(g, integrand, theta):
    """∫ g(x) dx over the integrand's domain, split at its discontinuities."""
    cuts = sorted(float(detach(d.location)) for d in integrand.discontinuities(variable(theta)))
    if integrand.domain is Circle:
        lo = min(cuts, default=0.0) - np.pi if cuts else -np.pi
        hi = lo + 2 * np.pi
        pieces = [lo, *[c for c in cuts if lo < c < hi], hi]
    else:
        pieces = [-np.inf, *cuts, np.inf]
    total = 0.0
    for a, b in itertools.pairwise(pieces):
        val, _ = integrate.quad(
            lambda x: float(g(np.array([x]))[0]), a, b, epsabs=1e-12, epsrel=1e-11, limit=200
        )
        total += val
    return total


@pytest.mark.parametrize("name", NAMES)
def test01_value_matches_quadrature(name):
    ig = INTEGRALS[name]
    for th in thetas(name):
        q = quad_of(lambda x, th=th: detach(ig.f(x, th)), ig, th)
        assert ig.value(th) == pytest.approx(q, abs=1e-8)


@pytest.mark.parametrize("name", NAMES)
def test02_derivative_matches_central_difference_of_quadrature(name):
    ig, h = INTEGRALS[name], 1e-4
    for th in thetas(name):
        plus = quad_of(lambda x, t=th + h: detach(ig.f(x, t)), ig, th + h)
        minus = quad_of(lambda x, t=th - h: detach(ig.f(x, t)), ig, th - h)
        # truncation error h² I''' / 6 ~ 1e-9; quadrature error 1e-11 / h ~ 1e-7
        assert ig.derivative(th) == pytest.approx((plus - minus) / (2 * h), abs=2e-6)


@pytest.mark.parametrize("name", NAMES)
def test03_listed_jumps_and_velocities_are_right(name):
    ig, eps, h = INTEGRALS[name], 1e-9, 1e-6
    for th in thetas(name):
        for d, d_plus, d_minus in zip(
            ig.discontinuities(variable(th)),
            ig.discontinuities(variable(th + h)),
            ig.discontinuities(variable(th - h)),
            strict=True,
        ):
            c = float(detach(d.location))
            left, right = detach(ig.f(np.array([c - eps]), th)), detach(ig.f(np.array([c + eps]), th))
            assert d.jump == pytest.approx(float(left[0] - right[0]), abs=1e-7)
            velocity = (float(detach(d_plus.location)) - float(detach(d_minus.location))) / (2 * h)
            assert float(tangent(d.location)) == pytest.approx(velocity, rel=1e-7)


@pytest.mark.parametrize("name", NAMES)
def test04_leibniz_interior_plus_discontinuity_term_is_the_derivative(name):
    ig = INTEGRALS[name]
    for th in thetas(name):
        interior = quad_of(lambda x, th=th: tangent(ig.f(x, variable(th))) * np.ones_like(x), ig, th)
        assert interior + ig.discontinuity_term(th) == pytest.approx(ig.derivative(th), abs=1e-8)


def test05_seed_example_numbers():
    """theory/leibniz: interior 0, moving limit 1·4, moving step (0 - 1)·2, dI/dθ = 2, I = 2θ."""
    ig = INTEGRALS["leibniz_seed"]
    terms = sorted(d.jump * float(tangent(d.location)) for d in ig.discontinuities(variable(1.3)))
    assert terms == [-2.0, 4.0]
    assert ig.value(1.3) == pytest.approx(2.6) and ig.derivative(1.3) == 2.0


def test06_paper_example_naive_derivative_is_zero_per_sample():
    """Loubet et al. 2019, Sec. 3.2: every sample of 1_{x>θ} K(x) has zero θ-derivative."""
    ig = INTEGRALS["step"]
    x = np.linspace(-3, 3, 101)
    assert np.all(tangent(ig.f(x, variable(0.2))) == 0.0)
