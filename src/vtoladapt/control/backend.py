"""The controller's back end, shared by every law: attitude, moment, allocation, output guard, diagnostics.

One call of :func:`back_end` per tick, after the law's update has written the force command
``f_r`` into the tick block (and updated theta-hat, if it adapts). Its named stages:

1. ``|f_r + g|`` limited (``accel_max_mps2``, :func:`limit_force`).
2. **Commanded heading and flow-angle protection** (:func:`heading`, :func:`flow_angle_protection`;
   :mod:`~vtoladapt.control.attitude` module notes): the heading
   weathervanes into the flow above ``weathervane_airspeed_mps`` and follows the reference yaw
   below, rate limited (while the probe cannot see the flow: against the force the physics columns
   leave unexplained, or into
   the front end's airflow estimate when ``unseen_flow_estimate`` has one); the probe's measured alpha beyond ``alpha_max`` (``alpha_min``) lowers
   (raises) the alpha_d limit through an integral trim.
3. **Desired attitude** (:func:`attitude`, :mod:`~vtoladapt.control.attitude`) and, if ``omega_d_feedforward`` is on (default off, see
   :mod:`~vtoladapt.control.settings`), ``omega_d``, ``omega_d'``: the desired frame's rate ``log(R_d,prev^T R_d)/dt``
   is limited to ``omega_d_max`` and passed through two cascaded first-order low-passes at
   ``omega_d_cutoff_hz``; ``omega_d`` is the second stage's output and ``omega_d'`` its exact
   derivative ``(x_1 - x_2) 2 pi f_c`` (a dirty derivative of a smoothed signal, limited to
   ``omega_d_dot_max``). The reference yaw rate is not used: the change of ``R_d`` already
   contains it.
4. **Moment command** (:func:`moment`, eq:wr, eq:m_ctrl) with the constrained quaternion error, limited per axis.
5. **Thruster allocation** at the current attitude with theta-hat's physics part (eq:f_proj,
   :func:`allocation`, :mod:`vtoladapt.control.allocation`). A basis's extra columns (after the paper's eight,
   :mod:`vtoladapt.bases`) predict a force ``W_extra theta_extra`` (the filtered regressor, at the throttles
   that produced the measured force): the desired attitude and the allocation take it as a known additive
   force, so the throttle solve follows only the physics columns' throttle dependence (:func:`extra_force`).
6. A non-finite command (:func:`output`) (impossible for finite sanitised inputs, but guarded) is replaced by the
   previous command and flagged.
7. The diagnostics (:data:`.blocks.SHARED_DIAG`, theta-hat; :func:`diagnostics`) other than the law's own.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .. import layout as L
from ..bases import IN_FLOW, IN_V_I_B, N_PHYSICS
from ..forces import F_ALPHA, F_V, I_CL0, I_CL1, model_at
from ..frames import GRAVITY_MPS2, quat_to_rotmat_rows, rows_times, rows_transpose_times
from . import filters
from .allocation import allocate_thrusters_at
from .attitude import (
    ALPHA_EXCESS_MAX_RAD,
    alpha_protection_step,
    desired_attitude_aligned,
    desired_frame_rate,
    heading_alignment_weight,
    heading_step,
    hover_blend_weight,
    measured_angle_of_attack,
)
from .blocks import (
    A_A_M, A_D_P_DIAG, A_D_THETA_HAT, A_N, A_P0, A_THETA, A_W, DIAG_A_M, DIAG_ADAPT_ACTIVE, DIAG_ALLOC_RES,
    DIAG_ALPHA_D, DIAG_ALPHA_LIMITS, DIAG_ALPHA_MEAS, DIAG_ALPHA_SPREAD, DIAG_AIRSPEED, DIAG_BLEND, DIAG_F_R,
    DIAG_FAULTS, DIAG_FLOW_EST_ON, DIAG_HEADING, DIAG_LYAP_Q, DIAG_LYAP_V, DIAG_OMEGA_D, DIAG_OMEGA_R,
    DIAG_P_TILDE, DIAG_PRED_ERR, DIAG_PROBE_VALID, DIAG_Q_D, DIAG_Q_TILDE, DIAG_SAT_X, DIAG_SAT_Z,
    DIAG_UNSEEN_FLOW, DIAG_V_I_USED, DIAG_V_R, DIAG_V_TILDE, DIAG_W_THETA, DIAG_WIND_EST, DIAG_WV_ON,
    FAULT_COMMAND, GAIN_OMEGA_D, P_ACC_MAX, P_ALIGN_COS, P_ALPHA_MAX, P_ALPHA_MIN, P_AP_GAIN, P_AP_SIGMAS,
    P_AP_SPREAD_TAU, P_AP_TAU, P_AP_TRIM_MAX, P_GAMMA_LYAP, P_HEADING_RATE, P_HEADING_TAU, P_J, P_K_OMEGA,
    P_LAMBDA_Q, P_LIFT_RESERVE, P_MIN_LIFT, P_MODEL, P_TAU_MAX, P_TILT_MAX, P_U_MAX, P_V_HI, P_V_LO,
    P_WD_DOT_MAX, P_WD_HZ, P_WD_MAX, P_WD_ON, P_WV_AIRSPEED, S_ALPHA_F, S_ALPHA_TRIM, S_ALPHA_VAR, S_FLOW_EST_ON,
    S_GAINS, S_HAVE_HEADING, S_HAVE_MEAS, S_HAVE_QD, S_HAVE_Y_I, S_HEADING, S_INPUT, S_OMEGA_LAST, S_Q_D_PREV,
    S_Q_LAST, S_RES_PREV_W, S_SAT_PREV, S_STEPS, S_TAU_PREV, S_TICK, S_TIME, S_TURN_SIGN, S_U_PREV,
    S_UNSEEN_FLOW, S_V_PREV, S_WD_X1, S_WD_X2, S_WIND_EST, S_WV_ON, S_Y_I_PREV, S_YAW_REF_PREV, T_ADAPT_ACTIVE,
    T_DT, T_E, T_F_R, T_FAULTS, T_LAW_FAULTS, T_P_TILDE, T_PROBE_OK, T_R_WB, T_V_R, T_V_TILDE_RAW, T_V_W,
    T_YAW_D,
)
from .frontend import physics_horizontal_error, physics_theta, plausible, put3, rows_at, vec3, wrap_angle
from .tracking import (
    limit_norm,
    moment_command,
    quat_error_from_quats,
    reference_angular_acceleration,
    reference_angular_rate,
)


@njit(cache=True, inline="always")
def default_law_diagnostics(params, diag) -> None:
    """``P_diag`` before the law runs: diag(P0) (an adaptive law overwrites it)."""
    n = int(params[A_N])
    p0 = int(params[A_P0])
    d = int(params[A_D_P_DIAG])
    for i in range(n):
        diag[d + i] = params[p0 + n * i + i]


@njit(cache=True)
def flow_of_input(state) -> tuple:
    """The flow quantities of this tick (:func:`vtoladapt.forces.incident_flow`) from the basis's input block."""
    f = S_INPUT + IN_FLOW
    return (state[f], state[f + 1], state[f + 2], state[f + 3], state[f + 4], state[f + 5], state[f + 6],
            state[f + 7], state[f + 8])


