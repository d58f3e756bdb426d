"""The component registries (vtoladapt.components): members from the package, a call and entry points."""
from __future__ import annotations

import dataclasses
import sys
import types

import pytest

from vtoladapt import components
from vtoladapt.components import Registry


@dataclasses.dataclass(frozen=True)
class Info:
    id: str
    module: str


def _check(module) -> None:
    if not hasattr(module, "step"):
        raise TypeError(f"{module.__name__}: missing step")


@pytest.fixture
def kind(monkeypatch):
    good = types.ModuleType("vtoladapt_test_good")
    good.step = lambda: None
    bad = types.ModuleType("vtoladapt_test_bad")
    monkeypatch.setitem(sys.modules, good.__name__, good)
    monkeypatch.setitem(sys.modules, bad.__name__, bad)
    monkeypatch.setattr(components, "_KINDS", dict(components._KINDS))
    return Registry("test_kind", _check, [Info("builtin", "vtoladapt_test_good")])


def test_members_keep_their_order_and_a_call_adds_one(kind):
    assert kind.ids() == ("builtin",)
    kind.register(Info("mine", "vtoladapt_test_good"))
    assert list(kind) == ["builtin", "mine"] and kind["mine"].module == "vtoladapt_test_good"
    assert kind.module("mine").step is not None


def test_a_module_that_misses_the_interface_is_refused_at_registration(kind):
    with pytest.raises(TypeError, match="missing step"):
        kind.register(Info("broken", "vtoladapt_test_bad"))
    assert "broken" not in kind
    with pytest.raises(TypeError, match="cannot be imported"):
        kind.register(Info("nowhere", "vtoladapt_no_such_module_xyz"))


def test_an_id_is_registered_once_unless_replaced(kind):
    with pytest.raises(ValueError, match="registered already"):
        kind.register(Info("builtin", "vtoladapt_test_good"))
    kind.register(Info("builtin", "vtoladapt_test_good"), replace=True)
    with pytest.raises(KeyError, match="unknown test_kind 'nope'; allowed: builtin"):
        kind["nope"]


def test_entry_points_of_the_kind_are_read_on_first_use(kind, monkeypatch):
    seen = []

    class EP:
        name, value, group = "plugged", "vtoladapt_test_good:INFO", "vtoladapt.test_kind"

        def load(self):
            return Info("plugged", "vtoladapt_test_good")

    def entry_points(group):
        seen.append(group)
        return [EP()] if group == "vtoladapt.test_kind" else []

    monkeypatch.setattr(components.importlib.metadata, "entry_points", entry_points)
    assert kind.ids() == ("builtin", "plugged") and seen == ["vtoladapt.test_kind"]
    kind.ids()
    assert seen == ["vtoladapt.test_kind"]  # read once


def test_the_control_laws_are_the_law_kind_and_the_bases_the_basis_kind():
    from vtoladapt.bases import BASES, basis_ids
    from vtoladapt.control.registry import CONTROLLERS, controller_ids

    assert components.registry("law") is CONTROLLERS
    assert CONTROLLERS.ids() == controller_ids() and "composite" in CONTROLLERS
    assert components.registry("basis") is BASES and "paper" in basis_ids()
    assert BASES.module("paper").__name__ == "vtoladapt.bases.paper"     # a package member's relative name
    with pytest.raises(KeyError, match="unknown component kind"):
        components.registry("no_such_kind")


def test_a_member_registered_by_a_call_names_its_module_absolutely(monkeypatch):
    """``module = "example_basis"`` of a registered member is the top-level module of that name (tests/), not
    one inside the kind's package: a user's module needs no dot in its name."""
    import example_basis
    from vtoladapt.bases import BASES

    monkeypatch.setattr(BASES, "_members", dict(BASES._members))
    components.register("basis", example_basis.INFO)
    assert BASES.module("paper_cy") is example_basis
