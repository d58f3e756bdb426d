"""The package reads in one direction: no import cycles among its modules.

The graph is built from the source by static analysis (:mod:`ast`), so it sees every import
statement, including those inside functions, which a run-time check would only see if the
function ran. Imports are resolved as Python resolves them: ``from .probe import ProbeTip``
depends on the package ``vtoladapt.probe`` (its ``__init__``), ``from . import forces`` and
``from vtoladapt.probe import tip`` on the submodule. Parent packages a dotted import runs first
are not counted as edges (every submodule would otherwise "depend" on its package's
``__init__``, which in turn re-exports it). Names loaded through ``importlib`` by string (the
lazy exports of :mod:`vtoladapt.fitting`) are invisible here by design.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import vtoladapt

PACKAGE_DIR = Path(vtoladapt.__file__).resolve().parent

KNOWN_CYCLES: set[frozenset[str]] = set()
"""Cycles known and owned elsewhere. The second test fails when one is gone, so the list shrinks."""


def module_files(package_dir: Path = PACKAGE_DIR) -> dict[str, tuple[Path, bool]]:
    """``{dotted module name: (file, is a package __init__)}`` for every ``.py`` file of the package."""
    out = {}
    for path in sorted(package_dir.rglob("*.py")):
        parts = list(path.relative_to(package_dir.parent).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        if is_package:
            parts = parts[:-1]
        out[".".join(parts)] = (path, is_package)
    return out


def _resolve(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def import_graph(modules: dict[str, tuple[Path, bool]]) -> dict[str, set[str]]:
    """Edges ``module -> modules of the package it imports`` (anywhere in its source)."""
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for module, (path, is_package) in modules.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                graph[module].update(a.name for a in node.names if a.name in modules)
            elif isinstance(node, ast.ImportFrom):
                target = _resolve(module, is_package, node)
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    if sub in modules:
                        graph[module].add(sub)
                    elif target in modules:
                        graph[module].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[frozenset[str]]:
    """Strongly connected components with more than one module, or a module importing itself
    (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: list[frozenset[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    component = set()
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        component.add(w)
                        if w == v:
                            break
                    if len(component) > 1 or v in graph[v]:
                        found.append(frozenset(component))
    return found


def _cycle_path(graph: dict[str, set[str]], component: frozenset[str]) -> str:
    """One closed walk through a component, for the failure message."""
    start = min(component)
    path, seen, v = [start], {start}, start
    while True:
        v = min(w for w in graph[v] if w in component)
        path.append(v)
        if v in seen:
            break
        seen.add(v)
    return " -> ".join(path[path.index(v):])


def test_no_import_cycles():
    graph = import_graph(module_files())
    new = [c for c in cycles(graph) if c not in KNOWN_CYCLES]
    assert not new, "import cycles:\n" + "\n".join(_cycle_path(graph, c) for c in new)


def test_known_cycles_still_exist():
    found = set(cycles(import_graph(module_files())))
    gone = [sorted(c) for c in KNOWN_CYCLES if c not in found]
    assert not gone, f"these cycles are gone: remove them from KNOWN_CYCLES: {gone}"


def _write(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root / "pkg"


def test_detects_a_function_level_cycle(tmp_path):
    pkg = _write(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/a.py": "from .b import g\n",
        "pkg/b.py": "def g():\n    from pkg.a import f\n    return f\n",
        "pkg/c.py": "from . import a\n",
    })
    graph = import_graph(module_files(pkg))
    assert graph["pkg.b"] == {"pkg.a"} and graph["pkg.c"] == {"pkg.a"}
    assert cycles(graph) == [frozenset({"pkg.a", "pkg.b"})]


def test_resolves_relative_imports_and_packages(tmp_path):
    pkg = _write(tmp_path, {
        "pkg/__init__.py": "from .sub import x\n",
        "pkg/sub/__init__.py": "from .leaf import x\nfrom .. import top\n",
        "pkg/sub/leaf.py": "import numpy\nx = 1\n",
        "pkg/top.py": "import pkg.sub.leaf\n",
    })
    graph = import_graph(module_files(pkg))
    assert graph == {"pkg": {"pkg.sub"}, "pkg.sub": {"pkg.sub.leaf", "pkg.top"},
                     "pkg.sub.leaf": set(), "pkg.top": {"pkg.sub.leaf"}}
    assert cycles(graph) == []


@pytest.mark.parametrize("edges, expected", [
    ({"a": {"a"}}, [{"a"}]),
    ({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}, [{"a", "b", "c"}]),
    ({"a": {"b"}, "b": set()}, []),
])
def test_cycles_on_small_graphs(edges, expected):
    assert sorted(map(sorted, cycles(edges))) == sorted(map(sorted, expected))
