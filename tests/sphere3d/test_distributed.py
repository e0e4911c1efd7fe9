"""``render``, ``render_gradient`` and ``irradiance`` on a Dask cluster: the same numbers, bit for bit,
as a local run.

A ``dask.distributed.LocalCluster`` of two single-threaded workers runs the tiles
(:meth:`sphere3d.tasks.ImageTask._on_cluster`, :meth:`sphere3d.tasks.PointTask._on_cluster`). Its
workers are threads of this process, started in a tenth of a second where two worker processes took
6-7 s to start on a 2-core machine; dask does not pickle what is scattered to such workers, so the
module's fixture makes every tile pickle its payload (the task with its scene, θ and the method's
transforms) as a worker process receives it (:func:`_pickled`), and test09 (slow) runs two worker
processes. Chunks are made small (``tasks.CHUNK``: 16 pixels of 4 spp) so that a 16 × 16 film is 16
chunks in 8 tiles, and the 1024 samples of a point in 4 batches are 16 chunks of 64 in 8 tiles; the
local runs use the same chunks (results do not depend on them: test_methods test10, test_film_splat
test06).
"""

from __future__ import annotations

import json
import pickle
from typing import ClassVar

import numpy as np
import pytest
import tqdm

pytest.importorskip("embreex")
distributed = pytest.importorskip("dask.distributed")

import dask  # noqa: E402

from flatland.core.validate import ValidationError  # noqa: E402
from sphere3d import execution, tasks  # noqa: E402
from sphere3d.__main__ import main  # noqa: E402
from sphere3d.render import irradiance, render, render_gradient  # noqa: E402
from sphere3d.scene import load_scene  # noqa: E402
from tests.tiers import SLOW  # noqa: E402

PARAM = "occluder.translate.x"
METHODS = ("naive", "reparam", "boundary", "finite_difference")
SPP = 4
CHUNK = 16 * SPP
"""Samples per memory chunk: 16 pixels, so the 256 pixels are 16 chunks, 8 tiles on 2 worker threads."""
POINT = {"point": [0.6, -0.1, 0.0], "normal": [0.0, 0.0, 1.0], "n": 1024, "batches": 4}
"""A point in the occluder's penumbra on the ground: 4 batches of 256 samples, 4 memory chunks each."""


def _scene() -> dict:
    """``hard_shadow`` on a 16 × 16 film."""
    data = load_scene("hard_shadow").to_dict()
    data["camera"].update(width=16, height=16)
    return data


_REMOTE = tasks._remote
TILES: list = []
"""The tiles :func:`_pickled` ran (its module is imported, not copied, by the in-process workers)."""


def _pickled(shared, item):
    """:func:`sphere3d.tasks._remote` on a pickled copy of its payload, as a worker process gets it."""
    TILES.append(item)
    return _REMOTE(pickle.loads(pickle.dumps(shared)), item)


@pytest.fixture(scope="module")
def scheduler():
    """The address of a local cluster of 2 workers × 1 thread, closed (workers, then scheduler) after."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(tasks, "_remote", _pickled)
        patch.setattr(tasks, "CHUNK", CHUNK)
        with distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0"
        ) as cluster:
            yield cluster.scheduler_address


def _same(local, remote) -> bool:
    fields = ("value", "stderr") if hasattr(local, "stderr") else (
        "value", "value_stderr", "derivative", "derivative_stderr"
    )  # fmt: skip
    return all(np.array_equal(getattr(local, f), getattr(remote, f)) for f in fields)


@pytest.mark.parametrize("film", ["splat", "pixel"])
def test01_render_on_the_cluster_is_bit_identical_to_the_local_render(scheduler, film):
    TILES.clear()
    local = render(_scene(), spp=SPP, seed=3, film=film, progress=False)
    remote = render(_scene(), spp=SPP, seed=3, film=film, progress=False, scheduler=scheduler)
    assert _same(local, remote)
    # 8 tiles of 2 memory chunks (32 pixels each), and the per-image term
    assert sorted(TILES, key=str) == sorted([(2 * k, 2 * k + 2) for k in range(8)] + [None], key=str)


@pytest.mark.parametrize("method", METHODS)
def test02_every_gradient_method_on_the_cluster_is_bit_identical_to_the_local_one(scheduler, method):
    """Splat film: the tiles' stencils are summed here in the local order; boundary's edge term on the
    film (``pixel_extra``) is one more task; finite differences make three renders."""
    local = render_gradient(_scene(), PARAM, method=method, spp=SPP, seed=5, progress=False)
    remote = render_gradient(
        _scene(), PARAM, method=method, spp=SPP, seed=5, progress=False, scheduler=scheduler
    )
    assert _same(local, remote)
    assert np.any(remote.derivative != 0.0)  # the comparison sees a gradient


@pytest.mark.parametrize("method", ["naive", "boundary"])
def test03_the_per_pixel_film_on_the_cluster_too(scheduler, method):
    args = (_scene(), PARAM)
    local = render_gradient(*args, method=method, spp=SPP, seed=5, film="pixel", progress=False)
    remote = render_gradient(
        *args, method=method, spp=SPP, seed=5, film="pixel", progress=False, scheduler=scheduler
    )
    assert _same(local, remote)


class Recorder:
    """Stands in for ``tqdm.tqdm``: records each bar's count and totals (as tests/test_progress.py)."""

    made: ClassVar[list[Recorder]] = []

    def __init__(self, total=0, desc="", **kwargs):
        self.total, self.desc, self.n, self.totals = total, desc, 0, []
        Recorder.made.append(self)

    def update(self, k=1):
        self.n += k
        self.totals.append(self.total)

    def close(self):
        pass


