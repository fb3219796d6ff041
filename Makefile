# Two set-up commands that work on a fresh machine with only Python 3.11:
#   make demo   -> .venv, install, flatten a generated mesh, results in out/
#   make test   -> .venv, install with test extras, run the suite CI runs: every test not marked
#                  slow and every notebook executed and its claims checked
# and, once set up:
#   make test-all  -> everything, the tests marked slow included (the gradient grid, the sweeps
#                     over ../shared/data, every notebook executed, the README examples run)
#   make test-fast -> the suite without the tests marked slow (no notebooks executed)
#   make notebooks -> execute every notebook in notebooks/ in place (figures kept, progress
#                     output stripped), then check what each one claims
#   make docs      -> build the documentation site into site/ (mkdocs --strict)
PYTHON ?= python3
# Test processes (pytest-xdist, in the test extra): 2 for CI's 2 cores; `make test JOBS=1` runs
# the suite in one process. Tests are handed out by file, so a module's shared compilations
# stay in one process.
JOBS ?= 2
XDIST = $(if $(filter 1,$(JOBS)),,-n $(JOBS))
VENV := .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip

.PHONY: demo test test-all test-fast notebooks docs venv clean bench

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --upgrade pip
	$(PIP) install --quiet -e ".[test,peers,fast]"
	touch $@

venv: $(VENV)/.installed

demo: venv
	$(PY) -m jaxparam.demo --out out

test: venv
	$(PY) -m pytest -q -p no:cacheprovider $(XDIST) $(if $(XDIST),--dist loadfile) \
		-m "not slow or notebook" tests

test-all: venv
	$(PY) -m pytest -q -p no:cacheprovider $(XDIST) $(if $(XDIST),--dist loadfile) tests

test-fast: venv
	$(PY) -m pytest -q -p no:cacheprovider $(XDIST) $(if $(XDIST),--dist loadfile) -m "not slow" tests

notebooks: venv
	$(PIP) install --quiet -e ".[notebooks]"
	$(PY) notebooks/execute.py
	$(PY) -m pytest -q -p no:cacheprovider tests/test_notebooks.py

docs: venv
	$(PIP) install --quiet -e ".[docs]"
	NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict --site-dir site

bench: venv
	$(PY) benchmarks/linear.py

clean:
	rm -rf $(VENV) out site .pytest_cache
