"""Sphinx configuration: theory pages, API reference from the docstrings, executed tutorials.

Build with ``make docs`` (``sphinx-build -W --keep-going -j auto -b html docs docs/_build/html``):
every warning is an error. ``DOCS_SOURCE_PAGES=0`` leaves out the highlighted source page of
each module (sphinx.ext.viewcode): CI sets it, as those pages check nothing and cost about
40 % of the build on a slow machine.

Generated at build time (git-ignored, never edited by hand):

- ``api/index.rst``: one recursive autosummary entry per importable package of
  :data:`API_PACKAGES`, so new modules of those packages appear in the reference
  without touching the docs;
- ``tutorials/NN_name.ipynb``: copies of the output-free notebooks of the
  repository's ``tutorials/`` folder, executed by myst-nb when the site is built
  (results cached in ``_build/.jupyter_cache`` between builds).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(DOCS / "_ext"))

import project_docs  # noqa: E402  (docs/_ext, after the path is set)

project = "reparam-lab"
author = "reparam-lab contributors"
copyright = "reparam-lab contributors"
release = "0.1.0"

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx_copybutton",
    "sphinx-mathjax-offline",  # MathJax 3 copied into _static: formulas typeset without a network
    "myst_nb",
    "project_docs",
]
if os.environ.get("DOCS_SOURCE_PAGES", "1") != "0":  # .ci/run: 0 (module docstring)
    extensions.append("sphinx.ext.viewcode")  # each module's highlighted source, linked from its API page

project_api_packages = API_PACKAGES = ("flatland", "sphere3d")
"""Packages in the API reference, each documented recursively when it can be imported."""

project_docs.write_api_index(DOCS / "api" / "index.rst", API_PACKAGES)
project_docs.copy_tutorials(ROOT / "tutorials", DOCS / "tutorials")

source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
root_doc = "index"
exclude_patterns = ["_build", "jupyter_execute", "**.ipynb_checkpoints", "_templates", ".gitignore"]
templates_path = ["_templates"]

# --- autodoc / autosummary / napoleon (numpydoc-style docstrings)
autosummary_generate = True
autosummary_ignore_module_all = True  # members defined in the module; __all__ filtering in project_docs
autosummary_imported_members = False
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_typehints_format = "short"
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_ivar = False  # attributes as ".. attribute::" entries: their types are not fuzzy-matched
napoleon_use_rtype = False
napoleon_use_param = False  # no cross-references made of type words ("shape", "optional")
add_module_names = False

# --- MyST and notebooks
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3
nb_execution_mode = "cache"
nb_execution_cache_path = str(DOCS / "_build" / ".jupyter_cache")
nb_execution_timeout = 300
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_output_stderr = "warn"
nb_merge_streams = True

# --- HTML
html_theme = "furo"  # a readable, searchable theme with a light and a dark mode
html_title = "reparam-lab"
html_static_path = ["_static"]
copybutton_prompt_text = r">>> |\.\.\. |\$ "  # copy commands and code, not their prompts
copybutton_prompt_is_regexp = True
