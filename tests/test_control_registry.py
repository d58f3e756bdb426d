"""The controller registry drives everything that lists controllers, and nothing else lists them."""
from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import pytest
from matplotlib.colors import is_color_like

import vtoladapt
from vtoladapt.config import ConfigError
from vtoladapt.config import choices_of
from vtoladapt.control import step
from vtoladapt.control.laws import check_law
from vtoladapt.control.registry import (
    CONTROLLERS, adaptive_ids, composite_ids, controller_ids, controller_info, law_key, law_of_key,
)
from vtoladapt.control.settings import ControllerConfig, controller_config_from_mapping
from vtoladapt.sim.scenario import ExperimentConfig

CONTROLLER_IDS = controller_ids()

SRC = Path(vtoladapt.__file__).resolve().parent

# Literal lists of controller ids outside the registry that are known and owned elsewhere: the
# paper's two baselines in a claim check of experiments.py (being split by another change; to be
# replaced by a registry attribute there). Anything else found fails the test below.
KNOWN_ID_LISTS: set = set()


@pytest.mark.parametrize("cid", CONTROLLER_IDS)
def test_every_entry_has_a_law_module_settings_label_and_colour(cid):
    info = controller_info(cid)
    check_law(info.law)                                    # Settings, PARAMS, STATE, fill_params, init_state, update
    assert info.law.__name__.startswith("vtoladapt.control.laws.")
    assert dataclasses.is_dataclass(info.settings) and info.settings is info.law.Settings
    assert info.label and info.description and is_color_like(info.colour)
    assert info.adaptive or not info.composite             # a composite law adapts


def test_labels_and_colours_are_distinct():
    assert len({c.label for c in CONTROLLERS.values()}) == len(CONTROLLERS)
    assert len({c.colour for c in CONTROLLERS.values()}) == len(CONTROLLERS)


def test_derived_id_lists_follow_the_flags():
    assert adaptive_ids() == tuple(k for k in CONTROLLER_IDS if CONTROLLERS[k].adaptive)
    assert composite_ids() == tuple(k for k in CONTROLLER_IDS if CONTROLLERS[k].composite)
    with pytest.raises(KeyError, match="allowed: " + ", ".join(CONTROLLER_IDS)):
        controller_info("lqr")


def test_configuration_has_one_table_per_law_and_validates_kind_from_the_registry():
    fields = {f.name: f for f in dataclasses.fields(ControllerConfig)}
    shared = set(fields)
    assert choices_of(fields["kind"].metadata) == CONTROLLER_IDS
    assert choices_of(ExperimentConfig.__dataclass_fields__["controllers"].metadata) == CONTROLLER_IDS
    keys = set()
    for cid in CONTROLLER_IDS:
        cfg = controller_config_from_mapping({"kind": cid})
        assert isinstance(cfg.law_settings, CONTROLLERS[cid].settings)
        assert law_of_key(law_key(cid)) is CONTROLLERS[cid]
        keys.add(law_key(cid))
        # a law's own key never repeats a shared one (it would be ambiguous where it belongs)
        assert not {f.name for f in dataclasses.fields(CONTROLLERS[cid].settings)} & shared
    assert len(keys) == len(CONTROLLER_IDS)                  # the keys the step's parameters hold are distinct
    with pytest.raises(ConfigError, match="kind = 'lqr': unknown"):
        controller_config_from_mapping({"kind": "lqr"})


def test_a_law_gain_in_the_shared_table_names_the_table_it_moved_to():
    for cid, info in CONTROLLERS.items():
        for f in dataclasses.fields(info.settings):
            with pytest.raises(ConfigError, match=rf"\[controller\] {f.name} = .*\[controller\.{cid}\] {f.name}"):
                controller_config_from_mapping({f.name: 1.0}, source="s.toml")
    with pytest.raises(ConfigError, match="unknown key"):
        controller_config_from_mapping({"no_such_gain": 1.0})


def test_the_compiled_step_calls_the_law_of_its_parameters_as_a_first_class_function(caltech):
    """The step holds no list of laws: ``controller_functions`` of a parameter array gives its law's
    ``update`` and its basis's ``regressor``, and the step is compiled for functions of their fixed
    signatures (one compilation for every law)."""
    from numba import types

    from vtoladapt.bases import basis_module
    from vtoladapt.control import controller_arrays

    for cid in CONTROLLER_IDS:
        params, _ = controller_arrays(caltech, ControllerConfig(kind=cid))
        fns = step.controller_functions(params)
        assert fns[0] is CONTROLLERS[cid].law.update and fns[1] is basis_module("paper").regressor
    assert not hasattr(step, "_LAWS")
    for sig in step.controller_step.signatures:
        assert all(isinstance(t, types.FunctionType) for t in sig[0])


def _literal_id_lists(tree: ast.AST) -> list[tuple[str, ...]]:
    found = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            ids = tuple(e.value for e in node.elts if isinstance(e, ast.Constant) and e.value in CONTROLLERS)
            if len(ids) >= 2:
                found.append(ids)
    return found


def test_no_other_list_of_controllers_exists_in_the_package():
    """Outside registry.py no tuple, list or set literal names two or more controller ids."""
    found = set()
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC).as_posix()
        if rel == "control/registry.py":
            continue
        for ids in _literal_id_lists(ast.parse(path.read_text())):
            found.add((rel, ids))
    assert found <= KNOWN_ID_LISTS, f"lists of controllers outside the registry: {sorted(found - KNOWN_ID_LISTS)}"
    # the check itself finds such a list
    assert _literal_id_lists(ast.parse(f"x = {CONTROLLER_IDS[:2]!r}")) == [CONTROLLER_IDS[:2]]


def _imports(path: Path, package: str) -> set[str]:
    """Modules that ``path`` imports, at module level or inside a function (relative imports resolved)."""
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.add(mod)
            out.update(f"{mod}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return out


def test_the_control_package_has_no_import_cycle():
    """Imports between the modules of vtoladapt.control, deferred ones included, form no cycle.

    (``config`` importing ``kernel`` inside a method while ``kernel`` imported ``config`` was one.)
    ``state_integrator`` of the generic step imported ``laws.pid``; no generic module imports a law.
    """
    root = SRC / "control"
    modules = {}
    for path in root.rglob("*.py"):
        rel = path.relative_to(SRC.parent).with_suffix("")
        name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        package = name if rel.name == "__init__" else name.rsplit(".", 1)[0]
        modules[name] = (path, package)
    graph = {name: {m for m in _imports(path, package) if m in modules and m != name}
             for name, (path, package) in modules.items()}
    # a package's __init__ importing its own submodules is not a cycle of the design
    for name in graph:
        graph[name] = {m for m in graph[name] if not (m.startswith(name + ".") and (SRC.parent / Path(*name.split("."))).is_dir())}
    state: dict[str, int] = {}

    def visit(node, stack):
        state[node] = 1
        for nxt in graph[node]:
            if state.get(nxt) == 1:
                raise AssertionError("import cycle: " + " -> ".join(stack[stack.index(nxt):] + [nxt]))
            if nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name, [name])
    assert graph["vtoladapt.control.step"] >= {"vtoladapt.control.registry"}     # the graph is read
    # the shared modules reach the laws only through the registry
    laws = {m for m in modules if m.startswith("vtoladapt.control.laws.")}
    for name, deps in graph.items():
        if not name.startswith("vtoladapt.control.laws"):
            assert not deps & laws, f"{name} imports a law: {sorted(deps & laws)}"
