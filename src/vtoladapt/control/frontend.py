"""The controller's front end, shared by every law: sanitised inputs, incident velocity, errors, regressor.

One call of :func:`front_end` per tick, before the law's update (see :mod:`vtoladapt.control`
for the whole tick). It is six named stages, each writing its results into the tick block
(:data:`.blocks.TICK`) or the basis's input block (:data:`vtoladapt.bases.INPUT`) in the state:

1. **dt** (:func:`check_dt`). Outside ``(0, 0.1]`` or not finite it is replaced (nominal rate, or 0.1 s) and flagged;
   when it changes the shared filter gains are recomputed (``new_dt`` tells the law to redo its own).
2. **Sanitise the measurement and reference** (:func:`sanitise_measurement`, :func:`sanitise_reference`). Each group (position, velocity, attitude, gyro,
   accelerometer, probe; reference position, velocity, acceleration, yaw) that is non-finite or
   implausible is replaced by its last good value and flagged in ``diag['fault_flags']``; the
   gyro is clipped to +-35 rad/s (a real gyro's range).
3. **Incident velocity** (:func:`incident_velocity`, with :func:`probe_usable`, :func:`follow_probe`,
   :func:`fallback_flow`). The probe's ``v_i`` is used if ``meas[MEAS_V_I_VALID] == 1``, finite and
   below ``probe_airspeed_max_mps``; a finite reading flagged invalid only for a low airspeed
   (below the vehicle's hover-blend airspeed) is used too, since it still measures still air --
   unless the body-horizontal prediction error (filtered, above ``unseen_flow_accel_mps2``; of the
   physics columns alone, :func:`physics_horizontal_error`, so that a basis's extra columns cannot
   explain the flow away) shows an airflow the probe cannot see (from the side or behind: it reads
   "invalid, zero" then too).
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
4. **Tracking errors** (:func:`tracking_errors`) ``p~``, ``v_r``, ``v~`` (eq:wr; ``|Lambda_p p~|`` and ``|v~|`` limited).
5. **Regressor and filters** (:func:`regressor_and_filters`, eq:prediction_error). The basis's input block gets the current
   ``v_i``, its validity, the throttles commanded for the interval that just ended passed through
   the vehicle's nominal motor lag (``regressor_motor_lag``: what produced the measured specific
   force), the attitude, rates, velocity and the flow quantities; the basis's compiled regressor
   (a first-class function argument of the step, :mod:`vtoladapt.bases`) writes ``Phi``.
   ``W = [Phi]_f`` and ``a_m`` are filtered for every law, so every law's log holds the prediction
   error of its theta-hat (``E`` of the tick, before the law's update). ``may_adapt``: the filters
   have started, the probe and the accelerometer are valid and have been for
   ``adaptation_holdoff_s`` -- an adaptive law updates theta-hat only then. ``accel_ok``: the same
   without the probe (filters started, accelerometer valid for ``adaptation_holdoff_s``) -- what a law
   built on the accelerometer and the actuator state alone (INDI) needs.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .. import layout as L
from ..bases import IN_FLOW, IN_OMEGA_B, IN_Q_WB, IN_U, IN_V_I_B, IN_V_I_VALID, IN_V_W, INPUT_SIZE, N_PHYSICS
from ..forces import FLOW_SIZE, incident_flow, model_at, theta_at
from ..frames import quat_to_rotmat_rows, rows_times, rows_transpose_times, yaw_pitch_roll
from . import adaptation as ad
from . import filters
from .airflow_estimate import SIN_SIDESLIP_MAX, estimate_horizontal_wind
from .blocks import (
    A_A_M, A_BASIS, A_BASIS_SIZE, A_BASIS_WORK, A_BASIS_WORK_SIZE, A_N, A_PHI, A_THETA, A_W, FAULT_ACCEL,
    FAULT_ATTITUDE, FAULT_DT, FAULT_GYRO, FAULT_POSITION, FAULT_PROBE, FAULT_REFERENCE, FAULT_VELOCITY, GAIN_FADE,
    GAIN_FLOW_EST, GAIN_LOWPASS, GAIN_MOTOR_X, GAIN_MOTOR_Z, GAIN_OMEGA_D, GAIN_WIND, P_DT_NOMINAL, P_FLOW_EST_ON, P_FLOW_EST_TAU,
    P_HOLDOFF_S, P_LAMBDA_P, P_LOWPASS_HZ, P_MODEL, P_MOTOR_LAG_ON, P_MOTOR_TAU, P_UNSEEN_ACCEL, P_V_LO,
    P_VCORR_MAX, P_VERR_MAX, P_VPROBE_MAX, P_WD_HZ, P_WIND_FADE, P_WIND_TAU, S_FILT_INIT, S_FLOW_EST_ON,
    S_FLOW_EST_W, S_GAINS, S_GAINS_DT, S_HAVE_REF, S_HAVE_WIND, S_INPUT, S_OMEGA_LAST, S_P_LAST, S_Q_LAST,
    S_REF_LAST, S_STEPS, S_TICK, S_U_EST, S_U_PREV, S_UNSEEN_FLOW, S_V_LAST, S_VALID_TIME, S_ACCEL_VALID_TIME,
    S_WIND_EST, T_A_D, T_ACCEL_OK, T_DT, T_E, T_FAULTS, T_MAY_ADAPT, T_NEW_DT, T_P_TILDE, T_PROBE_OK, T_R_WB, T_V_R,
    T_V_R_DOT, T_V_TILDE, T_V_TILDE_RAW, T_V_W, T_YAW_D,
)
from .tracking import limit_norm, reference_velocity

GYRO_RANGE_RADPS = 35.0
POSITION_PLAUSIBLE_M = 1e6
VELOCITY_PLAUSIBLE_MPS = 1e3
ACCEL_PLAUSIBLE_MPS2 = 1e3

# The stages read their arrays by offset into scalars and tuples and pass those on: an array view
# handed to a compiled function costs two atomic reference-count updates where reference counting
# is on (the Python API's and the tests' callers); the only arrays passed are params, state, the
# measurement, the reference and diag. ``t`` below is the tick block's first slot in the state.


@njit(cache=True)
def vec3(a, o) -> tuple:
    """``(a[o], a[o+1], a[o+2])``."""
    return (a[o], a[o + 1], a[o + 2])


@njit(cache=True)
def put3(a, o, x) -> None:
    """``a[o:o+3] = x`` for a 3-tuple ``x``."""
    a[o] = x[0]
    a[o + 1] = x[1]
    a[o + 2] = x[2]


@njit(cache=True)
def rows_at(a, o) -> tuple:
    """The three rows of the row-major 3 x 3 matrix at ``a[o:]``, as tuples."""
    return ((a[o], a[o + 1], a[o + 2]), (a[o + 3], a[o + 4], a[o + 5]), (a[o + 6], a[o + 7], a[o + 8]))


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
    state[g + GAIN_LOWPASS] = filters.lowpass_gain(params[P_LOWPASS_HZ], dt)
    state[g + GAIN_WIND] = 1.0 - np.exp(-dt / params[P_WIND_TAU])
    state[g + GAIN_FADE] = np.exp(-dt / params[P_WIND_FADE])
    state[g + GAIN_MOTOR_X] = np.exp(-dt / params[P_MOTOR_TAU])
    state[g + GAIN_MOTOR_Z] = np.exp(-dt / params[P_MOTOR_TAU + 1])
    state[g + GAIN_OMEGA_D] = filters.lowpass_gain(params[P_WD_HZ], dt)
    state[g + GAIN_FLOW_EST] = 1.0 - np.exp(-dt / params[P_FLOW_EST_TAU])
    state[S_GAINS_DT] = dt


@njit(cache=True)
def prediction_error(params, state) -> tuple:
    """``e = W theta-hat - a_m`` (eq:prediction_error) from the shared estimate, body, m/s^2."""
    n = int(params[A_N])
    w, th, am = int(params[A_W]), int(params[A_THETA]), int(params[A_A_M])
    if n == ad.N_SLOT_0:
        return ad.prediction_error(state, w, state, th, state, am, ad.N_SLOT_0)
    if n == ad.N_SLOT_1:
        return ad.prediction_error(state, w, state, th, state, am, ad.N_SLOT_1)
    if n == ad.N_SLOT_2:
        return ad.prediction_error(state, w, state, th, state, am, ad.N_SLOT_2)
    return ad.prediction_error(state, w, state, th, state, am, n)


@njit(cache=True)
def physics_horizontal_error(params, state) -> tuple:
    """The body-horizontal part ``(e_x, e_y)`` of ``e`` with the physics columns alone, ``W_phys theta_phys - a_m``
    (the paper's eight, :data:`vtoladapt.bases.N_PHYSICS`), body m/s^2.

    The unseen-flow detector and the blind weathervane judge this one: the force the physics model
    leaves unexplained. A basis's extra columns (a learned block) may explain part of an unseen
    flow's drag away, and would make the detector and the weathervane depend on the basis (issue
    #34, defect 2). With the paper's basis it is ``e``'s first two entries, bit for bit.
    """
    n = int(params[A_N])
    if n == N_PHYSICS:
        e = prediction_error(params, state)
        return (e[0], e[1])
    w, th, am = int(params[A_W]), int(params[A_THETA]), int(params[A_A_M])
    e0 = -state[am]
    e1 = -state[am + 1]
    for j in range(N_PHYSICS):
        e0 += state[w + j] * state[th + j]
        e1 += state[w + n + j] * state[th + j]
    return (e0, e1)


@njit(cache=True)
def physics_theta(params, state) -> tuple:
    """The first eight entries of theta-hat, the paper's physics columns (:mod:`vtoladapt.bases`), as a tuple."""
    return theta_at(state, int(params[A_THETA]))


# --- 1. dt ----------------------------------------------------------------------------------------

@njit(cache=True, inline="always")
def check_dt(params, state, dt) -> None:
    """The tick's ``DT`` and ``NEW_DT`` (an invalid dt replaced and flagged); the shared gains when it changed."""
    t = S_TICK
    faults = 0
    if not (dt > 0.0 and dt <= 0.1):
        faults |= FAULT_DT
        dt = params[P_DT_NOMINAL] if not dt > 0.1 else 0.1
    new_dt = not state[S_GAINS_DT] == dt
    if new_dt:
        update_shared_gains(params, state, dt)
    state[t + T_DT] = dt
    state[t + T_NEW_DT] = 1.0 if new_dt else 0.0
    state[t + T_FAULTS] = faults


# --- 2. sanitise -----------------------------------------------------------------------------------

@njit(cache=True, inline="always")
def sanitise_measurement(state, meas) -> bool:
    """Every group of the measurement falls back to its last good value (flagged); the tick's ``R_WB`` and
    ``V_W`` from them. Returns whether the accelerometer is plausible (it has no last good value)."""
    t = S_TICK
    faults = 0
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
    accel_ok = plausible(vec3(meas, L.MEAS_ACCEL_B), ACCEL_PLAUSIBLE_MPS2)
    if not accel_ok:
        faults |= FAULT_ACCEL
    q_WB = (state[S_Q_LAST], state[S_Q_LAST + 1], state[S_Q_LAST + 2], state[S_Q_LAST + 3])
    R = quat_to_rotmat_rows(q_WB)
    for r in range(3):
        put3(state, t + T_R_WB + 3 * r, R[r])
    put3(state, t + T_V_W, vec3(state, S_V_LAST))
    state[t + T_FAULTS] = int(state[t + T_FAULTS]) | faults
    return accel_ok


@njit(cache=True, inline="always")
def sanitise_reference(state, ref) -> None:
    """Each reference group (position, velocity, acceleration, yaw) falls back to its last good value, or
    before any, to the current position and heading (flagged); the tick's ``A_D`` and ``YAW_D``."""
    t = S_TICK
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
                put3(state, S_REF_LAST + off, vec3(state, S_P_LAST))
    if np.isfinite(ref[L.REF_YAW]):
        state[S_REF_LAST + L.REF_YAW] = wrap_angle(ref[L.REF_YAW])
    else:
        ok_ref = False
        if not have_ref:
            # no good reference yet: face where we face
            q_WB = (state[S_Q_LAST], state[S_Q_LAST + 1], state[S_Q_LAST + 2], state[S_Q_LAST + 3])
            state[S_REF_LAST + L.REF_YAW] = yaw_pitch_roll(q_WB)[0]
    if not ok_ref:
        state[t + T_FAULTS] = int(state[t + T_FAULTS]) | FAULT_REFERENCE
    state[S_HAVE_REF] = 1.0
    put3(state, t + T_A_D, vec3(state, S_REF_LAST + L.REF_A_W))
    state[t + T_YAW_D] = state[S_REF_LAST + L.REF_YAW]


# --- 3. incident velocity --------------------------------------------------------------------------

@njit(cache=True, inline="always")
def probe_usable(params, state, meas) -> bool:
    """Whether the probe's reading is used: flagged valid, finite and below ``probe_airspeed_max_mps``; or a
    finite reading flagged invalid at an airspeed below the hover blend while no unseen flow shows.

    A finite reading flagged invalid only because the airspeed is low (the pressure probe's q_inf
    floor, the probe's minimum airspeed) still says "the air is nearly still": use it. Below the
    hover-blend airspeed the aerodynamic columns of Phi are ~V^2 ~ 0, so C_Tz keeps adapting in
    hover instead of pausing whenever the fan is off. But the probe reads the same "invalid, near
    zero" with the flow outside its cone (wind from the side or behind), and taking that for still
    air made every adaptive law adapt on a regressor without the wind (issue #11). An unseen flow
    shows in the accelerometer: the body-horizontal prediction error (the model has no horizontal
    force in still air) is then large.
    """
    v_i = vec3(meas, L.MEAS_V_I_B)
    all_finite = plausible(v_i, np.inf)
    V_probe = np.sqrt(v_i[0] * v_i[0] + v_i[1] * v_i[1] + v_i[2] * v_i[2])
    probe_ok = meas[L.MEAS_V_I_VALID] == 1.0 and all_finite and V_probe <= params[P_VPROBE_MAX]
    if state[S_FILT_INIT] > 0.0:
        e_prev = physics_horizontal_error(params, state)
        e_h = np.sqrt(e_prev[0] * e_prev[0] + e_prev[1] * e_prev[1])
        if e_h > params[P_UNSEEN_ACCEL + 1]:
            state[S_UNSEEN_FLOW] = 1.0
        elif e_h < params[P_UNSEEN_ACCEL] and not state[S_FLOW_EST_ON] > 0.0:
            # (while the airflow estimate is on, e is small because v_i holds the estimated flow: the
            # estimate itself says when the flow is gone, in fallback_flow)
            state[S_UNSEEN_FLOW] = 0.0
    if (not probe_ok and meas[L.MEAS_V_I_VALID] == 0.0 and all_finite and V_probe < params[P_V_LO]
            and not state[S_UNSEEN_FLOW] > 0.0):
        probe_ok = True
    return probe_ok


@njit(cache=True, inline="always")
def follow_probe(state, R, v_W, v_i) -> None:
    """The probe is used: the wind estimate low-passes ``v - R v_i`` toward the probe's wind."""
    cw = state[S_GAINS + GAIN_WIND]
    v_i_probe_W = rows_times(R, v_i)
    for i in range(3):
        w_i = v_W[i] - v_i_probe_W[i]
        if state[S_HAVE_WIND] > 0.0:
            state[S_WIND_EST + i] = filters.lowpass(state[S_WIND_EST + i], w_i, cw)
        else:
            state[S_WIND_EST + i] = w_i
    state[S_HAVE_WIND] = 1.0
    state[S_FLOW_EST_ON] = 0.0


@njit(cache=True, inline="always")
def fallback_flow(params, state, R, v_W, accel_ok) -> tuple:
    """The probe is not used: ``v_i = R^T (v - w_hat)``, the wind estimate fading toward still air, or
    following the airflow estimated from the unexplained force (``unseen_flow_estimate``, module notes)."""
    est_ok = False
    if (params[P_FLOW_EST_ON] > 0.0 and state[S_UNSEEN_FLOW] > 0.0 and state[S_FILT_INIT] > 0.0
            and accel_ok):
        est_on = state[S_FLOW_EST_ON] > 0.0
        w0_N = state[S_FLOW_EST_W] if est_on else state[S_WIND_EST]
        w0_E = state[S_FLOW_EST_W + 1] if est_on else state[S_WIND_EST + 1]
        est_ok, w_N, w_E, _ = estimate_horizontal_wind(
            v_W, R, state[S_WIND_EST + 2], w0_N, w0_E, not est_on, state[S_U_EST], state[S_U_EST + 1],
            physics_theta(params, state), model_at(params, P_MODEL), state[int(params[A_A_M])],
            state[int(params[A_A_M]) + 1], params[P_UNSEEN_ACCEL], params[P_VPROBE_MAX], SIN_SIDESLIP_MAX)
        if est_ok:
            state[S_FLOW_EST_W], state[S_FLOW_EST_W + 1] = w_N, w_E
            c = state[S_GAINS + GAIN_FLOW_EST]
            state[S_WIND_EST] = filters.lowpass(state[S_WIND_EST], w_N, c)
            state[S_WIND_EST + 1] = filters.lowpass(state[S_WIND_EST + 1], w_E, c)
            state[S_WIND_EST + 2] = filters.flush_tiny(state[S_WIND_EST + 2] * state[S_GAINS + GAIN_FADE])
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
            state[S_WIND_EST + i] = filters.flush_tiny(state[S_WIND_EST + i] * fade)
    d = (v_W[0] - state[S_WIND_EST], v_W[1] - state[S_WIND_EST + 1], v_W[2] - state[S_WIND_EST + 2])
    return rows_transpose_times(R, d)


@njit(cache=True, inline="always")
def incident_velocity(params, state, meas, accel_ok) -> None:
    """Step 3 of the module notes: the tick's ``PROBE_OK`` and the input block's ``V_I_B``, ``V_I_VALID``."""
    t = S_TICK
    R = rows_at(state, t + T_R_WB)
    v_W = vec3(state, t + T_V_W)
    probe_ok = probe_usable(params, state, meas)
    if meas[L.MEAS_V_I_VALID] != 1.0:
        state[t + T_FAULTS] = int(state[t + T_FAULTS]) | FAULT_PROBE  # the sensor's own flag, even if used
    if probe_ok:
        v_i = vec3(meas, L.MEAS_V_I_B)
        follow_probe(state, R, v_W, v_i)
    else:
        state[t + T_FAULTS] = int(state[t + T_FAULTS]) | FAULT_PROBE
        v_i = fallback_flow(params, state, R, v_W, accel_ok)
    state[t + T_PROBE_OK] = 1.0 if probe_ok else 0.0
    put3(state, S_INPUT + IN_V_I_B, v_i)
    state[S_INPUT + IN_V_I_VALID] = 1.0 if probe_ok else 0.0


# --- 4. tracking errors ----------------------------------------------------------------------------

@njit(cache=True, inline="always")
def tracking_errors(params, state) -> None:
    """``p~``, ``v_r``, ``v_r'``, ``v~`` (eq:wr; ``|Lambda_p p~|`` and ``|v~|`` limited) into the tick."""
    t = S_TICK
    p_W = vec3(state, S_P_LAST)
    v_W = vec3(state, t + T_V_W)
    p_d = vec3(state, S_REF_LAST + L.REF_P_W)
    p_tilde = (p_W[0] - p_d[0], p_W[1] - p_d[1], p_W[2] - p_d[2])
    v_r, v_r_dot, _ = reference_velocity(p_tilde, vec3(state, S_REF_LAST + L.REF_V_W), vec3(state, t + T_A_D),
                                         v_W, vec3(params, P_LAMBDA_P), params[P_VCORR_MAX])
    v_tilde_raw = (v_W[0] - v_r[0], v_W[1] - v_r[1], v_W[2] - v_r[2])
    v_tilde, _ = limit_norm(v_tilde_raw, params[P_VERR_MAX])
    put3(state, t + T_P_TILDE, p_tilde)
    put3(state, t + T_V_R, v_r)
    put3(state, t + T_V_R_DOT, v_r_dot)
    put3(state, t + T_V_TILDE_RAW, v_tilde_raw)
    put3(state, t + T_V_TILDE, v_tilde)


# --- 5. regressor and filters ----------------------------------------------------------------------

@njit(cache=True, inline="always")
def basis_input(params, state) -> None:
    """The input block's throttles (through the nominal motor lag), attitude, rates, velocity and flow."""
    # The accelerometer feels the thrust of motors that lag their commands (30-40 ms): pass the
    # command held over the last interval through the vehicle's nominal lag, so that Phi uses the
    # throttles that produced the measured specific force (not the plant's true lag).
    if params[P_MOTOR_LAG_ON] > 0.0 and state[S_STEPS] >= 2.0:
        for j, gain in ((0, GAIN_MOTOR_X), (1, GAIN_MOTOR_Z)):
            a_lag = state[S_GAINS + gain]
            state[S_U_EST + j] = state[S_U_PREV + j] + (state[S_U_EST + j] - state[S_U_PREV + j]) * a_lag
    else:
        state[S_U_EST] = state[S_U_PREV]
        state[S_U_EST + 1] = state[S_U_PREV + 1]
    x = S_INPUT
    state[x + IN_U] = state[S_U_EST]
    state[x + IN_U + 1] = state[S_U_EST + 1]
    for i in range(4):
        state[x + IN_Q_WB + i] = state[S_Q_LAST + i]
    put3(state, x + IN_OMEGA_B, vec3(state, S_OMEGA_LAST))
    put3(state, x + IN_V_W, vec3(state, S_TICK + T_V_W))
    # the flow quantities (airspeed, angles, dynamic pressure) once: the allocation reuses them
    flow = incident_flow(vec3(state, x + IN_V_I_B), model_at(params, P_MODEL))
    for k in range(FLOW_SIZE):
        state[x + IN_FLOW + k] = flow[k]


@njit(cache=True)
def filter_regressor(state, wf, phi, c_f, n) -> None:
    """``W <- [Phi]_f``: one step of the low-pass on each of the 3 n entries."""
    for k in range(3 * n):
        state[wf + k] = filters.lowpass(state[wf + k], state[phi + k], c_f)


@njit(cache=True, inline="always")
def regressor_and_filters(fns, params, state, meas, accel_ok) -> None:
    """Step 5 of the module notes: ``Phi`` by the basis, ``W = [Phi]_f``, ``a_m``; the tick's ``MAY_ADAPT`` and ``E``."""
    t = S_TICK
    basis_input(params, state)
    n = int(params[A_N])
    phi = int(params[A_PHI])
    b, bw = int(params[A_BASIS]), int(params[A_BASIS_WORK])
    fns[1](params[b:b + int(params[A_BASIS_SIZE])], state[S_INPUT:S_INPUT + INPUT_SIZE],
           state[phi:phi + 3 * n], state[bw:bw + int(params[A_BASIS_WORK_SIZE])])
    wf = int(params[A_W])
    am = int(params[A_A_M])
    c_f = state[S_GAINS + GAIN_LOWPASS]
    if state[S_FILT_INIT] > 0.0:
        if n == ad.N_SLOT_0:
            filter_regressor(state, wf, phi, c_f, ad.N_SLOT_0)
        elif n == ad.N_SLOT_1:
            filter_regressor(state, wf, phi, c_f, ad.N_SLOT_1)
        elif n == ad.N_SLOT_2:
            filter_regressor(state, wf, phi, c_f, ad.N_SLOT_2)
        else:
            filter_regressor(state, wf, phi, c_f, n)
        if accel_ok:
            for r in range(3):
                state[am + r] = filters.lowpass(state[am + r], meas[L.MEAS_ACCEL_B + r], c_f)
    elif accel_ok and state[S_STEPS] >= 1.0:
        # start the filters from a sample whose regressor uses a command this controller issued
        for r in range(3):
            state[am + r] = meas[L.MEAS_ACCEL_B + r]
        for k in range(3 * n):
            state[wf + k] = state[phi + k]
        state[S_FILT_INIT] = 1.0
    probe_ok = state[t + T_PROBE_OK] > 0.0
    if probe_ok and accel_ok:
        state[S_VALID_TIME] += state[t + T_DT]
    else:
        state[S_VALID_TIME] = 0.0
    if accel_ok:
        state[S_ACCEL_VALID_TIME] += state[t + T_DT]
    else:
        state[S_ACCEL_VALID_TIME] = 0.0
    may_adapt = (state[S_FILT_INIT] > 0.0 and probe_ok and accel_ok
                 and state[S_VALID_TIME] >= params[P_HOLDOFF_S] - 1e-12)
    state[t + T_MAY_ADAPT] = 1.0 if may_adapt else 0.0
    # a law built on the accelerometer alone (INDI) needs the filter flushed, not the probe
    accel_usable = (state[S_FILT_INIT] > 0.0 and accel_ok
                    and state[S_ACCEL_VALID_TIME] >= params[P_HOLDOFF_S] - 1e-12)
    state[t + T_ACCEL_OK] = 1.0 if accel_usable else 0.0
    put3(state, t + T_E, prediction_error(params, state))


@njit(cache=True, inline="always")
def front_end(fns, params, state, meas, ref, dt) -> None:
    """Steps 1-5 of the module notes for one tick, into the tick block and the basis's input block."""
    check_dt(params, state, dt)
    accel_ok = sanitise_measurement(state, meas)
    sanitise_reference(state, ref)
    incident_velocity(params, state, meas, accel_ok)
    tracking_errors(params, state)
    regressor_and_filters(fns, params, state, meas, accel_ok)
