"""README "Adding a controller" and "Adding a force-model basis" are recipes the tests run.

Each section shows a whole module (its first line names the file under ``tests/``) and a block that
registers it and flies it. The module block must be that file as it stands (so the file the
extension tests hold to their references, ``tests/test_extension_law.py`` and
``tests/test_extension_basis.py``, is the one the README shows), and the flying block is run here as
written, every ``print`` checked against the value its comment states.
"""
from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

from vtoladapt.bases import BASES
from vtoladapt.control.registry import CONTROLLERS

ROOT = Path(__file__).resolve().parents[1]
SECTIONS = [("### Adding a controller", "example_law.py", CONTROLLERS, "example"),
            ("### Adding a force-model basis", "example_basis.py", BASES, "paper_cy")]


def section_blocks(title: str) -> list[str]:
    """The python code blocks of the README section ``title`` (up to the next heading outside a code block)."""
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines(keepends=True)
    start = lines.index(title + "\n")
    blocks, block, fenced = [], None, False
    for line in lines[start + 1:]:
        if line.startswith("```"):
            fenced = not fenced
            if fenced and line.strip() == "```python":
                block = []
            elif not fenced and block is not None:
                blocks.append("".join(block))
                block = None
            continue
        if not fenced and line.startswith("#"):
            break
        if block is not None:
            block.append(line)
    return blocks


@pytest.mark.parametrize("title, module_file, registry, member_id", SECTIONS, ids=["law", "basis"])
def test_the_readme_recipe_is_the_tested_module_and_flies(title, module_file, registry, member_id):
    blocks = section_blocks(title)
    assert len(blocks) == 2, [b[:40] for b in blocks]
    module, usage = blocks
    header = f"# tests/{module_file}\n"
    assert module.startswith(header)
    assert module[len(header):] == (ROOT / "tests" / module_file).read_text(encoding="utf-8")
    assert member_id not in registry
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            exec(compile(usage, "README.md", "exec"), {"__name__": "readme_recipe"})
    finally:
        if member_id in registry:
            registry.unregister(member_id)
    expected = [m.group(1) for m in re.finditer(r"^print\(.*\)\s+# (.*)$", usage, flags=re.M)]
    printed = out.getvalue().splitlines()
    assert len(printed) == len(expected) >= 1
    for got, comment in zip(printed, expected):
        assert re.match(re.escape(got) + r"($|[ :])", comment), (got, comment)
