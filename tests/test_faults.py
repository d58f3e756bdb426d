"""Faults in the closed loop: every shipped fault scenario flown, and the injection kernels alone.

Per fault (scenarios/faults/<kind>.toml, fault from 8 s): no non-finite value in the log outside
the measurement slots the fault itself corrupts, the position error within the bound stated
below, theta-hat inside its bounds, and adaptation active again once the fault is over. The
bounds were measured (seed 3) and set with about 50 % margin; two faults physics cannot ride
through in hover (the pusher at full throttle, a lift motor stuck) are held instead to the log
naming the limit they hit (the allocator saturated) and to recovering after the fault. The surface
faults (a surface stuck, lost, a servo slowed) fly at 80 % fan wind, where the surfaces carry moments.
"""
from __future__ import annotations

import numpy as np
import pytest

from vtoladapt.config import ConfigError
from vtoladapt.sim.faults import (FAULT_KINDS, FAULT_STATE, FaultConfig, apply_actuator_faults,
                              apply_measurement_faults, fault_table, faults_to_kernel)
from vtoladapt import layout
from vtoladapt.layout import MEAS_P_W, MEAS_SIZE, MEAS_V_I_B, MEAS_V_I_VALID, N_MOTORS, PLANT_INPUT_SIZE
from vtoladapt.sim.scenario import load_scenario, scenario_from_mapping
from vtoladapt.sim.driver import controller_prior, simulate_many

FAULT_START_S = 8.0
# worst position error (m) over the whole run: measured, then ~1.5x; see README fault table
POSITION_ERROR_BOUND_M = {
    "probe_dropout": 0.5, "probe_stuck": 0.35, "probe_nan": 0.5, "probe_blocked_port": 2.75,
    "imu_spike": 0.4, "imu_nan": 1.5, "mocap_dropout": 1.3, "mocap_latency": 0.15,
    "lift_motor_loss": 0.45, "surface_stuck": 0.16, "surface_lost": 1.0, "servo_slow": 0.16,
}
# cannot be held in hover: the worst error is not the controller's to bound; after the fault the
# vehicle must head back (error falling) or be back within this
UNRECOVERABLE_FINAL_ERROR_M = {"pusher_saturated": 0.5, "stuck_throttle": 0.5}
# the measurement slots each sensor fault itself turns to NaN (recorded as the sensor gave them)
CORRUPTED_MEAS = {
    "probe_dropout": ("meas_v_i_",), "probe_nan": ("meas_v_i_",), "imu_nan": ("meas_omega_", "meas_accel_"),
    "mocap_dropout": ("meas_p_", "meas_v_N", "meas_v_E", "meas_v_D"),
}


@pytest.fixture(scope="module")
def fault_runs():
    scenarios = [load_scenario(f"faults/{k}") for k in FAULT_KINDS]
    return dict(zip(FAULT_KINDS, zip(scenarios, simulate_many(scenarios, workers=2))))


def test_every_fault_kind_has_a_scenario_and_a_verdict():
    assert set(POSITION_ERROR_BOUND_M) | set(UNRECOVERABLE_FINAL_ERROR_M) == set(FAULT_KINDS)


@pytest.mark.parametrize("kind", FAULT_KINDS)
def test_fault_run(fault_runs, kind):
    scenario, res = fault_runs[kind]
    assert not res.diverged, res.divergence_reason
    t = res.time_s
    fault = scenario.faults[0]
    assert fault.kind == kind
    in_window = (t >= fault.start_s) & (t < fault.end_s)
    # the log marks the fault's window, and only it
    assert np.array_equal(res["faults_active"] == 1.0, in_window)
    # no non-finite value anywhere, except the corrupted readings inside the window
    prefixes = CORRUPTED_MEAS.get(kind, ())
    for i, name in enumerate(res.columns):
        col = res.data[:, i]
        if name.startswith(prefixes) and prefixes:
            assert np.isfinite(col[~in_window]).all(), name
        else:
            assert np.isfinite(col).all(), name
    pe = np.linalg.norm(res.position_error_W, axis=1)
    if kind in POSITION_ERROR_BOUND_M:
        assert pe.max() < POSITION_ERROR_BOUND_M[kind]
    else:
        # physics cannot hold the point: the log says the allocator could not meet its demand for a good
        # part of the fault (it is not told of the fault, so only what its model cannot do counts: 48 % of
        # the window for the pusher, 16 % for the stuck rotor, measured)
        assert res["mixer_saturated"][in_window].mean() > 0.1
        # far off the point from the fault on (the stuck rotor's worst, 1.75 m, comes as it is released at
        # 12 s: 0.41 m inside the window since the allocator spreads the moments over the other rotors and
        # the surfaces; the saturated pusher 190 m)
        assert pe[t >= fault.start_s].max() > 1.0
        # after the fault the vehicle heads back: the error falls, steadily over the last 5 s
        assert pe[-1] < 0.5 * pe.max()
        late = t >= t[-1] - 5.0
        assert np.all(np.diff(pe[late][::25]) < 0.0) or pe[late].max() < UNRECOVERABLE_FINAL_ERROR_M[kind]
    # theta-hat inside the controller's bounds throughout
    _, _, _, lower, upper, _ = controller_prior(scenario, scenario.load_vehicle())
    th = res.theta_hat
    assert (th >= lower - 1e-12).all() and (th <= upper + 1e-12).all()
    # adaptation runs again after recovery (holdoff and filters settle within 3 s)
    after = t >= fault.end_s + 3.0
    assert res["adaptation_active"][after].mean() > 0.9
    assert res["adaptation_active"][(t > 3.0) & (t < FAULT_START_S)].mean() > 0.9


