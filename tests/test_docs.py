"""The documentation's promises, checked without building the site (fast: imports and parsing only).

1. Every public module of ``flatland`` and ``sphere3d`` (when importable) has a
   docstring, and so does every function and class it exports (``__all__``, or its
   public definitions when it has no ``__all__``): the API reference is generated from
   them.
2. The theory pages tie their sections to code with ``implements`` blocks (MyST
   ``{implements} theory-label`` fences, one fully qualified name per line; see
   docs/_ext/project_docs.py). Every block is well-formed, its label is defined on its
   own page just before a heading, and every name in it imports and is a function or
   class.
3. Every theory page and every section of the paper cited anywhere — docs pages,
   tutorials, tests, the packages' source — leads to code: the page exists and has an
   ``implements`` block, the section has a row in the theory index, so a reader who
   meets "(Loubet et al. 2019, Sec. 4.2)" or "(Leibniz rule, theory/leibniz)" in a
   comment finds its theory and its code.
4. Every explicit cross-reference to a ``flatland``/``sphere3d`` name in the hand-written
   pages (``{func}`~flatland.x.y```) names an importable object.
5. The guide "How to add an estimator" runs its example, ``docs/guides/edge_sampling.py``:
   it must be unbiased and show the variance the guide predicts.
6. The guide "How to add an image gradient method" runs its example,
   ``docs/guides/image_method_example.py``, in both packages: plugged into the real
   method table for the test only, it renders through ``render_gradient`` and is the
   combination of finite differences it claims to be, bit for bit.
7. The theory index (docs/theory/index.md) is a table with one row per ``implements``
   label: the paper's section, the topic, the page and the names of that block, and
   tests that exist.
8. No file cites a document that is not shipped: a citation names the paper's section or a
   theory page, never "DESIGN" followed by a section number.
9. The architecture page (docs/theory/architecture.md) names every module of both packages,
   and every ``flatland``/``sphere3d`` name or path it writes in backticks exists.
10. Docstring maths written ``$...$`` reaches the API pages as ``:math:`` roles (typeset by
    MathJax), and no docstring keeps a stray dollar outside literals.
11. The guide "How to write a study file" describes its template, ``docs/guides/example_study.json``:
    the cells it counts, loadable by both packages, and it runs.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import pkgutil
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from markdown_it import MarkdownIt

from flatland import estimate
from flatland.core.dual import tangent, variable
from flatland.core.stats import normal_quantile, sidak
from flatland.integrals import INTEGRALS
from tests.tiers import SLOW

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
PACKAGES = ("flatland", "sphere3d")
PAGES = sorted(p for p in DOCS.rglob("*.md") if "_build" not in p.parts)
THEORY_INDEX = DOCS / "theory" / "index.md"
THEORY_CITATION = re.compile(r"\btheory/([a-z_]+)")
"""A theory page as code and tutorials cite it: ``theory/leibniz``, ``docs/theory/leibniz.md``."""
PAPER_CITATION = re.compile(r"\bSec\. (\d+(?:\.\d+)?)(?:\s*[-–]\s*(\d+(?:\.\d+)?))?")
"""A section of the paper as cited: ``Sec. 4.2``, or a range ``Sec. 4.1-4.2`` (both ends count)."""
LABEL_TARGET = re.compile(r"^\(([^)\s]+)\)=[ \t]*\n#{1,6} ", re.MULTILINE)
"""A MyST target ``(label)=`` on the line just before a heading: the label names that section."""
ROLE = re.compile(r"\{(?:py:)?(?:func|class|meth|mod|data|attr|obj|exc)\}`([^`]+)`")


def importable(name: str) -> bool:
    try:
        module = importlib.import_module(name)
    except ImportError:
        return False
    return getattr(module, "__file__", None) is not None  # an empty folder is a namespace package


def load_extension() -> Any:
    """The site's Sphinx extension, docs/_ext/project_docs.py: the tests use its own name resolution and
    docstring passes, so they check what the build does."""
    spec = importlib.util.spec_from_file_location("project_docs", DOCS / "_ext" / "project_docs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


project_docs = load_extension()
resolve = project_docs.resolve_name


def public_modules(package: str) -> list[str]:
    pkg = importlib.import_module(package)
    found = [package]
    for info in pkgutil.walk_packages(pkg.__path__, package + "."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            found.append(info.name)
    return found


def exported(module: Any) -> list[str]:
    names = getattr(module, "__all__", None)
    if names is None:
        names = [
            n
            for n, o in vars(module).items()
            if not n.startswith("_") and getattr(o, "__module__", None) == module.__name__
        ]
    return list(names)


def implements_blocks() -> list[tuple[Path, str, list[str]]]:
    """(page, label, names) for every ``implements`` fence of the hand-written pages."""
    md = MarkdownIt("commonmark")
    blocks = []
    for page in PAGES:
        for token in md.parse(page.read_text(encoding="utf-8")):
            if token.type == "fence" and token.info.strip().startswith("{implements}"):
                argument = token.info.strip()[len("{implements}") :].strip()
                names = [line.strip() for line in token.content.splitlines() if line.strip()]
                blocks.append((page, argument, names))
    return blocks


def prose_of(page: Path) -> str:
    """A page's text outside code fences (so example snippets do not count as citations)."""
    md = MarkdownIt("commonmark")
    lines = page.read_text(encoding="utf-8").splitlines()
    for token in md.parse("\n".join(lines)):
        if token.type in ("fence", "code_block") and token.map and not token.info.strip().startswith("{"):
            for i in range(*token.map):
                lines[i] = ""
    return "\n".join(lines)


