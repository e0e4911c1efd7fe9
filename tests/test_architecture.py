"""Layering: the numeric kernel flatland.core, the application layer flatland.app, the renderers;
and the one vocabulary the two renderers share.

Each layering check imports in a fresh interpreter and inspects ``sys.modules``, the only
place an import that should not happen shows. ``import sphere3d`` loads flatland's kernel
(Dual, rng, stats, validation) but not its 2D renderer, its command line or matplotlib;
``import flatland`` imports a public name's module on first use (PEP 562).

The vocabulary checks (test09 on) compare explicit lists: the modules both renderers have
(docs/theory/architecture.md), the public names each pair of modules exposes, and the
options of the gradient methods both packages have, with the documented finite-difference
steps pinned.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import inspect
import json
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import pytest

import flatland
import flatland.core
from tests.tiers import SLOW

ROOT = Path(__file__).resolve().parent.parent
RENDERER = (
    "flatland.render",
    "flatland.integrator",
    "flatland.tasks",
    "flatland.tracing",
    "flatland.reparam",
    "flatland.state",
    "flatland.scene",
    "flatland.methods",
)
"""The 2D renderer's modules (and packages: their submodules count too)."""
APP = ("flatland.app", "matplotlib")


def _modules_after(code: str) -> list[str]:
    """``sys.modules`` after running ``code`` in a new interpreter started in the repository root."""
    script = f"import json, sys\n{code}\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout
    return json.loads(out.splitlines()[-1])


def _loaded(modules: list[str], prefixes: tuple[str, ...]) -> list[str]:
    return [m for m in modules if any(m == p or m.startswith(p + ".") for p in prefixes)]


def test01_import_sphere3d_loads_no_2d_renderer_no_app_no_matplotlib():
    modules = _modules_after("import sphere3d")
    assert "sphere3d.render" in modules and "flatland.core.dual" in modules  # the check can see imports
    assert _loaded(modules, RENDERER + APP) == []


def test02_import_flatland_imports_a_renderer_module_only_when_a_name_is_used():
    modules = _modules_after("import flatland")
    assert _loaded(modules, RENDERER + APP + ("flatland.textbook",)) == []
    used = _modules_after("import flatland\nflatland.render_gradient")
    assert "flatland.render" in used and "flatland.scene" in used
    assert _loaded(used, APP) == []


@SLOW
def test03_flatland_core_imports_no_matplotlib_no_argparse_no_app():
    """At run time (every core module imported) and in the sources: scipy.special itself imports
    argparse, so argparse is checked in the sources (no core module imports it) and at run time as
    nothing beyond what core's own third-party imports load."""
    core = [m.name for m in pkgutil.walk_packages(flatland.core.__path__, "flatland.core.")]
    assert "flatland.core.dual" in core and "flatland.core.validate" in core
    modules = _modules_after("\n".join(f"import {m}" for m in ["flatland.core", *core]))
    assert set(core) <= set(modules)
    assert _loaded(modules, RENDERER + APP + ("flatland.textbook", "flatland.integrals", "sphere3d")) == []
    imported, third_party = set(), set()  # module names; the third-party import statements
    for path in Path(flatland.core.__path__[0]).glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import | ast.ImportFrom) and getattr(node, "level", 0) == 0:
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module]
                imported |= set(names)
                if names[0].split(".")[0] in ("numpy", "scipy"):
                    third_party.add(ast.unparse(node))
    assert "numpy" in imported and "flatland.core.dual" in imported  # the scan sees imports
    # tqdm: a dependency of the package, imported by flatland.core.progress only once a bar is shown
    allowed_top = {"numpy", "scipy", "tqdm", "flatland"} | set(sys.stdlib_module_names) - {"argparse"}
    assert {m for m in imported if m.split(".")[0] not in allowed_top} == set()
    assert {m for m in imported if m.startswith("flatland.") and not m.startswith("flatland.core")} == set()
    baseline = _modules_after("\n".join(sorted(third_party)))
    assert "argparse" not in set(modules) - set(baseline)


def test04_every_public_name_resolves_and_is_listed_by_dir():
    for name in flatland.__all__:
        assert getattr(flatland, name) is not None, name
    assert set(flatland.__all__) <= set(dir(flatland))
    assert callable(flatland.render) and callable(flatland.render_gradient)


