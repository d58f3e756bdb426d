"""The compiled controller step: the shared front end, the law's update, the shared back end.

The simulator calls it every tick inside its compiled loop::

    controller_step(params, state, meas, ref, dt, cmd, diag)   # all float64 1-D arrays, dt float

* ``params``: from :func:`controller_params` (built once; the law is a number in it);
* ``state``: the controller's memory, from :func:`controller_initial_state`, updated in place;
* ``meas``: :mod:`vtoladapt.layout` ``MEAS_*``; ``ref``: ``REF_*``; ``cmd`` (output): ``CMD_*``
  (``u_x``, ``u_z`` as fractions, ``tau_B`` in N m); ``diag`` (output): named by
  :data:`CONTROLLER_DIAG_COLUMNS` (units in the names).

The step is a dispatcher: :func:`.frontend.front_end`, then the ``update`` of the law whose
registry index is in ``params``, then :func:`.backend.back_end`. The laws come from
:mod:`~vtoladapt.control.registry`; the loop over them is unrolled at compile time (``numba.literal_unroll`` over
the tuple of their compiled ``update`` functions), so the compiled step calls the chosen law
directly and holds no list of laws of its own. The array layouts are in :mod:`.layouts` (shared
blocks) and in each law's module (its own blocks); outside them use the accessors
(:func:`state_theta_hat`, :func:`state_P_inv`, :func:`state_P`, :func:`set_state_theta_hat`, ...).

The step is compiled without Numba's reference counting, as every kernel of the simulator's tick
(:mod:`vtoladapt.sim.loop`): a law's ``update`` must not allocate arrays (its scratch lives in
its state block, and values pass between functions as tuples).
"""
from __future__ import annotations

import warnings

import numpy as np
from numba import literal_unroll, njit

from . import adaptation as ad
from .backend import back_end, default_law_diagnostics
from .frontend import front_end
from .laws import LawContext, check_law
from .layouts import (  # noqa: F401  (the layout names are part of this module's interface)
    CONTROLLER_DIAG_COLUMNS, DIAG_A_M, DIAG_ADAPT_ACTIVE, DIAG_AIRSPEED, DIAG_ALLOC_RES, DIAG_ALPHA_D, DIAG_BLEND,
    DIAG_F_R, DIAG_FAULTS, DIAG_INTEGRATOR, DIAG_LYAP_Q, DIAG_LYAP_V, DIAG_OMEGA_D, DIAG_OMEGA_R, DIAG_P_DIAG,
    DIAG_P_TILDE, DIAG_PRED_ERR, DIAG_PROBE_VALID, DIAG_PROJ_ACTIVE, DIAG_Q_D, DIAG_Q_TILDE, DIAG_SAT_X,
    DIAG_SAT_Z, DIAG_THETA_HAT, DIAG_V_I_USED, DIAG_V_R, DIAG_V_TILDE, DIAG_W_THETA, DIAG_WIND_EST,
    DIAGNOSTICS, DIAG_SIZE, FAULT_ACCEL, FAULT_ADAPTATION, FAULT_ATTITUDE, FAULT_COMMAND, FAULT_DT,
    FAULT_GYRO, FAULT_POSITION, FAULT_PROBE, FAULT_REFERENCE, FAULT_VELOCITY, N_THETA, P_ACC_MAX, P_ALPHA_MAX,
    P_ALPHA_MIN, P_DT_NOMINAL, P_GAMMA0, P_GAMMA_LYAP, P_HOLDOFF_S, P_J, P_K_OMEGA, P_K_V, P_LAMBDA_P,
    P_LAMBDA_Q, P_LAW, P_LAW_INDEX, P_LOWER, P_LOWPASS_HZ, P_MIN_LIFT, P_MODEL, P_MOTOR_LAG_ON, P_MOTOR_TAU,
    P_P0, P_PRIOR, P_TAU_MAX, P_THETA0, P_THETA_INIT, P_TILT_MAX, P_U_MAX, P_UPPER, P_V_HI, P_V_LO,
    P_VCORR_MAX, P_VERR_MAX, P_VPROBE_MAX, P_WD_DOT_MAX, P_WD_HZ, P_WD_MAX, P_WD_ON, P_WIND_FADE, P_WIND_TAU,
    S_AM_F, S_GAINS, S_GAINS_DT, S_GAMMA, S_LAW, S_Q_D_PREV, S_Q_LAST, S_THETA, S_U_PREV, S_VALID_TIME, S_W_F,
    S_INFO_SUM, S_V_I_LAW, S_WIND_EST, SHARED_PARAMS, SHARED_STATE,
)
from .registry import CONTROLLERS, law_index

