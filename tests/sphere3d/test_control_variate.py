"""The filter-weight control variate of the pixel integral, per pixel, against the closed-form triangle image.

:meth:`sphere3d.tasks.ImageTask._control_variate` subtracts ``c_{-i} ẇ_i`` from each camera
sample's derivative, ``ẇ_i`` the tangent of its filter weight (zero mean given the pixel's
rotation, Loubet et al. 2019, Sec. 4.2) and ``c_{-i}`` the mean radiance of the pixel's other
samples: all of them (``cv_scope="pixel"``, the default) or those of the same batch
(``"batch"``, which is off at one sample per batch). With the per-pixel film (``film="pixel"``)
throughout: the splatted film's control variate (the default) is tested in ``test_film_splat``.

The scene is :func:`sphere3d.closed_form.pinhole_triangle_scene` (a black 8 px triangle against
the sky, 16 × 16 pixels) moving sideways, and the transform :class:`FollowPlane` gives every
camera sample the rotation that follows the triangle's plane point under it. The triangle's
image translates uniformly on the film while a rotation moves film x by (1 + x²) φ̇, so the
rotation follows the silhouette up to a relative 2 |x| Δx <= 2 · 0.1 · 0.04 = 0.8 % across a
footprint (|x| <= 0.1 at the triangle, Δx <= 1.5 px = 0.0375 in film units): the estimator's
expectation is the closed form's derivative to < 1 % of it, far below the resolution of these
tests (the per-pixel standard errors are >= 10 % of the largest |dI/dθ|).

Per-pixel tests: |estimate - exact| <= q · stderr for every pixel with spread, q the two-sided
Student-t quantile (batches - 1 degrees of freedom) at the Šidák level over the pixels,
α = 1e-3. Seeds are fixed.
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
from sphere3d.tasks import ImageTask
from tests.sphere3d.helpers import FollowPlane

ALPHA = 1e-3
BATCHES = 16
PARAM = "tri.translate.x"


def _task(spp, seed, scope):
    scene = s3.load_scene(cf.pinhole_triangle_scene(8, 16))
    return ImageTask(scene, PARAM, spp, seed, BATCHES, cv_scope=scope, film="pixel")


def _derivative(spp, seed, scope):
    """Per-batch derivative images (batches, 16, 16) under :class:`FollowPlane`."""
    return _task(spp, seed, scope).evaluate(Dual(0.0, 1.0), FollowPlane()).derivative


def _exact():
    return cf.triangle_image(cf.pinhole_triangle_scene(8, 16), PARAM).derivative


def test01_a_bad_scope_is_refused():
    with pytest.raises(ValidationError, match="cv_scope"):
        _task(16, 1, "all")


def test02_the_value_does_not_change_bit_for_bit():
    """The control variate subtracts an exact zero from the value, whatever its scope."""
    task = _task(32, 2, "pixel")
    values = [
        _task(32, 2, scope).evaluate(Dual(0.0, 1.0), FollowPlane()).value
        for scope in ("pixel", "batch", "off")
    ]
    assert np.array_equal(values[0], values[1]) and np.array_equal(values[0], values[2])
    assert np.array_equal(values[0], task.evaluate(0.0).value)


def test03_pooled_control_variate_is_unbiased_in_every_pixel():
    """256 spp: every pixel with spread within the Šidák-corrected Student-t interval of the closed form.

    Tested are the pixels where the triangle and the sky each expect at least HITS = 16 of
    the samples (spp · min(c, 1 - c) >= 16, c the filter mass on the triangle); elsewhere a
    hit is a rare event and the batch spread no guide (the same rule as test08 of
    test_triangle_closed_form). Pixels without spread have all samples on one side: their
    controlled derivative is exactly 0. Test05 covers every pixel, at one sample per batch.
    """
    spp, hits = 256, 16
    image = cf.triangle_image(cf.pinhole_triangle_scene(8, 16), PARAM)
    d = _derivative(spp, 3, "pixel")
    g, se = d.mean(axis=0), d.std(axis=0, ddof=1) / math.sqrt(BATCHES)
    tested = (spp * np.minimum(image.coverage, 1.0 - image.coverage) >= hits) & (se > 0.0)
    assert tested.sum() >= 20  # the silhouette's pixels
    q = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, int(tested.sum())), BATCHES - 1)
    assert np.all(np.abs(g - image.derivative)[tested] <= q * se[tested])
    assert np.all(g[se == 0.0] == 0.0)


def test04_pooled_control_variate_beats_the_per_batch_one_at_one_sample_per_batch():
    """Paired over pixels (independent samples), squared error against the closed form, same samples.

    At 16 spp in 16 batches the per-batch control variate has no other sample and is off; the
    pooled one uses the pixel's 15 others. d_p = err_batch² - err_pixel² per pixel; asserted:
    mean(d) > t_{1-α}(m - 1) · sd(d) / √m (one-sided paired t-test, α = 1e-3), and the
    per-batch estimate equals the uncontrolled one exactly.
    """
    exact = _exact()
    pooled, per_batch = (_derivative(16, 4, scope).mean(axis=0) for scope in ("pixel", "batch"))
    assert np.array_equal(per_batch, _derivative(16, 4, "off").mean(axis=0))
    d = ((per_batch - exact) ** 2 - (pooled - exact) ** 2).ravel()
    m = d.size
    assert d.mean() > stats.t.ppf(1.0 - ALPHA, m - 1) * d.std(ddof=1) / math.sqrt(m)


def test05_pooled_control_variate_is_unbiased_at_one_sample_per_batch_on_the_film():
    """16 spp in 16 batches, 128 seeds: the signed film error ``Σ_p sign(I'_p) (g_p - I'_p)`` has mean 0.

    The weights sign(I'_p) come from the closed form, not the data, so each seed's statistic is
    an unbiased estimate of 0 and the seeds are independent: two-sided Student-t test, 127
    degrees of freedom, α = 1e-3. Every pixel counts, rare events included. A coefficient that
    used the sample's own radiance would bias each pixel by -I'_p / spp (here L̇ = 0, so
    E[L ẇ] = I'): measured z = -3.8 and -3.5 with 32 seeds, about -7 with 128.
    """
    exact = _exact()
    sign = np.sign(exact)
    film = np.array(
        [np.sum(sign * (_derivative(16, seed, "pixel").mean(axis=0) - exact)) for seed in range(128)]
    )
    q = stats.t.ppf(1.0 - 0.5 * ALPHA, film.size - 1)
    assert abs(film.mean()) <= q * film.std(ddof=1) / math.sqrt(film.size)
