"""The controller's back end, shared by every law: attitude, moment, allocation, output guard, diagnostics.

One call of :func:`back_end` per tick, after the law's update has given the force command
``f_r`` (and updated theta-hat, if it adapts):

1. ``|f_r + g|`` limited (``accel_max_mps2``).
2. **Commanded heading and flow-angle protection** (:mod:`~vtoladapt.control.attitude` module notes): the heading
   weathervanes into the flow above ``weathervane_airspeed_mps`` and follows the reference yaw
   below, rate limited (while the probe cannot see the flow: against the unexplained force, or into
   the front end's airflow estimate when ``unseen_flow_estimate`` has one); the probe's measured alpha beyond ``alpha_max`` (``alpha_min``) lowers
   (raises) the alpha_d limit through an integral trim.
3. **Desired attitude** (:mod:`~vtoladapt.control.attitude`) and, if ``omega_d_feedforward`` is on (default off, see
   :mod:`~vtoladapt.control.config`), ``omega_d``, ``omega_d'``: the desired frame's rate ``log(R_d,prev^T R_d)/dt``
   is limited to ``omega_d_max`` and passed through two cascaded first-order low-passes at
   ``omega_d_cutoff_hz``; ``omega_d`` is the second stage's output and ``omega_d'`` its exact
   derivative ``(x_1 - x_2) 2 pi f_c`` (a dirty derivative of a smoothed signal, limited to
   ``omega_d_dot_max``). The reference yaw rate is not used: the change of ``R_d`` already
   contains it.
4. **Moment command** (eq:wr, eq:m_ctrl) with the constrained quaternion error, limited per axis.
5. **Thruster allocation** at the current attitude with theta-hat (eq:f_proj, :mod:`.allocation`).
6. A non-finite command (impossible for finite sanitised inputs, but guarded) is replaced by the
   previous command and flagged.
7. The diagnostics (:data:`.layouts.DIAGNOSTICS`) other than the law's own columns.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .. import layout as L
from ..forces import F_ALPHA, F_V, I_CL0, I_CL1, model_at, theta_at
from ..frames import GRAVITY_MPS2, quat_to_rotmat_rows, rows_times, rows_transpose_times
from . import adaptation as ad
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
from .frontend import plausible, vec3, wrap_angle
from .layouts import (
    DIAG_A_M, DIAG_ADAPT_ACTIVE, DIAG_ALLOC_RES, DIAG_ALPHA_D, DIAG_AIRSPEED, DIAG_BLEND, DIAG_F_R, DIAG_FAULTS,
    DIAG_INTEGRATOR, DIAG_LYAP_Q, DIAG_LYAP_V, DIAG_OMEGA_D, DIAG_OMEGA_R, DIAG_P_DIAG, DIAG_P_TILDE,
    DIAG_PRED_ERR, DIAG_PROBE_VALID, DIAG_PROJ_ACTIVE, DIAG_Q_D, DIAG_Q_TILDE, DIAG_SAT_X, DIAG_SAT_Z,
    DIAG_THETA_HAT, DIAG_V_I_USED, DIAG_V_R, DIAG_V_TILDE, DIAG_W_THETA, DIAG_WIND_EST, FAULT_COMMAND,
    GAIN_OMEGA_D, N_THETA, P_ACC_MAX, P_ALPHA_MAX, P_ALPHA_MIN, P_GAMMA_LYAP, P_J, P_K_OMEGA, P_LAMBDA_Q,
    P_MIN_LIFT, P_MODEL, P_P0, P_TAU_MAX, P_TILT_MAX, P_U_MAX, P_V_HI, P_V_LO, P_WD_DOT_MAX, P_WD_HZ,
    P_WD_MAX, P_WD_ON, S_AM_F, S_GAINS, S_HAVE_MEAS, S_HAVE_QD, S_HAVE_Y_I, S_OMEGA_LAST, S_Q_D_PREV, S_Q_LAST,
    S_RES_PREV_W, S_SAT_PREV, S_STEPS, S_TAU_PREV, S_THETA, S_TIME, S_U_PREV, S_V_PREV, S_WD_X1, S_WD_X2,
    S_WIND_EST, S_Y_I_PREV, DIAG_HEADING, DIAG_WV_ON, DIAG_ALPHA_MEAS, DIAG_ALPHA_LIMITS, P_ALIGN_COS, P_AP_GAIN,
    P_AP_TAU, P_AP_TRIM_MAX, P_HEADING_RATE, P_HEADING_TAU, P_WV_AIRSPEED, S_ALPHA_F, S_ALPHA_TRIM, S_HAVE_HEADING,
    S_HEADING, S_TURN_SIGN, S_WV_ON, S_YAW_REF_PREV, DIAG_ALPHA_SPREAD, DIAG_UNSEEN_FLOW, P_AP_SIGMAS, P_AP_SPREAD_TAU,
    S_ALPHA_VAR, S_UNSEEN_FLOW, P_LIFT_RESERVE, S_FLOW_EST_ON, DIAG_FLOW_EST_ON,
)
from .tracking import (
    limit_norm,
    moment_command,
    quat_error_from_quats,
    reference_angular_acceleration,
    reference_angular_rate,
)


@njit(cache=True, inline="always")
def default_law_diagnostics(params, diag) -> None:
    """The law-owned columns before the law runs: ``P_diag`` = diag(P0), no active bound, no integral."""
    for i in range(N_THETA):
        diag[DIAG_P_DIAG + i] = params[P_P0 + N_THETA * i + i]
    diag[DIAG_PROJ_ACTIVE] = 0.0
    for i in range(3):
        diag[DIAG_INTEGRATOR + i] = 0.0


@njit(cache=True, inline="always")
def back_end(params, state, cmd, diag, dt, faults, f_r, e, adapt_active, probe_ok, R, v_W, v_i, flow, p_tilde,
             v_r, v_tilde_raw, yaw_d) -> None:
    """Steps 1-7 of the module notes: writes ``cmd`` and ``diag``, updates the shared state.

    ``flow`` is :func:`vtoladapt.forces.incident_flow` of ``v_i`` (the front end's): the airspeed, the
    angle of attack and the allocation's flow quantities are read from it, not evaluated again.
    """
    for i in range(3):
        state[S_V_PREV + i] = v_W[i]
    u_max = params[P_U_MAX]
    theta = theta_at(state, S_THETA)
    model = model_at(params, P_MODEL)
    q_WB = (state[S_Q_LAST], state[S_Q_LAST + 1], state[S_Q_LAST + 2], state[S_Q_LAST + 3])
    omega = vec3(state, S_OMEGA_LAST)
    v_i_W = rows_times(R, v_i)
    airspeed = flow[F_V]

    # 1. |f_r + g| limited
    f_r, _ = limit_norm((f_r[0], f_r[1], f_r[2] + GRAVITY_MPS2), params[P_ACC_MAX])
    f_r = (f_r[0], f_r[1], f_r[2] - GRAVITY_MPS2)

    # 2. commanded heading: into the flow above the weathervane airspeed, the reference yaw below
    V_h = np.sqrt(v_i_W[0] ** 2 + v_i_W[1] ** 2)
    if V_h > params[P_WV_AIRSPEED + 1]:
        state[S_WV_ON] = 1.0
    elif V_h < params[P_WV_AIRSPEED]:
        state[S_WV_ON] = 0.0
    # the probe's alpha; in forward flow (v_ix > 0) it is the flow's atan2(v_iz, v_ix), already evaluated
    alpha_raw = flow[F_ALPHA] if v_i[0] > 0.0 else measured_angle_of_attack(v_i)
    if state[S_HAVE_HEADING] > 0.0:
        if not probe_ok and state[S_FLOW_EST_ON] > 0.0:
            # the airflow estimated from the unexplained force (frontend) is in v_i: nose into it
            target, ff = np.arctan2(v_i_W[1], v_i_W[0]), 0.0
        elif not probe_ok and state[S_UNSEEN_FLOW] > 0.0:
            # blind weathervane: the probe cannot see the flow, the unexplained body-horizontal force
            # (-e, downwind) can: turn the nose against it, until the flow enters the probe's cone
            e_W = rows_times(R, (e[0], e[1], 0.0))
            target, ff = np.arctan2(e_W[1], e_W[0]), 0.0
        elif state[S_WV_ON] > 0.0:
            target, ff = np.arctan2(v_i_W[1], v_i_W[0]), 0.0
        else:
            target, ff = yaw_d, wrap_angle(yaw_d - state[S_YAW_REF_PREV])
        heading, turn = heading_step(state[S_HEADING], state[S_TURN_SIGN], target, ff, dt,
                                     params[P_HEADING_TAU], params[P_HEADING_RATE])
        alpha_m = ad.lowpass(state[S_ALPHA_F], alpha_raw, dt / (params[P_AP_TAU] + dt))
    else:
        heading, turn = yaw_d, 0.0
        alpha_m = alpha_raw
    state[S_HEADING] = heading
    state[S_TURN_SIGN] = turn
    state[S_YAW_REF_PREV] = yaw_d
    state[S_HAVE_HEADING] = 1.0
    state[S_ALPHA_F] = alpha_m
    # the heading alignment weight serves the flow-angle protection and the desired attitude (step 3):
    # evaluated once, and only if a hover-blend weight it multiplies can be nonzero (airspeed above V_lo)
    V_W = np.sqrt(v_i_W[0] ** 2 + v_i_W[1] ** 2 + v_i_W[2] ** 2)
    align = 0.0
    if V_W > params[P_V_LO] or (probe_ok and airspeed > params[P_V_LO]):
        align = heading_alignment_weight(v_i_W, heading, params[P_ALIGN_COS], params[P_ALIGN_COS + 1])
    # flow-angle protection: the measured alpha's upper (lower) envelope beyond the limits moves the
    # alpha_d limits; the envelope is the filtered alpha +- n standard deviations of its fluctuation,
    # estimated only while the wing flies (elsewhere alpha is not the wing's and the estimate fades)
    w_wing = 0.0
    if probe_ok:
        w_wing = hover_blend_weight(airspeed, params[P_V_LO], params[P_V_HI])
        if w_wing > 0.0:
            w_wing *= align
    d_a = min(max(alpha_raw - alpha_m, -ALPHA_EXCESS_MAX_RAD), ALPHA_EXCESS_MAX_RAD)
    alpha_var = state[S_ALPHA_VAR]
    alpha_var = ad.flush_tiny(alpha_var + (w_wing * d_a * d_a - alpha_var) * dt / (params[P_AP_SPREAD_TAU] + dt))
    state[S_ALPHA_VAR] = alpha_var
    spread = np.sqrt(alpha_var)
    if probe_ok:
        state[S_ALPHA_TRIM], state[S_ALPHA_TRIM + 1] = alpha_protection_step(
            state[S_ALPHA_TRIM], state[S_ALPHA_TRIM + 1], alpha_m, params[P_ALPHA_MIN], params[P_ALPHA_MAX], w_wing,
            params[P_AP_GAIN], dt, params[P_AP_TRIM_MAX], params[P_AP_SIGMAS] * spread)
    alpha_max_flown = params[P_ALPHA_MAX] - state[S_ALPHA_TRIM]
    alpha_min_flown = params[P_ALPHA_MIN] - state[S_ALPHA_TRIM + 1]

    # 3. desired attitude and the desired frame's rate
    q_d, y_i, alpha_d, w_blend, formed = desired_attitude_aligned(
        f_r, v_i_W, V_W, heading, theta[I_CL0], theta[I_CL1], model[0], alpha_min_flown, alpha_max_flown,
        params[P_V_LO], params[P_V_HI], params[P_TILT_MAX], params[P_MIN_LIFT], vec3(state, S_Y_I_PREV),
        state[S_HAVE_Y_I] > 0.0, align, params[P_LIFT_RESERVE])
    if formed:
        state[S_Y_I_PREV], state[S_Y_I_PREV + 1], state[S_Y_I_PREV + 2] = y_i
        state[S_HAVE_Y_I] = 1.0
    if state[S_HAVE_QD] > 0.0 and params[P_WD_ON] > 0.0:
        q_d_prev = (state[S_Q_D_PREV], state[S_Q_D_PREV + 1], state[S_Q_D_PREV + 2], state[S_Q_D_PREV + 3])
        raw, _ = limit_norm(desired_frame_rate(q_d_prev, q_d, dt), params[P_WD_MAX])
        c_w = state[S_GAINS + GAIN_OMEGA_D]
        for i in range(3):
            state[S_WD_X1 + i] = ad.lowpass(state[S_WD_X1 + i], raw[i], c_w)
            state[S_WD_X2 + i] = ad.lowpass(state[S_WD_X2 + i], state[S_WD_X1 + i], c_w)
    state[S_HAVE_QD] = 1.0
    for i in range(4):
        state[S_Q_D_PREV + i] = q_d[i]
    x1 = vec3(state, S_WD_X1)
    omega_d = vec3(state, S_WD_X2)
    k_wd = 2.0 * np.pi * params[P_WD_HZ]
    omega_d_dot, _ = limit_norm((k_wd * (x1[0] - omega_d[0]), k_wd * (x1[1] - omega_d[1]),
                                 k_wd * (x1[2] - omega_d[2])), params[P_WD_DOT_MAX])

    # 4. moment command (eq:wr, eq:m_ctrl)
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

    # 5. thruster allocation at the current attitude (eq:f_proj)
    f_rb = rows_transpose_times(R, f_r)
    u_x, u_z, res, sat_x, sat_z = allocate_thrusters_at(f_rb, flow, theta, model, u_max)

    # 6. output, with a last guard against non-finite values
    if not (np.isfinite(u_x) and np.isfinite(u_z) and plausible(tau, np.inf)):
        faults |= FAULT_COMMAND
        u_x = state[S_U_PREV]
        u_z = state[S_U_PREV + 1]
        tau = vec3(state, S_TAU_PREV)
    cmd[L.CMD_U_X] = min(max(u_x, 0.0), u_max)
    cmd[L.CMD_U_Z] = min(max(u_z, 0.0), u_max)
    for i in range(3):
        cmd[L.CMD_TAU_B + i] = tau[i]
    state[S_U_PREV] = cmd[L.CMD_U_X]
    state[S_U_PREV + 1] = cmd[L.CMD_U_Z]
    res_W = rows_times(R, res)
    for i in range(3):
        state[S_TAU_PREV + i] = tau[i]
        state[S_RES_PREV_W + i] = res_W[i]
    state[S_SAT_PREV] = sat_x
    state[S_SAT_PREV + 1] = sat_z
    state[S_TIME] += dt
    state[S_STEPS] += 1.0
    state[S_HAVE_MEAS] = 1.0

    # 7. diagnostics
    for i in range(3):
        diag[DIAG_P_TILDE + i] = p_tilde[i]
        diag[DIAG_V_TILDE + i] = v_tilde_raw[i]
        diag[DIAG_V_R + i] = v_r[i]
        diag[DIAG_F_R + i] = f_r[i]
        diag[DIAG_OMEGA_D + i] = omega_d[i]
        diag[DIAG_OMEGA_R + i] = omega_r[i]
        diag[DIAG_V_I_USED + i] = v_i[i]
        diag[DIAG_WIND_EST + i] = state[S_WIND_EST + i]
        diag[DIAG_PRED_ERR + i] = e[i]
        diag[DIAG_A_M + i] = state[S_AM_F + i]
        diag[DIAG_W_THETA + i] = e[i] + state[S_AM_F + i]
        diag[DIAG_ALLOC_RES + i] = res[i]
    for i in range(4):
        diag[DIAG_Q_TILDE + i] = q_tilde[i]
        diag[DIAG_Q_D + i] = q_d[i]
    diag[DIAG_ALPHA_D] = alpha_d
    diag[DIAG_AIRSPEED] = airspeed
    diag[DIAG_BLEND] = w_blend
    for i in range(N_THETA):
        diag[DIAG_THETA_HAT + i] = theta[i]
    diag[DIAG_SAT_X] = sat_x
    diag[DIAG_SAT_Z] = sat_z
    diag[DIAG_PROBE_VALID] = 1.0 if probe_ok else 0.0
    diag[DIAG_ADAPT_ACTIVE] = 1.0 if adapt_active else 0.0
    diag[DIAG_LYAP_V] = 0.5 * (v_tilde_raw[0] ** 2 + v_tilde_raw[1] ** 2 + v_tilde_raw[2] ** 2)
    diag[DIAG_LYAP_Q] = (2.0 - 2.0 * q_tilde[0]) / params[P_GAMMA_LYAP]
    diag[DIAG_FAULTS] = faults
    diag[DIAG_HEADING] = heading
    diag[DIAG_WV_ON] = state[S_WV_ON]
    diag[DIAG_ALPHA_MEAS] = alpha_m
    diag[DIAG_ALPHA_LIMITS] = alpha_min_flown
    diag[DIAG_ALPHA_LIMITS + 1] = alpha_max_flown
    diag[DIAG_ALPHA_SPREAD] = spread
    diag[DIAG_UNSEEN_FLOW] = state[S_UNSEEN_FLOW]
    diag[DIAG_FLOW_EST_ON] = state[S_FLOW_EST_ON]
