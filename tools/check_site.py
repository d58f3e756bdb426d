"""Load pages of the built documentation site in headless Chromium at 1300 px and check their layout.

    python tools/check_site.py [SITE_DIR] [PAGE ...]

SITE_DIR defaults to ``docs/_build/html`` (``make docs`` builds it); the pages default to the home
page, a tutorial and an API page. Each page is served from a local HTTP server on 127.0.0.1 (an
ephemeral port, stopped at the end) and loaded in a 1300 px wide frame of a probe page; after the
page's scripts have run, the probe reports every table wider than the box it sits in (a table the
reader must scroll sideways) or than the window, and every image that failed to load. Chromium's
``--dump-dom`` prints the probe's report, so nothing but the browser is needed (Debian: ``apt-get
install chromium``); it is started with the flags that keep it off the network.

``--search QUERY`` also runs the site's own search page (``search.html?q=QUERY``, the index in
``searchindex.js``, nothing fetched) and reports how many pages it finds.

Exit status: 0 every page passed, 1 a page has an overflowing table or a broken image, 2 no
Chromium, no built site or a page missing.
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
DEFAULT_PAGES = ("index.html", "tutorials/first-flight.html", "reference/generated/vtoladapt.sim.driver.html")
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
  const images = [];
  doc.querySelectorAll("img").forEach(img => {
    if (!img.complete || img.naturalWidth === 0) images.push(img.getAttribute("src"));
  });
  results[page] = {viewport_px: viewport, page_px: doc.documentElement.scrollWidth,
                   tables_checked: doc.querySelectorAll("table").length, overflowing_tables: tables,
                   images_checked: doc.querySelectorAll("img").length, broken_images: images};
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


def search_hits(site: Path, query: str, chromium: str | None = None, timeout_s: float = 120) -> int:
    """How many pages the site's own search page finds for ``query`` (its summary line)."""
    import re
    from urllib.parse import quote_plus

    done = _dump_dom(site, f"search.html?q={quote_plus(query)}", chromium, timeout_s)
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
        bad = r["overflowing_tables"] or r["broken_images"]
        failed = failed or bool(bad)
        print(f"{'FAIL' if bad else 'ok  '} {page}: {r['tables_checked']} tables, {r['images_checked']} images at "
              f"{r['viewport_px']} px (page {r['page_px']} px wide)")
        for t in r["overflowing_tables"]:
            print(f"     table {t['index']} ('{t['first_cell']}') is {t['table_px']} px in a {t['box_px']} px box")
        for src in r["broken_images"]:
            print(f"     broken image {src}")
    return 1 if failed or hits == 0 else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
