"""The documentation site builds offline and strictly, its search works from the files, its generated
reference covers every configuration key and command, and its pages lay out at 1300 px.

One fresh build (``-E``: nothing reused) into a temporary folder, as ``make docs`` runs it: ``-W
--keep-going -n``, so any warning, broken cross-reference or missing file fails it. It also runs the
examples the tutorials take figures from, unless their output is current (``docs/_generated``).
The layout check needs Chromium (Debian package ``chromium``) and is skipped, saying so, without it.
"""
from __future__ import annotations

import argparse
import dataclasses
import html
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    import fcntl

    out = tmp_path_factory.mktemp("site")
    # the build runs the examples into docs/_generated, whose output folders a run locks: two test
    # processes building the site at once (each builds its own copy) take turns
    lock_path = DOCS / "_build" / ".site-build.lock"
    lock_path.parent.mkdir(parents=True, exist_ok=True)
    with open(lock_path, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        done = subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", "-E", "-W", "--keep-going", "-n", "-q",
                               "-d", str(out / "doctrees"), str(DOCS), str(out / "html")],
                              cwd=ROOT, capture_output=True, text=True, timeout=1800)
    assert done.returncode == 0, "the site does not build strictly:\n" + done.stderr[-6000:]
    assert "WARNING" not in done.stderr and "ERROR" not in done.stderr, done.stderr[-6000:]
    return out / "html"


