# Two commands set up a fresh machine: `make reproduce` (the paper's experiments, figures
# and report) and `make test` (the test suite). Both create the virtual environment.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= results

.PHONY: venv test test-boundscheck test-slow test-hypothesis test-numba-latest reproduce tune bench docs clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test,docs]'
	touch $(STAMP)

# The one set-up the documentation assumes (docs/index.md): .venv with the package, then
# `source .venv/bin/activate`. test, reproduce, docs, tune and bench run it first.
venv: $(STAMP)

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
TEST_SESSION_LIMIT ?= 60m
TEST_FLAGS = --durations=20 --durations-min=1 --timeout=$(TEST_TIMEOUT_S) --timeout-method=thread
XDIST_FLAGS = -n $(TEST_WORKERS) --dist loadgroup --max-worker-restart=0
# glibc reports a corrupted heap (then aborts) on the terminal, which CI has not: send it to stderr,
# so the abort a fresh clone's run still meets (docs/explanation/testing.md) names what it found
export LIBC_FATAL_STDERR_ = 1

test: $(STAMP)
	timeout --kill-after=30s $(TEST_SESSION_LIMIT) $(PY) -X faulthandler -m pytest $(TEST_FLAGS) \
	    $(if $(filter 0,$(TEST_WORKERS)),,$(XDIST_FLAGS))

test-slow: $(STAMP)
	$(PY) -X faulthandler -m pytest $(TEST_FLAGS) --timeout=$(TEST_TIMEOUT_SLOW_S) -m slow

# The property tests with fresh examples, within a budget (tests/conftest.py's "ci" Hypothesis profile: each
# property's own count, at most 300, and HYPOTHESIS_CI_BUDGET_S of them per process, default 900 s), for a
# scheduled job beside make test, whose derandomized examples are the same every run.
test-hypothesis: $(STAMP)
	HYPOTHESIS_PROFILE=ci $(PY) -X faulthandler -m pytest $(TEST_FLAGS) -m 'hypothesis and not slow' $(XDIST_FLAGS)

# The suite with every compiled kernel checking its indices (NUMBA_BOUNDSCHECK=1: an index outside an array
# raises IndexError instead of reading or writing beside it), in a kernel cache of its own (Numba's cache does
# not key on the flag). How issue #32's abort was found: a test handed a kernel an array shorter than its
# layout, and the write past its end corrupted the heap. Slower (every kernel compiled twice as checked code);
# run it after changing a kernel or a test that calls one directly.
test-boundscheck: $(STAMP)
	NUMBA_BOUNDSCHECK=1 NUMBA_CACHE_DIR=$(abspath $(VENV))/numba-cache-boundscheck $(MAKE) test TEST_TIMEOUT_S=2400

# The suite on the newest Numba and llvmlite releases instead of the pinned ones (pyproject.toml), in a
# virtual environment of its own: what the next Numba breaks shows here first (src/vtoladapt/_numba_abi.py
# is the one module holding what the package takes from Numba's internals). pip warns that the upgrade
# leaves vtoladapt's pin; that is the point. The kernels compile into a cache of their own, emptied on every
# run (the package's stale-cache check, vtoladapt/_kernel_cache.py, cleans its own __pycache__ only).
NUMBA_LATEST_VENV := .venv-numba-latest
test-numba-latest:
	$(MAKE) $(NUMBA_LATEST_VENV)/.installed VENV=$(NUMBA_LATEST_VENV)
	$(NUMBA_LATEST_VENV)/bin/python -m pip install --quiet --upgrade numba llvmlite
	$(NUMBA_LATEST_VENV)/bin/python -c "import numba, llvmlite; print('numba', numba.__version__, 'llvmlite', llvmlite.__version__)"
	rm -rf $(NUMBA_LATEST_VENV)/numba-cache
	NUMBA_CACHE_DIR=$(abspath $(NUMBA_LATEST_VENV))/numba-cache $(MAKE) test VENV=$(NUMBA_LATEST_VENV)

reproduce: $(STAMP)
	$(VENV)/bin/vtoladapt reproduce --out $(OUT)

# Re-tune every law on the paper's comparison: the shared loop gains and its own, one budget for every law
# (23 min on 2 cores shared with other jobs). make reproduce reads the shipped results in scenarios/tuned/ and does not re-tune.
tune: $(STAMP)
	$(VENV)/bin/vtoladapt tune scenarios/paper_comparison.toml --controller all --out scenarios/tuned --force

# The documentation site, offline and strict: a warning, a broken cross-reference or a missing file fails
# it (-W --keep-going -n). Runs the examples the tutorials take figures from (once per version of each
# script) and writes docs/_build/html; open docs/_build/html/index.html. tools/check_site.py checks its
# layout in headless Chromium. Not quiet (no -q): Sphinx's progress through the pages shows, and
# docs/conf.py prints a line as each example starts and ends (a fresh build is minutes of them).
docs: $(STAMP)
	$(PY) -m sphinx -b html -W --keep-going -n docs docs/_build/html

bench: $(STAMP)
	$(PY) benchmarks/run_benchmarks.py

clean:
	rm -rf $(VENV) $(NUMBA_LATEST_VENV) $(OUT) .pytest_cache docs/_build docs/_generated docs/reference/generated