for _info in CONTROLLERS.values():
    check_law(_info.law)

_LAWS = tuple((i, info.law.update) for i, info in enumerate(CONTROLLERS.values()))
"""``(registry index, compiled update)`` per law: what :func:`controller_step` dispatches over."""

# literal_unroll's lowering compares the element types of this tuple (each law's update has its
# own Numba type) through the "first-class function" machinery, which warns that it is
# experimental although no function pointer is used: each law is called directly.
warnings.filterwarnings("ignore", message="First-class function type feature is experimental")


@njit(cache=True, _nrt=False)
def controller_step(params, state, meas, ref, dt, cmd, diag) -> None:
    """One controller tick: front end, the law's update, back end (see :mod:`vtoladapt.control`).

    Reads ``meas`` (``MEAS_*``) and ``ref`` (``REF_*``), writes ``cmd`` (``CMD_*``) and ``diag``
    (:data:`CONTROLLER_DIAG_COLUMNS`), updates ``state`` in place. ``dt`` (s) outside ``(0, 0.1]``
    or not finite is replaced (nominal rate, or 0.1 s) and flagged.
    """
    (dt, new_dt, faults, may_adapt, probe_ok, R, v_W, v_i, p_tilde, v_r, v_r_dot, v_tilde_raw, v_tilde, a_d, yaw_d,
     Phi, flow) = front_end(params, state, meas, ref, dt)
    default_law_diagnostics(params, diag)
    # the front end's fault bits of this tick, readable by the law (e.g. a velocity held by the
    # sanitiser); the back end overwrites the column with these and the law's own bits
    diag[DIAG_FAULTS] = faults
    # the flow the laws' model-validity measures read (the controller's own v_i, never the plant's)
    state[S_V_I_LAW] = v_i[0]
    state[S_V_I_LAW + 1] = v_i[1]
    state[S_V_I_LAW + 2] = v_i[2]
    f_r = (0.0, 0.0, 0.0)
    e = (0.0, 0.0, 0.0)
    adapt_active = False
    law_faults = 0
    k = int(params[P_LAW_INDEX])
    for law in literal_unroll(_LAWS):
        if law[0] == k:
            f_r, e, adapt_active, law_faults = law[1](params, state, diag, dt, new_dt, may_adapt, Phi, R, v_W,
                                                      v_r_dot, v_tilde, a_d)
    back_end(params, state, cmd, diag, dt, faults | law_faults, f_r, e, adapt_active, probe_ok, R, v_W, v_i,
             flow, p_tilde, v_r, v_tilde_raw, yaw_d)


# --- parameters and state from the configuration (Python, once per run) ---------------------------

def _vector(name: str, value, n: int = N_THETA) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} = {a.tolist()}: must be finite")
    return a


def theta_bound_half_widths(theta_0, theta_std, bound_fraction, bound_sigmas: float) -> np.ndarray:
    """Half-widths of the theta-hat box: ``max(bound_fraction |theta_0|, bound_sigmas |std|)``.

    :func:`theta_bounds` applies them (and the signs physics gives). Never narrower than ``1e-13 |theta_0|`` (1e-13 where theta_0 = 0): well above rounding, far
    below any real bound, so a degenerate setting cannot give a zero-width box that freezes
    theta-hat.
    """
    th0 = np.asarray(theta_0, dtype=float)
    half = np.maximum(np.asarray(bound_fraction, dtype=float) * np.abs(th0),
                      bound_sigmas * np.abs(np.asarray(theta_std, dtype=float)))
    return np.maximum(half, 1e-13 * np.where(th0 != 0.0, np.abs(th0), 1.0))


