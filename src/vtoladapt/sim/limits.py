"""Size ceilings, each derived from the memory its arrays need against one budget.

Every size a user chooses (simulated duration over the control period, runs of an experiment or
a campaign, tunnel repeats, MCMC walkers and steps) is checked here before anything runs or is
written, against :data:`vtoladapt.config.MEMORY_BUDGET_BYTES` (6 GiB unless
``VTOLADAPT_MEMORY_BUDGET_GB`` says otherwise). The message says how the bytes were counted.
README "When things go wrong" lists the resulting ceilings.
"""
from __future__ import annotations

import math
import pickle

from ..config import MEMORY_BUDGET_BYTES, ConfigError, check_memory

FLOAT_BYTES = 8
FORCE_BALANCE_COLUMNS = 16
"""Float columns of a force-balance table in memory (inputs, forces, moments, derived values)."""
FIT_PARAMETERS_MAX = 8
"""Most dimensions the MCMC samples (k1, k2 and the noise model), an upper count for its chain."""
FIT_WORK_COPIES = 4
"""Residual arrays (walkers x rows x 3 axes) alive at once in one vectorised likelihood call."""
CAMPAIGN_ROW_BYTES = 4096
"""A campaign row (about forty metrics in a dict) and its Dask task record, generously."""


def log_columns(scenario=None) -> int:
    """Columns of a simulation log (one float64 each per control tick): of ``scenario``'s controller (its
    basis's n parameters, its law's diagnostics; of a comparison the widest of its laws'), or without a
    scenario of the paper's eight-parameter basis and the registered law with the most diagnostics."""
    from .loop import log_size
    from ..control.step import diagnostics_size_for

    if scenario is None:
        return log_size(diagnostics_size_for(8))
    from ..bases import describe_basis

    try:
        n = describe_basis(scenario.load_vehicle(), scenario.controller.basis).n
    except ConfigError:
        n = 8  # an unknown basis is refused, naming the file, when the run is prepared
    laws = (scenario.experiment.controllers if scenario.experiment.kind == "comparison"
            else (scenario.controller.kind,))
    return log_size(max(diagnostics_size_for(n, law) for law in laws))


def experiment_runs(scenario) -> int:
    """How many runs of ``scenario`` are held in memory together by ``vtoladapt run``."""
    kind = scenario.experiment.kind
    if kind == "comparison":
        return len(scenario.experiment.controllers)
    if kind == "convergence":
        return scenario.experiment.runs
    return 1


def check_run_size(scenario, where: str, n_runs: int | None = None) -> None:
    """Refuse a scenario whose logs (runs x ticks x columns x 8 bytes) exceed the budget."""
    n_runs = experiment_runs(scenario) if n_runs is None else n_runs
    ticks = scenario.n_ticks
    if ticks < 2:
        raise ConfigError(f"{where}: duration_s = {scenario.duration_s:g} s at dt_control_s = "
                          f"{scenario.dt_control_s:g} s is {ticks} control ticks; a run needs at "
                          "least 2")
    cols = log_columns(scenario)
    check_memory(f"{n_runs} run(s) x {ticks} log rows x {cols} columns x {FLOAT_BYTES} bytes",
                 float(n_runs) * ticks * cols * FLOAT_BYTES, where,
                 "shorten duration_s, lengthen dt_control_s or fly fewer runs at once")


def in_memory_run_bytes(scenario) -> float:
    """Bytes :func:`vtoladapt.simulate.simulate` holds for one run: the log, the reference table and
    the tick times, one float64 each per control tick (``log_columns() + REF_SIZE + 1`` per tick)."""
    from ..layout import REF_SIZE

    return float(scenario.n_ticks) * (log_columns(scenario) + REF_SIZE + 1) * FLOAT_BYTES


def check_in_memory_runs(scenarios, where: str) -> None:
    """Refuse runs whose in-memory logs (:func:`in_memory_run_bytes`, summed: ``simulate_many``
    returns them all) exceed the budget, before any array is allocated."""
    from ..layout import REF_SIZE

    scenarios = list(scenarios)
    ticks = sum(sc.n_ticks for sc in scenarios)
    cols = max((log_columns(sc) for sc in scenarios), default=log_columns())
    check_memory(f"{len(scenarios)} run(s), {ticks} ticks in all x ({cols} log + {REF_SIZE} reference "
                 f"+ 1 time) columns x {FLOAT_BYTES} bytes", sum(in_memory_run_bytes(sc) for sc in scenarios),
                 where, "shorten duration_s, lengthen dt_control_s or fly fewer runs at once")


def max_duration_s(scenario, n_runs: int = 1) -> float:
    """The longest duration whose logs fit the budget at the scenario's control period."""
    return MEMORY_BUDGET_BYTES / (n_runs * log_columns(scenario) * FLOAT_BYTES) * scenario.dt_control_s


