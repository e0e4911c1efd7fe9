"""Requests too large for memory or time are refused up front, naming the field and the estimate."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import flatland as fl
import sphere3d as s3
from flatland.core.budget import (
    BYTES_PER_RAY,
    IMAGE_BYTES_PER_PIXEL,
    MEMORY_LIMIT,
    RAY_LIMIT,
    Request,
    check_request,
    rays_per_sample,
)
from flatland.core.validate import ValidationError

SPHERE_SHADOW = json.loads((Path(s3.__file__).parent / "scenes" / "shadow.json").read_text())


def test01_each_limit_is_a_boundary():
    # just inside each limit passes, just outside raises naming the field that would have to change
    pixels = MEMORY_LIMIT // (16 * IMAGE_BYTES_PER_PIXEL)
    check_request(Request(pixels, 1, 16, 3, 1, "camera.pixels"))
    with pytest.raises(ValidationError, match=r"^camera\.pixels: .* GiB for the per-batch images"):
        check_request(Request(pixels + 1, 1, 16, 3, 1, "camera.pixels"))
    chunk = MEMORY_LIMIT // (15 * BYTES_PER_RAY)
    check_request(Request(1, chunk, 1, 15, chunk))
    with pytest.raises(ValidationError, match=r"^probes: 15 rays per sample × \d+ samples per memory chunk"):
        check_request(Request(1, chunk + 1, 1, 15, chunk + 1))
    check_request(Request(1, RAY_LIMIT // 3, 1, 3, 1))
    with pytest.raises(ValidationError, match=r"^spp: .* rays, more than"):
        check_request(Request(1, RAY_LIMIT // 3 + 1, 1, 3, 1))


def test02_rays_per_sample_counts_probes_pairs_and_fd():
    assert rays_per_sample({}) == 3
    assert rays_per_sample({"probes": 4, "paired": False}) == 15
    assert rays_per_sample({"probes": 4, "paired": True}) == 30
    assert rays_per_sample({"h": 1e-3}) == 6


@pytest.mark.parametrize(
    ("call", "field", "estimate"),
    [
        (lambda: fl.render(fl.load_scene("shadow").with_camera(pixels=10**9), spp=1), "camera.pixels", "GiB"),
        (lambda: fl.render("shadow", spp=2**40), "spp", "rays"),
        (lambda: fl.render_gradient("shadow", "occluder.translate.x", probes=10**6), "probes", "TiB"),
        (lambda: fl.irradiance("shadow", [0.0, 0.0], [0.0, 1.0], n=2**40), "n", "rays"),
        (lambda: s3.render("shadow", spp=2**40), "spp", "TiB"),
        (lambda: s3.render("shadow", spp=2**24), "spp", "GiB"),
        (lambda: s3.render_gradient("shadow", "occluder.translate.x", probes=10**6), "probes", "TiB"),
        (lambda: s3.irradiance("shadow", [0, 0, 0], [0, 0, 1], n=2**40), "n", "rays"),
        (
            lambda: s3.render(
                {**SPHERE_SHADOW, "camera": {**SPHERE_SHADOW["camera"], "width": 4096, "height": 4096}},
                spp=16,
            ),
            "camera.width",
            "GiB",
        ),
    ],
)
def test03_huge_requests_are_refused_before_any_work(call, field, estimate):
    with pytest.raises(ValidationError, match=rf"^{field}: .*{estimate}") as info:
        call()
    assert info.value.field == field


def test04_a_non_finite_estimate_is_an_internal_error_not_a_result(monkeypatch):
    # validation keeps inputs finite, so NaN from an estimator is a defect: raised, never returned
    import flatland.integrator as integrator
    import flatland.tasks as tasks
    import sphere3d.integrator as s3_integrator

    real = integrator.shade
    nan_shade = lambda *a, **k: real(*a, **k) * float("nan")  # noqa: E731
    monkeypatch.setattr(integrator, "shade", nan_shade)  # under the pixel integral
    monkeypatch.setattr(tasks, "shade", nan_shade)  # at a point (PointTask calls it directly)
    real3 = s3_integrator.irradiance_samples
    monkeypatch.setattr(s3_integrator, "irradiance_samples", lambda *a, **k: real3(*a, **k) * float("inf"))
    with np.errstate(all="ignore"):  # the injected NaN and inf propagate quietly, as a defect's would
        with pytest.raises(FloatingPointError, match=r"^internal error: \d+ of \d+ per-batch pixel values"):
            fl.render("shadow", spp=4)
        with pytest.raises(FloatingPointError, match=r"internal error: .* per-batch values"):
            fl.irradiance("shadow", [0.0, 0.0], [0.0, 1.0], n=16)
        with pytest.raises(FloatingPointError, match=r"per-batch pixel values"):
            s3.render_gradient("shadow", "occluder.translate.x", method="naive", spp=2)