@pytest.mark.parametrize("kind", ["probe_dropout", "probe_nan", "imu_nan"])
def test_adaptation_pauses_while_its_inputs_are_bad(fault_runs, kind):
    """The front end flags the fault and theta-hat is frozen while the probe or IMU is unusable."""
    scenario, res = fault_runs[kind]
    t = res.time_s
    fault = scenario.faults[0]
    inside = (t >= fault.start_s + 0.02) & (t < fault.end_s)
    assert res["adaptation_active"][inside].max() == 0.0
    th = res.theta_hat[inside]
    assert np.all(th == th[0])


def test_fault_table_rows(fault_runs):
    rows = fault_table([res for _, res in fault_runs.values()])
    assert [r["faults"] for r in rows] == list(FAULT_KINDS)
    by = {r["faults"]: r for r in rows}
    # only the saturated pusher is still far away at the end of its run (it returns at the
    # velocity-correction limit); every other fault, the stuck rotor included, ends back on the point
    assert [k for k, r in by.items() if not r["recovered"]] == ["pusher_saturated"]
    assert by["pusher_saturated"]["saturated_during_fault"] > 0.3 and by["pusher_saturated"]["diverged"] == ""
    for kind, bound in POSITION_ERROR_BOUND_M.items():
        assert by[kind]["pos_err_worst_m"] < bound


# --- kernels alone -------------------------------------------------------------------------------

def _schedule(**kw):
    f = FaultConfig(**{"start_s": 1.0, "end_s": 2.0, **kw})
    return faults_to_kernel((f,), 0.004)


def _meas(value):
    m = np.full(MEAS_SIZE, value, dtype=float)
    m[MEAS_V_I_VALID] = 1.0
    return m


def test_probe_stuck_holds_the_reading_at_onset_then_releases():
    sched, st = _schedule(kind="probe_stuck")
    out = []
    for k, t in enumerate(np.arange(0.9, 2.1, 0.004)):
        m = _meas(float(k))
        apply_measurement_faults(sched, st, t, 0.004, m)
        out.append((t, m[MEAS_V_I_B], float(k)))
    held = [v for t, v, k in out if 1.0 <= t < 2.0]
    onset = next(k for t, v, k in out if t >= 1.0)
    assert held and all(v == onset for v in held)
    assert all(v == k for t, v, k in out if t < 1.0 or t >= 2.0)


def test_mocap_latency_delays_by_whole_ticks():
    sched, st = _schedule(kind="mocap_latency", extra_latency_s=0.02)  # 5 ticks
    for k, t in enumerate(np.arange(0.0, 1.5, 0.004)):
        m = _meas(float(k))
        apply_measurement_faults(sched, st, t, 0.004, m)
        expected = k - 5 if 1.0 <= t < 2.0 else k
        assert m[MEAS_P_W] == expected


def test_lift_motor_loss_removes_the_stated_share_of_thrust():
    sched, st = _schedule(kind="lift_motor_loss", motor=3, thrust_loss_fraction=0.3)
    u = np.zeros(PLANT_INPUT_SIZE)
    u[:N_MOTORS] = 0.6
    apply_actuator_faults(sched, st, 1.5, 1.0, u)
    thrust_ratio = (u[:N_MOTORS] / 0.6) ** 2  # rotor thrust ~ u^2 (plant.rotor_terms)
    assert thrust_ratio[2] == pytest.approx(0.7)
    assert np.all(np.delete(u[:N_MOTORS], 2) == 0.6)


def test_stuck_throttle_and_saturated_pusher():
    sched, st = faults_to_kernel((FaultConfig(kind="stuck_throttle", start_s=1.0, end_s=2.0, motor=2),
                                  FaultConfig(kind="pusher_saturated", start_s=1.0, end_s=2.0)), 0.004)
    assert st.size == FAULT_STATE.size
    for t, cmd in ((1.0, 0.4), (1.5, 0.9), (2.0, 0.9)):
        u = np.zeros(PLANT_INPUT_SIZE)
        u[:N_MOTORS] = cmd
        apply_actuator_faults(sched, st, t, 0.95, u)
        if t < 2.0:
            assert u[1] == 0.4 and u[4] == 0.95
        else:
            assert u[1] == 0.9 and u[4] == 0.9


