"""Film splatting (:mod:`sphere3d.film`, the default film), per pixel, against the closed-form triangle image.

Every camera sample contributes ``k(s - p) / q(s) · L`` to each pixel p its filter covers,
``q`` the pooled density of the pixels' samplers, with the control variate of
:meth:`sphere3d.tasks.ImageTask._splat_chunk`. The scene is
:func:`sphere3d.closed_form.pinhole_triangle_scene` (a black 8 px triangle against the sky,
16 × 16 pixels) moving sideways; :class:`FollowPlane` (the rotation following the triangle's
plane, ``test_control_variate``) gives the derivative the film's term, whose expectation is
the closed form's derivative to < 1 % (``test_control_variate``), far below the resolution here.

Per-pixel tests: |estimate - exact| <= q · stderr + 1e-12 for every pixel of the silhouette
(:func:`_outside`), q the two-sided Student-t quantile (batches - 1 degrees of freedom) at the
Šidák level over those pixels, α = 1e-3 (1e-12: rounding). Seeds are fixed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

import sphere3d as s3
from flatland.core.dual import Dual
from flatland.core.stats import sidak
from flatland.core.validate import ValidationError
from sphere3d import closed_form as cf
from sphere3d import execution, tasks
from sphere3d.methods import GRADIENT_METHODS
from sphere3d.tasks import ImageTask
from tests.sphere3d.helpers import FollowPlane, over_batches

ALPHA = 1e-3
BATCHES = 16
ROUNDING = 1e-12
HITS = 16
PARAM = "tri.translate.x"


def _scene(kind="gaussian"):
    return cf.pinhole_triangle_scene(8, 16, kind)


def _task(spp, seed, film="splat", kind="gaussian", scope="pixel"):
    return ImageTask(s3.load_scene(_scene(kind)), PARAM, spp, seed, BATCHES, cv_scope=scope, film=film)


def _outside(batches, exact, coverage, spp):
    """Tested pixels whose batch mean is off the closed form by more than the Šidák-corrected interval.

    Tested: the pixels where the triangle and the sky each expect at least HITS = 16 samples
    (spp · min(c, 1 - c) >= 16, c the filter mass on the triangle), as test03 of
    ``test_control_variate``; elsewhere a hit is a rare event (a pixel 1e-10 of whose filter
    covers the triangle has no hit in 4096 samples) and the batch spread no guide.
    """
    g, se = batches.mean(axis=0), batches.std(axis=0, ddof=1) / math.sqrt(BATCHES)
    tested = spp * np.minimum(coverage, 1.0 - coverage) >= HITS
    assert tested.sum() >= 20  # the silhouette's pixels
    q = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, int(tested.sum())), BATCHES - 1)
    return np.flatnonzero(tested & (np.abs(g - exact) > q * se + ROUNDING))


def test01_a_bad_film_is_refused():
    with pytest.raises(ValidationError, match="film"):
        _task(16, 1, film="mitsuba")
    with pytest.raises(ValidationError, match="film"):
        s3.render(_scene(), spp=1, film=None)


@pytest.mark.parametrize("kind", ["gaussian", "tent"])
def test02_splatted_primal_is_unbiased_in_every_pixel(kind):
    """256 spp in 16 batches: every pixel within its interval of L (1 - ∫_T k)."""
    value = _task(256, 5, kind=kind).evaluate(0.0).value
    image = cf.triangle_image(_scene(kind))
    assert _outside(value, image.value, image.coverage, 256).size == 0


@pytest.mark.parametrize("scope", ["pixel", "batch", "off"])
def test03_splatted_derivative_is_unbiased_in_every_pixel(scope):
    """256 spp: the derivative under :class:`FollowPlane`, with each control variate and without."""
    d = _task(256, 6, scope=scope).evaluate(Dual(0.0, 1.0), FollowPlane()).derivative
    image = cf.triangle_image(_scene(), PARAM)
    assert _outside(d, image.derivative, image.coverage, 256).size == 0


def test04_splatting_lowers_the_derivatives_error():
    """Same seed, 16 spp in 16 batches: the squared error against the closed form, splat below pixel.

    Statistic, per batch b (one sample per pixel; batch b of both films holds the same samples, a
    pair): D_b = mean_p [(pixel_bp - I'_p)² - (splat_bp - I'_p)²], and its mean over the batches with
    the standard error of their spread (:func:`~tests.sphere3d.helpers.over_batches`: the splatted
    film correlates the pixels of a batch, not the batches); asserted mean > t_{1-α}(15) · se
    (one-sided, α = 1e-3). Both films are unbiased per pixel (test02, test03), so E[D_b] is the
    difference of the per-batch variances, 16 times that of the 16-spp images' squared errors.
    Measured (seed 4, tested): mean 10.7 ± 1.8, t 5.95 (seeds 1-12: t 5.6-8.7). The 16-spp images'
    D itself, with the jackknife's standard error over the batch pairs, has less power (0.66 ± 0.18,
    t 3.6; seeds 1-12: 0.48-0.89 ± 0.14-0.36, t 2.0-3.8): its cross-batch products add noise.
    RMSE of the 16-spp images (seeds 4, 5, 6): 0.87, 0.89, 0.75 (pixel) against 0.31, 0.33, 0.19.
    """
    exact = cf.triangle_image(_scene(), PARAM).derivative
    pixel, splat = (
        _task(16, 4, film=film).evaluate(Dual(0.0, 1.0), FollowPlane()).derivative
        for film in ("pixel", "splat")
    )
    d, se = over_batches(np.mean((pixel - exact) ** 2 - (splat - exact) ** 2, axis=(1, 2)))
    limit = stats.t.ppf(1.0 - ALPHA, BATCHES - 1)
    print(f"D = {d:.3f} +- {se:.3f}, t {d / se:.2f} > {limit:.2f}")
    assert d > limit * se, (d, se)


def test05_every_method_sees_the_same_splatted_value():
    """Every method shares the primal bit for bit, as without splatting, and so does the plain render."""
    task = _task(16, 7)
    values = [
        GRADIENT_METHODS.run(m, task).value for m in ("naive", "reparam", "finite_difference", "boundary")
    ]
    assert all(np.array_equal(values[0], v) for v in values[1:])
    assert np.array_equal(values[0], task.evaluate(0.0).value)


def test06_the_image_does_not_depend_on_chunks_or_threads(monkeypatch):
    """Samples near a chunk's pixels splat into other chunks' pixels: the sums run in a fixed order."""
    task = _task(16, 8)
    whole = GRADIENT_METHODS.run("reparam", task)
    monkeypatch.setattr(tasks, "CHUNK", 16 * 5)  # 5 pixels per chunk: chunks end mid-row
    monkeypatch.setattr(execution, "WORKERS", 1)
    parts = GRADIENT_METHODS.run("reparam", task)
    assert np.array_equal(whole.value, parts.value) and np.array_equal(whole.derivative, parts.derivative)


def test07_box_filter_splats_nowhere_else():
    """The box filter covers its own pixel only (q = k = 1): splatting changes nothing, bit for bit."""
    pixel, splat = (
        GRADIENT_METHODS.run("naive", _task(16, 9, film=f, kind="box")) for f in ("pixel", "splat")
    )
    assert np.array_equal(pixel.value, splat.value) and np.array_equal(pixel.derivative, splat.derivative)


def test08_the_film_sums_standard_error_is_the_spread_of_the_batches_sums():
    """A splatted render's film sums carry std(ddof=1) / sqrt(batches) of the per-batch sums.

    ``shadow`` at 12 × 12 pixels, ``reparam``, 16 spp in 16 batches: the per-batch images come from
    the task itself (the same samples: the render's means are theirs bit for bit), their sums' spread
    is the render's film-sum standard error to rounding (rel 1e-12). The splatted film correlates
    neighbouring pixels, so the pixels' standard errors in quadrature are too small: measured for the
    derivative's sum, seeds 1-8, 1.1-1.9 × (mean 1.6; seed 3: 1.21 ×, which fails the equality here).
    """
    d = s3.load_scene("shadow").to_dict()
    d["camera"].update(width=12, height=12)
    g = s3.render_gradient(d, "occluder.translate.x", method="reparam", spp=16, seed=3)
    tally = GRADIENT_METHODS.run("reparam", ImageTask(s3.load_scene(d), "occluder.translate.x", 16, 3, 16))
    assert np.array_equal(tally.derivative.mean(axis=0), g.derivative) and g.batches == 16
    for of, per_batch in (("value", tally.value), ("derivative", tally.derivative)):
        sums = per_batch.sum(axis=(1, 2))
        s = g.film_sum(of)
        assert s.from_batches and s.total == pytest.approx(sums.mean(), rel=1e-12)
        assert s.stderr == pytest.approx(sums.std(ddof=1) / math.sqrt(16), rel=1e-12)
    quadrature = math.sqrt(np.sum(g.derivative_stderr**2))
    print(f"film sum {g.film_sum().total:+.3f} ± {g.film_sum().stderr:.3f}, quadrature {quadrature:.3f}")