def check_campaign_runs(runs: int, base_mapping: dict, where: str = "--runs") -> None:
    """Refuse a campaign whose planned runs (each a scenario copy and a result row) exceed the budget."""
    per_run = len(pickle.dumps(base_mapping)) * 3 + CAMPAIGN_ROW_BYTES  # dict overhead ~3x pickle
    check_memory(f"{runs} runs x {per_run} bytes (scenario copy and result row)",
                 float(runs) * per_run, where, "split the campaign into several")


def check_tunnel_rows(points_per_repeat: int, repeats: int, where: str = "--repeats") -> None:
    """Refuse a tunnel design whose table (rows x columns x 8 bytes) exceeds the budget."""
    rows = float(points_per_repeat) * repeats
    check_memory(f"{points_per_repeat} points x {repeats} repeats x {FORCE_BALANCE_COLUMNS} "
                 f"columns x {FLOAT_BYTES} bytes", rows * FORCE_BALANCE_COLUMNS * FLOAT_BYTES, where)


def check_fit_size(walkers: int, max_steps: int, n_rows: int, where: str) -> None:
    """Refuse MCMC settings whose chain and vectorised residuals exceed the budget."""
    chain = float(walkers) * max_steps * FIT_PARAMETERS_MAX * FLOAT_BYTES
    work = float(walkers) * n_rows * 3 * FLOAT_BYTES * FIT_WORK_COPIES
    check_memory(f"chain {walkers} walkers x {max_steps} steps x {FIT_PARAMETERS_MAX} parameters "
                 f"x {FLOAT_BYTES} bytes + residuals {walkers} walkers x {n_rows} rows x 3 axes x "
                 f"{FLOAT_BYTES} bytes x {FIT_WORK_COPIES}", chain + work, where)


def ceiling(n_bytes_per_unit: float) -> int:
    """How many units of ``n_bytes_per_unit`` the budget holds."""
    return int(math.floor(MEMORY_BUDGET_BYTES / n_bytes_per_unit))


ROW_CHECKS = {
    "wind.fan_array.schedule": "rows [t_s, throttle_pct]: t_s >= 0 and non-decreasing, "
                               "throttle_pct 0 to 100",
    "geometry.lift_rotor_spin": "+1 or -1 for each of the four rotors",
    "reference.waypoints": "rows [t_s, north_m, east_m, down_m], each within +-10000, t_s "
                           "increasing",
}
"""Keys whose range is checked per row by the settings class rather than per element."""


def _range_text(meta) -> str:
    from ..config import MAGNITUDE_MAX

    parts = []
    for name, sym in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
        v = meta.get(name)
        if v is not None:
            parts.append(f"{sym} {v:g}" if abs(v) < 2**62 else f"{sym} 2^63-1")
    if meta.get("gt") is None and meta.get("ge") is None:
        parts.insert(0, f">= {-MAGNITUDE_MAX:g}")
    if meta.get("lt") is None and meta.get("le") is None:
        parts.append(f"<= {MAGNITUDE_MAX:g}")
    unit = meta.get("unit")
    text = ", ".join(parts)
    return f"{text} ({unit})" if unit and unit != "-" else text


def _settings_rows(cls: type, prefix: str = "") -> list[tuple[str, str, str]]:
    """(dotted key, unit, allowed values) of every numeric setting under ``cls``."""
    import dataclasses
    import types
    import typing

    from ..config import _type_hints

    rows = []
    hints = _type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        inner = tp
        while True:  # unwrap Optional[...] and tuple[...]
            origin = typing.get_origin(inner)
            if origin is typing.Union or origin is types.UnionType or origin is tuple:
                args = [a for a in typing.get_args(inner) if a is not type(None) and a is not Ellipsis]
                if not args:
                    break
                inner = args[0]
                continue
            break
        key = prefix + f.name
        if dataclasses.is_dataclass(inner):
            sub = f"{key}[]." if typing.get_origin(tp) is tuple else f"{key}."
            rows += _settings_rows(inner, sub)
        elif inner in (int, float):
            rows.append((key, f.metadata.get("unit", ""), _range_text(f.metadata)))
    # tables named by a registry rather than by a field (a law's [controller.<id>])
    for name, sub in getattr(cls, "sub_tables", dict)().items():
        rows += _settings_rows(sub, f"{prefix}{name}.")
    return rows


def ranges_markdown() -> str:
    """The README's table of every numeric key of a scenario and a vehicle file and its range."""
    from .scenario import Scenario
    from ..vehicle import Vehicle

    lines = ["| file | key | allowed (unit) |", "|---|---|---|"]
    for name, cls in (("scenario", Scenario), ("vehicle", Vehicle)):
        for key, unit, text in _settings_rows(cls):
            if key == "source_path":
                continue
            text = ROW_CHECKS.get(key, text)
            lines.append(f"| {name} | `{key}` | {text.replace('|', '/')} |")
    return "\n".join(lines)
