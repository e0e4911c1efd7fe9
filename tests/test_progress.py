"""Progress bars (flatland.core.progress): one per long call, advanced per chunk, in both packages.

A bar changes no number; its total is right from the start (a finite difference's three passes
included); it is off by default when stderr is no terminal (the test suite, notebooks, pipes), on
with ``progress=True``, off with ``progress=False`` and the command line's ``--quiet``; a study's
trials show none of their own. Cheap: tiny films, and chunks made small (results do not depend on
the chunk size, flatland.tasks.CHUNK and sphere3d.tasks.CHUNK).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
from typing import ClassVar

import numpy as np
import pytest
import tqdm

import flatland
import flatland.tasks
from flatland.__main__ import PACKAGE
from flatland.app.cli import main
from flatland.app.study import run_study
from flatland.app.study_config import StudyConfig
from flatland.core import progress
from flatland.core.validate import ValidationError
from flatland.scene import load_scene

PARAM = "occluder.translate.x"


class Recorder:
    """Stands in for ``tqdm.tqdm``: records each bar's description, total at every update and count."""

    made: ClassVar[list[Recorder]] = []

    def __init__(self, total=0, desc="", **kwargs):
        self.total, self.desc, self.n, self.totals, self.closed = total, desc, 0, [], False
        Recorder.made.append(self)

    def update(self, k=1):
        self.n += k
        self.totals.append(self.total)

    def close(self):
        self.closed = True


@pytest.fixture
def bars(monkeypatch):
    Recorder.made = []
    monkeypatch.setattr(tqdm, "tqdm", Recorder)
    return Recorder.made


def _scene(pixels=12):
    return load_scene("shadow").with_camera(pixels=pixels)


def test01_one_bar_per_call_its_total_right_from_the_start_and_no_number_changed(bars, monkeypatch):
    """12 pixels × 16 spp in chunks of 32 samples: 6 chunks a render; a finite difference makes 3."""
    monkeypatch.setattr(flatland.tasks, "CHUNK", 32)
    scene = _scene()
    quiet = flatland.render_gradient(scene, PARAM, method="finite_difference", spp=16, progress=False)
    assert bars == []
    shown = flatland.render_gradient(scene, PARAM, method="finite_difference", spp=16, progress=True)
    assert np.array_equal(quiet.derivative, shown.derivative) and np.array_equal(quiet.value, shown.value)
    assert np.array_equal(quiet.derivative_stderr, shown.derivative_stderr)
    (bar,) = bars
    assert bar.desc == "finite_difference shadow" and bar.n == 18 and set(bar.totals) == {18} and bar.closed
    flatland.render(scene, spp=16, progress=True)
    flatland.irradiance(scene, [0.0, 0.0], [0.0, 1.0], PARAM, method="reparam", n=96, progress=True)
    assert [(b.desc, b.n, set(b.totals)) for b in bars[1:]] == [
        ("render shadow", 6, {6}),
        ("irradiance reparam", 3, {3}),
    ]


def test02_off_by_default_without_a_terminal_and_a_bad_value_is_named():
    assert progress.show(None) is False  # pytest captures stderr: no terminal
    assert progress.show(True) and not progress.show(False)
    with pytest.raises(ValidationError, match=r"^progress: must be True, False or None, got 'yes'"):
        flatland.render(_scene(), spp=1, progress="yes")


def test03_a_real_bar_goes_to_stderr_and_leaves_no_line_behind(monkeypatch, capsys):
    monkeypatch.setattr(progress, "DELAY", 0.0)
    monkeypatch.setattr(flatland.tasks, "CHUNK", 32)
    flatland.render(_scene(), spp=16, progress=True)
    captured = capsys.readouterr()
    assert captured.out == "" and "render shadow" in captured.err and "chunk" in captured.err
    assert not captured.err.endswith("\n")  # erased when the call returns (leave=False)


def test04_a_studys_trials_show_no_bar_of_their_own(bars, tmp_path):
    """The reference's bar and the trials' bar; none from the renders inside them."""
    scene = tmp_path / "small.json"
    scene.write_text(json.dumps(_scene().to_dict()))
    config = StudyConfig.from_dict(
        {"problem": {"scene": "small.json", "param": PARAM}, "methods": [{"method": "naive"}],
         "spp": 2, "trials": 2, "reference": {"method": "boundary", "spp": 64}},
        package=PACKAGE, base_dir=tmp_path,
    )  # fmt: skip
    run_study(config, progress=True, grow_reference=False)
    assert [b.desc for b in bars] == ["reference boundary", "study"]
    assert bars[1].n == 2 and all(b.closed for b in bars)


def test05_the_command_lines_quiet_turns_it_off(bars, tmp_path, monkeypatch, capsys):
    """In a terminal the command line shows the bar, with --quiet not (figures left out: not the point)."""
    path = tmp_path / "small.json"
    path.write_text(json.dumps(_scene().to_dict()))
    package = dataclasses.replace(PACKAGE, plot_image=lambda *args, **kwargs: tmp_path / "x.png", sketch=None)
    monkeypatch.setattr("sys.stderr.isatty", lambda: True, raising=False)  # as in a terminal
    assert main(package, ["render", str(path), "--spp", "2", "--out", str(tmp_path)]) == 0
    assert [b.desc for b in bars] == ["render shadow"]
    assert main(package, ["render", str(path), "--spp", "2", "--out", str(tmp_path), "--quiet"]) == 0
    assert len(bars) == 1
    capsys.readouterr()


@pytest.mark.skipif(importlib.util.find_spec("embreex") is None, reason="needs the embree extra")
def test06_sphere3d_counts_its_thread_chunks_in_one_bar(bars, monkeypatch):
    """8 × 6 pixels × 4 spp in chunks of 16 samples (4 pixels): 12 chunks a pass, on the threads."""
    import sphere3d
    import sphere3d.tasks

    monkeypatch.setattr(sphere3d.tasks, "CHUNK", 16)
    data = sphere3d.load_scene("shadow").to_dict()
    data["camera"].update(width=8, height=6)
    scene = sphere3d.load_scene(data)
    quiet = sphere3d.render_gradient(scene, PARAM, method="finite_difference", spp=4, progress=False)
    shown = sphere3d.render_gradient(scene, PARAM, method="finite_difference", spp=4, progress=True)
    assert np.array_equal(quiet.derivative, shown.derivative) and np.array_equal(quiet.value, shown.value)
    (bar,) = bars
    assert bar.desc == "finite_difference shadow" and bar.n == 36 and set(bar.totals) == {36}