@njit(cache=True)
def extra_force(params, state) -> tuple:
    """``W_extra theta_extra``, body m/s^2: the force of the basis's columns after the physics ones, from the
    *filtered* regressor ``W = [Phi]_f`` (zero for the paper's basis, which has none).

    Why filtered (issue #34, defect 3): the extra columns are evaluated at the throttles that produced
    the measured force, i.e. at the allocation's own earlier commands. Taken at once as a known force
    (``Phi_extra theta_extra``), a column whose force grows with a throttle closes a loop through the
    allocation one tick long, with gain ``-r`` (``r`` the column's ``dF/du`` over the physics thrust
    slope; the learned network's pusher reaches r = 0.66-0.85): a barely damped oscillation of the
    throttle, unstable for ``r > 1``. Through ``[.]_f`` (gain ``c = 1 - exp(-2 pi f_c dt)``, 0.22 at
    10 Hz and 4 ms) the per-tick gain is ``1 - c (1 + r)``: the throttle solve follows only the physics
    columns' throttle dependence at the tick, and the extra force settles to the full model's fixed point
    (where ``Phi theta`` at the flown throttles is the command) within a few filter time constants, for any
    ``0 <= r < 2/c - 1`` (8 at the defaults). ``W`` is the same filtered regressor the prediction error and
    INDI's ``f_0`` use: the extra force the accelerometer is compared with, synchronised alike; and it costs
    nothing, ``W`` being formed every tick anyway. (Evaluating the extra columns a second time at a held
    throttle would cost a network evaluation per tick; bounding them would leave the loop's gain as it is.)"""
    n = int(params[A_N])
    phi = int(params[A_W])
    th = int(params[A_THETA])
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    for k in range(N_PHYSICS, n):
        th_k = state[th + k]
        f0 += state[phi + k] * th_k
        f1 += state[phi + n + k] * th_k
        f2 += state[phi + 2 * n + k] * th_k
    return (f0, f1, f2)


