"""The package's layers: every module belongs to one, and no module imports from a layer above its own.

From the bottom: the foundation (configuration, array layouts, frames, errors, outputs and their folder
lock, the component registries and the parts' interface), the models (the vehicle, the force model and its
bases, the airflow probe's physics), the components (wind parts, sensor channels, the controller), the simulator, the
applications built on it (experiments, fitting, the probe's tools, replay, the Gymnasium environment, the
pre-flight check that sets up an experiment's runs), what runs many experiments (campaigns, and learning a
basis from campaigns' flights) and the command line. A module imports its own layer and those below: a
model never reaches into the simulator, the simulator never into an application. The import graph is
the static one of ``tests/test_import_graph.py`` (imports inside functions included).
"""
from __future__ import annotations

import pytest

from test_import_graph import import_graph, module_files

LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("foundation", ("vtoladapt.config", "vtoladapt.layout", "vtoladapt.frames", "vtoladapt.errors",
                    "vtoladapt.outputs", "vtoladapt.components", "vtoladapt.parts", "vtoladapt.progress",
                    "vtoladapt.stats", "vtoladapt._kernel_cache", "vtoladapt._numba_abi", "vtoladapt._version",
                    "vtoladapt.ceilings", "vtoladapt.folder_lock", "vtoladapt.file_kinds", "vtoladapt.plugins")),
    ("models", ("vtoladapt.scaling", "vtoladapt.vehicle", "vtoladapt.vehicles", "vtoladapt.forces", "vtoladapt.bases",
                "vtoladapt.models", "vtoladapt.probe.tip", "vtoladapt.probe.sensor", "vtoladapt.probe.estimation",
                "vtoladapt.probe.calibration", "vtoladapt.probe.flow", "vtoladapt.probe.points",
                "vtoladapt.probe.errors", "vtoladapt.probe.nasa", "vtoladapt.probe.data")),
    ("components", ("vtoladapt.wind", "vtoladapt.sensors", "vtoladapt.control")),
    ("sim", ("vtoladapt.sim",)),
    ("apps", ("vtoladapt.experiments", "vtoladapt.fitting", "vtoladapt.probe", "vtoladapt.replay", "vtoladapt.gym",
              "vtoladapt.preflight")),
    ("campaigns", ("vtoladapt.campaign", "vtoladapt.learn")),
    ("cli", ("vtoladapt.cli", "vtoladapt")),
)
"""Layer name and the modules (a name and everything under it) it holds, bottom first; a module is in
the layer of its longest listed prefix: the probe's physics (tip, sensors, estimation, calibration,
its simulated tunnel data) are models the simulated probe is made of, its command and figures are an
application; a fitted posterior file is what the controller's prior is read from, so reading it is a model
(``vtoladapt.bases.posterior``) and all of ``vtoladapt.fitting``, writing it included, is above the simulator."""


def layer_of(module: str) -> int:
    """Index in :data:`LAYERS` of ``module``'s layer (its longest listed prefix); -1 if none."""
    best, best_len = -1, -1
    for i, (_, prefixes) in enumerate(LAYERS):
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > best_len:
                best, best_len = i, len(p)
    return best


def violations(graph: dict[str, set[str]]) -> list[str]:
    """``a (layer) -> b (layer)`` for every import of a module from a layer above ``a``'s."""
    out = []
    for a, targets in graph.items():
        for b in targets:
            if layer_of(b) > layer_of(a):
                out.append(f"{a} ({LAYERS[layer_of(a)][0]}) -> {b} ({LAYERS[layer_of(b)][0]})")
    return sorted(out)


def test_every_module_has_a_layer():
    missing = [m for m in module_files() if layer_of(m) < 0]
    assert missing == [], "modules without a layer (add them to LAYERS): " + ", ".join(missing)


def test_no_module_imports_from_a_layer_above_its_own():
    bad = violations(import_graph(module_files()))
    assert bad == [], "imports from a higher layer:\n" + "\n".join(bad)


def package_of(module: str) -> str:
    """``vtoladapt.X`` of a module (a subpackage, or a module of the package root)."""
    return ".".join(module.split(".")[:2])


