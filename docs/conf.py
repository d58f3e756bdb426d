"""Sphinx configuration of the vtoladapt documentation site (``make docs``).

The site is built offline and strictly (``-W --keep-going -n``): a warning, a broken cross-reference
or a missing file fails the build. Nothing here fetches anything: no intersphinx inventories (the
references into numpy, scipy and the standard library are listed in ``nitpick_ignore_regex`` as
external instead), no web fonts (furo ships its own CSS). The equations are rendered by MathJax 3
served from the site itself (``sphinx-mathjax-offline`` copies it into ``_static/mathjax``; nothing is
loaded from a CDN). The search index (``searchindex.js``) is built with the site and works from the
files.

Generated at build time, never written by hand (folder ``docs/_generated/``, git-ignored):

- ``settings.md``: every key of a scenario and a vehicle file with its unit, default, allowed values
  and meaning, from the settings classes (:mod:`vtoladapt.settings_reference`);
- ``ranges.md``: the range table the input checks apply (:func:`vtoladapt.sim.limits.ranges_markdown`);
- the API reference's module pages (``reference/api/``, by autosummary from the docstrings).

The CLI reference comes from the real parser (:func:`vtoladapt.cli.build_parser`) through
sphinx-argparse.
"""
from __future__ import annotations

import dataclasses
import os
import re
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT / "src"))  # the package from this checkout, installed or not

from vtoladapt._version import __version__  # noqa: E402

project = "vtoladapt"
author = "the vtoladapt developers"
copyright = "2026, the vtoladapt developers"
release = version = __version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinxarg.ext",
    "sphinx.ext.mathjax",
    "sphinx-mathjax-offline",  # MathJax 3 bundled into _static/mathjax: the site works offline
]
# the pages' numbered equations ({math} with :label:, referenced with {eq}) are numbered per page
math_number_all = False
math_eqref_format = "Eq. {number}"

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
# docs/ also holds the measurement scripts, their JSON and figures that README and `make reproduce`
# use: they are data, not pages (Sphinx reads only .md/.rst sources; these keep it from looking).
exclude_patterns = ["_build", "_generated", "Thumbs.db", ".DS_Store", "measure_*.py", "*.json",
                    "basis_comparison.md"]  # a generated table the bases page summarises

myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 4  # `page.md#a-heading` links resolve and are checked
suppress_warnings: list[str] = []
smartquotes = False  # "--out" in a help text or a page stays two hyphens, quotes stay as typed

templates_path = ["_templates"]

html_theme = "furo"
html_title = f"vtoladapt {release}"
html_static_path = ["_static"]
html_css_files = ["tables.css"]
html_last_updated_fmt = None
html_copy_source = False
html_show_sourcelink = False

# --- the API reference ------------------------------------------------------------------------------
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "show-inheritance": False, "member-order": "bysource"}
autodoc_typehints = "signature"
autodoc_typehints_format = "short"
autodoc_preserve_defaults = True
autodoc_class_signature = "separated"
napoleon_numpy_docstring = True
napoleon_google_docstring = False
napoleon_use_rtype = False
# numpydoc type fields ("x : ndarray, shape (3,)", "float, optional") are prose, not class names: shown
# as written rather than cross-referenced word by word (which nitpicky mode would report as missing)
napoleon_use_param = False
napoleon_use_keyword = False
napoleon_preprocess_types = False
add_module_names = False

# --- strictness -----------------------------------------------------------------------------------
# Every reference into this package must resolve. References into other packages cannot be
# resolved offline (no intersphinx inventory is fetched), so those are let through by name.
nitpicky = True
_EXTERNAL = ("numpy", "np", "npt", "numba", "scipy", "pandas", "pyarrow", "pa", "pq", "dask", "distributed",
             "gymnasium", "gym", "matplotlib", "emcee", "jinja2", "pyulog", "tqdm", "argparse", "pathlib",
             "collections", "typing", "types", "contextvars", "dataclasses", "enum", "concurrent", "threading",
             "multiprocessing", "subprocess", "io", "os", "json", "datetime", "signal", "socket", "logging")
