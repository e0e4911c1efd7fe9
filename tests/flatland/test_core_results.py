"""Named results built from independent batches: means, standard errors, batch counts."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from flatland.core.contract import Estimate
from flatland.core.image import GradientImage, Image, relative_error, resolve_batches, summarize_batches
from flatland.core.stats import ROUNDING, rounding_floor, spread, summarize, z_score


def test01_batch_summary_is_mean_and_std_over_sqrt_batches():
    per_batch = np.array([[1.0, 2.0], [3.0, 2.0], [5.0, 2.0], [7.0, 2.0]])
    s = summarize_batches(per_batch)
    np.testing.assert_array_equal(s.mean, [4.0, 2.0])
    # sample std (ddof=1) of 1, 3, 5, 7 is sqrt(20/3); divided by sqrt(4)
    np.testing.assert_allclose(s.stderr, [np.sqrt(20.0 / 3.0) / 2.0, 0.0])
    assert np.all(np.isinf(summarize_batches(per_batch[:1]).stderr))


def test02_images_and_estimates_from_batches():
    rng = np.random.default_rng(0)
    v, d = rng.normal(size=(8, 3, 5)), rng.normal(size=(8, 3, 5))
    img = Image.from_batches(v, spp=64, seed=1, scene="s")
    assert img.shape == (3, 5) and img.batches == 8 and img.spp == 64
    np.testing.assert_allclose(img.stderr, v.std(axis=0, ddof=1) / np.sqrt(8))
    g = GradientImage.from_batches(v, d, param="a.scale", method="naive", spp=64, seed=1, options={"h": 1})
    np.testing.assert_allclose(g.derivative, d.mean(axis=0))
    assert g.options["h"] == 1 and g.batches == 8
    with pytest.raises(TypeError):
        g.options["h"] = 2  # read-only
    e = Estimate.from_batches(v[:, 0, 0], d[:, 0, 0], n=64, method="naive")
    assert e.value == pytest.approx(v[:, 0, 0].mean()) and e.n == 64


def test03_default_batches_is_the_largest_divisor_up_to_16_and_bad_counts_name_the_field():
    assert resolve_batches(64, None) == 16
    assert resolve_batches(12, None) == 12
    assert resolve_batches(17, None) == 1
    assert resolve_batches(64, 4) == 4
    with pytest.raises(ValueError, match=r"^batches: must divide spp=10 \(equal batches\), got 4"):
        resolve_batches(10, 4)
    with pytest.raises(ValueError, match=r"^batches"):
        resolve_batches(10, 0)


def test04_relative_error_metric():
    ref = np.array([0.0, 2.0, -4.0])
    assert relative_error(ref, ref) == 0.0
    assert relative_error(ref + 1.0, ref) == pytest.approx(1.0 / 4.0)
    with pytest.raises(ValueError, match="all zero"):
        relative_error(ref, np.zeros(3))


def test05_estimate_interval_and_z_score_pick_value_or_derivative():
    e = Estimate(value=1.0, derivative=-2.0, value_stderr=0.5, derivative_stderr=0.25, n=10)
    assert e.z_score(2.0, of="value") == pytest.approx(-2.0)
    assert e.z_score(-1.0) == pytest.approx(-4.0)
    iv = e.interval(0.95)
    assert iv.contains(-2.0) and iv.high - iv.low == pytest.approx(2 * 1.959964 * 0.25, rel=1e-6)
    with pytest.raises(ValueError, match=r"^of"):
        e.interval(of="valu")


@given(
    value=st.floats(min_value=-1e12, max_value=1e12, allow_nan=False, allow_subnormal=False),
    n=st.integers(min_value=2, max_value=50_000),
)
def test05_identical_samples_have_exactly_zero_stderr_on_every_cpu(value, n):
    # the mean of n copies of a float need not be bit-equal to it (summation order and SIMD
    # width differ between CPUs): rounding-level spread goes through one policy, stats.spread
    samples = np.full(n, value)
    assert summarize(samples).stderr == 0.0
    assert np.all(summarize_batches(np.full((n % 17 + 2, 3), value)).stderr == 0.0)


def test06_spread_above_the_rounding_floor_is_kept():
    # the floor is ROUNDING * |scale|: a relative spread 10x above it is variance, one 10x below is not
    base = np.full(1000, 3.0)
    jitter = np.tile([-1.0, 1.0], 500)
    above = summarize(base + 10 * ROUNDING * 3.0 * jitter).stderr
    below = summarize(base + 0.1 * ROUNDING * 3.0 * jitter).stderr
    assert above > 0.0 and below == 0.0
    assert spread(np.array([1e-20, 1.0]), np.array([1.0, 1.0])).tolist() == [0.0, 1.0]
    assert rounding_floor(-2.0) == 2.0 * ROUNDING


def test07_a_zero_spread_estimate_is_exact_to_rounding_not_bit_for_bit():
    # the mean of identical samples may be an ulp off the closed form on some CPUs: z = 0, not inf
    value = -0.35206532676429952  # -K(0.5) of the step integral
    off_by_ulps = value + 4 * np.spacing(value)
    e = Estimate.from_batches(np.zeros(4), np.full(4, off_by_ulps), 64, "boundary", {})
    assert e.derivative_stderr == 0.0 and e.z_score(value) == 0.0
    assert z_score(value * (1 + 1e-9), value, 0.0) == -np.inf  # beyond rounding (value < 0): significant
    assert z_score(1.0, 3.0, 0.5) == -4.0


def test08_film_sum_stderr_comes_from_the_per_batch_sums():
    """Σ over the film's pixels, its standard error std(ddof=1) / sqrt(batches) of the per-batch sums.

    Perfectly correlated pixels (every pixel of a batch moves by the same z_b): the film sum's
    standard error is P s for P pixels of standard error s each, sqrt(P) times the quadrature
    sqrt(P) s. Independent normal pixels (B batches, P pixels, σ = 1): with A = (B - 1) S²_sum / P
    ~ χ²(B - 1) and the pixels' spread orthogonal to the all-ones direction W ~ χ²((P - 1)(B - 1)),
    independent of A, (se_batches / se_quadrature)² / P = A / (A + W) ~ Beta((B - 1) / 2,
    (P - 1)(B - 1) / 2) exactly: the check is that it lies in that law's central 1 - 1e-3 interval.
    """
    from scipy import stats

    rng = np.random.default_rng(8)
    b, shape = 16, (3, 5)
    p = int(np.prod(shape))
    offsets = rng.normal(size=shape)  # a fixed image, plus one shared deviation per batch
    correlated = offsets + rng.normal(size=(b, 1, 1))
    g = GradientImage.from_batches(correlated, correlated, param="a.scale", method="naive", spp=64, seed=1)
    quadrature = np.sqrt(np.sum(g.derivative_stderr**2))
    s = g.film_sum()
    assert s.from_batches and s.total == pytest.approx(correlated.mean(axis=0).sum(), rel=1e-14)
    assert s.stderr == pytest.approx(np.sqrt(p) * quadrature, rel=1e-12)
    assert g.film_sum("value").stderr == s.stderr == g.derivative_sum_stderr

    b, shape = 16, (40, 50)
    p = int(np.prod(shape))
    independent = rng.normal(size=(b, *shape))
    g = GradientImage.from_batches(independent, independent, param="a.scale", method="naive", spp=64, seed=1)
    ratio2 = (g.film_sum().stderr / np.sqrt(np.sum(g.derivative_stderr**2))) ** 2 / p
    low, high = stats.beta.ppf([0.0005, 0.9995], (b - 1) / 2, (p - 1) * (b - 1) / 2)
    print(f"(se_batches / se_quadrature)² / P = {ratio2:.3g} in [{low:.3g}, {high:.3g}]")
    assert low <= ratio2 <= high


def test09_a_film_sum_without_batches_is_the_quadrature_flagged_never_nan():
    """An image built by hand (no per-batch sums) adds its pixels' standard errors in quadrature,
    correct only for independent pixels, and says so (``from_batches`` False); one batch gives an
    infinite standard error; pixels with rounding-level spread give exactly 0 even when they cancel;
    a film sum pickles (study trials run in worker processes)."""
    import pickle

    d = np.array([1.0, -2.0, 4.0])
    g = GradientImage(d, d, np.full(3, 0.5), np.array([0.1, 0.2, 0.2]), "a.scale", "naive", 4, 0, 4)
    s = g.film_sum()
    assert (s.total, s.stderr, s.from_batches) == (3.0, pytest.approx(0.3, rel=1e-15), False)
    assert g.film_sum("value").stderr == pytest.approx(np.sqrt(3) * 0.5, rel=1e-15)
    with pytest.raises(ValueError, match=r"^of"):
        g.film_sum("values")
    one = GradientImage.from_batches(d[None], d[None], param="a.scale", method="naive", spp=4, seed=0)
    assert one.film_sum().stderr == np.inf and one.film_sum().from_batches
    # pixels ±1e3 constant over the batches up to ulps: a sum ~1e-13, its spread rounding at 1e3's scale
    ulps = np.array([[1e3, -1e3 + 1e-13]] * 8) + np.spacing(1e3) * (np.arange(8)[:, None] % 3)
    flat = GradientImage.from_batches(ulps, ulps, param="a.scale", method="naive", spp=8, seed=0)
    assert np.all(flat.derivative_stderr == 0.0) and flat.film_sum().stderr == 0.0
    assert pickle.loads(pickle.dumps(s)) == s


def test10_results_pickle_with_their_read_only_options():
    """An image and an estimate cross process boundaries (pickled) with their options intact; the
    options stay read-only and equal any mapping with the same items."""
    import pickle

    d = np.array([[1.0, -2.0], [4.0, 0.5]])
    g = GradientImage.from_batches(
        np.stack([d, d + 1.0]),
        np.stack([d, -d]),
        param="a.scale",
        method="reparam",
        spp=8,
        seed=3,
        options={"kappa": 100.0},
    )
    back = pickle.loads(pickle.dumps(g))
    assert back.options == {"kappa": 100.0} and type(back.options) is type(g.options)
    for f in ("value", "derivative", "value_stderr", "derivative_stderr"):
        assert np.array_equal(getattr(back, f), getattr(g, f))
    assert (back.param, back.method, back.spp, back.seed, back.batches) == ("a.scale", "reparam", 8, 3, 2)
    e = Estimate.from_batches([1.0, 2.0], [0.5, 0.7], n=2, method="naive", options={"h": 1e-3})
    assert pickle.loads(pickle.dumps(e)) == e
    with pytest.raises(TypeError):
        g.options["kappa"] = 1.0  # type: ignore[index]
    assert repr(g.options) == "Options({'kappa': 100.0})"
