"""The control allocator: feasible demands met exactly, infeasible ones the same weighted bounded
least-squares solution as scipy.optimize.lsq_linear, yaw given up first, the mixer's entry points."""
import math

import numpy as np
import pytest
from scipy.optimize import lsq_linear

import vtoladapt
from vtoladapt import layout
from vtoladapt.sim.allocation import (AL_TOTAL_UNIT, ALLOC_REPORT, ALLOC_REPORT_OFFSET, ALLOC_WORK_SIZE, N_ALLOC, N_OUT,
                                      allocate, allocation_problem, allocator_params)
from vtoladapt.sim.mixer import applied_collective, mixer_params, motor_commands


@pytest.fixture(scope="module", params=["caltech_vtol", "px4_standard_vtol"])
def veh(request):
    return vtoladapt.load_vehicle(request.param)


def _meas(veh, qbar):
    meas = np.zeros(layout.MEAS_SIZE)
    meas[layout.MEAS_Q_WB] = 1.0
    meas[layout.MEAS_V_I_B] = math.sqrt(2.0 * qbar / veh.envelope.air_density_kgpm3)
    meas[layout.MEAS_V_I_VALID] = 1.0
    return meas


def _run(veh, p, y, qbar):
    """Allocate the demand ``y = [T, tau]``: (actuators in physical units, achieved, saturated)."""
    total = p[AL_TOTAL_UNIT]
    cmd = np.zeros(layout.CMD_SIZE)
    cmd[layout.CMD_U_Z] = math.sqrt(max(y[0], 0.0) / total)
    cmd[layout.CMD_TAU_B:layout.CMD_TAU_B + 3] = y[1:]
    out = np.zeros(layout.N_ACTUATORS)
    w = np.zeros(ALLOC_WORK_SIZE)
    sat = allocate(cmd, _meas(veh, qbar), p, out, w, 0)
    t_unit = total / 4
    a = np.r_[t_unit * out[:4] ** 2, out[layout.ACT_SURFACE:layout.ACT_SURFACE + layout.N_SURFACES]]
    rep = w[ALLOC_REPORT_OFFSET:ALLOC_REPORT_OFFSET + ALLOC_REPORT.size]
    return a, rep[ALLOC_REPORT.slice("ACHIEVED")], rep[ALLOC_REPORT.slice("ASKED")], bool(sat)


@pytest.mark.parametrize("qbar", [0.0, 40.0, 150.0])
def test_feasible_demands_are_met_exactly(veh, qbar):
    """Random actuators inside their bounds make a demand that can be met: it is, to 1e-6 of each output's
    scale, and the actuators stay inside their bounds."""
    p = allocator_params(veh)
    rng = np.random.default_rng(1)
    prob = allocation_problem(p, [1.0, 0, 0, 0], qbar)
    scale = 1.0 / prob["row_weight"]
    for _ in range(200):
        a0 = rng.uniform(prob["lower"], prob["upper"])
        y = prob["B"] @ a0
        a, achieved, asked, sat = _run(veh, p, y, qbar)
        np.testing.assert_allclose(asked, y, rtol=1e-12, atol=1e-12)
        assert not sat
        np.testing.assert_array_less(np.abs(achieved - y), 1e-6 * np.maximum(scale, 1.0))
        np.testing.assert_allclose(prob["B"] @ a, achieved, rtol=1e-9, atol=1e-9)
        assert np.all(a >= prob["lower"] - 1e-9) and np.all(a <= prob["upper"] + 1e-9)


def _reference(prob, y):
    """The allocator's stages (module docstring of vtoladapt.sim.allocation) solved by scipy's lsq_linear."""
    fixed = prob["lower"] == prob["upper"]  # an actuator the airframe lacks: lsq_linear needs lo < hi
    B, rw, cw, eps = prob["B"], prob["row_weight"], prob["col_weight"], prob["eps"]

    def solve(weights, target):
        A = np.vstack([(weights * rw)[:, None] * B, math.sqrt(eps) * np.diag(cw)])
        b = np.r_[weights * rw * target, math.sqrt(eps) * cw * prob["preferred"]]
        x = prob["lower"].copy()
        res = lsq_linear(A[:, ~fixed], b - A[:, fixed] @ x[fixed], bounds=(prob["lower"][~fixed],
                         prob["upper"][~fixed]), method="bvls", tol=1e-15, lsmr_tol="auto")
        x[~fixed] = res.x
        return x

    a = solve(np.ones(4), y)
    if np.max(np.abs(rw * (B @ a - y))) <= 1e-6:
        return a, False
    a2 = solve(np.array([1.0, 1.0, 1.0, 0.0]), y)
    H = prob["hold_weight"]
    return solve(np.array([1.0, 1.0, 1.0, 1.0 / H]), np.r_[(B @ a2)[:3], y[3]]), True


