"""The configuration reference: every key of the package's settings files, generated from the code.

Every settings field is declared with :func:`vtoladapt.config.setting` (unit, meaning, default and
allowed values), so the reference is read off the dataclasses, never written by hand:
:func:`settings_markdown` renders one Markdown table per TOML table of a scenario file
(:class:`vtoladapt.sim.scenario.Scenario`), a vehicle file (:class:`vtoladapt.vehicle.Vehicle`), a
campaign file (:class:`vtoladapt.campaign.runner.CampaignConfig`) and the Gymnasium environment's
keyword arguments (:class:`vtoladapt.gym.settings.HoldEnvConfig`). The documentation site's build
(``docs/conf.py``) writes it to ``docs/_generated/settings.md``; the allowed values are the ones the
input checks apply (the same text as :func:`vtoladapt.sim.limits.ranges_markdown`).
"""
from __future__ import annotations

import dataclasses
import math
import types
import typing

from .config import _PATTERN_TEXT, INTERNAL_KEYS, _type_hints, choices_of
from .sim.limits import BOUND_REASONS, ROW_CHECKS, _range_text


def _unwrap(tp) -> tuple[object, bool, bool]:
    """``(inner type, is a list, is optional)`` of an annotation: Optional[...] and tuple[...] peeled."""
    is_list = optional = False
    while True:
        origin = typing.get_origin(tp)
        if origin is typing.Union or origin is types.UnionType:
            args = [a for a in typing.get_args(tp) if a is not type(None)]
            optional = optional or len(args) < len(typing.get_args(tp))
            tp = args[0] if len(args) == 1 else tp
            if len(args) != 1:
                return tp, is_list, optional
            continue
        if origin is tuple:
            args = [a for a in typing.get_args(tp) if a is not Ellipsis]
            is_list = True
            if not args:
                return typing.Any, is_list, optional
            tp = args[0]
            continue
        return tp, is_list, optional


def _type_text(inner, is_list: bool, meta) -> str:
    names = {float: "number", int: "integer", str: "text", bool: "true/false"}
    name = names.get(inner, "table" if dataclasses.is_dataclass(inner) else "value")
    if not is_list:
        return name
    if meta.get("length"):
        return f"{meta['length']} × {name}"
    return f"list of {name}"


def _default_text(field: dataclasses.Field) -> str:
    if field.default is not dataclasses.MISSING:
        value = field.default
    elif field.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        return "(table defaults)"
    else:
        return "required"
    if value is None:
        return "none (see meaning)"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and math.isfinite(value):
        return f"{value:g}"
    if isinstance(value, tuple):
        if value and dataclasses.is_dataclass(value[0]):
            return f"{len(value)} tables"
        return "[" + ", ".join(f"{v:g}" if isinstance(v, float) else repr(v) for v in value) + "]"
    if isinstance(value, str):
        return f'"{value}"'
    return str(value)


def _allowed_text(key: str, inner, meta) -> str:
    if key in ROW_CHECKS:
        return ROW_CHECKS[key]
    choices = choices_of(meta)  # a registry's ids are read when the reference is made
    if choices:
        return "one of " + ", ".join(f'"{c}"' if isinstance(c, str) else str(c) for c in choices)
    if inner is bool:
        return "true or false"
    if inner in (int, float):
        text = _range_text(meta)
        why = BOUND_REASONS.get(key)
        return f"{text}; lower bound: {why}" if why else text
    if meta.get("pattern"):
        return _PATTERN_TEXT.get(meta["pattern"], f"matches `{meta['pattern']}`")
    if inner is str:
        return "text"
    return "see meaning"


def _cell(text: str) -> str:
    return str(text).replace("|", "/").replace("\n", " ")


def _tables(cls: type, section: str, out: list[str], array: bool = False) -> None:
    """Append the table of ``cls``'s own keys, then a section per sub-table, to ``out``."""
    hints = _type_hints(cls)
    rows, subs = [], []
    for f in dataclasses.fields(cls):
        if f.name in INTERNAL_KEYS:
            continue
        inner, is_list, _optional = _unwrap(hints[f.name])
        key = f"{section}.{f.name}" if section else f.name
        if dataclasses.is_dataclass(inner):
            subs.append((inner, key, is_list, f))
            continue
        meta = f.metadata
        unit = meta.get("unit", "")
        rows.append(f"| `{f.name}` | {_type_text(inner, is_list, meta)} | {_cell(unit if unit != '-' else '')} | "
                    f"{_cell(_default_text(f))} | {_cell(_allowed_text(key, inner, meta))} | "
                    f"{_cell(meta.get('doc', ''))} |")
    doc = (cls.__doc__ or "").strip().split("\n\n")[0].replace("\n", " ")
    if section:
        out.append(f"### `[[{section}]]`\n" if array else f"### `[{section}]`\n")
    if doc:
        out.append(f"{doc}\n")
    if array:
        out.append(f"An array of tables: one `[[{section}]]` per entry.\n")
    if rows:
        out.append("| key | type | unit | default | allowed | meaning |\n|---|---|---|---|---|---|")
        out.extend(rows)
        out.append("")
    for inner, key, is_list, f in subs:
        _tables(inner, key, out, array=is_list)
    # tables named by a registry rather than by a field (each law's [controller.<id>]), read now
    for name, sub in getattr(cls, "sub_tables", dict)().items():
        _tables(sub, f"{section}.{name}" if section else name, out)


FILES = (
    ("Scenario file", "vtoladapt.sim.scenario", "Scenario",
     "A scenario TOML (`vtoladapt run FILE`, `load_scenario`); its top-level keys, then one table per section."),
    ("Vehicle file", "vtoladapt.vehicle", "Vehicle",
     "A vehicle TOML (`vehicle = \"NAME\"` or a path in a scenario, `load_vehicle`)."),
    ("Campaign file", "vtoladapt.campaign.runner", "CampaignConfig",
     "The `[campaign]` table of a campaign file (`vtoladapt campaign FILE`); its `set` and `choices` "
     "sub-tables take dotted scenario keys from the tables above."),
    ("Gymnasium environment", "vtoladapt.gym.settings", "HoldEnvConfig",
     "The keyword arguments of `gym.make(\"vtoladapt/Hold-v0\", ...)`."),
)
"""(title, module, class, what it configures) of every settings file the reference covers."""


def settings_markdown() -> str:
    """The configuration reference (Markdown): one section per file kind, one table per TOML table."""
    import importlib

    out: list[str] = []
    for title, module, name, what in FILES:
        cls = getattr(importlib.import_module(module), name)
        out.append(f"## {title}\n")
        out.append(f"{what} Read from `{module}.{name}`.\n")
        _tables(cls, "", out)
    return "\n".join(out).rstrip() + "\n"


def metrics_markdown() -> str:
    """Every metric a run or an experiment reports (``metrics.json`` key, meaning, unit), from the one
    map the tables and figures use (:data:`vtoladapt.sim.run_metrics.METRIC_INFO` and the per-phase
    :data:`vtoladapt.experiments.metrics.PHASE_METRIC_INFO`)."""
    from .experiments.metrics import PHASE_METRIC_INFO
    from .sim.run_metrics import METRIC_INFO

    rows = ["| key in `metrics.json` | meaning | unit |", "|---|---|---|"]
    for key, (label, unit) in {**METRIC_INFO, **PHASE_METRIC_INFO}.items():
        rows.append(f"| `{key}` | {_cell(label)} | {_cell(unit)} |")
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    print(settings_markdown(), end="")