AVAILABLE = [p for p in PACKAGES if importable(p)]
BLOCKS = implements_blocks()


@dataclass(frozen=True)
class IndexRow:
    """One row of the theory index's table, as written."""

    paper: str
    sections: tuple[str, ...]
    labels: tuple[str, ...]
    pages: tuple[str, ...]
    names: tuple[str, ...]
    tests: tuple[str, ...]


def theory_index() -> list[IndexRow]:
    """The rows of the table in docs/theory/index.md (columns: paper, topic, page, names, tests)."""
    rows = []
    for line in THEORY_INDEX.read_text(encoding="utf-8").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")] if line.startswith("|") else []
        if len(cells) != 5 or set(cells[0]) <= set("-: ") or not cells[2].startswith("{doc}"):
            continue  # not a table line, the separator, or the header
        paper, topic, page, names, tests = cells
        rows.append(
            IndexRow(
                paper=paper,
                sections=tuple(re.findall(r"\d+(?:\.\d+)?", paper)) if paper.startswith("Sec.") else (),
                labels=tuple(re.findall(r"\{ref\}`([^`]+)`", topic)),
                pages=tuple(re.findall(r"\{doc\}`([^`]+)`", page)),
                names=tuple(n.lstrip("~") for n in ROLE.findall(names)),
                tests=tuple(re.findall(r"`([^`]+)`", tests)),
            )
        )
    return rows


@pytest.mark.parametrize("package", AVAILABLE)
def test01_every_public_function_and_class_has_a_docstring(package):
    missing = []
    for name in public_modules(package):
        module = importlib.import_module(name)
        if not inspect.getdoc(module):
            missing.append(f"module {name}")
        for attr in exported(module):
            obj = getattr(module, attr)
            if not (inspect.isclass(obj) or inspect.isroutine(obj)):
                continue
            if getattr(obj, "__module__", "").split(".")[0] not in PACKAGES:
                continue
            if not inspect.getdoc(obj):
                missing.append(f"{name}.{attr}")
    assert not missing, "no docstring: " + ", ".join(missing)


def test02_every_implements_block_is_well_formed_and_names_importable_code():
    assert BLOCKS, "the theory pages tie no section to code"
    problems = []
    arguments = [argument for _, argument, _ in BLOCKS]
    for page, argument, names in BLOCKS:
        where = f"{page.relative_to(DOCS)} [{argument}]"
        if not project_docs.LABEL.fullmatch(argument):
            problems.append(f"{where}: argument must be a theory label such as 'theory-kernels'")
        elif argument not in LABEL_TARGET.findall(page.read_text(encoding="utf-8")):
            problems.append(f"{where}: the label is not defined on this page just before a heading")
        if arguments.count(argument) > 1:
            problems.append(f"{where}: the label closes more than one block")
        if not names:
            problems.append(f"{where}: lists no name")
        for name in names:
            if name.split(".")[0] not in PACKAGES:
                problems.append(f"{where}: {name} is not a name of {' or '.join(PACKAGES)}")
                continue
            try:
                obj = resolve(name)
            except (ImportError, AttributeError) as exc:
                problems.append(f"{where}: {name} does not import ({exc!r})")
                continue
            if not callable(obj):
                problems.append(f"{where}: {name} is not a function or class")
    assert not problems, "\n".join(problems)


