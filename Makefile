# Two commands set up a fresh machine: `make reproduce` (the paper's experiments, figures
# and report) and `make test` (the test suite). Both create the virtual environment.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= results

.PHONY: test test-slow reproduce tune bench clean

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

# Re-tune every law on the paper's comparison: the shared loop gains and its own, one budget for every law
# (23 min on 2 cores shared with other jobs). make reproduce reads the shipped results in scenarios/tuned/ and does not re-tune.
tune: $(STAMP)
	$(VENV)/bin/vtoladapt tune scenarios/paper_comparison.toml --controller all --out scenarios/tuned --force

bench: $(STAMP)
	$(PY) benchmarks/run_benchmarks.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache
