"""The simulator's size ceilings (its logs), derived from the memory they need against one budget.

The simulated duration over the control period and the runs held together are checked here before
anything runs or is written, against :data:`vtoladapt.config.MEMORY_BUDGET_BYTES` (6 GiB unless
``VTOLADAPT_MEMORY_BUDGET_GB`` says otherwise); the ceilings that have nothing to do with the
simulator (a campaign's plan, a tunnel design, a fit) are :mod:`vtoladapt.ceilings`'. The message
says how the bytes were counted. docs/reference/errors.md ("Size ceilings") lists the resulting ceilings. Also
here: the README's table of every numeric key's range.
"""
from __future__ import annotations

from ..config import MEMORY_BUDGET_BYTES, ConfigError, check_memory

from ..ceilings import FLOAT_BYTES


def log_columns(scenario=None) -> int:
    """Columns of a simulation log (one float64 each per control tick): of ``scenario``'s controller (its
    basis's n parameters, its law's diagnostics; of a comparison the widest of its laws'), or without a
    scenario of the paper's eight-parameter basis and the registered law with the most diagnostics."""
    from .loop import log_size
    from ..control.step import diagnostics_size_for

    if scenario is None:
        return log_size(diagnostics_size_for(8))
    n = basis_size(scenario)
    laws = (scenario.experiment.controllers if scenario.experiment.kind == "comparison"
            else (scenario.controller.kind,))
    return log_size(max(diagnostics_size_for(n, law) for law in laws))


def basis_size(scenario) -> int:
    """n, the parameters of the force-model basis ``scenario``'s controller adapts (8 if it names an unknown
    basis: that is refused, naming the file, when the run is prepared)."""
    from ..bases import describe_basis

    try:
        return describe_basis(scenario.load_vehicle(), scenario.controller.basis).n
    except ConfigError:
        return 8


def experiment_runs(scenario) -> int:
    """How many runs of ``scenario``'s experiment ``vtoladapt run`` flies (each streamed to its log)."""
    kind = scenario.experiment.kind
    if kind == "comparison":
        return len(scenario.experiment.controllers)
    if kind == "convergence":
        return scenario.experiment.runs
    return 1


# What a run holds, per control tick, in float64 values (measured with LoggedResult.loaded_columns and
# the peak resident memory of `vtoladapt run`; tests/test_memory.py holds the model to the measurement)
ANALYSIS_COLUMNS_PER_RUN = 38
"""Log columns the metrics and figures of ``vtoladapt run`` read back from each run's streamed log
(at most 35: a convergence run; 33 a single run, 25 a compared controller) and the cached velocity error (3)."""
ANALYSIS_TRANSIENT_COLUMNS = 64
"""Values per tick of the run being analysed that its metrics and figures create and drop again (norms,
errors, filtered series): measured 56 for the one-hour single run (peak minus a short run's)."""
STREAM_ROW_GROUP_ROWS = 15_000
"""Rows of the row group a streamed run holds (60 s at 250 Hz; :data:`vtoladapt.sim.longrun.ROW_GROUP_S`),
held twice while it is written (the buffer and its Arrow copy)."""


