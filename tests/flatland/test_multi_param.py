"""Several parameters per pass: Duals with k tangents, and flatland's gradients of k parameters at once.

A k-Dual's slot i must be, bit for bit, what the same computation gives a classic Dual seeded with
slot i's tangent alone: test01-test02 check it for every rule of the tables (and indexing), on
drawn values and tangents (hypothesis), with ``np.testing.assert_array_equal``, no tolerance. The
renderer's results then follow: a list of parameters gives each one the derivative its single call
gives (test05), exactly when no parameter of the list changes the geometry's values at θ0
(translations, vertices, emission, albedo, camera translation); a rotation or a scale in the list
moves the shared geometry by rounding (``c + (p - c)`` is not always p, and ``cos``/``sin`` of a
camera's angle do not give its direction back exactly), and the other parameters then agree with
their single calls to rounding (test06: measured at most 1.3e-14 of the image's largest derivative,
bounded here by 1e-12, 4 500 units in the last place). A single string never builds a k-Dual: the
classic path runs the expressions it ran before k existed (test04).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from flatland.core import dual
from flatland.core.dual import Dual, as_dual, k_of, variable, variables
from flatland.core.image import GradientImage, GradientImages
from flatland.core.stats import normal_quantile, sidak
from flatland.core.validate import ValidationError
from flatland.render import irradiance, render_gradient
from flatland.scene import load_scene

X = (4, 3)
"""Shape of the main operands x, y and of the plain array c; z has shape (3,), s is a scalar."""

IDX = np.array([[2, 0, 1], [1, 1, 0], [0, 2, 2], [0, 0, 1]])
"""Indices for take_along_axis along axis 1 (values 0..2)."""

MASK = np.array([[True, False, True], [False, False, True], [True, True, False], [False, True, True]])

# Every rule, by name: the functions it covers and calls of them on (x, y, z, s, c).
UFUNC_CASES = {
    "unary": [lambda x, y, z, s, c, u=u: u(x) for u in dual._UNARY]
    + [lambda x, y, z, s, c, u=u: u(s) for u in dual._UNARY],
    "value_only": [lambda x, y, z, s, c, u=u: u(x) if u.nin == 1 else u(x, y) for u in dual._VALUE_ONLY],
}
BINARY_CALLS = [
    lambda f, x, y, z, s, c: f(x, y),
    lambda f, x, y, z, s, c: f(x, z),  # a lower-dimensional Dual: its tangent lines up after k
    lambda f, x, y, z, s, c: f(z, x),
    lambda f, x, y, z, s, c: f(s, x),
    lambda f, x, y, z, s, c: f(x, c),
    lambda f, x, y, z, s, c: f(c, z),
    lambda f, x, y, z, s, c: f(x, 1.7),
    lambda f, x, y, z, s, c: f(0.6, x),
]
MATMUL_CALLS = [
    lambda f, x, y, z, s, c: f(x, y.T),
    lambda f, x, y, z, s, c: f(x, z),
    lambda f, x, y, z, s, c: f(y[:, 0], x),
    lambda f, x, y, z, s, c: f(z, z),
    lambda f, x, y, z, s, c: f(c, z),
]
FUNCTION_CASES = {
    np.sum: [lambda x, *_: np.sum(x), lambda x, *_: np.sum(x, axis=0), lambda x, *_: x.sum(1, keepdims=True)],
    np.mean: [lambda x, *_: np.mean(x), lambda x, *_: np.mean(x, axis=-1), lambda x, *_: x.mean(0)],
    np.cumsum: [
        lambda x, *_: np.cumsum(x),
        lambda x, *_: np.cumsum(x, axis=0),
        lambda x, *_: np.cumsum(x, 1),
    ],
    np.diff: [
        lambda x, *_: np.diff(x),
        lambda x, *_: np.diff(x, axis=0),
        lambda x, *_: np.diff(x, 2, axis=1),
    ],
    np.reshape: [
        lambda x, *_: np.reshape(x, (3, 4)),
        lambda x, *_: x.reshape(-1),
        lambda x, *_: x.reshape(2, 6),
    ],
    np.transpose: [lambda x, *_: np.transpose(x), lambda x, *_: x.T, lambda x, *_: x.transpose(1, 0)],
    np.swapaxes: [lambda x, *_: np.swapaxes(x, 0, 1), lambda x, *_: np.swapaxes(x[None], -1, 0)],
    np.moveaxis: [lambda x, *_: np.moveaxis(x[None], 0, -1), lambda x, *_: np.moveaxis(x, [0, 1], [1, 0])],
    np.expand_dims: [lambda x, *_: np.expand_dims(x, 0), lambda x, *_: np.expand_dims(x, (0, -1))],
    np.squeeze: [
        lambda x, *_: np.squeeze(x[:, None, :]),
        lambda x, *_: x[:1].squeeze(),  # the value's axis of length 1, never k (k may be 1)
        lambda x, *_: np.squeeze(x[None], axis=0),
    ],
    np.ravel: [lambda x, *_: np.ravel(x), lambda x, *_: x.ravel()],
    np.flip: [lambda x, *_: np.flip(x), lambda x, *_: np.flip(x, 0), lambda x, *_: np.flip(x, axis=-1)],
    np.roll: [lambda x, *_: np.roll(x, 1), lambda x, *_: np.roll(x, 2, axis=0)],
    np.repeat: [
        lambda x, *_: np.repeat(x, 2),
        lambda x, *_: np.repeat(x, 2, axis=0),
        lambda x, *_: np.repeat(x, [1, 2, 3], axis=1),
    ],
    np.tile: [lambda x, *_: np.tile(x, 2), lambda x, y, z, *_: np.tile(z, (2, 1, 1))],
    np.broadcast_to: [
        lambda x, *_: np.broadcast_to(x, (2, 4, 3)),
        lambda x, y, z, *_: np.broadcast_to(z, (4, 3)),
        lambda x, y, z, s, c: np.broadcast_to(s, 5),
    ],
    np.atleast_1d: [lambda x, y, z, s, c: np.atleast_1d(s), lambda x, *_: np.atleast_1d(x)],
    np.take: [
        lambda x, *_: np.take(x, [0, 2]),
        lambda x, *_: np.take(x, [3, 0, 0], axis=0),
        lambda x, *_: np.take(x, np.array([2, 1]), axis=1),
    ],
    np.diagonal: [lambda x, *_: np.diagonal(x), lambda x, *_: np.diagonal(x, 1)],
    np.trace: [lambda x, *_: np.trace(x)],
    np.copy: [lambda x, *_: np.copy(x), lambda x, *_: x.copy()],
    np.real: [lambda x, *_: np.real(x)],
    np.rot90: [lambda x, *_: np.rot90(x), lambda x, *_: np.rot90(x, 2)],
    np.stack: [
        lambda x, y, *_: np.stack([x, y]),
        lambda x, y, z, s, c: np.stack([x, c], axis=1),
        lambda x, y, *_: np.stack([x, y], axis=-1),
    ],
    np.concatenate: [
        lambda x, y, *_: np.concatenate([x, y]),
        lambda x, y, z, s, c: np.concatenate([c, x], axis=1),
        lambda x, y, *_: np.concatenate([x, y], axis=None),
    ],
    np.hstack: [lambda x, y, *_: np.hstack([x, y])],
    np.vstack: [lambda x, y, z, *_: np.vstack([x, z])],
    np.column_stack: [lambda x, y, *_: np.column_stack([x, y[:, 0]])],
    np.take_along_axis: [
        lambda x, *_: np.take_along_axis(x, IDX, axis=1),
        lambda x, *_: np.take_along_axis(x, IDX[:, :1] % 4, axis=0),
        lambda x, *_: np.take_along_axis(x, np.array([5, 0, 11]), axis=None),
    ],
    np.where: [
        lambda x, y, *_: np.where(MASK, x, y),
        lambda x, *_: np.where(MASK, x, 0.0),
        lambda x, y, z, *_: np.where(MASK, 1.0, z),
        lambda x, y, z, s, c: np.where(MASK[0], s, z),
    ],
    np.clip: [lambda x, *_: np.clip(x, -1.0, 1.0), lambda x, *_: np.clip(x, None, 0.5)],
    np.max: [lambda x, *_: np.max(x), lambda x, *_: np.max(x, axis=0), lambda x, *_: x.max(1, keepdims=True)],
    np.amax: [lambda x, *_: np.amax(x, axis=1)],
    np.min: [lambda x, *_: np.min(x), lambda x, *_: x.min(0)],
    np.amin: [lambda x, *_: np.amin(x, axis=0)],
    np.sort: [lambda x, *_: np.sort(x), lambda x, *_: np.sort(x, axis=0)],
    np.dot: [
        lambda x, y, z, *_: np.dot(x, z),
        lambda x, y, *_: x.dot(y.T),
        lambda x, y, z, s, c: np.dot(c, z),
    ],
    np.cross: [lambda x, y, *_: np.cross(x, y), lambda x, y, z, s, c: np.cross(c, z)],
    np.inner: [lambda x, y, *_: np.inner(x, y)],
    np.outer: [lambda x, y, z, *_: np.outer(z, x[0])],
    np.vdot: [lambda x, y, *_: np.vdot(x, y)],
    np.tensordot: [lambda x, y, *_: np.tensordot(x, y, axes=([0], [0]))],
    np.kron: [lambda x, y, z, *_: np.kron(z, y[1])],
    np.einsum: [lambda x, y, *_: np.einsum("ij,ij->i", x, y), lambda x, y, z, *_: np.einsum("ij,j->i", x, z)],
    np.linalg.norm: [lambda x, *_: np.linalg.norm(x, axis=-1), lambda x, y, z, *_: np.linalg.norm(z)],
    np.interp: [lambda x, *_: np.interp(x, [-3.0, 0.0, 3.0], [1.0, 2.0, -1.0])],
    np.broadcast_arrays: [lambda x, y, z, *_: np.broadcast_arrays(x, z)],
}
VALUE_FUNCTIONS = (
    np.shape, np.ndim, np.size, np.argmax, np.argmin, np.argsort, np.nonzero, np.all, np.any,
    np.zeros_like, np.ones_like, np.count_nonzero, np.flatnonzero, np.result_type,
)  # fmt: skip
for _f in VALUE_FUNCTIONS:
    FUNCTION_CASES[_f] = [lambda x, *_, f=_f: f(x > 0.0) if f in (np.all, np.any, np.count_nonzero) else f(x)]
FUNCTION_CASES |= {
    np.argpartition: [lambda x, *_: np.argpartition(x, 1, axis=1)],
    np.searchsorted: [lambda x, y, z, *_: np.searchsorted(np.sort(z), x)],
    np.isclose: [lambda x, y, *_: np.isclose(x, y)],
    np.allclose: [lambda x, y, *_: np.allclose(x, y)],
    np.empty_like: [lambda x, *_: np.empty_like(x).shape],
    np.full_like: [lambda x, *_: np.full_like(x, 2.0)],
    np.array_equal: [lambda x, y, *_: np.array_equal(x, y)],
}
INDEXING = [
    lambda x, *_: x[1],
    lambda x, *_: x[1:3],
    lambda x, *_: x[:, 2],
    lambda x, *_: x[..., 0],
    lambda x, *_: x[None, :, None],
    lambda x, *_: x[np.array([3, 0, 0])],  # rows by np.take
    lambda x, *_: x[[0, 2]],
    lambda x, *_: x[MASK],
    lambda x, *_: x[MASK[:, 0]],
    lambda x, *_: x[np.array([0, 1]), np.array([2, 2])],
    lambda x, *_: x[np.array([[0], [3]]), np.array([1, 2])],
    lambda x, *_: x[:, [2, 0]],
    lambda x, *_: x[np.array([1, 2]), 0],
    lambda x, *_: x[None, np.array([1, 2]), :],
    lambda x, y, z, s, c: np.stack([x, y])[np.array([0, 1]), :, np.array([2, 0])],  # advanced apart
    lambda x, *_: list(x)[2],
]


def _assign(x, y, z, s, c):
    out = x.copy()
    out[1] = z  # a lower-dimensional item
    out[2:, 1] = 7.0  # a constant: zero tangent
    out[np.array([0, 3])] = y[1:3]
    out[MASK] = y[MASK]
    out[..., 0] = s
    cube = np.stack([x, y])
    cube[np.array([0, 1]), :, np.array([2, 0])] = z[:2, None] * x[:, 0]  # advanced apart: slot by slot
    out += cube[1]
    return out


SETITEM = [_assign, lambda x, y, *_: np.add(x, y, out=x.copy())]
CASES = (
    {f"ufunc.{name}": calls for name, calls in UFUNC_CASES.items()}
    | {
        f"ufunc.{u.__name__}": [
            lambda x, y, z, s, c, u=u, call=call: call(u, x, y, z, s, c) for call in calls
        ]
        for u in dual._BINARY
        for calls in [MATMUL_CALLS if u is np.matmul else BINARY_CALLS]
    }
    | {f"function.{f.__name__}": calls for f, calls in FUNCTION_CASES.items()}
    | {"getitem": INDEXING, "setitem": SETITEM}
)


def _same_slot(a, b, i: int, k: int) -> None:
    """Assert that slot i of the k-run's output ``a`` equals the single run's ``b``, bit for bit."""
    if isinstance(b, Dual):
        assert isinstance(a, Dual) and a.k == k and b.k is None
        assert a.tangent.shape == (k, *a.shape)
        np.testing.assert_array_equal(a.value, b.value)
        np.testing.assert_array_equal(a.tangent[i], b.tangent)
    elif isinstance(b, list | tuple):
        assert len(a) == len(b)
        for u, v in zip(a, b, strict=True):
            _same_slot(u, v, i, k)
    elif isinstance(b, np.dtype):
        assert a == b
    else:
        assert not isinstance(a, Dual)
        np.testing.assert_array_equal(a, b)


def _check(call, k: int, values, tangents) -> None:
    c = values[1] - 0.3  # a plain array among the operands
    with np.errstate(all="ignore"):  # drawn values leave some domains: NaN in both runs alike
        multi = call(*(Dual(v, t, k) for v, t in zip(values, tangents, strict=True)), c)
        for i in range(k):
            single = call(*(Dual(v, t[i]) for v, t in zip(values, tangents, strict=True)), c)
            _same_slot(multi, single, i, k)


def _operands(k: int):
    def floats(shape):
        return hnp.arrays(np.float64, shape, elements=st.floats(-2.5, 2.5, allow_subnormal=False))

    shapes = [X, X, (3,), ()]
    return st.tuples(*(floats(s) for s in shapes), *(floats((k, *s)) for s in shapes))


# ------------------------------------------------------------------ the Dual with k tangents
def test01_the_cases_cover_every_rule_of_the_tables():
    assert set(dual._FUNCTIONS) - set(FUNCTION_CASES) == set()
    assert len({f.__name__ for f in FUNCTION_CASES}) == len(FUNCTION_CASES)  # one case name per function
    assert set(dual._UNARY) and set(dual._BINARY) and set(dual._VALUE_ONLY)  # the ufunc cases loop over them
    assert all(f"ufunc.{u.__name__}" in CASES for u in dual._BINARY)
    assert len(dual._FUNCTIONS) >= 60  # the tables are filled (the rule modules were imported)


@pytest.mark.parametrize("name", sorted(CASES))
def test02_every_rule_gives_each_of_k_slots_exactly_its_single_tangent_result(name):
    @given(k=st.integers(1, 3), data=st.data())
    def check(k, data):
        drawn = data.draw(_operands(k))
        values, tangents = drawn[:4], drawn[4:]
        for call in CASES[name]:
            _check(call, k, values, tangents)

    check()


def test03_a_single_dual_and_a_k_dual_do_not_mix():
    one, (a, b) = variable(np.ones(3)), variables(2)
    three = Dual(np.ones(3), None, 3)
    for mix in (
        lambda: one + a,
        lambda: a * three,
        lambda: np.stack([one, a * np.ones(3)]),
        lambda: np.where(np.ones(3, bool), one, a),
        lambda: np.dot(one, three),
        lambda: as_dual(one, 2),
        lambda: k_of(one, a),
    ):
        with pytest.raises(TypeError, match="must carry the tangents of the same parameters"):
            mix()
    target = Dual(np.zeros(3))
    with pytest.raises(TypeError, match="same parameters"):
        target[0] = a
    with pytest.raises(TypeError, match="same parameters"):
        three[0] = one[0]
    with pytest.raises(TypeError, match="drop"):
        np.zeros(2)[:] = a * np.ones(2)  # a plain array takes no Dual, whatever its tangents
    with pytest.raises(ValueError, match="leading axis of 2"):
        Dual(np.ones(3), np.ones(3), 2)
    with pytest.raises(ValueError, match="k >= 1"):
        variables(0)
    assert k_of(one, 1.0) is None and k_of(a, b, np.ones(2)) == 2 and k_of() is None
    assert a.tangent.tolist() == [1.0, 0.0] and b.tangent.tolist() == [0.0, 1.0]


# ------------------------------------------------------------------ flatland's gradients of k parameters
SHADOW = load_scene("shadow").with_camera(pixels=24)
EXACT = list(load_scene("shadow").parameters)
"""Translations, emission, albedo, a camera translation: parameters leaving each other's values alone."""
RUN = dict(spp=16, seed=5)
METHODS = [
    ("naive", {}),
    ("boundary", {}),
    ("reparam", {}),
    ("reparam", {"paired": True}),
    ("finite_difference", {}),
]
SUMMARY = (
    "value",
    "value_stderr",
    "derivative",
    "derivative_stderr",
    "value_sum_stderr",
    "derivative_sum_stderr",
)