nitpick_ignore_regex = [
    (r"py:.*", rf"({'|'.join(_EXTERNAL)})\..*"),
    # private helpers that appear in signatures and base classes: not part of the reference
    (r"py:.*", r".*\b_[A-Za-z]\w*"),
    # builtins and typing names as they appear in annotations
    (r"py:.*", r"(Any|Callable|Iterable|Iterator|Mapping|Sequence|Generator|Literal|Self|Optional|Union|"
               r"ClassVar|Final|TypeVar|Protocol|NamedTuple|Path|PathLike|ndarray|Generator|Figure|Axes|"
               r"Table|RecordBatch|Client|LocalCluster|Future|Dispatcher|Env|Space|Box|ULog|"
               r"Template|Environment|Namespace|ArgumentParser|Enum|IntEnum|Event|Lock|Popen|"
               r"TextIO|BinaryIO|IO|Buffer|Counter|OrderedDict|defaultdict|deque|Decimal|Fraction|"
               r"datetime|timedelta|Real|Integral|Number|DataFrame|float64|int64|bool_|dtype|"
               r"EllipsisType|NoneType|ModuleType|FunctionType|TracebackType|FrameType|"
               r"KeyboardInterrupt|BaseException|Exception|ValueError|OSError|RuntimeError)"),
]


_IDENTIFIER = re.compile(r"^~?[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")


def _instance_attribute(cls: type, attr: str) -> bool:
    """Whether instances of ``cls`` have ``attr``: a dataclass field, or assigned as ``self.attr`` in
    the class's source."""
    import inspect

    if dataclasses.is_dataclass(cls) and attr in {f.name for f in dataclasses.fields(cls)}:
        return True
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return False
    return re.search(rf"\bself\.{re.escape(attr)}\b[^\n=]*=(?!=)", source) is not None


def _lookup(target: str, module: str | None, cls: str | None):
    """``(dotted name, object)`` that ``target`` names: absolute, relative to the documented module
    (and class), or None when the name does not exist in the code."""
    import importlib

    target = target.lstrip("~.")
    candidates = [target]
    if module:
        candidates += ([f"{module}.{cls}.{target}"] if cls else []) + [f"{module}.{target}"]
        parent = module.rsplit(".", 1)[0]
        candidates.append(f"{parent}.{target}")
    for name in candidates:
        parts = name.split(".")
        for i in range(len(parts), 0, -1):
            try:
                obj = importlib.import_module(".".join(parts[:i]))
            except ImportError:
                continue
            try:
                for attr in parts[i:]:
                    if isinstance(obj, type) and not hasattr(obj, attr) and _instance_attribute(obj, attr):
                        obj = None  # set on every instance (a dataclass field, self.x = ... in __init__)
                        continue
                    obj = getattr(obj, attr)
            except AttributeError:
                break
            return name, obj
    return None


def _missing_reference(app, env, node, contnode):
    """A reference Sphinx could not resolve to a documented object.

    - a re-exported name (``vtoladapt.simulate``) links to where the object is defined;
    - a name that exists in the code but has no entry of its own (a module constant without a
      docstring, a dataclass field) is shown as code, unlinked;
    - the words of a docstring's type field ("array, shape (3,)", "m/s") are shown as written.

    Anything else, a name that does not exist in the code, stays a warning, which fails the build.
    """
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "")
    if not _IDENTIFIER.match(target):
        return contnode  # prose in a type field, not a name
    found = _lookup(target, node.get("py:module"), node.get("py:class"))
    if found is None:
        if node.get("refspecific") and node.get("reftype") == "class" and "." not in target:
            return contnode  # a word of a type field ("N", "alpha", "Pa"), not a reference
        return None
    name, obj = found
    obj = getattr(obj, "py_func", obj)  # a compiled kernel is documented by its Python source
    home, qual = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if isinstance(home, str) and isinstance(qual, str) and "<locals>" not in qual:
        domain = env.get_domain("py")
        for role in ("obj", node.get("reftype")):
            ref = domain.resolve_xref(env, node["refdoc"], app.builder, role, f"{home}.{qual}", node, contnode)
            if ref is not None:
                return ref
    return contnode  # exists in the code, has no entry of its own


