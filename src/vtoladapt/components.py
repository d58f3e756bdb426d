"""Registries of the package's components: one per kind (control laws, force-model bases, wind parts,
sensor channels, the allocator's effectiveness), and the one way to add a member from outside the package.

A member of a kind is described by an *info* object (a frozen dataclass of that kind, with at least
``id`` and ``module``, the dotted name of the module that implements it). Members come from three
places, and every part of the package reads them from here, never from a list of its own:

1. the package's own members, given when the kind is declared (:class:`Registry`);
2. a call from the user's code, before the simulation is built::

       from vtoladapt.components import register
       register("law", MY_LAW_INFO)          # an info object of the kind

3. an entry point of an installed distribution, in the group ``vtoladapt.<kind>`` (for example
   ``vtoladapt.law``), whose value is the info object (``"my_package.my_law:INFO"``); entry points
   are read once, on the first look-up of the kind.

A member's module is imported and checked against its kind's interface when it is registered, so
a module that does not meet it is refused at once with a ``TypeError`` naming what is missing, not
deep inside a compiled kernel. Ids are unique across the three sources: registering an id twice is
an error unless ``replace=True``.

Compiled kernels do not dispatch on a member's position in a registry: the simulator passes each
component's compiled function to the kernels that call it (Numba first-class functions of the
kind's fixed signature), so a member registered from outside the package is flown by the same
cached kernels as the package's own.
"""
from __future__ import annotations

import importlib
import importlib.metadata
import threading
from types import ModuleType
from collections.abc import Mapping
from typing import Any, Callable, Iterator

ENTRY_POINT_PREFIX = "vtoladapt."
"""Entry points of kind ``k`` are read from the group ``vtoladapt.<k>``."""

_KINDS: dict[str, "Registry"] = {}
_LOCK = threading.RLock()


def _import_module(name: str) -> ModuleType:
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        raise TypeError(f"module {name!r} cannot be imported: {exc}") from None


class Registry(Mapping):
    """The members of one kind of component, in registration order (the package's own first).

    A read-only mapping ``id -> info`` (``reg[id]``, ``id in reg``, ``reg.values()``, ...) that also
    reads the kind's entry points on first use; :meth:`register` adds to it.

    Parameters
    ----------
    kind : str
        The kind's name (``"law"``, ``"basis"``, ...): the first argument of :func:`register` and the
        suffix of its entry-point group.
    check : callable(module) -> None
        Raises ``TypeError`` naming what is missing if a module does not meet the kind's interface.
    builtins : iterable of info objects
        The package's own members. Their modules are imported on first use, not here (importing a
        kind must stay cheap).
    package : str
        Where a relative ``module`` name (no dot) of one of the package's own members is looked up,
        e.g. ``"vtoladapt.control.laws"``. A member added by a call or an entry point names its module
        in full (a top-level module of the user's, ``"my_wind"``, has no dot and is not in the package).
    """

    def __init__(self, kind: str, check: Callable[[ModuleType], None], builtins, package: str = ""):
        if kind in _KINDS:
            raise ValueError(f"component kind {kind!r} is declared twice")
        self.kind = kind
        self.check = check
        self.package = package
        self._members: dict[str, Any] = {}
        self._checked: set[str] = set()
        self._entry_points_read = False
        self._own: set[str] = set()
        for info in builtins:
            self._add(info, replace=False, check_now=False)
            self._own.add(info.id)
        with _LOCK:
            _KINDS[kind] = self

    # --- look-up ---------------------------------------------------------------------------------
    def _ensure_entry_points(self) -> None:
        if self._entry_points_read:
            return
        with _LOCK:
            if self._entry_points_read:
                return
            self._entry_points_read = True
            for ep in importlib.metadata.entry_points(group=ENTRY_POINT_PREFIX + self.kind):
                try:
                    info = ep.load()
                except Exception as exc:  # a broken plug-in names itself, it does not break the package
                    raise TypeError(f"entry point {ep.name!r} = {ep.value!r} in group {ep.group!r} cannot be "
                                    f"loaded: {exc}") from None
                self._add(info, replace=False, check_now=True)

    def ids(self) -> tuple[str, ...]:
        """The members' ids, in registration order."""
        self._ensure_entry_points()
        return tuple(self._members)

    def __iter__(self) -> Iterator[str]:
        self._ensure_entry_points()
        return iter(tuple(self._members))

    def __len__(self) -> int:
        self._ensure_entry_points()
        return len(self._members)

    def __getitem__(self, member_id: str) -> Any:
        """The info of ``member_id``; ``KeyError`` naming the allowed ids otherwise."""
        self._ensure_entry_points()
        try:
            return self._members[member_id]
        except KeyError:
            raise KeyError(f"unknown {self.kind} {member_id!r}; allowed: {', '.join(self._members)}") from None

    def module(self, member_id: str) -> ModuleType:
        """The member's module, imported and checked against the kind's interface on first use."""
        info = self[member_id]
        module = _import_module(self.module_name(info))
        if member_id not in self._checked:
            self.check(module)
            self._checked.add(member_id)
        return module

    def module_name(self, info) -> str:
        """The absolute dotted name of a member's module (a package member's may be relative to ``package``)."""
        name = info.module
        own = info.id in self._own and self._members.get(info.id) is info
        return f"{self.package}.{name}" if own and self.package and "." not in name else name

    # --- registration ----------------------------------------------------------------------------
    def _add(self, info, *, replace: bool, check_now: bool) -> None:
        member_id = getattr(info, "id", None)
        if not isinstance(member_id, str) or not member_id.isidentifier():
            raise TypeError(f"{self.kind} info {info!r}: needs an 'id' that is a Python identifier")
        if not isinstance(getattr(info, "module", None), str):
            raise TypeError(f"{self.kind} {member_id!r}: needs a 'module' (the dotted name of its module)")
        with _LOCK:
            if member_id in self._members and not replace:
                raise ValueError(f"{self.kind} {member_id!r} is registered already (from "
                                 f"{self.module_name(self._members[member_id])}); pass replace=True to replace it")
            if check_now:
                self._own.discard(member_id)   # a member added now names its module absolutely
                self.check(_import_module(info.module))
                self._checked.add(member_id)
            else:
                self._checked.discard(member_id)
            self._members[member_id] = info

    def register(self, info, *, replace: bool = False) -> Any:
        """Add a member (its module is imported and checked now); returns ``info``."""
        self._ensure_entry_points()
        self._add(info, replace=replace, check_now=True)
        return info

    def unregister(self, member_id: str) -> None:
        """Remove a member registered by a call (tests and notebooks); the package's own stay."""
        self[member_id]
        with _LOCK:
            del self._members[member_id]
            self._checked.discard(member_id)