@SLOW
def test05_importing_the_render_module_does_not_shadow_the_render_function():
    """``import flatland.render`` sets the package attribute ``render`` to the module; it stays the
    function, as when ``flatland/__init__`` imported it eagerly."""
    out = subprocess.run(
        [sys.executable, "-c", "import flatland.render, flatland; print(callable(flatland.render))"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert out.strip() == "True"


def test06_an_unknown_name_is_an_attribute_error():
    try:
        flatland.no_such_name  # noqa: B018
    except AttributeError as e:
        assert "no_such_name" in str(e)
    else:
        raise AssertionError("flatland.no_such_name resolved")


MAX_CODE_LINES = 300
"""Most code lines a module of the packages may have (docstrings, comments and blank lines not
counted): a longer one is split by job, not by the length of its documentation."""


def code_lines(path: Path) -> int:
    """Lines of ``path`` that hold code: not blank, not a comment, not part of a docstring (a
    module's, class's or function's, or the string after an assignment that documents it)."""
    source = path.read_text(encoding="utf-8")
    documentation: set[int] = set()
    for node in ast.walk(ast.parse(source)):
        body = getattr(node, "body", None)
        if not isinstance(body, list) or not body:
            continue
        for before, stmt in zip([None, *body[:-1]], body, strict=True):
            is_string = isinstance(stmt, ast.Expr) and isinstance(getattr(stmt, "value", None), ast.Constant)
            if is_string and isinstance(stmt.value.value, str):
                first = before is None and isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef)
                if first or isinstance(before, ast.Assign | ast.AnnAssign):
                    documentation.update(range(stmt.lineno, stmt.end_lineno + 1))
    return sum(
        1
        for number, line in enumerate(source.splitlines(), 1)
        if number not in documentation and line.strip() and not line.strip().startswith("#")
    )


def test07_no_module_of_either_package_has_more_than_300_lines_of_code():
    modules = sorted(p for package in ("flatland", "sphere3d") for p in (ROOT / package).rglob("*.py"))
    assert ROOT / "flatland" / "core" / "dual.py" in modules  # the scan sees the packages
    lengths = {str(p.relative_to(ROOT)): code_lines(p) for p in modules}
    assert {name: n for name, n in lengths.items() if n > MAX_CODE_LINES} == {}
    # the count can fail: a module of blank lines and docstrings counts 0, one of statements counts them
    assert code_lines(ROOT / "flatland" / "reparam" / "__init__.py") < 5
    assert code_lines(ROOT / "sphere3d" / "integrator.py") > 100


LAYERS = {
    "sphere3d": (
        (
            "primitives",
            (
                "vector",
                "jit",
                "live",
                "shapes",
                "harmonics",
                "sampling",
                "bsdf",
                "rotation",
                "tracing",
                "film",
            ),
        ),
        ("scene at θ", ("scene", "materials", "offsets", "state", "tables", "world")),
        ("integrals", ("integrator", "glossy", "paths", "path_changes", "execution", "tasks")),
        ("method parts", ("boundary", "reparam", "closed_form")),
        ("methods", ("methods",)),
        ("entry points", ("render", "optimize", "plot", "__main__", "")),
    ),
}
"""sphere3d's layers, lowest first (the architecture page draws them): a module imports only modules
of its own layer or below, and the import graph has no cycle."""


def _imports(path: Path, package: str) -> set[str]:
    """The package's modules ``path`` imports, at any depth of the file (function-level included)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == package:
            for alias in node.names:
                full = f"{node.module}.{alias.name}"
                out.add(full if _is_module(full) else node.module)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] == package)
    return out


def _is_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:
        return False


def _layer(package: str, module: str) -> int:
    """The index of ``module``'s layer: by its first name below the package."""
    top = module[len(package) + 1 :].split(".")[0] if module != package else ""
    for index, (_, names) in enumerate(LAYERS[package]):
        if top in names:
            return index
    raise AssertionError(f"{module} is in no layer of {package}")


def test08_sphere3d_modules_import_only_their_own_layer_or_below_and_form_no_cycle():
    package = "sphere3d"
    files = {
        ".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"): p
        for p in (ROOT / package).rglob("*.py")
    }
    graph = {name: _imports(path, package) - {name} for name, path in files.items()}
    assert "sphere3d.reparam.paper" in graph and "sphere3d.integrator" in graph["sphere3d.reparam.paper"]
    upward = [
        (name, target)
        for name, targets in graph.items()
        for target in targets
        if _layer(package, target) > _layer(package, name)
    ]
    assert upward == []
    # no cycle: repeatedly remove the modules that import nothing left
    left = {name: {t for t in targets if t in graph} for name, targets in graph.items()}
    while left:
        leaves = [name for name, targets in left.items() if not targets & set(left)]
        assert leaves, f"an import cycle among {sorted(left)}"
        for name in leaves:
            del left[name]
    # the integrator knows no method: it imports nothing of the method parts or the methods
    integrals = {n for n in graph if _layer(package, n) == 2}
    assert all(_layer(package, t) <= 2 for n in integrals for t in graph[n])


