"""``python -m flatland``: the real commands in a subprocess (exit codes, files written).

The one-line errors of the real commands are checked for both packages in tests/test_contract.py.

Extra error cases that need no subprocess run through ``flatland.__main__.main`` in-process:
bad arguments and bad JSON files are one line and status 2; an internal error is a
traceback and status 1.
"""

from __future__ import annotations

import json
import pickle
import subprocess
import sys
from functools import partial

import matplotlib.colors
import matplotlib.image as mpimg
import numpy as np
import pytest

from flatland.__main__ import PACKAGE, main
from flatland.app.study import load_config, read_csv
from flatland.core.validate import MAX_JSON_DEPTH, ValidationError, check_depth
from flatland.plotting.style import SKETCH_COLOURS
from flatland.scene import load_scene, parameter_names
from flatland.state import parse_parameter
from tests.tiers import HANG, SLOW


def run(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "flatland", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=HANG,
        cwd=cwd,
    )


def has_sketch(png, moving):
    """True if the PNG shows the scene sketch: emitter and camera colours (no other figure uses them),
    and the moving part's green exactly when a parameter moves something."""
    rgb = mpimg.imread(png)[..., :3]

    def count(key):
        target = np.array(matplotlib.colors.to_rgb(SKETCH_COLOURS[key]))
        return int(np.sum(np.all(np.abs(rgb - target) < 0.02, axis=-1)))

    return count("emitter") > 20 and count("camera") > 20 and (count("moving") > 20) == moving


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
    assert panel.stat().st_size > 20_000 and has_sketch(panel, moving=True)
    out = result.stdout
    for method in ("naive", "boundary", "reparam", "finite_difference"):
        assert f"\n{method} " in out
    assert "relative error" in out and "Textbook integrals" in out and "two_steps" in out


@SLOW
def test03_render_writes_png_and_structured_npy(tmp_path, scene_file):
    result = run("render", scene_file, "--spp", 8, "--seed", 3, "--out", tmp_path)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "small_shadow.png").stat().st_size > 5_000
    assert has_sketch(tmp_path / "small_shadow.png", moving=False)
    data = np.load(tmp_path / "small_shadow.npy")
    assert data.shape == (24,) and data.dtype.names == ("value", "value_stderr")  # as gradient's .npy
    assert np.all(data["value"] >= 0.0) and np.any(data["value"] > 0.0)


