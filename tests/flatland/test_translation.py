"""flatland.core.translation: the reparameterization's building blocks against closed forms.

Loubet et al. 2019, Sec. 3.2 (offset of value 0), 4.2 (kernel weight of value 1), the
authors' paired control variate (theory/kernels), the box-filter refusal (theory/pixel_filters)
and the central finite difference.
"""

from __future__ import annotations

import numpy as np
import pytest

from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.stats import normal_quantile
from flatland.core.translation import (
    SMALL_WEIGHT,
    central_difference,
    check_continuous_filter,
    control_variate,
    paired_combine,
    translation_offset,
    unit_weight,
)
from flatland.core.validate import ValidationError

EPS = np.finfo(np.float64).eps
Z = normal_quantile(0.999)  # two-sided 99.9 %: a correct estimator fails one run in a thousand (fixed seed)


def test01_translation_offset_has_value_zero_and_the_derivative_of_c():
    rng = np.random.default_rng(1)
    c = Dual(rng.normal(size=6) * 10.0, rng.normal(size=6))
    delta = translation_offset(c)
    assert np.all(detach(delta) == 0.0)  # T(y, θ0) = y exactly
    assert np.array_equal(tangent(delta), tangent(c))
    ok = np.array([True, False, True, False, True, True])
    followed = translation_offset(c, ok)
    # where nothing was chosen: the identity transform, value and derivative exactly 0
    assert np.all(detach(followed) == 0.0)
    assert np.array_equal(tangent(followed), np.where(ok, tangent(c), 0.0))


def test02_unit_weight_is_exactly_one_with_the_log_kernels_derivative():
    kappa, omega = 50.0, 0.3
    y0 = np.linspace(-3.0, 3.0, 13)
    y = Dual(y0, np.ones_like(y0))
    # von Mises: log k = κ cos(y - ω) + const, d/dy = -κ sin(y - ω)
    w = unit_weight(kappa * np.cos(y - omega))
    assert np.all(detach(w) == 1.0)
    np.testing.assert_allclose(tangent(w), -kappa * np.sin(y0 - omega), rtol=4 * EPS, atol=0)
    # Gaussian far in its tail: k itself underflows (exp(-1e6) = 0, and k / k would be 0/0),
    # the weight from log k is still 1 with derivative -κ (y - ω)
    kappa = 2e5
    w = unit_weight(-0.5 * kappa * (y - omega) ** 2)
    assert np.exp(-0.5 * kappa * (y0[0] - omega) ** 2) == 0.0
    assert np.all(detach(w) == 1.0)
    np.testing.assert_allclose(tangent(w), -kappa * (y0 - omega), rtol=4 * EPS, atol=0)


def test03_control_variate_keeps_the_value_and_subtracts_scale_times_the_weights_derivative():
    e = Dual(np.array([1.5, -2.0, 0.25]), np.array([0.5, 1.0, -3.0]))
    w = Dual(np.ones(3), np.array([2.0, -1.0, 0.0]))
    out = control_variate(e, np.array([3.0, 0.5, 7.0]), w)
    assert np.array_equal(detach(out), detach(e))  # an exact zero is subtracted
    assert np.array_equal(tangent(out), np.array([0.5 - 6.0, 1.0 + 0.5, -3.0]))


