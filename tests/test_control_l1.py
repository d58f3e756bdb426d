"""The L1 adaptive baseline (:mod:`vtoladapt.control.laws.l1`): its discretisation, its steady state, its faults.

What each test compares with:

* **Piecewise-constant gains and the predictor step**: the matrix formulas of Hovakimyan & Cao
  (``Phi(T) = A_s^-1 (e^{A_s T} - I)``, ``Phi(T)^-1 e^{A_s T}``) and the exact solution of the
  predictor's ODE, both from ``scipy.linalg.expm`` (an augmented matrix for the affine ODE).
* **Steady state under a model error** (closed loop, plant coefficients off the controller's):
  the uncompensated force error ``d = R Phi (theta_true - theta_0)`` computed from the log's
  trim and the regressor, not by the controller. The baseline (PD, theta_0 held) settles at
  ``v~ = d / K_v``; the piecewise-constant estimate settles at ``sigma-hat = e^{-a_s T} d`` (one
  tick of the predictor's error decays before it is measured), so l1 settles at
  ``v~ = (1 - e^{-a_s T}) d / K_v``, checked for two predictor poles.
* **Faults, dt changes, saturation, start-up**: the law's own state after synthetic ticks.
* The exact-model hold at 0, 4 and 9 m/s and the probe dropouts run l1 in
  ``tests/test_closed_loop_sim.py`` (every registered controller is parametrised there).
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.linalg import expm

import vtoladapt
from vtoladapt import forces
from vtoladapt import layout as L
from vtoladapt.config import ConfigError
from control_helpers import columns, new_diag, step as controller_step
from vtoladapt.control import (
    Controller, ControllerConfig, Measurement, Reference, controller_arrays, controller_config_from_mapping,
)
from vtoladapt.control.blocks import FAULT_ADAPTATION, FAULT_VELOCITY, P_ACC_MAX
from vtoladapt.control.laws import l1
from vtoladapt.control.registry import CONTROLLERS, law_key, law_of_key
from vtoladapt.frames import GRAVITY_MPS2, quat_to_rotmat
from vtoladapt.sim.scenario import scenario_from_mapping
from vtoladapt.sim.driver import simulate
from vtoladapt.wind import FAN_MAX_SPEED_MPS

COL = columns(controller_arrays(vtoladapt.load_vehicle("caltech_vtol"), ControllerConfig(kind="l1"))[0])
"""The L1 controller's diagnostics columns (its own: ``l1_adaptive_term_*``)."""
DT_S = 0.004


def _field(state, name):
    o = l1.S_LAW + l1.STATE.offset(name)
    return state[o:o + l1.STATE.field(name).size]


def _hover_meas(v_W=(0.0, 0.0, 0.0)):
    m = np.zeros(L.MEAS_SIZE)
    m[L.MEAS_P_W:L.MEAS_P_W + 3] = (0.0, 0.0, -1.5)
    m[L.MEAS_V_W:L.MEAS_V_W + 3] = v_W
    m[L.MEAS_Q_WB] = 1.0
    m[L.MEAS_ACCEL_B:L.MEAS_ACCEL_B + 3] = (0.0, 0.0, -GRAVITY_MPS2)
    m[L.MEAS_V_I_VALID] = 1.0
    return m


def _arrays(caltech, **settings):
    return controller_arrays(caltech, ControllerConfig(kind="l1", l1=l1.L1Settings(**settings)))


# ==================================================================================================
# 1. The discretisation against scipy
# ==================================================================================================