# --- 1. limit ----------------------------------------------------------------------------------------

@njit(cache=True, inline="always")
def limit_force(params, state) -> tuple:
    """The law's ``f_r`` with ``|f_r + g|`` limited (``accel_max_mps2``), written back into the tick."""
    f_r = vec3(state, S_TICK + T_F_R)
    f_r, _ = limit_norm((f_r[0], f_r[1], f_r[2] + GRAVITY_MPS2), params[P_ACC_MAX])
    f_r = (f_r[0], f_r[1], f_r[2] - GRAVITY_MPS2)
    put3(state, S_TICK + T_F_R, f_r)
    return f_r


# --- 2. heading and flow-angle protection ------------------------------------------------------------

@njit(cache=True, inline="always")
def heading(params, state, v_i, v_i_W, alpha_raw, probe_ok) -> tuple:
    """The commanded heading (into the flow above the weathervane airspeed, the reference yaw below; against
    the unexplained force while the probe cannot see the flow) and the filtered measured alpha.

    Returns ``(heading, alpha_m)``; both are kept in the state.
    """
    t = S_TICK
    dt = state[t + T_DT]
    yaw_d = state[t + T_YAW_D]
    V_h = np.sqrt(v_i_W[0] ** 2 + v_i_W[1] ** 2)
    if V_h > params[P_WV_AIRSPEED + 1]:
        state[S_WV_ON] = 1.0
    elif V_h < params[P_WV_AIRSPEED]:
        state[S_WV_ON] = 0.0
    if state[S_HAVE_HEADING] > 0.0:
        if not probe_ok and state[S_FLOW_EST_ON] > 0.0:
            # the airflow estimated from the unexplained force (frontend) is in v_i: nose into it
            target, ff = np.arctan2(v_i_W[1], v_i_W[0]), 0.0
        elif not probe_ok and state[S_UNSEEN_FLOW] > 0.0:
            # blind weathervane: the probe cannot see the flow, the unexplained body-horizontal force
            # (-e, downwind) can: turn the nose against it, until the flow enters the probe's cone
            # (of the physics columns: the force the physics leaves unexplained, whatever extra columns
            # the basis has; with the paper's basis it is e's, bit for bit)
            if int(params[A_N]) > N_PHYSICS:
                e_x, e_y = physics_horizontal_error(params, state)
            else:
                e_x, e_y = state[t + T_E], state[t + T_E + 1]
            e_W = rows_times(rows_at(state, t + T_R_WB), (e_x, e_y, 0.0))
            target, ff = np.arctan2(e_W[1], e_W[0]), 0.0
        elif state[S_WV_ON] > 0.0:
            target, ff = np.arctan2(v_i_W[1], v_i_W[0]), 0.0
        else:
            target, ff = yaw_d, wrap_angle(yaw_d - state[S_YAW_REF_PREV])
        psi, turn = heading_step(state[S_HEADING], state[S_TURN_SIGN], target, ff, dt,
                                 params[P_HEADING_TAU], params[P_HEADING_RATE])
        alpha_m = filters.lowpass(state[S_ALPHA_F], alpha_raw, dt / (params[P_AP_TAU] + dt))
    else:
        psi, turn = yaw_d, 0.0
        alpha_m = alpha_raw
    state[S_HEADING] = psi
    state[S_TURN_SIGN] = turn
    state[S_YAW_REF_PREV] = yaw_d
    state[S_HAVE_HEADING] = 1.0
    state[S_ALPHA_F] = alpha_m
    return psi, alpha_m


