"""Issue #27, item 1: configuration built in Python is validated as a file's table is, and no kernel
indexes with an unchecked integer that came from a user.

Before the fix ``FaultConfig(motor=100000000)`` reached the actuator-fault kernel, which wrote
through ``motor_cmd[99999999]`` (exit 139); ``plant_substeps=-3`` froze the plant, ``dt_control_s=0``
divided by zero. Every settings class reachable from a scenario, a vehicle, the gym's and a campaign
file's settings is checked here, field by field, against its own declared range.
"""
from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
import typing

import numpy as np
import pytest

from vtoladapt.config import ConfigError, Validated, _type_hints
from vtoladapt.layout import MEAS_SIZE, PLANT_INPUT_SIZE
from vtoladapt.sim.faults import (FAULT_ROW, FAULT_STATE, FaultConfig, apply_actuator_faults, apply_measurement_faults,
                                  faults_to_kernel)
from vtoladapt.sim.scenario import load_scenario, scenario_from_mapping

SEGFAULT_SCRIPT = """
from dataclasses import replace
from vtoladapt.sim.faults import FaultConfig
from vtoladapt.sim.scenario import load_scenario
from vtoladapt.sim.driver import simulate
base = load_scenario("gym_hold").replace(duration_s=1.0)
try:
    fault = FaultConfig(kind="stuck_throttle", start_s=0.2, end_s=0.8, motor=MOTOR)
except ValueError as exc:
    print("refused:", exc)
    raise SystemExit(2)
simulate(replace(base, faults=(fault,)))
print("ran")
"""


@pytest.mark.parametrize("motor", [100000000, 50])
def test_an_out_of_range_fault_motor_is_refused_not_written_through(motor):
    """In a child process (before the fix, 100000000 killed it with SIGSEGV, 50 wrote past the motors)."""
    proc = subprocess.run([sys.executable, "-c", SEGFAULT_SCRIPT.replace("MOTOR", str(motor))],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr[-2000:])
    assert proc.stdout.strip() == (f"refused: FaultConfig: [faults] motor = {motor}: out of range; "
                                   "allowed: >= 1 and <= 5")


GUARD = 64
"""Elements of sentinel on each side of an array handed to a kernel: a write outside the array lands there."""


def _guarded(values) -> tuple[np.ndarray, np.ndarray]:
    """``values`` as a view into a larger buffer of NaN sentinels, and the buffer."""
    values = np.asarray(values, dtype=float)
    buf = np.full(values.size + 2 * GUARD, np.nan)
    view = buf[GUARD:GUARD + values.size]
    view[:] = values
    return view, buf


def _sentinels_intact(buf) -> bool:
    return bool(np.isnan(buf[:GUARD]).all() and np.isnan(buf[-GUARD:]).all())


def test_the_actuator_fault_kernel_ignores_a_motor_index_outside_the_commands():
    """A schedule made by hand (not by faults_to_kernel) with a wild motor index writes nothing: neither
    the commands nor anything beside the plant input."""
    row = FAULT_ROW.pack(KIND=10, START=0.0, END=1.0, MOTOR=1e8)  # stuck_throttle, motor 100 000 001
    schedule = np.array([row])
    state, state_buf = _guarded(np.zeros(FAULT_STATE.size))
    cmd = np.zeros(PLANT_INPUT_SIZE)
    cmd[:5] = [0.1, 0.2, 0.3, 0.4, 0.5]
    u_in, u_buf = _guarded(cmd)
    apply_actuator_faults(schedule, state, 0.5, 1.0, u_in)
    assert u_in.tolist() == cmd.tolist()
    assert _sentinels_intact(u_buf) and _sentinels_intact(state_buf)