def _assert_identical(a: GradientImage, b: GradientImage) -> None:
    for name in SUMMARY:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert (a.param, a.method, a.spp, a.seed, a.batches, a.scene) == (
        b.param,
        b.method,
        b.spp,
        b.seed,
        b.batches,
        b.scene,
    )
    assert dict(a.options) == dict(b.options)


@pytest.mark.parametrize(("method", "options"), METHODS)
def test04_a_single_string_builds_no_k_dual_and_a_list_of_it_gives_its_numbers_bit_for_bit(
    method, options, monkeypatch
):
    """The classic path never reaches the k code (every k-Dual is built by ``_with_slots``), so it runs
    the expressions it ran before k existed; a list of that one name (k = 1) gives the same numbers."""
    param = "occluder.translate.x"

    def refuse(*args):
        raise AssertionError("a single string built a Dual with k tangents")

    with monkeypatch.context() as patch:
        patch.setattr(dual, "_with_slots", refuse)
        single = render_gradient(SHADOW, param, method, **RUN, **options)
        if method != "finite_difference":  # the check can fail (finite differences carry no tangent)
            with pytest.raises(AssertionError, match="k tangents"):
                render_gradient(SHADOW, [param], method, **RUN, **options)
    assert type(single) is GradientImage
    images = render_gradient(SHADOW, [param], method, **RUN, **options)
    assert type(images) is GradientImages and images.params == (param,)
    _assert_identical(images[param], single)
    assert np.any(single.derivative != 0.0)