def citation_sources() -> list[tuple[Path, str]]:
    """(path, text) of everything that cites: docs prose, tutorial scripts, tests, the packages' source."""
    sources = [(p, prose_of(p)) for p in PAGES]
    sources += [
        (p, p.read_text(encoding="utf-8")) for p in sorted((ROOT / "tutorials").glob("[0-9][0-9]_*.py"))
    ]
    sources += [(p, p.read_text(encoding="utf-8")) for p in sorted((ROOT / "tests").rglob("*.py"))]
    for package in AVAILABLE:
        sources += [(p, p.read_text(encoding="utf-8")) for p in sorted((ROOT / package).rglob("*.py"))]
    return sources


def cited(pattern: re.Pattern[str]) -> dict[str, set[str]]:
    """What ``pattern`` captures (every non-empty group) -> the files that cite it."""
    found: dict[str, set[str]] = {}
    for path, text in citation_sources():
        for match in pattern.finditer(text):
            for value in filter(None, match.groups()):
                found.setdefault(value, set()).add(str(path.relative_to(ROOT)))
    return found


def test03_every_cited_theory_page_and_paper_section_leads_to_code():
    pages = cited(THEORY_CITATION)
    sections = cited(PAPER_CITATION)
    assert pages and sections, "nothing cites a theory page or a section of the paper"
    documented = {page.stem for page, _, _ in BLOCKS if page.parent == DOCS / "theory"}
    documented.add(THEORY_INDEX.stem)  # the index is the table from sections to pages, code and tests
    missing = {p: sorted(w)[:3] for p, w in pages.items() if p not in documented}
    assert not missing, f"theory pages cited that do not exist or have no implements block: {missing}"
    indexed = {s for row in theory_index() for s in row.sections}
    # a whole chapter ("Sec. 3") is indexed when one of its sections is
    unindexed = {
        s: sorted(w)[:3]
        for s, w in sections.items()
        if s not in indexed and not any(i.startswith(s + ".") for i in indexed)
    }
    assert not unindexed, f"sections of the paper cited without a row in docs/theory/index.md: {unindexed}"


def test04_explicit_project_cross_references_in_the_pages_import():
    broken = []
    for page in PAGES:
        for text in ROLE.findall(page.read_text(encoding="utf-8")):
            target = re.search(r"<([^>]+)>", text)
            name = (target.group(1) if target else text).lstrip("~!")
            if name.split(".")[0] not in PACKAGES:
                continue
            try:
                resolve(name)
            except (ImportError, AttributeError):
                broken.append(f"{page.relative_to(DOCS)}: {name}")
    assert not broken, "cross-references to missing names: " + ", ".join(broken)


# ------------------------------------------------------------------ the guide's worked example
N = 100_000
SEED = 7
Z = normal_quantile(1.0 - sidak(1e-4, 2 * len(INTEGRALS)))  # two comparisons per integral


