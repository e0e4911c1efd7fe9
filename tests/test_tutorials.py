"""The tutorials: diffable, well-formed, and executed top to bottom.

Each tutorial is a pair ``tutorials/NN_name.ipynb`` (committed without outputs, what a
student opens) and ``tutorials/NN_name.py`` (jupytext percent format, what a reviewer
diffs). The tests check that the pair agrees cell for cell, that the notebook carries
no outputs, that it follows the course's cell conventions (docs/guides/tutorials.md),
and finally run it top to bottom: a cell that raises, including a failing ``assert`` in a
check cell, fails the test, and so does anything written to stderr (warnings included),
which the docs build would also reject.

The notebooks a test process runs share one Jupyter kernel (a process of its own, driven by
nbclient), its namespace reset (``%reset -f``), figures closed and matplotlib's settings
restored before each notebook: a name a notebook uses without defining it fails as in a
fresh kernel, and the kernel's start and the imports (minutes on a slow shared machine) are
paid once per process instead of once per notebook.

A notebook that passes is handed to the docs build: ``make docs`` executes the same
notebooks through myst-nb's cache (``docs/_build/.jupyter_cache``, keyed by the code
cells' sources), so it finds this run's outputs there and does not execute them again.
A notebook changed since, or a docs build without a test run before it, executes as usual.
"""

from __future__ import annotations

import atexit
import fcntl
import os
import re
import tempfile
import time
import warnings
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

PREFIX = """\
get_ipython().run_line_magic("reset", "-f")  # the previous notebook's names are gone
import matplotlib as _mpl, matplotlib.pyplot as _plt, os as _os, sys as _sys
_plt.close("all"); _mpl.rcdefaults(); _os.chdir({workdir!r})
if {root!r} not in _sys.path: _sys.path.insert(0, {root!r})
from tests.figure_checks import install_notebook_check
install_notebook_check({dump!r})
del _mpl, _plt, _os, _sys, install_notebook_check
get_ipython().execution_count = 0  # the notebook's first cell is [1], as in a fresh kernel
"""
"""The first cell of every run, taken out again after it: a clean namespace, figures and rc settings,
and every figure a cell returns checked for layout defects (tests/figure_checks.py, written to stderr)."""


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


class _Kernel:
    """One IPython kernel per test process, shared by the notebooks that process runs (module
    docstring), started on first use, started again if a notebook killed it."""

    manager = None

    @classmethod
    def get(cls, sockets: Path):
        from jupyter_client.manager import KernelManager

        if cls.manager is None or not cls.manager.is_alive():
            if cls.manager is not None:
                cls.manager.shutdown_kernel(now=True)
            sockets.mkdir(parents=True, exist_ok=True)
            # IPC sockets in a private folder: no TCP ports to race for with other processes
            cls.manager = KernelManager(kernel_name="python3", transport="ipc", ip=str(sockets / "kernel"))
            cls.manager.start_kernel(env=_kernel_environment(), cwd=str(TUTORIALS))
            atexit.register(cls.manager.shutdown_kernel, now=True)
        return cls.manager


def _run_notebook(path: Path, tmp_path: Path) -> None:
    from nbclient import NotebookClient
    from nbclient.exceptions import CellExecutionError

    nb = read_notebook(path)
    dump = os.environ.get("FIGURE_DUMP", "") and str(Path(os.environ["FIGURE_DUMP"]) / path.stem)
    prefix = PREFIX.format(workdir=str(TUTORIALS), root=str(ROOT), dump=dump or None)
    nb.cells.insert(0, nbformat.v4.new_code_cell(prefix))
    manager = _Kernel.get(Path(tempfile.gettempdir()) / f"tutorial-kernel-{os.getpid()}")
    client = NotebookClient(nb, km=manager, timeout=CELL_TIMEOUT)
    start, error = time.perf_counter(), ""
    # the client machinery's own deprecation notices are not the notebook's: the kernel is a
    # process of its own, and what the notebook writes to stderr is checked below
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            client.execute()
        except CellExecutionError as exc:
            error = str(exc)
        finally:
            if client.kc is not None:  # the client's channels; the kernel stays for the next notebook
                client.kc.stop_channels()
    seconds = time.perf_counter() - start
    assert not error, ANSI.sub("", error)
    nb.cells.pop(0)
    executed = tmp_path / path.name
    nbformat.write(nb, executed)
    for i, cell in code_cells(nb):
        for out in cell.outputs:
            assert out.output_type != "error", (
                f"{path.name} cell {i}: {out.get('ename')}: {out.get('evalue')}"
            )
            text = out.get("text", "")
            assert not (out.output_type == "stream" and out.name == "stderr"), (
                f"{path.name} cell {i} wrote to stderr:\n{text}"
            )
    _hand_to_the_docs_build(executed, ROOT / "docs" / "tutorials" / path.name, seconds)


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
    # one worker at a time: the cache is an sqlite database that the first caller creates, and two
    # workers creating it at once fail ("table settings already exists"); a lock file beside it
    DOCS_CACHE.parent.mkdir(parents=True, exist_ok=True)
    with open(DOCS_CACHE.parent / ".jupyter_cache.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
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
