"""``make test`` fails fast and never hangs: the flags the Makefile gives pytest, tried on a small
suite of its own whose tests crash their process or hang.

Before these flags, a worker process that died under ``--dist loadgroup`` (a native abort) was
replaced and its group never handed out again: both workers sat idle until the job was killed.
The flags are read from the Makefile itself, so the test follows what ``make test`` runs.
"""
from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# three groups of short tests; one test of group "a" ends its process as a native abort does
CRASHING_SUITE = '''
import os, time, pytest

@pytest.mark.xdist_group("a")
@pytest.mark.parametrize("i", range(4))
def test_a(i):
    time.sleep(0.1)
    if i == 1:
        os.abort()

@pytest.mark.xdist_group("b")
@pytest.mark.parametrize("i", range(4))
def test_b(i):
    time.sleep(0.1)

@pytest.mark.xdist_group("c")
@pytest.mark.parametrize("i", range(4))
def test_c(i):
    time.sleep(0.1)
'''

HANGING_SUITE = '''
import time, pytest

@pytest.mark.xdist_group("a")
def test_hangs():
    time.sleep(600)

@pytest.mark.xdist_group("b")
def test_fine():
    pass
'''

# what a run is allowed, start to end, for a suite of a dozen 0.1 s tests (two workers start in ~2 s)
FAST_S = 60.0


def makefile_flags(name: str) -> list[str]:
    """The words of the Makefile's ``NAME = ...`` line, its ``$(VAR)`` references filled from the
    variables' ``?=`` defaults."""
    text = (REPO / "Makefile").read_text()
    defaults = dict(re.findall(r"^(\w+) \?= (.*)$", text, flags=re.M))
    line = re.search(rf"^{name} = (.*)$", text, flags=re.M)
    assert line, f"Makefile: no {name} line"
    value = re.sub(r"\$\((\w+)\)", lambda m: defaults[m.group(1)], line.group(1))
    return value.split()


def run_suite(tmp_path: Path, source: str, extra: list[str]) -> tuple[subprocess.CompletedProcess, float]:
    (tmp_path / "test_small.py").write_text(source)
    (tmp_path / "conftest.py").write_text("")
    flags = makefile_flags("TEST_FLAGS") + makefile_flags("XDIST_FLAGS")
    cmd = [sys.executable, "-X", "faulthandler", "-m", "pytest", *flags, *extra, "-q", "-p", "no:cacheprovider",
           "--rootdir", str(tmp_path), str(tmp_path)]
    start = time.monotonic()
    # a hang here is the defect under test: the limit turns it into a failure, not a stuck suite
    done = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=4 * FAST_S)
    return done, time.monotonic() - start


def test_the_makefile_runs_the_suite_with_the_fail_fast_flags():
    flags = makefile_flags("TEST_FLAGS") + makefile_flags("XDIST_FLAGS")
    assert "--max-worker-restart=0" in flags
    assert any(f.startswith("--timeout=") for f in flags)
    assert "--reruns" not in " ".join(flags)  # a crash is a defect to find, never re-run
    assert "--durations=20" in flags


def test_a_worker_that_aborts_ends_the_run_at_once_with_the_test_named(tmp_path):
    done, took_s = run_suite(tmp_path, CRASHING_SUITE, [])
    out = done.stdout + done.stderr
    assert done.returncode != 0
    assert took_s < FAST_S, f"the run took {took_s:.0f} s"
    assert "crashed while running" in out and "test_a[1]" in out, out[-2000:]


def test_a_hanging_test_is_ended_and_named(tmp_path):
    done, took_s = run_suite(tmp_path, HANGING_SUITE, ["--timeout=3"])
    out = done.stdout + done.stderr
    assert done.returncode != 0
    assert took_s < FAST_S, f"the run took {took_s:.0f} s"
    # under xdist the timed-out worker's stack dump goes to its own stderr; the run names the test
    assert "test_hangs" in out and "crashed while running" in out, out[-2000:]


@pytest.mark.parametrize("name", ["TEST_FLAGS", "XDIST_FLAGS"])
def test_the_flags_are_known_to_this_pytest(name):
    """A flag that a plugin no longer provides would stop ``make test`` before it starts."""
    flags = makefile_flags(name)
    done = subprocess.run([sys.executable, "-m", "pytest", *flags, "--co", "-q", "-p", "no:cacheprovider",
                           str(Path(__file__))], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert "error: unrecognized arguments" not in done.stderr, done.stderr
