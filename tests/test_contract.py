"""The shared contract, checked identically over every renderer package that is installed.

API names, result types, method and option names, the command-line verbs and the
one-line error behaviour (theory/architecture), in-process and as real commands in a subprocess
(a missing file, a malformed JSON scene, an unknown parameter, a negative spp, a scene
nested 100 000 deep). An internal error is a traceback and status 1, never a usage
error. The command line names what exists: scenes, methods, parameters, studies.
A new gradient method plugs in through the method table and ``render_gradient``, and
the table is as before once it is unregistered. Scenes are the built-in ``shadow`` on
a small film.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.util
import json
import re
import subprocess
import sys

import numpy as np
import pytest

from flatland.app.study import load_config
from flatland.core.contract import MethodTable, Option
from flatland.core.image import GradientImage, Image
from flatland.core.validate import MAX_JSON_DEPTH, ValidationError, check_positive
from tests.tiers import HANG, SLOW

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
VERBS = ("demo", "render", "gradient", "study", "optimize")
PARAM = "occluder.translate.x"
DEEP = 100_000
"""Nesting depth of the deep JSON files: far past Python's recursion limit (1000)."""
TOO_DEEP = f"JSON nested deeper than {MAX_JSON_DEPTH} levels"


def _deep_text(depth=DEEP):
    """A JSON object holding ``depth`` nested lists, as text."""
    return '{"name": ' + "[" * depth + "]" * depth + "}"