@pytest.mark.parametrize("qbar", [0.0, 60.0, 200.0])
def test_infeasible_demands_match_lsq_linear(veh, qbar):
    """Demands up to three times the airframe's authority: the allocator's actuators are those of the same
    weighted bounded least squares solved by scipy.optimize.lsq_linear (its three stages), to 1e-5 of each
    actuator's range."""
    p = allocator_params(veh)
    rng = np.random.default_rng(2)
    n_sat = 0
    for _ in range(150):
        probe = allocation_problem(p, [1.0, 0, 0, 0], qbar)
        a0 = rng.uniform(probe["lower"], probe["upper"])
        y = probe["B"] @ a0 * np.r_[rng.uniform(0.3, 1.0), rng.uniform(-3.0, 3.0, 3)]
        prob = allocation_problem(p, y, qbar)
        a, achieved, _asked, sat = _run(veh, p, y, qbar)
        ref, ref_sat = _reference(prob, y)
        assert sat == ref_sat
        n_sat += sat
        rng_col = 1.0 / prob["col_weight"]
        np.testing.assert_allclose(a / rng_col, ref / rng_col, atol=1e-5)
        np.testing.assert_allclose(achieved * prob["row_weight"], prob["B"] @ ref * prob["row_weight"], atol=1e-5)
    assert n_sat > 50  # the check is mostly of saturated demands


def test_yaw_gives_way_first(veh):
    """A yaw demand far beyond authority with a modest roll and pitch: roll, pitch and lift are kept within
    2 % of their asked values, yaw is what is not met."""
    p = allocator_params(veh)
    prob = allocation_problem(p, [1.0, 0, 0, 0], 0.0)
    t_total = prob["upper"][:4].sum() * 0.5
    y = np.array([t_total, 0.1 * prob["B"][1, 0] * prob["upper"][0], 0.1 * prob["B"][2, 0] * prob["upper"][0],
                  50.0])
    _a, achieved, asked, sat = _run(veh, p, y, 0.0)
    assert sat
    np.testing.assert_allclose(achieved[:3], asked[:3], rtol=0.02)
    assert achieved[3] < 0.5 * asked[3]


def test_surfaces_take_moments_at_speed_and_none_in_hover():
    veh = vtoladapt.load_vehicle("px4_standard_vtol")
    p = allocator_params(veh)
    y = np.array([30.0, 2.0, 1.0, 0.0])
    a_hover, *_ = _run(veh, p, y, 0.0)
    a_fast, *_ = _run(veh, p, y, 150.0)
    assert np.all(a_hover[4:] == 0.0)
    assert np.abs(a_fast[4:]).max() > 0.05
    # the rotors' differential thrust falls when the surfaces help
    assert np.ptp(a_fast[:4]) < 0.7 * np.ptp(a_hover[:4])
    # surfaces off: they stay neutral at any airspeed
    a_off, *_ = _run(veh, allocator_params(veh, surfaces=False), y, 150.0)
    assert np.all(a_off[4:] == 0.0)


def test_an_invalid_airflow_reading_leaves_the_surfaces_neutral():
    veh = vtoladapt.load_vehicle("px4_standard_vtol")
    cmd = np.array([0.0, 0.6, 2.0, 1.0, 0.0])
    meas = _meas(veh, 150.0)
    meas[layout.MEAS_V_I_VALID] = 0.0
    out, _sat = motor_commands(cmd, veh, meas)
    assert np.all(out[layout.ACT_SURFACE:] == 0.0)
    meas[layout.MEAS_V_I_VALID] = 1.0
    meas[layout.MEAS_V_I_B] = np.nan
    out, _sat = motor_commands(cmd, veh, meas)
    assert np.all(out[layout.ACT_SURFACE:] == 0.0) and np.all(np.isfinite(out))


def test_non_finite_commands_never_reach_the_actuators(veh):
    out, _ = motor_commands(np.zeros(layout.CMD_SIZE), veh)
    w = np.zeros(ALLOC_WORK_SIZE)
    allocate(np.full(layout.CMD_SIZE, np.nan), _meas(veh, 50.0), mixer_params(veh), out, w, 0)
    assert np.all(np.isfinite(out)) and np.all(out == 0.0)


def test_the_applied_collective_is_reported_when_saturated(veh):
    """A roll demand at high collective: lift is shared with roll, the rotors' collective falls, and that is
    what the controller is told (report_mixed), not what it asked."""
    from vtoladapt.control.api import Controller
    from vtoladapt.control.step import controller_initial_state, state_last_command
    from vtoladapt.sim.loop import report_mixed

    out, sat, rep = motor_commands(np.array([0.3, 0.97, 50.0, 0.0, 0.0]), veh, report=True)
    assert sat and rep["achieved"][1] < rep["asked"][1]
    u_eff = applied_collective(out)
    assert u_eff < 0.97 - 0.01
    state = controller_initial_state(Controller(veh).params)
    report_mixed(state, out, sat)
    np.testing.assert_array_equal(state_last_command(state), [out[layout.MOTOR_PUSHER], u_eff])
    # unsaturated: the controller's own record stands
    out, sat = motor_commands(np.array([0.2, 0.6, 0.01, 0.0, 0.0]), veh)
    assert not sat
    assert applied_collective(out) == pytest.approx(0.6, rel=1e-6)