def _conf():
    spec = importlib.util.spec_from_file_location("docs_conf", DOCS / "conf.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_equations_render_offline_and_the_search_shows_no_escaped_text(site):
    """issue #37: the paper's equations were labels only (eq:f_ctrl), and the search page showed a
    command's description as "the paper&#x27;s" (Sphinx escapes an object's display name; the CLI
    reference's objects are now named by their command)."""
    method = (site / "explanation" / "method.html").read_text(encoding="utf-8")
    for label in ("f_ctrl", "th_adapt", "P_adapt"):
        assert re.search(rf'id="equation-eq-{label.lower().replace("_", "-")}"', method, re.I), label
    scripts = re.findall(r'<script[^>]+src="([^"]*mathjax[^"]*)"', method, re.I)
    assert scripts and not any(s.startswith(("http:", "https:", "//")) for s in scripts), scripts
    assert (site / "_static" / "mathjax" / "tex-chtml.js").is_file()
    index = (site / "searchindex.js").read_text(encoding="utf-8")
    assert "&#x27;" not in index


def test_the_site_has_every_section_and_an_offline_search(site):
    for page in ("index.html", "tutorials/first-flight.html", "howto/index.html", "explanation/method.html",
                 "reference/cli.html", "reference/configuration.html", "reference/generated/vtoladapt.sim.driver.html",
                 "search.html"):
        assert (site / page).is_file(), page
    index = (site / "searchindex.js").read_text(encoding="utf-8")
    for word in ("composit", "turbul", "calibr"):  # stemmed terms of the index
        assert f'"{word}' in index, word
    search = (site / "search.html").read_text(encoding="utf-8")
    assert "searchindex.js" in search
    # nothing a page needs comes from the network: scripts, styles and images are the site's own files
    for page in site.rglob("*.html"):
        text = page.read_text(encoding="utf-8")
        remote = re.findall(r'<(?:script|img)[^>]+src="(https?:[^"]+)"|<link[^>]+href="(https?:[^"]+)"', text)
        assert not remote, (page.relative_to(site), remote[:3])


def test_every_command_is_in_the_cli_reference(site):
    from vtoladapt.cli import build_parser

    text = html.unescape(re.sub(r"<[^>]+>", "", (site / "reference" / "cli.html").read_text(encoding="utf-8")))

    def commands(parser, prefix):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    yield f"{prefix} {name}".strip(), sub
                    yield from commands(sub, f"{prefix} {name}")

    names = [name for name, _ in commands(build_parser(), "")]
    assert {"run", "reproduce", "tune", "campaign", "replay", "probe calibrate", "fit"} <= set(names)
    for name in names:
        assert f"vtoladapt {name}" in text, name
    for flag in ("--duration-scale", "--scheduler", "--require-converged", "--vary"):
        assert flag in text, flag
    assert "–out" not in text  # "--out" in a help text stays two hyphens (no typographic dash)


def _settings_tables(markdown: str) -> dict[str, dict[str, str]]:
    """``{section: {key: table row}}`` of the configuration reference's Markdown."""
    tables: dict[str, dict[str, str]] = {}
    section = ""
    for line in markdown.splitlines():
        if m := re.match(r"^## (.+)$", line):
            section = ""
        elif m := re.match(r"^### `\[\[?([^\]]+)\]\]?`$", line):
            section = m.group(1)
        elif m := re.match(r"^\| `([^`]+)` \|", line):
            tables.setdefault(section, {})[m.group(1)] = line
    return tables


def test_the_configuration_reference_states_every_key_as_the_checks_apply_it(site):
    """Against the range table the input checks print (vtoladapt.sim.limits), key by key."""
    from vtoladapt.settings_reference import settings_markdown
    from vtoladapt.sim.limits import ROW_CHECKS, _settings_rows
    from vtoladapt.sim.scenario import Scenario
    from vtoladapt.vehicle import Vehicle

    markdown = settings_markdown()
    for cls, title in ((Scenario, "## Scenario file"), (Vehicle, "## Vehicle file")):
        start = markdown.index(title)
        end = markdown.find("\n## ", start + 1)
        tables = _settings_tables(markdown[start:end if end > 0 else None])
        for key, unit, allowed in _settings_rows(cls):
            if key == "source_path":
                continue
            section, _, leaf = key.rpartition(".")
            section = section.replace("[]", "")
            row = tables.get(section, {}).get(leaf)
            assert row is not None, f"{cls.__name__}: {key} missing from the reference"
            assert ROW_CHECKS.get(key, allowed) in row, (key, row)
        # and every non-numeric key too: each field of each table has a row
        for f in dataclasses.fields(cls):
            if f.name != "source_path" and not dataclasses.is_dataclass(f.type if isinstance(f.type, type) else None):
                assert f.name in tables.get("", {}) or any(f.name == s.split(".")[0] for s in tables), f.name
    page = (site / "reference" / "configuration.html").read_text(encoding="utf-8")
    for word in ("max_position_error_m", "forgetting_lambda", "lift_motor_time_constant_s", "coefficient_sigmas"):
        assert word in page, word


def test_a_reference_to_a_name_that_does_not_exist_stays_an_error():
    """The build's handler of unresolved references (docs/conf.py): only real names pass."""
    conf = _conf()

    class Node(dict):
        pass

    contnode = object()

    def ref(target, reftype="func", specific=False, module=None):
        node = Node(refdomain="py", reftarget=target, reftype=reftype, refspecific=specific, refdoc="x")
        node["py:module"] = module
        return conf._missing_reference(None, None, node, contnode)

    assert ref("vtoladapt.sim.driver.not_a_function") is None
    assert ref("not_a_constant", "data", module="vtoladapt.sim.driver") is None
    assert ref("CHUNK_S", "data", module="vtoladapt.sim.driver") is contnode      # exists, no entry
    assert ref("RunBatch.actions", "attr", module="vtoladapt.gym.batch") is contnode  # set in __init__
    assert ref("RunBatch.no_such_attribute", "attr", module="vtoladapt.gym.batch") is None
    assert ref("array, shape (3,)", "class", specific=True) is contnode            # a type field's prose
    assert ref("N", "class", specific=True) is contnode


def test_pages_lay_out_at_1300_px(site):
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import check_site
    finally:
        sys.path.remove(str(ROOT / "tools"))
    if check_site.find_chromium() is None:
        pytest.skip("no Chromium installed (Debian: apt-get install chromium); tools/check_site.py needs it")
    results = check_site.check_site(site, check_site.DEFAULT_PAGES)
    assert set(results) == set(check_site.DEFAULT_PAGES)
    for page, r in results.items():
        assert r["viewport_px"] >= 1250, (page, r)        # the frame really was 1300 px wide
        assert not r["overflowing_tables"], (page, r["overflowing_tables"])
        assert not r["broken_images"], (page, r["broken_images"])
        assert not r["overflowing_code"], (page, r["overflowing_code"])     # issue #37: cut code lines
        assert not r["broken_words"], (page, r["broken_words"])             # `vehicl|e`, 3-character columns
        assert not r["literal_entities"], (page, r["literal_entities"])     # a literal &#x27;
    assert sum(r["code_blocks_checked"] for r in results.values()) >= 10
    assert sum(r["images_checked"] for r in results.values()) >= 2  # the home page's and the tutorial's figures
    # the site's own search page, served from loopback with nothing fetched, finds the pages
    assert check_site.search_hits(site, "composite adaptation") >= 10
    assert check_site.search_hits(site, "qwertyuiopzxcv") == 0
