# Two commands set up a fresh machine: `make reproduce` (the paper's experiments, figures
# and report) and `make test` (the test suite). Both create the virtual environment.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= results

.PHONY: test test-slow reproduce bench clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

# The suite in TEST_WORKERS processes (pytest-xdist; tests/conftest.py groups each module, and the
# modules sharing a session fixture, into one process). TEST_WORKERS=0 runs it in this process.
TEST_WORKERS ?= 2

test: $(STAMP)
	$(PY) -m pytest -n $(TEST_WORKERS) --dist loadgroup

test-slow: $(STAMP)
	$(PY) -m pytest -m slow

reproduce: $(STAMP)
	$(VENV)/bin/vtoladapt reproduce --out $(OUT)

bench: $(STAMP)
	$(PY) benchmarks/run_benchmarks.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache
