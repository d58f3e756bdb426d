"""Validated, frozen configuration dataclasses loaded from TOML.

Every configuration field is declared with :func:`setting`, which records its unit, a one-line
meaning and the values it allows. :func:`build` turns a parsed TOML table into the dataclass,
rejecting unknown keys (with a suggestion for a likely misspelling), missing fields, wrong types
and out-of-range values with a :class:`ConfigError` that names the file, the key, the value and
what is allowed. Nothing is partly built: either the whole object validates or an error is raised.
"""
from __future__ import annotations

import contextvars
import dataclasses
import difflib
import functools
import math
import numbers
import os
import re
import stat
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Mapping

import numpy as np


class ConfigError(ValueError):
    """A configuration file or mapping is invalid; the message says where and why."""


class ApplicableKeys(tuple):
    """The keys of a table that apply to it, and why (e.g. ``kind = 'probe_nan'``): what a
    dataclass's ``keys_for(data)`` returns for :func:`build` to refuse the others."""

    def __new__(cls, keys, reason: str):
        obj = super().__new__(cls, keys)
        obj.reason = reason
        return obj


MEMORY_BUDGET_BYTES = int(float(os.environ.get("VTOLADAPT_MEMORY_BUDGET_GB", "6")) * 2**30)
"""The most memory one command may plan to hold in its large arrays (simulation logs, chains,
tables): 6 GiB by default (a quarter of a 24 GiB machine, leaving room for copies made while
computing metrics and figures); set ``VTOLADAPT_MEMORY_BUDGET_GB`` to change it. Size ceilings
(``--duration`` x rate, ``--runs``, ``--repeats``, ``--walkers``) follow from it."""

MAX_INPUT_FILE_BYTES = 256 * 2**20
"""Data files (force-balance and probe CSVs, flight logs) larger than this are refused before they are read."""

TOML_BYTES_HELD_PER_BYTE = 40
"""Memory a configuration file takes per byte of TOML once parsed and validated, measured: a scenario of
waypoint rows held 1.7 GB for 50 MB (Python lists and floats, then the validated tuples)."""

