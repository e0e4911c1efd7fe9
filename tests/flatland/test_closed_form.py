"""flatland's closed forms for a black segment under the sky (:mod:`flatland.closed_form`).

Tests 01-04 check the closed forms themselves against routes that do not share their code: the
filter's integral against quadrature of its profile, the Dual derivatives against central
differences of the values, the camera's motions against scenes whose camera was moved by hand, the
irradiance against quadrature over the visible angles. Tests 05-06 check them against the renderer:
``render`` and ``irradiance`` are unbiased, and ``finite_difference``'s expectation is the closed
form's central difference at the same h, for every motion (so the parameters mean what the scene
table says). Per-pixel tests use the two-sided Student-t quantile (batches - 1 degrees of freedom)
at the Šidák level 1 - (1 - α)^(1/m) over the m claims of the test, α = 1e-3; seeds are fixed.
A pixel whose n samples all gave the same value (standard error 0) is held to the rare-event bound
instead: a part of the integrand of probability p is missed by all n importance-sampled samples
with probability (1 - p)^n <= e^{-pn}, so at the Šidák level the estimate misses at most
p <= log(m / α) / n of a radiance <= 1 (:func:`_unseen`).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import integrate, stats

import flatland as fl
from flatland import closed_form as cf
from flatland.core.stats import sidak
from flatland.core.validate import ValidationError

ALPHA = 1e-3
BATCHES = 16
SEGMENT = np.array([[-0.03, 2.4], [0.05, 2.6]])  # at depth 2.5, a few pixels wide, tilted
POINT, NORMAL = (0.0, 0.0), (math.sin(0.5), math.cos(0.5))
ABOVE = np.array([[-0.3, 1.0], [0.4, 1.2]])
MOTIONS = [
    "seg.translate.x",
    "seg.translate.y",
    "seg.rotate",
    "seg.scale",
    "seg.vertex.0.x",
    "seg.vertex.1.y",
    "camera.translate.x",
    "camera.translate.y",
    "camera.rotate",
]
SEGMENT_MOTIONS = [m for m in MOTIONS if m.startswith("seg.")]


def _quantile(m: int) -> float:
    return float(stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, m), BATCHES - 1))


def _unseen(m: int, n: int) -> float:
    """The largest share of a pixel that all its n samples miss at the Šidák level (module docstring)."""
    return math.log(m / ALPHA) / n


def _outside(estimate, stderr, expected, q, unseen) -> np.ndarray:
    """Pixels outside q · stderr (or ``unseen`` where the samples had no spread) of ``expected``."""
    allowed = np.where(stderr > 0.0, q * stderr, unseen)
    return np.flatnonzero(np.abs(estimate - expected) > allowed + 1e-12)


@pytest.mark.parametrize("kind", ["box", "tent", "gaussian"])
def test01_filter_cdf_is_the_integral_of_the_profile(kind):
    """K(x) = ∫_{-∞}^x k by adaptive quadrature (breaks at the kinks), at 9 offsets; k integrates to 1."""
    w = 0.2
    kinks = {"box": [-0.5 * w, 0.5 * w], "tent": [-w, 0.0, w], "gaussian": [0.0]}[kind]

    def k(x):
        return float(cf.filter_profile(kind, np.array(x), w))

    lo = -5.0 * w
    for x in np.linspace(-1.6 * w, 1.6 * w, 9):
        cuts = [lo, *(c for c in kinks if c < x), x]
        area = sum(integrate.quad(k, a, b, epsabs=1e-13)[0] for a, b in itertools.pairwise(cuts))
        assert float(cf.filter_cdf(kind, np.array(x), w)) == pytest.approx(area, abs=1e-9)
    assert float(cf.filter_cdf(kind, np.array(5.0 * w), w)) == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("param", MOTIONS)
def test02_derivatives_are_central_differences_of_the_values(param):
    """Film image and irradiance: Dual derivative against [f(h) - f(-h)] / 2h, h = 1e-6, < 1e-6 relative."""
    scene = cf.segment_scene(SEGMENT)
    h = 1e-6
    exact = cf.segment_image(scene, param).derivative
    diff = (cf.segment_image(scene, param, h).value - cf.segment_image(scene, param, -h).value) / (2 * h)
    assert np.max(np.abs(exact)) > 0.01
    assert np.max(np.abs(exact - diff)) < 1e-6 * np.max(np.abs(exact))
    if param in SEGMENT_MOTIONS:
        sky = cf.sky_segment_scene(ABOVE)
        _, slope = cf.occluded_sky_irradiance(sky, POINT, NORMAL, param)
        plus, minus = (cf.occluded_sky_irradiance(sky, POINT, NORMAL, param, t)[0] for t in (h, -h))
        assert abs(slope) > 0.01 or param == "seg.vertex.1.y"
        assert slope == pytest.approx((plus - minus) / (2 * h), rel=1e-6, abs=1e-9)
        assert cf.boundary_flux(sky, POINT, NORMAL, param).net == pytest.approx(slope, rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("param", ["camera.translate.x", "camera.translate.y", "camera.rotate"])
def test03_camera_motions_are_cameras_moved_by_hand(param):
    """The scene table's camera parameters (translate adds θ to the position, rotate turns the
    direction counter-clockwise): central differences of scenes whose camera dict was changed by hand."""
    scene = cf.segment_scene(SEGMENT)
    h = 1e-6

    def moved(t):
        cam = dict(scene["camera"])
        if param == "camera.rotate":
            c, s = math.cos(t), math.sin(t)
            x, y = cam["direction"]
            cam["direction"] = [c * x - s * y, s * x + c * y]
        else:
            cam["position"] = (np.array(cam["position"]) + np.eye(2)["xy".index(param[-1])] * t).tolist()
        return cf.segment_image({**scene, "camera": cam}).value

    exact = cf.segment_image(scene, param).derivative
    assert np.max(np.abs(exact - (moved(h) - moved(-h)) / (2 * h))) < 1e-6 * np.max(np.abs(exact))


def test04_irradiance_is_the_quadrature_over_the_visible_angles():
    """E = ∫ L max(0, cos(φ - φ_n)) over the directions the segment does not block, by quadrature with
    the two blocked angles found by intersecting rays with the segment (no closed form involved)."""
    phi_n = math.atan2(NORMAL[1], NORMAL[0])
    ends = np.sort([math.atan2(p[1], p[0]) for p in ABOVE])

    def integrand(phi):
        return max(0.0, math.cos(phi - phi_n))

    cuts = [phi_n - math.pi / 2, ends[0], ends[1], phi_n + math.pi / 2]
    visible = integrate.quad(integrand, cuts[0], cuts[1], epsabs=1e-13)[0]
    visible += integrate.quad(integrand, cuts[2], cuts[3], epsabs=1e-13)[0]
    value, _ = cf.occluded_sky_irradiance(cf.sky_segment_scene(ABOVE, sky=1.5), POINT, NORMAL)
    assert value == pytest.approx(1.5 * visible, rel=1e-12)


def test05_render_and_irradiance_are_unbiased_against_the_closed_forms():
    """``render`` in every pixel and ``irradiance`` (value): Student-t intervals, Šidák over 17 claims."""
    scene = cf.segment_scene(SEGMENT)
    exact = cf.segment_image(scene).value
    m = exact.size + 1
    image = fl.render(scene, spp=256, seed=3, batches=BATCHES, progress=False)
    assert _outside(image.value, image.stderr, exact, _quantile(m), _unseen(m, 256)).size == 0
    sky = cf.sky_segment_scene(ABOVE)
    e = fl.irradiance(sky, POINT, NORMAL, n=1 << 14, seed=4, batches=BATCHES, progress=False)
    value, _ = cf.occluded_sky_irradiance(sky, POINT, NORMAL)
    assert abs(e.value - value) <= _quantile(m) * e.value_stderr


def test06_finite_difference_expects_the_closed_forms_central_difference_for_every_motion():
    """``finite_difference`` (h = 0.02, a quarter pixel here; common random numbers) per pixel against
    the closed form's own [I(h) - I(-h)] / 2h, for every motion of the scene table: the renderer's
    parameters move what the closed form moves. Šidák over the pixels of all motions; a pixel without
    spread (no sample changed between the two renders) may miss the rare-event share of either render,
    divided by 2h."""
    scene = cf.segment_scene(SEGMENT)
    h, spp = 0.02, 256
    m = len(MOTIONS) * 16
    for param in MOTIONS:
        expected = (cf.segment_image(scene, param, h).value - cf.segment_image(scene, param, -h).value) / (
            2 * h
        )
        g = fl.render_gradient(
            scene, param, "finite_difference", spp=spp, seed=5, batches=BATCHES, progress=False, h=h
        )
        outside = _outside(
            g.derivative, g.derivative_stderr, expected, _quantile(m), _unseen(m, spp) / (2 * h)
        )
        assert outside.size == 0, (param, outside)
        assert np.count_nonzero(g.derivative_stderr) >= 1, param  # the test is not vacuous


def test07_bad_input_is_refused():
    scene = cf.segment_scene(SEGMENT)
    lit = {**scene, "shapes": [{**scene["shapes"][0], "albedo": 0.5}]}
    with pytest.raises(ValidationError, match="black"):
        cf.segment_image(lit)
    behind = cf.segment_scene(-SEGMENT)
    with pytest.raises(ValidationError, match="in front of the camera"):
        cf.segment_image(behind)
    with pytest.raises(ValidationError, match="above the point's horizon"):
        cf.occluded_sky_irradiance(cf.sky_segment_scene(-ABOVE), POINT, NORMAL)
    with pytest.raises(ValidationError, match="filter"):
        cf.filter_cdf("square", np.zeros(1), 1.0)
