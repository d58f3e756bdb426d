"""Load pages of the built documentation site in headless Chromium at 1300 px and check their layout.

    python tools/check_site.py [SITE_DIR] [PAGE ...]

SITE_DIR defaults to ``docs/_build/html`` (``make docs`` builds it); the pages default to the home
page, a tutorial and an API page. Each page is served from a local HTTP server on 127.0.0.1 (an
ephemeral port, stopped at the end) and loaded in a 1300 px wide frame of a probe page; after the
page's scripts have run, the probe reports every table wider than the box it sits in (a table the
reader must scroll sideways) or than the window, every code block whose text runs past its box
(``scrollWidth > clientWidth``: a line cut at the right edge), every table cell narrower than one of
its unbreakable words (a word drawn on more than one line: ``vehicl|e``, a file name over ten lines),
every character reference shown as text (a literal ``&#x27;``) and every image that failed to load. Chromium's
``--dump-dom`` prints the probe's report, so nothing but the browser is needed (Debian: ``apt-get
install chromium``); it is started with the flags that keep it off the network.

``--search QUERY`` also runs the site's own search page (``search.html?q=QUERY``, the index in
``searchindex.js``, nothing fetched) and reports how many pages it finds.

Exit status: 0 every page passed, 1 a page has one of the defects above (or the search page found
nothing or shows a character reference as text), 2 no Chromium, no built site or a page missing.
"""
from __future__ import annotations

import functools
import http.server
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_PAGES = ("index.html", "tutorials/first-flight.html", "reference/generated/vtoladapt.sim.driver.html",
                 # the pages of issue #37's layout defects: cut code blocks, three-character columns,
                 # key names broken mid-word, numbered equations
                 "tutorials/own-vehicle.html", "explanation/envelope.html", "howto/adding-a-basis.html",
                 "explanation/results.html", "reference/configuration.html", "explanation/method.html")
WIDTH_PX = 1300
PROBE_NAME = "_layout_probe.html"

PROBE = """<!doctype html><html><body>
<pre id="report">pending</pre>
<script>
const pages = %(pages)s;
const results = {};
let left = pages.length;
function check(frame, page) {
  const doc = frame.contentDocument;
  const win = frame.contentWindow;
  const viewport = doc.documentElement.clientWidth;
  const tables = [];
  doc.querySelectorAll("table").forEach((t, i) => {
    const box = t.parentElement;
    const right = t.getBoundingClientRect().right;
    if (t.scrollWidth > box.clientWidth + 1 || right > viewport + 1) {
      tables.push({index: i, table_px: t.scrollWidth, box_px: box.clientWidth, right_px: Math.round(right),
                   first_cell: (t.querySelector("th,td") || {textContent: ""}).textContent.trim().slice(0, 60)});
    }
  });
  // a code block whose lines run past its box: the reader loses the end of the line
  const code = [];
  doc.querySelectorAll("div.highlight pre, pre.literal-block").forEach((pre, i) => {
    if (pre.scrollWidth > pre.clientWidth + 1) {
      code.push({index: i, scroll_px: pre.scrollWidth, box_px: pre.clientWidth,
                 first_line: pre.textContent.split("\n")[0].slice(0, 60)});
    }
  });
  // a table cell narrower than one of its words: the word is drawn on more than one line
  // (words are split at white space, hyphens and slashes, where a browser may break)
  const cells = [];
  doc.querySelectorAll("table td, table th").forEach(cell => {
    const walker = doc.createTreeWalker(cell, NodeFilter.SHOW_TEXT);
    let node;
    while ((node = walker.nextNode())) {
      const re = /[^\\s\\-\u2010-\u2014\\/]+/g;
      let m;
      while ((m = re.exec(node.data))) {
        if (m[0].length < 2) continue;
        const range = doc.createRange();
        range.setStart(node, m.index);
        range.setEnd(node, m.index + m[0].length);
        const tops = new Set(Array.from(range.getClientRects()).filter(r => r.width > 0)
                                  .map(r => Math.round(r.top)));
        if (tops.size > 1) {
          cells.push({word: m[0].slice(0, 60), lines: tops.size, cell_px: cell.clientWidth});
          return;
        }
      }
    }
  });
  // a character reference shown as text (escaped twice): "the paper&#x27;s"
  const body = doc.body.cloneNode(true);
  body.querySelectorAll("script, style, pre, code").forEach(e => e.remove());
  const entities = (body.textContent.match(/&(#x?[0-9a-f]+|[a-z]{2,8});/gi) || []).slice(0, 10);
  const images = [];
  doc.querySelectorAll("img").forEach(img => {
    if (!img.complete || img.naturalWidth === 0) images.push(img.getAttribute("src"));
  });
  results[page] = {viewport_px: viewport, page_px: doc.documentElement.scrollWidth,
                   tables_checked: doc.querySelectorAll("table").length, overflowing_tables: tables,
                   images_checked: doc.querySelectorAll("img").length, broken_images: images,
                   code_blocks_checked: doc.querySelectorAll("div.highlight pre, pre.literal-block").length,
                   overflowing_code: code, broken_words: cells, literal_entities: entities};
  if (--left === 0) document.getElementById("report").textContent = JSON.stringify(results);
}
pages.forEach(page => {
  const frame = document.createElement("iframe");
  frame.style.width = "%(width)dpx"; frame.style.height = "900px"; frame.style.border = "0";
  frame.onload = () => setTimeout(() => check(frame, page), 500);
  frame.src = page;
  document.body.appendChild(frame);
});
</script></body></html>
"""

CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--disable-extensions", "--hide-scrollbars")


def find_chromium() -> str | None:
    """The Chromium binary on PATH (Debian's ``chromium``, or ``chromium-browser`` / ``google-chrome``)."""
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format, *args):  # the check's report is the output, not the access log
        pass


def _dump_dom(site: Path, path: str, chromium: str | None, timeout_s: float,
              extra: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """Chromium's DOM of ``path`` after its scripts ran, the site served on 127.0.0.1 from a copy (with
    the ``extra`` files added to the copy, so the built site itself is never written to)."""
    chromium = chromium or find_chromium()
    if chromium is None:
        raise FileNotFoundError("no Chromium on PATH (Debian: apt-get install chromium)")
    with tempfile.TemporaryDirectory() as tmp:
        served = Path(tmp) / "site"
        shutil.copytree(site, served)
        for name, text in (extra or {}).items():
            (served / name).write_text(text)
        handler = functools.partial(_QuietHandler, directory=str(served))
        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        thread = threading.Thread(target=server.serve_forever, daemon=True)
        thread.start()
        try:
            url = f"http://127.0.0.1:{server.server_address[1]}/{path}"
            return subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={tmp}/profile",
                                   "--window-size=1400,1000", "--virtual-time-budget=20000", "--dump-dom", url],
                                  capture_output=True, text=True, timeout=timeout_s)
        finally:
            server.shutdown()
            server.server_close()
            thread.join()


def literal_entities(dom: str) -> list[str]:
    """The character references a serialized DOM shows as text: a page's text ``&#x27;`` is
    serialized as ``&amp;#x27;`` (an escaped string escaped again, as the search page's object
    results were)."""
    import re

    return [m.group(0).replace("&amp;", "&", 1) for m in re.finditer(r"&amp;(#x?[0-9a-fA-F]+|[a-zA-Z]{2,8});", dom)]


def search_hits(site: Path, query: str, chromium: str | None = None, timeout_s: float = 120) -> int:
    """How many pages the site's own search page finds for ``query`` (its summary line)."""
    import re
    from urllib.parse import quote_plus

    done = _dump_dom(site, f"search.html?q={quote_plus(query)}", chromium, timeout_s)
    shown = literal_entities(done.stdout)
    if shown:
        raise RuntimeError(f"the search page shows character references as text: {', '.join(shown[:5])}")
    if "did not match any documents" in done.stdout:
        return 0
    m = re.search(r"found (\d+) pages?", done.stdout)
    if m is None:
        raise RuntimeError(f"the search page reported no result count (Chromium status {done.returncode})")
    return int(m.group(1))


def check_site(site: Path, pages=DEFAULT_PAGES, chromium: str | None = None, timeout_s: float = 120) -> dict:
    """``{page: report}`` for each page of the built ``site`` (see the module docstring)."""
    for page in pages:
        if not (site / page).is_file():
            raise FileNotFoundError(f"{site / page}: no such page (build the site first: make docs)")
    # the probe must share the pages' origin to read their layout, so it is served with them
    probe = PROBE % {"pages": json.dumps(list(pages)), "width": WIDTH_PX}
    done = _dump_dom(site, PROBE_NAME, chromium, timeout_s, {PROBE_NAME: probe})
    text = done.stdout
    start, end = text.find('<pre id="report">'), text.find("</pre>")
    report = text[start + len('<pre id="report">'):end] if start >= 0 and end > start else ""
    if not report or report == "pending":
        raise RuntimeError(f"the probe page reported nothing (Chromium status {done.returncode}): "
                           f"{done.stderr.strip()[-500:]}")
    import html

    return json.loads(html.unescape(report))


def main(argv: list[str]) -> int:
    query = None
    if "--search" in argv:
        i = argv.index("--search")
        query = argv[i + 1] if i + 1 < len(argv) else ""
        argv = argv[:i] + argv[i + 2:]
    site = Path(argv[0]) if argv else ROOT / "docs" / "_build" / "html"
    pages = tuple(argv[1:]) or DEFAULT_PAGES
    try:
        results = check_site(site, pages)
        hits = search_hits(site, query) if query else None
    except (FileNotFoundError, RuntimeError, subprocess.TimeoutExpired) as exc:
        print(f"check_site: {exc}", file=sys.stderr)
        return 2
    if hits is not None:
        print(f"{'ok  ' if hits else 'FAIL'} search.html?q={query}: {hits} pages found")
    failed = False
    for page, r in results.items():
        bad = (r["overflowing_tables"] or r["broken_images"] or r["overflowing_code"] or r["broken_words"]
               or r["literal_entities"])
        failed = failed or bool(bad)
        print(f"{'FAIL' if bad else 'ok  '} {page}: {r['tables_checked']} tables, {r['code_blocks_checked']} code "
              f"blocks, {r['images_checked']} images at {r['viewport_px']} px (page {r['page_px']} px wide)")
        for t in r["overflowing_tables"]:
            print(f"     table {t['index']} ('{t['first_cell']}') is {t['table_px']} px in a {t['box_px']} px box")
        for c in r["overflowing_code"]:
            print(f"     code block {c['index']} ('{c['first_line']}') is {c['scroll_px']} px in a {c['box_px']} px box")
        for w in r["broken_words"]:
            print(f"     table cell {w['cell_px']} px wide breaks '{w['word']}' over {w['lines']} lines")
        for e in r["literal_entities"]:
            print(f"     '{e}' shown as text")
        for src in r["broken_images"]:
            print(f"     broken image {src}")
    return 1 if failed or hits == 0 else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