@pytest.mark.parametrize(("method", "options"), METHODS)
def test05_each_of_k_parameters_gets_exactly_its_single_calls_derivative(method, options):
    images = render_gradient(SHADOW, EXACT, method, **RUN, **options)
    assert images.derivative.shape == (len(EXACT), SHADOW.camera.pixels) and list(images) == EXACT
    for name in EXACT:
        _assert_identical(images[name], render_gradient(SHADOW, name, method, **RUN, **options))
    assert np.all(np.any(images.derivative != 0.0, axis=1))  # every parameter moves the image


ROUNDING = 1e-12
"""Agreement, relative to the image's largest derivative, when a rotation or a scale in the list
moves the shared geometry by rounding: measured at most 1.3e-14 on ``silhouette``."""


@pytest.mark.parametrize(("method", "options"), METHODS)
def test06_with_a_rotation_or_a_scale_in_the_list_the_others_agree_to_rounding(method, options):
    scene = load_scene("silhouette").with_camera(pixels=24)
    names = list(scene.parameters)  # occluder.rotate, ball.scale, camera.rotate among them
    images = render_gradient(scene, names, method, **RUN, **options)
    for name in names:
        single = render_gradient(scene, name, method, **RUN, **options)
        g = images[name]
        scale = np.max(np.abs(single.derivative))
        assert np.max(np.abs(g.derivative - single.derivative)) <= ROUNDING * scale, name
        assert np.max(np.abs(g.value - single.value)) <= ROUNDING * np.max(np.abs(single.value)), name
        if method == "finite_difference":  # each parameter's pair of renders is its own call's
            np.testing.assert_array_equal(g.derivative, single.derivative)