@pytest.fixture(scope="module")
def example():
    spec = importlib.util.spec_from_file_location(
        "edge_sampling_example", DOCS / "guides" / "edge_sampling.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("name", list(INTEGRALS))
def test05_the_guides_example_estimator_is_unbiased_with_the_predicted_variance(example, name):
    """Jump term sampled ∝ |t_j|: per-sample jump variance (Σ|t_j|)² - (Σ t_j)² on top of the interior's.

    Every textbook integrand but ``smooth`` has a θ-free smooth factor, so its interior
    term is exactly zero and the per-sample derivative is the two-valued t_J / P_J;
    its sample variance has the standard error sqrt((m4 - σ⁴)/n) with m4 the fourth
    central moment of that two-point law. For ``smooth`` (no jumps) the example is the
    boundary estimator sample for sample.
    """
    ig = INTEGRALS[name]
    th = ig.default_theta
    est = example.edge_sampling(ig, th, N, SEED)
    reference = estimate(name, th, "boundary", n=N, seed=SEED)
    assert est.value == reference.value  # same primary samples: the value is the naive one, bit for bit
    exact = ig.derivative(th)
    assert abs(est.derivative - exact) <= Z * est.derivative_stderr + 1e-12 * max(1.0, abs(exact))
    terms = np.array([d.jump * float(tangent(d.location)) for d in ig.discontinuities(variable(th))])
    if name == "smooth":
        assert est.derivative == reference.derivative
        return
    assert reference.derivative_stderr == 0.0  # the interior term is zero at every sample
    predicted = np.abs(terms).sum() ** 2 - terms.sum() ** 2
    measured = est.derivative_stderr**2 * N
    if predicted == 0.0:
        # all jump terms share a sign: t_J / P_J is constant, and the spread of a constant is rounding,
        # which the shared policy (flatland.core.stats.spread) reports as exactly zero on every CPU
        assert measured == 0.0
        return
    p = np.abs(terms[terms > 0]).sum() / np.abs(terms).sum()  # probability of the positive value
    spread = 2 * np.abs(terms).sum()  # t_J / P_J takes the two values +Σ|t_j| and -Σ|t_j|
    fourth = p * (1 - p) * spread**4 * (1 - 3 * p * (1 - p))
    assert abs(measured - predicted) <= Z * np.sqrt((fourth - predicted**2) / N), (measured, predicted)


def test06_the_guides_example_registers_in_its_own_table_only(example):
    assert example.EXAMPLE_METHODS.names == ("edge_sampling",)
    with pytest.raises(ValueError, match="edge_sampling"):
        estimate("step", 0.5, "edge_sampling", n=10)


# ------------------------------------------------------------------ the site's Sphinx extension
def build_tiny_site(tmp_path, page: str) -> str:
    """Build a one-page site with docs/_ext/project_docs.py; return its warnings and HTML."""
    import io
    import sys

    from sphinx.application import Sphinx

    src = tmp_path / "src"
    src.mkdir()
    (src / "conf.py").write_text(
        "extensions = ['myst_parser', 'project_docs']\n"
        "html_static_path = []\nproject_api_packages = ('flatland',)\n",
        encoding="utf-8",
    )
    (src / "index.md").write_text(page, encoding="utf-8")
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        warnings = io.StringIO()
        app = Sphinx(src, src, tmp_path / "out", tmp_path / "doctrees", "html", status=None, warning=warnings)
        app.build()
    finally:
        sys.path.remove(str(DOCS / "_ext"))
    return warnings.getvalue(), (tmp_path / "out" / "index.html").read_text(encoding="utf-8")


@SLOW
def test07_the_implements_directive_links_good_names_and_warns_about_bad_ones(tmp_path):
    page = "\n".join(
        [
            "(tiny-follow)=",
            "# Following the nearest jump",
            "",
            "```{py:function} flatland.textbook.reparam.follow_nearest(domain, discontinuities, points)",
            "```",
            "",
            "```{implements} tiny-follow",
            "flatland.textbook.reparam.follow_nearest",
            "flatland.no_such_function",
            "```",
            "",
            "```{implements} tiny-undefined",
            "flatland.textbook.reparam.follow_nearest",
            "```",
            "",
            "```{implements} Sec. 4.2",
            "flatland.textbook.reparam.follow_nearest",
            "```",
            "",
            "See {func}`flatland.also_missing`.",
        ]
    )
    warnings, html = build_tiny_site(tmp_path, page)
    # the label renders as its section's title, linked to the section
    assert re.search(
        r'href="#tiny-follow"[^>]*><span[^>]*>Following the nearest jump</span></a> in the code', html
    )
    assert 'href="#flatland.textbook.reparam.follow_nearest"' in html
    assert "flatland.no_such_function cannot be imported" in warnings
    assert "undefined label: 'tiny-undefined'" in warnings
    assert "argument must be a theory label such as 'theory-kernels', got 'Sec. 4.2'" in warnings
    assert "reference target not found: flatland.also_missing" in warnings
    # the bad name (not importable, and no page to link to), the undefined label, the bad argument
    assert warnings.count("WARNING") + warnings.count("ERROR") == 5


# ------------------------------------------------------------------ the scene-file guide
SCENE_GUIDE = DOCS / "guides" / "scene_files.md"
EXAMPLE_SCENE = DOCS / "guides" / "example_scene.json"


def test08_the_guides_example_scene_loads_and_renders_every_parameter():
    from flatland.render import render_gradient
    from flatland.scene import load_scene

    scene = load_scene(EXAMPLE_SCENE)
    assert len(scene.parameters) == 5
    for param in scene.parameters:
        grad = render_gradient(scene, param, "reparam", spp=2, seed=0, batches=2)
        assert grad.derivative.shape == (scene.camera.pixels,) and np.all(np.isfinite(grad.derivative))


def _mutate(change):
    import copy
    import json

    data = copy.deepcopy(json.loads(EXAMPLE_SCENE.read_text(encoding="utf-8")))
    change(data)
    return data


SCENE_ERRORS = [
    (lambda d: d["shapes"][1].update(radius=-0.25), "shapes[1].radius: must be > 0, got -0.25"),
    (
        lambda d: d["shapes"][2].update(colour="red"),
        "shapes[2].colour: unknown key (value 'red'); allowed keys: name, type, albedo, emission, "
        "one_sided, roughness, points",
    ),
    (
        lambda d: d["shapes"][0].update(points=[[-3.0, 0.0], [-3.0, 0.0]]),
        "shapes[0].points[1]: zero-length segment: point 1 [-3.0, 0.0] equals point 0 [-3.0, 0.0]",
    ),
    (
        lambda d: d["camera"].update(filter="sinc"),
        "camera.filter: must be one of box, tent, gaussian; got 'sinc'",
    ),
    (
        lambda d: d.update(parameters=["ball.rotate"]),
        "parameters[0]: unknown parameter 'ball.rotate': "
        "a circle does not change when rotated about its centre",
    ),
    (lambda d: d["shapes"][3].update(fade=0.7), "shapes[3].fade: must lie in [0.0, 0.5], got 0.7"),
]


@pytest.mark.parametrize(("change", "message"), SCENE_ERRORS)
def test09_the_guides_error_messages_are_the_real_ones(change, message):
    from flatland.scene import load_scene

    with pytest.raises(ValueError) as info:
        load_scene(_mutate(change))
    assert str(info.value) == message
    assert f"`{message}`" in SCENE_GUIDE.read_text(encoding="utf-8")


# ------------------------------------------------------------------ docstrings as the site reads them
SPHINX_ROLES = ("func", "class", "meth", "mod", "data", "attr", "obj", "exc", "any", "doc", "ref", "term")
SPHINX_DIRECTIVES = (
    "attribute",
    "method",
    "function",
    "seealso",
    "versionadded",
    "deprecated",
    "autosummary",
)


def _register_sphinx_markup() -> None:
    """Stand-ins for the Sphinx roles and directives docstrings use, so plain docutils can parse them."""
    from docutils import nodes
    from docutils.parsers.rst import Directive, directives, roles

    def literal_role(name, rawtext, text, lineno, inliner, options=None, content=None):
        return [nodes.literal(rawtext, text)], []

    class Container(Directive):
        optional_arguments = 10
        final_argument_whitespace = True
        has_content = True
        option_spec = None

        def run(self):
            node = nodes.container()
            self.state.nested_parse(self.content, self.content_offset, node)
            return [node]

    Container.option_spec = type(
        "AnyOption", (dict,), {"__missing__": lambda self, key: directives.unchanged}
    )()
    for name in SPHINX_ROLES:
        roles.register_local_role(name, literal_role)
        roles.register_local_role(f"py:{name}", literal_role)
    for name in SPHINX_DIRECTIVES:
        directives.register_directive(name, Container)


def _as_the_site_reads_it(doc: str, what: str, name: str, obj: Any) -> str:
    """The docstring after the site's maths and pipe passes, napoleon and the plain-type pass (docs/_ext)."""
    from sphinx.ext.napoleon import Config, NumpyDocstring

    lines = doc.splitlines()
    project_docs._process_docstring(None, what, name, obj, None, lines)
    config = Config(napoleon_google_docstring=False, napoleon_use_ivar=False, napoleon_use_param=False,
                    napoleon_use_rtype=False)  # fmt: skip
    lines = NumpyDocstring(lines, config, app=None, what=what, name=name, obj=obj).lines()
    project_docs._plain_types(None, what, name, obj, None, lines)
    return "\n".join(lines)


def _documented(package: str):
    """(what, qualified name, object) for every docstring the API reference renders."""
    for modname in public_modules(package):
        module = importlib.import_module(modname)
        yield "module", modname, module
        for attr in exported(module):
            obj = getattr(module, attr)
            if getattr(obj, "__module__", None) != modname:
                continue  # rendered on its defining module's page
            if inspect.isclass(obj):
                yield "class", f"{modname}.{attr}", obj
                for member, value in vars(obj).items():
                    if member.startswith("_"):
                        continue
                    target = value.__func__ if isinstance(value, staticmethod | classmethod) else value
                    if inspect.isfunction(target) or isinstance(target, property):
                        yield "method", f"{modname}.{attr}.{member}", target
            elif inspect.isroutine(obj):
                yield "function", f"{modname}.{attr}", obj


@pytest.mark.parametrize("package", AVAILABLE)
@SLOW
def test10_every_rendered_docstring_is_valid_restructuredtext(package):
    """What ``make docs`` would report as a docutils warning (an error under -W), found without Sphinx."""
    import io

    from docutils.frontend import get_default_settings
    from docutils.parsers.rst import Parser
    from docutils.utils import new_document

    _register_sphinx_markup()
    parser = Parser()
    settings = get_default_settings(Parser)
    settings.report_level, settings.halt_level = 2, 5
    problems = []
    for what, name, obj in _documented(package):
        doc = inspect.getdoc(obj)
        if not doc:
            continue
        settings.warning_stream = report = io.StringIO()
        parser.parse(_as_the_site_reads_it(doc, what, name, obj), new_document(name, settings))
        if report.getvalue():
            first = report.getvalue().strip().splitlines()[0]
            problems.append(f"{name}: {first.removeprefix(name + ':')}")
    assert not problems, "docstrings the docs build rejects:\n" + "\n".join(problems)


# ------------------------------------------------------------------ the image-method guide's example
IMAGE_PARAM = "light.translate.x"
"""A parameter with a nonzero derivative on the small films below, in both packages."""
RENDERABLE = [
    "flatland",
    pytest.param(
        "sphere3d",
        marks=pytest.mark.skipif(
            importlib.util.find_spec("embreex") is None, reason="needs the embree extra"
        ),
    ),
]


@pytest.fixture(scope="module")
def image_example():
    spec = importlib.util.spec_from_file_location(
        "image_method_example", DOCS / "guides" / "image_method_example.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _example_table(image_example, package):
    return getattr(image_example, f"{package.upper()}_EXAMPLE_METHODS")


def test11_the_image_method_guides_example_registers_in_its_own_tables_only(image_example):
    for package in PACKAGES:
        assert _example_table(image_example, package).names == ("richardson",)
        assert "richardson" not in importlib.import_module(f"{package}.render").GRADIENT_METHODS.names


@pytest.mark.parametrize("package", RENDERABLE)
def test12_the_image_method_guides_example_plugs_in_and_is_richardsons_combination(image_example, package):
    """One batch: the image is that batch's estimate, so the claimed combination holds bit for bit."""
    render = importlib.import_module(f"{package}.render")
    scene = importlib.import_module(f"{package}.scene").load_scene("shadow").to_dict()
    if package == "flatland":
        scene["camera"]["pixels"] = 12
    else:
        scene["camera"].update(width=8, height=6)
    method = _example_table(image_example, package).get("richardson")
    h = method.options["h"].default
    run = dict(spp=8, seed=3, batches=1)
    wide = render.render_gradient(scene, IMAGE_PARAM, "finite_difference", h=h, **run)
    narrow = render.render_gradient(scene, IMAGE_PARAM, "finite_difference", h=0.5 * h, **run)
    naive = render.render_gradient(scene, IMAGE_PARAM, "naive", **run)
    assert np.any(wide.derivative != narrow.derivative)  # else the combination could not be told apart
    with render.GRADIENT_METHODS.registered("richardson", method.func, *method.options.values()):
        g = render.render_gradient(scene, IMAGE_PARAM, "richardson", **run)
        with pytest.raises(ValueError, match=r"h.*-0\.5"):
            render.render_gradient(scene, IMAGE_PARAM, "richardson", h=-0.5, **run)
    assert "richardson" not in render.GRADIENT_METHODS.names
    assert (g.method, dict(g.options)) == ("richardson", {"h": h})
    assert np.array_equal(g.value, naive.value)  # the same primary samples: the naive value, bit for bit
    assert np.array_equal(g.derivative, (4.0 * narrow.derivative - wide.derivative) / 3.0)


# ------------------------------------------------------------------ the theory index and the citations
def test13_the_theory_index_has_one_row_per_implements_block_with_its_names_and_real_tests():
    rows = theory_index()
    assert rows, "docs/theory/index.md has no table"
    blocks = {argument: (page, names) for page, argument, names in BLOCKS if page.parent == DOCS / "theory"}
    problems = []
    seen: list[str] = []
    for row in rows:
        where = f"row {row.labels or row.paper!r}"
        if len(row.labels) != 1 or len(row.pages) != 1:
            problems.append(f"{where}: one {{ref}} label and one {{doc}} page per row")
            continue
        label, page = row.labels[0], row.pages[0]
        seen.append(label)
        if not row.sections and not row.paper.startswith("—"):
            problems.append(f"{where}: the paper column reads 'Sec. x.y' or '— (source)', got {row.paper!r}")
        if label not in blocks:
            problems.append(f"{where}: no implements block has this label")
            continue
        block_page, names = blocks[label]
        if block_page.stem != page:
            problems.append(f"{where}: the block is on {block_page.stem}.md, the row says {page}")
        if sorted(row.names) != sorted(names):
            problems.append(f"{where}: names differ from the block's: {sorted(set(row.names) ^ set(names))}")
        if not row.tests:
            problems.append(f"{where}: names no test")
        for test in row.tests:
            path, _, name = test.partition("::")
            source = ROOT / "tests" / path
            if not name or not source.is_file():
                problems.append(f"{where}: {test} is not tests/<file>::<test>")
            elif not re.search(
                rf"^def {re.escape(name)}[a-z]?_\w*\(", source.read_text(encoding="utf-8"), re.M
            ):
                problems.append(f"{where}: {path} has no test {name}")
    problems += [f"label {s!r} has two rows" for s in sorted({s for s in seen if seen.count(s) > 1})]
    problems += [f"implements block {s!r} has no row in the index" for s in sorted(set(blocks) - set(seen))]
    assert not problems, "\n".join(problems)


SHIPPED = ("flatland", "sphere3d", "tests", "tutorials", "docs", "README.md")
GENERATED = ("_build", "jupyter_execute", "__pycache__", ".ipynb_checkpoints", ".hypothesis")
"""Folders the build or the tools write (docs/.gitignore, .gitignore): not part of the sources."""


def shipped_text_files() -> list[Path]:
    found = []
    for top in (ROOT / name for name in SHIPPED):
        for path in [top] if top.is_file() else sorted(top.rglob("*")):
            rel = path.relative_to(ROOT)
            if not path.is_file() or any(part in GENERATED for part in rel.parts):
                continue
            if rel.parts[:3] == ("docs", "api", "generated") or rel.as_posix() == "docs/api/index.rst":
                continue  # written by the docs build from the docstrings, which are scanned
            if rel.parts[:2] == ("docs", "tutorials") and path.suffix == ".ipynb":
                continue  # copies of tutorials/*.ipynb made by the docs build
            found.append(path)
    return found


def test14_no_file_cites_a_document_that_is_not_shipped():
    # built from pieces so that this file does not match its own pattern
    pattern = re.compile("DESIGN" + " " + "[0-9]")
    files = shipped_text_files()
    assert any(p.name == "test_docs.py" for p in files) and any(p.suffix == ".ipynb" for p in files)
    hits = []
    for path in files:
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue  # images and other binary files
        for number, line in enumerate(text.splitlines(), 1):
            if pattern.search(line):
                hits.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()[:80]}")
    assert not hits, "citations of an unshipped document:\n" + "\n".join(hits)


ARCHITECTURE = DOCS / "theory" / "architecture.md"
DOTTED = re.compile(r"`~?((?:flatland|sphere3d)(?:\.\w+)*)`")
"""A dotted project name in backticks, plain (```flatland.state```) or in a role (``{func}`~flatland.x```)."""
PATH = re.compile(r"`((?:flatland|sphere3d)/[\w./]*)`")
"""A project path in backticks: ```flatland/core/```, ```flatland/integrals.py```."""


def all_modules(package: str) -> set[str]:
    """``package`` and every module under it, private ones and ``__main__`` included (found, not imported)."""
    pkg = importlib.import_module(package)
    return {package} | {info.name for info in pkgutil.walk_packages(pkg.__path__, package + ".")}


def test15_the_architecture_page_names_every_module_and_only_real_ones():
    text = ARCHITECTURE.read_text(encoding="utf-8")
    named = set(DOTTED.findall(text))
    modules = set().union(*(all_modules(p) for p in AVAILABLE))
    assert {"flatland.core.dual", "flatland.__main__"} <= modules  # the walk sees private modules
    missing = sorted(modules - named)
    assert not missing, f"modules missing from {ARCHITECTURE.name}: {missing}"
    unknown = []
    for name in sorted(named - modules):  # not a module: must be an attribute of one (a function, a class)
        if name.split(".")[0] not in AVAILABLE:
            continue
        try:
            resolve(name)
        except (ImportError, AttributeError):
            unknown.append(name)
    unknown += [path for path in PATH.findall(text) if not (ROOT / path).exists()]
    assert not unknown, f"{ARCHITECTURE.name} names what does not exist: {unknown}"


def test16_docstring_maths_in_dollars_becomes_math_roles_and_no_dollar_is_left():
    convert = project_docs.dollar_math
    assert convert("bias $h^2 I'''(θ)/6$ at $|x|$") == "bias :math:`h^2 I'''(θ)/6` at :math:`|x|`"
    assert convert("``$x$`` and $a$") == "``$x$`` and :math:`a`"  # literals stay as written
    assert convert("costs $5 and $6, or \\$3") == "costs $5 and $6, or $3"  # no formula: spaces inside
    from flatland.textbook.finite_difference import finite_difference

    lines = inspect.getdoc(finite_difference).splitlines()
    project_docs._process_docstring(
        None, "function", "flatland.textbook.finite_difference", None, None, lines
    )
    assert ":math:`I'(θ) + h^2 I'''(θ) / 6 + O(h^4)`" in "\n".join(lines)
    stray = []
    for package in AVAILABLE:
        for what, name, obj in _documented(package):
            lines = (inspect.getdoc(obj) or "").splitlines()
            project_docs._process_docstring(None, what, name, obj, None, lines)
            outside = [re.sub(r"``.+?``|:math:`[^`]*`", "", line) for line in lines]
            stray += [f"{name}: {line.strip()}" for line in outside if "$" in line]
    assert not stray, "dollars left as text (a formula split over lines, or a space inside):\n" + "\n".join(
        stray
    )


# ------------------------------------------------------------------ the study-file guide
STUDY_GUIDE = DOCS / "guides" / "study_files.md"
EXAMPLE_STUDY = DOCS / "guides" / "example_study.json"


def test17_the_guides_study_template_has_the_cells_it_describes_and_runs(tmp_path):
    """The guide counts 7 cells; the same file loads in both packages; it runs (its counts made small)."""
    from flatland.__main__ import PACKAGE
    from flatland.app.study import load_config, run_study

    config = load_config(EXAMPLE_STUDY, package=PACKAGE)
    labels = [(c.label, c.n) for c in config.cells]
    assert labels == [
        ("naive", 16), ("finite_difference h=0.01", 16), ("boundary", 4), ("boundary", 16),
        ("reparam kappa=100", 16), ("reparam kappa=1000", 16), ("reparam kappa=10000", 16),
    ]  # fmt: skip
    assert "1 + 1 + 2 + 3 = 7 cells" in STUDY_GUIDE.read_text(encoding="utf-8")
    assert "guides/study_files" in (DOCS / "index.md").read_text(encoding="utf-8")  # in the toctree
    if importlib.util.find_spec("embreex") is not None:
        assert (
            len(
                load_config(EXAMPLE_STUDY, package=importlib.import_module("sphere3d.__main__").PACKAGE).cells
            )
            == 7
        )
    small = load_config(EXAMPLE_STUDY, package=PACKAGE, samples=2)  # boundary's two counts become one cell
    result = run_study(small, progress=False, cache_dir=tmp_path)
    assert len(small.cells) == len(result.rows) == 6 and result.row("naive").biased
