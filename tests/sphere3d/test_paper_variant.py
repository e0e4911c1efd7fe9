"""reparam's ``variant="paper"``, the estimator as published (:mod:`sphere3d.reparam.paper`): its value,
its probe rule, and the biases its derivation predicts, each against a closed form.

Statistics: z-scores of per-batch estimates (16 batches, Student t with 15 degrees of freedom), the
quantile at a family-wise level of 1e-3 with Šidák over the file's comparisons; fixed seeds. The
biases are tested by their sign and by the order of the two variants (paired per batch: the same
seed gives both variants the same camera and emitter samples), not by a measured size.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import sphere3d as s3
from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.rng import Draws
from flatland.core.stats import sidak
from flatland.core.validate import ValidationError
from sphere3d import closed_form as cf
from sphere3d.reparam.paper import PaperTransforms, choose, pair_index
from sphere3d.scene import load_scene
from sphere3d.state import build_state
from sphere3d.tasks import ImageTask, PointTask
from sphere3d.tracing import Hits
from tests.sphere3d.helpers import ORIGIN, UP, light_exact, light_scene

BATCHES = 16
COMPARISONS = 6
Q = float(stats.t.ppf(1.0 - 0.5 * sidak(1e-3, COMPARISONS), BATCHES - 1))


def _t(batches: np.ndarray) -> tuple[float, float]:
    """Mean and standard error of per-batch values."""
    return float(np.mean(batches)), float(np.std(batches, ddof=1) / np.sqrt(len(batches)))


def test01_the_value_is_naives_where_nothing_is_paired_and_unbiased_where_it_is():
    # a black triangle under the sky: no shading integral, so the paper variant's camera rotation (value
    # the identity) leaves the primal naive's, bit for bit
    scene = cf.pinhole_triangle_scene(6.0, 8)
    paper = s3.render_gradient(scene, "tri.translate.x", method="reparam", spp=16, seed=3, variant="paper")
    naive = s3.render_gradient(scene, "tri.translate.x", method="naive", spp=16, seed=3)
    assert np.array_equal(paper.value, naive.value)
    # the irradiance under the sky with a black triangle: paired kernel samples replace the cosine
    # sample (a different primal), still unbiased for Lambert's closed form
    sky = cf.sky_triangle_scene(np.array([[-0.2, -0.5, 1.0], [0.9, 0.1, 1.1], [0.1, 0.6, 0.9]]))
    value, _ = cf.occluded_sky_irradiance(load_scene(sky), ORIGIN, UP, "tri.translate.z")
    e = s3.irradiance(
        sky, ORIGIN, UP, "tri.translate.z", method="reparam", n=1 << 14, seed=4, variant="paper"
    )
    assert abs(e.value - value) <= Q * e.value_stderr


def test02_the_rule_pairs_probe_0_with_the_last_probe_that_sees_another_shape():
    shape = np.array([[3, 3, 5, 3, -1], [2, 2, 2, 2, 2], [-1, 4, 4, -1, -1]])
    assert pair_index(shape).tolist() == [4, 0, 2]
    assert pair_index(shape[:, :1]).tolist() == [0, 0, 0]  # one probe has no partner
    # a probe on the triangle and a miss beside it: only probe 0 hits, so its own hit is followed
    state = build_state(load_scene(cf.pinhole_triangle_scene(6.0, 8)), "tri.translate.x", variable(0.0))
    origin = detach(state.camera.origin)
    tri = np.asarray(detach(state.triangles))[0]
    inside = tri.mean(axis=0) - origin
    outside = inside + np.array([5.0, 0.0, 0.0])
    d = np.stack([inside, outside])[None] / np.linalg.norm(np.stack([inside, outside]), axis=1)[None, :, None]
    hits: Hits = state.tracer.intersect(origin, d)
    choice = choose(state, state.camera.origin, d, hits)
    assert (
        choice.found.tolist() == [True] and choice.single.tolist() == [0] and choice.first.tolist() == [True]
    )
    point = choice.point()
    np.testing.assert_allclose(detach(point)[0], tri.mean(axis=0), atol=1e-6)  # float32 barycentrics
    assert np.allclose(tangent(point)[0], [1.0, 0.0, 0.0])  # attached: it moves with the triangle


def _cosine_share(nodes: int = 64) -> float:
    r"""The cosine strategy's share of the edge term of :func:`light_scene`'s light moving in x.

    The light, $[0.2, 0.8] × [0, 0.4]$ at height $h = 1.5$ facing down, radiance $L$, above the
    origin (normal +z). $E = ∫_A F\, dA$ with $F = L h^2 / d^4$ ($\cos θ_x = \cos θ_y = h / d$); moving
    the light by θ in x moves A, and by Reynolds' rule $dE/dθ = ∫_{x=0.8} F\, dy - ∫_{x=0.2} F\, dy$.
    The balance heuristic splits F into $F w_C + F w_L$, $w_C = p_C / (p_C + p_L)$, $p_C = \cos θ_x / π$,
    $p_L = d^2 / (A \cos θ_y)$: the cosine strategy's share is the same difference with $F w_C$.
    """
    g, w = np.polynomial.legendre.leggauss(nodes)
    y, w = 0.2 + 0.2 * g, 0.2 * w
    h, area = 1.5, 0.6 * 0.4

    def edge(x: float, weighted: bool) -> float:
        d2 = x * x + y * y + h * h
        f = h * h / d2**2
        if weighted:
            p_c, p_l = (h / np.sqrt(d2)) / np.pi, d2 / (area * h / np.sqrt(d2))
            f = f * p_c / (p_c + p_l)
        return float(np.sum(w * f))

    return (edge(0.8, True) - edge(0.2, True)) / (edge(0.8, False) - edge(0.2, False))


def test03_the_published_emitter_rule_drags_a_sharp_lights_edges():
    """A 0.6 x 0.4 light, no fade, moving sideways above the point (closed form by quadrature). No
    probe is occluded, so the published emitter rotation is the identity and the emitter strategy
    keeps none of the light's edge term (its samples' directions stay put while the edges move); the
    cosine strategy's rotation follows the light where its probes hit it, so the paper variant keeps
    at most that strategy's share of the term (:func:`_cosine_share`, a few per cent: the light is
    small, emitter sampling dominates), and nothing negative. The default holds the edges by their
    boundary term and keeps all of it."""
    exact = float(tangent(light_exact(0.0)))
    share = _cosine_share()
    assert 0.0 < share < 0.1
    scene = s3.load_scene(light_scene(0.0))
    task = PointTask(scene, "light.translate.x", tuple(ORIGIN), tuple(UP), 1 << 14, 6, BATCHES)
    paper = s3.GRADIENT_METHODS.run("reparam", task, variant="paper").derivative
    default = s3.GRADIENT_METHODS.run("reparam", task).derivative
    kept, se = _t(paper / exact)
    assert -Q * se <= kept <= share + Q * se, (kept, se, share)
    kept_default, se_default = _t(default / exact)
    assert abs(kept_default - 1.0) <= Q * se_default, (kept_default, se_default)


def test04_probes_drawn_from_the_kernel_miss_edges_the_ring_finds():
    """A black 8 px triangle translating sideways under the sky (closed form). The film rotation of
    either variant follows a point of the triangle wherever its probes see the triangle and the
    sky: under a translation every point moves alike, so those kernels are exact. Kernels whose
    probes all land on one side keep the identity and drop the edge's term; probes drawn from the
    kernel do so with a probability that does not shrink with the samples, a ring around the centre
    rarely. So the paper variant loses a positive share of the derivative, significantly more than
    the default (per batch, the same samples)."""
    scene = load_scene(cf.pinhole_triangle_scene(8.0, 16))
    exact = cf.triangle_image(scene, "tri.translate.x").derivative
    task = ImageTask(scene, "tri.translate.x", 64, 5, BATCHES)
    paper = s3.GRADIENT_METHODS.run("reparam", task, variant="paper").derivative
    default = s3.GRADIENT_METHODS.run("reparam", task).derivative
    weight = np.sign(exact) / np.abs(exact).sum()
    lost = lambda d: 1.0 - np.sum(d * weight, axis=(1, 2))  # noqa: E731  (share lost, per batch)
    loss, se = _t(lost(paper))
    assert loss > Q * se, (loss, se)
    gap, se_gap = _t(lost(paper) - lost(default))
    assert gap > Q * se_gap, (gap, se_gap)


@pytest.mark.parametrize(
    ("options", "field"),
    [
        ({"spread": 2.0}, "spread"),
        ({"refine": 0}, "refine"),
        ({"paired": True}, "paired"),
        ({"kappa": None}, "kappa"),
    ],
)
def test05_options_of_the_default_variant_are_refused_by_the_paper_variant(options, field):
    with pytest.raises(ValidationError, match=f"^{field}: "):
        s3.render_gradient("shadow", "occluder.translate.x", spp=1, variant="paper", **options)
    with pytest.raises(ValidationError, match="variant"):
        s3.render_gradient("shadow", "occluder.translate.x", spp=1, variant="published")


def test06_the_paper_variant_rotations_are_the_identity_in_value():
    # every change of variables is the identity at θ0: Dual directions with the samples' values
    scene = load_scene(cf.pinhole_triangle_scene(6.0, 8))
    state = build_state(scene, "tri.translate.x", variable(0.0))
    rng = np.random.default_rng(2)
    x, y = rng.uniform(2.0, 6.0, 200), rng.uniform(2.0, 6.0, 200)
    film = PaperTransforms(1000.0, 12.5, 4, 4).camera(state, x, y, Draws.of(1, np.arange(200)))
    (rotation,) = film.rotations
    d = state.camera.directions(x, y)
    rotated = rotation.apply(d)
    assert isinstance(rotated, Dual) and np.array_equal(detach(rotated), d)
    assert 0 < rotation.active.sum() < 200  # some kernels see the triangle's edge, others do not
