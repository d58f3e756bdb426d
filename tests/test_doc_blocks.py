"""Every code block of the README and of the documentation pages is run, checked, or says why not.

A fenced block is one of:

- ``python``: executed, in page order, the blocks of one page sharing a namespace, in a temporary
  working directory that links the repository's ``data/``, ``scenarios/`` and ``examples/`` (so a
  block reads what a clone has and writes its files there); a ``toml`` block whose first line is a
  file name (``# gusty_hold.toml``) is written to that file first, as the page asks the reader to;
- ``toml``: parsed (a fragment shown must at least be valid TOML);
- preceded by ``<!-- run by: tests/test_NAME.py -->``: a test that file names executes it (the file
  must exist and read the page the block is on);
- preceded by ``<!-- not run: REASON -->``: shown only, for the reason given (a command that takes
  minutes, a cluster, an excerpt of the package's own source, a program's output).

Anything else fails, so a new block must be runnable or say why it is not. MyST directives
(```` ```{name} ````) are not code blocks (``literalinclude`` shows a file that tests run).
"""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SKIP_DIRS = ("_build", "_generated", "generated")


def pages() -> list[Path]:
    docs = [p for p in sorted((ROOT / "docs").rglob("*.md"))
            if not any(part in SKIP_DIRS for part in p.relative_to(ROOT / "docs").parts)]
    return [ROOT / "README.md", *docs]


def blocks(text: str) -> list[tuple[int, str, str, str]]:
    """``(line, language, code, marker)`` of each fenced block; marker is the comment line before it."""
    out, lines, i = [], text.splitlines(), 0
    while i < len(lines):
        m = re.match(r"^(`{3,})(.*)$", lines[i])
        if not m:
            i += 1
            continue
        fence, info = m.group(1), m.group(2).strip()
        j = i + 1
        while j < len(lines) and not lines[j].startswith(fence):
            j += 1
        k = i - 1
        while k >= 0 and not lines[k].strip():
            k -= 1
        marker = lines[k].strip() if k >= 0 and lines[k].strip().startswith("<!--") else ""
        if not info.startswith("{"):
            out.append((i + 1, info.split()[0] if info else "", "\n".join(lines[i + 1:j]) + "\n", marker))
        i = j + 1
    return out


def _rel(page: Path) -> str:
    return str(page.relative_to(ROOT))


@pytest.mark.parametrize("page", pages(), ids=_rel)
def test_every_block_is_run_checked_or_marked(page):
    text = page.read_text(encoding="utf-8")
    unmarked = []
    for line, lang, code, marker in blocks(text):
        if m := re.match(r"<!-- not run: (.+?) -->$", marker):
            assert len(m.group(1).split()) >= 2, f"{_rel(page)}:{line}: say why the block is not run"
            continue
        if m := re.match(r"<!-- run by: (tests/\S+\.py) -->$", marker):
            test = ROOT / m.group(1)
            assert test.is_file(), f"{_rel(page)}:{line}: {m.group(1)} does not exist"
            assert page.name in test.read_text(encoding="utf-8") or page.stem in test.read_text(encoding="utf-8"), \
                f"{_rel(page)}:{line}: {m.group(1)} does not read {page.name}"
            continue
        if lang == "toml":
            tomllib.loads(code)
            continue
        if lang == "python":
            continue  # executed by test_python_blocks_run
        unmarked.append(f"{_rel(page)}:{line}: ```{lang} block neither run nor marked '<!-- not run: why -->'")
    assert not unmarked, "\n".join(unmarked)


def _python_blocks(page: Path) -> list[tuple[int, str]]:
    return [(line, code) for line, lang, code, marker in blocks(page.read_text(encoding="utf-8"))
            if lang == "python" and not marker.startswith(("<!-- not run:", "<!-- run by:"))]


def _files(page: Path) -> dict[str, str]:
    """The files a page's TOML blocks are (first line ``# NAME.toml``)."""
    out = {}
    for _, lang, code, _ in blocks(page.read_text(encoding="utf-8")):
        m = re.match(r"# ([\w.-]+\.toml)\n", code)
        if lang == "toml" and m:
            out[m.group(1)] = code
    return out


@pytest.mark.parametrize("page", [p for p in pages() if _python_blocks(p)], ids=_rel)
def test_python_blocks_run(page, tmp_path, monkeypatch):
    for folder in ("data", "scenarios", "examples"):
        (tmp_path / folder).symlink_to(ROOT / folder, target_is_directory=True)
    for name, text in _files(page).items():
        (tmp_path / name).write_text(text)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    from vtoladapt.components import KIND_HOMES, registry

    # a block may register a part, a law or a basis, as the page shows: removed again afterwards,
    # so the tests of that kind that run later in this process find the registry as the package has it
    before = {kind: set(registry(kind).ids()) for kind in KIND_HOMES}
    namespace: dict = {"__name__": "doc_block"}
    try:
        for line, code in _python_blocks(page):
            # the block's own line numbers in tracebacks
            exec(compile("\n" * line + code, str(page), "exec"), namespace)
    finally:
        for kind, ids in before.items():
            for member in set(registry(kind).ids()) - ids:
                registry(kind).unregister(member)


def test_the_parser_sees_markers_and_skips_directives():
    text = ("x\n\n<!-- not run: needs a cluster -->\n```sh\nvtoladapt campaign\n```\n\n"
            "```{literalinclude} f.py\n```\n\n```python\nprint(1)\n```\n")
    assert blocks(text) == [(4, "sh", "vtoladapt campaign\n", "<!-- not run: needs a cluster -->"),
                            (11, "python", "print(1)\n", "")]
