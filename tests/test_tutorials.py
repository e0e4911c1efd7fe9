"""The tutorials: diffable, well-formed, and executed top to bottom.

Each tutorial is a pair ``tutorials/NN_name.ipynb`` (committed without outputs, what a
student opens) and ``tutorials/NN_name.py`` (jupytext percent format, what a reviewer
diffs). The tests check that the pair agrees cell for cell, that the notebook carries
no outputs, that it follows the course's cell conventions (docs/guides/tutorials.md),
and finally run it in a fresh Jupyter kernel: a cell that raises, including a failing
``assert`` in a check cell, fails the test, and so does anything written to stderr
(warnings included), which the docs build would also reject.

Execution happens in a subprocess (nbclient driving an ipykernel), so the test
process's ``filterwarnings = error`` applies to neither the Jupyter client machinery
nor the notebook's own kernel.

A notebook that passes is handed to the docs build: ``make docs`` executes the same
notebooks through myst-nb's cache (``docs/_build/.jupyter_cache``, keyed by the code
cells' sources), so it finds this run's outputs there and does not execute them again.
A notebook changed since, or a docs build without a test run before it, executes as usual.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import jupytext
import nbformat
import pytest

from tests.tiers import HANG

ROOT = Path(__file__).resolve().parent.parent
TUTORIALS = ROOT / "tutorials"
DOCS_CACHE = ROOT / "docs" / "_build" / ".jupyter_cache"  # docs/conf.py: nb_execution_cache_path
NOTEBOOKS = sorted(TUTORIALS.glob("[0-9][0-9]_*.ipynb"))
SCRIPTS = sorted(TUTORIALS.glob("[0-9][0-9]_*.py"))
IDS = [nb.stem for nb in NOTEBOOKS]
PAIRING = "ipynb,py:percent"
CELL_TIMEOUT = HANG  # seconds per cell: a guard against a hung kernel, not a speed requirement
PLOT_CALL = re.compile(r"\bplot_[a-z_]+\(")
ANSI = re.compile(r"\x1b\[[0-9;]*m")  # colour codes in IPython tracebacks

RUNNER = r"""
import json, sys, time
import nbformat
from jupyter_client.manager import KernelManager
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError

source, target, workdir, sockets, timeout, root, dump = sys.argv[1:8]
nb = nbformat.read(source, as_version=4)
# a first cell, taken out again below: every figure a cell returns is checked for layout defects
# (tests/figure_checks.py), which are written to stderr
check = f"import sys; sys.path.insert(0, {root!r})\n"
check += f"from tests.figure_checks import install_notebook_check; install_notebook_check({dump or None!r})"
nb.cells.insert(0, nbformat.v4.new_code_cell(check))
# IPC sockets in a private folder: no TCP ports to race for with other processes on the machine
kernel = KernelManager(kernel_name="python3", transport="ipc", ip=sockets)
client = NotebookClient(nb, km=kernel, timeout=int(timeout), resources={"metadata": {"path": workdir}})
start = time.perf_counter()
status, error = 0, ""
try:
    client.execute()
except CellExecutionError as exc:
    status, error = 1, str(exc)
nb.cells.pop(0)
nbformat.write(nb, target)
print(json.dumps({"seconds": time.perf_counter() - start, "error": error}))
sys.exit(status)
"""


def read_notebook(path: Path) -> nbformat.NotebookNode:
    return nbformat.read(path, as_version=4)


def code_cells(nb: nbformat.NotebookNode) -> list[tuple[int, nbformat.NotebookNode]]:
    return [(i, c) for i, c in enumerate(nb.cells) if c.cell_type == "code"]


def is_check(cell: nbformat.NotebookNode) -> bool:
    return cell.cell_type == "code" and cell.source.lstrip().startswith("# check")


def test01_every_notebook_has_its_percent_script_and_vice_versa():
    assert NOTEBOOKS, "no tutorials found"
    assert [p.stem for p in NOTEBOOKS] == [p.stem for p in SCRIPTS]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test02_notebook_is_committed_without_outputs(path):
    nb = read_notebook(path)
    for i, cell in code_cells(nb):
        assert cell.outputs == [], f"{path.name} cell {i} has outputs: clear them before committing"
        assert cell.execution_count is None, f"{path.name} cell {i} has an execution count"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test03_notebook_matches_its_percent_script(path):
    nb = read_notebook(path)
    script = jupytext.read(path.with_suffix(".py"))
    assert nb.metadata.get("jupytext", {}).get("formats") == PAIRING
    assert script.metadata.get("jupytext", {}).get("formats") == PAIRING
    assert nb.metadata.get("kernelspec", {}).get("name") == "python3"
    in_nb = [(c.cell_type, c.source.strip()) for c in nb.cells]
    in_script = [(c.cell_type, c.source.strip()) for c in script.cells]
    for i, (a, b) in enumerate(zip(in_nb, in_script, strict=False)):
        assert a == b, f"{path.name} cell {i} differs from {path.stem}.py: run `jupytext --sync {path}`"
    assert len(in_nb) == len(in_script), f"{path.name}: cell counts differ; run `jupytext --sync {path}`"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test04_notebook_follows_the_cell_conventions(path):
    """docs/guides/tutorials.md: title, setup, prose before code, a check after each computation."""
    nb = read_notebook(path)
    cells = nb.cells
    number = int(path.name[:2])
    assert cells[0].cell_type == "markdown" and cells[0].source.startswith(f"# {number}. "), "title cell"
    code = code_cells(nb)
    setup_index, setup = code[0]
    assert "%matplotlib inline" in setup.source and re.search(r"^SEED = \d+", setup.source, re.M), (
        "the first code cell selects the inline backend and fixes SEED"
    )
    assert sum(is_check(c) for _, c in code) >= 2, "at least two check cells"
    for i, cell in code:
        before = cells[i - 1]
        after = cells[i + 1] if i + 1 < len(cells) else None
        where = f"{path.name} cell {i}"
        assert "pyplot" not in cell.source and "plt." not in cell.source, (
            f"{where}: figures come from the library's plotting helpers"
        )
        if is_check(cell):
            assert before.cell_type == "code" and not is_check(before), (
                f"{where}: a check follows its computation"
            )
            assert re.search(r"^\s*assert ", cell.source, re.M), f"{where}: a check cell asserts"
            continue
        assert before.cell_type == "markdown" and before.source.strip(), f"{where}: prose comes first"
        if i != setup_index and not PLOT_CALL.search(cell.source):
            assert after is not None and is_check(after), f"{where}: a computing cell is followed by a check"


def _kernel_environment() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("MPLBACKEND", None)  # the notebooks select the inline backend themselves
    env["JUPYTER_PLATFORM_DIRS"] = "1"  # the platformdirs layout, without jupyter_core's deprecation notice
    env["PYDEVD_DISABLE_FILE_VALIDATION"] = "1"  # ipykernel's debugger: no frozen-modules notice
    return env


def _notebook_runs(path: Path) -> type:
    """A test class of its own per notebook: ``make test`` hands out work by class and module
    (pytest-xdist ``--dist loadscope``), so the notebooks, the suite's longest tests, are shared
    among the workers instead of queueing on one."""

    def test05_notebook_runs_top_to_bottom_and_every_check_passes(self, tmp_path):
        _run_notebook(path, tmp_path)

    test = test05_notebook_runs_top_to_bottom_and_every_check_passes
    name = "TestNotebook" + path.stem.title().replace("_", "")  # 01_leibniz_rule: TestNotebook01LeibnizRule
    return type(name, (), {test.__name__: test})


for _path in NOTEBOOKS:
    _cls = _notebook_runs(_path)
    globals()[_cls.__name__] = _cls


def _run_notebook(path: Path, tmp_path: Path) -> None:
    executed = tmp_path / path.name
    sockets = tmp_path / "kernel"
    run = subprocess.run(
        [
            sys.executable,
            "-c",
            RUNNER,
            str(path),
            str(executed),
            str(TUTORIALS),
            str(sockets),
            str(CELL_TIMEOUT),
            str(ROOT),
            os.environ.get("FIGURE_DUMP", "") and str(Path(os.environ["FIGURE_DUMP"]) / path.stem),
        ],
        capture_output=True,
        text=True,
        env=_kernel_environment(),
        timeout=10 * CELL_TIMEOUT,
        check=False,
    )
    report = json.loads(run.stdout.strip().splitlines()[-1]) if run.stdout.strip() else {}
    assert run.returncode == 0, ANSI.sub("", report.get("error") or run.stderr[-4000:])
    nb = read_notebook(executed)
    for i, cell in code_cells(nb):
        for out in cell.outputs:
            assert out.output_type != "error", (
                f"{path.name} cell {i}: {out.get('ename')}: {out.get('evalue')}"
            )
            text = out.get("text", "")
            assert not (out.output_type == "stream" and out.name == "stderr"), (
                f"{path.name} cell {i} wrote to stderr:\n{text}"
            )
    _hand_to_the_docs_build(executed, ROOT / "docs" / "tutorials" / path.name, report["seconds"])


def _hand_to_the_docs_build(executed: Path, docs_path: Path, seconds: float) -> None:
    """Store the executed notebook in the docs build's myst-nb cache (module docstring), as myst-nb
    itself stores a notebook it executed. Without jupyter-cache (no docs extras) there is nothing to do."""
    try:
        from jupyter_cache import get_cache
        from jupyter_cache.base import CacheBundleIn
    except ImportError:
        return
    # the cache key hashes the code cells with their metadata, to which nbclient adds execution
    # times: the source notebook (what myst-nb looks up) is cached, with the executed outputs
    nb, ran = read_notebook(TUTORIALS / executed.name), read_notebook(executed)
    for cell, done in zip(nb.cells, ran.cells, strict=True):
        if cell.cell_type == "code":
            cell.outputs, cell.execution_count = done.outputs, done.execution_count
    nb.metadata["language_info"] = ran.metadata.get("language_info", {})
    cache = get_cache(DOCS_CACHE)
    cache.cache_notebook_bundle(
        CacheBundleIn(nb, str(docs_path), data={"execution_seconds": seconds}),
        check_validity=False,
        overwrite=True,
    )
    try:  # what myst-nb looks up: the docs copy of the source notebook, byte for byte the same
        cache.match_cache_notebook(read_notebook(TUTORIALS / executed.name))
    except KeyError:
        pytest.fail(f"{executed.name}: the docs build would not find these outputs (another cache key)")
