"""Sphinx extension of this site: theory-to-code links, strict project cross-references, generated pages.

The ``implements`` directive
----------------------------
Every theory page ties each topic it explains to the code that implements it, in one
machine-checkable form (MyST syntax)::

    (theory-change-of-variables)=
    ## Change of variables that stops the jumps
    ...
    ```{implements} theory-change-of-variables
    flatland.textbook.reparam.follow_nearest
    flatland.textbook.reparam.reparam
    ```

The argument is the label of the theory section the block closes (a MyST target
``(label)=`` placed just before that section's heading); the body lists fully
qualified names of functions or classes, one per line. The directive renders a line
"<section title> in the code: ..." whose names link to the API reference, and warns
(an error under ``-W``) when the label is not defined, or when a name cannot be
imported or has no page in the API reference. The theory index
(``docs/theory/index.md``) has one row per label: the paper's section, the topic, the
page, the same names, and the tests that check them. ``tests/test_docs.py`` checks
the blocks and the index against each other without building the site.

Strict project references
-------------------------
A cross-reference to ``flatland.*`` or ``sphere3d.*`` that does not resolve is a
warning, even without ``nitpicky``: a renamed function breaks the build instead of
leaving a dead link. References to numpy or Python types stay unchecked.

Re-exported names
-----------------
``flatland.estimate`` and ``flatland.Dual`` are documented where they are defined
(``flatland.textbook.estimate``, ``flatland.core.dual.Dual``); a reference to the
re-exported name resolves to that page.

Mathematics in docstrings
-------------------------
Docstrings write formulas as the theory pages do, between dollars:
``$I'(θ) + h^2 I'''(θ) / 6$`` (TeX, with Unicode letters where they read better in
``help()``; a formula stays on one line). Each ``$...$`` outside inline literals becomes
a ``:math:`` role before the docstring is parsed, and MathJax typesets it as in the
pages. A dollar sign that is not maths is written ``\\$`` or inside a literal.
Plain-text absolute values and determinants, ``|x|`` and ``|det J|``, which
reStructuredText would read as substitution references, are escaped outside literals,
roles and table lines.

Members outside ``__all__``
---------------------------
Autosummary lists the functions and classes a module defines; those missing from
the module's ``__all__`` (helpers that are public by name only) are skipped.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
import shutil
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from docutils import nodes
from sphinx import addnodes
from sphinx.application import Sphinx
from sphinx.errors import PycodeError
from sphinx.ext import autosummary
from sphinx.pycode import ModuleAnalyzer
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

PROJECT_PACKAGES = ("flatland", "sphere3d")
LABEL = re.compile(r"[a-z][a-z0-9]*(?:-[a-z0-9]+)*")
"""A theory label as ``implements`` takes it: lowercase words joined by hyphens."""
logger = logging.getLogger(__name__)


def resolve_name(dotted: str) -> Any:
    """The object a fully qualified name refers to: the longest importable module prefix, then attributes.

    Raises ImportError (no importable module prefix) or AttributeError (a missing attribute).
    """
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for attr in parts[cut:]:
            obj = getattr(obj, attr)
        return obj
    raise ImportError(f"no module of {dotted!r} can be imported")


class Implements(SphinxDirective):
    """``{implements} <theory label>`` with one fully qualified name per body line."""

    required_arguments = 1
    final_argument_whitespace = True
    has_content = True

    def run(self) -> list[nodes.Node]:
        label = self.arguments[0].strip()
        if LABEL.fullmatch(label) is None:
            raise self.error(
                f"implements: argument must be a theory label such as 'theory-kernels', got {label!r}"
            )
        targets = [line.strip() for line in self.content if line.strip()]
        if not targets:
            raise self.error("implements: list at least one fully qualified name")
        para = nodes.paragraph(classes=["implements"])
        section = addnodes.pending_xref(
            "",
            refdomain="std",
            reftype="ref",
            reftarget=label,
            refdoc=self.env.docname,
            refexplicit=False,
            refwarn=True,
        )
        section += nodes.inline(label, label)  # replaced by the section's title when the label resolves
        strong = nodes.strong()
        strong += section
        strong += nodes.Text(" in the code: ")
        para += strong
        for i, target in enumerate(targets):
            try:
                obj = resolve_name(target)
            except (ImportError, AttributeError) as exc:
                logger.warning(
                    f"implements: {target} cannot be imported ({exc})", location=self.get_location()
                )
            else:
                if not callable(obj):
                    logger.warning(
                        f"implements: {target} is not a function or class", location=self.get_location()
                    )
            if i:
                para += nodes.Text(", ")
            ref = addnodes.pending_xref(
                "", refdomain="py", reftype="obj", reftarget=target, refexplicit=False, refwarn=True
            )
            ref += nodes.literal(target, target.rsplit(".", 1)[-1], classes=["xref", "py", "py-obj"])
            para += ref
        return [para]


def _canonical_name(target: str) -> str | None:
    """``module.qualname`` of the object ``target`` names, if that differs from ``target``."""
    try:
        obj = resolve_name(target)
    except (ImportError, AttributeError):
        return None
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if not module or not qualname:
        return None
    canonical = f"{module}.{qualname}"
    return canonical if canonical != target else None


def _resolve_project_reference(app: Sphinx, env: Any, node: Any, contnode: Any) -> Any:
    """Resolve re-exported names to their defining module; make hand-written dead links warn.

    A reference from a page outside the generated API reference to an unresolvable
    ``flatland.*`` / ``sphere3d.*`` name gets ``refwarn`` so Sphinx reports it
    (docstrings may mention helpers that are not exported; those stay plain text).
    """
    target = node.get("reftarget", "")
    if node.get("refdomain") != "py" or target.split(".")[0] not in PROJECT_PACKAGES:
        return None
    canonical = _canonical_name(target)
    if canonical is not None:
        domain = env.get_domain("py")
        resolved = domain.resolve_xref(
            env, node["refdoc"], app.builder, node["reftype"], canonical, node, contnode
        )
        if resolved is not None:
            return resolved
    if not node.get("refdoc", "").startswith("api/generated/"):
        node["refwarn"] = True
    return None


_PROTECTED = re.compile(r"(``.+?``|(?::[\w:+-]+:)?`[^`]+`_{0,2})")


def _escape_pipes(line: str) -> str:
    """``line`` with ``|`` escaped outside inline literals and interpreted text."""
    stripped = line.strip()
    if stripped.startswith(("| ", "+-", "+=")) or stripped == "|":
        return line  # a grid-table row or a line block: pipes are syntax there
    parts = _PROTECTED.split(line)
    return "".join(p if i % 2 else p.replace("|", r"\|") for i, p in enumerate(parts))


_TYPE_FIELD = re.compile(r"^(\s*:(?:type|vartype|rtype|kwtype)(?: [^:]+)?:)\s+(\S.*)$")


def _plain_types(app: Sphinx, what: str, name: str, obj: Any, options: Any, lines: list[str]) -> None:
    """Render napoleon's type fields as emphasized text, not as cross-references.

    numpydoc types are prose ("ndarray, shape (n, 3)", "Dual or float"); Sphinx would
    turn every word into a fuzzy cross-reference, linking "shape" to whichever
    ``.shape`` it finds first. A type field whose content is not plain text is
    rendered as written.
    """
    if name.split(".")[0] not in PROJECT_PACKAGES:
        return
    for i, line in enumerate(lines):
        match = _TYPE_FIELD.match(line)
        if match and not any(ch in match.group(2) for ch in "*`"):
            lines[i] = f"{match.group(1)} *{match.group(2).strip()}*"


_LITERAL = re.compile(r"(``.+?``)")
_DOLLAR_MATH = re.compile(r"(?<![\\$\w])\$(?=[^\s$])((?:[^$\\]|\\.)+?)(?<=\S)\$(?![\w$])")
"""Inline maths ``$...$`` as MyST's dollarmath reads it: no space just inside the dollars, no
escaped dollar, not glued to a word on either side."""


def dollar_math(line: str) -> str:
    """``line`` with each ``$...$`` outside inline literals written as a ``:math:`` role; ``\\$`` as ``$``.

    A formula containing a backquote (which would end the role) is left as written.
    """
    parts = _LITERAL.split(line)
    for i in range(0, len(parts), 2):  # even parts are outside literals
        text = _DOLLAR_MATH.sub(lambda m: m[0] if "`" in m[1] else f":math:`{m[1]}`", parts[i])
        parts[i] = text.replace("\\$", "$")
    return "".join(parts)


def _process_docstring(app: Sphinx, what: str, name: str, obj: Any, options: Any, lines: list[str]) -> None:
    """Project docstrings, in place: ``$...$`` as ``:math:`` roles, plain-text pipes (``|x|``) escaped."""
    if name.split(".")[0] in PROJECT_PACKAGES:
        lines[:] = [_escape_pipes(dollar_math(line)) for line in lines]


def _skip_outside_all(app: Sphinx, what: str, name: str, obj: Any, skip: bool, options: Any) -> bool | None:
    """Skip module-level functions and classes of the project that their module's ``__all__`` omits."""
    if skip or getattr(obj, "__qualname__", None) != name:
        return None  # already skipped, or a class member (qualname "Class.name")
    modname = getattr(obj, "__module__", None) or ""
    if modname.split(".")[0] not in PROJECT_PACKAGES:
        return None
    public = getattr(sys.modules.get(modname), "__all__", None)
    return True if public is not None and name not in public else None