MAX_TOML_FILE_BYTES = min(16 * 2**20, MEMORY_BUDGET_BYTES // TOML_BYTES_HELD_PER_BYTE)
"""Configuration files (scenarios, vehicles, campaign files) larger than this are refused before they
are read: 16 MiB (about 0.6 GiB once parsed, some ten seconds of parsing; the shipped files are a few
kB, and the longest table a scenario takes, 100 000 waypoint rows, is 4 MiB), less if the memory
budget is below 16 MiB x 40."""


def check_memory(what: str, n_bytes: float, where: str, hint: str = "") -> None:
    """Refuse a size whose arrays would exceed :data:`MEMORY_BUDGET_BYTES`.

    ``what`` says how the bytes were counted (e.g. "5 runs x 900000 log rows x 122 columns x
    8 bytes"); the message names ``where`` (the flag or key), the need and the budget.
    """
    if n_bytes > MEMORY_BUDGET_BYTES:
        extra = f"; {hint}" if hint else ""
        raise ConfigError(
            f"{where}: needs {n_bytes / 2**30:.3g} GiB ({what}), over the memory budget of "
            f"{MEMORY_BUDGET_BYTES / 2**30:.3g} GiB (VTOLADAPT_MEMORY_BUDGET_GB){extra}")


def check_value(cls: type, name: str, value: Any, where: str) -> Any:
    """Validate one value against field ``name`` of settings class ``cls``; return it converted.

    Command-line flags that override a file key go through here, so a flag and the key have the
    same range and the same messages (``where`` is the flag, e.g. ``"--duration"``).
    """
    f = {f.name: f for f in dataclasses.fields(cls)}[name]
    hints = _type_hints(cls)
    return _convert(value, hints[name], f.metadata, where, where)


def check_flag(where: str, value: Any, *, unit: str = "-", ge: float | None = None,
               gt: float | None = None, le: float | None = None, lt: float | None = None,
               integer: bool = False) -> Any:
    """Validate a command-line number that has no settings field (same rules and messages)."""
    meta = {"unit": unit, "gt": gt, "ge": ge, "lt": lt, "le": le}
    return _convert(value, int if integer else float, meta, where, where)


_MISSING = dataclasses.MISSING

INTERNAL_KEYS = ("source_path",)
"""Fields the loaders fill in (the file a configuration was read from): never written in a file,
so a file that sets one is refused and the unknown-key message does not offer them."""


def setting(
    unit: str,
    doc: str,
    *,
    default: Any = _MISSING,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    length: int | None = None,
    max_items: int | None = None,
    choices: tuple | None = None,
    pattern: str | None = None,
) -> Any:
    """Declare a configuration field with its unit, meaning and allowed values.

    Bounds apply to a scalar, or to every element of a tuple (and of nested tuples). ``max_items``
    caps a list's length (rows of a table), checked before any element is: a list's memory grows
    with its length, so it answers to the memory budget before it is read. ``pattern`` is a
    regular expression a text value must match in full (e.g. names used in file names).
    ``choices`` is a tuple, or a function returning one when a value is checked (the ids of a
    component registry, which may gain members after import: :mod:`vtoladapt.components`).
    """
    meta = {"unit": unit, "doc": doc, "gt": gt, "ge": ge, "lt": lt, "le": le,
            "length": length, "max_items": max_items, "choices": choices, "pattern": pattern}
    if default is _MISSING:
        return dataclasses.field(metadata=meta)
    if isinstance(default, (list, dict, set)):
        raise TypeError("use a tuple for a sequence default")
    return dataclasses.field(default=default, metadata=meta)


MAX_STRING_CHARS = 4096
"""Longest text value of a setting (names, paths, descriptions)."""

PATH_PATTERN = r"(?!.*[^/]{256})[^\x00]{1,4096}"
"""``setting(pattern=...)`` of a file path: no NUL, no name in it longer than 255 characters."""
NAME_PATTERN = r"[A-Za-z0-9_.-]{1,64}"
"""``setting(pattern=...)`` of a name used in file names."""
_PATTERN_TEXT = {PATH_PATTERN: "a file path (no NUL character, no name in it over 255 characters)",
                 NAME_PATTERN: "1 to 64 letters, digits, '_', '.' or '-'"}


def _shown(value: Any) -> str:
    """``repr(value)`` cut to 60 characters for messages."""
    text = repr(value)
    return text if len(text) <= 60 else text[:45] + "..." + text[-12:]


def _key_text(key: Any) -> str:
    """A key as the user would type it, quoted when it is not a plain TOML bare key."""
    text = str(key)
    if re.fullmatch(r"[A-Za-z0-9_-]{1,64}", text):
        return text
    return _shown(text)


def _where(source: str, section: str, key: str) -> str:
    return f"{source}: [{section}] {_key_text(key)}" if section else f"{source}: {_key_text(key)}"


def choices_of(meta: Mapping[str, Any]) -> tuple | None:
    """The allowed values of a field now: its ``choices`` tuple, or what its ``choices`` function returns."""
    choices = meta.get("choices")
    return tuple(choices()) if callable(choices) else choices


def _allowed_text(meta: Mapping[str, Any]) -> str:
    parts = []
    for name, sym in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
        if meta.get(name) is not None:
            parts.append(f"{sym} {meta[name]:g}")
    choices = choices_of(meta)
    if choices:
        parts.append("one of " + ", ".join(repr(c) for c in choices))
    text = " and ".join(parts) if parts else "any value"
    unit = meta.get("unit")
    return f"{text} ({unit})" if unit and unit != "-" else text


MAGNITUDE_MAX = 1e9
"""Every number with no declared bound on a side is still bounded there by this magnitude, so no
setting is unbounded (fields should declare their physical range; this is the safety net)."""


def _check_scalar(value: float, meta: Mapping[str, Any], where: str) -> None:
    if not math.isfinite(value):
        raise ConfigError(f"{where} = {_shown(value)}: must be finite; allowed: {_allowed_text(meta)}")
    no_upper = meta.get("lt") is None and meta.get("le") is None
    no_lower = meta.get("gt") is None and meta.get("ge") is None
    if (no_upper and value > MAGNITUDE_MAX) or (no_lower and value < -MAGNITUDE_MAX):
        raise ConfigError(f"{where} = {_shown(value)}: out of range; allowed: {_allowed_text(meta)}"
                          f" and magnitude <= {MAGNITUDE_MAX:g}")
    bad = ((meta.get("gt") is not None and not value > meta["gt"])
           or (meta.get("ge") is not None and not value >= meta["ge"])
           or (meta.get("lt") is not None and not value < meta["lt"])
           or (meta.get("le") is not None and not value <= meta["le"]))
    if bad:
        raise ConfigError(f"{where} = {_shown(value)}: out of range; allowed: {_allowed_text(meta)}")


def _is_bool(value: Any) -> bool:
    return isinstance(value, (bool, np.bool_))


def _convert(value: Any, tp: Any, meta: Mapping[str, Any], where: str, source: str) -> Any:
    if tp is Any:  # a field its class checks itself (the gym's scenario: a name, a mapping or a Scenario)
        return value
    origin = typing.get_origin(tp)
    if origin is typing.Union or origin is types.UnionType:
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        return _convert(value, args[0], meta, where, source)
    if origin is tuple:
        args = typing.get_args(tp)
        if isinstance(value, np.ndarray) and value.ndim == 1:  # a Python caller's array, as a list
            value = value.tolist()
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where} = {_shown(value)}: must be a list; allowed: {_allowed_text(meta)}")
        if meta.get("length") is not None and len(value) != meta["length"]:
            raise ConfigError(
                f"{where} = {_shown(value)}: must have exactly {meta['length']} elements, has {len(value)}")
        _check_items(value, meta, where)
        inner = args[0] if args else Any
        inner_meta = dict(meta, length=None, max_items=None)
        return tuple(_convert(v, inner, inner_meta, f"{where}[{i}]", source)
                     for i, v in enumerate(value))
    if tp is float:
        if _is_bool(value) or not isinstance(value, numbers.Real):
            raise ConfigError(f"{where} = {_shown(value)}: must be a number; allowed: {_allowed_text(meta)}")
        value = float(value)
        _check_scalar(value, meta, where)
        return value
    if tp is int:
        if _is_bool(value) or not isinstance(value, numbers.Integral):
            raise ConfigError(f"{where} = {_shown(value)}: must be a whole number; allowed: {_allowed_text(meta)}")
        value = int(value)
        if abs(value) >= 2**63:
            raise ConfigError(f"{where} = {_shown(value)}: out of range; allowed: {_allowed_text(meta)}")
        _check_scalar(value, meta, where)
        return value
    if tp is bool:
        if not _is_bool(value):
            raise ConfigError(f"{where} = {_shown(value)}: must be true or false")
        return bool(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where} = {_shown(value)}: must be a string")
        if "\x00" in value:
            raise ConfigError(f"{where} = {_shown(value)}: contains a NUL character")
        if len(value) > MAX_STRING_CHARS:
            raise ConfigError(f"{where} = {_shown(value)}: {len(value)} characters; allowed: at "
                              f"most {MAX_STRING_CHARS}")
        if meta.get("pattern") and not re.fullmatch(meta["pattern"], value):
            allowed = _PATTERN_TEXT.get(meta["pattern"], f"text matching {meta['pattern']}")
            raise ConfigError(f"{where} = {_shown(value)}: not allowed; allowed: {allowed}")
        choices = choices_of(meta)
        if choices and value not in choices:
            raise ConfigError(f"{where} = {_shown(value)}: unknown; allowed: {_allowed_text(meta)}")
        return value
    raise TypeError(f"unsupported configuration field type {tp!r} at {where}")


