"""A polygon's shape coefficients ``NAME.shape.K`` and a scene's ``offsets``: the deformation, and its
derivative by every method.

1. The names: a polygon of n vertices has 2 min(4, (n - 1) // 2) + 1 coefficients, listed by
   ``parameter_names``; a circle, a segment and a coefficient past the last are refused.
2. Bit for bit: coefficients at 0 leave the state unchanged; a scene with zero offsets renders the
   same image as without; offsets add exactly (a scene moved twice is the scene moved once by the sum).
3. The deformation is the documented one: each vertex stays on its ray from the centre, at the radius
   r_i (1 + Σ_K θ_K B_K(φ_i)) (to rounding).
4. Linearity, exact for the Dual methods: the derivative with respect to shape.K is the combination
   Σ_i (p_i - c) B_K(φ_i) · ∂I/∂p_i of the vertices' derivatives, from one pass of all of them
   (naive, boundary, reparam: forward mode is linear in the seed tangent and every branch depends
   on values only), to 1e-12 of the largest derivative (rounding: measured below 1e-15).
5. Against the closed form (a black polygon before a constant sky: the film interval between its
   extreme vertices, :mod:`flatland.closed_form`'s formula for a segment, written here for the
   polygon's extreme vertices): boundary, reparam and finite differences agree pixel by pixel
   within z standard errors (z the two-sided normal quantile at 1 - sidak(1e-3, pixels)), finite
   differences also within 1 % of the largest derivative (their resolution, tests/flatland/test_methods.py).
6. A derivative at a moved scene is the derivative at its offsets: finite differences there are bit for
   bit the central difference of the scenes moved by θ0 ± h, for a translation, a scale and a shape
   coefficient (a scale's offsets add: its factor is 1 + θ0 + h, not (1 + θ0)(1 + h)).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from flatland.closed_form import filter_cdf, filter_profile
from flatland.core.dual import variables
from flatland.core.stats import normal_quantile, sidak
from flatland.core.validate import ValidationError
from flatland.render import render, render_gradient
from flatland.scene import load_scene, parameter_names
from flatland.state import build_state, moved_scene, parse_parameter, shape_basis

N = 24
PIXELS = 16
ALPHA = 1e-3


def blob(n: int = N, sky: float = 1.0, pixels: int = PIXELS, albedo: float = 0.0) -> dict:
    """A black n-gon of radius 0.5 (slightly irregular) before a constant sky, seen from 2.5 away."""
    radii = 0.5 + 0.04 * np.cos(3 * 2 * np.pi * np.arange(n) / n)
    pts = [
        [r * math.cos(2 * math.pi * i / n), r * math.sin(2 * math.pi * i / n)] for i, r in enumerate(radii)
    ]
    camera = {
        "position": [0.3, -2.5],
        "direction": [0.0, 1.0],
        "fov": 0.9,
        "pixels": pixels,
        "filter": "tent",
    }
    shape = {"name": "blob", "type": "polygon", "points": pts, "albedo": albedo}
    return {"name": "blob", "camera": camera, "sky": sky, "shapes": [shape]}


def test01_a_polygon_has_its_shape_coefficients_and_other_shapes_none():
    for n, terms in ((3, 3), (4, 3), (5, 5), (8, 7), (9, 9), (24, 9)):
        scene = load_scene(blob(n))
        names = [p for p in parameter_names(scene) if ".shape." in p]
        assert names == [f"blob.shape.{k}" for k in range(terms)]
        assert all(parse_parameter(scene, p).kind == "shape" for p in names)
        with pytest.raises(ValidationError, match=f"shape.0 to shape.{terms - 1}"):
            parse_parameter(scene, f"blob.shape.{terms}")
    other = load_scene("silhouette")
    with pytest.raises(ValidationError, match="no shape coefficients"):
        parse_parameter(other, "ball.shape.0")
    with pytest.raises(ValidationError, match="no shape coefficients"):
        parse_parameter(load_scene("shadow"), "occluder.shape.0")


def test02_zero_coefficients_and_zero_offsets_change_nothing_and_offsets_add():
    scene = load_scene(blob())
    names = [f"blob.shape.{k}" for k in range(9)]
    plain, zero = build_state(scene), build_state(scene, names, [0.0] * 9)
    assert np.array_equal(plain.seg_a, zero.seg_a) and np.array_equal(plain.seg_b, zero.seg_b)
    params = [*names, "blob.translate.x", "blob.rotate", "blob.scale"]
    moved0 = moved_scene(scene, params, np.zeros(len(params)))
    assert np.array_equal(render(moved0, spp=16, seed=4).value, render(scene, spp=16, seed=4).value)
    # offsets add: moved by a then by b is moved by a + b (the same floats: the state is the same)
    a, b = np.linspace(-0.1, 0.1, len(params)), np.linspace(0.05, -0.02, len(params))
    twice = moved_scene(moved_scene(scene, params, a), params, b)
    once = moved_scene(scene, params, a + b)
    assert np.array_equal(build_state(twice).seg_a, build_state(once).seg_a)
    assert load_scene(once.to_dict()) == once  # offsets survive the round trip through a dict


def test03_the_deformation_moves_each_vertex_along_its_radius():
    scene = load_scene(blob())
    theta = np.array([0.1, -0.05, 0.08, 0.03, -0.06, 0.02, 0.04, -0.03, 0.05])
    p0 = np.array(scene.shapes[0].points)
    c = p0.mean(axis=0)
    phi = np.arctan2(p0[:, 1] - c[1], p0[:, 0] - c[0])
    basis = [np.ones(N)] + [f(m * phi) for m in range(1, 5) for f in (np.cos, np.sin)]
    radius = np.hypot(*(p0 - c).T) * (1.0 + sum(t * bk for t, bk in zip(theta, basis, strict=True)))
    p = np.array(build_state(moved_scene(scene, [f"blob.shape.{k}" for k in range(9)], theta)).vertices)
    np.testing.assert_allclose(
        p, c + radius[:, None] * np.stack([np.cos(phi), np.sin(phi)], axis=1), atol=1e-15
    )
    for k in range(9):  # the basis function of the state module is the same field
        np.testing.assert_allclose(shape_basis(scene.shapes[0], k), (p0 - c) * basis[k][:, None], atol=1e-15)


@pytest.mark.parametrize("method", ["naive", "boundary", "reparam"])
def test04_a_coefficient_derivative_is_the_combination_of_the_vertex_derivatives(method):
    scene = load_scene(blob(n=9, albedo=0.6, sky=0.5))  # lit by the sky: interior terms as well
    vertices = [f"blob.vertex.{i}.{axis}" for i in range(9) for axis in "xy"]
    shapes = ["blob.shape.3", "blob.shape.4"]
    g = render_gradient(scene, [*vertices, *shapes], method=method, spp=32, seed=5)
    d_vertices = g.derivative[: len(vertices)].reshape(9, 2, PIXELS)
    scale = np.max(np.abs(g.derivative[-2:]))
    assert scale > 0.0
    for k, name in ((3, shapes[0]), (4, shapes[1])):
        combination = np.einsum("ia,iaj->j", shape_basis(scene.shapes[0], k), d_vertices)
        assert np.max(np.abs(g[name].derivative - combination)) <= 1e-12 * scale


def _closed_form(scene, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel values and derivatives of a black polygon before a sky of radiance L, for shape.k.

    The polygon covers the film between its extreme vertices' film coordinates t_a < t_b:
    I_j = L (1 - K_j(t_b) + K_j(t_a)), dI_j/dθ = -L (k_j(t_b) t_b' - k_j(t_a) t_a'), the vertices moving
    at (p_i - c) B_k(φ_i) (the documented field), t = (v · r) / (v · f) with v = p - o.
    """
    cam, shape = scene.camera, scene.shapes[0]
    p = np.array(shape.points)
    c = p.mean(axis=0)
    phi = np.arctan2(p[:, 1] - c[1], p[:, 0] - c[0])
    order = (k + 1) // 2
    b = np.ones(len(p)) if k == 0 else np.cos(order * phi) if k % 2 else np.sin(order * phi)
    p_dot = (p - c) * b[:, None]
    f = np.array(cam.direction)
    r = np.array([f[1], -f[0]])
    v = p - np.array(cam.position)
    t = (v @ r) / (v @ f)
    t_dot = ((p_dot @ r) * (v @ f) - (v @ r) * (p_dot @ f)) / (v @ f) ** 2
    a, z = np.argmin(t), np.argmax(t)
    centres, width = cam.pixel_centers(), cam.pixel_width
    cdf = lambda x: filter_cdf(cam.filter, x - centres, width)  # noqa: E731
    pdf = lambda x: filter_profile(cam.filter, x - centres, width)  # noqa: E731
    value = scene.sky * (1.0 - cdf(t[z]) + cdf(t[a]))
    return value, -scene.sky * (pdf(t[z]) * t_dot[z] - pdf(t[a]) * t_dot[a])