def test_surface_faults_on_the_plant_input():
    """A stuck surface holds the deflection commanded at onset; a lost one is flagged gone; a slow servo's
    time constant is scaled; all of it cleared when the faults end (a zeroed plant input is healthy)."""
    sched, st = faults_to_kernel((FaultConfig(kind="surface_stuck", start_s=1.0, end_s=2.0, surface=2),
                                  FaultConfig(kind="surface_lost", start_s=1.0, end_s=2.0, surface=1),
                                  FaultConfig(kind="servo_slow", start_s=1.0, end_s=2.0, surface=3,
                                              time_constant_factor=4.0)), 0.004)
    s0, loss, slow = layout.ACT_SURFACE, layout.IN_SURFACE_LOSS, layout.IN_SERVO_SLOWDOWN
    for t, cmd in ((0.5, 0.05), (1.0, 0.1), (1.5, -0.2), (2.0, -0.2)):
        u = np.zeros(PLANT_INPUT_SIZE)
        u[s0:s0 + 3] = cmd
        apply_actuator_faults(sched, st, t, 1.0, u)
        if 1.0 <= t < 2.0:
            assert u[s0 + 1] == 0.1 and u[s0] == cmd and u[s0 + 2] == cmd
            assert list(u[loss:loss + 3]) == [1.0, 0.0, 0.0] and list(u[slow:slow + 3]) == [0.0, 0.0, 3.0]
        else:
            assert np.all(u[s0:s0 + 3] == cmd) and not u[loss:].any()


def test_a_surface_fault_on_a_surface_the_vehicle_lacks_is_refused():
    from vtoladapt.sim.driver import prepare

    sc = scenario_from_mapping({"name": "x", "vehicle": "caltech_vtol", "duration_s": 1.0,
                                "faults": [{"kind": "surface_lost", "start_s": 0.1, "end_s": 0.5, "surface": 4}]},
                               "bad.toml")
    with pytest.raises(ConfigError, match=r"bad.toml: \[faults\]\[0\] surface_lost: surface = 4: caltech_vtol has 3 "
                                          r"control surfaces; allowed: 1 to 3"):
        prepare(sc)


@pytest.mark.parametrize("entry, words", [
    ({"kind": "probe_dropout", "start_s": 5.0, "end_s": 4.0}, "end_s = 4: must be after start_s = 5"),
    ({"kind": "motor_on_fire", "start_s": 1.0, "end_s": 2.0}, "kind = 'motor_on_fire': unknown"),
    ({"kind": "lift_motor_loss", "start_s": 1.0, "end_s": 2.0, "motor": 5}, "lift motors are 1-4"),
    ({"kind": "imu_nan", "start_s": 1.0}, "end_s: missing required key"),
    ({"kind": "lift_motor_loss", "start_s": 1.0, "end_s": 2.0, "thrust_loss_fraction": 1.5}, "thrust_loss_fraction"),
])
def test_schedule_errors_are_one_line(entry, words):
    with pytest.raises(ConfigError) as exc:
        scenario_from_mapping({"name": "x", "vehicle": "caltech_vtol", "duration_s": 1.0, "faults": [entry]},
                              "bad.toml")
    msg = str(exc.value)
    assert "\n" not in msg and "bad.toml" in msg and words in msg


@pytest.mark.parametrize("entry, key", [
    ({"kind": "probe_nan", "motor": 2}, "motor"),
    ({"kind": "lift_motor_loss", "port": "beta"}, "port"),
    ({"kind": "imu_nan", "extra_latency_s": 0.05}, "extra_latency_s"),
])
def test_a_key_that_does_not_apply_to_the_kind_is_refused(entry, key):
    data = {"name": "f", "vehicle": "caltech_vtol", "duration_s": 1.0,
            "faults": [{"start_s": 0.1, "end_s": 0.5, **entry}]}
    with pytest.raises(ConfigError) as exc:
        scenario_from_mapping(data, "f.toml")
    message = str(exc.value)
    assert "\n" not in message and "f.toml" in message and f"{key} = " in message
    assert f"kind = {entry['kind']!r}" in message and "does not apply" in message


def test_every_kind_accepts_the_keys_it_uses():
    for kind in FAULT_KINDS:
        keys = FaultConfig.keys_for({"kind": kind})
        assert keys[:3] == ("kind", "start_s", "end_s")
        entry = {"kind": kind, "start_s": 0.1, "end_s": 0.5}
        entry.update({k: FaultConfig.__dataclass_fields__[k].default for k in keys[3:]})
        scenario_from_mapping({"name": "f", "vehicle": "caltech_vtol", "duration_s": 1.0, "faults": [entry]}, "f")
