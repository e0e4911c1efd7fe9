"""The renderer against closed forms (theory/radiometry), every method on them, and the render API's contract.

Closed forms:

(a) a black segment at height h spanning x in [x_lo, x_hi], in front of a radiance-1
    sky, seen by a pinhole at the origin looking along +y: film coordinate t sees the
    segment for t in [t_lo, t_hi] = [x_lo, x_hi] / h, so pixel j is
    ``1 - (K_j(t_hi) - K_j(t_lo))`` (K_j the filter's CDF) and, translating the
    segment along x (t_lo' = t_hi' = 1/h), ``dI_j/dθ = (k_j(t_lo) - k_j(t_hi)) / h``;
(b) the cosine-weighted sky at a point with normal +y under a black segment
    [a + θ, b + θ] at height h: ``E = 2 - (s(b + θ) - s(a + θ))``, s(u) = u / √(u² + h²);
(c) a uniform segment emitter of radiance L over [a + θ, b + θ] at height h:
    ``E = L (sin φ_b - sin φ_a) = L (s(b + θ) - s(a + θ))``.

Tolerances: ``|estimate - reference| <= z * stderr + FLOOR * max|reference|`` with z
the two-sided normal quantile at 1 - ALPHA, Šidák-corrected across the pixels of an
image (ALPHA = 1e-3), fixed seeds. FLOOR = 1e-4 covers pixels whose difference from
the reference lives on events too rare for any sample to see: a derivative below 1e-4
of the image's largest comes from a Gaussian filter's far tail, 4 or more of its σ
from the edge, where fewer than one sample in 10⁴ lands within a kernel's reach of
the edge, so that with 8192 samples none may and the batch stderr is exactly 0.
Pixel values use the rule-of-three bound instead (see ``_within``). The boundary
method's derivative of (a), (b) and (c) has no Monte Carlo term at all (the interior
term is exactly zero, the jumps are exact), so it must equal the closed form to
rounding.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import special, stats

from flatland.core.stats import normal_quantile, sidak
from flatland.core.validate import ValidationError
from flatland.render import GRADIENT_METHODS, irradiance, render, render_gradient
from flatland.scene import load_scene
from tests.tiers import SLOW

ALPHA = 1e-3
FLOOR = 1e-4
H, PIXELS, FOV = 1.0, 16, 1.2
# the segment's ends sit 0.3 and 0.6 of a pixel from pixel centres, so no tent reaches them by a sliver
_T, _DT = np.tan(0.5 * FOV), 2.0 * np.tan(0.5 * FOV) / PIXELS
X_LO, X_HI = H * (-_T + 5.8 * _DT), H * (-_T + 11.1 * _DT)


def _segment_scene(filt: str) -> dict:
    return {
        "name": "closed_form_a",
        "camera": {
            "position": [0.0, 0.0],
            "direction": [0.0, 1.0],
            "fov": 1.2,
            "pixels": PIXELS,
            "filter": filt,
        },
        "sky": 1.0,
        "shapes": [{"name": "occ", "type": "segment", "points": [[X_LO, H], [X_HI, H]]}],
    }


def _cdf(filt: str, t: float, c: np.ndarray, w: float) -> np.ndarray:
    x = t - c
    if filt == "box":
        return np.clip(x / w + 0.5, 0.0, 1.0)
    if filt == "tent":
        y = np.clip(x / w, -1.0, 1.0)
        return np.where(y < 0, 0.5 * (1 + y) ** 2, 1 - 0.5 * (1 - y) ** 2)
    return special.ndtr(x / (0.5 * w))


def _pdf(filt: str, t: float, c: np.ndarray, w: float) -> np.ndarray:
    """The filter k_j(t): the derivative of :func:`_cdf`, written out (not the renderer's)."""
    x = t - c
    if filt == "box":
        return np.where(np.abs(x) <= 0.5 * w, 1.0 / w, 0.0)
    if filt == "tent":
        return np.maximum(w - np.abs(x), 0.0) / (w * w)
    sigma = 0.5 * w
    return np.exp(-0.5 * (x / sigma) ** 2) / (sigma * np.sqrt(2.0 * np.pi))


def _closed_form_a(filt: str) -> tuple[np.ndarray, np.ndarray]:
    cam = load_scene(_segment_scene(filt)).camera
    c, w = cam.pixel_centers(), cam.pixel_width
    t_lo, t_hi = X_LO / H, X_HI / H
    value = 1.0 - (_cdf(filt, t_hi, c, w) - _cdf(filt, t_lo, c, w))
    deriv = (_pdf(filt, t_lo, c, w) - _pdf(filt, t_hi, c, w)) / H
    return value, deriv


def _z(m: int) -> float:
    return normal_quantile(1.0 - sidak(ALPHA, m))


def _within(estimate, stderr, reference, n: int | None = None) -> bool:
    """``|estimate - reference| <= z stderr + FLOOR max|reference|``, pixel by pixel.

    With ``n`` (samples per pixel, per-sample values in [0, 1]): where no sample saw a
    difference (stderr exactly 0), the event it missed has probability below
    ln(m / ALPHA) / n at the family level ALPHA over m pixels (the "rule of three"
    generalised), which bounds the missed part of the pixel value.
    """
    m = np.size(reference)
    tol = _z(m) * stderr + FLOOR * np.max(np.abs(reference))
    if n is not None:
        tol = np.where(stderr == 0.0, np.log(m / ALPHA) / n, tol)
    return bool(np.all(np.abs(estimate - reference) <= tol))


def _s(u):
    return u / np.sqrt(u * u + H * H)


def _ds(u):
    return H * H / (u * u + H * H) ** 1.5


@pytest.mark.parametrize("filt", ["box", "tent", "gaussian"])
def test01_pixel_values_match_the_closed_form(filt):
    value, _ = _closed_form_a(filt)
    image = render(_segment_scene(filt), spp=1024, seed=1)
    assert image.shape == (PIXELS,) and _within(image.value, image.stderr, value, n=1024)
    assert np.any((value > 0.05) & (value < 0.95))  # the test sees partially covered pixels


@pytest.mark.parametrize("filt", ["box", "tent", "gaussian"])
def test02_boundary_pixel_derivative_equals_the_closed_form(filt):
    _, deriv = _closed_form_a(filt)
    g = render_gradient(_segment_scene(filt), "occ.translate.x", method="boundary", spp=16, seed=2)
    assert np.allclose(g.derivative, deriv, atol=1e-5 * np.abs(deriv).max())
    assert np.abs(deriv).max() > 5.0


@pytest.mark.parametrize("filt", ["tent", "gaussian"])
def test03_reparam_pixel_derivative_matches_the_closed_form_and_naive_misses_it(filt):
    _, deriv = _closed_form_a(filt)
    g = render_gradient(_segment_scene(filt), "occ.translate.x", method="reparam", spp=8192, seed=3)
    assert _within(g.derivative, g.derivative_stderr, deriv)
    naive = render_gradient(_segment_scene(filt), "occ.translate.x", method="naive", spp=64, seed=3)
    # naive AD sees no moving discontinuity: exactly zero, the whole boundary term missing
    # (Loubet et al. 2019, Sec. 3.2)
    assert np.all(naive.derivative == 0.0)


def test04_reparam_probe_spread_bias_is_the_predicted_fraction():
    """Probes spanning ±s kernel deviations detect an edge only when it lies within their span.

    A lone translating edge then contributes the fraction P(|Z| < s) = 2Φ(s) - 1 of its
    term (Z the kernel centre's offset from the edge in kernel deviations): 0.683 at
    s = 1, 0.997 at the default s = 3. Measured on closed form (a), Gaussian filter.

    Checked on the pixels whose edge term is at least 1 % of the largest: further
    out, the edge lies in the filter's far tail, a sample lands within the probes'
    span of it only rarely (at seed 4 none of pixel 7's 8192 samples did, where the
    predicted term is 0.4 % of the largest), the batch means are not normal and a
    normal-quantile tolerance does not apply.
    """
    _, deriv = _closed_form_a("gaussian")
    g = render_gradient(
        _segment_scene("gaussian"), "occ.translate.x", method="reparam", spp=8192, seed=4, spread=1.0
    )
    fraction = 2.0 * special.ndtr(1.0) - 1.0
    live = np.abs(deriv) >= 0.01 * np.abs(deriv).max()
    assert _within(g.derivative[live], g.derivative_stderr[live], fraction * deriv[live])
    edge = np.argmax(np.abs(deriv))
    assert abs(g.derivative[edge] - deriv[edge]) > 5 * g.derivative_stderr[edge]  # the bias is visible


@pytest.mark.parametrize("filt", ["tent", "gaussian"])
def test05_paired_reparam_matches_the_closed_form(filt):
    value, deriv = _closed_form_a(filt)
    g = render_gradient(
        _segment_scene(filt), "occ.translate.x", method="reparam", spp=4096, seed=5, paired=True
    )
    assert _within(g.derivative, g.derivative_stderr, deriv)
    assert _within(g.value, g.value_stderr, value)


SKY = {
    "name": "closed_form_b",
    "camera": {"position": [0.0, -1.0], "direction": [0.0, 1.0], "fov": 1.0, "pixels": 2},
    "sky": 1.0,
    "shapes": [{"name": "occ", "type": "segment", "points": [[-0.5, H], [1.5, H]]}],
}


@SLOW
def test06_sky_irradiance_under_a_segment():
    a, b = -0.5, 1.5
    value, deriv = 2.0 - (_s(b) - _s(a)), -(_ds(b) - _ds(a))
    e = irradiance(SKY, (0.0, 0.0), (0.0, 1.0), n=65536, seed=6)
    assert abs(e.value - value) <= _z(1) * e.value_stderr
    boundary = irradiance(SKY, (0.0, 0.0), (0.0, 1.0), "occ.translate.x", "boundary", n=64, seed=6)
    assert boundary.derivative == pytest.approx(deriv, rel=1e-6)
    for options in ({"kappa": 100.0}, {"kappa": 1000.0}, {"kappa": 100.0, "paired": True}):
        r = irradiance(SKY, (0.0, 0.0), (0.0, 1.0), "occ.translate.x", "reparam", n=65536, seed=7, **options)
        assert abs(r.derivative - deriv) <= _z(3) * r.derivative_stderr, options
        assert r.derivative_stderr < 0.1 * deriv  # the comparison has power
    naive = irradiance(SKY, (0.0, 0.0), (0.0, 1.0), "occ.translate.x", "naive", n=1024, seed=6)
    assert naive.derivative == 0.0 and deriv > 0.5


def _emitters(second: bool) -> dict:
    shapes = [{"name": "light", "type": "segment", "points": [[-0.2, H], [0.9, H]], "emission": 2.0}]
    if second:  # a wider emitter behind it, partly hidden: the light technique's mixture density
        shapes.append(
            {"name": "far", "type": "segment", "points": [[-1.0, 2 * H], [3.0, 2 * H]], "emission": 0.5}
        )
    return {
        "name": "closed_form_c",
        "camera": {"position": [0.0, -1.0], "direction": [0.0, 1.0], "fov": 1.0, "pixels": 2},
        "sky": 0.0,
        "shapes": shapes,
    }


@SLOW
def test07_segment_emitter_irradiance():
    a, b, radiance = -0.2, 0.9, 2.0
    value, deriv = radiance * (_s(b) - _s(a)), radiance * (_ds(b) - _ds(a))
    scene = _emitters(second=False)
    e = irradiance(scene, (0.0, 0.0), (0.0, 1.0), n=65536, seed=8)
    assert abs(e.value - value) <= _z(1) * e.value_stderr
    boundary = irradiance(scene, (0.0, 0.0), (0.0, 1.0), "light.translate.x", "boundary", n=64, seed=8)
    assert boundary.derivative == pytest.approx(deriv, rel=1e-6)
    r = irradiance(
        scene, (0.0, 0.0), (0.0, 1.0), "light.translate.x", "reparam", n=65536, seed=9, kappa=300.0
    )
    assert abs(r.derivative - deriv) <= _z(1) * r.derivative_stderr and r.derivative_stderr < 0.2 * abs(deriv)
    naive = irradiance(scene, (0.0, 0.0), (0.0, 1.0), "light.translate.x", "naive", n=1024, seed=8)
    assert naive.derivative == 0.0
    # emission enters smoothly: naive AD is exact there, dE/dL = s(b) - s(a)
    dl = irradiance(scene, (0.0, 0.0), (0.0, 1.0), "light.emission", "naive", n=65536, seed=8)
    assert abs(dl.derivative - value / radiance) <= _z(1) * dl.derivative_stderr


def test08_overlapping_emitters_use_the_mixture_density():
    """The near emitter hides part of the far one; MIS with the technique's mixture density stays unbiased."""
    near = (_s(-0.2), _s(0.9))
    far = (-1.0 / np.sqrt(1.0 + 4.0), 3.0 / np.sqrt(9.0 + 4.0))  # sin φ of the far ends at height 2h
    visible_far = (near[0] - far[0]) + (far[1] - near[1])
    value = 2.0 * (near[1] - near[0]) + 0.5 * visible_far
    e = irradiance(_emitters(second=True), (0.0, 0.0), (0.0, 1.0), n=65536, seed=10)
    assert abs(e.value - value) <= _z(1) * e.value_stderr
    assert e.value_stderr < 0.01 * value


@pytest.mark.parametrize("name", ["silhouette", "shadow", "polygon"])
def test09_reparam_primal_is_bit_identical_to_naive(name):
    scene = load_scene(name).with_camera(pixels=12)
    for param in scene.parameters[:2]:
        naive = render_gradient(scene, param, method="naive", spp=8, seed=11)
        reparam = render_gradient(scene, param, method="reparam", spp=8, seed=11)
        assert np.array_equal(naive.value, reparam.value)
        assert np.array_equal(naive.value_stderr, reparam.value_stderr)
        assert not np.array_equal(naive.derivative, reparam.derivative)
    translate = render_gradient(scene, "camera.translate.x", method="naive", spp=8, seed=11)
    assert np.array_equal(render(scene, spp=8, seed=11).value, translate.value)


def test10_seeds_batches_and_standard_errors():
    """Same seed, same image; batch standard errors match the spread of independent renders.

    With Gaussian batch means, (std over R = 30 renders / stderr from B = 8 batches)² is
    F(R - 1, B - 1) per pixel, independently across pixels; the median ratio over the
    live pixels must lie in the central 1 - ALPHA interval of that null, drawn with a
    fixed seed. Measured median (reference seeds 100..103): 1.03, 0.89, 0.95, 0.90
    (the interval is [0.73, 1.56] for the 10 live pixels).
    """
    scene = load_scene("shadow").with_camera(pixels=12)
    a, b = render(scene, spp=32, seed=12), render(scene, spp=32, seed=12)
    assert np.array_equal(a.value, b.value) and a.batches == 16
    assert not np.array_equal(a.value, render(scene, spp=32, seed=13).value)
    assert render(scene, spp=12).batches == 12 and render(scene, spp=17).batches == 1
    assert np.all(np.isinf(render(scene, spp=17).stderr))
    # batch standard errors describe the spread between independent renders
    r, b = 30, 8
    runs = np.array([render(scene, spp=64, seed=s, batches=b).value for s in range(r)])
    se = render(scene, spp=64, seed=100, batches=b).stderr
    live = se > 0
    median = np.median(runs.std(axis=0, ddof=1)[live] / se[live])
    null = stats.f.rvs(r - 1, b - 1, size=(100_000, np.count_nonzero(live)), random_state=0)
    lo, hi = np.quantile(np.median(np.sqrt(null), axis=1), [0.5 * ALPHA, 1.0 - 0.5 * ALPHA])
    assert lo <= median <= hi, (lo, median, hi)


@pytest.mark.parametrize(
    ("call", "field"),
    [
        ({"spp": 0}, "spp"),
        ({"spp": 2.5}, "spp"),
        ({"seed": -3}, "seed"),
        ({"batches": 3}, "batches"),
        ({"param": "occluder.wobble"}, "param"),
        ({"method": "magic"}, "method"),
        ({"kappa": 0.0}, "kappa"),
        ({"kappa": -1.0}, "kappa"),
        ({"kappa_film": 0.0}, "kappa_film"),
        ({"probes": 0}, "probes"),
        ({"paired": 1}, "paired"),
        ({"refine": -1}, "refine"),
        ({"method": "finite_difference", "h": 0.0}, "h"),
        ({"method": "boundary", "kappa": 10.0}, "kappa"),
        ({"scene": {"name": "x"}}, "camera"),
    ],
)
def test11_bad_input_raises_one_error_naming_the_field(call, field):
    args = {"scene": load_scene("shadow").with_camera(pixels=4), "param": "occluder.translate.x"}
    args |= {"method": "reparam", "spp": 4, "seed": 0} | call
    with pytest.raises(ValidationError) as info:
        render_gradient(**args)
    assert info.value.field == field and str(info.value).startswith(f"{field}: ")


def test12_reparam_refuses_a_box_filter_and_points_to_the_tent():
    with pytest.raises(ValidationError) as info:
        render_gradient(_segment_scene("box"), "occ.translate.x", method="reparam", spp=4)
    assert info.value.field == "camera.filter" and "'box'" in str(info.value) and "tent" in str(info.value)
    assert set(GRADIENT_METHODS.names) == {"naive", "finite_difference", "boundary", "reparam"}
    with pytest.raises(ValidationError, match="normal"):
        irradiance(SKY, (0.0, 0.0), (0.0, 0.0))
    with pytest.raises(ValidationError, match=r"^point\[1\]: must be finite"):
        irradiance(SKY, (0.0, float("nan")), (0.0, 1.0))


@pytest.mark.parametrize(
    ("scene", "param", "h"),
    [("polygon", "polygon.scale", 1.0), ("silhouette", "ball.scale", 1.5), ("penumbra", "light.scale", 1.0)],
)
def test13_finite_difference_refuses_a_step_that_scales_a_shape_to_nothing(scene, param, h):
    """At θ0 - h a ``*.scale`` parameter scales by 1 - h: a point or a mirrored shape for h >= 1.

    Before the check, ``penumbra``'s ``light.scale`` at h = 1 divided by its zero-length
    emitter (a RuntimeWarning, an error here) and the others returned derivatives of a
    scene that does not exist. Just below 1 the step is accepted.
    """
    small = load_scene(scene).with_camera(pixels=2)
    with pytest.raises(ValidationError) as info:
        render_gradient(small, param, method="finite_difference", spp=4, h=h)
    message = str(info.value)
    assert info.value.field == "h" and message.startswith("h: must be < 1 for a scale parameter")
    assert repr(h) in message and repr(param) in message
    with pytest.raises(ValidationError, match=r"^h: must be < 1"):
        irradiance(small, (0.0, 0.0), (0.0, 1.0), param=param, method="finite_difference", n=4, h=h)
    g = render_gradient(small, param, method="finite_difference", spp=4, h=0.5)
    assert np.all(np.isfinite(g.derivative))
