"""The controller's front end, shared by every law: sanitised inputs, incident velocity, errors, regressor.

One call of :func:`front_end` per tick, before the law's update (see :mod:`vtoladapt.control`
for the whole tick):

1. **dt.** Outside ``(0, 0.1]`` or not finite it is replaced (nominal rate, or 0.1 s) and flagged;
   when it changes the shared filter gains are recomputed (``new_dt`` tells the law to redo its own).
2. **Sanitise the measurement and reference.** Each group (position, velocity, attitude, gyro,
   accelerometer, probe; reference position, velocity, acceleration, yaw) that is non-finite or
   implausible is replaced by its last good value and flagged in ``diag['fault_flags']``; the
   gyro is clipped to +-35 rad/s (a real gyro's range).
3. **Incident velocity.** The probe's ``v_i`` is used if ``meas[MEAS_V_I_VALID] == 1``, finite and
   below ``probe_airspeed_max_mps``; a finite reading flagged invalid only for a low airspeed
   (below the vehicle's hover-blend airspeed) is used too, since it still measures still air --
   unless the body-horizontal prediction error (filtered, above ``unseen_flow_accel_mps2``) shows
   an airflow the probe cannot see (from the side or behind: it reads "invalid, zero" then too).
   Otherwise the fallback is ``v_i = R^T (v - w_hat)`` with ``w_hat`` the wind estimate
   ``v - R v_i`` low-passed (``wind_estimate_time_constant_s``) while the probe was valid, fading
   toward still air (``wind_estimate_fade_s``) while it is not: a short dropout keeps the wind, a
   long outage (a probe that reads "invalid" at low airspeed after the wind stopped) does not fly
   the wing solution in still air. ``diag['probe_valid_used']`` says which.
   **Airflow estimate** (``unseen_flow_estimate``, off by default): while the unseen-flow detector
   is on and the probe is not used, :func:`.airflow_estimate.estimate_horizontal_wind` solves for
   the horizontal wind whose incident flow makes the model's body-horizontal force (theta-hat, the
   lagged throttles) match the filtered accelerometer, warm-started from its last solution. An
   accepted solution (converged to the detector's "off" threshold, ``|v_i|`` below
   ``probe_airspeed_max_mps``, sideslip within 30 deg) replaces the fade: ``w_hat`` follows it with
   ``unseen_flow_estimate_time_constant_s`` and the heading turns into it (``diag['unseen_flow_estimate']``).
   While it is on, the prediction error is small by construction, so the detector is not cleared by
   it: the estimate ends when the probe is valid again (``w_hat`` then low-passes back to the probe's
   wind), when a solve is rejected (the fade resumes), or when the solved airspeed is below the
   hover-blend start (the wind is gone: the probe's "invalid, near zero" is still air again).
4. **Tracking errors** ``p~``, ``v_r``, ``v~`` (eq:wr; ``|Lambda_p p~|`` and ``|v~|`` limited).
5. **Regressor and filters** (eq:prediction_error). The regressor uses the current ``v_i`` and the
   throttles commanded for the interval that just ended, passed through the vehicle's nominal
   motor lag (``regressor_motor_lag``: what produced the measured specific force); ``W = [Phi]_f``
   and ``a_m`` are filtered for every law, so every law's log holds the prediction error of its
   theta-hat. ``may_adapt``: the filters have started, the probe and the accelerometer are valid
   and have been for ``adaptation_holdoff_s`` -- an adaptive law updates theta-hat only then.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .. import layout as L
from ..forces import M_K1, M_K2, incident_flow, model_at, regressor_at, theta_at
from ..frames import quat_to_rotmat_rows, rows_times, rows_transpose_times, yaw_pitch_roll
from . import adaptation as ad
from .airflow_estimate import SIN_SIDESLIP_MAX, estimate_horizontal_wind
from .layouts import (
    FAULT_ACCEL, FAULT_ATTITUDE, FAULT_DT, FAULT_GYRO, FAULT_POSITION, FAULT_PROBE, FAULT_REFERENCE,
    FAULT_VELOCITY, GAIN_FADE, GAIN_LOWPASS, GAIN_MOTOR_X, GAIN_MOTOR_Z, GAIN_OMEGA_D, GAIN_WIND, N_THETA,
    P_DT_NOMINAL, P_HOLDOFF_S, P_LAMBDA_P, P_LOWPASS_HZ, P_MODEL, P_MOTOR_LAG_ON, P_MOTOR_TAU, P_V_LO,
    P_VCORR_MAX, P_VERR_MAX, P_VPROBE_MAX, P_WD_HZ, P_WIND_FADE, P_WIND_TAU, S_AM_F, S_FILT_INIT, S_GAINS,
    S_GAINS_DT, S_HAVE_REF, S_HAVE_WIND, S_OMEGA_LAST, S_P_LAST, S_Q_LAST, S_REF_LAST, S_STEPS, S_THETA,
    S_U_EST, S_U_PREV, S_V_LAST, S_VALID_TIME, S_W_F, S_WIND_EST, P_UNSEEN_ACCEL, S_UNSEEN_FLOW,
    GAIN_FLOW_EST, P_FLOW_EST_ON, P_FLOW_EST_TAU, S_FLOW_EST_ON, S_FLOW_EST_W,
)
from .tracking import limit_norm, reference_velocity

GYRO_RANGE_RADPS = 35.0
POSITION_PLAUSIBLE_M = 1e6
VELOCITY_PLAUSIBLE_MPS = 1e3
ACCEL_PLAUSIBLE_MPS2 = 1e3

# The step reads its arrays by offset into scalars and tuples and calls kernels that take and
# return those: an array view handed to a compiled function costs two atomic reference-count
# updates (about 30 ns here); the only arrays passed on are params, state and diag.


@njit(cache=True)
def vec3(a, o) -> tuple:
    """``(a[o], a[o+1], a[o+2])``."""
    return (a[o], a[o + 1], a[o + 2])


@njit(cache=True)
def plausible(x, bound) -> bool:
    """Every entry of the tuple ``x`` finite and within ``+-bound`` (``bound = inf``: finite)."""
    ok = True
    for i in range(len(x)):
        ok = ok and np.isfinite(x[i]) and abs(x[i]) <= bound
    return ok


@njit(cache=True)
def wrap_angle(a) -> float:
    """``a`` in (-pi, pi] (unchanged if already there)."""
    if -np.pi < a <= np.pi:
        return a
    return np.arctan2(np.sin(a), np.cos(a))


@njit(cache=True)
def update_shared_gains(params, state, dt) -> None:
    """Store the shared filter and lag gains for a tick of ``dt`` (``GAINS`` layout) in ``state``."""
    g = S_GAINS
    state[g + GAIN_LOWPASS] = ad.lowpass_gain(params[P_LOWPASS_HZ], dt)
    state[g + GAIN_WIND] = 1.0 - np.exp(-dt / params[P_WIND_TAU])
    state[g + GAIN_FADE] = np.exp(-dt / params[P_WIND_FADE])
    state[g + GAIN_MOTOR_X] = np.exp(-dt / params[P_MOTOR_TAU])
    state[g + GAIN_MOTOR_Z] = np.exp(-dt / params[P_MOTOR_TAU + 1])
    state[g + GAIN_OMEGA_D] = ad.lowpass_gain(params[P_WD_HZ], dt)
    state[g + GAIN_FLOW_EST] = 1.0 - np.exp(-dt / params[P_FLOW_EST_TAU])
    state[S_GAINS_DT] = dt


@njit(cache=True)
def prediction_error(state) -> tuple:
    """``e = W theta-hat - a_m`` (eq:prediction_error) from the shared estimate, body, m/s^2."""
    return ad.prediction_error(state, S_W_F, state, S_THETA, state, S_AM_F)


@njit(cache=True, inline="always")
def front_end(params, state, meas, ref, dt) -> tuple:
    """Steps 1-5 of the module notes for one tick; updates the shared state in place.

    Returns
    -------
    (dt, new_dt, faults, may_adapt, probe_ok, R, v_W, v_i, p_tilde, v_r, v_r_dot, v_tilde_raw, v_tilde,
     a_d, yaw_d, Phi, flow)
        The tick used (s) and whether it differs from the last one; the ``FAULT_*`` bits so far;
        whether an adaptive law may update theta-hat; whether the probe was used; ``R_WB`` (rows);
        velocity (m/s NED); incident velocity used (m/s body); ``p~`` (m), ``v_r``, ``v_r'``,
        ``v~`` before and after its limit (NED); desired acceleration (m/s^2 NED) and heading
        (rad); the unfiltered regressor ``Phi`` (three rows of 8); and the flow quantities of
        ``v_i`` (:func:`vtoladapt.forces.incident_flow`) it was formed from.
    """
    faults = 0
    if not (dt > 0.0 and dt <= 0.1):
        faults |= FAULT_DT
        dt = params[P_DT_NOMINAL] if not dt > 0.1 else 0.1
    new_dt = not state[S_GAINS_DT] == dt
    if new_dt:
        update_shared_gains(params, state, dt)

    # sanitise the measurement: every group falls back to its last good value
    x = vec3(meas, L.MEAS_P_W)
    if plausible(x, POSITION_PLAUSIBLE_M):
        state[S_P_LAST], state[S_P_LAST + 1], state[S_P_LAST + 2] = x
    else:
        faults |= FAULT_POSITION
    x = vec3(meas, L.MEAS_V_W)
    if plausible(x, VELOCITY_PLAUSIBLE_MPS):
        state[S_V_LAST], state[S_V_LAST + 1], state[S_V_LAST + 2] = x
    else:
        faults |= FAULT_VELOCITY
    q = (meas[L.MEAS_Q_WB], meas[L.MEAS_Q_WB + 1], meas[L.MEAS_Q_WB + 2], meas[L.MEAS_Q_WB + 3])
    qn = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) if plausible(q, np.inf) else 0.0
    if 0.5 < qn < 1.5:
        for i in range(4):
            state[S_Q_LAST + i] = q[i] / qn
    else:
        faults |= FAULT_ATTITUDE
    x = vec3(meas, L.MEAS_OMEGA_B)
    if plausible(x, np.inf):
        for i in range(3):
            state[S_OMEGA_LAST + i] = min(max(x[i], -GYRO_RANGE_RADPS), GYRO_RANGE_RADPS)
    else:
        faults |= FAULT_GYRO
    accel = vec3(meas, L.MEAS_ACCEL_B)
    accel_ok = plausible(accel, ACCEL_PLAUSIBLE_MPS2)
    if not accel_ok:
        faults |= FAULT_ACCEL
    p_W = vec3(state, S_P_LAST)
    v_W = vec3(state, S_V_LAST)
    q_WB = (state[S_Q_LAST], state[S_Q_LAST + 1], state[S_Q_LAST + 2], state[S_Q_LAST + 3])
    R = quat_to_rotmat_rows(q_WB)

    # sanitise the reference (groups: position, velocity, acceleration, yaw)
    have_ref = state[S_HAVE_REF] > 0.0
    ok_ref = True
    for off, bound in ((L.REF_P_W, POSITION_PLAUSIBLE_M), (L.REF_V_W, VELOCITY_PLAUSIBLE_MPS),
                       (L.REF_A_W, ACCEL_PLAUSIBLE_MPS2)):
        x = vec3(ref, off)
        if plausible(x, bound):
            state[S_REF_LAST + off], state[S_REF_LAST + off + 1], state[S_REF_LAST + off + 2] = x
        else:
            ok_ref = False
            if off == L.REF_P_W and not have_ref:
                # no good reference yet: hold where we are
                state[S_REF_LAST + off], state[S_REF_LAST + off + 1], state[S_REF_LAST + off + 2] = p_W
    if np.isfinite(ref[L.REF_YAW]):
        state[S_REF_LAST + L.REF_YAW] = wrap_angle(ref[L.REF_YAW])
    else:
        ok_ref = False
        if not have_ref:
            # no good reference yet: face where we face
            state[S_REF_LAST + L.REF_YAW] = yaw_pitch_roll(q_WB)[0]
    if not ok_ref:
        faults |= FAULT_REFERENCE
    state[S_HAVE_REF] = 1.0
    p_d = vec3(state, S_REF_LAST + L.REF_P_W)
    v_d = vec3(state, S_REF_LAST + L.REF_V_W)
    a_d = vec3(state, S_REF_LAST + L.REF_A_W)
    yaw_d = state[S_REF_LAST + L.REF_YAW]

    # incident velocity: probe, or the fallback from the wind estimate
    v_i = vec3(meas, L.MEAS_V_I_B)
    all_finite = plausible(v_i, np.inf)
    V_probe = np.sqrt(v_i[0] * v_i[0] + v_i[1] * v_i[1] + v_i[2] * v_i[2])
    probe_ok = meas[L.MEAS_V_I_VALID] == 1.0 and all_finite and V_probe <= params[P_VPROBE_MAX]
    # A finite reading flagged invalid only because the airspeed is low (the pressure probe's
    # q_inf floor, the probe's minimum airspeed) still says "the air is nearly still": use it.
    # Below the hover-blend airspeed the aerodynamic columns of Phi are ~V^2 ~ 0, so C_Tz keeps
    # adapting in hover instead of pausing whenever the fan is off.
    # But the probe reads the same "invalid, near zero" with the flow outside its cone (wind from the
    # side or behind), and taking that for still air made every adaptive law adapt on a regressor
    # without the wind (issue #11). An unseen flow shows in the accelerometer: the body-horizontal
    # prediction error (the model has no horizontal force in still air) is then large.
    if state[S_FILT_INIT] > 0.0:
        e_prev = prediction_error(state)
        e_h = np.sqrt(e_prev[0] * e_prev[0] + e_prev[1] * e_prev[1])
        if e_h > params[P_UNSEEN_ACCEL + 1]:
            state[S_UNSEEN_FLOW] = 1.0
        elif e_h < params[P_UNSEEN_ACCEL] and not state[S_FLOW_EST_ON] > 0.0:
            # (while the airflow estimate is on, e is small because v_i holds the estimated flow: the
            # estimate itself says when the flow is gone, below)
            state[S_UNSEEN_FLOW] = 0.0
    if (not probe_ok and meas[L.MEAS_V_I_VALID] == 0.0 and all_finite and V_probe < params[P_V_LO]
            and not state[S_UNSEEN_FLOW] > 0.0):
        probe_ok = True
    if meas[L.MEAS_V_I_VALID] != 1.0:
        faults |= FAULT_PROBE  # the sensor's own flag is always reported, even when the reading is used
    if probe_ok:
        cw = state[S_GAINS + GAIN_WIND]
        v_i_probe_W = rows_times(R, v_i)
        for i in range(3):
            w_i = v_W[i] - v_i_probe_W[i]
            if state[S_HAVE_WIND] > 0.0:
                state[S_WIND_EST + i] = ad.lowpass(state[S_WIND_EST + i], w_i, cw)
            else:
                state[S_WIND_EST + i] = w_i
        state[S_HAVE_WIND] = 1.0
        state[S_FLOW_EST_ON] = 0.0
    else:
        faults |= FAULT_PROBE
        # an airflow the probe cannot see: estimate it from the force the model cannot explain
        est_ok = False
        if (params[P_FLOW_EST_ON] > 0.0 and state[S_UNSEEN_FLOW] > 0.0 and state[S_FILT_INIT] > 0.0
                and accel_ok):
            est_on = state[S_FLOW_EST_ON] > 0.0
            theta = theta_at(state, S_THETA)
            w0_N = state[S_FLOW_EST_W] if est_on else state[S_WIND_EST]
            w0_E = state[S_FLOW_EST_W + 1] if est_on else state[S_WIND_EST + 1]
            est_ok, w_N, w_E, _ = estimate_horizontal_wind(
                v_W, R, state[S_WIND_EST + 2], w0_N, w0_E, not est_on, state[S_U_EST], state[S_U_EST + 1],
                theta, model_at(params, P_MODEL), state[S_AM_F], state[S_AM_F + 1], params[P_UNSEEN_ACCEL],
                params[P_VPROBE_MAX], SIN_SIDESLIP_MAX)
            if est_ok:
                state[S_FLOW_EST_W], state[S_FLOW_EST_W + 1] = w_N, w_E
                c = state[S_GAINS + GAIN_FLOW_EST]
                state[S_WIND_EST] = ad.lowpass(state[S_WIND_EST], w_N, c)
                state[S_WIND_EST + 1] = ad.lowpass(state[S_WIND_EST + 1], w_E, c)
                state[S_WIND_EST + 2] = ad.flush_tiny(state[S_WIND_EST + 2] * state[S_GAINS + GAIN_FADE])
                state[S_HAVE_WIND] = 1.0
                # the flow the model places is slower than the probe's still-air story allows: the wind
                # is gone, the probe's "invalid, near zero" is still air again
                d_N, d_E = v_W[0] - w_N, v_W[1] - w_E
                if d_N * d_N + d_E * d_E < params[P_V_LO] * params[P_V_LO]:
                    est_ok = False
                    state[S_UNSEEN_FLOW] = 0.0
        state[S_FLOW_EST_ON] = 1.0 if est_ok else 0.0
        if not est_ok:
            # a stale estimate must not outlive the wind: fade toward still air while the probe is out
            fade = state[S_GAINS + GAIN_FADE]
            for i in range(3):
                state[S_WIND_EST + i] = ad.flush_tiny(state[S_WIND_EST + i] * fade)
        d = (v_W[0] - state[S_WIND_EST], v_W[1] - state[S_WIND_EST + 1], v_W[2] - state[S_WIND_EST + 2])
        v_i = rows_transpose_times(R, d)

    # tracking errors (eq:wr)
    p_tilde = (p_W[0] - p_d[0], p_W[1] - p_d[1], p_W[2] - p_d[2])
    v_r, v_r_dot, _ = reference_velocity(p_tilde, v_d, a_d, v_W, vec3(params, P_LAMBDA_P), params[P_VCORR_MAX])
    v_tilde_raw = (v_W[0] - v_r[0], v_W[1] - v_r[1], v_W[2] - v_r[2])
    v_tilde, _ = limit_norm(v_tilde_raw, params[P_VERR_MAX])

    # regressor and filters (eq:prediction_error)
    # The accelerometer feels the thrust of motors that lag their commands (30-40 ms): pass the
    # command held over the last interval through the vehicle's nominal lag, so that Phi uses the
    # throttles that produced the measured specific force (not the plant's true lag).
    if params[P_MOTOR_LAG_ON] > 0.0 and state[S_STEPS] >= 2.0:
        for j in range(2):
            a_lag = state[S_GAINS + GAIN_MOTOR_X + j]
            state[S_U_EST + j] = state[S_U_PREV + j] + (state[S_U_EST + j] - state[S_U_PREV + j]) * a_lag
    else:
        state[S_U_EST] = state[S_U_PREV]
        state[S_U_EST + 1] = state[S_U_PREV + 1]
    # the flow quantities (airspeed, angles, dynamic pressure) once: the allocation reuses them
    flow = incident_flow(v_i, model_at(params, P_MODEL))
    Phi = regressor_at(flow, state[S_U_EST], state[S_U_EST + 1], params[P_MODEL + M_K1], params[P_MODEL + M_K2])
    c_f = state[S_GAINS + GAIN_LOWPASS]
    if state[S_FILT_INIT] > 0.0:
        for r in range(3):
            for k in range(N_THETA):
                state[S_W_F + N_THETA * r + k] = ad.lowpass(state[S_W_F + N_THETA * r + k], Phi[r][k], c_f)
        if accel_ok:
            for r in range(3):
                state[S_AM_F + r] = ad.lowpass(state[S_AM_F + r], accel[r], c_f)
    elif accel_ok and state[S_STEPS] >= 1.0:
        # start the filters from a sample whose regressor uses a command this controller issued
        for r in range(3):
            state[S_AM_F + r] = accel[r]
            for k in range(N_THETA):
                state[S_W_F + N_THETA * r + k] = Phi[r][k]
        state[S_FILT_INIT] = 1.0
    if probe_ok and accel_ok:
        state[S_VALID_TIME] += dt
    else:
        state[S_VALID_TIME] = 0.0
    may_adapt = (state[S_FILT_INIT] > 0.0 and probe_ok and accel_ok
                 and state[S_VALID_TIME] >= params[P_HOLDOFF_S] - 1e-12)
    return (dt, new_dt, faults, may_adapt, probe_ok, R, v_W, v_i, p_tilde, v_r, v_r_dot, v_tilde_raw, v_tilde,
            a_d, yaw_d, Phi, flow)
