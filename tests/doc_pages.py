"""The documentation's pages as the tests read them: the README and the site's Markdown pages.

A test that holds a page to the code (a recipe that must run, a table that must match what the code
generates) finds its text here by the page's path or a section's heading, so content can move between
pages without the test losing it.
"""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
SKIP_DIRS = ("_build", "_generated", "generated")


def pages() -> list[Path]:
    """The README, then every Markdown page of the site (generated ones left out)."""
    docs = [p for p in sorted(DOCS.rglob("*.md"))
            if not any(part in SKIP_DIRS for part in p.relative_to(DOCS).parts)]
    return [ROOT / "README.md", *docs]


def page(path: str) -> str:
    """The text of a page by its path from the repository root (``docs/howto/tuning.md``)."""
    return (ROOT / path).read_text(encoding="utf-8")


def section(title: str) -> tuple[Path, str]:
    """``(page, text)`` of the section headed ``title`` (any level; a page's own ``#`` title gives the
    whole page), from its heading to the next heading of the same or a higher level outside code."""
    for path in pages():
        lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
        fenced, start, level = False, None, 0
        for i, line in enumerate(lines):
            if line.startswith("```"):
                fenced = not fenced
                continue
            m = None if fenced else re.match(r"^(#{1,6}) (.+?)\s*$", line)
            if m is None:
                continue
            if start is None and m.group(2) == title:
                start, level = i, len(m.group(1))
            elif start is not None and len(m.group(1)) <= level:
                return path, "".join(lines[start:i])
        if start is not None:
            return path, "".join(lines[start:])
    raise LookupError(f"no page has a section {title!r}")


def code_blocks(text: str, language: str | None = None) -> list[tuple[str, str]]:
    """``(language, code)`` of the fenced blocks of ``text`` (of one language, if given)."""
    blocks = re.findall(r"^```(\w*)\n(.*?)^```", text, flags=re.S | re.M)
    return [(lang, code) for lang, code in blocks if language is None or lang == language]