def _write_if_changed(path: Path, text: str) -> None:
    """Write a generated page only when it changed, so an unchanged build stays incremental."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")


def _generate(app) -> None:
    """The pages made from the code, before Sphinx reads the sources."""
    from vtoladapt.settings_reference import metrics_markdown, settings_markdown
    from vtoladapt.sim.limits import ranges_markdown

    out = DOCS / "_generated"
    _write_if_changed(out / "settings.md", settings_markdown())
    _write_if_changed(out / "ranges.md", ranges_markdown() + "\n")
    _write_if_changed(out / "metrics.md", metrics_markdown())


FIGURE_EXAMPLES = ("first_flight", "scenario_variant", "own_law", "fit_tunnel_data", "calibrate_probe",
                   "replay_flight_log", "campaign")
"""The examples whose output folders the tutorials show figures from (``docs/_generated/examples/NAME``)."""


def _run_examples(app) -> None:
    """Run the examples the tutorials take figures from, each once per version of its script and of the
    package (a stamp holds the SHA-256 of both): the figures are the examples' output, never pasted."""
    import hashlib
    import subprocess
    import time

    package = hashlib.sha256()
    for path in sorted((ROOT / "src" / "vtoladapt").rglob("*")):
        if path.suffix in (".py", ".toml", ".json") and "__pycache__" not in path.parts:
            package.update(path.relative_to(ROOT).as_posix().encode() + path.read_bytes())
    for name in FIGURE_EXAMPLES:
        script = ROOT / "examples" / f"{name}.py"
        out = DOCS / "_generated" / "examples" / name
        stamp = out / ".stamp"
        digest = hashlib.sha256(script.read_bytes() + package.digest()).hexdigest()
        if stamp.exists() and stamp.read_text() == digest:
            continue
        env = dict(os.environ, MPLBACKEND="Agg", PYTHONPATH=str(ROOT / "src"))
        # a line as each example starts and ends, even under -q: the examples are most of a fresh
        # build's time (make docs ran 13 minutes without a word, issue #37)
        print(f"docs: running examples/{name}.py ({FIGURE_EXAMPLES.index(name) + 1} of {len(FIGURE_EXAMPLES)}; "
              f"not again until it or the package changes)...", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, str(script), "--out", str(out)], cwd=ROOT, env=env,
                              capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"examples/{name}.py failed (status {done.returncode}): {done.stderr[-2000:]}")
        print(f"docs:   examples/{name}.py done in {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
        stamp.write_text(digest)


def _drop_stale_api_pages(app, config) -> None:
    """Delete the API pages autosummary wrote for modules that no longer exist (it never does): a
    renamed or removed module would otherwise keep a page outside every table of contents."""
    import importlib
    import importlib.util
    import re

    def exists(name: str) -> bool:
        try:
            if importlib.util.find_spec(name) is not None:
                return True
        except (ImportError, ValueError):
            pass
        parent, _, attr = name.rpartition(".")
        try:
            return bool(parent) and hasattr(importlib.import_module(parent), attr)
        except Exception:  # a parent that does not import: the name is gone with it
            return False

    for stub in (DOCS / "reference" / "generated").glob("*.rst"):
        # a page whose own module is gone, or a package's page that still lists a submodule or member
        # since moved (autosummary reads the old listing and warns before it writes the page anew)
        listed = re.findall(r"^\s+(\w+)\s*$", stub.read_text(), flags=re.M)  # autosummary's entries
        if not exists(stub.stem) or not all(exists(f"{stub.stem}.{name}") for name in listed):
            stub.unlink()


def _name_commands_by_command(app) -> None:
    """Name the CLI reference's objects by their command (``vtoladapt run``) rather than by their
    description: Sphinx HTML-escapes an object's display name into the search index and the search
    page shows it as text, so a description's apostrophe read "the paper&#x27;s" (issue #37)."""
    from sphinxarg.ext import ArgParseDomain

    def get_objects(self):
        for name, _description, *rest in self.data["commands"]:
            yield (name, name, *rest)

    ArgParseDomain.get_objects = get_objects


def setup(app):
    app.connect("builder-inited", _name_commands_by_command)
    app.connect("config-inited", _drop_stale_api_pages)
    app.connect("builder-inited", _generate)
    app.connect("builder-inited", _run_examples)
    app.connect("missing-reference", _missing_reference)
    os.environ.setdefault("MPLBACKEND", "Agg")
    return {"parallel_read_safe": True}