@njit(cache=True, inline="always")
def flow_angle_protection(params, state, v_i_W, V_W, airspeed, psi, alpha_raw, alpha_m, probe_ok) -> tuple:
    """The heading alignment weight and the alpha_d limits after the flow-angle protection.

    The measured alpha's upper (lower) envelope beyond the limits moves the alpha_d limits; the envelope
    is the filtered alpha +- n standard deviations of its fluctuation, estimated only while the wing flies
    (elsewhere alpha is not the wing's and the estimate fades). Returns ``(align, alpha_min_flown,
    alpha_max_flown, spread)``.
    """
    dt = state[S_TICK + T_DT]
    # the heading alignment weight serves the protection and the desired attitude: evaluated once, and
    # only if a hover-blend weight it multiplies can be nonzero (airspeed above V_lo)
    align = 0.0
    if V_W > params[P_V_LO] or (probe_ok and airspeed > params[P_V_LO]):
        align = heading_alignment_weight(v_i_W, psi, params[P_ALIGN_COS], params[P_ALIGN_COS + 1])
    w_wing = 0.0
    if probe_ok:
        w_wing = hover_blend_weight(airspeed, params[P_V_LO], params[P_V_HI])
        if w_wing > 0.0:
            w_wing *= align
    d_a = min(max(alpha_raw - alpha_m, -ALPHA_EXCESS_MAX_RAD), ALPHA_EXCESS_MAX_RAD)
    alpha_var = state[S_ALPHA_VAR]
    alpha_var = filters.flush_tiny(alpha_var + (w_wing * d_a * d_a - alpha_var) * dt / (params[P_AP_SPREAD_TAU] + dt))
    state[S_ALPHA_VAR] = alpha_var
    spread = np.sqrt(alpha_var)
    if probe_ok:
        state[S_ALPHA_TRIM], state[S_ALPHA_TRIM + 1] = alpha_protection_step(
            state[S_ALPHA_TRIM], state[S_ALPHA_TRIM + 1], alpha_m, params[P_ALPHA_MIN], params[P_ALPHA_MAX], w_wing,
            params[P_AP_GAIN], dt, params[P_AP_TRIM_MAX], params[P_AP_SIGMAS] * spread)
    return (align, params[P_ALPHA_MIN] - state[S_ALPHA_TRIM + 1], params[P_ALPHA_MAX] - state[S_ALPHA_TRIM],
            spread)


# --- 3. desired attitude ------------------------------------------------------------------------------

