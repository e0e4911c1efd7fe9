"""``python -m flatland``: the real commands in a subprocess (exit codes, files written).

The one-line errors of the real commands are checked for both packages in tests/test_contract.py.

Extra error cases that need no subprocess run through ``flatland.__main__.main`` in-process.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from flatland.__main__ import main
from flatland.core.study import read_csv
from flatland.scene import load_scene


def run(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "flatland", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=cwd,
    )


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    """The built-in shadow scene with a 24-pixel film, as a JSON file."""
    path = tmp_path_factory.mktemp("scenes") / "small_shadow.json"
    path.write_text(json.dumps(load_scene("shadow").with_camera(pixels=24).to_dict()))
    return path


def test01_help_on_every_verb(capsys):
    top = run("--help")
    assert top.returncode == 0 and all(v in top.stdout for v in ("demo", "render", "gradient", "study"))
    for verb in ("demo", "render", "gradient", "study"):  # in-process: the same parser, no start-up cost
        assert main([verb, "--help"]) == 0
        out = capsys.readouterr().out
        assert all(flag in out for flag in ("--seed", "--spp", "--out", "--quiet")), verb


def test02_demo_writes_the_panel_and_prints_both_tables(tmp_path):
    result = run("demo", "--spp", 32, "--out", tmp_path / "demo", "--quiet")
    assert result.returncode == 0, result.stderr
    panel = tmp_path / "demo" / "demo_panel.png"
    assert panel.stat().st_size > 20_000
    out = result.stdout
    for method in ("naive", "boundary", "reparam", "finite_difference"):
        assert f"\n{method} " in out
    assert "relative error" in out and "Textbook integrals" in out and "two_steps" in out


def test03_render_writes_png_and_structured_npy(tmp_path, scene_file):
    result = run("render", scene_file, "--spp", 8, "--seed", 3, "--out", tmp_path)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "small_shadow.png").stat().st_size > 5_000
    data = np.load(tmp_path / "small_shadow.npy")
    assert data.shape == (24,) and data.dtype.names == ("value", "stderr")
    assert np.all(data["value"] >= 0.0) and np.any(data["value"] > 0.0)


def test04_gradient_writes_value_derivative_and_standard_errors(tmp_path, scene_file):
    result = run(
        "gradient", scene_file, "--param", "occluder.translate.x", "--method", "reparam", "--kappa", 500,
        "--spp", 16, "--out", tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    png = tmp_path / "small_shadow_occluder.translate.x_reparam.png"
    npy = tmp_path / "small_shadow_occluder.translate.x_reparam.npy"
    assert png.stat().st_size > 5_000
    data = np.load(npy)
    assert data.dtype.names == ("value", "value_stderr", "derivative", "derivative_stderr")
    assert (
        data.shape == (24,) and np.any(data["derivative"] != 0.0) and np.all(data["derivative_stderr"] >= 0)
    )
    assert "Σ dI/dθ" in result.stdout


def test05_study_on_a_scene_writes_csv_and_figures(tmp_path, scene_file):
    config = {
        "name": "scene_study",
        "problem": {"scene": scene_file.name, "param": "occluder.translate.x"},
        "methods": [{"method": "naive"}, {"method": "reparam", "kappa": [100, 1000]}],
        "spp": 4,
        "trials": 3,
        "reference": {"method": "boundary", "spp": 64},
    }
    path = scene_file.parent / "scene_study.json"  # the scene path is relative to the config's folder
    path.write_text(json.dumps(config))
    # in-process (the study verb runs in a subprocess in test_study_cli.py)
    assert main(["study", str(path), "--out", str(tmp_path), "--quiet", "--workers", "1"]) == 0
    rows = read_csv(tmp_path / "scene_study.csv")
    assert [r["method"] for r in rows] == ["naive", "reparam", "reparam"]
    assert [r["kappa"] for r in rows] == [None, 100.0, 1000.0]
    assert all(r["samples"] == 4 * 24 and r["reference_stderr"] > 0.0 for r in rows)
    assert (tmp_path / "scene_study_kappa.png").is_file() and (
        tmp_path / "scene_study_efficiency.png"
    ).is_file()
    assert len(list((tmp_path / ".cache" / "reparam-lab").glob("*.npz"))) == 1


@pytest.mark.parametrize(
    ("argv", "fragments"),
    [
        (["fly"], ["invalid choice", "fly"]),
        (["gradient", "shadow"], ["--param"]),
        (["render", "shadow", "--spp", "many"], ["--spp", "many"]),
        (["render", "nowhere"], ["unknown scene", "nowhere"]),
        (["render", "shadow", "--seed", "-1"], ["seed"]),
        (["gradient", "shadow", "--param", "occluder.translate.x", "--method", "magic"], ["method", "magic"]),
        (
            ["gradient", "shadow", "--param", "occluder.translate.x", "--method", "naive", "--kappa", "10"],
            ["kappa"],
        ),
        (["gradient", "shadow", "--param", "occluder.translate.x", "--kappa", "-1"], ["kappa", "-1"]),
        (["render", "shadow", "--spp", "8", "--batches", "3"], ["batches"]),
        (["study", "no_such_study.json"], ["no_such_study.json"]),
    ],
)
def test06_more_bad_arguments_in_process(argv, fragments, capsys, tmp_path):
    assert main([*argv, "--out", str(tmp_path)] if argv[0] != "fly" else argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and captured.out == ""
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])


def test07_bad_study_configuration_names_the_field(tmp_path, capsys):
    path = tmp_path / "bad.json"
    path.write_text(
        json.dumps(
            {"problem": {"integral": "step"}, "methods": [{"method": "reparam", "kappa": 0}], "n": 100}
        )
    )
    assert main(["study", str(path), "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err.startswith("error: methods[0].kappa: must be > 0")


def test08_builtin_study_by_name_with_overrides(tmp_path, capsys):
    assert main(["study", "kappa", "--spp", "500", "--seed", "4", "--out", str(tmp_path), "--quiet"]) == 0
    rows = read_csv(tmp_path / "kappa.csv")
    assert len(rows) == 14 and all(r["n"] == 500 and r["seed"] == 4 and r["trials"] == 20 for r in rows)
    assert "reparam kappa=10000 paired" in capsys.readouterr().out


def test09_finite_difference_step_too_large_for_a_scale_parameter(tmp_path):
    """``--h 1`` on a ``*.scale`` parameter would scale the shape by 1 - h = 0: one line, exit 2."""
    argv = ["gradient", "polygon", "--param", "polygon.scale", "--method", "finite_difference", "--h", "1"]
    out = run(*argv, "--spp", "4", "--out", tmp_path, "--quiet")
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and out.stdout == "" and len(lines) == 1, out
    expected = (
        "h: must be < 1 for a scale parameter (the scale 1 - h must stay > 0), got 1.0 for 'polygon.scale'"
    )
    assert lines[0] == f"error: {expected}"
    assert not any(tmp_path.iterdir())