API_INDEX = """\
API reference
=============

Generated from the numpydoc docstrings. Each package below is documented
recursively: every public module gets a page listing the functions and classes it
defines and exports in ``__all__``. New modules appear here without editing the
docs; a new package is added to ``API_PACKAGES`` in ``docs/conf.py``.

Start here: what each package exports at its top level (its ``__all__``), which is all
the tutorials and the command line use; each name links to the page of the module
that defines it.

{exports}

Every module:

.. autosummary::
   :toctree: generated
   :recursive:

{entries}
"""


def _export(package: str, name: str) -> str:
    """One exported name: a link for a class or function (documented on its package's page), else
    the name itself (a table or constant, documented in its module's docstring)."""
    obj = getattr(sys.modules[package], name)
    if inspect.isclass(obj) or inspect.isroutine(obj):
        return f":py:obj:`~{package}.{name}`"
    return f"``{name}``"


def write_api_index(path: Path, packages: Iterable[str]) -> list[str]:
    """Write the API index listing the importable ``packages``; returns them.

    The file is rewritten only when its content changes, so incremental builds stay
    incremental.
    """
    found = []
    for name in packages:
        try:
            importlib.import_module(name)
        except ImportError:
            continue
        if getattr(sys.modules[name], "__file__", None) is None:
            continue  # an empty folder imports as a namespace package: nothing to document
        found.append(name)
    exports = "\n\n".join(
        f"``{name}``: " + ", ".join(_export(name, n) for n in sorted(sys.modules[name].__all__))
        for name in found
        if hasattr(sys.modules[name], "__all__")
    )
    text = API_INDEX.format(entries="\n".join(f"   {name}" for name in found), exports=exports)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")
    return found