@pytest.mark.parametrize("short", ["u_in", "fstate"])
def test_the_actuator_fault_kernel_refuses_an_array_shorter_than_its_layout(short):
    """Issue #32's abort: this file's test above once passed the five motor commands alone, and the kernel
    reset the surfaces' condition rows past their end, into the heap; glibc aborted the worker minutes
    later, in whatever test freed memory next (the crash seen in test_reliability_api, test_reports,
    test_scenario). The kernel now refuses such an array and writes nothing, not even beside it."""
    row = FAULT_ROW.pack(KIND=10, START=0.0, END=1.0, MOTOR=0)
    sizes = {"u_in": PLANT_INPUT_SIZE, "fstate": FAULT_STATE.size}
    sizes[short] = 5
    u_in, u_buf = _guarded(np.arange(sizes["u_in"], dtype=float))
    state, state_buf = _guarded(np.zeros(sizes["fstate"]))
    with pytest.raises(ValueError, match="shorter than"):
        apply_actuator_faults(np.array([row]), state, 0.5, 1.0, u_in)
    assert _sentinels_intact(u_buf) and _sentinels_intact(state_buf)
    assert u_in.tolist() == list(range(sizes["u_in"]))


@pytest.mark.parametrize("short", ["meas", "fstate"])
def test_the_measurement_fault_kernel_refuses_an_array_shorter_than_its_layout(short):
    row = FAULT_ROW.pack(KIND=0, START=0.0, END=1.0)
    sizes = {"meas": MEAS_SIZE, "fstate": FAULT_STATE.size}
    sizes[short] = 5
    meas, m_buf = _guarded(np.ones(sizes["meas"]))
    state, state_buf = _guarded(np.zeros(sizes["fstate"]))
    with pytest.raises(ValueError, match="shorter than"):
        apply_measurement_faults(np.array([row]), state, 0.5, 0.004, meas)
    assert _sentinels_intact(m_buf) and _sentinels_intact(state_buf)


def test_faults_to_kernel_rechecks_the_motor_it_packs():
    fault = FaultConfig(kind="stuck_throttle", start_s=0.1, end_s=0.2, motor=5)
    object.__setattr__(fault, "motor", 6)  # past validation, as only a determined caller can
    with pytest.raises(ConfigError, match="motor = 6: allowed: 1 to 5"):
        faults_to_kernel((fault,), 0.004)


@pytest.mark.parametrize("change, message", [
    ({"plant_substeps": -3}, "Scenario: plant_substeps = -3: out of range; allowed: >= 1 and <= 100"),
    ({"dt_control_s": 0.0}, "Scenario: dt_control_s = 0.0: out of range"),
    ({"duration_s": 1e5}, "Scenario: duration_s = 100000.0: out of range; allowed: > 0 and <= 3600 (s)"),
    ({"seed": -1}, "Scenario: seed = -1: out of range"),
])
def test_scenario_replaced_in_python_is_checked(change, message):
    base = load_scenario("gym_hold")
    with pytest.raises(ConfigError) as info:
        dataclasses.replace(base, **change)
    assert str(info.value).startswith(message), str(info.value)


def test_simulate_refuses_a_log_beyond_the_memory_budget_before_allocating_it():
    """3600 s at 10 kHz is 36 M ticks (about 48 GiB of log): the size-ceiling error, not numpy's MemoryError."""
    from vtoladapt.sim.driver import simulate

    sc = dataclasses.replace(load_scenario("gym_hold"), duration_s=3600.0, dt_control_s=1e-4,
                             controller=dataclasses.replace(load_scenario("gym_hold").controller,
                                                            loop_rate_hz=10000.0))
    with pytest.raises(ConfigError, match="over the memory budget"):
        simulate(sc)


def test_a_mocap_latency_beyond_its_ring_is_refused_at_load_naming_the_file(tmp_path):
    """Before: the sensor kernel raised 'sensors: mocap latency_s / dt exceeds the ring buffer' mid-run."""
    path = tmp_path / "s.toml"
    path.write_text('name = "s"\nvehicle = "caltech_vtol"\nduration_s = 1.0\ndt_control_s = 0.001\n'
                    '[sensors.mocap]\nlatency_s = 0.2\n')
    with pytest.raises(ConfigError) as info:
        load_scenario(path)
    assert str(info.value).startswith(f"{path}: [sensors.mocap] latency_s = 0.2: 200 ticks"), str(info.value)


# --- every settings class, every bounded field -----------------------------------------------------

