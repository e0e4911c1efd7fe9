"""Moving silhouettes and static edges in one film kernel (:mod:`sphere3d.reparam.junctions`).

The closed form of :mod:`sphere3d.closed_form.junction` (a black triangle moving in front of a
static black triangle under the sky, :func:`~sphere3d.closed_form.junction_scene`) first checks
itself: the clipping against a polygon computed by hand, on Duals, and the derivative against
central differences of its own value. Then ``reparam`` against it, pixel by pixel: with the
junctions followed (the default: the affine map keeping both lines) every pixel lies within its
Šidák-corrected Student-t interval; without them (``ReparamTransforms(film_junctions=False)``) a
film kernel at a junction follows one of the two edges: the static one (the identity, which loses
the silhouette's term there) or the moving silhouette (which drags the static edge with it), and
significantly more of the derivative is lost than with them, paired per batch. Where no static edge
crosses a moving silhouette (one triangle under the sky) the option changes nothing, bit for bit.
Where the moving silhouette's corner lies on the static edge
(:func:`~sphere3d.closed_form.corner_junction_scene`, at heights from 0.3 px under it to 0.05 px
above, under five motions), every pixel within its interval with the field keeping the corner's edges
and the static one (:mod:`sphere3d.reparam.corner_lines`), not with the corner's fan alone.
boundary's own film term is unbiased at the junction, pixel by pixel (its side rays'
extrapolation). A silhouette running nearly parallel to the static edge with a thin sliver of sky
between (:func:`~sphere3d.closed_form.sliver_scene`), where the lines cross far off the film: every
pixel within its interval with the map, not without.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
from scipy import stats

import sphere3d as s3
from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.image import summarize_batches
from flatland.core.stats import sidak
from sphere3d import closed_form as cf
from sphere3d.boundary.camera import camera_edge_term
from sphere3d.boundary.edges import mesh_edges
from sphere3d.methods.boundary import RATE, SECONDARY, boundary
from sphere3d.reparam.default import ReparamTransforms
from sphere3d.state import build_state
from sphere3d.tasks import ImageTask
from tests.sphere3d.helpers import over_batches
from tests.tiers import SLOW, sweep

ALPHA = 1e-3
BATCHES = 16
MOTIONS = {"sideways": "tri.translate.x", "depth": "tri.translate.z"}
SPP = 2048


def test01_clipping_on_duals_gives_the_area_and_its_derivative():
    # the unit square [θ, 1 + θ] x [0, 1] clipped by a triangle whose right edge is x = 0.5 and which
    # covers the square's left half: [θ, 0.5] x [0, 1], area 0.5 - θ, derivative -1 (its left edge moves)
    theta = variable(0.0)
    square = [(theta, 0.0), (1.0 + theta, 0.0), (1.0 + theta, 1.0), (theta, 1.0)]
    clip = np.array([[0.5, -10.0], [0.5, 10.0], [-20.0, 0.0]])
    out = cf.clip_convex(square, clip)
    x = [p[0] if isinstance(p[0], Dual) else Dual(np.float64(p[0])) for p in out]
    y = [p[1] if isinstance(p[1], Dual) else Dual(np.float64(p[1])) for p in out]
    area = 0.5 * sum(x[k - 1] * y[k] - x[k] * y[k - 1] for k in range(len(out)))  # shoelace, on Duals
    assert len(out) == 4 and abs(float(detach(area))) == pytest.approx(0.5, abs=1e-15)
    assert float(tangent(area)) * np.sign(float(detach(area))) == pytest.approx(-1.0, abs=1e-15)
    assert cf.clip_convex(square, clip - [30.0, 0.0]) == []  # disjoint: nothing left


@pytest.mark.parametrize("motion", list(MOTIONS))
def test02_the_closed_form_derivative_matches_central_differences_of_its_value(motion):
    # central differences of the closed form's own value at h = 1e-5: truncation h² f'''/6 and rounding
    # ε/h, both far below 1e-6 of the largest derivative (f''' is about f' over a pixel's width squared,
    # 0.1² world units: truncation about 2e-9 of f'; rounding 2e-11 in units of the image)
    scene = cf.junction_scene()
    exact = cf.junction_image(scene, MOTIONS[motion]).derivative
    axis = "xyz".index(MOTIONS[motion][-1])
    h = 1e-5

    def value(offset):
        moved = copy.deepcopy(scene)
        moved["shapes"][0]["translate"][axis] += offset
        return cf.junction_image(moved).value

    central = (value(h) - value(-h)) / (2.0 * h)
    assert np.abs(exact).max() > 0.3
    assert np.abs(central - exact).max() <= 1e-6 * np.abs(exact).max()


def _render(motion, junctions, spp=SPP, seed=1):
    scene = s3.load_scene(cf.junction_scene())
    task = ImageTask(scene, MOTIONS[motion], spp, seed, BATCHES)
    return task.evaluate(variable(0.0), ReparamTransforms(film_junctions=junctions)).derivative


@pytest.mark.parametrize("motion", sweep(MOTIONS, ["sideways"]))
@SLOW
def test03_reparam_matches_the_junction_closed_form_in_every_pixel(motion):
    # every pixel with spread within its Šidák-corrected Student-t interval (15 dof) of the exact
    # derivative; pixels without spread (no sample's kernel saw the moving triangle) exactly 0, and so
    # the exact derivative there below the filter's reach: beyond 1.5 px of every edge it is 0
    batches = _render(motion, True)
    exact = cf.junction_image(cf.junction_scene(), MOTIONS[motion]).derivative
    summary = summarize_batches(batches)
    mean, se = summary.mean, summary.stderr
    live = se > 0.0
    q = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, int(live.sum())), BATCHES - 1)
    z = (mean - exact)[live] / se[live]
    print(f"{motion}: max |z| {np.abs(z).max():.2f} <= {q:.2f} over {live.sum()} pixels")
    assert np.abs(z).max() <= q
    assert np.all(mean[~live] == 0.0) and np.abs(exact[~live]).max() < 1e-9


@pytest.mark.parametrize("motion", sweep(MOTIONS, ["sideways"]))
@SLOW
def test04_without_junctions_significantly_more_of_the_derivative_is_lost(motion):
    # Following the junction's crossing moves the kernel's film point with the silhouette's normal
    # speed and along the static edge: both edges held (test03). Without it, a kernel at a junction
    # either follows the wall (the identity: the silhouette's term in it is lost) or the triangle,
    # which drags the wall's edge by the triangle's film motion across it: nearly along it here (the
    # edge runs a few degrees off the horizontal, 0.4 px below the optical axis, about which the
    # depth motion scales the image), so the loss dominates. Share kept per batch b,
    # k_b = Σ sign(g) d_b / Σ |g| (closed_form.share_lost); the same seed for both, so batch b of
    # each holds the same samples: (1 - k_b) without junctions significantly positive, and
    # k_b(with) - k_b(without) significantly positive, one-sided Student-t (15 dof) at the Šidák
    # level over the 2 motions x 2 claims.
    exact = cf.junction_image(cf.junction_scene(), MOTIONS[motion]).derivative
    q = stats.t.ppf(1.0 - sidak(ALPHA, 4), BATCHES - 1)
    kept = {}
    for junctions in (True, False):
        d = _render(motion, junctions, seed=12)
        kept[junctions] = np.sum((np.sign(exact) * d).reshape(BATCHES, -1), axis=1) / np.sum(np.abs(exact))
    lost, lost_se = over_batches(1.0 - kept[False])
    gain, gain_se = over_batches(kept[True] - kept[False])
    print(
        f"{motion}: lost without {lost:.4f} +- {lost_se:.4f}, kept with - without {gain:.4f} +- {gain_se:.4f}"
    )
    assert lost > q * lost_se
    assert gain > q * gain_se


def test05_without_a_static_edge_the_junctions_change_nothing():
    # one triangle under the sky: no ring sees two static things, so the images are the same, bit for bit
    task = ImageTask(s3.load_scene(cf.pinhole_triangle_scene(6.0)), "tri.translate.x", 16, 5, 16)
    images = [task.evaluate(variable(0.0), ReparamTransforms(film_junctions=j)) for j in (True, False)]
    assert np.array_equal(images[0].derivative, images[1].derivative)
    assert np.array_equal(images[0].value, images[1].value)


CORNER_HEIGHTS = (0.3, 0.1, 0.01, -0.05)
CORNER_MOTIONS = ("tri.translate.y", "tri.scale", "tri.rotate.y", "tri.rotate.z", "tri.translate.z")


def _pixel_z(scene, motion, method, spp=SPP, **options):
    """Per pixel that every batch reaches: (mean - exact) / standard error over the batches; the pixels
    some batches do not reach (the filter's far tail, a few samples per image: batch means with a point
    mass at 0, far from normal, where the t interval does not hold) pooled into one more z of their sum;
    the Šidák-corrected two-sided Student-t quantile over these; the largest exact value (relative)
    where no batch has a sample."""
    exact = cf.junction_image(scene, motion).derivative
    task = ImageTask(s3.load_scene(scene), motion, spp, 1, BATCHES)
    if method == "reparam":
        d = task.evaluate(variable(0.0), ReparamTransforms(**options)).derivative
    else:
        d = boundary(task, rate=RATE, secondary=SECONDARY).derivative
    summary = summarize_batches(d)
    live, reached = np.all(d != 0.0, axis=0), np.any(d != 0.0, axis=0)
    z = (summary.mean - exact)[live] / summary.stderr[live]
    tail = reached & ~live
    if tail.any():
        pooled = summarize_batches(d[:, tail].sum(axis=1))
        z = np.append(z, (pooled.mean - exact[tail].sum()) / pooled.stderr)
    q = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, z.size), BATCHES - 1)
    return z, q, np.abs(exact[~reached]).max(initial=0.0) / np.abs(exact).max()


CORNER_CASES = [(h, m) for h in CORNER_HEIGHTS for m in CORNER_MOTIONS]


@pytest.mark.parametrize(
    ("below", "motion"), sweep(CORNER_CASES, [(0.1, "tri.translate.y"), (0.01, "tri.rotate.y")])
)
def test06_a_corner_on_the_static_edge_is_followed_in_every_pixel(below, motion):
    # The moving silhouette's corner ``below`` px under the static edge (above it where negative; as the
    # box of hard_shadow_cube's corner on the ground's far edge): the kernels there hold the corner's
    # edges and the static one, kept by one field (sphere3d.reparam.corner_lines). Pixel by pixel every
    # reparam estimate within its Šidák-corrected Student-t interval (15 dof), as boundary's (the
    # control, at one height); without the field (the corner's fan, which drags the static edge) some
    # pixel is not: the test can fail. Pixels no batch reaches: the filter's far tail, whose exact
    # derivative is below 1e-6 of the largest.
    scene = cf.corner_junction_scene(below)
    z, q, dead = _pixel_z(scene, motion, "reparam")
    z_off, _, _ = _pixel_z(scene, motion, "reparam", film_corner_lines=False)
    print(f"{below} px, {motion}: max |z| {np.abs(z).max():.2f} <= {q:.2f}; fan {np.abs(z_off).max():.1f}")
    assert np.abs(z).max() <= q and dead < 1e-6
    assert np.abs(z_off).max() > q
    if (below, motion) == (0.1, "tri.translate.y"):
        z_b, q_b, _ = _pixel_z(scene, motion, "boundary")
        assert np.abs(z_b).max() <= q_b


SLIVER_MOTIONS = ("tri.translate.y", "tri.scale", "tri.rotate.z", "tri.translate.z")


@pytest.mark.parametrize("motion", sweep(SLIVER_MOTIONS, ["tri.scale"]))
def test08_a_sliver_between_a_silhouette_and_a_static_edge_is_followed_in_every_pixel(motion):
    # A silhouette running 1 degree off the static edge, 0.3 px above it at the film's centre
    # (closed_form.sliver_scene): the kernels hold both lines, which cross far off the film, and the
    # probes mostly miss the sky between them. The affine map keeping both (reparam.junctions): every
    # pixel within its Šidák-corrected Student-t interval (15 dof); without it (the probes' rotation,
    # following the silhouette, drags the static edge) some pixel is not: the test can fail.
    scene = cf.sliver_scene(0.3, 1.0)
    z, q, dead = _pixel_z(scene, motion, "reparam", spp=1024)
    z_off, _, _ = _pixel_z(scene, motion, "reparam", spp=1024, film_junctions=False)
    print(f"{motion}: max |z| {np.abs(z).max():.2f} <= {q:.2f}; without the map {np.abs(z_off).max():.1f}")
    assert np.abs(z).max() <= q and dead < 1e-6
    assert np.abs(z_off).max() > q


@pytest.mark.parametrize("motion", sweep(MOTIONS, ["sideways"]))
def test07_boundary_s_film_term_is_unbiased_at_the_junction_in_every_pixel(motion):
    # At a T-junction the side ray beside the moving edge crosses the static edge within about δ / sin α
    # of the crossing; one pair of side rays is O(δ) off there (a whole jump wrong on that stretch, many
    # standard errors at this rate), the pairs at δ and 2δ extrapolated (sphere3d.boundary.camera) are
    # not. At 4 000 edge points per pixel of edge length every pixel's batches see the stretch many
    # times, so its error is a bias, not a rare event: every pixel within its Šidák-corrected t interval.
    scene = cf.junction_scene()
    param = MOTIONS[motion]
    loaded = s3.load_scene(scene)
    state, plain = build_state(loaded, param, variable(0.0)), build_state(loaded, param, 0.0)
    edges = mesh_edges(plain.triangles, plain.shape_of)
    exact = cf.junction_image(scene, param).derivative
    d = np.array([camera_edge_term(state, plain, edges, 1, b, 4000.0) for b in range(8)])
    mean, se = d.mean(axis=0), d.std(axis=0, ddof=1) / np.sqrt(len(d))
    tested = np.abs(exact) >= 0.01 * np.abs(exact).max()
    q = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, int(tested.sum())), len(d) - 1)
    z = (mean - exact)[tested] / se[tested]
    print(f"{motion}: max |z| {np.abs(z).max():.2f} <= {q:.2f}")
    assert np.abs(z).max() <= q