def shadowed_modules(packages: Iterable[str]) -> list[str]:
    """Submodules hidden by a same-named attribute of their package (``sphere3d.render`` the function).

    ``import sphere3d.render`` binds the package attribute ``render`` to the function the
    package re-exports, so autosummary documents the function under the module's name
    and the module's own page is lost. :func:`_document_shadowed_modules` writes those
    pages itself.
    """
    found = []
    for package in packages:
        try:
            pkg = importlib.import_module(package)
        except ImportError:
            continue
        for info in pkgutil.walk_packages(getattr(pkg, "__path__", []), package + "."):
            if any(part.startswith("_") for part in info.name.split(".")):
                continue
            parent, _, leaf = info.name.rpartition(".")
            attr = getattr(sys.modules.get(parent), leaf, None)
            if attr is not None and not inspect.ismodule(attr):
                found.append(info.name)
    return found


def module_page(name: str) -> str:
    """reStructuredText of one module's API page, as ``_templates/autosummary/module.rst`` writes it."""
    module = importlib.import_module(name)
    public = getattr(module, "__all__", None)
    defined = [
        (n, o)
        for n, o in vars(module).items()
        if not n.startswith("_")
        and getattr(o, "__module__", None) == name
        and (public is None or n in public)
        and (inspect.isclass(o) or inspect.isfunction(o))
    ]
    classes = [n for n, o in defined if inspect.isclass(o)]
    functions = [n for n, o in defined if inspect.isfunction(o)]
    try:
        attributes = sorted({a for ns, a in ModuleAnalyzer.for_module(name).find_attr_docs() if not ns})
    except PycodeError:
        attributes = []
    attributes = [a for a in attributes if not a.startswith("_")]
    lines = [name, "=" * len(name), "", f".. automodule:: {name}", ""]
    if attributes or classes or functions:
        lines += [".. rubric:: Contents", "", ".. autosummary::", "   :nosignatures:", ""]
        lines += [f"   {n}" for n in attributes + classes + functions] + [""]
    for n in attributes:
        lines += [f".. autodata:: {n}", "   :no-value:", ""]
    for n in classes:
        lines += [f".. autoclass:: {n}", "   :members:", "   :show-inheritance:", ""]
    for n in functions:
        lines += [f".. autofunction:: {n}", ""]
    return "\n".join(lines)