@given(a_s=st.floats(0.05, 100.0), dt=st.floats(1e-4, 0.1))
def test_piecewise_constant_gains_are_the_matrix_formulas(a_s, dt):
    """``e^{A_s T}`` and ``Phi(T) = A_s^-1 (e^{A_s T} - I)`` for ``A_s = -a_s I`` (3x3), from expm."""
    A = -a_s * np.eye(3)
    E = expm(A * dt)
    Phi = np.linalg.solve(A, E - np.eye(3))
    gain = np.linalg.solve(Phi, E)                      # sigma-hat = -gain x~
    decay, phi = l1.piecewise_constant_gains(a_s, dt)
    np.testing.assert_allclose(decay * np.eye(3), E, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(phi * np.eye(3), Phi, rtol=1e-10, atol=1e-300)
    np.testing.assert_allclose(decay / phi * np.eye(3), gain, rtol=1e-10, atol=1e-300)


@given(a_s=st.floats(0.05, 100.0), dt=st.floats(1e-4, 0.1), x0=st.floats(-50.0, 50.0),
       v=st.floats(-50.0, 50.0), c=st.floats(-100.0, 100.0))
def test_predictor_step_is_the_exact_solution_for_constant_inputs(a_s, dt, x0, v, c):
    """``x' = -a_s (x - v) + c`` over one tick, from expm of ``[x, 1]' = [[-a_s, a_s v + c], [0, 0]] [x, 1]``."""
    M = np.array([[-a_s, a_s * v + c], [0.0, 0.0]])
    exact = (expm(M * dt) @ np.array([x0, 1.0]))[0]
    decay, phi = l1.piecewise_constant_gains(a_s, dt)
    got = l1.predictor_step(x0, v, c, decay, phi)
    assert got == pytest.approx(exact, rel=1e-9, abs=1e-9 * (abs(x0) + abs(v) + abs(c) * dt))


# ==================================================================================================
# 2. Closed loop: the steady state under a model error
# ==================================================================================================

DURATION_S = 20.0
SETTLED_FROM_S = 15.0
WIND_MPS = 9.0
UNMODELLED_OFF = {"stall": False, "side_force": False, "pusher_advance_ratio_loss": False,
                  "rotor_reaction_torque": False, "aero_rate_damping": False}
IDEAL_SENSORS = {name: {"ideal": True} for name in ("imu", "mocap", "attitude", "probe")}
MODEL_ERRORS = {"CTx_30pct_low": {"CTx": 0.7 * 3.02e-3}, "CD0_doubled": {"CD0": 2.0 * 0.1551}}


def _run(name, controller, coefficients):
    thr = 100.0 * WIND_MPS / FAN_MAX_SPEED_MPS
    data = {"name": name, "vehicle": "caltech_vtol", "duration_s": DURATION_S, "seed": 1,
            "wind": {"fan_array": {"schedule": [[0.0, thr], [DURATION_S, thr]]}},
            "plant": dict(UNMODELLED_OFF, coefficients=coefficients), "sensors": IDEAL_SENSORS,
            "controller": controller}
    return simulate(scenario_from_mapping(data, f"tests/test_control_l1.py::{name}"))


def _force_error_W(r, vehicle) -> np.ndarray:
    """``d = R Phi (theta_true - theta_0)`` (m/s^2 NED) at the settled trim, from the log and the regressor."""
    s = np.flatnonzero(r.time_s >= SETTLED_FROM_S)
    d_theta = np.array(r.metadata["theta_true_scaled"]) - vehicle.theta_scaled
    v_i = r.columns_like(("v_i_x_mps", "v_i_y_mps", "v_i_z_mps"))
    q = r.columns_like(("q_w", "q_x", "q_y", "q_z"))
    out = []
    for k in s[::50]:
        Phi = np.empty((3, 8))
        forces.regressor(np.ascontiguousarray(v_i[k]), r["cmd_u_x_frac"][k], r["cmd_u_z_frac"][k],
                         vehicle.model_kernel, Phi)
        out.append(quat_to_rotmat(np.ascontiguousarray(q[k])) @ Phi @ d_theta)
    return np.mean(out, axis=0)


@pytest.mark.parametrize("error", list(MODEL_ERRORS))
def test_l1_removes_all_but_one_tick_of_a_model_error(caltech, error):
    """At 9 m/s with a model error, l1's steady v~ is ``(1 - e^{-a_s T})`` times the baseline's ``d / K_v``.

    Measured (CTx 30 % low / CD0 doubled), steady v~_N in m/s: PD -0.552 / -0.561 (= d_N / K_v
    within 0.1 %), l1 (a_s = 10 /s) -0.0217 / -0.0220, l1 (a_s = 25 /s) ~2.4x that.
    """
    coeffs = MODEL_ERRORS[error]
    K_v = np.array(ControllerConfig().K_v)
    pd = _run(f"pd_{error}", {"kind": "pd"}, coeffs)
    settled = pd.time_s >= SETTLED_FROM_S
    d_W = _force_error_W(pd, caltech)
    v_pd = pd.velocity_error_W[settled].mean(axis=0)
    assert abs(d_W[0]) > 0.5                                     # a real model error along north
    np.testing.assert_allclose(v_pd[0], d_W[0] / K_v[0], rtol=0.03)
    for a_s in (10.0, 25.0):
        r = _run(f"l1_{error}_{a_s:g}", {"kind": "l1", "l1": {"predictor_pole_radps": a_s}}, coeffs)
        v_l1 = r.velocity_error_W[settled]
        assert np.all(np.isfinite(v_l1))
        residual = 1.0 - np.exp(-a_s * DT_S)
        d_l1 = _force_error_W(r, caltech)
        np.testing.assert_allclose(v_l1.mean(axis=0)[0], residual * d_l1[0] / K_v[0], rtol=0.1)
        # settled, not oscillating, and far below the baseline
        assert np.ptp(v_l1[:, 0]) < 0.1 * abs(v_pd[0])
        assert np.abs(v_l1).max() < 0.1 * np.abs(pd.velocity_error_W[settled]).max()


def test_l1_with_its_filter_closed_is_the_baseline(caltech):
    """``omega_c`` -> 0 leaves eq:f_ctrl with theta_0: the same steady error as the independent PD code."""
    coeffs = MODEL_ERRORS["CTx_30pct_low"]
    off = _run("l1_off", {"kind": "l1", "l1": {"cutoff_radps": 1e-9}}, coeffs)
    pd = _run("pd_ref", {"kind": "pd"}, coeffs)
    s = pd.time_s >= SETTLED_FROM_S
    np.testing.assert_allclose(off.velocity_error_W[s].mean(axis=0), pd.velocity_error_W[s].mean(axis=0),
                               rtol=1e-3, atol=1e-5)


# ==================================================================================================
# 3. Start-up, faults, dt changes, saturation
# ==================================================================================================

def test_start_up_seats_the_predictor_on_the_measurement(caltech):
    params, state = _arrays(caltech)
    cmd = np.zeros(L.CMD_SIZE)
    diag = new_diag(params)
    v = (0.3, -0.2, 0.1)
    controller_step(params, state, _hover_meas(v), L.pack_reference((0.0, 0.0, -1.5)), DT_S, cmd, diag)
    np.testing.assert_array_equal(_field(state, "V_HAT"), v)
    np.testing.assert_array_equal(_field(state, "SIGMA_HAT"), 0.0)
    np.testing.assert_array_equal(_field(state, "SIGMA_LPF"), 0.0)
    assert _field(state, "RUNNING")[0] == 1.0
    assert np.all(np.isfinite(cmd))


def _accelerating(params, state, n, accel_N, v0=0.0, dt=DT_S):
    """``n`` ticks of a hover whose measured north velocity grows by ``accel_N dt`` per tick."""
    cmd = np.zeros(L.CMD_SIZE)
    diag = new_diag(params)
    ref = L.pack_reference((0.0, 0.0, -1.5))
    for k in range(n):
        controller_step(params, state, _hover_meas((v0 + accel_N * dt * k, 0.0, 0.0)), ref, dt, cmd, diag)
    return cmd, diag


def test_unexplained_acceleration_is_estimated_and_compensated(caltech):
    """Level hover, measured north velocity ramping at 0.5 m/s^2 that the model's force does not explain.

    With the measured velocity ``v_k = v_0 + a k T`` and a steady model force ``f`` the
    piecewise-constant law settles at ``sigma-hat = e^{-a_s T} (a T / Phi(T) - f)``: the
    predictor holds ``v`` over the tick while the truth ramps (``T / Phi(T) = 1.02`` at
    ``a_s T = 0.04``), and one tick of its error decays before it is measured (``e^{-a_s T}``).
    """
    params, state = _arrays(caltech)
    cmd, diag = _accelerating(params, state, 1500, 0.5)     # 6 s = 15 filter time constants
    decay, phi = l1.piecewise_constant_gains(l1.L1Settings().predictor_pole_radps, DT_S)
    f_model_N = _field(state, "F_PREV")[0]
    assert abs(f_model_N) < 0.05
    expected = decay * (0.5 * DT_S / phi - f_model_N)
    assert _field(state, "SIGMA_HAT")[0] == pytest.approx(expected, rel=1e-6)
    assert _field(state, "SIGMA_LPF")[0] == pytest.approx(_field(state, "SIGMA_HAT")[0], rel=1e-3)
    # the command leans against it: integrator column = -sigma_lpf
    assert diag[COL["l1_adaptive_term_N_mps2"]] == -_field(state, "SIGMA_LPF")[0]


def test_saturation_limits_the_adaptive_term(caltech):
    params, state = _arrays(caltech, adaptive_term_max_mps2=2.0)
    cmd, diag = _accelerating(params, state, 500, 40.0)
    assert np.linalg.norm(_field(state, "SIGMA_HAT")) <= params[P_ACC_MAX] * (1 + 1e-12)
    assert np.linalg.norm(_field(state, "SIGMA_LPF")) == pytest.approx(2.0, rel=1e-12)
    assert np.all(np.isfinite(cmd)) and np.all(np.isfinite(diag))


def test_velocity_fault_freezes_bleeds_and_reseats(caltech):
    """NaN velocity: the front end holds the last value; sigma-hat is frozen and bled, then the predictor re-seats."""
    params, state = _arrays(caltech, fault_bleed_s=0.5)
    _accelerating(params, state, 600, 0.5)
    sigma0 = _field(state, "SIGMA_HAT").copy()
    assert sigma0[0] > 0.3
    cmd = np.zeros(L.CMD_SIZE)
    diag = new_diag(params)
    ref = L.pack_reference((0.0, 0.0, -1.5))
    bad = _hover_meas((np.nan, 0.0, 0.0))
    n = 100
    for _ in range(n):
        controller_step(params, state, bad, ref, DT_S, cmd, diag)
        assert np.all(np.isfinite(cmd)) and np.all(np.isfinite(diag))
        assert int(diag[COL["fault_flags"]]) & FAULT_VELOCITY
    assert _field(state, "RUNNING")[0] == 0.0
    np.testing.assert_allclose(_field(state, "SIGMA_HAT"), sigma0 * np.exp(-n * DT_S / 0.5), rtol=1e-9)
    v_new = (0.1, 0.02, -0.03)
    controller_step(params, state, _hover_meas(v_new), ref, DT_S, cmd, diag)
    np.testing.assert_array_equal(_field(state, "V_HAT"), v_new)   # seated on the fresh sample
    assert _field(state, "RUNNING")[0] == 1.0
    np.testing.assert_allclose(_field(state, "SIGMA_HAT"), sigma0 * np.exp(-n * DT_S / 0.5), rtol=1e-9)


def _sample_and_hold_hover(params, state, source_hz, accel_N, duration_s=20.0, noise_mps=0.0, seed=7):
    """A hover at 250 Hz whose velocity comes from a ``source_hz`` sample-and-hold source (motion
    capture slower than the loop, a replayed log): north velocity ramping at ``accel_N`` plus
    white noise per source sample. Returns, per tick, ``(RUNNING, fault_flags, sigma_lpf_N)``."""
    rng = np.random.default_rng(seed)
    cmd = np.zeros(L.CMD_SIZE)
    diag = new_diag(params)
    ref = L.pack_reference((0.0, 0.0, -1.5))
    n = int(round(duration_s / DT_S))
    out = np.empty((n, 3))
    sample_k = -1
    v_N = 0.0
    for k in range(n):
        t = k * DT_S
        kk = int(np.floor(t * source_hz + 1e-9))       # the source's latest sample at this tick
        if kk != sample_k:
            sample_k = kk
            v_N = accel_N * kk / source_hz + noise_mps * rng.normal()
        controller_step(params, state, _hover_meas((v_N, 0.0, 0.0)), ref, DT_S, cmd, diag)
        out[k] = (_field(state, "RUNNING")[0], diag[COL["fault_flags"]], _field(state, "SIGMA_LPF")[0])
    return out


def test_sample_and_hold_motion_capture_is_not_a_sensor_fault(caltech):
    """A 100 Hz motion capture held between its samples (a 250 Hz loop sees each sample 2-3 times)
    over a 20 s hold: l1 never takes the repeated samples for a fault, and its compensation is the
    full-rate source's.

    Before: a velocity equal to the last tick's counted as a held (faulty) one, so the predictor was
    re-seated on every fresh sample and the estimate only bled: RUNNING fell to 0 on 60 % of the ticks
    and sigma_lpf stayed near 0 against a 0.5 m/s^2 unexplained acceleration.
    """
    accel = 0.5
    params, state = _arrays(caltech)
    held = _sample_and_hold_hover(params, state, 100.0, accel, noise_mps=0.002)
    assert np.all(held[1:, 0] == 1.0)                              # never re-seated, never frozen
    assert not np.any(held[:, 1].astype(int) & FAULT_VELOCITY)
    params, state = _arrays(caltech)
    full = _sample_and_hold_hover(params, state, 250.0, accel)
    late = slice(int(10.0 / DT_S), None)                           # 10 s = 25 filter time constants
    # the unexplained acceleration is compensated as from the full-rate source (the piecewise-
    # constant estimate sees the staircase's mean slope; its ripple is filtered by C(s))
    assert full[late, 2].mean() > 0.9 * accel
    assert held[late, 2].mean() == pytest.approx(full[late, 2].mean(), rel=0.02)


def test_nan_everything_gives_finite_commands(caltech):
    params, state = _arrays(caltech)
    _accelerating(params, state, 50, 0.5)
    cmd = np.zeros(L.CMD_SIZE)
    diag = new_diag(params)
    for dt in (np.nan, DT_S, -1.0, DT_S):
        controller_step(params, state, np.full(L.MEAS_SIZE, np.nan), np.full(L.REF_SIZE, np.nan), dt, cmd, diag)
        assert np.all(np.isfinite(cmd)) and np.all(np.isfinite(diag))
        assert np.all(np.isfinite(state))


def test_corrupted_memory_restarts_the_law_and_is_flagged(caltech):
    """A non-finite value in the law's memory (not reachable from sanitised inputs) restarts it, flagged."""
    params, state = _arrays(caltech)
    _accelerating(params, state, 50, 0.5)
    _field(state, "V_HAT")[1] = np.nan
    cmd = np.zeros(L.CMD_SIZE)
    diag = new_diag(params)
    v = (0.7, 0.0, 0.0)
    controller_step(params, state, _hover_meas(v), L.pack_reference((0.0, 0.0, -1.5)), DT_S, cmd, diag)
    assert int(diag[COL["fault_flags"]]) & FAULT_ADAPTATION
    np.testing.assert_array_equal(_field(state, "V_HAT"), v)
    np.testing.assert_array_equal(_field(state, "SIGMA_LPF"), 0.0)
    assert np.all(np.isfinite(state)) and np.all(np.isfinite(cmd))


def test_gains_follow_dt(caltech):
    s = l1.L1Settings()
    params, state = _arrays(caltech)
    for dt in (0.004, 0.002, 0.01):
        _accelerating(params, state, 3, 0.5, dt=dt)
        decay, phi = l1.piecewise_constant_gains(s.predictor_pole_radps, dt)
        np.testing.assert_allclose(_field(state, "GAINS"),
                                   (decay, decay / phi, 1.0 - np.exp(-s.cutoff_radps * dt),
                                    np.exp(-dt / s.fault_bleed_s)), rtol=1e-12)


# ==================================================================================================
# 4. Registry, configuration, step API
# ==================================================================================================

def test_registry_and_configuration_accept_l1():
    info = CONTROLLERS["l1"]
    assert (info.label, info.colour, info.adaptive, info.composite) == ("L1 adaptive", "C6", True, False)
    assert info.law is l1 and law_of_key(law_key("l1")) is CONTROLLERS["l1"]
    cfg = controller_config_from_mapping({"kind": "l1", "l1": {"cutoff_radps": 3.0, "predictor_pole_radps": 8.0}})
    assert cfg.kind == "l1" and cfg.law_settings == l1.L1Settings(cutoff_radps=3.0, predictor_pole_radps=8.0)
    with pytest.raises(ConfigError, match="cutoff_radps"):
        controller_config_from_mapping({"kind": "l1", "l1": {"cutoff_radps": -1.0}})
    with pytest.raises(ConfigError, match="l1"):
        controller_config_from_mapping({"kind": "l1", "l1": {"no_such_gain": 1.0}})


def test_predictor_pole_too_fast_for_the_tick_is_refused(caltech):
    with pytest.raises(ValueError, match="predictor_pole_radps"):
        _arrays(caltech, predictor_pole_radps=200.0)            # a_s dt = 0.8


def test_step_api_runs_l1_exactly_like_the_kernel(caltech, rng):
    cfg = ControllerConfig(kind="l1")
    ctrl = Controller(caltech, cfg)
    params, state = controller_arrays(caltech, cfg)
    ref = Reference.hold((0.0, 0.0, -1.5))
    cmd = np.zeros(L.CMD_SIZE)
    diag = new_diag(params)
    for k in range(200):
        m = Measurement.from_parts(p_W=(0.0, 0.0, -1.5), v_W=(0.2 + 0.01 * rng.normal(), 0.0, 0.0),
                                   q_WB=(1.0, 0.0, 0.0, 0.0), omega_B=(0.0, 0.0, 0.0),
                                   accel_B=(0.0, 0.0, -GRAVITY_MPS2), v_i_B=(0.0, 0.0, 0.0))
        out = ctrl.step(DT_S * k, m, ref)
        dt = DT_S if k == 0 else DT_S * k - DT_S * (k - 1)
        controller_step(params, state, m.array, ref.array, dt, cmd, diag)
        assert np.array_equal(out.array, cmd)
    assert np.array_equal(ctrl.state.array, state)
    np.testing.assert_array_equal(ctrl.state.law_field("SIGMA_LPF"), _field(state, "SIGMA_LPF"))
    assert np.any(_field(state, "SIGMA_LPF") != 0.0)