def theta_bounds(theta_0, theta_std, bound_fraction, bound_sigmas: float) -> tuple[np.ndarray, np.ndarray]:
    """Box bounds of theta-hat: ``theta_0 +- max(bound_fraction |theta_0|, bound_sigmas |std|)``
    (:func:`theta_bound_half_widths`), cut at zero where a coefficient's sign is known from physics
    (:func:`vtoladapt.vehicle.parameter_signs`): a non-negative one's lower bound is at least 0, a
    non-positive one's upper bound at most 0.

    The one rule for the bounds, whether theta_0 comes from the vehicle file or a fitted posterior.
    (Without the cut the caltech_vtol's ``bound_fraction`` 1.5 on C_S let theta-hat reach
    ``-0.5 theta_0``: a rotor side force along the flow.)
    """
    from ..vehicle import parameter_signs

    th0 = np.asarray(theta_0, dtype=float)
    half = theta_bound_half_widths(th0, theta_std, bound_fraction, bound_sigmas)
    signs = parameter_signs()
    lower = np.where(signs > 0, np.maximum(th0 - half, 0.0), th0 - half)
    upper = np.where(signs < 0, np.minimum(th0 + half, 0.0), th0 + half)
    return lower, upper


def default_theta_bounds(vehicle, theta_0=None, theta_std=None) -> tuple[np.ndarray, np.ndarray]:
    """Box bounds of theta-hat (:func:`theta_bounds`) with the vehicle's ``bound_fraction``, ``bound_sigmas``.

    ``std`` defaults to ``vehicle.theta_std_scaled`` (Table I), all in the adaptation scaling.
    """
    th0 = vehicle.theta_scaled if theta_0 is None else _vector("theta_0", theta_0)
    std = vehicle.theta_std_scaled if theta_std is None else _vector("theta_std", theta_std)
    return theta_bounds(th0, std, vehicle.adaptation.bound_fraction, vehicle.adaptation.bound_sigmas)


