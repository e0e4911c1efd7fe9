"""``python -m sphere3d``: the real commands in a subprocess (exit codes, files written).

The one-line errors of the real commands are checked for both packages in tests/test_contract.py.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("embreex")

from sphere3d.__main__ import PACKAGE, main
from sphere3d.scene import load_scene, parameter_names
from tests.tiers import HANG, SLOW

W, H = 16, 12


def run(*args):
    return subprocess.run(
        [sys.executable, "-m", "sphere3d", *map(str, args)], capture_output=True, text=True, timeout=HANG
    )


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    """The built-in shadow scene on a 16 × 12 film, as a JSON file."""
    data = load_scene("shadow").to_dict()
    data["camera"].update(width=W, height=H)
    path = tmp_path_factory.mktemp("scenes") / "small_shadow.json"
    path.write_text(json.dumps(data))
    return path


@SLOW
def test01_demo_writes_the_panel_and_the_error_table(tmp_path):
    result = run("demo", "--spp", 4, "--out", tmp_path, "--quiet")
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "demo_panel.png").stat().st_size > 20_000
    for method in ("naive", "boundary", "reparam", "finite_difference"):
        assert f"\n{method} " in result.stdout
    # the demo's own reference (Package.demo_reference): boundary at 20 × 4 spp, grown (up to 4 ×)
    # until its stderr is <= 1/4 of the unbiased methods', else a warning says it is not
    ratio = re.search(r"reference: boundary at (\d+) spp.*\n.* method's se = ([\d.]+)", result.stdout)
    assert ratio is not None and 80 <= int(ratio[1]) <= 320, result.stdout
    assert (float(ratio[2]) <= 0.25) == ("warning: the demo's reference" not in result.stderr)
    assert "BIASED" in result.stdout.split("\nnaive ")[1].splitlines()[0]  # naive misses the moving edge
    # boundary judged by a boundary reference: the table says its bias cannot show
    assert "boundary is the reference's own method" in result.stdout


@SLOW
def test02_render_and_gradient_write_png_and_npy(tmp_path, scene_file):
    """render in a subprocess, gradient in-process (the same command code)."""
    result = run("render", scene_file, "--spp", 4, "--out", tmp_path)
    assert result.returncode == 0, result.stderr
    image = np.load(tmp_path / "small_shadow.npy")
    assert image.shape == (H, W) and image.dtype.names == ("value", "value_stderr")  # as gradient's .npy
    assert (tmp_path / "small_shadow.png").stat().st_size > 3_000
    argv = ["gradient", str(scene_file), "--param", "occluder.translate.x", "--method", "finite_difference"]
    assert main([*argv, "--h", "0.05", "--spp", "4", "--out", str(tmp_path)]) == 0  # in-process
    png = tmp_path / "small_shadow_occluder.translate.x_finite_difference.png"
    npy = tmp_path / "small_shadow_occluder.translate.x_finite_difference.npy"
    data = np.load(npy)
    assert data.shape == (H, W) and data.dtype.names == (
        "value",
        "value_stderr",
        "derivative",
        "derivative_stderr",
    )
    assert np.any(data["derivative"] != 0.0) and png.stat().st_size > 3_000


@SLOW
def test03_study_on_a_scene_pixel(tmp_path, scene_file):
    """A study's default reference is finite differences (its ``h`` is accepted), not the demo's
    boundary: on one pixel boundary's reference grew to 314,352 spp (5.5 minutes). No ``naive`` cell:
    with the splatted film its derivative there is nearly 0 but not exactly (neighbours' samples on
    the occluder), a standard error of 0.0004 over two trials that the 1/4 rule would have the
    reference reach (8.5 million spp)."""
    assert (PACKAGE.reference_method, PACKAGE.demo_reference) == ("finite_difference", "boundary")
    config = {
        "name": "s3",
        "problem": {"scene": str(scene_file), "param": "occluder.translate.x", "pixel": [6, 8]},
        "methods": [{"method": "finite_difference", "h": 0.05}, {"method": "reparam", "kappa": [100, 1000]}],
        "spp": 2,
        "trials": 2,
        "reference": {"spp": 8, "h": 0.05},
    }
    path = tmp_path / "s3.json"
    path.write_text(json.dumps(config))
    assert main(["study", str(path), "--out", str(tmp_path), "--quiet"]) == 0  # in-process: the same code
    text = (tmp_path / "s3.csv").read_text()
    assert text.count("\n") == 4 and "small_shadow:occluder.translate.x[6,8]" in text
    assert (tmp_path / "s3_kappa.png").is_file() and (tmp_path / "s3_efficiency.png").is_file()


def test04_help_offers_the_sphere3d_methods_and_an_unknown_one_is_a_usage_error(tmp_path, capsys):
    """The help offers sphere3d's methods (boundary among them); argparse refuses others, naming them."""
    assert main(["gradient", "--help"]) == 0
    assert "--method {naive,finite_difference,boundary,reparam}" in capsys.readouterr().out
    argv = ["gradient", "shadow", "--param", "occluder.translate.x", "--method", "textbook"]
    assert main([*argv, "--out", str(tmp_path)]) == 2
    captured = capsys.readouterr()
    assert captured.err == (
        "error: gradient: argument --method: invalid choice: 'textbook' "
        "(choose from 'naive', 'finite_difference', 'boundary', 'reparam')\n"
    )


