# Two commands set up a fresh machine: `make reproduce` (the paper's experiments, figures
# and report) and `make test` (the test suite). Both create the virtual environment.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= results

.PHONY: test test-slow reproduce tune bench docs clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test,docs]'
	touch $(STAMP)

# The suite in TEST_WORKERS processes (pytest-xdist; tests/conftest.py groups each module, and the
# modules sharing a session fixture, into one process). TEST_WORKERS=0 runs it in this process.
TEST_WORKERS ?= 2
# The suite fails fast and never hangs:
# - a worker process that dies (a native crash) ends the run at once with the test named
#   (--max-worker-restart=0): a crash is a defect to find, never re-run; with a restart, xdist's
#   loadgroup scheduler waits forever for the dead worker's group;
# - a test (with its fixtures) that runs past TEST_TIMEOUT_S has every thread's stack printed and its
#   process ended (pytest-timeout's thread method), which then ends the run as above;
# - the whole run is ended after TEST_SESSION_LIMIT (GNU timeout), whatever else happens;
# - faulthandler prints every thread's stack on a native abort (-X faulthandler).
# The 20 slowest tests are listed at the end (--durations).
TEST_TIMEOUT_S ?= 600
TEST_TIMEOUT_SLOW_S ?= 3600
TEST_SESSION_LIMIT ?= 30m
TEST_FLAGS = --durations=20 --durations-min=1 --timeout=$(TEST_TIMEOUT_S) --timeout-method=thread
XDIST_FLAGS = -n $(TEST_WORKERS) --dist loadgroup --max-worker-restart=0

test: $(STAMP)
	timeout --kill-after=30s $(TEST_SESSION_LIMIT) $(PY) -X faulthandler -m pytest $(TEST_FLAGS) \
	    $(if $(filter 0,$(TEST_WORKERS)),,$(XDIST_FLAGS))

test-slow: $(STAMP)
	$(PY) -X faulthandler -m pytest $(TEST_FLAGS) --timeout=$(TEST_TIMEOUT_SLOW_S) -m slow

reproduce: $(STAMP)
	$(VENV)/bin/vtoladapt reproduce --out $(OUT)

# Re-tune every law on the paper's comparison: the shared loop gains and its own, one budget for every law
# (23 min on 2 cores shared with other jobs). make reproduce reads the shipped results in scenarios/tuned/ and does not re-tune.
tune: $(STAMP)
	$(VENV)/bin/vtoladapt tune scenarios/paper_comparison.toml --controller all --out scenarios/tuned --force

# The documentation site, offline and strict: a warning, a broken cross-reference or a missing file fails
# it (-W --keep-going -n). Runs the examples the tutorials take figures from (once per version of each
# script) and writes docs/_build/html; open docs/_build/html/index.html. tools/check_site.py checks its
# layout in headless Chromium.
docs: $(STAMP)
	$(PY) -m sphinx -b html -W --keep-going -n -q docs docs/_build/html

bench: $(STAMP)
	$(PY) benchmarks/run_benchmarks.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache docs/_build docs/_generated docs/reference/generated
