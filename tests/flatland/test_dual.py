"""Forward-mode rules of Dual, each compared with a central difference (hypothesis property tests).

Central difference along the tangent: [f(x + h t) - f(x - h t)] / 2h with h = 1e-6 has
truncation error h² |f'''| / 6 ≈ 1e-12 and round-off about eps |f| / h ≈ 1e-10 for the
well-conditioned domains drawn here, so rtol = 1e-6 with atol = 1e-7 leaves a margin of
three orders of magnitude while still catching any wrong rule (a wrong rule is off by O(1)).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from flatland.core.dual import Dual, as_dual, detach, is_dual, tangent, variable

H = 1e-6
RTOL, ATOL = 1e-6, 1e-7


def arrays(lo: float, hi: float, shape=(5,)):
    return hnp.arrays(np.float64, shape, elements=st.floats(lo, hi, allow_nan=False, allow_subnormal=False))


def central_difference(f, *args):
    """Directional derivative of f along the tangents of the Dual arguments."""
    plus = f(*[detach(a) + H * tangent(a) if is_dual(a) else a for a in args])
    minus = f(*[detach(a) - H * tangent(a) if is_dual(a) else a for a in args])
    return (np.asarray(plus) - np.asarray(minus)) / (2 * H)


def check_rule(f, *args):
    out = f(*args)
    assert isinstance(out, Dual)
    np.testing.assert_allclose(out.value, f(*[detach(a) for a in args]), rtol=1e-15, atol=0)
    np.testing.assert_allclose(out.tangent, central_difference(f, *args), rtol=RTOL, atol=ATOL)


UNARY = {
    "negative": (np.negative, -3, 3),
    "positive": (np.positive, -3, 3),
    "sqrt": (np.sqrt, 0.1, 4),
    "cbrt": (np.cbrt, 0.1, 4),
    "exp": (np.exp, -3, 3),
    "expm1": (np.expm1, -3, 3),
    "log": (np.log, 0.1, 5),
    "log1p": (np.log1p, -0.5, 5),
    "sin": (np.sin, -4, 4),
    "cos": (np.cos, -4, 4),
    "tan": (np.tan, -1.3, 1.3),
    "arcsin": (np.arcsin, -0.9, 0.9),
    "arccos": (np.arccos, -0.9, 0.9),
    "arctan": (np.arctan, -4, 4),
    "sinh": (np.sinh, -2, 2),
    "cosh": (np.cosh, -2, 2),
    "tanh": (np.tanh, -2, 2),
    "square": (np.square, -3, 3),
    "abs": (np.abs, 0.1, 3),
    "abs_negative": (np.abs, -3, -0.1),
    "reciprocal": (np.reciprocal, 0.2, 3),
    "pow_const": (lambda x: x**2.5, 0.1, 3),
    "rpow_const": (lambda x: 1.7**x, -2, 2),
    "mod_2pi": (lambda x: np.mod(x, 2 * np.pi), 0.1, 6.0),
    "norm": (lambda x: np.linalg.norm(x), 0.5, 2),
    "sum": (np.sum, -3, 3),
    "mean": (np.mean, -3, 3),
    "cumsum": (np.cumsum, -3, 3),
    "max": (np.max, -3, 3),
    "min": (np.min, -3, 3),
    "sort": (np.sort, -3, 3),
    "clip": (lambda x: np.clip(x, -1.0, 1.0), -3, 3),
    "interp": (lambda x: np.interp(x, [0.0, 1.0, 3.0], [1.0, -2.0, 5.0]), 0.01, 2.99),
    "getitem_fancy": (lambda x: x[[0, 2, 2, 4]], -3, 3),
    "getitem_mask": (lambda x: x[np.array([True, False, True, True, False])], -3, 3),
    "getitem_int_array": (lambda x: x[np.array([[0, -1], [2, 2]])], -3, 3),  # by np.take
    "reshape": (lambda x: np.reshape(x, (5, 1)) * x, -3, 3),
    "stack": (lambda x: np.stack([x, 2 * x, x * x]), -3, 3),
    "concatenate": (lambda x: np.concatenate([x, np.ones(2), x * x]), -3, 3),
    "broadcast": (lambda x: x[:, None] * x[None, :], -3, 3),
    "take": (lambda x: np.take(x, [4, 0]), -3, 3),
    "where": (lambda x: np.where(detach(x) > 0, x * x, -x), -3, 3),
}


@pytest.mark.parametrize("name", list(UNARY))
def test01_unary_rules_match_central_difference(name):
    f, lo, hi = UNARY[name]

    @given(x=arrays(lo, hi), t=arrays(-1, 1))
    def check(x, t):
        if name in ("max", "min", "sort"):  # ties are kinks: the ordering must not change within ±H t
            assume(np.min(np.diff(np.sort(x))) > 1e-4)
        if name in ("clip", "where", "interp"):  # keep away from kinks
            x = x + 1e-3 * np.arange(x.size)
            if name == "clip":
                x = np.where(np.abs(np.abs(x) - 1.0) < 1e-3, x + 0.01, x)
            if name == "where":
                x = np.where(np.abs(x) < 1e-3, 0.01, x)
            if name == "interp":
                x = np.where(np.abs(x - 1.0) < 1e-3, 1.01, x)
        check_rule(f, Dual(x, t))

    check()


BINARY = {
    "add": (np.add, (-3, 3), (-3, 3)),
    "subtract": (np.subtract, (-3, 3), (-3, 3)),
    "multiply": (np.multiply, (-3, 3), (-3, 3)),
    "divide": (np.divide, (-3, 3), (0.3, 3)),
    "power": (np.power, (0.2, 3), (-2, 2)),
    "arctan2": (np.arctan2, (0.2, 3), (-3, 3)),
    "hypot": (np.hypot, (0.2, 3), (-3, 3)),
    "minimum": (np.minimum, (-3, 3), (-3, 3)),
    "maximum": (np.maximum, (-3, 3), (-3, 3)),
    "remainder": (np.remainder, (0.5, 6), (0.7, 0.9)),
    "fmod": (np.fmod, (0.5, 6), (0.7, 0.9)),
    "dot": (np.dot, (-3, 3), (-3, 3)),
    "einsum": (lambda a, b: np.einsum("i,i->", a, b), (-3, 3), (-3, 3)),
    "outer_matmul": (lambda a, b: a[:, None] @ b[None, :], (-3, 3), (-3, 3)),
}


@pytest.mark.parametrize("name", list(BINARY))
@pytest.mark.parametrize("which", ["both", "first", "second"])
def test02_binary_rules_match_central_difference(name, which):
    f, (alo, ahi), (blo, bhi) = BINARY[name]

    @given(a=arrays(alo, ahi), b=arrays(blo, bhi), ta=arrays(-1, 1), tb=arrays(-1, 1))
    def check(a, b, ta, tb):
        if name in ("minimum", "maximum"):
            b = np.where(np.abs(a - b) < 1e-3, b + 0.01, b)
        if name in ("remainder", "fmod"):
            a = np.where(np.abs(np.remainder(a, b)) < 1e-3, a + 0.01, a)
            a = np.where(np.abs(np.remainder(a, b) - b) < 1e-3, a - 0.01, a)
        args = {
            "both": (Dual(a, ta), Dual(b, tb)),
            "first": (Dual(a, ta), b),
            "second": (a, Dual(b, tb)),
        }[which]
        check_rule(f, *args)

    check()


@given(a=arrays(-2, 2, (4, 3)), b=arrays(-2, 2, (4, 3)), ta=arrays(-1, 1, (4, 3)), tb=arrays(-1, 1, (4, 3)))
def test03_vector_products_cross_matmul_norm(a, b, ta, tb):
    check_rule(lambda x, y: np.cross(x, y), Dual(a, ta), Dual(b, tb))
    check_rule(lambda x, y: np.cross(x, y, axis=0), Dual(a[:3], ta[:3]), Dual(b[:3], tb[:3]))
    check_rule(lambda x, y: x @ y.T, Dual(a, ta), Dual(b, tb))
    check_rule(lambda x: np.linalg.norm(x + 3.0, axis=-1), Dual(a, ta))
    check_rule(lambda x: np.sum(x * x, axis=0, keepdims=True), Dual(a, ta))
    check_rule(lambda x: np.take_along_axis(x, np.argsort(detach(b), axis=1), axis=1), Dual(a, ta))


def test04_rendering_expression_chain_rule():
    """A typical rendering expression mixes many rules; chain rule against a central difference."""
    theta = Dual(np.array([0.3]), np.array([1.0]))
    x = np.linspace(-1.0, 1.0, 7)

    def f(t):
        d = np.stack([np.cos(t + x), np.sin(t + x)], axis=-1)
        p = np.array([0.2, 0.1]) + 2.0 * d
        r = np.linalg.norm(p, axis=-1)
        return np.arctan2(p[..., 1], p[..., 0]) * np.exp(-r) / np.hypot(r, t)

    check_rule(f, theta)


def test05_comparisons_act_on_values_and_return_plain_arrays():
    x = Dual([1.0, 2.0, 3.0], [5.0, -5.0, 0.0])
    for out in (x > 2.0, x <= 2.0, x == 2.0, np.isfinite(x), np.sign(x), np.floor(x)):
        assert type(out) is np.ndarray
    np.testing.assert_array_equal(x > 1.5, [False, True, True])
    assert np.argmax(x) == 2 and np.all(x > 0)


def test06_setitem_and_inplace_keep_tangents():
    x = Dual(np.zeros(4))
    x[1:3] = Dual([1.0, 2.0], [3.0, 4.0])
    x[0] = 7.0  # a constant has zero tangent
    np.testing.assert_array_equal(x.tangent, [0.0, 3.0, 4.0, 0.0])
    x += Dual(np.ones(4), np.ones(4))
    np.testing.assert_array_equal(x.value, [8.0, 2.0, 3.0, 1.0])
    np.testing.assert_array_equal(x.tangent, [1.0, 4.0, 5.0, 1.0])


def test07_unsupported_operations_raise_type_error_instead_of_dropping_the_tangent():
    x = variable(np.array([0.5, 1.5]))
    with pytest.raises(TypeError, match="detach"):
        np.asarray(x)
    with pytest.raises(TypeError, match="fft"):
        np.fft.fft(x)
    with pytest.raises(TypeError, match="no forward-mode rule"):
        np.logaddexp(x, x)
    with pytest.raises(TypeError, match="float"):
        float(x[0])
    with pytest.raises(TypeError, match="ambiguous"):
        bool(x[0])
    with pytest.raises(TypeError, match="plain array"):
        np.add(x, x, out=np.zeros(2))
    with pytest.raises(TypeError, match="index"):
        x[x]


def test08_helpers_detach_tangent_variable():
    x = variable(2.0)
    assert detach(x) == 2.0 and tangent(x) == 1.0
    assert detach(3.0) == 3.0 and np.all(tangent(np.ones(3)) == 0)
    assert is_dual(as_dual(np.ones(2))) and not is_dual(np.ones(2))
    y = x * np.ones(3)
    assert y.shape == (3,) and y.ndim == 1 and y.size == 3 and len(y) == 3
    assert [float(detach(e)) for e in y] == [2.0, 2.0, 2.0]


def test09_sqrt_and_norm_at_zero_with_zero_tangent_are_finite_and_quiet():
    """sqrt'(0) is infinite; with a zero tangent there the product is reported as 0, without warnings."""
    z = Dual(np.zeros(3), np.zeros(3))
    assert np.all(np.sqrt(z).tangent == 0.0)
    v = Dual(np.zeros((2, 2)))
    assert np.all(np.linalg.norm(v, axis=-1).tangent == 0.0)