@SLOW
def test04_gradient_writes_value_derivative_and_standard_errors(tmp_path, scene_file):
    result = run(
        "gradient", scene_file, "--param", "occluder.translate.x", "--method", "reparam", "--kappa", 500,
        "--spp", 16, "--out", tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    png = tmp_path / "small_shadow_occluder.translate.x_reparam.png"
    npy = tmp_path / "small_shadow_occluder.translate.x_reparam.npy"
    assert png.stat().st_size > 5_000 and has_sketch(png, moving=True)
    data = np.load(npy)
    assert data.dtype.names == ("value", "value_stderr", "derivative", "derivative_stderr")
    assert (
        data.shape == (24,) and np.any(data["derivative"] != 0.0) and np.all(data["derivative_stderr"] >= 0)
    )
    assert "Σ dI/dθ" in result.stdout


@SLOW
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


@SLOW
def test08_builtin_study_by_name_with_overrides(tmp_path, capsys):
    assert main(["study", "kappa", "--spp", "500", "--seed", "4", "--out", str(tmp_path), "--quiet"]) == 0
    rows = read_csv(tmp_path / "kappa.csv")
    assert len(rows) == 14 and all(r["n"] == 500 and r["seed"] == 4 and r["trials"] == 20 for r in rows)
    out = capsys.readouterr().out
    assert "reparam kappa=10000 paired" in out
    assert "What to see: The κ trade-off (reparam, n=500;" in out  # the paragraph under the table


def test09_parameter_names_are_exactly_those_parse_parameter_accepts():
    """``gradient SCENE`` without --param lists these: a circle and a triangle, counted by hand."""
    scene = load_scene(
        {
            "name": "two",
            "camera": {"position": [0, -3], "direction": [0, 1], "fov": 0.8, "pixels": 4},
            "shapes": [
                {"name": "ball", "type": "circle", "center": [0, 0], "radius": 0.5, "emission": 1.0},
                {"name": "tri", "type": "polygon", "points": [[1, 0], [2, 0], [1, 1]]},
            ],
        }
    )
    names = parameter_names(scene)
    # camera: translate.x|y, rotate (3); circle: translate.x|y, scale, emission, albedo (5);
    # triangle: translate.x|y, rotate, scale, vertex.0-2.x|y, shape.0-2 (orders 0 and 1: 3 vertices
    # allow no order 2), emission, albedo (15)
    assert len(names) == 3 + 5 + 15 == len(set(names))
    assert all(parse_parameter(scene, name).name == name for name in names)
    refused_names = (
        "ball.rotate",
        "ball.vertex.0.x",
        "tri.vertex.3.x",
        "camera.scale",
        "ball.shape.0",
        "tri.shape.3",
    )
    for refused in refused_names:
        assert refused not in names
        with pytest.raises(ValidationError):
            parse_parameter(scene, refused)
    shadow = load_scene("shadow")
    assert set(shadow.parameters) <= set(parameter_names(shadow))  # the declared ones are among them


def _bad_json_files(folder):
    """Files ``load_scene`` and ``load_config`` must refuse with one ValidationError, and what it says."""
    folder.mkdir(exist_ok=True)
    files = {
        "deep.json": ("[" * 65 + "]" * 65, "JSON nested deeper than 64 levels"),  # one past the limit
        "binary.json": (b"\xff\xfe{}", "is not UTF-8 text (byte 0)"),
        "huge_int.json": ('{"name": ' + "9" * 5000 + "}", "invalid JSON: Exceeds the limit"),
        "trailing.json": ('{"name": "x",}', "invalid JSON: Expecting property name"),
    }
    for name, (content, _) in files.items():
        path = folder / name
        path.write_bytes(content) if isinstance(content, bytes) else path.write_text(content)
    (folder / "folder.json").mkdir(exist_ok=True)
    return {folder / k: v for k, (_, v) in files.items()} | {folder / "folder.json": "cannot be read"}


def test10_every_bad_json_file_is_one_validation_error_naming_the_file(tmp_path):
    """A binary file or a 5000-digit integer raised UnicodeDecodeError/ValueError: now a user error."""
    for path, message in _bad_json_files(tmp_path / "bad").items():
        for load, what in ((load_scene, "scene"), (partial(load_config, package=PACKAGE), "config")):
            with pytest.raises(ValidationError) as info:
                load(path)
            assert info.value.field == f"{what} file {str(path)!r}"
            assert str(info.value).startswith(f"{what} file {str(path)!r}: {message}"), str(info.value)


def test11_bad_json_files_on_the_command_line_are_one_line_and_status_2(tmp_path, capsys):
    for path, message in _bad_json_files(tmp_path / "bad").items():
        for argv in (["render", str(path)], ["study", str(path)]):
            assert main([*argv, "--out", str(tmp_path / "out")]) == 2, argv
            lines = capsys.readouterr().err.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], lines


def test12_depth_is_counted_without_recursion_up_to_the_limit():
    value = 0  # a scalar has depth 0, [0] depth 1
    for _ in range(MAX_JSON_DEPTH):
        value = [value]
    assert check_depth("scene", {"a": value[0]}) == {"a": value[0]}  # depth exactly 64
    with pytest.raises(ValidationError, match=r"^scene: JSON nested deeper than 64 levels$"):
        check_depth("scene", {"a": value})
    cycle = {"shapes": []}
    cycle["shapes"].append(cycle)  # a dict that holds itself: refused, not an endless walk
    with pytest.raises(ValidationError, match="nested deeper"):
        load_scene(cycle)
    shared = [0.0]
    for _ in range(MAX_JSON_DEPTH - 2):
        shared = [shared, shared]  # 2**62 paths through 63 distinct lists: each walked once per level
    assert check_depth("scene", {"a": shared})["a"] is shared


def test13_validation_errors_cross_process_boundaries_as_themselves():
    """Study workers send their errors back pickled; they used to arrive as a plain ValueError."""
    error = pickle.loads(pickle.dumps(ValidationError("methods[0].kappa", "must be > 0, got -2")))
    assert type(error) is ValidationError and error.field == "methods[0].kappa"
    assert str(error) == "methods[0].kappa: must be > 0, got -2"


