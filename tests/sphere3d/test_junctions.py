"""T-junctions on the film: a moving silhouette across a static edge (:mod:`sphere3d.reparam.junctions`).

The closed form of :mod:`sphere3d.closed_form.junction` (a black triangle moving in front of a
static black triangle under the sky, :func:`~sphere3d.closed_form.junction_scene`) first checks
itself: the clipping against a polygon computed by hand, on Duals, and the derivative against
central differences of its own value. Then ``reparam`` against it, pixel by pixel: with the
junctions followed (the default) every pixel lies within its Šidák-corrected Student-t interval;
without them (``ReparamTransforms(film_junctions=False)``) the film kernels that follow the moving
silhouette drag
the static edge, and the share of the derivative lost is tested as a bias. Where no static edge
crosses a moving silhouette (one triangle under the sky) the option changes nothing, bit for bit.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from scipy import stats

import sphere3d as s3
from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.image import summarize_batches
from flatland.core.stats import sidak
from sphere3d import closed_form as cf
from sphere3d.reparam.default import ReparamTransforms
from sphere3d.tasks import ImageTask

ALPHA = 1e-3
BATCHES = 16
MOTIONS = {"sideways": "tri.translate.x", "depth": "tri.translate.z"}
SPP = 2048
LOST_WITHOUT = {"sideways": (4.20, 0.33), "depth": (13.17, 0.35)}
"""Share of the derivative lost without junctions, % ± one standard error (16384 spp, seed 11, 16
batches): the documented bias of :mod:`sphere3d.reparam.junctions`."""
LOST_WITH = {"sideways": (0.82, 0.29), "depth": (1.40, 0.33)}
"""The same with junctions: what the film kernel loses on a 6 px triangle anyway (its top corner,
:mod:`sphere3d.reparam.film_kernel`, Bias: 0.9-1.8 % for 4-8 px)."""


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
    # ε/h, both far below 1e-6 of the largest derivative (measured 3.5e-8 and 4e-11 of 6.7 and 0.4)
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


@pytest.mark.parametrize("motion", list(MOTIONS))
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


@pytest.mark.parametrize("motion", list(MOTIONS))
def test04_without_junctions_the_static_edge_is_dragged_a_documented_bias(motion):
    # share lost, 1 - Σ sign(g) d / Σ |g| (closed_form.share_lost), its standard error from the 16
    # batches: without junctions significantly positive (z > 4) and consistent with LOST_WITHOUT,
    # with them consistent with LOST_WITH, each within the two-sided Student-t quantile (15 dof) at the
    # Šidák level over the four checks
    exact = cf.junction_image(cf.junction_scene(), MOTIONS[motion]).derivative
    q = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, 4), BATCHES - 1)
    for junctions, documented in ((False, LOST_WITHOUT), (True, LOST_WITH)):
        lost = cf.share_lost(_render(motion, junctions, seed=12), exact)
        doc, doc_se = (v / 100.0 for v in documented[motion])
        print(f"{motion}, junctions {junctions}: {100 * lost.mean:.2f} +- {100 * lost.stderr:.2f} %")
        assert abs(lost.mean - doc) <= q * math.hypot(lost.stderr, doc_se)
        if not junctions:
            assert lost.mean / lost.stderr > 4.0


def test05_without_a_static_edge_the_junctions_change_nothing():
    # one triangle under the sky: no ring sees two static things, so the images are the same, bit for bit
    task = ImageTask(s3.load_scene(cf.pinhole_triangle_scene(6.0)), "tri.translate.x", 16, 5, 16)
    images = [task.evaluate(variable(0.0), ReparamTransforms(film_junctions=j)) for j in (True, False)]
    assert np.array_equal(images[0].derivative, images[1].derivative)
    assert np.array_equal(images[0].value, images[1].value)