def test_the_effectiveness_kind_takes_a_users_airframe(veh):
    """A user's airframe is a module with effectiveness(vehicle), registered like the other kinds."""
    import sys
    import types

    from vtoladapt.components import registry
    from vtoladapt.sim.allocation import EffectivenessInfo
    from vtoladapt.sim.effectiveness import effectiveness as package_effectiveness

    mod = types.ModuleType("user_airframe_no_surfaces")

    def effectiveness(vehicle):
        e = package_effectiveness(vehicle)
        B_per_Pa = np.zeros_like(e.B_per_Pa)
        return type(e)(e.B0, B_per_Pa, e.lower, e.upper, e.preferred_share, e.t_unit_N, e.throttle_max)

    mod.effectiveness = effectiveness
    sys.modules[mod.__name__] = mod
    reg = registry("effectiveness")
    reg.register(EffectivenessInfo("user_no_surfaces", "rotors only", mod.__name__))
    try:
        p = allocator_params(veh, effectiveness_id="user_no_surfaces")
        a, *_ = _run(veh, p, np.array([30.0, 1.0, 0.5, 0.0]), 150.0)
        assert np.all(a[4:] == 0.0)
    finally:
        reg.unregister("user_no_surfaces")
        del sys.modules[mod.__name__]
    assert N_OUT == 4 and N_ALLOC == 8


def test_in_the_closed_loop_the_surfaces_fly_at_speed_and_stay_neutral_when_off():
    """PX4 holding in a 70 % fan wind (9 m/s): with surfaces the servos move and the allocator's report
    says what it met; with [allocation] surfaces = false every surface stays at zero and the rotors take
    the moments. Whenever the allocator did not saturate, it achieved what it was asked."""
    from dataclasses import replace

    from vtoladapt.sim.driver import simulate
    from vtoladapt.sim.scenario import scenario_from_mapping

    sc = scenario_from_mapping({
        "name": "alloc_loop", "vehicle": "px4_standard_vtol", "duration_s": 12.0, "seed": 4,
        "wind": {"fan_array": {"schedule": [[0, 0], [1, 0], [4, 70], [12, 70]]}},
        "controller": {"kind": "composite"}}, "alloc_loop")
    on = simulate(sc)
    off = simulate(replace(sc, allocation=replace(sc.allocation, surfaces=False)))
    late = on.time_s > 6.0
    assert np.abs(on["surface3_cmd_rad"][late]).max() > 0.01 and np.abs(on["surface1_rad"][late]).max() > 1e-3
    for name in ("surface1_cmd_rad", "surface2_cmd_rad", "surface3_cmd_rad", "surface1_rad", "surface3_rad"):
        assert np.all(off[name] == 0.0), name
    for res in (on, off):
        ok = res["mixer_saturated"] == 0.0
        for ax in ("T_N", "tau_x_Nm", "tau_y_Nm", "tau_z_Nm"):
            np.testing.assert_allclose(res[f"alloc_achieved_{ax}"][ok], res[f"alloc_asked_{ax}"][ok], atol=1e-4)
    assert on["alloc_qbar_Pa"][late].mean() > 30.0 and np.all(off["alloc_qbar_Pa"] >= 0.0)
    # the rotors' share of roll and pitch falls when the surfaces help: their roll and pitch moments by the
    # vehicle file's geometry (-sum y_i T_i, sum x_i T_i with T_i = T_unit u_i^2)
    veh = sc.load_vehicle()
    xy = np.array(veh.geometry.lift_rotor_positions_m)
    t_unit = veh.mass.mass_kg * veh.theta_scaled[1] / 4

    def rotor_roll_pitch(r):
        T = t_unit * np.stack([r[f"motor{i}_cmd_frac"] for i in range(1, 5)], 1)[late] ** 2
        return np.hypot(-(T * xy[:, 1]).sum(1), (T * xy[:, 0]).sum(1)).mean()

    assert rotor_roll_pitch(on) < 0.8 * rotor_roll_pitch(off)  # measured 0.33 against 0.45 N m (0.72)


def test_the_readme_airframe_example_runs_as_written():
    """README "The airframe": its first python block is run as written (its assert included); the second
    registers a module of the user's and says it is not run."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    section = text.split("## The airframe: control surfaces, the allocator, the truth drawn\n", 1)[1].split("\n## ", 1)[0]
    blocks = [b.split("```", 1)[0] for b in section.split("```python\n")[1:]]
    assert len(blocks) == 2 and "my_package" in blocks[1] and "not run here" in section
    exec(compile(blocks[0], "README.md (The airframe)", "exec"), {})
