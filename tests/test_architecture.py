"""Layering: the numeric kernel flatland.core, the application layer flatland.app, the renderers.

Each check imports in a fresh interpreter and inspects ``sys.modules``, the only place
an import that should not happen shows. ``import sphere3d`` loads flatland's kernel
(Dual, rng, stats, validation) but not its 2D renderer, its command line or matplotlib;
``import flatland`` imports a public name's module on first use (PEP 562).
"""

from __future__ import annotations

import ast
import json
import pkgutil
import subprocess
import sys
from pathlib import Path

import flatland
import flatland.core

ROOT = Path(__file__).resolve().parent.parent
RENDERER = (
    "flatland.render",
    "flatland.integrator",
    "flatland.geometry",
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
    allowed_top = {"numpy", "scipy", "flatland"} | set(sys.stdlib_module_names) - {"argparse"}
    assert {m for m in imported if m.split(".")[0] not in allowed_top} == set()
    assert {m for m in imported if m.startswith("flatland.") and not m.startswith("flatland.core")} == set()
    baseline = _modules_after("\n".join(sorted(third_party)))
    assert "argparse" not in set(modules) - set(baseline)


def test04_every_public_name_resolves_and_is_listed_by_dir():
    for name in flatland.__all__:
        assert getattr(flatland, name) is not None, name
    assert set(flatland.__all__) <= set(dir(flatland))
    assert callable(flatland.render) and callable(flatland.render_gradient)


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


MAX_LINES = 400
"""Longest module allowed in the packages: a longer one is split by job."""


def test07_no_module_of_either_package_is_longer_than_400_lines():
    modules = sorted(p for package in ("flatland", "sphere3d") for p in (ROOT / package).rglob("*.py"))
    assert ROOT / "flatland" / "core" / "dual.py" in modules  # the scan sees the packages
    lengths = {str(p.relative_to(ROOT)): len(p.read_text(encoding="utf-8").splitlines()) for p in modules}
    assert {name: n for name, n in lengths.items() if n > MAX_LINES} == {}
