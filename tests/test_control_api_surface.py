"""The control package's public surface: every public function and class documented, every setting with a unit and a meaning."""
from __future__ import annotations

import dataclasses
import importlib
import inspect
import pkgutil

import pytest

import vtoladapt.control as control
from vtoladapt.control.registry import CONTROLLERS
from vtoladapt.control.settings import ControllerConfig

MODULES = sorted({m.name for m in pkgutil.walk_packages(control.__path__, control.__name__ + ".")}
                 | {control.__name__})


def _public_members(module):
    """``(qualified name, object)`` of the functions, compiled kernels and classes ``module`` defines, and their public methods."""
    for name, obj in vars(module).items():
        if name.startswith("_"):
            continue
        func = getattr(obj, "py_func", obj)              # a Numba dispatcher documents its Python function
        if not (inspect.isfunction(func) or inspect.isclass(obj)) or getattr(func, "__module__", None) != module.__name__:
            continue
        yield f"{module.__name__}.{name}", func
        if inspect.isclass(obj):
            for meth_name, meth in vars(obj).items():
                if meth_name.startswith("_") or not (inspect.isfunction(meth) or isinstance(meth, (property, classmethod))):
                    continue
                yield f"{module.__name__}.{name}.{meth_name}", getattr(meth, "__func__", meth)


@pytest.mark.parametrize("module_name", MODULES)
def test_every_public_function_and_class_has_a_docstring(module_name):
    module = importlib.import_module(module_name)
    assert (module.__doc__ or "").strip(), f"{module_name} has no module docstring"
    missing = [q for q, obj in _public_members(module) if not (inspect.getdoc(obj) or "").strip()]
    assert not missing, f"undocumented: {missing}"


def _settings_classes():
    yield "controller", ControllerConfig
    for cid, info in CONTROLLERS.items():
        yield f"controller.{cid}", info.settings


@pytest.mark.parametrize("table, cls", list(_settings_classes()))
def test_every_setting_has_a_unit_and_a_description(table, cls):
    for f in dataclasses.fields(cls):
        assert f.metadata.get("unit"), f"[{table}] {f.name}: no unit"
        assert len(f.metadata.get("doc", "")) >= 10, f"[{table}] {f.name}: no description"


def test_controller_config_has_each_registered_laws_table_as_an_attribute():
    """No field per law (the laws are looked up when asked for): every registered law's table is read as
    ``config.<id>``, its defaults where the configuration was not given one."""
    assert not [f.name for f in dataclasses.fields(ControllerConfig) if f.name in CONTROLLERS]
    cfg = ControllerConfig()
    for cid, info in CONTROLLERS.items():
        assert getattr(cfg, cid) == info.settings()
    with pytest.raises(AttributeError):
        cfg.no_such_law


def test_the_surface_check_finds_an_undocumented_function():
    import types

    mod = types.ModuleType("fake_module", "a module")
    exec("def undocumented():\n    return 1\n", mod.__dict__)
    mod.undocumented.__module__ = "fake_module"
    assert [q for q, obj in _public_members(mod) if not inspect.getdoc(obj)] == ["fake_module.undocumented"]