@SLOW
def test14_a_real_internal_error_exits_1_with_its_traceback(tmp_path):
    """As a real process: a ValueError from inside render (a bug) is not reported as a usage error."""
    code = (
        "import importlib, sys\n"
        "r = importlib.import_module('flatland.render')  # the module (flatland.render is also a function)\n"
        "def broken(*a, **k):\n"
        "    raise ValueError('operands could not be broadcast together')\n"
        "r.render = broken\n"
        "from flatland.__main__ import main\n"
        f"sys.exit(main(['render', 'shadow', '--out', {str(tmp_path)!r}]))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=HANG)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 1 and lines[0] == "Traceback (most recent call last):", result.stderr
    assert lines[-1].startswith("internal error: ValueError in python -m flatland: operands could not")
    assert "error: " not in lines[-1].split("internal error: ", 1)[0]


def test15_an_unwritable_output_folder_is_a_user_error(tmp_path, capsys):
    """OSError stays a user error: --out names an existing file."""
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main(["render", "shadow", "--spp", "1", "--out", str(blocker)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and str(blocker) in lines[0], lines


def test16_a_malformed_scheduler_address_is_a_user_error(tmp_path, capsys):
    """dask raises a plain ValueError for it, which would otherwise be reported as an internal error."""
    pytest.importorskip("distributed")
    argv = ["study", "kappa", "--spp", "100", "--scheduler", "nonsense", "--quiet", "--out", str(tmp_path)]
    assert main(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [
        "error: scheduler: cannot connect to 'nonsense': missing port number in address 'nonsense'"
    ]


def test17_finite_difference_step_too_large_for_a_scale_parameter(tmp_path):
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


def test18_optimize_writes_images_loss_and_history_and_refuses_bad_targets(tmp_path, scene_file, capsys):
    """``optimize``: from --target-theta and from a ``render`` .npy; a wrong-size target, a missing target
    and a parameter count that does not match --target-theta are one line and status 2."""
    argv = ["optimize", str(scene_file), "--param", "occluder.translate.x", "--param", "occluder.albedo"]
    small = ["--steps", "3", "--spp", "4", "--target-spp", "16", "--quiet", "--out", str(tmp_path)]
    assert main([*argv, "--target-theta", "0.1", "0.2", *small]) == 0
    out = capsys.readouterr().out
    assert "occluder.translate.x = " in out and "loss " in out
    for suffix in ("_images.png", "_loss.png"):
        assert mpimg.imread(tmp_path / f"small_shadow_optimize_reparam{suffix}").shape[0] > 100
    history = np.loadtxt(tmp_path / "small_shadow_optimize_reparam.csv", delimiter=",", skiprows=1)
    assert history.shape == (4, 5)  # steps 0-3: step, loss, seconds and the two parameters
    assert main(["render", str(scene_file), "--spp", "4", "--quiet", "--out", str(tmp_path)]) == 0
    assert main([*argv, "--target", str(tmp_path / "small_shadow.npy"), *small]) == 0
    capsys.readouterr()
    np.save(tmp_path / "wrong.npy", np.zeros(7))
    cases = {
        "--target": (
            ["--target", str(tmp_path / "wrong.npy")],
            "error: targets[0]: must be an image of the view's 24",
        ),
        "none": ([], "error: optimize: give exactly one of --target FILE.npy and --target-theta"),
        "count": (["--target-theta", "0.1"], "error: target-theta: needs one offset per --param (2)"),
    }
    for extra, message in cases.values():
        assert main([*argv, *extra, *small]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(message), lines


def test19_max_depth_renders_longer_paths_and_a_bad_one_is_one_line(tmp_path, scene_file, capsys):
    """``--max-depth`` reaches render and gradient: depth 3 adds light (never removes it; in this scene
    the first extra light is the floor's, bounced off the occluder's underside back to the floor: three
    vertices), naive and reparam take it, paired reparam refuses it and 0 is refused, one line each."""
    base = ["render", str(scene_file), "--spp", "4", "--quiet"]
    assert main([*base, "--out", str(tmp_path / "d1")]) == 0
    assert main([*base, "--max-depth", "3", "--out", str(tmp_path / "d2")]) == 0
    one, two = (np.load(tmp_path / d / "small_shadow.npy")["value"] for d in ("d1", "d2"))
    assert np.all(two >= one - 1e-12) and np.any(two > one)
    grad = ["gradient", str(scene_file), "--param", "occluder.albedo", "--spp", "4", "--quiet"]
    assert main([*grad, "--method", "naive", "--max-depth", "2", "--out", str(tmp_path)]) == 0
    assert main([*grad, "--method", "reparam", "--max-depth", "2", "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    for argv, message in (
        ([*base, "--max-depth", "0", "--out", str(tmp_path)], "error: max_depth: "),
        (
            [*grad, "--method", "reparam", "--paired", "--max-depth", "2", "--out", str(tmp_path)],
            "error: paired: ",
        ),
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(message)