# ------------------------------------------------------------------ the vocabulary both renderers share
PACKAGES = ("flatland", "sphere3d")
SHARED_MODULES = {
    "scene", "state", "tracing", "integrator", "tasks", "sampling", "bsdf", "render",
    "methods", "methods._common", "methods.naive", "methods.finite_difference", "methods.reparam",
    "reparam", "reparam.probes", "reparam.default", "optimize",
}  # fmt: skip
"""Modules both renderers have, with the same role (the table of docs/theory/architecture.md)."""
RETIRED = {"flatland": {"geometry", "methods.heuristic", "probes"}, "sphere3d": {"probes", "camera_kernel"}}
"""Former module names, gone without compatibility shims."""
SHARED_NAMES = {
    "scene": {"Scene", "load_scene", "list_scenes", "parameter_names"},
    "state": {"SceneState", "build_state", "moved_scene"},
    "optimize": {"optimize", "render_targets", "silhouette_iou"},
    "tracing": {"Hits", "attached_points"},
    "reparam.probes": {"select_points"},
    "reparam.default": {"ReparamTransforms"},
    "integrator": {"PRIMARY_UNIFORMS", "Transforms", "Identity"},
    "tasks": {"CHUNK", "ImageTask", "PointTask", "Tally"},
    "sampling": {"filter_value", "sample_filter", "pdf_filter"},
    "bsdf": {"eval_ggx", "sample_ggx", "pdf_ggx", "weight_ggx", "albedo_ggx"},
    "render": {"GRADIENT_METHODS", "render", "render_gradient", "irradiance"},
    "methods": {"GRADIENT_METHODS"},
    "methods._common": {"GRADIENT_METHODS"},
}
"""Public names (in ``__all__``) each pair of shared modules exposes, for the same role."""
PACKAGE_NAMES = {"GRADIENT_METHODS", "render", "render_gradient", "irradiance", "load_scene", "list_scenes"}
"""Public names of both packages themselves."""
SHARED_OPTIONS = {
    "naive": (),
    "finite_difference": ("h",),
    "reparam": ("kappa", "kappa_film", "probes", "spread", "refine", "paired", "lobe"),
    "boundary": (),
}
"""Gradient methods both packages have, and their options in order (2D-only options aside)."""
ONLY_2D_OPTIONS: dict[str, tuple[str, ...]] = {}
"""Options flatland's methods have beyond the shared ones (none: both have the film kernel ``kappa_film``)."""
ONLY_3D_OPTIONS = {
    "boundary": ("rate", "secondary", "indirect"),
    "reparam": ("variant", "emitter_probes", "baseline"),
}
"""Options sphere3d's methods have beyond the shared ones (flatland's boundary terms are exact
sums over endpoints and tangent points; sphere3d's are sampled along edges at a ``rate`` on the
film and ``secondary`` times per shading point, and on paths ``indirect`` times per vertex for the
reflected radiance's jump, where flatland enumerates every jump point; sphere3d's reparam has the
published estimator as a ``variant`` and shadow probes on the emitters' area, where flatland gives
every emitter sample its own kernel and probes, and a control variate of the cosine kernels' weights,
``baseline``, scaled by the sky seen at the kernel's centre)."""
FD_STEP = {"flatland": 1e-3, "sphere3d": 1e-2}
"""Default finite-difference steps h (the reason: docs/theory/naive.md, and each method's docstring)."""


