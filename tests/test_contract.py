"""The shared contract, checked identically over every renderer package that is installed.

API names, result types, method and option names, the command-line verbs and the
one-line error behaviour (DESIGN 5), in-process and as real commands in a subprocess
(a missing file, a malformed JSON scene, an unknown parameter, a negative spp).
Scenes are the built-in ``shadow`` on a small film.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import subprocess
import sys

import numpy as np
import pytest

from flatland.core.contract import MethodTable
from flatland.core.image import GradientImage, Image
from flatland.core.validate import ValidationError

PACKAGES = [
    "flatland",
    pytest.param(
        "sphere3d",
        marks=pytest.mark.skipif(
            importlib.util.find_spec("embreex") is None, reason="needs the embree extra"
        ),
    ),
]
SHARED_METHODS = ("naive", "finite_difference", "reparam")
VERBS = ("demo", "render", "gradient", "study")
PARAM = "occluder.translate.x"


def _small_scene(name):
    """The built-in shadow scene on a small film, and the film's shape."""
    scene_module = importlib.import_module(f"{name}.scene")
    data = scene_module.load_scene("shadow").to_dict()
    if name == "flatland":
        data["camera"]["pixels"] = 12
        shape = (12,)
    else:
        data["camera"].update(width=8, height=6)
        shape = (6, 8)
    return scene_module.load_scene(data), shape


@pytest.fixture(params=PACKAGES)
def package(request):
    return request.param


def test01_api_names(package):
    scene = importlib.import_module(f"{package}.scene")
    render = importlib.import_module(f"{package}.render")
    plot = importlib.import_module(f"{package}.plot")
    main = importlib.import_module(f"{package}.__main__")
    assert callable(scene.load_scene) and "shadow" in scene.list_scenes()
    assert callable(render.render) and callable(render.render_gradient)
    assert isinstance(render.GRADIENT_METHODS, MethodTable)
    for name in ("plot_image", "plot_gradient", "plot_panel", "plot_kappa", "plot_efficiency", "plot_study"):
        assert callable(getattr(plot, name)), name
    assert callable(main.main)


def test02_method_and_option_names(package):
    table = importlib.import_module(f"{package}.render").GRADIENT_METHODS
    assert set(SHARED_METHODS) <= set(table.names)
    assert ("boundary" in table.names) == (package == "flatland")  # sphere3d has no boundary method
    assert {"kappa", "probes", "paired"} <= set(table.get("reparam").options)
    assert "h" in table.get("finite_difference").options
    assert not table.get("naive").options


def test03_result_types_and_shared_primary_samples(package):
    render = importlib.import_module(f"{package}.render")
    scene, shape = _small_scene(package)
    image = render.render(scene, spp=4, seed=5)
    assert isinstance(image, Image) and image.shape == shape and image.stderr.shape == shape
    assert (image.spp, image.seed) == (4, 5) and np.all(np.isfinite(image.value))
    results = {
        m: render.render_gradient(scene, PARAM, method=m, spp=4, seed=5)
        for m in render.GRADIENT_METHODS.names
    }
    for method, g in results.items():
        assert isinstance(g, GradientImage) and g.shape == shape
        assert g.derivative.shape == g.value_stderr.shape == g.derivative_stderr.shape == shape
        assert (g.param, g.method, g.spp, g.seed) == (PARAM, method, 4, 5)
        assert np.all(np.isfinite(g.derivative))
    # T(·, θ0) is the identity: the reparameterized primal is the naive one, bit for bit (DESIGN 2.5)
    assert np.array_equal(results["reparam"].value, results["naive"].value)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"spp": 0}, "spp"),
        ({"param": "occluder.spin"}, "param"),
        ({"kappa": 0.0}, "kappa"),
        ({"method": "magic"}, "method"),
        ({"method": "naive", "kappa": 10.0}, "kappa"),
        ({"seed": -1}, "seed"),
    ],
)
def test04_bad_input_raises_one_error_naming_the_field(package, kwargs, field):
    render = importlib.import_module(f"{package}.render")
    scene, _ = _small_scene(package)
    call = {"param": PARAM, "method": "reparam", "spp": 2, "seed": 0} | kwargs
    with pytest.raises(ValidationError) as info:
        render.render_gradient(scene, **call)
    assert info.value.field == field and str(info.value).startswith(f"{field}: ")


def test05_same_cli_verbs_and_one_line_errors(package, tmp_path, capsys):
    main = importlib.import_module(f"{package}.__main__").main
    assert main(["--help"]) == 0
    help_text = capsys.readouterr().out
    assert all(verb in help_text for verb in VERBS)
    broken = tmp_path / "broken.json"
    broken.write_text('{"name": [')
    bad_study = tmp_path / "study.json"
    bad_study.write_text(
        json.dumps({"problem": {"scene": "shadow", "param": PARAM}, "methods": [], "spp": 2})
    )
    cases = [
        (["render", str(tmp_path / "missing.json")], "missing.json"),
        (["render", str(broken)], "JSON"),
        (["gradient", "shadow", "--param", "occluder.spin"], "occluder.spin"),
        (["render", "shadow", "--spp", "-1"], "spp"),
        (["gradient", "shadow", "--param", PARAM, "--kappa", "0"], "kappa"),
        (["study", str(bad_study)], "methods"),
        (["teleport"], "teleport"),
    ]
    for argv, fragment in cases:
        assert main([*argv, "--out", str(tmp_path)] if argv[0] != "teleport" else argv) == 2, argv
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and fragment in lines[0], (
            argv,
            captured.err,
        )
        assert captured.out == ""


@pytest.fixture(scope="module", params=PACKAGES)
def error_runs(request, tmp_path_factory):
    """The four bad commands of the CLI issue, as real ``python -m PACKAGE`` processes, started together."""
    package = request.param
    folder = tmp_path_factory.mktemp(f"errors_{package}")
    scene_file = folder / "small_shadow.json"
    scene_file.write_text(json.dumps(_small_scene(package)[0].to_dict()))
    broken = folder / "broken.json"
    broken.write_text('{"name": "broken", "shapes": [}')
    commands = {
        "missing file": ["render", folder / "missing.json"],
        "malformed JSON": ["gradient", broken, "--param", PARAM],
        "unknown parameter": ["gradient", scene_file, "--param", "occluder.spin"],
        "negative spp": ["render", scene_file, "--spp", -4],
    }
    procs = {
        name: subprocess.Popen(
            [sys.executable, "-m", package, *map(str, argv), "--out", str(folder)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for name, argv in commands.items()
    }
    results = {}
    for name, proc in procs.items():
        out, err = proc.communicate(timeout=180)
        results[name] = subprocess.CompletedProcess(proc.args, proc.returncode, out, err)
    return results


@pytest.mark.parametrize(
    ("case", "fragments"),
    [
        ("missing file", ["missing.json"]),
        ("malformed JSON", ["broken.json", "JSON"]),
        ("unknown parameter", ["param", "occluder.spin"]),
        ("negative spp", ["spp", "-4"]),
    ],
)
def test06_real_commands_fail_with_one_line_and_status_2(error_runs, case, fragments):
    result = error_runs[case]
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, (result.returncode, result.stderr)
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert "Traceback" not in result.stderr and result.stdout == ""
    assert all(f in lines[0] for f in fragments), (fragments, lines[0])
