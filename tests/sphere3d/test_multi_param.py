"""sphere3d's gradients of k parameters at once: one pass of Duals with k tangents (flatland.core.dual).

A single name never builds a k-Dual, so it runs the classic path (test01); a list of that one name
gives its numbers bit for bit. A list then gives each parameter the numbers of its single call, with
``np.testing.assert_array_equal`` (no tolerance), wherever the pass makes the same discrete choices as
that call (test02): ``naive`` always; ``reparam`` always (its default variant renders one pass per
shape the parameters move, :func:`sphere3d.methods.reparam._by_motion`; the paper variant keys
nothing on motion); ``finite_difference`` always (each parameter's pair of renders is its own call's);
``boundary`` where the parameters move the same edges and shading points. Scene values do not change
by rounding here (an offset of 0 added to a rotation angle or a scale leaves them exact), so no case
agrees "to rounding" only. Where ``boundary``'s parameters move different points (test03, measured:
translate.x leaves a shading point on a plane parallel to x still, translate.y moves it), its shading
term draws its edge samples among the edges and points that move under *any* parameter: another
draw, unbiased for each parameter (an edge a parameter does not move has speed 0 in its slot), so
the film sums are compared at the Šidák-corrected normal quantile of their standard errors.
"""

from __future__ import annotations

import numpy as np
import pytest

from flatland.core import dual
from flatland.core.contract import Estimate
from flatland.core.image import GradientImage, GradientImages
from flatland.core.stats import normal_quantile, sidak
from flatland.core.validate import ValidationError
from sphere3d.render import irradiance, render_gradient
from sphere3d.scene import load_scene
from tests.sphere3d.helpers import TRIANGLE, lambert, triangle_exact, triangle_scene

METHODS = [
    ("naive", {}),
    ("finite_difference", {}),
    ("boundary", {}),
    ("reparam", {}),
    ("reparam", {"variant": "paper"}),
]
RUN = dict(spp=4, seed=5, progress=False)
OCCLUDER = [
    "occluder.translate.x",
    "occluder.translate.y",
    "occluder.translate.z",
    "occluder.rotate.x",
    "occluder.rotate.y",
    "occluder.rotate.z",
    "occluder.scale",
    "occluder.albedo",
]
"""What ``python -m sphere3d gradient hard_shadow`` lists for the occluder, but its emission (an
emission parameter makes a dark shape an emitter of the whole pass: every number changes)."""
MIXED = ["occluder.translate.x", "light.translate.x", "ground.albedo", "light.emission", "camera.translate.y"]
"""Parameters that move different things: the occluder, the light, the camera, and none."""
SUMMARY = ("value", "value_stderr", "derivative", "derivative_stderr", "value_sum_stderr")


def _small(name: str, size: int = 16) -> dict:
    d = load_scene(name).to_dict()
    d["camera"].update(width=size, height=size)
    return d


HARD = _small("hard_shadow")


def _assert_identical(a: GradientImage, b: GradientImage) -> None:
    for name in SUMMARY:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.film_sum().stderr == b.film_sum().stderr
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
def test01_a_single_string_builds_no_k_dual_and_a_list_of_it_gives_its_numbers_bit_for_bit(
    method, options, monkeypatch
):
    """Every k-Dual is built by ``dual._with_slots``: refused, the single name still renders (it runs
    the expressions it ran before k existed), and the list of that name (k = 1) reaches it."""
    param = "occluder.translate.x"

    def refuse(*args):
        raise AssertionError("a single string built a Dual with k tangents")

    with monkeypatch.context() as patch:
        patch.setattr(dual, "_with_slots", refuse)
        single = render_gradient(HARD, param, method, **RUN, **options)
        if method != "finite_difference":  # the check can fail (finite differences carry no tangent)
            with pytest.raises(AssertionError, match="k tangents"):
                render_gradient(HARD, [param], method, **RUN, **options)
    assert type(single) is GradientImage
    images = render_gradient(HARD, [param], method, **RUN, **options)
    assert type(images) is GradientImages and images.params == (param,)
    _assert_identical(images[param], single)
    assert np.any(single.derivative != 0.0)


EXACT = [(m, o, n) for n in (OCCLUDER, MIXED) for m, o in METHODS if not (m == "boundary" and n is MIXED)]
"""Every method on the occluder's list; every method but boundary (test03) on the mixed list."""


@pytest.mark.parametrize(("method", "options", "names"), EXACT)
def test02_each_of_k_parameters_gets_exactly_its_single_calls_numbers(method, options, names):
    images = render_gradient(HARD, names, method, **RUN, **options)
    assert images.derivative.shape == (len(names), 16, 16) and list(images) == names
    for name in names:
        _assert_identical(images[name], render_gradient(HARD, name, method, **RUN, **options))
    moved = np.any(images.derivative != 0.0, axis=(1, 2))
    # every parameter moves the image (naive misses a light sliding in its own plane: its interior term is 0)
    assert np.all(moved | ((method == "naive") & (np.array(names) == "light.translate.x")))


