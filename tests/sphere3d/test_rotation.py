"""The differentiable rotation of Loubet et al. 2019, Sec. 4.1, property by property (hypothesis).

R(a → b) = c I + [v]× + v vᵀ / (1 + c) with v = a × b, c = a · b. Checked for random
unit vectors: it is a rotation (orthonormal, det +1) taking a to b; with b = ω_p a
Dual and a = detach(ω_p) it is the identity in value — exactly, sample for sample —
and its derivative moves ω_p0 like ω_p (∂R/∂θ ω_p0 = ∂ω_p/∂θ), with a skew-symmetric
∂R/∂θ (the derivative of R Rᵀ = I). Tolerances are floating-point ones (1e-12 on unit
vectors), no statistics involved.
"""

from __future__ import annotations

import numpy as np
from hypothesis import assume, given
from hypothesis import strategies as st

from flatland.core.dual import Dual, detach, tangent
from sphere3d.rotation import Rotation, rotate, rotation_matrix
from sphere3d.vector import normalize

finite = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
vectors = st.tuples(finite, finite, finite).map(np.array)


def _unit(v: np.ndarray) -> np.ndarray:
    assume(np.linalg.norm(v) > 1e-3)
    return v / np.linalg.norm(v)


@given(vectors, vectors)
def test01_rotation_matrix_is_orthonormal_with_det_one(a, b):
    a, b = _unit(a), _unit(b)
    assume(a @ b > -0.99)  # the construction is singular only for antiparallel a, b
    r = rotation_matrix(a, b)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert abs(np.linalg.det(r) - 1.0) < 1e-12


@given(vectors, vectors, vectors)
def test02_rotation_takes_a_to_b_and_rotate_matches_the_matrix(a, b, w):
    a, b = _unit(a), _unit(b)
    assume(a @ b > -0.99)
    np.testing.assert_allclose(rotation_matrix(a, b) @ a, b, atol=1e-12)
    np.testing.assert_allclose(rotate(a, b, w), rotation_matrix(a, b) @ w, atol=1e-12)


@given(vectors, vectors, vectors)
def test03_identity_in_value_exactly(p, p_dot, w):
    omega_p = normalize(Dual(_unit(p), p_dot))
    omega = _unit(w)
    rotated = Rotation.following(omega_p[None]).apply(omega[None])
    assert np.array_equal(detach(rotated)[0], omega)  # bit for bit: the primal is unchanged
    np.testing.assert_allclose(detach(rotation_matrix(detach(omega_p), omega_p)), np.eye(3), atol=1e-15)


@given(vectors, vectors)
def test04_derivative_moves_the_followed_direction_exactly(p, p_dot):
    # ω_p(θ) = normalize(p + θ ṗ): ∂R/∂θ ω_p0 must equal ∂ω_p/∂θ (Loubet et al. 2019, Sec. 4.1)
    omega_p = normalize(Dual(_unit(p), p_dot))
    rotated = Rotation.following(omega_p[None]).apply(detach(omega_p)[None])
    np.testing.assert_allclose(tangent(rotated)[0], tangent(omega_p), atol=1e-12)


@given(vectors, vectors, vectors)
def test05_derivative_is_skew_and_matches_finite_differences(p, p_dot, w):
    a = _unit(p)
    omega_p = normalize(Dual(a, p_dot))
    r_dot = tangent(rotation_matrix(detach(omega_p), omega_p))
    np.testing.assert_allclose(r_dot, -r_dot.T, atol=1e-12)  # d(R Rᵀ)/dθ = 0 at R = I
    omega = _unit(w)
    h = 1e-6
    plus = rotate(a, normalize(a + h * p_dot), omega)
    minus = rotate(a, normalize(a - h * p_dot), omega)
    rotated = Rotation.following(omega_p[None]).apply(omega[None])
    np.testing.assert_allclose(tangent(rotated)[0], (plus - minus) / (2 * h), atol=1e-6)


def test06_inactive_rotations_are_the_identity_also_in_derivative():
    omega_p = Dual(np.array([[0.0, 0.0, 0.0], [0.0, 0.6, 0.8]]), np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    rotation = Rotation.following(omega_p, np.array([True, False]))  # row 0: zero vector; row 1: masked
    assert not rotation.active.any()
    out = rotation.apply(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]))
    assert np.array_equal(tangent(out), np.zeros((2, 3)))
    assert np.array_equal(tangent(Rotation.identity((3,)).apply(np.eye(3))), np.zeros((3, 3)))


@given(vectors, vectors, vectors, finite)
def test07_a_spin_turns_about_the_followed_direction_and_keeps_the_value(p, p_dot, w, rate):
    """Ṙω = (a × ȧ) × ω + ψ̇ (a × ω): the followed direction still moves exactly like ω_p (a × a = 0),
    the value is still ω bit for bit, and Ṙ stays skew (ω · Ṙω = 0)."""
    omega_p = normalize(Dual(_unit(p), p_dot))
    a, omega = detach(omega_p), _unit(w)
    spin = Dual(np.zeros(1), np.array([rate]))
    turning = Rotation.following(omega_p[None], spin=spin)
    plain = Rotation.following(omega_p[None]).apply(omega[None])
    out = turning.apply(omega[None])
    assert np.array_equal(detach(out)[0], omega)
    np.testing.assert_allclose(tangent(out)[0], tangent(plain)[0] + rate * np.cross(a, omega), atol=1e-12)
    np.testing.assert_allclose(tangent(turning.apply(a[None]))[0], tangent(omega_p), atol=1e-12)
    assert abs(omega @ tangent(out)[0]) < 1e-12
    # the row-by-row path (some rows inactive) gives the same numbers as the whole-array one
    both = Rotation.following(
        np.concatenate([omega_p[None], omega_p[None]]), np.array([True, False]), spin[[0, 0]]
    )
    rows = both.apply(np.stack([omega, omega]))
    np.testing.assert_allclose(tangent(rows)[0], tangent(out)[0], atol=1e-15)
    assert np.array_equal(tangent(rows)[1], np.zeros(3)) and both.take([0]).spin.shape == (1,)


@given(vectors, vectors, vectors)
def test08_apply_gives_the_tangent_of_the_dual_rotate_bit_for_bit(p, p_dot, w):
    """Rotation.apply's closed form ċ ω + v̇ × ω against the Dual evaluation of rotate (bit-identity
    is the claim: the Dual rules add only exact zeros; a zero may differ in sign, which == ignores)."""
    omega_p = Dual(_unit(p)[None], p_dot[None])
    rotation = Rotation.following(omega_p)
    omega = _unit(w)[None]
    expected = tangent(rotate(detach(rotation.target), rotation.target, omega))
    assert np.array_equal(tangent(rotation.apply(omega)), expected)
    # the row-by-row path (another row inactive) too
    both = Rotation.following(
        Dual(np.concatenate([detach(omega_p)] * 2), np.concatenate([p_dot[None]] * 2)), [True, False]
    )
    assert np.array_equal(tangent(both.apply(np.concatenate([omega] * 2)))[0], expected[0])