KIND_HOMES: dict[str, str] = {
    "law": "vtoladapt.control.registry",
    "basis": "vtoladapt.bases",
    "wind": "vtoladapt.wind.registry",
    "sensor": "vtoladapt.sensors.registry",
    "effectiveness": "vtoladapt.sim.allocation",
}
"""The module that declares each kind (imported by :func:`registry` on first use of the kind)."""


def kinds() -> dict[str, Registry]:
    """Every kind declared so far, by name."""
    return dict(_KINDS)


def registry(kind: str) -> Registry:
    """The registry of ``kind`` (its declaring module is imported on first use)."""
    if kind not in _KINDS and kind in KIND_HOMES:
        importlib.import_module(KIND_HOMES[kind])
    try:
        return _KINDS[kind]
    except KeyError:
        raise KeyError(f"unknown component kind {kind!r}; kinds: {', '.join(sorted(KIND_HOMES))}") from None


def register(kind: str, info, *, replace: bool = False) -> Any:
    """Register a member of ``kind`` from outside the package (see the module notes); returns ``info``."""
    return registry(kind).register(info, replace=replace)


def component_tables(data: Mapping[str, Any], members: Registry, settings_of: Callable[[str], Any], *,
                     own: set[str], refused: str, refusal: Callable[[Any], str], source: str, section: str,
                     skip=(), listed=(), no_table: str | None = None) -> tuple[dict, tuple]:
    """Take the tables of registered members (``[<section>.<id>]``) out of a component table and build them:
    the one implementation behind each holder's ``component_tables`` hook of
    :func:`vtoladapt.config.build` (the wind's parts, the sensors' channels, the controller's laws).

    ``data``: the holder's table; ``members``: the registry whose ids name sub-tables; ``settings_of(id)``:
    the member's Settings class; ``own``: the holder's own keys (never a member's table, whatever a
    member is called); ``skip``: ids left to the holder (its built-in parts, built as its own keys).
    ``refused``: the key under which the built tables are stored (``parts``, ``laws``); a table that
    writes it is refused with ``refusal(value)``, the holder's message. ``listed``: ids the table names
    without a table of their own, built with their defaults. ``no_table``: what a member is called, where
    its Settings may be None (``"wind part"``), to refuse a table for it.

    Returns the rest of the table (every other key, in order) and ``((id, settings), ...)`` in the
    registry's order, so that a configuration does not depend on the order its tables were written in.
    A member's table is built as ``section.id`` (``id`` alone where the holder has no section).
    """
    from .config import ConfigError, build  # config is the lower module; it never imports this one

    if refused in data:
        raise ConfigError(refusal(data[refused]))
    rest, built = {}, []
    for key, value in data.items():
        if key in own or not isinstance(key, str) or key not in members or key in skip:
            rest[key] = value
            continue
        settings_cls = settings_of(key)
        if settings_cls is None and no_table is not None:
            raise ConfigError(f"{source}: [{section}.{key}]: this {no_table} takes no table")
        built.append((key, build(settings_cls, value, source=source, section=f"{section}.{key}" if section else key)))
    given = {key for key, _ in built}
    for key in listed:
        # a listed member of the user's without a table of its own runs with its defaults
        if isinstance(key, str) and key in members and key not in given:
            built.append((key, build(settings_of(key), {}, source=source,
                                     section=f"{section}.{key}" if section else key)))
    order = list(members)
    built.sort(key=lambda p: order.index(p[0]))
    return rest, tuple(built)


__all__ = ["ENTRY_POINT_PREFIX", "KIND_HOMES", "Registry", "component_tables", "kinds", "register", "registry"]