def controller_params(config, vehicle, theta_0=None, P0_diag=None, theta_lower=None, theta_upper=None,
                      theta_init=None) -> np.ndarray:
    """Kernel parameter array from a :class:`~.config.ControllerConfig` and the controller's vehicle model.

    The shared block (:data:`.layouts.SHARED_PARAMS`) followed by the law's own (its
    ``fill_params`` from its ``[controller.<kind>]`` settings).

    Parameters
    ----------
    config : ControllerConfig
    vehicle : Vehicle
        The controller's model of the aircraft (inertia, force model, limits), never the plant.
    theta_0 : array (8,), optional
        Prior mean (adaptation scaling); default ``vehicle.theta_scaled`` (Table I).
    P0_diag : array (8,) or (8, 8), optional
        Initial gain P0: its diagonal, or a full SPD matrix (a fitted posterior covariance);
        default ``vehicle.adaptation.P0_diag`` (Table III).
    theta_lower, theta_upper : array (8,), optional
        Bounds of theta-hat; default :func:`default_theta_bounds`.
    theta_init : array (8,), optional
        theta-hat at the start; default ``theta_0``; clipped into the bounds.

    Raises
    ------
    ValueError
        Naming the argument, if a shape, a value or the bounds are invalid.
    """
    th0 = vehicle.theta_scaled.copy() if theta_0 is None else _vector("theta_0", theta_0)
    P0 = np.asarray(vehicle.adaptation.P0_diag if P0_diag is None else P0_diag, dtype=float)
    if P0.shape == (N_THETA,):
        if not np.all(P0 > 0) or not np.all(np.isfinite(P0)):
            raise ValueError(f"P0_diag = {P0.tolist()}: every entry must be finite and > 0")
        P0 = np.diag(P0)
    elif P0.shape == (N_THETA, N_THETA):
        if not np.all(np.isfinite(P0)) or not np.allclose(P0, P0.T, rtol=1e-10, atol=0.0):
            raise ValueError("P0 (8x8) must be finite and symmetric")
        P0 = 0.5 * (P0 + P0.T)
        try:
            np.linalg.cholesky(P0)
        except np.linalg.LinAlgError:
            raise ValueError("P0 (8x8) must be positive definite") from None
    else:
        raise ValueError(f"P0_diag must have shape (8,) or (8, 8), got {P0.shape}")
    Gamma0 = np.linalg.inv(P0)
    Gamma0 = 0.5 * (Gamma0 + Gamma0.T)
    lo_d, hi_d = default_theta_bounds(vehicle, th0)
    lo = lo_d if theta_lower is None else _vector("theta_lower", theta_lower)
    hi = hi_d if theta_upper is None else _vector("theta_upper", theta_upper)
    if not np.all(lo < hi):
        raise ValueError(f"theta bounds: lower {lo.tolist()} must be below upper {hi.tolist()}")
    if not np.all((lo <= th0) & (th0 <= hi)):
        raise ValueError(f"theta_0 = {th0.tolist()} must lie within the bounds [{lo.tolist()}, {hi.tolist()}]")
    init = th0 if theta_init is None else _vector("theta_init", theta_init)
    init = np.clip(init, lo, hi)

    J = vehicle.mass.inertia_matrix
    if config.K_omega is not None:
        K_omega = np.array(config.K_omega, dtype=float)
    else:
        K_omega = np.diag(J) * np.array(config.rate_bandwidth_radps)
    alpha_max = np.radians(config.alpha_max_deg if config.alpha_max_deg is not None
                           else vehicle.envelope.alpha_max_deg)
    alpha_min = np.radians(config.alpha_min_deg) if config.alpha_min_deg is not None else -alpha_max
    if not alpha_min < alpha_max:
        raise ValueError(f"alpha_min_deg = {np.degrees(alpha_min)} must be below alpha_max "
                         f"{np.degrees(alpha_max)} deg")
    u_max = vehicle.actuators.throttle_max_pct / 100.0
    if config.torque_max_Nm is not None:
        tau_max = np.array(config.torque_max_Nm, dtype=float)
    else:
        T_rotor = vehicle.mass.mass_kg * vehicle.theta_scaled[1] / 4.0 * u_max * u_max
        xs = [abs(p[0]) for p in vehicle.geometry.lift_rotor_positions_m]
        ys = [abs(p[1]) for p in vehicle.geometry.lift_rotor_positions_m]
        tau_max = 2.0 * T_rotor * np.array([max(ys), max(xs), vehicle.actuators.yaw_torque_per_thrust_m])
    V_lo, V_hi = vehicle.envelope.hover_blend_airspeed_mps
    wv = config.weathervane_airspeed_mps if config.weathervane_airspeed_mps is not None else (0.75 * V_lo, V_lo)
    tol = np.radians(config.wing_heading_tolerance_deg)
    # the two trims together must leave alpha_min - trim_lo below alpha_max - trim_hi
    trim_max = min(np.radians(config.alpha_protect_trim_max_deg), 0.45 * (alpha_max - alpha_min))

    p = SHARED_PARAMS.pack(
        LAW_INDEX=law_index(config.kind), K_V=config.K_v, LAMBDA_P=config.Lambda_p, LAMBDA_Q=config.Lambda_q,
        K_OMEGA=K_omega, J=J.ravel(), MODEL=vehicle.model_kernel,
        PRIOR=ad.PRIOR.pack(THETA0=th0, THETA_INIT=init, LOWER=lo, UPPER=hi, GAMMA0=Gamma0.ravel(),
                            P0=P0.ravel()),
        LOWPASS_HZ=config.lowpass_cutoff_hz, GAMMA_LYAP=config.gamma, HOLDOFF_S=config.adaptation_holdoff_s,
        ALPHA_MIN=alpha_min, ALPHA_MAX=alpha_max, V_LO=V_lo, V_HI=V_hi, TILT_MAX=np.radians(config.tilt_max_deg),
        MIN_LIFT=config.min_lift_mps2, ACC_MAX=config.accel_max_mps2, VCORR_MAX=config.velocity_correction_max_mps,
        VERR_MAX=config.velocity_error_max_mps, WD_ON=1.0 if config.omega_d_feedforward else 0.0,
        WD_HZ=config.omega_d_cutoff_hz, WD_MAX=config.omega_d_max_radps, WD_DOT_MAX=config.omega_d_dot_max_radps2,
        TAU_MAX=tau_max, U_MAX=u_max, VPROBE_MAX=config.probe_airspeed_max_mps,
        WIND_TAU=config.wind_estimate_time_constant_s, WIND_FADE=config.wind_estimate_fade_s,
        DT_NOMINAL=1.0 / config.loop_rate_hz, MOTOR_LAG_ON=1.0 if config.regressor_motor_lag else 0.0,
        MOTOR_TAU=(vehicle.actuators.pusher_motor_time_constant_s, vehicle.actuators.lift_motor_time_constant_s),
        WV_AIRSPEED=wv, HEADING_TAU=config.heading_time_constant_s,
        HEADING_RATE=np.radians(config.heading_rate_max_degps), ALIGN_COS=(np.cos(tol[0]), np.cos(tol[1])),
        AP_GAIN=config.alpha_protect_gain_per_s, AP_TAU=1.0 / (2.0 * np.pi * config.alpha_protect_filter_hz),
        AP_TRIM_MAX=trim_max, AP_SIGMAS=config.alpha_protect_sigmas,
        AP_SPREAD_TAU=config.alpha_protect_spread_time_constant_s, UNSEEN_ACCEL=config.unseen_flow_accel_mps2,
        LIFT_RESERVE=config.lift_rotor_reserve_mps2, FLOW_EST_ON=1.0 if config.unseen_flow_estimate else 0.0,
        FLOW_EST_TAU=config.unseen_flow_estimate_time_constant_s)
    law = config.info.law
    ctx = LawContext(config=config, vehicle=vehicle, theta_0=th0, P0=P0, dt_nominal_s=1.0 / config.loop_rate_hz)
    own = np.asarray(law.fill_params(config.law_settings, ctx), dtype=float)
    if own.shape != (law.PARAMS.size,):
        raise ValueError(f"{law.__name__}.fill_params returned shape {own.shape}, its PARAMS need "
                         f"({law.PARAMS.size},)")
    return np.concatenate([p, own])