def test04_the_progress_bar_advances_per_finished_tile(scheduler, monkeypatch):
    """16 chunks in 8 tiles (4 per worker thread), and the per-image term's task: 9 per render."""
    monkeypatch.setattr(tqdm, "tqdm", Recorder)
    Recorder.made = []
    render_gradient(_scene(), PARAM, method="finite_difference", spp=SPP, progress=True, scheduler=scheduler)
    (bar,) = Recorder.made
    assert bar.n == 3 * 9 and set(bar.totals) == {3 * 9}


def test05_a_malformed_address_or_one_of_another_type_is_one_error_naming_scheduler():
    for bad, message in [
        ("nonsense", "scheduler: cannot connect to 'nonsense': missing port number in address 'nonsense'"),
        (8786, "scheduler: must be a dask.distributed scheduler address such as 'tcp://host:8786', got 8786"),
    ]:
        with pytest.raises(ValidationError) as e:
            render_gradient(_scene(), PARAM, method="naive", spp=SPP, progress=False, scheduler=bad)
        assert e.value.field == "scheduler" and str(e.value) == message


def test06_an_address_where_no_scheduler_answers_is_one_error_naming_scheduler():
    """Port 1 on this machine: nothing listens; dask gives up after its connect timeout (0.2 s here)."""
    with dask.config.set({"distributed.comm.timeouts.connect": "0.2s"}), pytest.raises(ValidationError) as e:
        render(_scene(), spp=SPP, progress=False, scheduler="tcp://127.0.0.1:1")
    assert e.value.field == "scheduler" and "cannot connect to 'tcp://127.0.0.1:1'" in str(e.value)


def test07_other_arguments_are_checked_before_the_cluster_is_reached():
    """A bad option is reported as itself, not as the unreachable scheduler's error."""
    with pytest.raises(ValidationError) as e:
        render_gradient(_scene(), PARAM, method="reparam", spp=SPP, kappa=-1.0, scheduler="nonsense")
    assert e.value.field == "kappa"


@pytest.mark.parametrize("verb", [["render"], ["gradient", "--param", PARAM, "--method", "boundary"]])
def test08_the_command_line_passes_scheduler_on(tmp_path, capsys, verb):
    """``render`` and ``gradient`` take ``--scheduler``, handed to the function as ``scheduler=``: a
    malformed address is its one-line error, status 2 (the arrays are the API's, test01 and test02)."""
    scene = tmp_path / "small.json"
    scene.write_text(json.dumps(_scene()))
    argv = [verb[0], str(scene), *verb[1:], "--spp", "1", "--quiet", "--out", str(tmp_path)]
    assert main([*argv, "--scheduler", "nonsense"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [
        "error: scheduler: cannot connect to 'nonsense': missing port number in address 'nonsense'"
    ]


@SLOW  # test02 checks the same identity with the payload pickled in this process
def test09_worker_processes_give_the_same_arrays(monkeypatch):
    monkeypatch.setattr(tasks, "CHUNK", CHUNK)
    local = render_gradient(_scene(), PARAM, method="boundary", spp=SPP, seed=7, progress=False)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        remote = render_gradient(
            _scene(), PARAM, method="boundary", spp=SPP, seed=7, progress=False,
            scheduler=cluster.scheduler_address,
        )  # fmt: skip
    assert _same(local, remote)
    assert execution.client() is None  # the call's client is closed with it


def test10_the_irradiance_on_the_cluster_is_bit_identical_to_the_local_one(scheduler, monkeypatch):
    """The value alone (no ``param``): its 16 memory chunks go to the cluster as 8 tiles of 2 (batch-major:
    tile k holds chunks 2k and 2k + 1), the bar advancing per finished tile."""
    local = irradiance(_scene(), **POINT, seed=3, progress=False)
    TILES.clear()
    monkeypatch.setattr(tqdm, "tqdm", Recorder)
    Recorder.made = []
    remote = irradiance(_scene(), **POINT, seed=3, progress=True, scheduler=scheduler)
    assert _same(local, remote) and remote.value > 0.0
    assert sorted(TILES) == [(2 * k, 2 * k + 2) for k in range(8)]  # no per-image term at a point
    (bar,) = Recorder.made
    assert bar.n == 8 and set(bar.totals) == {8}


@pytest.mark.parametrize("method", METHODS)
def test11_every_gradient_method_of_the_irradiance_on_the_cluster_is_bit_identical(scheduler, method):
    """Each chunk's sum is computed on a worker, the batches' sums added here in the local order; finite
    differences make three estimates. naive misses the shadow's moving edge: its derivative is 0 here."""
    local = irradiance(_scene(), **POINT, param=PARAM, method=method, seed=5, progress=False)
    TILES.clear()
    remote = irradiance(
        _scene(), **POINT, param=PARAM, method=method, seed=5, progress=False, scheduler=scheduler
    )
    assert _same(local, remote) and TILES  # computed by the workers
    assert (remote.derivative != 0.0) == (method != "naive")  # the comparison sees a gradient


def test12_the_irradiance_checks_scheduler_and_its_other_arguments_as_render_gradient_does():
    """The errors of test05 and test07: a bad address names ``scheduler``, a bad option itself."""
    for bad, message in [
        ("nonsense", "scheduler: cannot connect to 'nonsense': missing port number in address 'nonsense'"),
        (8786, "scheduler: must be a dask.distributed scheduler address such as 'tcp://host:8786', got 8786"),
    ]:
        for param in (None, PARAM):
            with pytest.raises(ValidationError) as e:
                irradiance(_scene(), **POINT, param=param, progress=False, scheduler=bad)
            assert e.value.field == "scheduler" and str(e.value) == message
    with pytest.raises(ValidationError) as e:
        irradiance(_scene(), **POINT, param=PARAM, method="reparam", kappa=-1.0, scheduler="nonsense")
    assert e.value.field == "kappa"
