"""The compiled step: invariants over any input (hypothesis), sensor faults, baselines' anti-windup."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import examples
from control_helpers import columns, new_diag, step
from vtoladapt import layout as L
from vtoladapt.control import ControllerConfig, controller_arrays
from vtoladapt.control.blocks import FAULT_PROBE, P_TAU_MAX, P_U_MAX
from vtoladapt.control.registry import controller_ids
from vtoladapt.control.step import state_law_field, state_P_inv, state_theta_hat
from vtoladapt.frames import GRAVITY_MPS2, quat_from_euler, quat_to_rotmat

JUNK = [np.nan, np.inf, -np.inf, 1e300, -1e300, 1e20, 0.0]
_COLS: dict = {}


def _col(diag, name, n=1):
    i = _COLS[diag.size][name]
    return diag[i] if n == 1 else diag[i:i + n]


def _diag(params):
    """A diag array for ``params``, its columns known to :func:`_col` (by length: one law per length here)."""
    diag = new_diag(params)
    _COLS[diag.size] = columns(params)
    return diag


def _hover_meas(q=(1.0, 0, 0, 0), v_i_B=(0.0, 0.0, 0.0), valid=1.0, v_W=(0.0, 0.0, 0.0)):
    m = np.zeros(L.MEAS_SIZE)
    m[L.MEAS_P_W:L.MEAS_P_W + 3] = (0.0, 0.0, -1.5)
    m[L.MEAS_V_W:L.MEAS_V_W + 3] = v_W
    m[L.MEAS_Q_WB:L.MEAS_Q_WB + 4] = q
    m[L.MEAS_ACCEL_B:L.MEAS_ACCEL_B + 3] = (0.0, 0.0, -GRAVITY_MPS2)
    m[L.MEAS_V_I_B:L.MEAS_V_I_B + 3] = v_i_B
    m[L.MEAS_V_I_VALID] = valid
    return m


def _check_invariants(params, state, cmd, diag, lower, upper, P0):
    u_max = params[P_U_MAX]
    assert np.all(np.isfinite(cmd))
    assert 0.0 <= cmd[L.CMD_U_X] <= u_max and 0.0 <= cmd[L.CMD_U_Z] <= u_max
    assert np.all(np.abs(cmd[L.CMD_TAU_B:L.CMD_TAU_B + 3]) <= params[P_TAU_MAX:P_TAU_MAX + 3])
    assert np.all(np.isfinite(diag))
    assert _col(diag, "q_tilde_0") >= 0.0
    G = state_P_inv(params, state)
    assert np.array_equal(G, G.T)
    np.linalg.cholesky(G)                                        # P^-1 (hence P) is SPD
    P = np.linalg.inv(G)
    assert np.linalg.eigvalsh(P0 - P).min() > -1e-9 * np.abs(P0).max()   # P <= P0
    th = state_theta_hat(params, state)
    assert np.all((lower <= th) & (th <= upper))


_value = st.one_of(st.floats(-60.0, 60.0), st.sampled_from(JUNK))


@st.composite
def _measurement(draw):
    m = np.array(draw(st.lists(_value, min_size=L.MEAS_SIZE, max_size=L.MEAS_SIZE)))
    if draw(st.booleans()):      # often a proper attitude, so the wing/hover logic is exercised
        m[L.MEAS_Q_WB:L.MEAS_Q_WB + 4] = quat_from_euler(*draw(st.lists(st.floats(-3.2, 3.2), min_size=3,
                                                                         max_size=3)))
    m[L.MEAS_V_I_VALID] = draw(st.sampled_from([1.0, 1.0, 0.0, 0.5, np.nan]))
    return m


@st.composite
def _reference(draw):
    r = np.array(draw(st.lists(_value, min_size=L.REF_SIZE, max_size=L.REF_SIZE)))
    return r


@pytest.mark.parametrize("kind", controller_ids())
@settings(max_examples=examples(60))
@given(data=st.data())
def test_invariants_over_any_input(caltech, kind, data):
    params, state = controller_arrays(caltech, ControllerConfig(kind=kind))
    lower, upper = params_bounds(params)
    P0 = np.diag(caltech.adaptation.P0_diag)
    cmd = np.zeros(L.CMD_SIZE)
    diag = _diag(params)
    for _ in range(data.draw(st.integers(1, 6))):
        meas = data.draw(_measurement())
        ref = data.draw(_reference())
        dt = data.draw(st.one_of(st.just(0.004), st.floats(1e-5, 0.2), st.sampled_from([0.0, -1.0, np.nan])))
        step(params, state, meas, ref, dt, cmd, diag)
        _check_invariants(params, state, cmd, diag, lower, upper, P0)
        vi = meas[L.MEAS_V_I_B:L.MEAS_V_I_B + 3]
        plausible = np.all(np.abs(vi) <= 60.0) and np.sqrt(np.sum(vi * vi)) <= 60.0
        with np.errstate(over="ignore"):  # 1e300-sized readings overflow to inf, as in the kernel
            low_speed_reading = (meas[L.MEAS_V_I_VALID] == 0.0 and np.all(np.isfinite(vi))
                                 and np.sqrt(np.sum(vi * vi)) < caltech.envelope.hover_blend_airspeed_mps[0])
        if meas[L.MEAS_V_I_VALID] != 1.0:
            assert int(_col(diag, "fault_flags")) & FAULT_PROBE
        if not (meas[L.MEAS_V_I_VALID] == 1.0 and plausible) and not low_speed_reading:
            assert _col(diag, "probe_valid_used") == 0.0
            assert _col(diag, "adaptation_active") == 0.0


def params_bounds(params):
    from vtoladapt.control.blocks import A_LOWER, A_N, A_UPPER
    n, lo, up = int(params[A_N]), int(params[A_LOWER]), int(params[A_UPPER])
    return params[lo:lo + n], params[up:up + n]


def test_hover_command_in_still_air(caltech):
    params, state = controller_arrays(caltech, ControllerConfig())
    cmd = np.zeros(L.CMD_SIZE)
    diag = _diag(params)
    step(params, state, _hover_meas(), L.pack_reference((0.0, 0.0, -1.5)), 0.004, cmd, diag)
    assert cmd[L.CMD_U_Z] == pytest.approx(np.sqrt(GRAVITY_MPS2 / caltech.theta_scaled[1]), rel=1e-12)
    assert cmd[L.CMD_U_X] == 0.0
    np.testing.assert_allclose(cmd[L.CMD_TAU_B:], 0.0, atol=1e-12)
    assert _col(diag, "blend_weight_wing") == 0.0


def test_invalid_probe_falls_back_to_the_wind_estimate_and_pauses_adaptation(caltech):
    params, state = controller_arrays(caltech, ControllerConfig())
    cmd = np.zeros(L.CMD_SIZE)
    diag = _diag(params)
    wind = np.array([-6.0, 1.0, 0.0])
    q = quat_from_euler(0.2, np.radians(10.0), 0.0)
    R = quat_to_rotmat(q)
    v_W = np.array([0.1, 0.0, 0.0])
    v_i_B = R.T @ (v_W - wind)
    ref = L.pack_reference((0.0, 0.0, -1.5))
    for _ in range(1000):                                        # 4 s valid: the estimate settles
        step(params, state, _hover_meas(q, v_i_B, 1.0, v_W), ref, 0.004, cmd, diag)
    np.testing.assert_allclose(_col(diag, "wind_est_N_mps", 3), wind, atol=1e-9)
    theta_before = state_theta_hat(params, state).copy()
    k = 0
    for bad in ([np.nan, 0.0, 0.0], [1e6, 0.0, 0.0], [0.0, np.nan, 0.0]):
        for valid in (0.0, 1.0):
            m = _hover_meas(q, bad, valid, v_W)
            step(params, state, m, ref, 0.004, cmd, diag)
            k += 1
            assert _col(diag, "probe_valid_used") == 0.0 and _col(diag, "adaptation_active") == 0.0
            # the wind estimate fades toward still air (wind_estimate_fade_s = 2 s) while the probe is out
            w_k = wind * np.exp(-k * 0.004 / 2.0)
            np.testing.assert_allclose(_col(diag, "wind_est_N_mps", 3), w_k, atol=1e-9)
            np.testing.assert_allclose(_col(diag, "ctrl_v_i_x_mps", 3), R.T @ (v_W - w_k), atol=1e-9)
            assert np.array_equal(state_theta_hat(params, state), theta_before)
    for _ in range(2500):                                        # a 10 s outage ends in still air
        step(params, state, _hover_meas(q, [np.nan, np.nan, np.nan], 0.0, v_W), ref, 0.004,
                        cmd, diag)
    np.testing.assert_allclose(_col(diag, "wind_est_N_mps", 3), 0.0, atol=0.05)
    # valid again: adaptation waits for the filters (adaptation_holdoff_s = 0.05 s) before resuming,
    # and the wind estimate recovers
    active = []
    for _ in range(1000):
        step(params, state, _hover_meas(q, v_i_B, 1.0, v_W), ref, 0.004, cmd, diag)
        active.append(_col(diag, "adaptation_active"))
    assert active[0] == 0.0 and active[-1] == 1.0
    assert 10 <= int(np.argmax(active)) <= 14
    np.testing.assert_allclose(_col(diag, "wind_est_N_mps", 3), wind, atol=0.2)


def test_low_airspeed_reading_flagged_invalid_is_still_used_in_hover(caltech):
    """A finite reading the sensor flags only for its low airspeed says 'still air': it is used
    (fault flag set), the wind estimate follows it, and C_Tz keeps adapting in hover."""
    params, state = controller_arrays(caltech, ControllerConfig())
    cmd = np.zeros(L.CMD_SIZE)
    diag = _diag(params)
    ref = L.pack_reference((0.0, 0.0, -1.5))
    v_low = np.array([0.3, 0.0, 0.1])                      # below hover_blend_airspeed_mps[0] = 2 m/s
    theta0 = state_theta_hat(params, state).copy()
    for _ in range(500):
        m = _hover_meas(v_i_B=v_low, valid=0.0)
        m[L.MEAS_ACCEL_B + 2] = -1.05 * GRAVITY_MPS2       # 5 % more thrust than Table I predicts
        step(params, state, m, ref, 0.004, cmd, diag)
    assert int(_col(diag, "fault_flags")) & FAULT_PROBE
    assert _col(diag, "probe_valid_used") == 1.0 and _col(diag, "adaptation_active") == 1.0
    np.testing.assert_allclose(_col(diag, "ctrl_v_i_x_mps", 3), v_low, atol=1e-12)
    assert state_theta_hat(params, state)[1] > theta0[1]           # CTz adapts upward toward the measured thrust
    # the same reading above the hover-blend airspeed is not trusted
    m = _hover_meas(v_i_B=[5.0, 0.0, 0.0], valid=0.0)
    step(params, state, m, ref, 0.004, cmd, diag)
    assert _col(diag, "probe_valid_used") == 0.0 and _col(diag, "adaptation_active") == 0.0


def test_nan_everywhere_still_gives_a_finite_command(caltech):
    for kind in controller_ids():
        params, state = controller_arrays(caltech, ControllerConfig(kind=kind))
        cmd = np.full(L.CMD_SIZE, np.nan)
        diag = _diag(params)
        for _ in range(3):
            step(params, state, np.full(L.MEAS_SIZE, np.nan), np.full(L.REF_SIZE, np.nan), np.nan,
                            cmd, diag)
            assert np.all(np.isfinite(cmd)) and np.all(np.isfinite(diag))


def _sinking(vehicle, throttle_max_pct, kind="pid", n=500):
    veh = vehicle.replace(actuators=dataclasses.replace(vehicle.actuators, throttle_max_pct=throttle_max_pct))
    params, state = controller_arrays(veh, ControllerConfig(kind=kind))
    cmd = np.zeros(L.CMD_SIZE)
    diag = _diag(params)
    m = _hover_meas(v_W=(0.0, 0.0, 0.5))                         # sinking at 0.5 m/s, at the setpoint
    for _ in range(n):
        step(params, state, m, L.pack_reference((0.0, 0.0, -1.5)), 0.004, cmd, diag)
    return state_law_field(state, params, "INTEGRATOR").copy(), diag


def test_pid_integrator_freezes_while_the_allocation_saturates(caltech):
    free, diag = _sinking(caltech, 100.0)
    assert free[2] < -1.5                                        # integrates the sinking (up is -D)
    frozen, diag = _sinking(caltech, 59.0)                       # hover needs 58.5 %: lift saturates
    assert _col(diag, "sat_u_z") == 1.0
    assert abs(frozen[2]) < 0.01
    pd, _ = _sinking(caltech, 100.0, kind="pd")
    np.testing.assert_array_equal(pd, 0.0)


def test_equivalent_gains_are_shared(caltech):
    from vtoladapt.control.blocks import P_K_V, P_LAMBDA_P
    arrays = {k: controller_arrays(caltech, ControllerConfig(kind=k))[0] for k in controller_ids()}
    for k in controller_ids():
        np.testing.assert_array_equal(arrays[k][P_K_V:P_K_V + 3], arrays["pid"][P_K_V:P_K_V + 3])
        np.testing.assert_array_equal(arrays[k][P_LAMBDA_P:P_LAMBDA_P + 3], arrays["pid"][P_LAMBDA_P:P_LAMBDA_P + 3])


@pytest.mark.parametrize("kind", ["composite", "pid"])
def test_gains_cached_per_dt_equal_gains_computed_every_tick(caltech, kind):
    """The filter and lag gains are kept in the state for the last dt: reusing them is exact."""
    from vtoladapt.control.blocks import S_GAINS_DT
    config = ControllerConfig(kind=kind, omega_d_feedforward=True)
    cached = controller_arrays(caltech, config)
    fresh = controller_arrays(caltech, config)
    outputs = []
    for params, state in (cached, fresh):
        cmd = np.zeros(L.CMD_SIZE)
        diag = _diag(params)
        rows = []
        for k in range(400):
            pitch = 0.1 * np.sin(0.05 * k)
            m = _hover_meas(q=quat_from_euler(0.0, pitch, 0.0), v_i_B=(8.0 + np.sin(0.02 * k), 0.0, 1.0),
                            valid=0.0 if 150 <= k < 200 else 1.0, v_W=(8.0, 0.0, 0.1 * np.cos(0.03 * k)))
            dt = (0.004, 0.004, 0.005, 0.0041)[(k // 7) % 4]        # runs of equal dt, then a change
            if state is fresh[1]:
                state[S_GAINS_DT] = 0.0                              # forget the gains: recompute
            step(params, state, m, L.pack_reference((1.0, 0.0, -1.5)), dt, cmd, diag)
            rows.append(np.concatenate([cmd, diag]))
        outputs.append(np.array(rows))
    np.testing.assert_array_equal(outputs[0], outputs[1])