def law_of_params(params: np.ndarray):
    """The registry entry of the law a parameter array was built for."""
    return list(CONTROLLERS.values())[int(params[P_LAW_INDEX])]


def controller_initial_state(params) -> np.ndarray:
    """The controller's state before its first tick: theta-hat = theta_init, P = P0, filters empty.

    The shared block, then the law's own (zeros, then its ``init_state``).
    """
    law = law_of_params(params).law
    s = np.zeros(S_LAW + law.STATE.size)
    s[S_THETA:S_THETA + N_THETA] = params[P_THETA_INIT:P_THETA_INIT + N_THETA]
    s[S_GAMMA:S_GAMMA + N_THETA * N_THETA] = params[P_GAMMA0:P_GAMMA0 + N_THETA * N_THETA]
    s[S_Q_D_PREV] = 1.0
    s[S_Q_LAST] = 1.0
    # the filters start from the first sample, so no settling time is needed at start-up
    s[S_VALID_TIME] = params[P_HOLDOFF_S]
    law.init_state(params, s)
    return s


# --- state accessors (the shared block; a law's own fields: ControllerState.law_field) ------------

@njit(cache=True)
def state_theta_hat(state) -> np.ndarray:
    """theta-hat (8,) in the adaptation scaling (a view into ``state``)."""
    return state[S_THETA:S_THETA + N_THETA]