def _deep_value(depth=DEEP):
    """The same as a Python dict (built without recursion)."""
    value = []
    for _ in range(depth - 1):
        value = [value]
    return {"name": value}


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
    assert "boundary" in table.names  # both packages have one (sphere3d's samples mesh edges)
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
    # T(·, θ0) is the identity: the reparameterized primal is the naive one, bit for bit
    # (Loubet et al. 2019, Sec. 3.2)
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
    """The bad commands, as real ``python -m PACKAGE`` processes, started together."""
    package = request.param
    folder = tmp_path_factory.mktemp(f"errors_{package}")
    scene_file = folder / "small_shadow.json"
    scene_file.write_text(json.dumps(_small_scene(package)[0].to_dict()))
    broken = folder / "broken.json"
    broken.write_text('{"name": "broken", "shapes": [}')
    deep = folder / "deep.json"
    deep.write_text(_deep_text())
    commands = {
        "missing file": ["render", folder / "missing.json"],
        "malformed JSON": ["gradient", broken, "--param", PARAM],
        "unknown parameter": ["gradient", scene_file, "--param", "occluder.spin"],
        "negative spp": ["render", scene_file, "--spp", -4],
        "deep scene": ["render", deep],
        "deep study": ["study", deep],
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
        out, err = proc.communicate(timeout=HANG)
        results[name] = subprocess.CompletedProcess(proc.args, proc.returncode, out, err)
    return results


@pytest.mark.parametrize(
    ("case", "fragments"),
    [
        ("missing file", ["missing.json"]),
        ("malformed JSON", ["broken.json", "JSON"]),
        ("unknown parameter", ["param", "occluder.spin"]),
        ("negative spp", ["spp", "-4"]),
        ("deep scene", ["scene file", "deep.json", TOO_DEEP]),
        ("deep study", ["config file", "deep.json", TOO_DEEP]),
    ],
)
@SLOW
def test06_real_commands_fail_with_one_line_and_status_2(error_runs, case, fragments):
    result = error_runs[case]
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, (result.returncode, result.stderr)
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert "Traceback" not in result.stderr and result.stdout == ""
    assert all(f in lines[0] for f in fragments), (fragments, lines[0])


def test07_deep_json_is_one_error_from_every_load_function(package, tmp_path):
    """Scene and study loaders, from a file and from a dict: a ValidationError, not a RecursionError."""
    load_scene = importlib.import_module(f"{package}.scene").load_scene
    description = importlib.import_module(f"{package}.__main__").PACKAGE
    deep = tmp_path / "deep.json"
    deep.write_text(_deep_text())
    loads = {
        "scene file": lambda: load_scene(deep),
        "scene dict": lambda: load_scene(_deep_value()),
        "config file": lambda: load_config(deep, package=description),
        "config dict": lambda: load_config(_deep_value(), package=description),
    }
    for source, load in loads.items():
        with pytest.raises(ValidationError) as info:
            load()
        assert TOO_DEEP in str(info.value), (source, str(info.value)[:200])
        assert info.value.field == (
            f"{source.split()[0]} file {str(deep)!r}" if "file" in source else source.split()[0]
        )


@pytest.mark.parametrize("verb", ["render", "gradient", "study"])
def test08_deep_json_on_the_command_line_is_one_line_and_status_2(package, verb, tmp_path, capsys):
    main = importlib.import_module(f"{package}.__main__").main
    deep = tmp_path / "deep.json"
    deep.write_text(_deep_text())
    extra = ["--param", PARAM] if verb == "gradient" else []
    assert main([verb, str(deep), *extra, "--out", str(tmp_path)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and TOO_DEEP in lines[0], captured.err
    assert captured.out == ""


@pytest.mark.parametrize(
    ("verb", "target"),
    [("render", "render"), ("gradient", "render_gradient"), ("study", "study.run_study")],
)
@pytest.mark.parametrize("error", [ValueError("operands could not be broadcast"), IndexError("index 7")])
def test09_an_internal_error_is_a_traceback_and_status_1_not_a_usage_error(
    package, verb, target, error, tmp_path, capsys, monkeypatch
):
    """A ValueError or IndexError from deep inside (a bug) is never reported as the user's mistake."""
    entry = importlib.import_module(f"{package}.__main__")

    def broken(*args, **kwargs):
        raise error

    if target.startswith("study."):  # the study runner of the application layer
        monkeypatch.setattr(importlib.import_module("flatland.app.study"), "run_study", broken)
    else:  # the package's function, as its description hands it to the command line
        monkeypatch.setattr(entry, "PACKAGE", dataclasses.replace(entry.PACKAGE, **{target: broken}))
    main = entry.main
    argv = {
        "render": ["render", "shadow", "--spp", "1"],
        "gradient": ["gradient", "shadow", "--param", PARAM, "--spp", "1"],
        "study": ["study", "shadow", "--spp", "1", "--quiet"],
    }[verb]
    assert main([*argv, "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert lines[0] == "Traceback (most recent call last):" and f"{type(error).__name__}: {error}" in err
    assert lines[-1].startswith("internal error: ") and str(error) in lines[-1]
    assert not any(line.startswith("error: ") for line in lines)


def test10_a_validation_error_from_the_same_place_is_one_line_and_status_2(
    package, tmp_path, capsys, monkeypatch
):
    """The counterpart of test09: the class decides, not where it is raised."""
    entry = importlib.import_module(f"{package}.__main__")

    def refuses(*args, **kwargs):
        raise ValidationError("spp", "must be an integer >= 1, got 0")

    monkeypatch.setattr(entry, "PACKAGE", dataclasses.replace(entry.PACKAGE, render=refuses))
    main = entry.main
    assert main(["render", "shadow", "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err == "error: spp: must be an integer >= 1, got 0\n"


def _help(main, argv, capsys):
    assert main([*argv, "--help"]) == 0
    return capsys.readouterr().out.split()


def test11_help_lists_the_builtin_scenes_and_only_the_package_methods(package, capsys):
    main = importlib.import_module(f"{package}.__main__").main
    scenes = importlib.import_module(f"{package}.scene").list_scenes()
    methods = importlib.import_module(f"{package}.render").GRADIENT_METHODS.names
    for verb in ("render", "gradient"):
        words = " ".join(_help(main, [verb], capsys))
        assert all(re.search(rf"\b{name}\b", words) for name in scenes), (verb, words)
    words = " ".join(_help(main, ["gradient"], capsys))
    assert "--method {" + ",".join(methods) + "}" in words
    assert ("boundary" in words) == ("boundary" in methods)  # the help offers exactly the package's methods


def test12_a_method_the_package_lacks_is_a_usage_error_listing_the_choices(package, tmp_path, capsys):
    main = importlib.import_module(f"{package}.__main__").main
    methods = importlib.import_module(f"{package}.render").GRADIENT_METHODS.names
    assert main(["gradient", "shadow", "--param", PARAM, "--method", "magic", "--out", str(tmp_path)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "invalid choice: 'magic'" in lines[0]
    assert all(repr(m) in lines[0] for m in methods)


def test13_gradient_without_param_names_the_scene_parameters(package, tmp_path, capsys):
    main = importlib.import_module(f"{package}.__main__").main
    scene_module = importlib.import_module(f"{package}.scene")
    names = scene_module.parameter_names(scene_module.load_scene("shadow"))
    assert PARAM in names and len(names) == len(set(names))
    assert main(["gradient", "shadow", "--out", str(tmp_path)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and captured.out == ""
    assert lines[0] == f"error: gradient: --param is required; parameters of 'shadow': {', '.join(names)}"


def test14_an_unknown_study_lists_the_builtin_studies(package, tmp_path, capsys):
    main = importlib.import_module(f"{package}.__main__")
    studies = tuple(main.PACKAGE.studies)
    assert studies and "shadow" in studies
    assert main.main(["study", "nosuch", "--out", str(tmp_path)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "'nosuch'" in lines[0]
    assert lines[0].endswith("built-in studies: " + ", ".join(studies))
    words = " ".join(_help(main.main, ["study"], capsys))
    assert all(re.search(rf"\b{name}\b", words) for name in studies)


# ------------------------------------------------------------------ a new method plugs in
SMOOTH_PARAM = "light.translate.x"
"""A parameter whose naive derivative is nonzero on the small films of both packages."""


def _naive_scaled(package):
    """A method defined here: the naive estimator through identity transforms written out, its
    derivative times the option ``scale`` (``scale=1`` is the naive method, by construction)."""
    from flatland.core.dual import variable

    if package == "flatland":
        from flatland.integrator import Identity, Members
        from flatland.tasks import Tally

        class PassThrough(Identity):  # the identity, as a new method's transforms start out
            def camera(self, ctx, t, pixel, draws):
                return Members(t[:, None])

            def directions(self, ctx, x, ignore, phi, draws):
                return Members(phi[:, None])

        def naive_scaled(task, scale):
            result = task.evaluate(variable(0.0), PassThrough())
            return Tally(result.value, scale * result.derivative)

        return naive_scaled

    from flatland.core.dual import Dual
    from sphere3d.film import FilmTransform
    from sphere3d.integrator import EmitterChange, Identity, Members
    from sphere3d.rotation import Rotation
    from sphere3d.tasks import Tally

    class PassThroughTransforms(Identity):  # the identity, as a new method's transforms start out
        def camera(self, state, x, y, draws):
            return FilmTransform.identity(x.shape)

        def emitter(self, shading, visible):
            rows = np.flatnonzero(visible)
            return EmitterChange(Rotation.identity((len(rows),)), rows)

        def bsdf(self, shading, mu, hits):
            return Members(Dual(mu) if shading.state.dual else mu)

    def naive_scaled(task, scale):
        tally = task.evaluate(variable(0.0), PassThroughTransforms())
        return Tally(value=tally.value, derivative=scale * tally.derivative)

    return naive_scaled


def test15_a_new_method_plugs_in_through_render_gradient_and_is_removed_after(package):
    render = importlib.import_module(f"{package}.render")
    table = render.GRADIENT_METHODS
    before = table.names
    scene, _ = _small_scene(package)
    naive = render.render_gradient(scene, SMOOTH_PARAM, "naive", spp=4, seed=5)
    assert np.any(naive.derivative != 0.0)  # else the comparisons below could not fail
    with table.registered("naive_scaled", _naive_scaled(package), Option("scale", 1.0, check_positive)):
        assert table.names == (*before, "naive_scaled")
        one = render.render_gradient(scene, SMOOTH_PARAM, "naive_scaled", spp=4, seed=5)
        two = render.render_gradient(scene, SMOOTH_PARAM, "naive_scaled", spp=4, seed=5, scale=2.0)
        assert (one.method, dict(one.options), dict(two.options)) == (
            "naive_scaled",
            {"scale": 1.0},
            {"scale": 2.0},
        )
        # identity transforms at θ0 are the naive estimator, bit for bit
        for field in ("value", "derivative", "value_stderr", "derivative_stderr"):
            assert np.array_equal(getattr(one, field), getattr(naive, field)), field
        # scaling by 2 is exact in binary floating point: the mean and its standard error double exactly
        assert np.array_equal(two.value, naive.value)
        assert np.array_equal(two.derivative, 2.0 * naive.derivative)
        assert np.array_equal(two.derivative_stderr, 2.0 * naive.derivative_stderr)
        with pytest.raises(ValidationError, match=r"scale.*-1\.0"):
            render.render_gradient(scene, SMOOTH_PARAM, "naive_scaled", spp=4, seed=5, scale=-1.0)
        with pytest.raises(ValidationError, match=r"kappa.*naive_scaled.*\(options: scale\)"):
            render.render_gradient(scene, SMOOTH_PARAM, "naive_scaled", spp=4, seed=5, kappa=1.0)
    assert table.names == before
    with pytest.raises(ValidationError, match="unknown gradient method 'naive_scaled'"):
        render.render_gradient(scene, SMOOTH_PARAM, "naive_scaled", spp=4, seed=5)


def test16_a_temporary_registration_survives_an_error_and_never_shadows_a_method(package):
    table = importlib.import_module(f"{package}.render").GRADIENT_METHODS
    before, naive = table.names, table.get("naive")
    with (
        pytest.raises(RuntimeError, match="inside the block"),
        table.registered("temporary", lambda job: None),
    ):
        raise RuntimeError("inside the block")
    assert table.names == before
    with pytest.raises(ValueError, match="'naive' is already registered"), table.registered("naive", print):
        pass
    assert table.names == before and table.get("naive") is naive
    with pytest.raises(KeyError, match="'temporary' is not registered"):
        table.unregister("temporary")


def test17_the_method_table_is_a_read_only_mapping_in_one_order(package):
    """``'boundary' in table``, iteration, ``table[name]`` as for any mapping; both packages and the
    textbook estimators list naive, finite_difference, boundary, reparam; no item assignment."""
    from collections.abc import Mapping

    from flatland.core.contract import METHOD_ORDER
    from flatland.textbook import METHODS

    top = importlib.import_module(package)
    table = top.GRADIENT_METHODS
    assert isinstance(table, Mapping) and "boundary" in table and "magic" not in table and 3 not in table
    assert list(table) == list(table.names) == list(METHOD_ORDER) == list(METHODS) and len(table) == 4
    assert table["reparam"] is table.lookup("reparam") and table.get("magic") is None
    assert dict(table.items())["naive"].name == "naive"
    with pytest.raises(KeyError):
        table["magic"]
    with pytest.raises(ValidationError, match=r"^method: unknown gradient method 'magic'; choose from naive"):
        table.lookup("magic")
    with pytest.raises(TypeError):
        table["magic"] = table["naive"]


def test18_dir_lists_the_public_names_only(package):
    top = importlib.import_module(package)
    importlib.import_module(f"{package}.scene")  # a submodule imported: still not listed
    assert dir(top) == sorted([*top.__all__, "__version__"])
    assert all(getattr(top, name) is not None for name in top.__all__)


def test19_help_states_every_options_default_and_no_verb_lists_the_verbs(package, capsys):
    import argparse

    from flatland.app.cli import _parser

    entry = importlib.import_module(f"{package}.__main__")
    verbs = next(a for a in _parser(entry.PACKAGE)._actions if isinstance(a, argparse._SubParsersAction))
    for verb, parser in verbs.choices.items():
        for action in parser._actions:
            if action.option_strings and not isinstance(action, argparse._HelpAction):
                assert "default" in action.help, (verb, action.option_strings, action.help)
    assert entry.main([]) == 0
    out = capsys.readouterr().out
    assert all(f"\n    {verb} " in out for verb in VERBS) and "VERB --help" in out
    words = " ".join(_help(entry.main, ["gradient"], capsys))
    table = importlib.import_module(f"{package}.render").GRADIENT_METHODS
    assert f"(default {table['reparam'].options['kappa'].default:g})" in words
    assert f"(default {table['finite_difference'].options['h'].default:g})" in words


def test20_every_builtin_study_loads_and_each_package_sweeps_kappa_on_a_scene(package):
    """Every built-in study is a valid configuration, and each package has one κ sweep on a scene
    (the bias/variance trade-off shown where a renderer's shading integral holds it), with the
    methods it is judged beside."""
    entry = importlib.import_module(f"{package}.__main__")
    configs = [load_config(data, package=entry.PACKAGE, name=name) for name, data in entry.STUDIES.items()]

    def kappas(config):
        return sorted({c.options_dict["kappa"] for c in config.cells if c.method == "reparam"})

    sweeps = [c for c in configs if c.problem.is_scene and len(kappas(c)) >= 3]
    assert sweeps, f"{package}: no built-in κ sweep on a scene"
    assert {"naive", "boundary", "reparam"} <= {c.method for c in sweeps[0].cells}
    assert kappas(sweeps[0])[-1] / kappas(sweeps[0])[0] >= 100  # wide enough to cross from bias to variance
