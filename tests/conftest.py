"""Shared test fixtures: shipped vehicles, a seeded generator, the repository's vendored real data.

Hypothesis runs without a per-example deadline because the first call of a Numba kernel in a
fresh process may compile it (seconds). Choose another profile with ``HYPOTHESIS_PROFILE``.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

from vtoladapt import load_vehicle

settings.register_profile("vtoladapt", deadline=None)
settings.register_profile("thorough", deadline=None, max_examples=2000)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "vtoladapt"))

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


WARM_UP_MIN_TESTS = 300
"""A session of at least this many tests compiles the simulator's kernels first, in two processes."""


def pytest_collection_finish(session):
    """Compile (or load) the simulator's kernels before a long session starts.

    On a cold cache the loop's callees compile in two processes side by side
    (:func:`vtoladapt.simulate.load_kernels`: the controller in a second process), which saves
    about a third of the loop's compile time on two cores; otherwise the first test that flies
    compiles everything in one. A warm cache only loads the code (a second or two).
    ``VTOLADAPT_NO_WARM_UP=1`` skips it.
    """
    if len(session.items) < WARM_UP_MIN_TESTS or os.environ.get("VTOLADAPT_NO_WARM_UP", "") not in ("", "0"):
        return
    from vtoladapt.scenario import scenario_from_mapping
    from vtoladapt.simulate import load_kernels

    load_kernels(scenario_from_mapping({"name": "warm-up", "vehicle": "caltech_vtol", "duration_s": 0.1},
                                       "<warm-up>"))