@njit(cache=True, inline="always")
def attitude(params, state, f_r, v_i_W, V_W, psi, align, alpha_min_flown, alpha_max_flown) -> tuple:
    """The desired attitude and, with the feed-forward on, the desired frame's rate and its derivative.

    Returns ``(q_d, alpha_d, w_blend, omega_d, omega_d_dot)``.
    """
    theta = physics_theta(params, state)
    q_d, y_i, alpha_d, w_blend, formed = desired_attitude_aligned(
        f_r, v_i_W, V_W, psi, theta[I_CL0], theta[I_CL1], params[P_MODEL], alpha_min_flown, alpha_max_flown,
        params[P_V_LO], params[P_V_HI], params[P_TILT_MAX], params[P_MIN_LIFT], vec3(state, S_Y_I_PREV),
        state[S_HAVE_Y_I] > 0.0, align, params[P_LIFT_RESERVE])
    if formed:
        state[S_Y_I_PREV], state[S_Y_I_PREV + 1], state[S_Y_I_PREV + 2] = y_i
        state[S_HAVE_Y_I] = 1.0
    if state[S_HAVE_QD] > 0.0 and params[P_WD_ON] > 0.0:
        q_d_prev = (state[S_Q_D_PREV], state[S_Q_D_PREV + 1], state[S_Q_D_PREV + 2], state[S_Q_D_PREV + 3])
        raw, _ = limit_norm(desired_frame_rate(q_d_prev, q_d, state[S_TICK + T_DT]), params[P_WD_MAX])
        c_w = state[S_GAINS + GAIN_OMEGA_D]
        for i in range(3):
            state[S_WD_X1 + i] = filters.lowpass(state[S_WD_X1 + i], raw[i], c_w)
            state[S_WD_X2 + i] = filters.lowpass(state[S_WD_X2 + i], state[S_WD_X1 + i], c_w)
    state[S_HAVE_QD] = 1.0
    for i in range(4):
        state[S_Q_D_PREV + i] = q_d[i]
    x1 = vec3(state, S_WD_X1)
    omega_d = vec3(state, S_WD_X2)
    k_wd = 2.0 * np.pi * params[P_WD_HZ]
    omega_d_dot, _ = limit_norm((k_wd * (x1[0] - omega_d[0]), k_wd * (x1[1] - omega_d[1]),
                                 k_wd * (x1[2] - omega_d[2])), params[P_WD_DOT_MAX])
    return q_d, alpha_d, w_blend, omega_d, omega_d_dot


# --- 4. moment ----------------------------------------------------------------------------------------

@njit(cache=True, inline="always")
def moment(params, state, q_d, omega_d, omega_d_dot) -> tuple:
    """eq:wr, eq:m_ctrl with the constrained quaternion error, limited per axis: ``(q_tilde, omega_r, tau)``."""
    q_WB = (state[S_Q_LAST], state[S_Q_LAST + 1], state[S_Q_LAST + 2], state[S_Q_LAST + 3])
    omega = vec3(state, S_OMEGA_LAST)
    q_tilde = quat_error_from_quats(q_d, q_WB)
    if params[P_WD_ON] > 0.0:
        # omega_d and its rate in body axes: R~^T omega_d, R~ = R_d^T R
        Rt = quat_to_rotmat_rows(q_tilde)
        omega_d_B = rows_transpose_times(Rt, omega_d)
        omega_d_dot_B = rows_transpose_times(Rt, omega_d_dot)
    else:
        # without the feed-forward omega_d = omega_d' = 0 in every frame
        omega_d_B = (0.0, 0.0, 0.0)
        omega_d_dot_B = (0.0, 0.0, 0.0)
    Lq = vec3(params, P_LAMBDA_Q)
    omega_r = reference_angular_rate(omega_d_B, q_tilde, Lq)
    omega_r_dot = reference_angular_acceleration(q_tilde, omega, omega_d_B, omega_d_dot_B, Lq)
    J = (vec3(params, P_J), vec3(params, P_J + 3), vec3(params, P_J + 6))
    tau = moment_command(J, omega, omega_r, omega_r_dot, vec3(params, P_K_OMEGA))
    tau = (min(max(tau[0], -params[P_TAU_MAX]), params[P_TAU_MAX]),
           min(max(tau[1], -params[P_TAU_MAX + 1]), params[P_TAU_MAX + 1]),
           min(max(tau[2], -params[P_TAU_MAX + 2]), params[P_TAU_MAX + 2]))
    return q_tilde, omega_r, tau


# --- 5. allocation ------------------------------------------------------------------------------------

