"""A sub-pixel occluder on flatland's film: its edges are followed even when it falls between probes.

The scene: a black horizontal stick ``width`` pixels wide at depth 2.5 in front of an emissive
backdrop, 16 pixels, gaussian filter, θ = the stick's x-translation. Its image has the closed
form ``I_j = 1 - ∫_{t_a}^{t_b} k_j``, so ``dI_j/dθ = -(k_j(t_b) - k_j(t_a)) ṫ`` with ṫ = 1 / 2.5 (film
coordinate t = x / (y + 2.5)). The film probes of ``reparam`` are 2σ = 0.57 px apart at the
defaults (σ = 0.4 px / √2); a stick narrower than that lies between two probes for most kernel
centres, and without :func:`flatland.reparam.probes.film_gap_probe` the transform was the identity
there, losing 1 - width / 0.57 px of the edge terms (measured: 83 ± 36 % at 0.1 px, 57 ± 10 % at
0.2 px, 1024 spp × 8 positions).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

import flatland as fl
from flatland import closed_form as fcf
from flatland.core.dual import tangent, variable
from flatland.core.rng import Draws
from flatland.core.stats import sidak
from flatland.integrator import Context
from flatland.lights import Lights
from flatland.reparam.default import ReparamTransforms, default_kappa_film
from flatland.sampling import filter_value, sample_von_mises
from flatland.scene import load_scene
from flatland.state import build_state

ALPHA = 1e-3
PIXELS = 16
TAN_HALF = math.tan(0.45) / 4.0
DEPTH = 2.5
PIXEL_WORLD = 2.0 * TAN_HALF * DEPTH / PIXELS  # one pixel at the stick's depth
PARAM = "stick.translate.x"


def _scene(width_px, x0):
    half = 0.5 * width_px * PIXEL_WORLD
    return {
        "name": "stick",
        "camera": {
            "position": [0.0, -DEPTH],
            "direction": [0.0, 1.0],
            "fov": 2.0 * math.atan(TAN_HALF),
            "pixels": PIXELS,
            "filter": "gaussian",
        },
        "sky": 0.0,
        "shapes": [
            {"name": "backdrop", "type": "segment", "points": [[-4.0, 2.0], [4.0, 2.0]], "emission": 1.0},
            {
                "name": "stick",
                "type": "segment",
                "points": [[x0 - half, 0.0], [x0 + half, 0.0]],
                "albedo": 0.0,
            },
        ],
        "parameters": [PARAM],
    }


def _exact(scene):
    """dI_j/dθ = -(k_j(t_b) - k_j(t_a)) / 2.5 per pixel (module docstring)."""
    cam = load_scene(scene).camera
    (xa, _), (xb, _) = scene["shapes"][1]["points"]
    k = [filter_value("gaussian", x / DEPTH, cam.pixel_centers(), cam.pixel_width) for x in (xa, xb)]
    return -(k[1] - k[0]) / DEPTH


def test01_every_kernel_whose_probes_span_a_thin_stick_follows_it():
    """0.05 px stick: every film sample whose probe span [ω - 3σ, ω + 3σ] overlaps the stick's image
    is translated like the stick (tangent ṫ = 1 / 2.5); without the extra probe 9 % were."""
    scene = _scene(0.05, 0.0013)
    sc = load_scene(scene)
    state = build_state(sc, PARAM, variable(0.0))
    state0 = state.detached()
    kappa_film = default_kappa_film(sc.camera.pixel_width)
    transforms = ReparamTransforms(1000.0, kappa_film, 4, 3.0, 2, False)
    n = 20000
    t = np.random.default_rng(1).uniform(-0.02, 0.02, n)
    pixel = np.clip(np.searchsorted(sc.camera.pixel_centers(), t), 0, PIXELS - 1)
    draws = Draws.of(5, np.arange(n))
    members = transforms.camera(Context(state, state0, Lights.of(state0), transforms), t, pixel, draws)
    sigma = 1.0 / math.sqrt(kappa_film)
    centre = t + sigma * draws.normals("kernel.film")  # the kernel centres ω the transform drew
    (xa, _), (xb, _) = scene["shapes"][1]["points"]
    overlaps = (centre + 3.0 * sigma > xa / DEPTH) & (centre - 3.0 * sigma < xb / DEPTH)
    assert overlaps.sum() > 1000
    assert np.allclose(np.asarray(tangent(members.points))[overlaps, 0], 1.0 / DEPTH, rtol=1e-12)


def test02_a_thin_sticks_edge_terms_are_kept():
    """0.2 px stick at 8 positions across a pixel, 4096 spp: the share of its edge terms lost,
    1 - Σ sign(I') g / Σ |I'|, is 0 within q · stderr (two-sided normal quantile, α = 1e-3; the
    pixels are independent, so stderr² = Σ_j se_j² / (Σ |I'|)²). Without the extra probe the loss
    was 57 ± 10 % (z about 6); measured here -6.6 ± 9.8 %."""
    num = den = var = 0.0
    for x0 in np.linspace(0.0, PIXEL_WORLD, 8, endpoint=False) + 0.0013:
        scene = _scene(0.2, x0)
        exact = _exact(scene)
        g = fl.render_gradient(scene, PARAM, method="reparam", spp=4096, seed=2)
        num += np.sum(np.sign(exact) * g.derivative)
        den += np.sum(np.abs(exact))
        var += np.sum(g.derivative_stderr**2)
    lost, stderr = 1.0 - num / den, math.sqrt(var) / den
    assert abs(lost) <= stats.norm.ppf(1.0 - 0.5 * ALPHA) * stderr


def test03_every_shading_kernel_whose_probes_span_a_thin_stick_follows_it():
    """A stick seen under 0.02 rad from a shading point, below the probes' spacing 2 / √κ = 0.063 rad:
    every direction sample whose probe span [ω - 3σ, ω + 3σ] (σ = 1 / √κ) overlaps the stick's image
    is translated like the stick (``flatland.reparam.probes.angle_gap_probe``): its angle tangent lies
    between the
    rates -h / (x² + h²) of the stick's two ends."""
    x0, height, angle = 0.3, 1.0, 0.02
    w = angle * (1.0 + x0**2)  # the stick's length for that angle at x0 (dφ/dx = 1 / (1 + x²) at height 1)
    scene = {
        "name": "thin",
        "camera": {
            "position": [0.0, -3.0],
            "direction": [0.0, 1.0],
            "fov": 0.5,
            "pixels": 8,
            "filter": "tent",
        },
        "sky": 1.0,
        "shapes": [
            {"name": "stick", "type": "segment", "points": [[x0 - w / 2, height], [x0 + w / 2, height]]}
        ],
        "parameters": [PARAM],
    }
    sc = load_scene(scene)
    state = build_state(sc, PARAM, variable(0.0))
    state0 = state.detached()
    kappa = 1000.0
    transforms = ReparamTransforms(kappa, 1.0, 4, 3.0, 2, False)
    n = 20000
    phi = np.random.default_rng(2).uniform(1.2, 1.45, n)  # around the stick's direction, atan2(1, 0.3) = 1.28
    draws = Draws.of(6, np.arange(n))
    ctx = Context(state, state0, Lights.of(state0), transforms)
    members = transforms.directions(ctx, np.zeros((n, 2)), np.full(n, -1), phi, draws)
    centre = sample_von_mises(draws.uniforms("kernel.directions"), phi, kappa)  # the centres ω it drew
    sigma = 1.0 / math.sqrt(kappa)
    ends = np.arctan2(height, np.array([x0 + w / 2, x0 - w / 2]))
    overlaps = (centre + 3.0 * sigma > ends[0]) & (centre - 3.0 * sigma < ends[1])
    assert overlaps.sum() > 1000
    # the stick's angle φ = atan2(h, x) moves at dφ/dθ = -h / (x² + h²), between its ends' rates
    rates = -height / (np.array([x0 - w / 2, x0 + w / 2]) ** 2 + height**2)
    followed = np.asarray(tangent(members.points))[overlaps, 0]
    assert np.all((followed >= rates.min() - 1e-12) & (followed <= rates.max() + 1e-12))


SUB_PIXEL_MOTIONS = ("seg.rotate", "seg.scale", "seg.translate.y", "seg.vertex.0.y")
SUB_PIXEL_ANGLES = (90.0, 10.0)


def _sub_pixel_stick(x0_px: float, angle_deg: float) -> dict:
    """A black 0.2 px stick at depth 2.5 under the sky, ``x0_px`` pixels off the axis, its line
    ``angle_deg`` degrees from the line of sight (90: facing the camera)."""
    fov, pixels = 0.5, 16
    pixel = 2.0 * math.tan(0.5 * fov) / pixels * DEPTH
    half = 0.1 * pixel / math.sin(math.radians(angle_deg))  # its image is 0.2 px wide
    u = np.array([math.sin(math.radians(angle_deg)), math.cos(math.radians(angle_deg))])
    centre = np.array([x0_px * pixel, DEPTH])
    return fcf.segment_scene([centre - half * u, centre + half * u], pixels=pixels, fov=fov)


@pytest.mark.parametrize("angle", SUB_PIXEL_ANGLES)
@pytest.mark.parametrize("param", SUB_PIXEL_MOTIONS)
def test04_a_sub_pixel_stick_is_followed_under_every_motion(param, angle):
    """A 0.2 px stick turning or scaling about its middle, moving in depth or by one end, facing the
    camera or seen at 10 degrees: its image lies between two probes, and its ends move apart while
    its middle (what one probe sees) stands nearly still. Both ends are followed
    (:func:`flatland.reparam.probes.film_inner_shape`), so the share of the exact derivative lost
    (:func:`flatland.closed_form.segment_image`), 1 - Σ sign(g) d / Σ |g| over 4 positions across a
    pixel, is 0 within the normal quantile at family-wise α = 1e-3 over the 8 cases (Šidák) times
    its standard error (independent pixels: stderr² = Σ se² / (Σ |g|)²). Following the middle
    alone lost 94-100 % of it (z 5-110)."""
    num = den = var = 0.0
    for x0 in np.linspace(0.0, 1.0, 4, endpoint=False) + 0.13:
        scene = _sub_pixel_stick(x0, angle)
        exact = fcf.segment_image(scene, param).derivative
        g = fl.render_gradient(scene, param, method="reparam", spp=1024, seed=3)
        num += np.sum(np.sign(exact) * g.derivative)
        den += np.sum(np.abs(exact))
        var += np.sum(g.derivative_stderr**2)
    lost, stderr = 1.0 - num / den, math.sqrt(var) / den
    level = sidak(ALPHA, len(SUB_PIXEL_MOTIONS) * len(SUB_PIXEL_ANGLES))
    assert abs(lost) <= stats.norm.ppf(1.0 - 0.5 * level) * stderr, (lost, stderr)


@pytest.mark.parametrize("param", ["seg.rotate", "seg.translate.y", "seg.vertex.0.y"])
def test05_a_silhouette_end_inside_the_probes_span_is_followed_exactly(param):
    """A 4 px segment facing the camera, turning about its middle, receding or moved by one end: its
    ends' film coordinates move at rates ṫ_a ≠ ṫ_b, and points along it at rates between. Every film
    sample whose probe span [ω - 3σ, ω + 3σ] holds exactly one end is translated at that end's
    rate (:func:`flatland.reparam.probes.film_shape_end`), to rounding; the probes' hit next to
    the switch, 0 to 0.6 px inside the end, moved unlike it (7-16 % of the derivative lost)."""
    scene = _sub_pixel_stick(0.13, 90.0)
    (a, b) = np.array(scene["shapes"][0]["points"])
    middle, half = 0.5 * (a + b), 10.0 * (b - a)  # 20 times the 0.2 px stick: 4 px
    scene["shapes"][0]["points"] = [(middle - half).tolist(), (middle + half).tolist()]
    exact = fcf.segment_image(scene, param)
    sc = load_scene(scene)
    state = build_state(sc, param, variable(0.0))
    state0 = state.detached()
    kappa_film = default_kappa_film(sc.camera.pixel_width)
    transforms = ReparamTransforms(1000.0, kappa_film, 4, 3.0, 2, False)
    n = 20000
    width = sc.camera.pixel_width
    t = np.random.default_rng(4).uniform(exact.ends[0] - width, exact.ends[1] + width, n)
    pixel = np.clip(np.searchsorted(sc.camera.pixel_centers(), t), 0, sc.camera.pixels - 1)
    draws = Draws.of(7, np.arange(n))
    members = transforms.camera(Context(state, state0, Lights.of(state0), transforms), t, pixel, draws)
    sigma = 1.0 / math.sqrt(kappa_film)
    centre = t + sigma * draws.normals("kernel.film")
    inside = np.abs(exact.ends[None, :] - centre[:, None]) < 3.0 * sigma  # (n, 2): which end is in
    followed = np.asarray(tangent(members.points))[:, 0]
    assert abs(exact.rates[1] - exact.rates[0]) > 0.1 * np.abs(exact.rates).max()  # the ends differ
    for k in (0, 1):
        rows = inside[:, k] & ~inside[:, 1 - k]
        assert rows.sum() > 1000
        assert np.allclose(followed[rows], exact.rates[k], rtol=1e-9, atol=0.0)


SHADING_NORMAL = (math.sin(math.radians(30.0)), math.cos(math.radians(30.0)))  # no motion is symmetric


@pytest.mark.parametrize("angle", SUB_PIXEL_ANGLES)
@pytest.mark.parametrize("param", SUB_PIXEL_MOTIONS)
def test06_a_thin_stick_seen_from_a_shading_point_is_followed_under_every_motion(param, angle):
    """The shading integral's counterpart of test04: a black stick under the sky seen under 0.02 rad
    from a point (below the probes' spacing 0.063 rad at the defaults), its line at ``angle`` to the
    line of sight, turning, scaling, receding or moved by one end. Both ends are followed
    (:func:`flatland.reparam.probes.angle_inner_shape`), so the error of dE/dθ against the closed
    form (:func:`flatland.closed_form.occluded_sky_irradiance`), relative to the gross boundary flux
    (the atlas's measure), is 0 within the Student t quantile (16 batches) at family-wise α = 1e-3
    over the 8 cases (Šidák) times its standard error. Following one point lost 50-100 % of it."""
    half = 0.5 * 0.02 * np.array([math.sin(math.radians(angle)), math.cos(math.radians(angle))])
    scene = fcf.sky_segment_scene(np.stack([np.array([0.0, 1.0]) - half, np.array([0.0, 1.0]) + half]))
    point = (0.0, 0.0)
    exact = fcf.occluded_sky_irradiance(scene, point, SHADING_NORMAL, param)[1]
    gross = fcf.boundary_flux(scene, point, SHADING_NORMAL, param).gross
    e = fl.irradiance(scene, point, SHADING_NORMAL, param, method="reparam", n=1 << 16, seed=3, batches=16)
    lost, stderr = (exact - e.derivative) / gross, e.derivative_stderr / gross
    level = sidak(ALPHA, len(SUB_PIXEL_MOTIONS) * len(SUB_PIXEL_ANGLES))
    assert abs(lost) <= stats.t.ppf(1.0 - 0.5 * level, 15) * stderr, (lost, stderr)
