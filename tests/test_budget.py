"""Requests too large for memory or time are refused up front, naming the field and the estimate."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

import flatland as fl
import sphere3d as s3
import sphere3d.boundary.camera as film_edge_points
import sphere3d.boundary.transforms as edge_samples
import sphere3d.reparam.bisection as bisection
import sphere3d.state as state_module
import sphere3d.tasks as tasks
from flatland.core.budget import (
    BYTES_PER_RAY,
    IMAGE_BYTES_PER_PIXEL,
    MEMORY_LIMIT,
    RAY_LIMIT,
    Request,
    Term,
    check_request,
    memory_estimate,
    rays_per_sample,
)
from flatland.core.image import resolve_batches
from flatland.core.validate import ValidationError
from sphere3d import execution
from sphere3d.boundary.edges import mesh_edges
from sphere3d.film import reach
from sphere3d.methods import GRADIENT_METHODS
from sphere3d.scene import load_scene
from sphere3d.state import SCENE_BYTES_PER_TRIANGLE, build_state
from sphere3d.tasks import ImageTask

SPHERE_SHADOW = json.loads((Path(s3.__file__).parent / "scenes" / "shadow.json").read_text())
RENDER = sys.modules["sphere3d.render"]  # the module: ``sphere3d.render`` is also the function
PARAM = "occluder.translate.x"


def _shadow(width: int) -> dict:
    """sphere3d's shadow scene with a square image ``width`` pixels wide."""
    return {**SPHERE_SHADOW, "camera": {**SPHERE_SHADOW["camera"], "width": width, "height": width}}


def _request(scene, method, spp=1, film="splat", **options) -> Request:
    """What render_gradient(scene, PARAM, method, spp, film=film, **options) would be checked as, unrun."""
    task = ImageTask(load_scene(scene), PARAM, spp, 0, resolve_batches(spp, None), film=film)
    return RENDER._request(task, GRADIENT_METHODS.resolve_options(method, options), method)


def _largest_accepted(request_of, lo: int, hi: int) -> int:
    """The largest x in [lo, hi) whose request's memory estimate is within the limit (bisection; the
    estimate grows with x)."""
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if memory_estimate(request_of(mid)) <= MEMORY_LIMIT else (lo, mid)
    return lo


