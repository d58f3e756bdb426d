"""Shared test fixtures: shipped vehicles, a seeded generator, the repository's vendored real data.

Hypothesis runs without a per-example deadline because the first call of a Numba kernel in a
fresh process may compile it (seconds). Choose its profile with ``HYPOTHESIS_PROFILE``:

``vtoladapt`` (the default)
    derandomized: the same commit runs the same examples, so ``make test`` from a clean clone
    cannot fail on a draw no earlier run made. For every run whose verdict must be reproducible:
    a change's tests, CI's gate (``make test``), a release.
``ci``
    fresh examples every run, within a fixed budget: each property's own count (capped at
    :data:`CI_EXAMPLES`; a property without one gets Hypothesis's 100), and at most
    :data:`CI_BUDGET_S` of property tests per process (``HYPOTHESIS_CI_BUDGET_S``), after which the
    remaining properties are skipped and say so. A failure prints the blob that reproduces it
    (``@reproduce_failure``). For a scheduled CI job beside the gate, ``make test-hypothesis``: it
    keeps searching, run after run, at a cost known in advance; a find becomes an ``@example``.
``thorough``
    at least :data:`THOROUGH_EXAMPLES` fresh examples per property, no budget: by hand, to search
    hard after changing a kernel (hours).

``make test`` runs the suite in two processes (pytest-xdist, ``--dist loadgroup``): each test
module goes to one process whole, so its module-scoped fixtures are computed once, and the
modules that share an expensive session fixture (:data:`SHARED_SESSION_FIXTURES`) go to the
same process, so it is computed once too. Plain ``pytest`` runs everything in one process.
"""
from __future__ import annotations

import contextlib
import io
import os
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import settings

from vtoladapt import load_vehicle

# examples/ holds the modules the tutorials show (examples/example_law.py, the user's law the tests fly)
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))

HYPOTHESIS_PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "vtoladapt")
THOROUGH_EXAMPLES = 2000
CI_EXAMPLES = 300
"""The ``ci`` profile's examples per property at most (the default suite's largest counts are 300-500)."""
CI_BUDGET_S = float(os.environ.get("HYPOTHESIS_CI_BUDGET_S", "900"))
"""The ``ci`` profile's time for property tests per process (s): the budget of a scheduled search job."""
# derandomized: the same commit runs the same examples, so a clean clone's suite does not flake on
# a draw no earlier run made; "thorough" draws fresh examples every run (that is how to search).
# Every setting that matters is stated: a profile inherits the rest from Hypothesis's defaults, and
# where the CI variable is set those defaults are its derandomized "ci" profile.
settings.register_profile("vtoladapt", deadline=None, derandomize=True)
settings.register_profile(
    "thorough", deadline=None, derandomize=False, max_examples=THOROUGH_EXAMPLES
)
# "ci" replaces Hypothesis's built-in profile of that name (derandomized, loaded where a CI variable is
# set): here it is the search within a budget, and only HYPOTHESIS_PROFILE=ci loads it
settings.register_profile(
    "ci", deadline=None, derandomize=False, max_examples=100, print_blob=True
)
settings.load_profile(HYPOTHESIS_PROFILE)


SHORT_FAN_SCENARIO = """name = "b"
vehicle = "caltech_vtol"
duration_s = 1.0
seed = 3
[wind.fan_array]
schedule = [[0, 60], [1, 60]]
"""
"""A campaign's base: a 1 s hold in the fan at 60 % (short enough to run many in a test)."""


def examples(n: int) -> int:
    """A property's example count: ``n``, or at least :data:`THOROUGH_EXAMPLES` under the ``thorough`` profile.

    A test's own ``@settings(max_examples=...)`` overrides the loaded profile, so every property
    that sets its count goes through this, or ``HYPOTHESIS_PROFILE=thorough`` would not reach it.
    """
    if HYPOTHESIS_PROFILE == "thorough":
        return max(n, THOROUGH_EXAMPLES)
    if HYPOTHESIS_PROFILE == "ci":
        return min(n, CI_EXAMPLES)
    return n


_ci_search_s = [0.0]  # the ci profile's property time spent in this process


def pytest_runtest_setup(item):
    """Under the ``ci`` profile, skip a property once this process has spent :data:`CI_BUDGET_S` on them."""
    if HYPOTHESIS_PROFILE == "ci" and item.get_closest_marker("hypothesis") and _ci_search_s[0] >= CI_BUDGET_S:
        pytest.skip(f"the ci profile's search budget is spent ({_ci_search_s[0]:.0f} s of HYPOTHESIS_CI_BUDGET_S = "
                    f"{CI_BUDGET_S:g} s)")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item):
    """Count the time of property tests against the ``ci`` profile's budget."""
    t0 = time.monotonic()
    yield
    if HYPOTHESIS_PROFILE == "ci" and item.get_closest_marker("hypothesis"):
        _ci_search_s[0] += time.monotonic() - t0


REPO_DATA_DIR = Path(__file__).resolve().parents[1] / "data"
"""The real data vendored in the repository (small subsets); each folder has a SOURCE.md."""

SHIPPED_VEHICLES = ("caltech_vtol", "px4_standard_vtol")


@pytest.fixture(scope="session")
def caltech():
    """The paper's aircraft (Tables I-III)."""
    return load_vehicle("caltech_vtol")


@pytest.fixture(scope="session")
def px4():
    """PX4's Gazebo standard VTOL, converted."""
    return load_vehicle("px4_standard_vtol")