def _check_items(value, meta: Mapping[str, Any], where: str) -> None:
    if meta.get("max_items") is not None and len(value) > meta["max_items"]:
        raise ConfigError(f"{where}: {len(value)} entries; allowed: at most {meta['max_items']}")


def _is_table_list(tp: Any) -> bool:
    """``tuple[SomeDataclass, ...]``: a TOML array of tables (``[[section.key]]``)."""
    args = typing.get_args(tp)
    return typing.get_origin(tp) is tuple and bool(args) and dataclasses.is_dataclass(args[0])


def _build_table_list(tp: Any, value: Any, where: str, source: str, section: str,
                      meta: Mapping[str, Any]) -> tuple:
    if not isinstance(value, (list, tuple)):
        raise ConfigError(f"{where} = {_shown(value)}: must be a list of tables ([[{section}]])")
    _check_items(value, meta, where)
    cls = typing.get_args(tp)[0]
    return tuple(build(cls, item, source=source, section=f"{section}[{i}]")
                 for i, item in enumerate(value))


@functools.lru_cache(maxsize=None)
def _type_hints(cls: type) -> dict[str, Any]:
    """``typing.get_type_hints(cls)``, once per class (it dominated the cost of a build)."""
    return typing.get_type_hints(cls)


def build(cls: type, data: Mapping[str, Any], *, source: str = "<config>", section: str = "") -> Any:
    """Build and validate dataclass ``cls`` from a mapping (e.g. a parsed TOML table).

    A class may define ``component_tables(data, *, source, section) -> (data, kwargs)``: it builds the
    sub-tables of registered components it owns (a user's wind part's ``[wind.<id>]``, a law's
    ``[controller.<id>]``) and returns the rest of the table and the keyword arguments they make.

    Raises
    ------
    ConfigError
        On an unknown key (naming where it moved, if ``cls.moved_key(key)`` says), a missing
        required key, a wrong type or an out-of-range value; the
        message names ``source``, the section, the key, the value and what is allowed.
    """
    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: [{section}] must be a table, got {data!r}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    hints = _type_hints(cls)
    # a class that holds components registered from outside (a user's wind part in [wind.<id>], a law's
    # [controller.<id>]) takes their tables out first and builds them itself: they join what is built below
    components: Mapping[str, Any] = {}
    take = getattr(cls, "component_tables", None)
    if take is not None:
        data, components = take(data, source=source, section=section)
    # a class whose keys depend on the table (a fault's on its kind) says which apply to this one
    keys_for = getattr(cls, "keys_for", None)
    applicable = keys_for(data) if keys_for is not None else None
    if applicable is not None:
        inapplicable = [k for k in data if k in fields and k not in applicable]
        if inapplicable:
            key = inapplicable[0]
            raise ConfigError(f"{_where(source, section, key)} = {_shown(data[key])}: does not apply here "
                              f"({applicable.reason}); keys here: {', '.join(applicable)}")
    unknown = [k for k in data if k not in fields]
    if unknown:
        key = unknown[0]
        close = difflib.get_close_matches(key, list(fields), n=1)
        hint = f"; did you mean '{close[0]}'?" if close and isinstance(key, str) else ""
        shown = _shown(data[key])
        # a class may say where a key it no longer has went (e.g. a gain moved to a sub-table)
        moved = getattr(cls, "moved_key", None)
        moved_to = moved(key) if moved is not None and isinstance(key, str) else None
        if moved_to:
            raise ConfigError(f"{_where(source, section, key)} = {shown}: {moved_to}")
        allowed = ", ".join(k for k in fields if k not in INTERNAL_KEYS)
        if not allowed:
            raise ConfigError(f"{_where(source, section, key)} = {shown}: unknown key; this table takes no keys")
        # after a question the list is a new sentence; without one it follows a semicolon
        raise ConfigError(f"{_where(source, section, key)} = {shown}: unknown key"
                          + (f"{hint} Allowed keys: {allowed}" if hint else f"; allowed keys: {allowed}"))
    kwargs = {}
    for name, f in fields.items():
        where = _where(source, section, name)
        if name in components:
            kwargs[name] = components[name]
            continue
        if name not in data:
            if f.default is _MISSING and f.default_factory is _MISSING:  # type: ignore[misc]
                unit = f.metadata.get("unit", "")
                doc = f.metadata.get("doc", "")
                raise ConfigError(f"{where}: missing required key ({doc}; unit {unit})")
            continue
        sub_section = f"{section}.{name}" if section else name
        if dataclasses.is_dataclass(hints[name]):
            kwargs[name] = build(hints[name], data[name], source=source, section=sub_section)
        elif _is_table_list(hints[name]):
            kwargs[name] = _build_table_list(hints[name], data[name], where, source, sub_section, f.metadata)
        else:
            kwargs[name] = _convert(data[name], hints[name], f.metadata, where, source)
    # the values are converted and checked above: a Validated class's own check would repeat it
    # and, worse, name the class instead of the file
    kwargs.update({name: value for name, value in components.items() if name not in fields})
    token = _BUILDING.set(True)
    try:
        obj = cls(**kwargs)
    finally:
        _BUILDING.reset(token)
    check = getattr(obj, "_check", None)
    if check is not None:
        check(source)
    return obj