@pytest.mark.parametrize(
    ("method", "spp"), [("boundary", 64), ("reparam", 8192), ("finite_difference", 16384)]
)
def test05_every_method_agrees_with_the_closed_form(method, spp):
    scene = load_scene(blob())
    z = normal_quantile(1.0 - sidak(ALPHA, PIXELS))
    options = {"h": 1e-2} if method == "finite_difference" else {}
    for k in (2, 3):
        _, derivative = _closed_form(scene, k)
        g = render_gradient(scene, f"blob.shape.{k}", method=method, spp=spp, seed=6, **options)
        scale = np.max(np.abs(derivative))
        slack = 0.01 * scale if method == "finite_difference" else 1e-12 * scale
        assert np.all(np.abs(g.derivative - derivative) <= z * g.derivative_stderr + slack), (k, method)
        assert scale > 0.0 and np.max(np.abs(g.derivative)) > 0.5 * scale  # the estimate is not 0 either


@pytest.mark.parametrize("param", ["blob.translate.x", "blob.scale", "blob.shape.3"])
def test06_the_derivative_at_a_moved_scene_is_the_derivative_at_its_offsets(param):
    scene = load_scene(blob(albedo=0.5))
    h, theta0 = 1e-2, 0.2
    g = render_gradient(
        moved_scene(scene, param, theta0), param, method="finite_difference", spp=16, seed=7, h=h
    )
    plus = render(moved_scene(scene, param, theta0 + h), spp=16, seed=7, batches=g.batches)
    minus = render(moved_scene(scene, param, theta0 - h), spp=16, seed=7, batches=g.batches)
    assert np.array_equal(g.value, render(moved_scene(scene, param, theta0), spp=16, seed=7).value)
    np.testing.assert_allclose(g.derivative, (plus.value - minus.value) / (2 * h), rtol=0, atol=1e-12)
    assert np.max(np.abs(g.derivative)) > 0.1
    # the offset is a variable as in build_state: the same state as a Dual at θ0 (values)
    state = build_state(moved_scene(scene, param, theta0), [param], variables(1))
    again = build_state(scene, [param], [theta0])
    assert np.array_equal(np.asarray(state.detached().seg_a), np.asarray(again.seg_a))