@pytest.fixture(scope="session", params=SHIPPED_VEHICLES)
def any_vehicle(request):
    """Each shipped vehicle in turn."""
    return load_vehicle(request.param)


@pytest.fixture
def rng() -> np.random.Generator:
    """A fixed-seed generator, fresh for every test."""
    return np.random.default_rng(20200531)


REPRODUCED_VARIANTS = 4
"""Seeded variants of each experiment in the ``reproduced`` fixture (the real run flies 30 and 10)."""


@pytest.fixture(scope="session")
def reproduced(tmp_path_factory):
    """``vtoladapt reproduce`` at 0.12 of the paper's durations, each experiment over
    :data:`REPRODUCED_VARIANTS` seeded variants, the ablation over 2 and the method x wind table
    over 1: its output folder (shared by the tests of the experiments and of the reports, so it
    runs once)."""
    from vtoladapt.experiments import reproduce

    out = tmp_path_factory.mktemp("repro") / "results"
    reproduce(out, duration_scale=0.12, show_progress=False, variants=REPRODUCED_VARIANTS,
              ablation_variants=2, wind_variants=1)
    return out


@pytest.fixture(scope="session")
def cli_fit(tmp_path_factory):
    """``vtoladapt tunnel --seed 3`` then ``vtoladapt fit --fast --seed 1 --truth``, through the
    CLI's entry point: the folder, the tunnel CSV and truth side file, both exit codes and what
    the fit printed (shared by the fitting's end-to-end test and the report's R-hat test, so the
    fit runs once)."""
    from vtoladapt.cli import main

    root = tmp_path_factory.mktemp("cli_fit")
    csv_path, side, out = root / "tunnel.csv", root / "tunnel.truth.json", root / "fit"
    tunnel_rc = main(["tunnel", "--vehicle", "caltech_vtol", "--out", str(csv_path), "--seed", "3"])
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        fit_rc = main(["fit", str(csv_path), "--out", str(out), "--fast", "--seed", "1",
                       "--truth", str(side)])
    return SimpleNamespace(csv_path=csv_path, side=side, out=out, tunnel_rc=tunnel_rc,
                           fit_rc=fit_rc, stdout=printed.getvalue())


SHARED_SESSION_FIXTURES = ("reproduced", "cli_fit")
"""Session fixtures that take seconds: under ``--dist loadgroup`` every module using one runs in
the same process."""


@pytest.hookimpl(tryfirst=True)
@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Under ``--dist loadgroup``, one group per module, modules sharing a fixture of
    :data:`SHARED_SESSION_FIXTURES` merged into one group.

    First among the hooks: xdist's worker turns the ``xdist_group`` marks into node ids in its own
    ``pytest_collection_modifyitems``, which pluggy otherwise calls before this one (the plugin registers
    after the conftest), and marks added after it are ignored: every module was split across both
    processes and its module fixtures (the docs site's build among them) computed in each. (Both this order
    and the guard below had kept every module unsplit in name only; tests/test_suite_grouping.py checks it.)"""
    # a worker sees --dist as "no" and xdist's own "loadgroup" flag instead (xdist.remote.setup_config); the
    # guard read --dist alone, so no module was ever grouped
    if not (getattr(config.option, "loadgroup", False) or getattr(config.option, "dist", "no") == "loadgroup"):
        return
    group = {item.module.__name__: item.module.__name__ for item in items}

    def root(name: str) -> str:
        while group[name] != name:
            name = group[name]
        return name

    for fixture in SHARED_SESSION_FIXTURES:
        users = sorted({item.module.__name__ for item in items if fixture in item.fixturenames})
        for name in users[1:]:
            group[root(name)] = root(users[0])
    for item in items:
        item.add_marker(pytest.mark.xdist_group(root(item.module.__name__)))


WARM_UP_MIN_TESTS = 300
"""A session of at least this many tests compiles the simulator's kernels first, in two processes."""


def pytest_collection_finish(session):
    """Compile (or load) the simulator's kernels before a long session starts.

    On a cold cache the loop's callees compile in two processes side by side
    (:func:`vtoladapt.sim.driver.load_kernels`: the controller in a second process), which saves
    about a third of the loop's compile time on two cores; otherwise the first test that flies
    compiles everything in one. A warm cache only loads the code (a second or two).
    Under pytest-xdist the workers take turns through a file lock: the first compiles, the
    others then load its cache instead of compiling the same kernels again side by side.
    ``VTOLADAPT_NO_WARM_UP=1`` skips it.
    """
    if len(session.items) < WARM_UP_MIN_TESTS or os.environ.get("VTOLADAPT_NO_WARM_UP", "") not in ("", "0"):
        return
    from vtoladapt.sim.scenario import scenario_from_mapping
    from vtoladapt.sim.driver import load_kernels

    scenario = scenario_from_mapping({"name": "warm-up", "vehicle": "caltech_vtol", "duration_s": 0.1},
                                     "<warm-up>")
    if getattr(session.config, "workerinput", None) is None:
        load_kernels(scenario)
        return
    import fcntl

    import vtoladapt

    # beside the kernel cache it guards, so that any two sessions on this install take turns
    lock_path = Path(vtoladapt.__file__).parent / "__pycache__" / "warm-up.lock"
    try:
        lock_path.parent.mkdir(exist_ok=True)
        lock = open(lock_path, "a")
    except OSError:  # a read-only install: its cache cannot be written anyway
        load_kernels(scenario)
        return
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        load_kernels(scenario)  # the lock goes with the file's closing