def _modules(package: str) -> set[str]:
    """Every module of ``package``, by its name relative to the package."""
    root = importlib.import_module(package)
    return {m.name[len(package) + 1 :] for m in pkgutil.walk_packages(root.__path__, package + ".")}


def test09_both_renderers_have_the_shared_modules_and_no_retired_ones():
    for package in PACKAGES:
        modules = _modules(package)
        assert "core.dual" in modules or package == "sphere3d"  # the walk sees subpackages
        assert SHARED_MODULES - modules == set(), package
        assert RETIRED[package] & modules == set(), package


@pytest.mark.parametrize("module", sorted(SHARED_NAMES))
def test10_each_pair_of_shared_modules_exposes_the_same_public_names(module):
    pair = [importlib.import_module(f"{package}.{module}") for package in PACKAGES]
    for mod in pair:
        assert SHARED_NAMES[module] - set(mod.__all__) == set(), mod.__name__
        assert all(getattr(mod, name) is not None for name in SHARED_NAMES[module])
    for name in SHARED_NAMES[module]:  # the same kind of thing: both classes, both functions, ...
        kinds = {(inspect.isclass(getattr(m, name)), callable(getattr(m, name))) for m in pair}
        assert len(kinds) == 1, f"{module}.{name}: {kinds}"


def test11_the_shared_names_are_defined_where_the_vocabulary_says():
    for package in PACKAGES:
        table = importlib.import_module(f"{package}.methods._common").GRADIENT_METHODS
        for where in ("methods", "render", ""):
            mod = importlib.import_module(f"{package}.{where}" if where else package)
            assert mod.GRADIENT_METHODS is table, (package, where)
        for module, names in SHARED_NAMES.items():
            mod = importlib.import_module(f"{package}.{module}")
            for name in names:
                obj = getattr(mod, name)
                if inspect.isclass(obj) or inspect.isfunction(obj):
                    assert obj.__module__ == mod.__name__, f"{package}.{module}.{name} is {obj.__module__}'s"
        assert PACKAGE_NAMES - set(importlib.import_module(package).__all__) == set(), package
        integrator = importlib.import_module(f"{package}.integrator")
        protocol = {n for n, v in vars(integrator.Transforms).items() if inspect.isfunction(v)}
        assert protocol and protocol <= set(dir(integrator.Identity)), package  # Identity implements it all


def test12_methods_of_both_packages_have_the_same_option_names():
    tables = {p: importlib.import_module(f"{p}.methods").GRADIENT_METHODS for p in PACKAGES}
    assert set(tables["flatland"].names) & set(tables["sphere3d"].names) == set(SHARED_OPTIONS)
    for name, shared in SHARED_OPTIONS.items():
        sphere = tuple(
            o for o in tables["sphere3d"].get(name).options if o not in ONLY_3D_OPTIONS.get(name, ())
        )
        assert sphere == shared, name
        flat = tuple(
            o for o in tables["flatland"].get(name).options if o not in ONLY_2D_OPTIONS.get(name, ())
        )
        assert flat == shared, name


def test13_finite_difference_default_steps_are_pinned():
    """The steps differ on purpose (docs/theory/naive.md says why); a change of either must be deliberate."""
    for package, h in FD_STEP.items():
        method = importlib.import_module(f"{package}.methods").GRADIENT_METHODS.get("finite_difference")
        assert method.options["h"].default == h, package


@pytest.mark.parametrize("package", PACKAGES)
def test14_reparams_option_table_lists_exactly_the_registered_options_in_order(package):
    """Each ``reparam`` docstring holds one table of its options (name, default, meaning, values); its
    first column names the registered options, in their order, and nothing else."""
    method = importlib.import_module(f"{package}.methods").GRADIENT_METHODS.get("reparam")
    doc = inspect.getdoc(method.func)
    table = doc[doc.index("Options\n-------") :].split("\n\n")[0]
    names = [m.group(1) for m in re.finditer(r"^``(\w+)``", table, re.M)]
    assert names == list(method.options), (names, list(method.options))
