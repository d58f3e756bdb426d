"""What a new user meets in the first hour (issue #37), held to the files it describes.

- one set-up: ``make venv`` then ``source .venv/bin/activate``, said on the home page; every command
  on a tutorial or how-to is typed in that activated shell (``python``, ``vtoladapt``), never as
  ``.venv/bin/...``, and no page makes a virtual environment of its own;
- every tutorial that runs an example shows what it prints;
- the repository's ``scenarios/`` is the package's one copy (a link), not a second one;
- the envelope page's draws are the campaign file's;
- a shipped scenario file's pointer to a README section names a section that exists.
"""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from doc_pages import DOCS, ROOT, code_blocks, page

TUTORIALS = sorted((DOCS / "tutorials").glob("*.md"))
GUIDES = TUTORIALS + sorted((DOCS / "howto").glob("*.md")) + sorted((DOCS / "explanation").glob("*.md"))
SHELL = ("sh", "bash", "console", "shell")


def _rel(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def test_the_home_page_says_once_how_to_set_up_and_activate():
    home = page("docs/index.md")
    assert "make venv" in home and "source .venv/bin/activate" in home
    assert re.search(r"^venv: \$\(STAMP\)$", page("Makefile"), re.M), "the Makefile's venv target"
    for index in ("docs/tutorials/index.md", "docs/howto/index.md"):
        assert "source .venv/bin/activate" in page(index), index


@pytest.mark.parametrize("path", GUIDES, ids=_rel)
def test_commands_are_typed_in_the_activated_environment(path):
    bad = []
    for lang, code in code_blocks(path.read_text(encoding="utf-8")):
        if lang not in SHELL:
            continue
        for line in code.splitlines():
            command = line.strip()
            if re.match(r"(\S*/)?\.venv[^/]*/bin/", command):
                bad.append(f"{command!r}: type it activated (python ..., vtoladapt ...), as docs/index.md says")
            if re.search(r"-m venv\b|\bvirtualenv\b", command):
                bad.append(f"{command!r}: the one set-up is make venv (docs/index.md)")
            if re.match(r"python3 ", command):
                bad.append(f"{command!r}: the activated environment's python is `python`")
    assert not bad, f"{_rel(path)}:\n" + "\n".join(bad)


@pytest.mark.parametrize("path", TUTORIALS, ids=_rel)
def test_a_tutorial_shows_what_its_example_prints(path):
    text = path.read_text(encoding="utf-8")
    blocks = code_blocks(text)
    for i, (lang, code) in enumerate(blocks):
        if lang in SHELL and re.search(r"^python examples/\w+\.py", code, re.M):
            assert i + 1 < len(blocks) and blocks[i + 1][0] == "text" and blocks[i + 1][1].strip(), \
                f"{_rel(path)}: the output of {code.strip()!r} is not shown (a ```text block after it)"


def test_scenarios_folder_is_the_package_copy():
    """``scenarios/`` is a link to ``src/vtoladapt/scenarios/``: one copy, so a file edited there is the
    file the package reads (and the report names, as ``vtoladapt/scenarios/...``)."""
    link, package = ROOT / "scenarios", ROOT / "src" / "vtoladapt" / "scenarios"
    assert link.resolve() == package.resolve(), "scenarios/ must be the package's folder, not a copy"
    assert (link / "paper_comparison.toml").samefile(package / "paper_comparison.toml")


def test_the_envelope_page_has_the_campaign_files_draws():
    campaign = tomllib.loads((ROOT / "src" / "vtoladapt" / "scenarios" / "envelope.toml").read_text())["campaign"]
    text = page("docs/explanation/envelope.md")
    assert set(re.findall(r"^runs = (\d+)", text, re.M)) <= {str(campaign["runs"])}, "runs = on the page"
    for runs, seed in re.findall(r"`scenarios/envelope.toml`: (\d+) draws, seed (\d+)", text):
        assert (int(runs), int(seed)) == (campaign["runs"], campaign["seed"])
    for n in re.findall(r"flies (\d+) draws", text):
        assert int(n) == campaign["runs"]


def test_shipped_scenario_files_point_to_sections_that_exist():
    readme_headings = set(re.findall(r"^#+ (.+?)\s*$", page("README.md"), re.M))
    bad = []
    for path in sorted((ROOT / "src" / "vtoladapt" / "scenarios").rglob("*.toml")):
        text = path.read_text(encoding="utf-8")
        for section in re.findall(r'README "([^"]+)"', text):
            if section not in readme_headings:
                bad.append(f"{_rel(path)}: README has no section {section!r}")
        for doc in re.findall(r"\b(docs/[\w/.-]+\.md)\b", text):
            if not (ROOT / doc).is_file():
                bad.append(f"{_rel(path)}: {doc} does not exist")
    assert not bad, "\n".join(bad)


def test_the_site_css_wraps_code_and_keeps_words_whole_in_tables():
    """issue #37's layout defects, as the stylesheet states them (tools/check_site.py measures them in
    Chromium): code blocks wrap at the column's edge; code in a table cell never breaks mid-word
    (`overflow-wrap: anywhere` sized the results page's file column to three characters)."""
    css = page("docs/_static/tables.css")
    rules = dict(re.findall(r"([^{}]+)\{([^}]*)\}", re.sub(r"/\*.*?\*/", "", css, flags=re.S)))
    rules = {" ".join(k.split()): v for k, v in rules.items()}
    assert "white-space: pre-wrap" in rules["div.highlight pre, .highlight pre"]
    table_code = rules["table.docutils td code, table.docutils th code"]
    assert "overflow-wrap: normal" in table_code and "word-break: normal" in table_code
    assert "anywhere" not in "".join(v for k, v in rules.items() if k.startswith("table"))
    assert '"tables.css"' in page("docs/conf.py")