@njit(cache=True, inline="always")
def allocation(params, state, f_r, f_x_B) -> tuple:
    """eq:f_proj at the current attitude with theta-hat's physics part; ``f_x_B`` (body) is the extra columns'
    known force. Returns ``(u_x, u_z, residual_B, sat_x, sat_z)``."""
    R = rows_at(state, S_TICK + T_R_WB)
    f_rb = rows_transpose_times(R, f_r)
    if int(params[A_N]) > N_PHYSICS:
        f_rb = (f_rb[0] - f_x_B[0], f_rb[1] - f_x_B[1], f_rb[2] - f_x_B[2])
    return allocate_thrusters_at(f_rb, flow_of_input(state), physics_theta(params, state), model_at(params, P_MODEL),
                                 params[P_U_MAX])


# --- 6. output ----------------------------------------------------------------------------------------

@njit(cache=True, inline="always")
def output(params, state, cmd, u_x, u_z, tau, res, sat_x, sat_z) -> int:
    """Write ``cmd`` (a non-finite one replaced by the previous command, flagged) and the state it leaves;
    returns the ``FAULT_COMMAND`` bit or 0."""
    fault = 0
    u_max = params[P_U_MAX]
    if not (np.isfinite(u_x) and np.isfinite(u_z) and plausible(tau, np.inf)):
        fault = FAULT_COMMAND
        u_x = state[S_U_PREV]
        u_z = state[S_U_PREV + 1]
        tau = vec3(state, S_TAU_PREV)
    cmd[L.CMD_U_X] = min(max(u_x, 0.0), u_max)
    cmd[L.CMD_U_Z] = min(max(u_z, 0.0), u_max)
    for i in range(3):
        cmd[L.CMD_TAU_B + i] = tau[i]
    state[S_U_PREV] = cmd[L.CMD_U_X]
    state[S_U_PREV + 1] = cmd[L.CMD_U_Z]
    res_W = rows_times(rows_at(state, S_TICK + T_R_WB), res)
    for i in range(3):
        state[S_TAU_PREV + i] = tau[i]
        state[S_RES_PREV_W + i] = res_W[i]
    state[S_SAT_PREV] = sat_x
    state[S_SAT_PREV + 1] = sat_z
    state[S_TIME] += state[S_TICK + T_DT]
    state[S_STEPS] += 1.0
    state[S_HAVE_MEAS] = 1.0
    return fault


# --- 7. diagnostics -----------------------------------------------------------------------------------

@njit(cache=True, inline="always")
def diagnostics(params, state, diag, faults, f_r, q_tilde, q_d, omega_d, omega_r, alpha_d, w_blend, res, sat_x,
                sat_z, psi, alpha_m, alpha_min_flown, alpha_max_flown, spread) -> None:
    """The shared diagnostics and theta-hat (the law wrote its own and P_diag)."""
    t = S_TICK
    am = int(params[A_A_M])
    v_tilde_raw = vec3(state, t + T_V_TILDE_RAW)
    for i in range(3):
        diag[DIAG_P_TILDE + i] = state[t + T_P_TILDE + i]
        diag[DIAG_V_TILDE + i] = v_tilde_raw[i]
        diag[DIAG_V_R + i] = state[t + T_V_R + i]
        diag[DIAG_F_R + i] = f_r[i]
        diag[DIAG_OMEGA_D + i] = omega_d[i]
        diag[DIAG_OMEGA_R + i] = omega_r[i]
        diag[DIAG_V_I_USED + i] = state[S_INPUT + IN_V_I_B + i]
        diag[DIAG_WIND_EST + i] = state[S_WIND_EST + i]
        e_i = state[t + T_E + i]
        diag[DIAG_PRED_ERR + i] = e_i
        diag[DIAG_A_M + i] = state[am + i]
        diag[DIAG_W_THETA + i] = e_i + state[am + i]
        diag[DIAG_ALLOC_RES + i] = res[i]
    for i in range(4):
        diag[DIAG_Q_TILDE + i] = q_tilde[i]
        diag[DIAG_Q_D + i] = q_d[i]
    diag[DIAG_ALPHA_D] = alpha_d
    diag[DIAG_AIRSPEED] = state[S_INPUT + IN_FLOW + F_V]
    diag[DIAG_BLEND] = w_blend
    n = int(params[A_N])
    th = int(params[A_THETA])
    d = int(params[A_D_THETA_HAT])
    for i in range(n):
        diag[d + i] = state[th + i]
    diag[DIAG_SAT_X] = sat_x
    diag[DIAG_SAT_Z] = sat_z
    diag[DIAG_PROBE_VALID] = state[t + T_PROBE_OK]
    diag[DIAG_ADAPT_ACTIVE] = state[t + T_ADAPT_ACTIVE]
    diag[DIAG_LYAP_V] = 0.5 * (v_tilde_raw[0] ** 2 + v_tilde_raw[1] ** 2 + v_tilde_raw[2] ** 2)
    diag[DIAG_LYAP_Q] = (2.0 - 2.0 * q_tilde[0]) / params[P_GAMMA_LYAP]
    diag[DIAG_FAULTS] = faults
    diag[DIAG_HEADING] = psi
    diag[DIAG_WV_ON] = state[S_WV_ON]
    diag[DIAG_ALPHA_MEAS] = alpha_m
    diag[DIAG_ALPHA_LIMITS] = alpha_min_flown
    diag[DIAG_ALPHA_LIMITS + 1] = alpha_max_flown
    diag[DIAG_ALPHA_SPREAD] = spread
    diag[DIAG_UNSEEN_FLOW] = state[S_UNSEEN_FLOW]
    diag[DIAG_FLOW_EST_ON] = state[S_FLOW_EST_ON]