_BUILDING = contextvars.ContextVar("vtoladapt_config_building", default=False)
"""True while :func:`build` constructs a dataclass from values it has already validated."""


def validate(obj: Any, source: str, section: str = "") -> None:
    """Validate a settings dataclass built in Python exactly as :func:`build` validates a file's table.

    Every field against its :func:`setting` metadata (type, range, length, choices, pattern; a
    nested settings table must be an instance of its class), then the class's ``_check(source)``
    (its cross-field rules). Converted values (a list or 1-D array to a tuple, an int to a float,
    numpy scalars to Python's) replace the given ones, so the object is what a file would give.
    Raises :class:`ConfigError` naming ``source`` (e.g. the class), the section and the field.
    """
    cls = type(obj)
    hints = _type_hints(cls)
    for f in dataclasses.fields(cls):
        if not f.init or f.name in INTERNAL_KEYS:
            continue
        value = getattr(obj, f.name)
        tp = hints[f.name]
        where = _where(source, section, f.name)
        if dataclasses.is_dataclass(tp):
            if not isinstance(value, tp):
                raise ConfigError(f"{where} = {_shown(value)}: must be a {tp.__name__}")
            if not isinstance(value, Validated):  # a Validated one checked itself when it was made
                validate(value, source, f"{section}.{f.name}" if section else f.name)
            continue
        if _is_table_list(tp):
            item_cls = typing.get_args(tp)[0]
            if not isinstance(value, (list, tuple)) or not all(isinstance(v, item_cls) for v in value):
                raise ConfigError(f"{where} = {_shown(value)}: must be a tuple of {item_cls.__name__}")
            _check_items(value, f.metadata, where)
            converted = tuple(value)
        else:
            converted = _convert(value, tp, f.metadata, where, source)
        if converted is not value:
            object.__setattr__(obj, f.name, converted)  # frozen: the dataclass is still being made
    check = getattr(obj, "_check", None)
    if check is not None:
        check(source)