def _settings_objects():
    """One instance of every settings class reachable from the shipped configurations."""
    from vtoladapt.campaign.runner import load_campaign_file
    from vtoladapt.gym.settings import HoldEnvConfig
    from vtoladapt.sim.scenario import SCENARIO_DIR

    sc = scenario_from_mapping({
        "name": "all", "vehicle": "caltech_vtol", "duration_s": 1.0,
        "faults": [{"kind": "stuck_throttle", "start_s": 0.1, "end_s": 0.2}],
        "wind": {"gusts": [{"shape": "step", "start_s": 0.1, "duration_s": 0.2, "amplitude_mps": [1, 0, 0]}],
                 "turbulence": {"enabled": True, "w20_mps": 3.0}},
        "plant": {"mass_kg": 2.0}}, "<test>")
    roots = [sc, sc.load_vehicle(), HoldEnvConfig(scenario=sc),
             load_campaign_file(SCENARIO_DIR / "envelope.toml").config]
    seen, out = set(), []

    def walk(obj):
        if isinstance(obj, tuple):
            for item in obj:
                walk(item)
            return
        if not dataclasses.is_dataclass(obj) or id(obj) in seen:
            return
        seen.add(id(obj))
        if any("unit" in f.metadata for f in dataclasses.fields(obj)):
            out.append(obj)
        for f in dataclasses.fields(obj):
            walk(getattr(obj, f.name))
    for root in roots:
        walk(root)
    return out


def _bad_values(tp, meta):
    """Values the field's declaration refuses: below its lower bound, above its upper one, NaN."""
    origin = typing.get_origin(tp)
    if origin is typing.Union or origin is getattr(__import__("types"), "UnionType", None):
        tp = [a for a in typing.get_args(tp) if a is not type(None)][0]
        origin = typing.get_origin(tp)
    vector = origin is tuple
    inner = typing.get_args(tp)[0] if vector else tp
    while typing.get_origin(inner) is tuple:
        return []  # rows of rows: checked per row by the class (tested with the files)
    if inner not in (int, float):
        return []
    bad = []
    lo = meta.get("gt") if meta.get("gt") is not None else meta.get("ge")
    hi = meta.get("lt") if meta.get("lt") is not None else meta.get("le")
    if lo is not None:
        bad.append(lo if meta.get("gt") is not None else lo - 1)
    if hi is not None:
        bad.append(hi if meta.get("lt") is not None else hi + 1)
    if inner is float:
        bad.append(math.nan)
    if inner is int:
        bad = [int(b) for b in bad if math.isfinite(b) and abs(b) < 2**62]
    if vector:
        n = meta.get("length") or 1
        return [tuple([b] * n) for b in bad]
    return bad


def _cases():
    cases = []
    for obj in _settings_objects():
        hints = _type_hints(type(obj))
        for f in dataclasses.fields(obj):
            if f.name == "source_path" or "unit" not in f.metadata:
                continue
            for bad in _bad_values(hints[f.name], f.metadata):
                cases.append(pytest.param(obj, f.name, bad, id=f"{type(obj).__name__}.{f.name}={bad!r}"))
    return cases


def test_every_settings_class_validates_itself():
    classes = {type(o) for o in _settings_objects()}
    assert len(classes) >= 25, sorted(c.__name__ for c in classes)
    # the probe's tip and sensor check themselves in their own __post_init__ (the cases below hold them too)
    assert {c.__name__ for c in classes if not issubclass(c, Validated)} <= {"ProbeTip", "SDP33Sensor"}


@pytest.mark.parametrize("obj, name, bad", _cases())
def test_a_value_outside_a_fields_declared_range_is_refused_when_built_in_python(obj, name, bad):
    with pytest.raises(ConfigError) as info:
        dataclasses.replace(obj, **{name: bad})
    assert f"{name}" in str(info.value) and str(info.value).startswith(type(obj).__name__), str(info.value)


def test_simulate_refuses_a_run_of_no_tick():
    """Found by the hostile pass: duration_s below one dt_control_s raised UnboundLocalError."""
    from vtoladapt.sim.driver import simulate

    with pytest.raises(ConfigError, match="is 0 control ticks; a run needs at least 1"):
        simulate(load_scenario("gym_hold").replace(duration_s=0.001))