def _s(u: float, h: float = 1.0) -> float:
    return u / np.sqrt(u * u + h * h)


def _ds(u: float, h: float = 1.0) -> float:
    return h * h / (u * u + h * h) ** 1.5


def test07_irradiance_of_k_parameters_against_the_closed_form_and_the_single_calls():
    r"""A uniform segment emitter of radiance L over [a + θ, b + θ] at height 1 above a point with
    normal +y: $E = L (s(b + θ) - s(a + θ))$, $s(u) = u / \sqrt{u^2 + 1}$ (theory/radiometry).
    The boundary method's translation derivative has no Monte Carlo term (exact to rounding);
    dE/dL = s(b) - s(a) is the naive interior term, checked at the Šidák-corrected quantile."""
    a, b, radiance = -0.2, 0.9, 2.0
    scene = {
        "name": "closed_form_c",
        "camera": {"position": [0.0, -1.0], "direction": [0.0, 1.0], "fov": 1.0, "pixels": 2},
        "sky": 0.0,
        "shapes": [
            {"name": "light", "type": "segment", "points": [[a, 1.0], [b, 1.0]], "emission": radiance}
        ],
    }
    names = ["light.translate.x", "light.emission"]
    at = dict(point=(0.0, 0.0), normal=(0.0, 1.0), n=4096, seed=8)
    for method in ("naive", "boundary", "reparam", "finite_difference"):
        estimates = irradiance(scene, param=names, method=method, **at)
        assert list(estimates) == names
        for name in names:
            single = irradiance(scene, param=name, method=method, **at)
            assert estimates[name] == single  # the same numbers, bit for bit (dataclass equality of floats)
    e = irradiance(scene, param=names, method="boundary", **at)
    z = normal_quantile(1.0 - sidak(1e-3, 1))  # one Monte Carlo comparison at level 1e-3
    assert e["light.translate.x"].derivative == pytest.approx(radiance * (_ds(b) - _ds(a)), rel=1e-9)
    dl = e["light.emission"]
    assert abs(dl.derivative - (_s(b) - _s(a))) <= z * dl.derivative_stderr and dl.derivative_stderr > 0.0


