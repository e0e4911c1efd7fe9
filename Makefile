# Everything a fresh machine needs: Python >= 3.11, pip and make.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test test-all bench lint format docs clean

# Bytecode: pip installs without compiling the environment's thousands of modules (most are never
# imported), and Python compiles what is imported, once, and keeps it (even where the environment
# asks for no bytecode files). The venv gets no pip of its own (ensurepip compiles pip and
# setuptools: minutes on a slow machine); the system's pip installs into it (`--python`, pip >= 22.3,
# as Python 3.11 ships). To add a package: python3 -m pip --python .venv/bin/python install NAME
export PYTHONDONTWRITEBYTECODE :=

# an editable install maps the packages that exist when it runs: reinstall when one appears
$(STAMP): pyproject.toml $(wildcard */__init__.py)
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "Python >= 3.11 is required (PYTHON=$(PYTHON))")'
	$(PYTHON) -m venv --without-pip $(VENV)
	$(PYTHON) -m pip --python $(BIN)/python install --quiet --no-compile -e '.[dev,docs]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/python -m flatland demo --out out/flatland
	$(BIN)/python -m sphere3d demo --out out/sphere3d

# the suite on every core (pytest-xdist), one test module or class per worker at a time: a module's
# fixtures are built once; each tutorial notebook is a class of its own (tests/test_tutorials.py).
# test: all but the cases marked slow (tests/tiers.py); test-all: every test
WORKERS ?= auto
test: $(STAMP)
	$(BIN)/python -m pytest -n $(WORKERS) --dist loadscope -m "not slow"

test-all: $(STAMP)
	$(BIN)/python -m pytest -n $(WORKERS) --dist loadscope

bench: $(STAMP)
	$(BIN)/python -m benchmarks

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

docs: $(STAMP)
	$(BIN)/sphinx-build -W --keep-going -j auto -b html docs docs/_build/html

clean:
	rm -rf $(VENV) out docs/_build .pytest_cache .ruff_cache
