"""``HYPOTHESIS_PROFILE=thorough`` reaches every property: example counts go through ``conftest.examples``.

A test's own ``@settings(max_examples=N)`` overrides the loaded Hypothesis profile, so a literal
count would silently keep ``N`` examples under the thorough profile that the README promises
runs 2000 per property. The fuzz tests scale by ``VTOLADAPT_FUZZ_SCALE`` instead (their own knob).
"""
from __future__ import annotations

import ast
import time
from pathlib import Path

import conftest

TESTS_DIR = Path(__file__).resolve().parent
OWN_SCALE = {"test_fuzz_inputs.py"}


def literal_example_counts(path: Path) -> list[int]:
    """Line numbers of ``max_examples=`` keywords in ``path`` that are not a call of ``examples``."""
    lines = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.keyword) and node.arg == "max_examples":
            value = node.value
            if not (isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id == "examples"):
                lines.append(value.lineno)
    return lines


def test_every_example_count_follows_the_profile():
    offenders = {p.name: literal_example_counts(p) for p in sorted(TESTS_DIR.glob("test_*.py"))
                 if p.name not in OWN_SCALE}
    assert {k: v for k, v in offenders.items() if v} == {}


def test_the_guard_sees_a_literal_count(tmp_path):
    src = tmp_path / "test_x.py"
    src.write_text("@settings(max_examples=examples(30))\ndef a(): pass\n\n"
                   "@settings(deadline=None, max_examples=300)\ndef b(): pass\n")
    assert literal_example_counts(src) == [4]


def test_thorough_raises_every_count(monkeypatch):
    monkeypatch.setattr(conftest, "HYPOTHESIS_PROFILE", "thorough")
    assert conftest.examples(25) == conftest.THOROUGH_EXAMPLES
    assert conftest.examples(5000) == 5000
    monkeypatch.setattr(conftest, "HYPOTHESIS_PROFILE", "vtoladapt")
    assert conftest.examples(25) == 25


def test_the_default_profile_is_derandomized_and_thorough_is_not():
    """A clean clone runs the examples every earlier run ran (no flake on a new draw); thorough searches."""
    from hypothesis import settings

    assert settings.get_profile("vtoladapt").derandomize is True
    assert settings.get_profile("thorough").derandomize is False


def test_ci_searches_fresh_examples_with_a_capped_count(monkeypatch):
    from hypothesis import settings

    ci = settings.get_profile("ci")
    assert ci.derandomize is False and ci.deadline is None and ci.print_blob is True
    assert ci.max_examples <= conftest.CI_EXAMPLES
    monkeypatch.setattr(conftest, "HYPOTHESIS_PROFILE", "ci")
    assert conftest.examples(25) == 25
    assert conftest.examples(5000) == conftest.CI_EXAMPLES


class _Item:
    """What the budget hook reads of a test item: its markers."""

    def __init__(self, *markers: str):
        self.markers = markers

    def get_closest_marker(self, name: str):
        return name if name in self.markers else None


def test_ci_skips_properties_once_its_budget_is_spent(monkeypatch):
    import pytest

    monkeypatch.setattr(conftest, "HYPOTHESIS_PROFILE", "ci")
    monkeypatch.setattr(conftest, "CI_BUDGET_S", 0.05)
    monkeypatch.setattr(conftest, "_ci_search_s", [0.0])
    conftest.pytest_runtest_setup(_Item("hypothesis"))  # within the budget: runs
    for markers, sleep_s in ((("hypothesis",), 0.06), ((), 0.2)):  # a property's time counts, another test's not
        gen = conftest.pytest_runtest_call(_Item(*markers))
        next(gen)
        time.sleep(sleep_s)
        with pytest.raises(StopIteration):
            next(gen)
    assert 0.06 <= conftest._ci_search_s[0] < 0.2
    with pytest.raises(pytest.skip.Exception, match="budget is spent"):
        conftest.pytest_runtest_setup(_Item("hypothesis"))
    conftest.pytest_runtest_setup(_Item())  # a test that is not a property always runs
    monkeypatch.setattr(conftest, "HYPOTHESIS_PROFILE", "vtoladapt")
    conftest.pytest_runtest_setup(_Item("hypothesis"))  # the default profile has no budget