@pytest.mark.parametrize(
    ("param", "says"),
    [
        ([], "non-empty list"),
        ((), "non-empty list"),
        (["occluder.translate.x", "occluder.translate.x"], "repeated: ['occluder.translate.x']"),
        (["occluder.translate.x", 3], "got 3"),
        (["occluder.translate.x", "nothing.translate.x"], "unknown parameter 'nothing.translate.x'"),
        ({"occluder.translate.x"}, "parameter name like"),
    ],
)
def test08_a_bad_list_of_parameters_is_one_error_naming_param_and_the_value(param, says):
    with pytest.raises(ValidationError, match=r"^param: ") as caught:
        render_gradient(SHADOW, param, "naive", spp=1)
    assert caught.value.field == "param" and says in str(caught.value)
    with pytest.raises(ValidationError, match=r"^param: "):
        irradiance(SHADOW, (0.0, 0.0), (0.0, 1.0), param=param, n=1)
    with pytest.raises(ValidationError, match=r"^h: .*'polygon.scale'"):
        render_gradient("polygon", ["polygon.rotate", "polygon.scale"], "finite_difference", spp=1, h=1.0)


def test09_gradient_images_map_each_name_to_its_gradient_image():
    names = ["light.emission", "occluder.translate.x", "floor.albedo"]
    images = render_gradient(SHADOW, names, "boundary", spp=8, seed=1)
    assert list(images) == names and len(images) == 3 and "floor.albedo" in images and "x" not in images
    assert images.shape == (SHADOW.camera.pixels,) and images.derivative_stderr.shape == (
        3,
        SHADOW.camera.pixels,
    )
    for i, name in enumerate(names):
        g = images[name]
        assert g.param == name and g.method == "boundary" and g.spp == 8 and g.seed == 1
        np.testing.assert_array_equal(g.derivative, images.derivative[i])
        assert g.film_sum().stderr == images.derivative_sum_stderr[i]
    assert dict(images)["occluder.translate.x"].param == "occluder.translate.x"
    with pytest.raises(KeyError, match="not one of the parameters"):
        images["occluder.rotate"]
    with pytest.raises(TypeError):
        images.options["h"] = 1.0  # read-only, as a GradientImage's


def test10_a_method_that_seeds_one_tangent_refuses_a_list_and_still_takes_one_name():
    """A registered method evaluating at ``variable(0.0)`` instead of ``task.dual_offset()`` moves every
    listed parameter along one tangent (their sum's derivative): refused, naming param."""
    from flatland.integrator import Identity
    from flatland.render import GRADIENT_METHODS

    def one_tangent(task):
        return task.evaluate(variable(0.0), Identity())

    with GRADIENT_METHODS.registered("one_tangent", one_tangent):
        single = render_gradient(SHADOW, "occluder.translate.x", "one_tangent", **RUN)
        with pytest.raises(ValidationError, match=r"^param: method 'one_tangent' gives one derivative"):
            render_gradient(SHADOW, ["occluder.translate.x", "light.emission"], "one_tangent", **RUN)
    np.testing.assert_array_equal(
        single.derivative, render_gradient(SHADOW, "occluder.translate.x", "naive", **RUN).derivative
    )
