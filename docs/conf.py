"""Sphinx configuration of the vtoladapt documentation site (``make docs``).

The site is built offline and strictly (``-W --keep-going -n``): a warning, a broken cross-reference
or a missing file fails the build. Nothing here fetches anything: no intersphinx inventories (the
references into numpy, scipy and the standard library are listed in ``nitpick_ignore_regex`` as
external instead), no MathJax (the pages write their formulas as text), no web fonts (furo ships its
own CSS). The search index (``searchindex.js``) is built with the site and works from the files.

Generated at build time, never written by hand (folder ``docs/_generated/``, git-ignored):

- ``settings.md``: every key of a scenario and a vehicle file with its unit, default, allowed values
  and meaning, from the settings classes (:mod:`vtoladapt.settings_reference`);
- ``ranges.md``: the range table the input checks apply (:func:`vtoladapt.sim.limits.ranges_markdown`);
- the API reference's module pages (``reference/api/``, by autosummary from the docstrings).

The CLI reference comes from the real parser (:func:`vtoladapt.cli.build_parser`) through
sphinx-argparse.
"""
from __future__ import annotations

import os
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
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
# docs/ also holds the measurement scripts, their JSON and figures that README and `make reproduce`
# use: they are data, not pages (Sphinx reads only .md/.rst sources; these keep it from looking).
exclude_patterns = ["_build", "_generated", "Thumbs.db", ".DS_Store", "measure_*.py", "*.json"]

myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 4  # `page.md#a-heading` links resolve and are checked
suppress_warnings: list[str] = []

html_theme = "furo"
html_title = f"vtoladapt {release}"
html_static_path: list[str] = []
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


def _write_if_changed(path: Path, text: str) -> None:
    """Write a generated page only when it changed, so an unchanged build stays incremental."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")


def _generate(app) -> None:
    """The pages made from the code, before Sphinx reads the sources."""
    from vtoladapt.settings_reference import settings_markdown
    from vtoladapt.sim.limits import ranges_markdown

    out = DOCS / "_generated"
    _write_if_changed(out / "settings.md", settings_markdown())
    _write_if_changed(out / "ranges.md", ranges_markdown() + "\n")


def setup(app):
    app.connect("builder-inited", _generate)
    os.environ.setdefault("MPLBACKEND", "Agg")
    return {"parallel_read_safe": True}