def test03_boundary_with_parameters_moving_different_points_agrees_in_expectation():
    """Each parameter's film sum against its single call's, at the Šidák-corrected 1e-3 quantile of
    their standard errors added in quadrature (the two share the samples: positively correlated, so
    the quadrature overstates the difference's spread, a conservative test); the value and the film
    term's points are shared bit for bit."""
    names = OCCLUDER[:3] + MIXED[1:]
    images = render_gradient(HARD, names, "boundary", spp=16, seed=2, progress=False)
    z = normal_quantile(1.0 - sidak(1e-3, len(names)))
    differ = 0
    for name in names:
        single = render_gradient(HARD, name, "boundary", spp=16, seed=2, progress=False)
        np.testing.assert_array_equal(images[name].value, single.value)
        a, b = images[name].film_sum(), single.film_sum()
        assert abs(a.total - b.total) <= z * np.hypot(a.stderr, b.stderr), name
        differ += not np.array_equal(images[name].derivative, single.derivative)
    assert differ > 0  # the case this test is for: the draws are not the single calls'


@pytest.mark.parametrize(
    ("param", "says"),
    [
        ([], "non-empty list"),
        ((), "non-empty list"),
        (["occluder.translate.x", "occluder.translate.x"], "repeated: ['occluder.translate.x']"),
        (["occluder.translate.x", 3], "unknown parameter 3;"),
        (["occluder.translate.x", "nothing.translate.x"], "unknown parameter 'nothing.translate.x'"),
        ({"occluder.translate.x"}, "unknown parameter"),
    ],
)
def test04_a_bad_list_of_parameters_is_one_error_naming_param_and_the_value(param, says):
    with pytest.raises(ValidationError, match=r"^param: ") as caught:
        render_gradient(HARD, param, "naive", spp=1)
    assert caught.value.field == "param" and says in str(caught.value)
    with pytest.raises(ValidationError, match=r"^param: "):
        irradiance(HARD, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), param=param, n=1)
    with pytest.raises(ValidationError, match=r"^h: .*'occluder.scale'"):
        render_gradient(HARD, ["occluder.translate.x", "occluder.scale"], "finite_difference", spp=1, h=1.0)


def test05_irradiance_of_k_parameters_against_the_closed_form_and_the_single_calls():
    r"""Under a constant sky of radiance L a black triangle above the point hides Lambert's polygon
    integral Φ: $E = L (π - Φ)$ (tests/sphere3d/helpers.py ``lambert``, numpy's own vector code). Its
    derivatives by the triangle's translations (forward mode of the closed form) and by L ($π - Φ$)
    against the boundary method's estimates of one list, at the Šidák-corrected 1e-3 quantile of their
    standard errors; every method's list equals its single calls, bit for bit."""
    names = ["tri.translate.x", "tri.translate.y", "sky.emission"]
    at = dict(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), n=8192, seed=4, progress=False)
    for method, options in METHODS:
        estimates = irradiance(triangle_scene(), param=names, method=method, **at, **options)
        assert list(estimates) == names and all(type(e) is Estimate for e in estimates.values())
        for name in names:
            single = irradiance(triangle_scene(), param=name, method=method, **at, **options)
            assert estimates[name] == single, (method, name)  # dataclass equality of floats
    exact = {
        "tri.translate.x": float(triangle_exact(0).tangent),
        "tri.translate.y": float(triangle_exact(1).tangent),
        "sky.emission": float(np.pi - lambert(TRIANGLE)),
    }
    e = irradiance(triangle_scene(), param=names, method="boundary", **at)
    z = normal_quantile(1.0 - sidak(1e-3, len(names)))
    for name, slope in exact.items():
        assert abs(e[name].derivative - slope) <= z * e[name].derivative_stderr, name
        assert e[name].derivative_stderr > 0.0, name


def test06_a_method_that_seeds_one_tangent_refuses_a_list():
    from sphere3d.integrator import Identity
    from sphere3d.render import GRADIENT_METHODS

    def one_tangent(task):
        return task.evaluate(dual.variable(0.0), Identity())

    with GRADIENT_METHODS.registered("one_tangent", one_tangent):
        single = render_gradient(HARD, "occluder.translate.x", "one_tangent", **RUN)
        with pytest.raises(ValidationError, match=r"^param: method 'one_tangent' gives one derivative"):
            render_gradient(HARD, ["occluder.translate.x", "light.emission"], "one_tangent", **RUN)
    np.testing.assert_array_equal(
        single.derivative, render_gradient(HARD, "occluder.translate.x", "naive", **RUN).derivative
    )