def test01_each_limit_is_a_boundary():
    # just inside each limit passes, just outside raises naming the field that would have to change; the
    # memory estimate is the sum of the images and one chunk's rays
    pixels = (MEMORY_LIMIT - 3 * BYTES_PER_RAY) // (16 * IMAGE_BYTES_PER_PIXEL)  # one sample of 3 rays
    check_request(Request(pixels, 1, 16, 3, 1, "camera.pixels"))
    with pytest.raises(ValidationError, match=r"^camera\.pixels: .* GiB for the per-batch images"):
        check_request(Request(pixels + 1, 1, 16, 3, 1, "camera.pixels"))
    chunk = (MEMORY_LIMIT - IMAGE_BYTES_PER_PIXEL) // (15 * BYTES_PER_RAY)  # one pixel's image
    check_request(Request(1, chunk, 1, 15, chunk))
    with pytest.raises(ValidationError, match=r"^probes: 15 rays per sample × \d+ samples per memory chunk"):
        check_request(Request(1, chunk + 1, 1, 15, chunk + 1))
    check_request(Request(1, RAY_LIMIT // 3, 1, 3, 1))
    with pytest.raises(ValidationError, match=r"^spp: .* rays in all, more than"):
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
        (lambda: s3.render_gradient("shadow", "occluder.translate.x", spp=2**24), "spp", "GiB"),
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


def test05_a_method_term_adds_to_the_estimate_and_is_named_when_it_is_the_largest():
    base = memory_estimate(Request(1, 1, 1, 3, 1))
    table = lambda nbytes: Term("probes", 9, "probes per kernel", "a table", at_once=nbytes)  # noqa: E731
    check_request(Request(1, 1, 1, 3, 1, terms=(table(MEMORY_LIMIT - base),)))
    with pytest.raises(
        ValidationError, match=r"^probes: probes=9 \(probes per kernel\): a table need about 8\.0 GiB at once"
    ):
        check_request(Request(1, 1, 1, 3, 1, terms=(table(MEMORY_LIMIT - base + 1),)))
    # rays in all (time): a term's rays count against the ray limit beside the samples' own
    points = lambda rays: Term("rate", 2.0, "edge points", rays=rays)  # noqa: E731
    check_request(Request(1, 1, 1, 3, 1, terms=(points(RAY_LIMIT - 3),)))
    with pytest.raises(
        ValidationError, match=r"^rate: rate=2\.0 \(edge points\) adds 6\.9e\+10 rays: .* rays in all"
    ):
        check_request(Request(1, 1, 1, 3, 1, terms=(points(RAY_LIMIT - 2),)))


@pytest.mark.parametrize(("option", "extra"), [("probes", 0), ("emitter_probes", 6)])
def test06_probe_pair_tables_grow_like_p_squared_and_are_refused_by_the_option(option, extra):
    # closest_pair holds a slice of rows of p² pairs (p = probes, or emitter_probes + BOUNDARY + AIM);
    # one row is what no slicing bounds: 100 000 probes need 10^10 pairs at once
    with pytest.raises(
        ValidationError, match=rf"^{option}: {option}=100000 .* 1 × {100_000 + extra}² .* GiB at once"
    ):
        s3.render_gradient(_shadow(1), PARAM, spp=1, progress=False, **{option: 100_000})
    # the largest value accepted: its row of p² pairs fills the limit but for the rest of the request
    p = _largest_accepted(lambda v: _request(_shadow(1), "reparam", **{option: v}), 1, 10**6)
    check_request(_request(_shadow(1), "reparam", **{option: p}))
    with pytest.raises(ValidationError, match=rf"^{option}: .* probe pairs need about 8\.0 GiB at once"):
        check_request(_request(_shadow(1), "reparam", **{option: p + 1}))
    row_limit = math.isqrt(MEMORY_LIMIT // bisection.PAIR_ENTRY_BYTES) - extra
    assert 0.99 * row_limit < p <= row_limit


def test07_closest_pair_holds_a_slice_of_rows_within_its_model_with_the_same_pairs(monkeypatch):
    rng = np.random.default_rng(7)
    w = rng.normal(size=(30, 200, 3))
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    side = rng.random((30, 200)) < 0.5
    allowed = lambda rows: side[rows, :, None] & ~side[rows, None, :]  # noqa: E731
    whole = bisection.closest_pair(w, allowed)  # every row in one slice (PAIR_MEMORY holds them)
    assert bisection.pair_rows(200) >= 30
    monkeypatch.setattr(bisection, "PAIR_MEMORY", 2 << 20)  # now 3 rows of 200² pairs a slice
    assert bisection.pair_rows(200) == 3
    tracemalloc.start()
    sliced = bisection.closest_pair(w, allowed)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    for a, b in zip(whole, sliced, strict=True):
        np.testing.assert_array_equal(a, b)
    assert peak <= bisection.pair_bytes(200) + 30 * 8 * 4  # a slice, and the per-row outputs
    assert 5 * peak < 30 * 200**2 * 9  # unsliced, the cosines and the mask alone are five times that


def test08_film_edge_points_are_chunked_and_rate_is_refused_for_its_rays(monkeypatch):
    # N = ⌈rate · spp/batches · Λ⌉ points per batch, POINT_RAYS rays each; memory: one chunk of points
    with pytest.raises(ValidationError, match=r"^rate: rate=1000000\.0 .* rays in all, more than") as info:
        s3.render_gradient("shadow", PARAM, method="boundary", rate=1e6, progress=False)
    assert info.value.field == "rate"
    plain = build_state(load_scene("shadow"), PARAM)
    length = film_edge_points.film_edges(plain, plain, mesh_edges(plain.triangles, plain.shape_of)).total
    spp, pixels = 64, 64 * 64
    others = pixels * spp * (3 + 2 * 4)  # the samples' rays and the default secondary's
    rate = (RAY_LIMIT - others) / (spp * length * film_edge_points.POINT_RAYS)  # spp/batches · batches = spp
    check_request(_request("shadow", "boundary", spp, rate=0.999 * rate))
    with pytest.raises(ValidationError, match=r"^rate: "):
        check_request(_request("shadow", "boundary", spp, rate=1.001 * rate))
    bound = film_edge_points.POINT_CHUNK * film_edge_points.POINT_BYTES
    assert film_edge_points.point_bytes(10**12) == bound  # whatever the rate


def test09_edge_samples_are_sliced_by_shading_points_and_secondary_is_refused_beyond_one_point():
    # slices of DRAW_CHUNK // k points (at least one): the old MemoryError case (10^5 samples at every
    # point of a chunk; half as many here, within the ray limit at four rays each) now holds one
    # point's samples, what no slicing bounds
    k = 5 * 10**4
    request = _request("shadow", "boundary", 64, secondary=k)
    (edge,) = [t for t in request.terms if t.field == "secondary"]
    assert edge_samples.draw_points(k) == max(1, edge_samples.DRAW_CHUNK // k)
    assert edge.at_once == edge_samples.draw_points(k) * k * edge_samples.DRAW_BYTES
    check_request(request)
    with pytest.raises(
        ValidationError,
        match=r"^secondary: secondary=10000000 .* 1 shading points × 10000000 edge samples .* 9\.5 GiB",
    ):
        s3.render_gradient(_shadow(1), PARAM, method="boundary", spp=1, secondary=10**7, progress=False)
    rest = memory_estimate(_request(_shadow(1), "boundary", secondary=1)) - edge_samples.DRAW_BYTES
    k = int((MEMORY_LIMIT - rest) // edge_samples.DRAW_BYTES)
    check_request(_request(_shadow(1), "boundary", secondary=k))
    with pytest.raises(ValidationError, match=r"^secondary: "):
        check_request(_request(_shadow(1), "boundary", secondary=k + 1))


@pytest.mark.parametrize(("spp", "cv_scope"), [(1, "pixel"), (4, "pixel"), (4, "batch")])
@pytest.mark.parametrize("kind", ["gaussian", "tent", "box"])
def test10_the_film_model_is_what_the_splat_film_allocates(spp, cv_scope, kind):
    # per pixel and batch the images alone, whatever the film; the splat film's buffers (one tile's, here
    # the whole 8 × 8 image) are its term, named by the film
    scene = load_scene({**_shadow(8), "camera": {**_shadow(8)["camera"], "filter": kind}})
    task = ImageTask(scene, None, spp, 0, resolve_batches(spp, None), cv_scope=cv_scope)
    (term,) = task.film_terms()
    _, held = task._tile()
    assert held == 64
    assert sum(a.nbytes for a in task._splat_buffers(held) if a is not None) == term.at_once
    assert (term.field, term.value) == ("film", "splat")
    pixel = ImageTask(scene, None, spp, 0, task.batches, film="pixel")
    assert task.pixel_bytes() == pixel.pixel_bytes() == IMAGE_BYTES_PER_PIXEL
    assert pixel.film_terms() == ()


def test11_the_splat_film_holds_a_tile_of_rows_whatever_the_image_height(monkeypatch):
    # 4096 pixels wide: the same buffers for 1024 rows as for 4096, within TILE_BYTES (or a chunk per
    # thread) and the 2h + 1 rows the next tile's neighbours need
    _, h = reach("gaussian")
    for spp in (1, 16):
        held = []
        for height in (1024, 4096):
            scene = load_scene({**_shadow(4096), "camera": {**_shadow(4096)["camera"], "height": height}})
            task = ImageTask(scene, None, spp, 0, resolve_batches(spp, None))
            held.append(task.film_terms()[0].at_once)
        b = task._stencil_bytes()
        tile = max(tasks.TILE_BYTES, execution.workers() * task.chunk_pixels * b)
        assert held[0] == held[1] <= tile + (2 * h + 1) * 4096 * b
    # 4096² at 2 spp was refused for 27 GiB of stencils; now the images' 2 GiB and a tile
    check_request(_request(_shadow(4096), "naive", 2))
    # a film whose tile would not fit is refused naming the film (a tile of every chunk: 27 GiB)
    monkeypatch.setattr(tasks, "TILE_BYTES", 2**50)
    with pytest.raises(
        ValidationError,
        match=r"^film: film=splat \(each sample in every pixel its filter covers\): the stencils of 16777216 "
        r"pixels \(1024 memory chunks .*\) need about 25\.\d GiB at once \(27\.\d GiB in all\)",
    ):
        s3.render(_shadow(4096), spp=2, progress=False)
    check_request(_request(_shadow(4096), "naive", 2, film="pixel"))


@pytest.mark.parametrize(
    ("method", "spp", "options"),
    [
        ("reparam", 1, {"probes": 400, "emitter_probes": 400}),
        ("boundary", 2, {"rate": 100.0, "secondary": 512}),
    ],
)
def test12_the_estimate_bounds_the_peak_of_small_renders(monkeypatch, method, spp, options):
    # tracemalloc sees numpy's allocations; the renders are one memory chunk (one pixel), as the
    # estimate counts; slices of one row of probe pairs, chunks of 256 film edge points (of about 2000)
    # and slices of one shading point's 512 edge samples, so that the models are near what they hold
    monkeypatch.setattr(bisection, "PAIR_MEMORY", 1)
    monkeypatch.setattr(film_edge_points, "POINT_CHUNK", 256)
    monkeypatch.setattr(edge_samples, "DRAW_CHUNK", 512)
    estimate = memory_estimate(_request(_shadow(1), method, spp, **options))
    tracemalloc.start()
    s3.render_gradient(_shadow(1), PARAM, method=method, spp=spp, batches=1, progress=False, **options)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak <= estimate


@pytest.mark.parametrize(
    ("method", "spp", "kind", "size"),
    [(None, 1, "gaussian", (37, 23)), ("reparam", 4, "tent", (23, 37)), ("boundary", 2, "gaussian", (9, 31))],
)
def test13_the_splat_film_s_tiles_do_not_change_the_image(monkeypatch, method, spp, kind, size):
    # 64 samples per memory chunk (16 to 64 pixels: several chunks per row, or rows per chunk); one tile
    # of all of them, against tiles of one chunk (TILE_BYTES = 1, one thread): the same sums, same order
    width, height = size
    scene = {
        **_shadow(1),
        "camera": {**_shadow(1)["camera"], "width": width, "height": height, "filter": kind},
    }
    monkeypatch.setattr(tasks, "CHUNK", 64)

    def images() -> list[np.ndarray]:
        if method is None:
            image = s3.render(scene, spp=spp, progress=False)
            return [image.value, image.stderr]
        image = s3.render_gradient(scene, PARAM, method=method, spp=spp, progress=False)
        return [image.value, image.derivative, image.value_stderr, image.derivative_stderr]

    task = ImageTask(load_scene(scene), PARAM, spp, 0, resolve_batches(spp, None))
    assert task._tile()[0] * task.chunk_pixels >= width * height  # one tile
    whole = images()
    monkeypatch.setattr(tasks, "TILE_BYTES", 1)
    monkeypatch.setattr(execution, "WORKERS", 1)
    assert task._tile()[0] == 1 and -(-width * height // task.chunk_pixels) > 5  # a tile per chunk
    for a, b in zip(whole, images(), strict=True):
        assert np.array_equal(a, b)


def test14_a_large_splat_render_fits_without_the_whole_image_s_stencils():
    # 1024² at 1 spp in a fresh process whose address space may grow, after a small render (threads,
    # their heaps, Embree), by the stencils of the whole image only (2 × 25 float64 per pixel, 400 MiB):
    # what the film alone held before its tiles; the render needs the chunks, a tile and the image
    # (4096² at 1 spp: 7.3 GiB -> 0.7 GiB peak RSS, 50 s -> 25 s on 2 cores; too long for the suite)
    script = """
import json, resource
from pathlib import Path
import sphere3d as s3
from sphere3d.tasks import ImageTask
scene = json.loads((Path(s3.__file__).parent / "scenes" / "hard_shadow.json").read_text())
s3.render(scene, spp=1, progress=False)
scene["camera"]["width"] = scene["camera"]["height"] = 1024
stencils = ImageTask(s3.load_scene(scene), None, 1, 0, 1)._stencil_bytes() * 1024**2
assert stencils == 2 * 25 * 8 * 1024**2
size = next(int(line.split()[1]) * 1024 for line in open("/proc/self/status") if line.startswith("VmSize"))
resource.setrlimit(resource.RLIMIT_AS, (size + stencils, size + stencils))
image = s3.render(scene, spp=1, progress=False)
print(image.value.shape, float(image.value.mean()))
"""
    env = {**os.environ, "SPHERE3D_THREADS": "2"}
    done = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("(1024, 1024) ")


def test15_the_scene_s_triangles_are_counted_and_refused_named():
    """The scene's per-triangle tables are a term of every request (``shapes``: its triangle count); a
    scene whose tables alone exceed the limit is refused before any state is built, naming it."""
    scene = load_scene("hard_shadow")
    triangles = sum(len(shape.mesh.faces) for shape in scene.shapes)
    for method in ("reparam", "boundary"):
        (term,) = [t for t in _request("hard_shadow", method).terms if t.field == "shapes"]
        assert term.value == triangles and term.at_once == triangles * SCENE_BYTES_PER_TRIANGLE
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(state_module, "SCENE_BYTES_PER_TRIANGLE", MEMORY_LIMIT // triangles + 1)
        with pytest.raises(ValidationError, match=rf"^shapes: shapes={triangles} \(triangles in the scene\)"):
            s3.render_gradient("hard_shadow", PARAM, method="naive", spp=1, progress=False)
