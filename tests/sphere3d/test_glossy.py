r"""Glossy shapes in sphere3d (a ``roughness``: the rough GGX conductor of :mod:`sphere3d.bsdf`), shaded by
:mod:`sphere3d.glossy` and carried along paths by :mod:`sphere3d.paths`.

1. The material: ``roughness`` in (0, 1], a parameter of glossy shapes only; a mirror (0) refused
   with one error naming the field and why, in the API and on the command line.
2. The mixed path code changes nothing on diffuse vertices: a scene with a glossy shape that no ray
   meets renders as without it (to rounding) at depths 1-4.
3. Closed forms and quadratures at one point, from many samples of
   :func:`~sphere3d.glossy.glossy_samples` (the MIS estimate of $L_r = ∫ L_i f \cos θ\, dω$):
   under an area light, against scipy's adaptive quadrature of
   $∫_A L_e f(w_i, w) \cos θ_x \cos θ_y / d^2 dA$ over the light, with an independent GGX written
   out below (textbook D, height-correlated Smith $G_2$ from Λ); under a uniform sky of radiance 1
   (white furnace), against the directional albedo :func:`~sphere3d.bsdf.albedo_ggx` (Gauss-Legendre
   in the half vector), every sample at most F; and the roughness derivative (forward mode) against
   the central difference of that quadrature in α.
4. Images: the furnace scene's floor, a plane that cannot see itself, is the same at every depth;
   the roughness derivative of the image (naive) against finite differences of the primal (smooth:
   a uniform sky, no visibility moves).
5. Gradients on ``glossy_reflection`` and ``interreflection`` at depths 1-4: affine in the light's
   emission (naive = finite differences to rounding); the occluder's x-translation by region: naive
   misses the moving shadow's visibility terms, a bias of many standard errors (shown, as a bias).
6. ``boundary`` at depth 1 on the glossy floor against finite differences by region (shadow halves,
   reflection, occluder), ``reparam`` against finite differences and ``boundary`` (every region within
   noise); ``reparam`` refuses its paired
   kernel samples on glossy shapes (both methods' glossy paths: tests/sphere3d/test_path_boundary.py,
   tests/sphere3d/test_path_reparam.py).
7. A glossy vertex beyond the first: the irradiance under a glossy floor lit by a uniform sky, with
   one further vertex, against $2π S ∫ A(c) c\, dc$ by quadrature; the optimiser's bounds on roughness.

Tolerances: $|mean - reference| <= q · stderr$, q the normal quantile (point estimates from 2^17
samples) or the Student-t quantile of 16 batches, Šidák-corrected over each test's comparisons at
ALPHA = 1e-3, fixed seeds.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import integrate

from benchmarks.bench_glossy import regions as regions_of
from benchmarks.bench_glossy import shadow_halves
from flatland.core.dual import tangent, variable
from flatland.core.rng import Draws
from flatland.core.stats import family_quantile
from flatland.core.validate import ValidationError
from sphere3d.__main__ import main
from sphere3d.bsdf import albedo_ggx, weight_ggx
from sphere3d.glossy import glossy_samples
from sphere3d.integrator import Shading
from sphere3d.methods import GRADIENT_METHODS
from sphere3d.render import irradiance, render, render_gradient
from sphere3d.scene import load_scene
from sphere3d.state import build_state
from sphere3d.tasks import ImageTask
from tests.tiers import sweep

ALPHA = 1e-3
BATCHES = 16
N = 2**17
DEPTHS = (1, 2, 3, 4)


def _glossy_floor(roughness: float = 0.15, albedo: float = 0.9, sky: float = 0.0, light: bool = True) -> dict:
    """A 5 x 5 glossy floor (z = 0, normal +z) under glossy_reflection's 1 x 1 light (emission 20), no
    occluder."""
    scene = load_scene("glossy_reflection").to_dict()
    shapes = [dict(scene["shapes"][0], roughness=roughness, albedo=albedo)]
    shapes += [scene["shapes"][1]] if light else []
    return dict(scene, sky=sky, shapes=shapes)


def _points(state, x, wi, seed: int, n: int = N):
    """``n`` copies of the floor point x (normal +z) seen from ``wi``, with their uniforms."""
    x = np.broadcast_to(np.asarray(x, dtype=np.float64), (n, 3)).copy()
    normal = np.broadcast_to([0.0, 0.0, 1.0], (n, 3)).copy()
    wi = np.asarray(wi, dtype=np.float64)
    wi = np.broadcast_to(wi / np.linalg.norm(wi), (n, 3)).copy()
    shading = Shading.at(state, x, normal, Draws.of(seed, np.arange(n)))
    u = np.random.default_rng(seed).random((n, 5))
    return shading, wi, u


def _mean(values) -> tuple[float, float]:
    v = np.asarray(values, dtype=np.float64)
    return float(v.mean()), float(v.std(ddof=1) / np.sqrt(v.size))


def _ggx_textbook(wi, wo, alpha: float, albedo: float) -> float:
    r"""f for n = +z from the textbook forms: $D = α^2 / (π ((n·h)^2 (α^2 - 1) + 1)^2)$,
    $Λ(c) = (\sqrt{1 + α^2 (1 - c^2) / c^2} - 1) / 2$, $G_2 = 1 / (1 + Λ_i + Λ_o)$,
    $f = F D G_2 / (4 c_i c_o)$."""
    ci, co = wi[2], wo[2]
    if ci <= 0.0 or co <= 0.0:
        return 0.0
    h = (wi + wo) / np.linalg.norm(wi + wo)
    d = alpha**2 / (np.pi * (h[2] ** 2 * (alpha**2 - 1.0) + 1.0) ** 2)
    lam = lambda c: 0.5 * (np.sqrt(1.0 + alpha**2 * (1.0 - c * c) / (c * c)) - 1.0)  # noqa: E731
    return albedo * d / (1.0 + lam(ci) + lam(co)) / (4.0 * ci * co)


def test01_roughness_is_a_checked_parameter_of_glossy_shapes_only(tmp_path, capsys):
    assert "ground.roughness" in load_scene("glossy_reflection").parameters
    assert not any(p.endswith(".roughness") for p in load_scene("hard_shadow").parameters)
    assert load_scene("glossy_reflection").shapes[0].roughness == 0.15
    for bad in (0, 0.0, -0.1, 1.5, True, "0.2", float("nan")):
        scene = _glossy_floor()
        scene["shapes"][0]["roughness"] = bad
        with pytest.raises(ValidationError) as err:
            load_scene(scene)
        assert err.value.field == "shapes[0].roughness" and repr(bad) in str(err.value)
        assert "perfect mirror" in str(err.value) and "delta BSDF" in str(err.value)
    # offsets may not turn a glossy shape into a mirror
    with pytest.raises(ValidationError, match="leaves the roughness"):
        load_scene(dict(_glossy_floor(), offsets={"ground.roughness": -0.15}))
    # the command line: one line, exit 2
    mirror = _glossy_floor()
    mirror["shapes"][0]["roughness"] = 0.0
    path = tmp_path / "mirror.json"
    path.write_text(json.dumps(mirror))
    assert main(["render", str(path), "--spp", "1", "--out", str(tmp_path)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "shapes[0].roughness" in lines[0] and "perfect mirror" in lines[0]
    # the gradient verb lists the parameter
    assert main(["gradient", "glossy_reflection", "--out", str(tmp_path)]) == 2
    assert "ground.roughness" in capsys.readouterr().err


@pytest.mark.parametrize("depth", sweep(DEPTHS, [1, 3]))
def test02_the_mixed_path_code_is_the_diffuse_one_on_diffuse_vertices(depth):
    """hard_shadow with a glossy square under its ground, facing down, which no ray meets: its images
    go through :class:`~sphere3d.paths.MixedPaths` and equal hard_shadow's (:class:`~sphere3d.paths.Paths`,
    or direct light at depth 1) to rounding (the throughput's products are grouped differently)."""
    plain = load_scene("hard_shadow").to_dict()
    plain["camera"].update(width=16, height=16)
    hidden = json.loads(json.dumps(plain))
    hidden["shapes"].append(
        {"name": "under", "type": "rectangle", "size": [0.5, 0.5], "translate": [0.0, 0.0, -1.0],
         "rotate": [np.pi, 0.0, 0.0], "roughness": 0.3, "albedo": 0.8}
    )  # fmt: skip
    for method in ("naive", "finite_difference"):
        a = render_gradient(plain, "occluder.translate.x", method, spp=8, seed=5, max_depth=depth)
        b = render_gradient(hidden, "occluder.translate.x", method, spp=8, seed=5, max_depth=depth)
        assert np.max(a.value) > 0.1
        np.testing.assert_allclose(b.value, a.value, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(
            b.derivative, a.derivative, rtol=1e-9, atol=1e-12 * np.max(np.abs(a.derivative))
        )


def test03_a_glossy_point_under_an_area_light_against_quadrature():
    """Two floor points seen from hard_shadow's camera: one in the light's highlight, one in the lobe's
    tail (F = 0.9, α = 0.15 and 0.4)."""
    cases = [((0.2, -1.5, 0.0), 0.15), ((1.2, -0.4, 0.0), 0.4)]
    camera = np.array([0.6, -3.6, 2.6])
    centre, le = np.array([-0.4, 0.2, 2.5]), 20.0
    estimates, references = [], []
    for i, (x, alpha) in enumerate(cases):
        state = build_state(load_scene(_glossy_floor(alpha)))
        wi = camera - np.asarray(x)
        shading, wi_n, u = _points(state, x, wi, seed=11 + i)
        albedo = np.full(N, 0.9)
        g = glossy_samples(shading, wi_n, u, np.full(N, alpha), albedo)
        estimates.append(_mean(g.radiance))
        point = np.asarray(x)

        def integrand(b, a, x=point, w=wi_n[0], alpha=alpha):
            y = centre + np.array([a, b, 0.0])
            to = y - x
            d2 = to @ to
            wo = to / np.sqrt(d2)
            return le * _ggx_textbook(w, wo, alpha, 0.9) * wo[2] * wo[2] / d2  # cos_x = cos_y = wo_z

        value, err = integrate.dblquad(integrand, -0.5, 0.5, -0.5, 0.5, epsabs=1e-9, epsrel=1e-8)
        assert err < 1e-6
        references.append(value)
    q = family_quantile(len(cases), 1.0 - ALPHA)
    for (mean, se), ref in zip(estimates, references, strict=True):
        assert ref > 0.05 and se > 0.0
        assert abs(mean - ref) <= q * se, (mean, ref, se)


def test04_white_furnace_the_glossy_albedo_and_its_roughness_derivative():
    """Under a uniform sky of radiance 1 (no emitter) $L_r(w_i) = A(θ_i)$, the directional albedo; its
    forward-mode α-derivative against the quadrature's central difference; every sample at most F, and
    the throughput a path would carry on equal to :func:`~sphere3d.bsdf.weight_ggx`."""
    cosines, alpha, f = (0.05, 0.3, 0.7, 1.0), 0.5, 0.8
    scene = load_scene(_glossy_floor(alpha, f, sky=1.0, light=False))
    state = build_state(scene, "ground.roughness", variable(0.0))
    estimates, references = [], []
    for i, c in enumerate(cosines):
        wi = (np.sqrt(1.0 - c * c), 0.0, c)
        shading, wi_n, u = _points(state, (0.1, 0.2, 0.0), wi, seed=21 + i)
        rows = np.zeros(N, dtype=np.intp)
        g = glossy_samples(shading, wi_n, u, state.roughness[rows], state.albedo[rows])
        value = np.asarray(g.radiance.value)
        assert np.all(value <= f * (1.0 + 1e-12))  # weight_ggx <= F: each sample's energy at most F
        # a path's throughput at the vertex: f cos / p = F G2 / G1 (weight_ggx's closed form), 0 below
        weight = weight_ggx(wi_n, g.mu, np.array([0.0, 0.0, 1.0]), alpha, f)
        np.testing.assert_allclose(g.throughput.value, weight, rtol=1e-10, atol=1e-14)
        assert np.array_equal(g.above, weight > 0.0)
        estimates += [_mean(value), _mean(tangent(g.radiance))]
        h = 1e-4  # the quadrature converges geometrically (nodes 24): its difference is exact to ~1e-8
        slope = (albedo_ggx(c, alpha + h, f, nodes=24) - albedo_ggx(c, alpha - h, f, nodes=24)) / (2 * h)
        references += [float(albedo_ggx(c, alpha, f, nodes=24)), float(slope)]
    q = family_quantile(len(estimates), 1.0 - ALPHA)
    for (mean, se), ref in zip(estimates, references, strict=True):
        assert se > 0.0
        assert abs(mean - ref) <= q * se, (mean, ref, se)
    assert references[0] < 0.95 * f  # at grazing incidence a single-scattering lobe loses energy


def _task(scene, param, spp: int, seed: int, depth: int, width: int = 24) -> ImageTask:
    d = load_scene(scene).to_dict()
    d["camera"].update(width=width, height=width)
    return ImageTask(load_scene(d), param, spp, seed, BATCHES, film="pixel", max_depth=depth)


def test05_furnace_images_and_the_roughness_derivative_of_the_image():
    """The furnace's floor cannot see itself: every BSDF sample escapes to the sky, so depth 4 is depth 1
    bit for bit. The floor's image is smooth in α (a uniform sky: nothing moves but the lobe), so the
    central difference of the primal (common random numbers, h = 1e-3) and the naive derivative estimate
    the same derivative: their per-batch difference over the floor is noise about 0."""
    one, four = render("furnace", spp=4, seed=3), render("furnace", spp=4, seed=3, max_depth=4)
    assert np.array_equal(one.value, four.value)
    task = _task("furnace", "floor.roughness", 128, 8, 2, width=16)
    naive = GRADIENT_METHODS.run("naive", task)
    fd = GRADIENT_METHODS.run("finite_difference", task, h=1e-3)
    per_batch = (naive.derivative - fd.derivative).reshape(BATCHES, -1).mean(axis=1)
    level = naive.derivative.mean()
    mean, se = _mean(per_batch)
    q = family_quantile(1, 1.0 - ALPHA, dof=BATCHES - 1)
    assert level < -0.05 and se > 0.0  # rougher loses more energy towards the camera; not a vacuous 0
    assert abs(mean) <= q * se, (mean, se, level)


@pytest.mark.parametrize(
    ("scene", "depth"), sweep([(s, d) for s in ("glossy_reflection", "interreflection") for d in DEPTHS],
                             [("glossy_reflection", 2), ("interreflection", 3)])
)  # fmt: skip
def test06_affine_in_the_emission_naive_is_finite_differences(scene, depth):
    """Every path's contribution holds the one emitter's radiance once, and no sample or MIS weight
    depends on it: the image is affine in ``light.emission`` sample by sample, so the central
    difference is exact but for rounding, and so must naive be."""
    task = _task(scene, "light.emission", 16, 4, depth, width=12)
    naive = GRADIENT_METHODS.run("naive", task)
    fd = GRADIENT_METHODS.run("finite_difference", task)
    assert np.array_equal(naive.value, fd.value)
    scale = np.max(np.abs(naive.derivative))
    assert scale > 0.01
    np.testing.assert_allclose(naive.derivative, fd.derivative, rtol=0.0, atol=1e-9 * max(1.0, scale))


@pytest.mark.parametrize(
    ("scene", "depth"), sweep([(s, d) for s in ("glossy_reflection", "interreflection") for d in DEPTHS],
                             [("glossy_reflection", 4), ("interreflection", 2)])
)  # fmt: skip
def test07_naive_misses_the_moving_shadow_at_every_depth(scene, depth):
    """The occluder moves along +x: its shadow on the floor (direct, and at depth > 1 also seen in the
    glossy floor or lit by the walls) brightens on the trailing side and darkens on the leading one.
    The change is visibility only (the light's points appear from behind the occluder's silhouette), a
    boundary term naive does not have: per batch, trailing minus leading sum of the derivative is far
    from finite differences' (a bias of many standard errors; naive's is near 0). The two methods run
    on different seeds, so their batches are independent."""
    width = 32
    d = load_scene(scene).to_dict()
    d["camera"].update(width=width, height=width)
    loaded = load_scene(d)
    trailing, leading = shadow_halves(loaded, width)
    assert trailing.sum() >= 8 and leading.sum() >= 8
    stats = {}
    for method, seed in (("naive", 1), ("finite_difference", 2)):
        task = ImageTask(loaded, "occluder.translate.x", 128, seed, BATCHES, film="pixel", max_depth=depth)
        g = GRADIENT_METHODS.run(method, task).derivative
        stats[method] = _mean(g[:, trailing].sum(axis=1) - g[:, leading].sum(axis=1))
    (naive, se_n), (fd, se_fd) = stats["naive"], stats["finite_difference"]
    se = np.hypot(se_n, se_fd)
    q = family_quantile(len(DEPTHS) * 2, 1.0 - ALPHA, dof=BATCHES - 1)
    assert fd > q * se_fd  # the reference sees the shadow move
    assert fd - naive > q * se, (naive, fd, se)  # naive's bias: the missing boundary term
    assert abs(naive) < 0.1 * fd  # naive has (almost) nothing here


def test08_reparam_refuses_paired_samples_on_glossy_shapes():
    # its paired kernel samples assume cosine-sampled centres (boundary's glossy paths:
    # tests/sphere3d/test_path_boundary.py, reparam's: test_path_reparam.py)
    with pytest.raises(ValidationError) as err:
        render_gradient(_task_scene(), "occluder.translate.x", "reparam", spp=4, paired=True)
    assert err.value.field == "paired" and "glossy" in str(err.value)


def _glossy_floor_regions(width: int) -> tuple:
    """``glossy_reflection`` on a ``width``-pixel film and its regions (:func:`regions_of`), each of at
    least 8 pixels."""
    d = load_scene("glossy_reflection").to_dict()
    d["camera"].update(width=width, height=width)
    scene = load_scene(d)
    regions = regions_of(scene, width)
    assert all(r.sum() >= 8 for r in regions.values())
    return scene, regions


def test09_boundary_against_finite_differences_by_region_on_the_glossy_floor():
    """``glossy_reflection`` at depth 1, the occluder's x-translation: the boundary method (its edge terms
    at glossy points weighted by the BSDF at the edge direction, the film's edges shaded by their
    material) and finite differences agree, region by region (the shadow's trailing and leading
    halves, the occluder's reflection, the occluder itself), within the noise of both; naive misses
    the shadow (0 there)."""
    scene, regions = _glossy_floor_regions(32)
    sums = {}
    for method, seed in (("boundary", 1), ("finite_difference", 2), ("naive", 3)):
        task = ImageTask(scene, "occluder.translate.x", 128, seed, BATCHES, film="pixel")
        g = GRADIENT_METHODS.run(method, task).derivative
        sums[method] = {name: _mean(g[:, r].sum(axis=1)) for name, r in regions.items()}
    q = family_quantile(len(regions), 1.0 - ALPHA, dof=BATCHES - 1)
    for name in regions:
        (b, se_b), (fd, se_fd) = sums["boundary"][name], sums["finite_difference"][name]
        assert se_b > 0.0 and se_fd > 0.0
        assert abs(b - fd) <= q * np.hypot(se_b, se_fd), (name, b, fd, se_b, se_fd)
    assert sums["finite_difference"]["trailing"][0] > 10.0 and sums["finite_difference"]["leading"][0] < -5.0
    assert sums["naive"]["trailing"] == (0.0, 0.0) and sums["naive"]["leading"] == (0.0, 0.0)


def test10_reparam_against_finite_differences_and_boundary_by_region_on_the_glossy_floor():
    """``glossy_reflection`` at depth 1, the occluder's x-translation: ``reparam`` (the emitter rotation and
    the vMF kernel of the BSDF-sampled integral applied to the glossy integrand; the emitters' edge term
    with the BSDF) against finite differences and against ``boundary`` (itself against finite
    differences, test09, and far less noisy), region by region, Šidák over the 2 x 4 comparisons: every
    region within noise, the shadow's leading half too (where the emitter rotation alone left about 5 %,
    before the emitter field kept every shadow edge the probes find, sphere3d.reparam.emitter_field)."""
    scene, regions = _glossy_floor_regions(32)
    sums = {}
    for method, seed in (("reparam", 1), ("boundary", 4), ("finite_difference", 5)):
        g = GRADIENT_METHODS.run(
            method, ImageTask(scene, "occluder.translate.x", 512, seed, BATCHES)
        ).derivative
        sums[method] = {name: _mean(g[:, r].sum(axis=1)) for name, r in regions.items()}
    q = family_quantile(2 * len(regions), 1.0 - ALPHA, dof=BATCHES - 1)
    for reference in ("boundary", "finite_difference"):
        for name in regions:
            (r, se_r), (b, se_b) = sums["reparam"][name], sums[reference][name]
            assert se_r > 0.0 and se_b > 0.0
            assert abs(r - b) <= q * np.hypot(se_r, se_b), (reference, name, r, b, se_r, se_b)


def _task_scene() -> dict:
    d = load_scene("glossy_reflection").to_dict()
    d["camera"].update(width=8, height=8)
    return d


def test11_the_optimiser_keeps_a_glossy_shape_rough():
    """sphere3d.optimize's default bounds on a roughness offset keep α in [MIN_ROUGHNESS, 1] (a mirror,
    α = 0, would be refused mid-run), from the scene's own offsets on."""
    from sphere3d.optimize import MIN_ROUGHNESS, _bounds

    scene = load_scene(dict(load_scene("furnace").to_dict(), offsets={"floor.roughness": 0.1}))
    lower, upper = _bounds(scene, ("floor.roughness", "floor.albedo"), None)
    np.testing.assert_allclose(lower, [MIN_ROUGHNESS - 0.6, -1.0])
    np.testing.assert_allclose(upper, [1.0 - 0.6, 0.0])


def test12_a_glossy_vertex_beyond_the_first_against_the_albedo_quadrature():
    r"""A glossy vertex reached by a path (its $w_i = -μ$, towards the previous vertex): the irradiance at a
    point 0.01 above a 40 x 40 glossy floor (α = 0.5, F = 0.8), facing it, under a uniform sky of
    radiance S = 1. Every direction of the lower hemisphere meets the floor (but beyond 89.97°), which
    reflects $S A(c)$ towards the point, c the cosine at the floor, so with one further vertex

    $E_2 = ∫ S A(c) c\, dω = 2π S ∫_0^1 A(c)\, c\, dc$

    (Gauss-Legendre in c over :func:`~sphere3d.bsdf.albedo_ggx`; the floor's edge changes it by
    $< 10^{-6}$ relative). At depth 1 only the sky beyond the edge is seen ($E_1 < 10^{-6}$); at depth 3 the
    floor's samples escape to the sky: $E_3 = E_2$ bit for bit."""
    floor = {"name": "floor", "type": "rectangle", "size": [40.0, 40.0], "albedo": 0.8, "roughness": 0.5}
    camera = load_scene("furnace").to_dict()["camera"]
    scene = {"name": "under", "camera": camera, "sky": 1.0, "shapes": [floor]}
    at = dict(point=(0.0, 0.0, 0.01), normal=(0.0, 0.0, -1.0), n=2**16, seed=3, batches=BATCHES)
    c, w = np.polynomial.legendre.leggauss(64)
    c, w = 0.5 * (c + 1.0), 0.5 * w
    reference = 2.0 * np.pi * float(np.sum(w * c * albedo_ggx(c, 0.5, 0.8, nodes=16)))
    e1, e2, e3 = (irradiance(scene, max_depth=d, **at) for d in (1, 2, 3))
    assert e1.value < 1e-6 * reference
    assert e2.value == e3.value and e2.value_stderr > 0.0
    q = family_quantile(1, 1.0 - ALPHA, dof=BATCHES - 1)
    assert abs(e2.value - reference) <= q * e2.value_stderr, (e2.value, reference, e2.value_stderr)
    assert reference < 0.8 * np.pi  # below F π: the lobe loses energy (the test sees A, not F)