def test04_paired_combination_is_the_design_formula_with_one_small_weight_guard():
    # e_j = f_j w_j with unit weights: tangent 0.5 (f0' + f1') + 0.5 (f0 - f1) w0' + 0.5 (f1 - f0) w1'
    f0, f1 = (
        Dual(np.array([2.0, -1.0]), np.array([0.5, 4.0])),
        Dual(np.array([3.0, 0.5]), np.array([-1.0, 2.0])),
    )
    w0, w1 = Dual(np.ones(2), np.array([0.7, -1.3])), Dual(np.ones(2), np.array([-0.2, 2.5]))
    out = paired_combine(f0 * w0, f1 * w1, w0, w1)
    v0, v1, d0, d1 = detach(f0), detach(f1), tangent(w0), tangent(w1)
    np.testing.assert_allclose(detach(out), 0.5 * (v0 + v1), rtol=EPS, atol=0)
    expected = 0.5 * (tangent(f0) + tangent(f1)) + 0.5 * (v0 - v1) * d0 + 0.5 * (v1 - v0) * d1
    np.testing.assert_allclose(tangent(out), expected, rtol=8 * EPS, atol=8 * EPS)
    # a weight below SMALL_WEIGHT counts as 1 (value 1, derivative 0): no division by it
    tiny = Dual(np.full(2, 0.5 * SMALL_WEIGHT), np.array([3.0, -3.0]))
    e0, e1 = Dual(np.array([1.0, 2.0]), np.array([0.1, 0.2])), f1 * w1
    out = paired_combine(e0, e1, tiny, w1)
    ref = 0.5 * e0 + 0.5 * (e1 - detach(e0) * (w1 - 1.0))
    assert np.array_equal(detach(out), detach(ref)) and np.array_equal(tangent(out), tangent(ref))


def test05_paired_combination_has_the_expectation_of_one_member():
    """Kernel N(ω, σ²), one translation Δ = θ (Δ' = 1) shared by the pair, integrand cos(y - θ).

    ∫ cos(y - θ) N(y; ω, σ²) dy = cos(ω - θ) e^{-σ²/2}: derivative at θ = 0 is
    sin(ω) e^{-σ²/2}, value cos(ω) e^{-σ²/2}. Each member's derivative comes from its
    weight alone (cos(μ + Δ - θ) does not move), w' = -(μ - ω) / σ², zero mean and
    independent of the other member: the pair keeps the expectation (paired samples, theory/kernels).
    """
    omega, sigma, pairs = 0.6, 0.5, 20000
    theta = variable(0.0)
    rng = np.random.default_rng(7)
    mu = omega + sigma * rng.normal(size=(2, pairs))
    delta = translation_offset(theta)
    e, w = [], []
    for j in range(2):  # the two members (not a loop over samples)
        y = mu[j] + delta
        w.append(unit_weight(-0.5 * (y - omega) ** 2 / sigma**2))
        e.append(np.cos(y - theta) * w[j])
    pair = paired_combine(e[0], e[1], w[0], w[1])
    exact_value, exact_derivative = (
        np.cos(omega) * np.exp(-0.5 * sigma**2),
        np.sin(omega) * np.exp(-0.5 * sigma**2),
    )
    for estimates, exact in ((detach(pair), exact_value), (tangent(pair), exact_derivative)):
        z = (estimates.mean() - exact) / (estimates.std(ddof=1) / np.sqrt(pairs))
        assert abs(z) < Z, (estimates.mean(), exact, z)


def test06_box_filter_refused_with_one_message_naming_the_field():
    with pytest.raises(ValidationError) as info:
        check_continuous_filter("box")
    assert info.value.field == "camera.filter"
    assert str(info.value).startswith(
        "camera.filter: the reparam method needs a continuous pixel filter, got 'box'"
    )
    assert "'tent' or 'gaussian'" in str(info.value)
    check_continuous_filter("tent")
    check_continuous_filter("gaussian")


def test07_central_difference_is_exact_on_a_quadratic_and_has_the_h2_bias_on_a_cubic():
    theta, h = 0.7, 1e-3
    calls = []

    def quadratic(t: float) -> np.ndarray:
        calls.append(t)
        return np.array([3.0 * t * t - 2.0 * t + 5.0, -t * t])

    # round-off only: each value has error <= a few ulps of |f| <= 7, divided by 2h
    bound = 8 * EPS * 7.0 / (2.0 * h)
    np.testing.assert_allclose(
        central_difference(quadratic, theta, h), [6.0 * theta - 2.0, -2.0 * theta], atol=bound
    )
    assert calls == [theta + h, theta - h]  # θ + h first
    # f = t³: [f(θ + h) - f(θ - h)] / 2h = 3θ² + h² exactly (the h² f''' / 6 truncation term)
    h = 1e-2
    np.testing.assert_allclose(
        central_difference(lambda t: t**3, theta, h), 3.0 * theta**2 + h**2, rtol=0, atol=8 * EPS / (2 * h)
    )
