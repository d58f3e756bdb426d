"""A user's own components on the command line: ``--plugin MODULE_OR_FILE.py`` and the entry-point
group ``vtoladapt.plugins``.

A plug-in is a Python module of the user's. Importing it makes its components known, in one of two
ways:

* the module registers them itself on import (``vtoladapt.components.register("law", INFO)``), or
* it only defines them: every info object at the module's top level whose ``module`` is the plug-in
  itself and whose type is that of a kind's members (a law's ``ControllerInfo``, a basis's info, ...)
  and whose id is not registered yet is registered after the import. So ``examples/example_law.py``,
  written to be registered by a call, flies as ``--plugin examples/example_law.py`` unchanged.

``--plugin`` takes a dotted module name on ``sys.path`` (``my_package.my_law``) or a ``.py`` file,
imported under its file name (``my_law.py`` is the module ``my_law``; a name already taken by another
module is refused). Installed distributions can declare plug-ins in the entry-point group
:data:`PLUGIN_GROUP`, ``vtoladapt.plugins``; an entry's value is a module (imported as above) or a
callable (``"my_package.plugin:register"``, called with no arguments). The commands that fly or list
components (``run``, ``tune``, ``controllers``, ``bases``) load them first. The per-kind groups
``vtoladapt.law``, ``vtoladapt.basis``, ... of :mod:`vtoladapt.components` (one info object per entry)
work as before.

Any failure (missing file, import error, a module that does not meet its kind's interface) is a
one-line :class:`~vtoladapt.config.ConfigError` naming the plug-in: exit code 2.
"""
from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
import sys
from pathlib import Path
from types import ModuleType
from typing import Iterable, Optional

from .config import ConfigError

PLUGIN_GROUP = "vtoladapt.plugins"
"""The entry-point group of installed plug-ins (a module, or a callable to call)."""

_LOADED_ENTRY_POINTS = [False]


def _import_file(path: Path, flag: str) -> ModuleType:
    name = path.stem
    if not name.isidentifier():
        raise ConfigError(f"{flag} {path}: {name!r} is not a Python module name; allowed: a file named like "
                          "my_law.py (letters, digits, '_')")
    existing = sys.modules.get(name)
    if existing is not None:
        if Path(getattr(existing, "__file__", "") or "").resolve() == path.resolve():
            return existing      # given twice, or imported already: once is enough
        raise ConfigError(f"{flag} {path}: the module name {name!r} is taken by "
                          f"{getattr(existing, '__file__', None) or 'a built-in module'}; rename the file")
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ConfigError(f"{flag} {path}: cannot be imported as a Python module")
    module = importlib.util.module_from_spec(spec)
    # under its own name, before it runs: its components name it as their module, and the registry
    # imports that name to check them (and a law's compiled step finds it there)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return module


def _register_defined(module: ModuleType) -> list[str]:
    """Register the module's own top-level info objects not registered yet; their ``kind:id``."""
    from .components import KIND_HOMES, registry

    added = []
    for kind in KIND_HOMES:
        reg = registry(kind)
        types = {type(info) for info in reg.values()}
        for value in list(vars(module).values()):
            if type(value) in types and getattr(value, "module", None) == module.__name__ \
                    and getattr(value, "id", None) not in reg:
                reg.register(value)
                added.append(f"{kind}:{value.id}")
    return added


def load_plugin(spec: str, flag: str = "--plugin") -> ModuleType:
    """Import the plug-in ``spec`` (a dotted module name or a ``.py`` file) and register its
    components; a one-line :class:`ConfigError` naming ``spec`` if anything fails."""
    path = Path(spec)
    try:
        if spec.endswith(".py") or path.is_file():
            if not path.is_file():
                raise ConfigError(f"{flag} {spec}: file not found; allowed: a .py file or a module name on "
                                  "sys.path")
            module = _import_file(path, flag)
        else:
            module = importlib.import_module(spec)
        _register_defined(module)
        return module
    except ConfigError as exc:
        if str(exc).startswith(f"{flag} {spec}"):
            raise
        raise ConfigError(f"{flag} {spec}: {exc}") from None
    except ModuleNotFoundError as exc:
        raise ConfigError(f"{flag} {spec}: no module named {exc.name!r}; allowed: a .py file or a module name "
                          "on sys.path") from None
    except (Exception, SystemExit) as exc:  # the user's code: whatever it raises is about the plug-in
        raise ConfigError(f"{flag} {spec}: cannot be loaded: {type(exc).__name__}: {exc}") from None


def load_entry_point_plugins() -> list[str]:
    """Load every plug-in of the installed distributions' :data:`PLUGIN_GROUP` entry points (once per
    process); their names."""
    if _LOADED_ENTRY_POINTS[0]:
        return []
    _LOADED_ENTRY_POINTS[0] = True
    names = []
    for ep in importlib.metadata.entry_points(group=PLUGIN_GROUP):
        where = f"entry point {ep.name!r} = {ep.value!r} in group {PLUGIN_GROUP!r}"
        try:
            obj = ep.load()
            if isinstance(obj, ModuleType):
                _register_defined(obj)
            elif callable(obj):
                obj()
            else:
                raise TypeError(f"{type(obj).__name__} is neither a module nor a callable")
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        except Exception as exc:
            raise ConfigError(f"{where}: cannot be loaded: {type(exc).__name__}: {exc}") from None
        names.append(ep.name)
    return names


def load_plugins(specs: Optional[Iterable[str]] = None) -> None:
    """The installed plug-ins, then those given on the command line (``--plugin``, in order)."""
    load_entry_point_plugins()
    for spec in specs or ():
        load_plugin(spec)


__all__ = ["PLUGIN_GROUP", "load_entry_point_plugins", "load_plugin", "load_plugins"]