def test05_parameter_names_are_the_scene_parameters_and_all_accepted():
    scene = load_scene("shadow")
    names = parameter_names(scene)
    assert names == scene.parameters and all(scene.check_param(name) == name for name in names)
    # camera.translate.x|y|z, sky.emission; per shape translate.x|y|z, rotate.x|y|z, scale, albedo, emission
    assert len(names) == 3 + 1 + 9 * len(scene.shapes)


def test06_film_option_chooses_the_film_and_a_bad_one_is_one_line(tmp_path, scene_file, capsys):
    """``--film`` (render and gradient; default ``splat``) reaches the renderer: each film's image is
    the API's, bit for bit; a bad value is one line naming the field, exit status 2."""
    from sphere3d import render

    for verb in ("render", "gradient"):
        assert main([verb, "--help"]) == 0
        assert "--film FILM" in capsys.readouterr().out
    for film in (None, "pixel"):
        flag = [] if film is None else ["--film", film]
        out = tmp_path / str(film)
        assert main(["render", str(scene_file), "--spp", "2", "--out", str(out), *flag]) == 0
        expected = render(scene_file, spp=2, seed=0, **({} if film is None else {"film": film})).value
        assert np.array_equal(np.load(out / "small_shadow.npy")["value"], expected)
    assert not np.array_equal(np.load(tmp_path / "None/small_shadow.npy")["value"], expected)
    capsys.readouterr()
    assert main(["gradient", str(scene_file), "--param", "occluder.translate.x", "--film", "box"]) == 2
    assert capsys.readouterr().err == "error: film: must be one of splat, pixel; got 'box'\n"


def test07_optimize_writes_images_loss_and_history_and_refuses_bad_targets(tmp_path, scene_file, capsys):
    """``optimize``: from --target-theta and from a ``render`` .npy (images, loss and CSV written); a
    wrong-size target, an unknown parameter and a missing target are one line and status 2."""
    argv = ["optimize", str(scene_file), "--param", "occluder.translate.x", "--param", "occluder.albedo"]
    small = ["--steps", "3", "--spp", "2", "--target-spp", "8", "--quiet", "--out", str(tmp_path)]
    assert main([*argv, "--target-theta", "0.1", "-0.2", *small]) == 0
    out = capsys.readouterr().out
    assert "occluder.translate.x = " in out and "loss " in out
    for suffix in ("_images.png", "_loss.png"):
        assert (tmp_path / f"small_shadow_optimize_reparam{suffix}").stat().st_size > 1000
    history = np.loadtxt(tmp_path / "small_shadow_optimize_reparam.csv", delimiter=",", skiprows=1)
    assert history.shape == (4, 5)  # steps 0-3: step, loss, seconds and the two parameters
    assert main(["render", str(scene_file), "--spp", "2", "--quiet", "--out", str(tmp_path)]) == 0
    assert main([*argv, "--target", str(tmp_path / "small_shadow.npy"), *small]) == 0
    capsys.readouterr()
    np.save(tmp_path / "wrong.npy", np.zeros((H, W + 1)))
    cases = {
        "size": (
            ["--target", str(tmp_path / "wrong.npy")],
            f"error: targets[0]: must be an image of the view's {H} x {W}",
        ),
        "none": ([], "error: optimize: give exactly one of --target FILE.npy and --target-theta"),
        "param": (
            ["--param", "occluder.nope", "--target-theta", "0", "0", "0"],
            "error: params: unknown parameter",
        ),
    }
    for extra, message in cases.values():
        assert main([*argv, *extra, *small]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(message), lines