def package_loops(graph: dict[str, set[str]]) -> list[list[str]]:
    """The loops among packages: the sets (of two or more) of ``vtoladapt.X`` that reach each other
    through imports, though no module-level cycle need join them (``a.x -> b.y``, ``b.z -> a.w``)."""
    edges: dict[str, set[str]] = {}
    for a, targets in graph.items():
        for b in targets:
            if package_of(a) != package_of(b):
                edges.setdefault(package_of(a), set()).add(package_of(b))

    def reach(start: str) -> set[str]:
        seen, todo = set(), [start]
        while todo:
            for b in edges.get(todo.pop(), ()):
                if b not in seen:
                    seen.add(b)
                    todo.append(b)
        return seen

    reached = {p: reach(p) for p in edges}
    return sorted({tuple(sorted(q for q in reached if q in reached[p] and p in reached[q]))
                   for p in reached if p in reached[p]})


def test_no_two_packages_import_each_other():
    """Within one layer too: a loop of packages (``experiments`` -> ``learn`` -> ``experiments``, once)
    means neither can be read, moved or tested without the other."""
    loops = package_loops(import_graph(module_files()))
    assert loops == [], "packages that import each other:\n" + "\n".join(" <-> ".join(c) for c in loops)


@pytest.mark.parametrize("edges, expected", [
    ({"vtoladapt.experiments.envelope": {"vtoladapt.learn.ceiling"},
      "vtoladapt.learn.evaluate": {"vtoladapt.experiments.pairs"}}, [("vtoladapt.experiments", "vtoladapt.learn")]),
    ({"vtoladapt.learn.evaluate": {"vtoladapt.experiments.pairs"}}, []),
    ({"vtoladapt.sim.loop": {"vtoladapt.control.step"}, "vtoladapt.control.step": {"vtoladapt.sim"}},
     [("vtoladapt.control", "vtoladapt.sim")]),
])
def test_the_loop_check_sees_a_loop(edges, expected):
    assert package_loops(edges) == expected


@pytest.mark.parametrize("edges, expected", [
    ({"vtoladapt.sim.loop": {"vtoladapt.layout"}}, []),
    ({"vtoladapt.fitting.cli": {"vtoladapt.sim.limits"}}, []),  # an application may use the simulator
    ({"vtoladapt.sim.limits": {"vtoladapt.fitting.bayes"}}, ["vtoladapt.sim.limits (sim) -> vtoladapt.fitting.bayes (apps)"]),
    ({"vtoladapt.probe.tip": {"vtoladapt.probe.cli"}}, ["vtoladapt.probe.tip (models) -> vtoladapt.probe.cli (apps)"]),
    ({"vtoladapt.layout": {"vtoladapt"}}, ["vtoladapt.layout (foundation) -> vtoladapt (cli)"]),
    # the two that ran upward until issue #32: the simulator reading a posterior through the fitting,
    # the experiments taking the reproduction's basis metrics from the learning
    ({"vtoladapt.sim.driver": {"vtoladapt.fitting.posterior"}},
     ["vtoladapt.sim.driver (sim) -> vtoladapt.fitting.posterior (apps)"]),
    ({"vtoladapt.experiments.running": {"vtoladapt.learn.report"}},
     ["vtoladapt.experiments.running (apps) -> vtoladapt.learn.report (campaigns)"]),
    ({"vtoladapt.sim.driver": {"vtoladapt.bases.posterior"}}, []),
])
def test_the_check_sees_an_upward_import(edges, expected):
    assert violations(edges) == expected


def test_the_fitting_does_not_need_the_simulator():
    """Fitting force-balance data is below the simulator in what it needs: its modules (but the command
    line's, which checks a ``--vehicle`` as a scenario would) reach no module of ``vtoladapt.sim``,
    directly or through others. (Its memory ceilings came from ``vtoladapt.sim.limits``, which loads
    the compiled loop to count the log's columns; they are :mod:`vtoladapt.ceilings` now.)"""
    graph = import_graph(module_files())
    start = [m for m in graph if m.startswith("vtoladapt.fitting.") and m != "vtoladapt.fitting.cli"]
    seen, todo = set(start), list(start)
    while todo:
        for b in graph[todo.pop()]:
            if b not in seen:
                seen.add(b)
                todo.append(b)
    assert sorted(m for m in seen if m.startswith("vtoladapt.sim")) == []