@njit(cache=True)
def set_state_theta_hat(state, theta) -> None:
    """Overwrite theta-hat (e.g. a random initial estimate); the caller keeps it inside the bounds."""
    for i in range(N_THETA):
        state[S_THETA + i] = theta[i]


def information_sum(state) -> np.ndarray:
    """The un-forgotten information ``sum w_pred W^T W dt`` (8, 8) the adaptive law accumulated (a copy).

    Zero for a law that never adapts; see :func:`vtoladapt.experiments.metrics.identifiability`.
    """
    return np.array(state[S_INFO_SUM:S_INFO_SUM + N_THETA * N_THETA]).reshape((N_THETA, N_THETA))


@njit(cache=True)
def state_P_inv(state) -> np.ndarray:
    """The information matrix ``P^-1`` (8, 8) (a view into ``state``)."""
    return state[S_GAMMA:S_GAMMA + N_THETA * N_THETA].reshape((N_THETA, N_THETA))


@njit(cache=True)
def state_P(state) -> np.ndarray:
    """The adaptation gain ``P`` (8, 8), from the information matrix by Cholesky (a new array)."""
    P = np.empty(N_THETA * N_THETA)
    if not ad.spd_inverse(state, S_GAMMA, P, 0, np.empty(2 * N_THETA * N_THETA), 0):
        P[:] = np.nan
    return P.reshape((N_THETA, N_THETA))


@njit(cache=True)
def state_filtered_accel(state) -> np.ndarray:
    """The filtered specific force a_m (3,), m/s^2 body (a view into ``state``)."""
    return state[S_AM_F:S_AM_F + 3]


@njit(cache=True)
def state_filtered_regressor(state) -> np.ndarray:
    """The filtered regressor W (3, 8) (a view into ``state``)."""
    return state[S_W_F:S_W_F + 3 * N_THETA].reshape((3, N_THETA))


@njit(cache=True)
def state_wind_estimate(state) -> np.ndarray:
    """The wind estimate (3,), m/s NED, used while the probe is invalid (a view into ``state``)."""
    return state[S_WIND_EST:S_WIND_EST + 3]


@njit(cache=True)
def state_last_command(state) -> np.ndarray:
    """Throttles ``[u_x, u_z]`` of the last command (a view into ``state``)."""
    return state[S_U_PREV:S_U_PREV + 2]


@njit(cache=True, inline="always")
def set_last_command(state, u_x, u_z) -> None:
    """Overwrite the throttles of the last command: what the adaptation's regressor takes as applied
    (a caller that changed the command after the controller computed it, as the gym's residual does)."""
    state[S_U_PREV] = u_x
    state[S_U_PREV + 1] = u_z


def state_law_field(state: np.ndarray, params: np.ndarray, name: str) -> np.ndarray:
    """Field ``name`` of the law's own state block (its ``STATE`` layout), as a view into ``state``."""
    layout = law_of_params(params).law.STATE
    o = S_LAW + layout.offset(name)
    return state[o:o + layout.field(name).size]


def state_integrator(state: np.ndarray) -> np.ndarray:
    """The PID's (and PD's) integral term (3,), m/s^2 NED (a view into a pid or pd ``state``)."""
    from .laws.pid import S_INT

    return state[S_INT:S_INT + 3]


__all__ = ["CONTROLLER_DIAG_COLUMNS", "DIAG_SIZE", "controller_initial_state", "controller_params",
           "controller_step", "default_theta_bounds", "information_sum", "law_of_params", "set_state_theta_hat", "state_P",
           "state_P_inv", "state_filtered_accel", "state_filtered_regressor", "state_integrator",
           "state_last_command", "set_last_command", "state_law_field", "state_theta_hat", "state_wind_estimate",
           "theta_bound_half_widths", "theta_bounds"]