@njit(cache=True, inline="always")
def back_end(params, state, cmd, diag) -> None:
    """Steps 1-7 of the module notes: writes ``cmd`` and ``diag``, updates the shared state."""
    t = S_TICK
    put3(state, S_V_PREV, vec3(state, t + T_V_W))
    probe_ok = state[t + T_PROBE_OK] > 0.0
    R = rows_at(state, t + T_R_WB)
    v_i = vec3(state, S_INPUT + IN_V_I_B)
    v_i_W = rows_times(R, v_i)
    flow = flow_of_input(state)
    airspeed = flow[F_V]
    f_r = limit_force(params, state)
    # the probe's alpha; in forward flow (v_ix > 0) it is the flow's atan2(v_iz, v_ix), already evaluated
    alpha_raw = flow[F_ALPHA] if v_i[0] > 0.0 else measured_angle_of_attack(v_i)
    psi, alpha_m = heading(params, state, v_i, v_i_W, alpha_raw, probe_ok)
    V_W = np.sqrt(v_i_W[0] ** 2 + v_i_W[1] ** 2 + v_i_W[2] ** 2)
    align, alpha_min_flown, alpha_max_flown, spread = flow_angle_protection(
        params, state, v_i_W, V_W, airspeed, psi, alpha_raw, alpha_m, probe_ok)
    # a basis's extra columns: a known force at this tick's regressor, left out of what the physics must give
    f_x_B = extra_force(params, state)
    f_phys = f_r
    if int(params[A_N]) > N_PHYSICS:
        f_x_W = rows_times(R, f_x_B)
        f_phys = (f_r[0] - f_x_W[0], f_r[1] - f_x_W[1], f_r[2] - f_x_W[2])
    q_d, alpha_d, w_blend, omega_d, omega_d_dot = attitude(params, state, f_phys, v_i_W, V_W, psi, align,
                                                           alpha_min_flown, alpha_max_flown)
    q_tilde, omega_r, tau = moment(params, state, q_d, omega_d, omega_d_dot)
    u_x, u_z, res, sat_x, sat_z = allocation(params, state, f_r, f_x_B)
    faults = int(state[t + T_FAULTS]) | int(state[t + T_LAW_FAULTS])
    faults |= output(params, state, cmd, u_x, u_z, tau, res, sat_x, sat_z)
    diagnostics(params, state, diag, faults, f_r, q_tilde, q_d, omega_d, omega_r, alpha_d, w_blend, res, sat_x,
                sat_z, psi, alpha_m, alpha_min_flown, alpha_max_flown, spread)
