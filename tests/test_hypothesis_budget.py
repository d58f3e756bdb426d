"""``HYPOTHESIS_PROFILE=thorough`` reaches every property: example counts go through ``conftest.examples``.

A test's own ``@settings(max_examples=N)`` overrides the loaded Hypothesis profile, so a literal
count would silently keep ``N`` examples under the thorough profile that the README promises
runs 2000 per property. The fuzz tests scale by ``VTOLADAPT_FUZZ_SCALE`` instead (their own knob).
"""
from __future__ import annotations

import ast
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
