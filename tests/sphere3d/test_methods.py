"""The render API: results, exact identities, reproducibility, and one clear error per bad input.

Exact checks first: parameters that enter linearly (an albedo, an emission) have a
derivative image equal to the image divided by the parameter, sample for sample; the
reparameterized primal is the naive one bit for bit; same seed, same image, whatever
the number of threads. Then the method table and its errors.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import sphere3d as s3
from flatland.core.validate import ValidationError
from sphere3d import execution, tasks
from sphere3d.reparam.film_kernel import KAPPA_FILM
from tests.sphere3d.helpers import over_batches
from tests.tiers import sweep


def _small(name: str, size: int = 12, **camera) -> dict:
    d = s3.load_scene(name).to_dict()
    d["camera"].update(width=size, height=size, **camera)
    return d


def test01_api_exports_and_methods():
    assert s3.GRADIENT_METHODS.names == ("naive", "finite_difference", "boundary", "reparam")
    for name in ("Dual", "detach", "variable", "Image", "GradientImage", "Estimate", "relative_error"):
        assert hasattr(s3, name)
    image = s3.render(_small("shadow"), spp=4, seed=3)
    assert isinstance(image, s3.Image) and image.value.shape == (12, 12) == image.stderr.shape
    assert image.batches == 4 and image.spp == 4 and image.scene == "shadow"
    g = s3.render_gradient(_small("shadow"), "occluder.translate.x", spp=8, seed=3, kappa=300.0)
    assert isinstance(g, s3.GradientImage) and g.derivative.shape == (12, 12)
    assert dict(g.options) == {
        "variant": "default",
        "kappa": 300.0,
        "kappa_film": KAPPA_FILM,
        "probes": None,
        "emitter_probes": 4,
        "spread": 3.0,
        "refine": 3,
        "paired": False,
        "baseline": True,
        "lobe": 1.0,
    }
    assert g.method == "reparam" and g.param == "occluder.translate.x" and g.batches == 8


@pytest.mark.parametrize("method", ["naive", "reparam"])
def test02_linear_parameters_have_the_image_over_the_parameter_as_derivative(method):
    # direct illumination is linear in the floor's albedo when only the floor reflects, and in
    # the light's emission when nothing else emits: dI/dθ = I / θ per sample, up to rounding, with
    # either film (the splatted film's control variate is differentiated with the value,
    # sphere3d.tasks.ImageTask._splat_chunk)
    d = _small("shadow")
    d["shapes"][1]["albedo"] = 0.0
    for film in ("splat", "pixel"):
        g = s3.render_gradient(d, "floor.albedo", method=method, spp=8, seed=1, film=film)
        np.testing.assert_allclose(g.derivative * 0.7, g.value, rtol=1e-12, atol=1e-15)
        g = s3.render_gradient(d, "light.emission", method=method, spp=8, seed=1, film=film)
        np.testing.assert_allclose(g.derivative * 6.0, g.value, rtol=1e-12, atol=1e-15)
    e = s3.irradiance("shadow", [1.0, -1.0, 0.0], [0.0, 0.0, 1.0], "light.emission", method=method, n=4096)
    assert e.derivative * 6.0 == pytest.approx(e.value, rel=1e-12)


@pytest.mark.parametrize("scene, param", [("shadow", "occluder.translate.x"), ("sky", "camera.translate.x")])
def test03_reparam_primal_is_bit_identical_to_naive(scene, param):
    naive = s3.render_gradient(_small(scene), param, method="naive", spp=16, seed=5)
    reparam = s3.render_gradient(_small(scene), param, method="reparam", spp=16, seed=5)
    assert np.array_equal(naive.value, reparam.value)
    assert np.array_equal(naive.value_stderr, reparam.value_stderr)
    assert not np.array_equal(naive.derivative, reparam.derivative)  # the methods do differ
    point = [
        s3.irradiance(scene, [0.5, -0.4, 0.0], [0, 0, 1], param, method=m, n=2048, seed=2)
        for m in ("naive", "reparam")
    ]
    assert point[0].value == point[1].value


def test04_same_seed_same_image_whatever_the_threads(monkeypatch):
    d = _small("two_occluders")
    first = s3.render_gradient(d, "left.translate.x", spp=16, seed=9)
    monkeypatch.setattr(execution, "WORKERS", 1)
    again = s3.render_gradient(d, "left.translate.x", spp=16, seed=9)
    assert np.array_equal(first.derivative, again.derivative) and np.array_equal(first.value, again.value)
    other = s3.render_gradient(d, "left.translate.x", spp=16, seed=10)
    assert not np.array_equal(first.value, other.value)


def test05_standard_errors_come_from_the_batches():
    d = _small("sky", 8)
    g = s3.render_gradient(d, "occluder.translate.x", method="naive", spp=32, batches=4, seed=0)
    one = s3.render_gradient(d, "occluder.translate.x", method="naive", spp=32, batches=1, seed=0)
    assert g.batches == 4 and np.all(np.isfinite(g.value_stderr)) and np.all(np.isinf(one.value_stderr))
    # more samples per pixel, smaller standard errors (about 1/√4 for 4 times the samples), where
    # there are any: the splatted film (default) gives pure-sky pixels exactly (sphere3d.film)
    big = s3.render(d, spp=128, batches=4, seed=1)
    small = s3.render(d, spp=32, batches=4, seed=1)
    noisy = small.stderr > 0.0
    assert noisy.sum() >= 32 and np.median(big.stderr[noisy] / small.stderr[noisy]) < 0.8


def test06_finite_difference_agrees_with_naive_where_nothing_is_discontinuous():
    # an albedo changes no visibility: both methods estimate the same derivative, and with common
    # random numbers the central difference of a linear function is exact up to rounding (either film)
    d = _small("shadow")
    for film in ("splat", "pixel"):
        fd = s3.render_gradient(
            d, "floor.albedo", method="finite_difference", spp=8, seed=4, h=0.05, film=film
        )
        naive = s3.render_gradient(d, "floor.albedo", method="naive", spp=8, seed=4, film=film)
        np.testing.assert_allclose(fd.derivative, naive.derivative, rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(fd.value, s3.render(d, spp=8, seed=4, film=film).value)


BAD = [
    (dict(method="textbook"), "'textbook'; choose from naive, finite_difference, boundary, reparam"),
    (dict(kappa=0.0), "kappa: must be > 0, got 0.0"),
    (dict(kappa=float("nan")), "kappa: must be finite"),
    (dict(kappa_film=0.0), "kappa_film: must be > 0, got 0.0"),
    (dict(kappa_film=None), "kappa_film: must be"),
    (dict(kappa_film=1e13), "kappa_film: must be <= 1e+12"),
    (dict(probes=0), "probes: must be an integer >= 1, got 0"),
    (dict(spread=-1.0), "spread: must be >= 0, got -1.0"),
    (dict(paired=1), "paired: must be True or False, got 1"),
    (dict(kappa=None, paired=True), "paired: needs a convolution kernel"),
    (dict(method="finite_difference", h=-0.1), "h: must be > 0, got -0.1"),
    (dict(method="naive", kappa=10.0), "kappa: is not an option of method 'naive'"),
    (dict(spp=0), "spp: must be an integer >= 1, got 0"),
    (dict(spp=10, batches=4), "batches: must divide spp=10 (equal batches), got 4"),
    (dict(seed=-1), "seed: must be an integer >= 0, got -1"),
    (dict(param="occluder.wobble"), "param: unknown parameter 'occluder.wobble'; choose from"),
]


@pytest.mark.parametrize("kwargs, message", BAD, ids=[m.split(":")[0] for _, m in BAD])
def test07_bad_arguments_raise_one_error_naming_the_field(kwargs, message):
    kwargs = {"param": "occluder.translate.x", "spp": 4, **kwargs}
    with pytest.raises(ValidationError) as info:
        s3.render_gradient(_small("shadow", 4), **kwargs)
    assert message in str(info.value)


def test08_reparam_refuses_the_box_filter_and_fd_a_too_large_scale_step():
    with pytest.raises(
        ValidationError, match=r"camera\.filter: the reparam method needs a continuous pixel filter"
    ):
        s3.render_gradient(_small("shadow", 4, filter="box"), "occluder.translate.x", spp=4)
    s3.render_gradient(_small("shadow", 4, filter="box"), "occluder.translate.x", method="naive", spp=4)
    with pytest.raises(ValidationError, match="h: must be < 1 for a scale parameter"):
        s3.render_gradient(_small("shadow", 4), "occluder.scale", method="finite_difference", spp=4, h=1.5)
    with pytest.raises(ValidationError, match=r"normal: must not be zero"):
        s3.irradiance("shadow", [0, 0, 0], [0, 0, 0])
    with pytest.raises(ValidationError, match=r"point\[1\]: must be finite"):
        s3.irradiance("shadow", [0, float("inf"), 0], [0, 0, 1])
    # each coordinate is checked as given, not after float() (which turned True into 1.0 and
    # raised a bare "could not convert string to float" for a string)
    for bad in ("a", True):
        with pytest.raises(ValidationError, match=r"point\[0\]: must be a real number"):
            s3.irradiance("shadow", [bad, 0, 0], [0, 0, 1])
    with pytest.raises(ValidationError, match=r"normal: must be a list of 3 numbers"):
        s3.irradiance("shadow", [0, 0, 0], np.eye(3))


def test09_paired_and_kernel_free_variants_run_on_images():
    # paired: a different primal estimate (the outer sample is the kernel centre), still unbiased: the
    # two images' film sums (8 × 8 pixels) agree. Statistic: per batch b (16 of 4 samples, the same
    # seed: batch b of both holds the same primary samples), the paired difference of the film sums;
    # its mean and standard error from the batches' spread (the splatted film correlates neighbouring
    # pixels, the batches are independent), two-sided Student's t at 15 degrees of freedom, level 1e-3
    task = tasks.ImageTask(s3.load_scene(_small("shadow", 8)), "occluder.translate.x", 64, 1, 16)
    naive = s3.GRADIENT_METHODS.run("naive", task).value
    paired = s3.GRADIENT_METHODS.run("reparam", task, paired=True).value
    assert not np.array_equal(paired, naive)
    diff, se = over_batches(paired.sum(axis=(1, 2)) - naive.sum(axis=(1, 2)))
    assert abs(diff) <= stats.t.ppf(1.0 - 0.5e-3, 15) * se, (diff, se)
    d = _small("shadow", 8)
    free = s3.render_gradient(d, "occluder.translate.x", method="reparam", spp=8, seed=1, kappa=None)
    assert np.array_equal(free.value, s3.render(d, spp=8, seed=1).value) and np.all(
        np.isfinite(free.derivative)
    )


@pytest.mark.parametrize(
    ("method", "options"),
    sweep([("naive", {}), ("reparam", {}), ("reparam", {"paired": True, "kappa": 100.0})], [("naive", {})]),
)
def test10_results_do_not_depend_on_memory_chunks(monkeypatch, method, options):
    """Every draw is keyed on the sample's index: chunks of 2^15, 7 × spp and spp samples agree.

    An image's pixels are means of the same per-sample numbers in every layout, so
    they agree bit for bit; the irradiance at a point sums its chunks in another
    grouping, so it agrees to rounding (64 ε of the sum of magnitudes, bounded by
    1e3 times the value's scale).
    """
    d = _small("two_occluders", 8)
    args = ("left.translate.x",)
    whole = s3.render_gradient(d, *args, method=method, spp=16, seed=9, **options)
    point = s3.irradiance(
        "shadow", [0.5, -0.4, 0.0], [0, 0, 1], "occluder.translate.x", method=method, n=512, seed=2, **options
    )
    for chunk in (7 * 16, 16):
        monkeypatch.setattr(tasks, "CHUNK", chunk)
        other = s3.render_gradient(d, *args, method=method, spp=16, seed=9, **options)
        assert np.array_equal(whole.value, other.value) and np.array_equal(whole.derivative, other.derivative)
        again = s3.irradiance(
            "shadow",
            [0.5, -0.4, 0.0],
            [0, 0, 1],
            "occluder.translate.x",
            method=method,
            n=512,
            seed=2,
            **options,
        )
        scale = 1e3 * max(abs(point.value), abs(point.derivative))
        assert abs(again.value - point.value) <= 64 * np.finfo(float).eps * scale
        assert abs(again.derivative - point.derivative) <= 64 * np.finfo(float).eps * scale


def test11_reparam_refine_is_a_checked_option_that_moves_only_the_derivative():
    """``refine`` (bisection rays toward a silhouette) is validated like flatland's; any value keeps
    the naive primal bit for bit, and it changes which point the rotations follow, so the derivative
    at refine=0 (the probe's own hit) differs from the default's (the comparison can fail)."""
    for bad in (-1, 1.5, True):
        with pytest.raises(ValidationError, match=r"^refine: must be an integer >= 0"):
            s3.render_gradient(_small("shadow", 4), "occluder.translate.x", spp=4, refine=bad)
    d = _small("shadow", 8)
    default = s3.render_gradient(d, "occluder.translate.x", spp=16, seed=4)
    none = s3.render_gradient(d, "occluder.translate.x", spp=16, seed=4, refine=0)
    naive = s3.render_gradient(d, "occluder.translate.x", method="naive", spp=16, seed=4)
    assert default.options["refine"] == 3 and none.options["refine"] == 0
    assert np.array_equal(default.value, naive.value) and np.array_equal(none.value, naive.value)
    assert not np.array_equal(default.derivative, none.derivative)


def test12_the_callers_floating_point_policy_holds_in_the_worker_threads(monkeypatch):
    # np.errstate is a context variable: a thread that does not run in the caller's context
    # would warn where the caller asked for silence, or stay silent where it asked for an error
    monkeypatch.setattr(execution, "WORKERS", 2)

    def divide(i: int) -> float:
        return float(np.float64(i) / np.float64(0.0))

    with np.errstate(divide="raise"), pytest.raises(FloatingPointError, match="divide by zero"):
        execution._map_threads(divide, range(1, 4))
    with np.errstate(divide="ignore", invalid="ignore"):
        assert execution._map_threads(divide, range(1, 3)) == [np.inf, np.inf]


@pytest.mark.parametrize("workers", [1, 2, 16])
def test13_chunks_give_every_thread_several_and_change_no_number(monkeypatch, workers):
    """``execution.chunk_size``: at most the memory limit, and small enough for CHUNKS_PER_THREAD chunks
    per thread unless chunks would hold fewer than MIN_CHUNK samples; the image is the same bit for bit
    whatever the threads (hence the chunks)."""
    monkeypatch.setattr(execution, "WORKERS", workers)
    for items, per_item, limit in [(4096, 16, 2048), (64, 16, 2048), (10**6, 1, 1 << 15), (7, 4096, 8)]:
        size = execution.chunk_size(items, per_item, limit)
        chunks = -(-items // size)
        assert 1 <= size <= limit
        if size < limit:  # not at the memory ceiling: balance or the floor decides
            assert chunks >= execution.CHUNKS_PER_THREAD * workers or size * per_item >= execution.MIN_CHUNK
            assert (
                size - 1
            ) * per_item < execution.MIN_CHUNK or chunks <= execution.CHUNKS_PER_THREAD * workers
    d = _small("two_occluders", 16)
    monkeypatch.setattr(execution, "MIN_CHUNK", 16)  # one pixel: the chunks follow the threads
    monkeypatch.setattr(execution, "WORKERS", 1)
    assert execution.chunk_size(256, 16, 2048) == 64
    one = s3.render_gradient(d, "left.translate.x", method="boundary", spp=16, seed=5, progress=False)
    monkeypatch.setattr(execution, "WORKERS", workers)
    assert execution.chunk_size(256, 16, 2048) == -(-64 // workers)
    task_chunks = s3.render_gradient(d, "left.translate.x", method="boundary", spp=16, seed=5, progress=False)
    assert np.array_equal(one.value, task_chunks.value) and np.array_equal(
        one.derivative, task_chunks.derivative
    )