def run_memory(scenario, variants: int | None = None, workers: int | None = None) -> tuple[float, str]:
    """``(bytes, how they were counted)`` that ``vtoladapt run`` of ``scenario`` holds at its peak.

    Three phases, the largest counts: flying the runs (``workers`` at a time, each streaming its log:
    its reference table and tick times per tick, and a row group), analysing them (every run's
    :data:`ANALYSIS_COLUMNS_PER_RUN`, the one being analysed's transients, theta-hat stacked for a
    convergence study), and the seeded variants of a comparison or convergence study (flown in memory
    ``workers`` at a time, each a whole log with its transients, reduced to metrics as it ends).
    """
    import os

    from ..layout import REF_SIZE

    ticks = float(scenario.n_ticks)
    runs = experiment_runs(scenario)
    workers = min(runs, workers or os.cpu_count() or 1)
    cols = log_columns(scenario)
    row_group = min(ticks, STREAM_ROW_GROUP_ROWS) * cols * 2
    flying = workers * (ticks * (REF_SIZE + 1) + row_group)
    theta = basis_size(scenario) if scenario.experiment.kind == "convergence" else 0  # theta-hat stacked for the figure
    analysing = ticks * (runs * (ANALYSIS_COLUMNS_PER_RUN + theta) + ANALYSIS_TRANSIENT_COLUMNS)
    phases = {f"flying {workers} run(s) at a time: {ticks:.0f} ticks x ({REF_SIZE} reference + 1 time) "
              f"+ a {min(ticks, STREAM_ROW_GROUP_ROWS):.0f}-row group x {cols} columns x 2": flying,
              f"analysing {runs} run(s) x {ticks:.0f} ticks x {ANALYSIS_COLUMNS_PER_RUN + theta} columns + "
              f"{ANALYSIS_TRANSIENT_COLUMNS} transient": analysing}
    n_var = scenario.experiment.variants if variants is None else variants
    if scenario.experiment.kind != "single" and n_var > 1:
        per_variant = min(workers, runs) if scenario.experiment.kind == "comparison" else runs
        phases[f"variants: {per_variant} run(s) at a time in memory x {ticks:.0f} ticks x ({cols} log + "
               f"{REF_SIZE + 1} reference and time + {ANALYSIS_TRANSIENT_COLUMNS} transient)"] = (
            per_variant * ticks * (cols + REF_SIZE + 1 + ANALYSIS_TRANSIENT_COLUMNS))
    what, values = max(phases.items(), key=lambda kv: kv[1])
    return values * FLOAT_BYTES, f"{what}, x {FLOAT_BYTES} bytes"


def check_ticks(scenario, where: str, at_least: int = 2) -> None:
    """Refuse a scenario of fewer than ``at_least`` control ticks (a command's run needs two: the metrics
    compare ticks; a run of the Python API one)."""
    ticks = scenario.n_ticks
    if ticks < at_least:
        raise ConfigError(f"{where}: duration_s = {scenario.duration_s:g} s at dt_control_s = "
                          f"{scenario.dt_control_s:g} s is {ticks} control ticks; a run needs at "
                          f"least {at_least}")


def check_run_size(scenario, where: str, variants: int | None = None) -> None:
    """Refuse a scenario whose run (:func:`run_memory`) exceeds the budget, or that is shorter than two ticks."""
    check_ticks(scenario, where)
    n_bytes, what = run_memory(scenario, variants)
    check_memory(what, n_bytes, where, "shorten duration_s, lengthen dt_control_s or fly fewer runs at once")


def check_worker_runs(scenario, where: str, workers: int) -> None:
    """Refuse a scenario whose in-memory runs, ``workers`` at a time (a campaign's workers: each holds
    one log while it computes the run's metrics), exceed the budget."""
    from ..layout import REF_SIZE

    check_ticks(scenario, where)
    cols = log_columns(scenario)
    per_tick = cols + REF_SIZE + 1 + ANALYSIS_TRANSIENT_COLUMNS
    check_memory(f"{workers} run(s) at a time in memory x {scenario.n_ticks} ticks x ({cols} log + "
                 f"{REF_SIZE + 1} reference and time + {ANALYSIS_TRANSIENT_COLUMNS} transient) x {FLOAT_BYTES} bytes",
                 float(workers) * scenario.n_ticks * per_tick * FLOAT_BYTES, where,
                 "shorten duration_s, lengthen dt_control_s or use fewer workers")


def in_memory_run_bytes(scenario) -> float:
    """Bytes :func:`vtoladapt.sim.driver.simulate` holds for one run: the log, the reference table and
    the tick times, one float64 each per control tick (``log_columns() + REF_SIZE + 1`` per tick)."""
    from ..layout import REF_SIZE

    return float(scenario.n_ticks) * (log_columns(scenario) + REF_SIZE + 1) * FLOAT_BYTES


def check_in_memory_runs(scenarios, where: str) -> None:
    """Refuse runs whose in-memory logs (:func:`in_memory_run_bytes`, summed: ``simulate_many``
    returns them all) exceed the budget, before any array is allocated."""
    from ..layout import REF_SIZE

    scenarios = list(scenarios)
    for sc in scenarios:
        check_ticks(sc, sc.source_path or f"scenario {sc.name!r}", at_least=1)
    ticks = sum(sc.n_ticks for sc in scenarios)
    cols = max((log_columns(sc) for sc in scenarios), default=log_columns())
    check_memory(f"{len(scenarios)} run(s), {ticks} ticks in all x ({cols} log + {REF_SIZE} reference "
                 f"+ 1 time) columns x {FLOAT_BYTES} bytes", sum(in_memory_run_bytes(sc) for sc in scenarios),
                 where, "shorten duration_s, lengthen dt_control_s or fly fewer runs at once")