class Validated:
    """Base of a settings dataclass that validates itself when built in Python (:func:`validate`).

    A file's table goes through :func:`build`, whose messages name the file; an object made by
    hand (``ControllerConfig(K_v=...)``, ``dataclasses.replace``) is checked by the same rules
    with the class named in their place: ``ControllerConfig: [controller] K_v[0] = nan: must be
    finite; allowed: > 0 (1/s)``. ``config_section`` is the table it is in a file (for messages).
    """

    config_section = ""

    def __post_init__(self) -> None:
        if not _BUILDING.get():
            validate(self, type(self).__name__, self.config_section)


def check_input_file(path: str | Path, what: str = "file", max_bytes: int = MAX_INPUT_FILE_BYTES) -> Path:
    """``path`` if it is a readable regular file within ``max_bytes`` (:data:`MAX_INPUT_FILE_BYTES`),
    else a :class:`ConfigError` naming it (missing, a folder, a device or pipe, unreadable, too large,
    name too long)."""
    path = Path(path)
    shown = str(path) if len(str(path)) <= 120 else str(path)[:60] + "..." + str(path)[-40:]
    try:
        st = path.stat()
    except FileNotFoundError:
        raise ConfigError(f"{shown}: {what} not found") from None
    except OSError as exc:
        raise ConfigError(f"{shown}: cannot read the {what}: {exc.strerror}") from None
    if stat.S_ISDIR(st.st_mode):
        raise ConfigError(f"{shown}: is a folder; expected a {what}")
    if not stat.S_ISREG(st.st_mode):
        # a device or pipe has no size to check against the ceiling, and /dev/zero never ends
        raise ConfigError(f"{shown}: is not a regular file (a device, pipe or socket); expected a {what}")
    if not os.access(path, os.R_OK):
        raise ConfigError(f"{shown}: no permission to read the {what}")
    if st.st_size > max_bytes:
        raise ConfigError(f"{shown}: {st.st_size / 2**20:.3g} MiB; a {what} may have at most "
                          f"{max_bytes / 2**20:.3g} MiB")
    return path


def refuse_internal_keys(data: Mapping[str, Any], source: str) -> None:
    """A :class:`ConfigError` if a parsed file sets a key the loader fills in (:data:`INTERNAL_KEYS`):
    ``source_path = "elsewhere.toml"`` would move where the file's relative paths point."""
    for key in INTERNAL_KEYS:
        if isinstance(data, Mapping) and key in data:
            raise ConfigError(f"{source}: {key} = {_shown(data[key])}: unknown key; it is set from the "
                              "file's own location and cannot be written in the file")


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; a missing, unreadable, binary or invalid file is a :class:`ConfigError`
    naming it."""
    path = check_input_file(path, "TOML file", MAX_TOML_FILE_BYTES)
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not a text (UTF-8) file: byte {exc.start} is "
                          f"0x{exc.object[exc.start]:02x}; expected TOML") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(f"{path}: not valid TOML: nested too deeply") from None


def describe(cls: type) -> list[tuple[str, str, str, str]]:
    """(key, unit, allowed values, meaning) for every field of ``cls``, for docs and ``--help``."""
    rows = []
    for f in dataclasses.fields(cls):
        meta = f.metadata
        rows.append((f.name, meta.get("unit", ""), _allowed_text(meta), meta.get("doc", "")))
    return rows