def _document_shadowed_modules(app: Sphinx) -> None:
    """Replace autosummary's page of a shadowed module (it documents the function) by the module's page."""
    generated = Path(app.srcdir) / "api" / "generated"
    for name in shadowed_modules(app.config.project_api_packages):
        page = generated / f"{name}.rst"
        text = module_page(name)
        if page.exists() and page.read_text(encoding="utf-8") != text:
            page.write_text(text, encoding="utf-8")


def copy_tutorials(source: Path, target: Path) -> list[Path]:
    """Copy ``source/NN_*.ipynb`` into ``target`` (only changed files), removing stale copies."""
    target.mkdir(parents=True, exist_ok=True)
    notebooks = sorted(source.glob("[0-9][0-9]_*.ipynb"))
    names = {nb.name for nb in notebooks}
    for stale in target.glob("[0-9][0-9]_*.ipynb"):
        if stale.name not in names:
            stale.unlink()
    for nb in notebooks:
        dest = target / nb.name
        if not dest.exists() or dest.read_bytes() != nb.read_bytes():
            shutil.copyfile(nb, dest)
    return notebooks


def _forget_environment_after_warnings(app: Sphinx, exception: Exception | None) -> None:
    """Delete the saved environment after a build with warnings, so the next build reports them again.

    Sphinx re-reads only changed sources; without this, a second ``make docs`` after a
    failed one would skip the offending pages and succeed.
    """
    if getattr(app, "_warncount", 0) and app.doctreedir is not None:
        (Path(app.doctreedir) / "environment.pickle").unlink(missing_ok=True)


def setup(app: Sphinx) -> dict[str, Any]:
    """Register the directive and the event handlers."""
    app.setup_extension("sphinx.ext.autodoc")  # its events are connected below
    # a summary line citing "(Loubet et al. 2019, Sec. 4.2)" must not end at "Sec."
    if "Sec." not in autosummary.WELL_KNOWN_ABBREVIATIONS:
        autosummary.WELL_KNOWN_ABBREVIATIONS = (*autosummary.WELL_KNOWN_ABBREVIATIONS, "Sec.")
    app.add_config_value("project_api_packages", PROJECT_PACKAGES, "env")
    app.add_directive("implements", Implements)
    app.connect("builder-inited", _document_shadowed_modules, priority=900)  # after autosummary (500)
    app.connect("missing-reference", _resolve_project_reference, priority=900)
    app.connect("autodoc-process-docstring", _process_docstring, priority=400)  # before napoleon (500)
    app.connect("autodoc-process-docstring", _plain_types, priority=600)  # after napoleon
    app.connect("autodoc-skip-member", _skip_outside_all)
    app.connect("build-finished", _forget_environment_after_warnings)
    app.add_css_file("project.css")
    # sphinx-mathjax-offline declares nothing, so Sphinx would assume it unsafe for `make docs`'s
    # parallel build; all it does is copy MathJax into the output when the build has finished
    offline = app.extensions.get("sphinx-mathjax-offline")
    if offline is not None:
        offline.parallel_read_safe = offline.parallel_write_safe = True
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