def max_duration_s(scenario, variants: int | None = None, workers: int | None = None) -> float:
    """The longest ``duration_s`` whose run (:func:`run_memory`) fits the budget at the scenario's
    control period (the memory grows linearly with the ticks: found from two durations)."""
    a = run_memory(scenario.replace(duration_s=1000.0 * scenario.dt_control_s), variants, workers)[0]
    b = run_memory(scenario.replace(duration_s=2000.0 * scenario.dt_control_s), variants, workers)[0]
    per_tick = (b - a) / 1000.0
    return (MEMORY_BUDGET_BYTES - (a - 1000.0 * per_tick)) / per_tick * scenario.dt_control_s


_LIGHTEST = ("0.1 kg: the lightest aircraft this model describes (a 100 g micro VTOL); the forces are "
             "per unit mass, and 5e-324 kg divided by zero")
_SMALLEST_INERTIA = "1e-5 kg m^2: the lightest aircraft (0.1 kg) with a 1 cm radius of gyration"
_THINNEST_AIR = "0.3 kg/m^3: air at 12 km, above any small UAS's ceiling"
_FASTEST_MOTOR = ("1 ms: the fastest small motor and propeller spin up in about 10 ms; the run also checks "
                  "the plant's RK4 step against it")
_SMALLEST_EDDY = ("1 m: the Dryden model treats the aircraft as a point in the turbulence, which scales "
                  "shorter than its span break (MIL-F-8785C's low-altitude L_w at 1 m height is 1 m)")
BOUND_REASONS = {
    "mass.mass_kg": _LIGHTEST, "plant.mass_kg": _LIGHTEST,
    "mass.inertia_kgm2": _SMALLEST_INERTIA, "plant.inertia_kgm2": _SMALLEST_INERTIA,
    "geometry.wing_area_m2": "0.01 m^2: the wing of the lightest aircraft (10 cm x 10 cm)",
    "geometry.wingspan_m": "0.1 m: the span of the lightest aircraft; 5e-324 m diverged instead of being refused",
    "geometry.lift_prop_diameter_m": "25 mm: the one-inch propellers of the smallest drones",
    "geometry.pusher_prop_diameter_m": "25 mm: the one-inch propellers of the smallest drones",
    "geometry.pusher_prop_pitch_m": "10 mm: a flat one-inch propeller",
    "actuators.lift_motor_time_constant_s": _FASTEST_MOTOR, "actuators.pusher_motor_time_constant_s": _FASTEST_MOTOR,
    "plant.lift_motor_time_constant_s": _FASTEST_MOTOR, "plant.pusher_motor_time_constant_s": _FASTEST_MOTOR,
    "actuators.yaw_torque_per_thrust_m": ("1 mm: rotor drag torque per thrust is 10-50 mm for real propellers; "
                                          "below 1 mm the lift rotors have no yaw authority"),
    "envelope.air_density_kgpm3": _THINNEST_AIR, "plant.air_density_kgpm3": _THINNEST_AIR,
    "wind.turbulence.length_scale_m": _SMALLEST_EDDY,
    "wind.turbulence.altitude_m": "1 m: below it the low-altitude length scales fall under a span (see length_scale_m)",
}
"""Why a key's lower bound is where it is (README's range table shows it): the physical reason, not
the arithmetic one, for the keys whose lower bound is not simply 0."""

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

    lines = ["| file | key | allowed (unit) | why the lower bound |", "|---|---|---|---|"]
    for name, cls in (("scenario", Scenario), ("vehicle", Vehicle)):
        for key, unit, text in _settings_rows(cls):
            if key == "source_path":
                continue
            text = ROW_CHECKS.get(key, text)
            why = BOUND_REASONS.get(key, "")
            lines.append(f"| {name} | `{key}` | {text.replace('|', '/')} | {why.replace('|', '/')} |")
    return "\n".join(lines)
