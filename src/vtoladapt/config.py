"""Validated, frozen configuration dataclasses loaded from TOML.

Every configuration field is declared with :func:`setting`, which records its unit, a one-line
meaning and the values it allows. :func:`build` turns a parsed TOML table into the dataclass,
rejecting unknown keys (with a suggestion for a likely misspelling), missing fields, wrong types
and out-of-range values with a :class:`ConfigError` that names the file, the key, the value and
what is allowed. Nothing is partly built: either the whole object validates or an error is raised.
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Mapping


class ConfigError(ValueError):
    """A configuration file or mapping is invalid; the message says where and why."""


_MISSING = dataclasses.MISSING


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
    choices: tuple | None = None,
) -> Any:
    """Declare a configuration field with its unit, meaning and allowed values.

    Bounds apply to a scalar, or to every element of a tuple (and of nested tuples).
    """
    meta = {"unit": unit, "doc": doc, "gt": gt, "ge": ge, "lt": lt, "le": le,
            "length": length, "choices": choices}
    if default is _MISSING:
        return dataclasses.field(metadata=meta)
    if isinstance(default, (list, dict, set)):
        raise TypeError("use a tuple for a sequence default")
    return dataclasses.field(default=default, metadata=meta)


def _where(source: str, section: str, key: str) -> str:
    return f"{source}: [{section}] {key}" if section else f"{source}: {key}"


def _allowed_text(meta: Mapping[str, Any]) -> str:
    parts = []
    for name, sym in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
        if meta.get(name) is not None:
            parts.append(f"{sym} {meta[name]:g}")
    if meta.get("choices"):
        parts.append("one of " + ", ".join(repr(c) for c in meta["choices"]))
    text = " and ".join(parts) if parts else "any value"
    unit = meta.get("unit")
    return f"{text} ({unit})" if unit and unit != "-" else text


def _check_scalar(value: float, meta: Mapping[str, Any], where: str) -> None:
    if not math.isfinite(value):
        raise ConfigError(f"{where} = {value!r}: must be finite; allowed: {_allowed_text(meta)}")
    bad = ((meta.get("gt") is not None and not value > meta["gt"])
           or (meta.get("ge") is not None and not value >= meta["ge"])
           or (meta.get("lt") is not None and not value < meta["lt"])
           or (meta.get("le") is not None and not value <= meta["le"]))
    if bad:
        raise ConfigError(f"{where} = {value!r}: out of range; allowed: {_allowed_text(meta)}")


def _convert(value: Any, tp: Any, meta: Mapping[str, Any], where: str, source: str) -> Any:
    origin = typing.get_origin(tp)
    if origin is typing.Union or origin is types.UnionType:
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        return _convert(value, args[0], meta, where, source)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where} = {value!r}: must be a list; allowed: {_allowed_text(meta)}")
        if meta.get("length") is not None and len(value) != meta["length"]:
            raise ConfigError(
                f"{where} = {value!r}: must have exactly {meta['length']} elements, has {len(value)}")
        inner = args[0] if args else Any
        inner_meta = dict(meta, length=None)
        return tuple(_convert(v, inner, inner_meta, f"{where}[{i}]", source)
                     for i, v in enumerate(value))
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where} = {value!r}: must be a number; allowed: {_allowed_text(meta)}")
        value = float(value)
        _check_scalar(value, meta, where)
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where} = {value!r}: must be a whole number; allowed: {_allowed_text(meta)}")
        _check_scalar(float(value), meta, where)
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where} = {value!r}: must be true or false")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where} = {value!r}: must be a string")
        if meta.get("choices") and value not in meta["choices"]:
            raise ConfigError(f"{where} = {value!r}: unknown; allowed: {_allowed_text(meta)}")
        return value
    raise TypeError(f"unsupported configuration field type {tp!r} at {where}")


def _is_table_list(tp: Any) -> bool:
    """``tuple[SomeDataclass, ...]``: a TOML array of tables (``[[section.key]]``)."""
    args = typing.get_args(tp)
    return typing.get_origin(tp) is tuple and bool(args) and dataclasses.is_dataclass(args[0])


def _build_table_list(tp: Any, value: Any, where: str, source: str, section: str) -> tuple:
    if not isinstance(value, (list, tuple)):
        raise ConfigError(f"{where} = {value!r}: must be a list of tables ([[{section}]])")
    cls = typing.get_args(tp)[0]
    return tuple(build(cls, item, source=source, section=f"{section}[{i}]")
                 for i, item in enumerate(value))


def build(cls: type, data: Mapping[str, Any], *, source: str = "<config>", section: str = "") -> Any:
    """Build and validate dataclass ``cls`` from a mapping (e.g. a parsed TOML table).

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
    hints = typing.get_type_hints(cls)
    unknown = [k for k in data if k not in fields]
    if unknown:
        key = unknown[0]
        close = difflib.get_close_matches(key, list(fields), n=1)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        shown = repr(data[key])
        shown = shown if len(shown) <= 60 else shown[:57] + "..."
        # a class may say where a key it no longer has went (e.g. a gain moved to a sub-table)
        moved = getattr(cls, "moved_key", None)
        moved_to = moved(key) if moved is not None else None
        if moved_to:
            raise ConfigError(f"{_where(source, section, key)} = {shown}: {moved_to}")
        raise ConfigError(
            f"{_where(source, section, key)} = {shown}: unknown key{hint} "
            f"Allowed keys: {', '.join(fields)}")
    kwargs = {}
    for name, f in fields.items():
        where = _where(source, section, name)
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
            kwargs[name] = _build_table_list(hints[name], data[name], where, source, sub_section)
        else:
            kwargs[name] = _convert(data[name], hints[name], f.metadata, where, source)
    obj = cls(**kwargs)
    check = getattr(obj, "_check", None)
    if check is not None:
        check(source)
    return obj


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file, turning a syntax error into a :class:`ConfigError` naming the file."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None


def describe(cls: type) -> list[tuple[str, str, str, str]]:
    """(key, unit, allowed values, meaning) for every field of ``cls``, for docs and ``--help``."""
    rows = []
    for f in dataclasses.fields(cls):
        meta = f.metadata
        rows.append((f.name, meta.get("unit", ""), _allowed_text(meta), meta.get("doc", "")))
    return rows
