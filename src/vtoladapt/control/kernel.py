"""The compiled controller step and the layouts of its parameter, state and diagnostics arrays.

One kernel serves all five controllers; the simulator calls it every tick inside its compiled
loop::

    controller_step(params, state, meas, ref, dt, cmd, diag)   # all float64 1-D arrays, dt float

* ``params``: from :func:`controller_params` (built once; the controller kind is a number in it);
* ``state``: the controller's memory, from :func:`controller_initial_state`, updated in place;
* ``meas``: :mod:`vtoladapt.layout` ``MEAS_*``; ``ref``: ``REF_*``; ``cmd`` (output): ``CMD_*``
  (``u_x``, ``u_z`` as fractions, ``tau_B`` in N m); ``diag`` (output): named by
  :data:`CONTROLLER_DIAG_COLUMNS` (units in the names).

The ``P_*``, ``S_*`` and ``DIAG_*`` offsets below are the only place these layouts are written
down; outside this module use the accessors (:func:`state_theta_hat`, :func:`state_P_inv`,
:func:`state_P`, :func:`set_state_theta_hat`, ...) and the column names.

One tick, in order
------------------
1. **Sanitise the measurement and reference.** Each group (position, velocity, attitude, gyro,
   accelerometer, probe; reference position, velocity, acceleration, yaw) that is non-finite or
   implausible is replaced by its last good value and flagged in ``diag['fault_flags']``; the
   gyro is clipped to +-35 rad/s (a real gyro's range).
2. **Incident velocity.** The probe's ``v_i`` is used if ``meas[MEAS_V_I_VALID] == 1``, finite and
   below ``probe_airspeed_max_mps``; a finite reading flagged invalid only for a low airspeed
   (below the vehicle's hover-blend airspeed) is used too, since it still measures still air.
   Otherwise the fallback is ``v_i = R^T (v - w_hat)`` with
   ``w_hat`` the wind estimate ``v - R v_i`` low-passed (``wind_estimate_time_constant_s``) while
   the probe was valid, fading toward still air (``wind_estimate_fade_s``) while it is not: a
   short dropout keeps the wind, a long outage (a probe that reads "invalid" at low airspeed
   after the wind stopped) does not fly the wing solution in still air. ``diag['probe_valid_used']``
   says which.
3. **Tracking errors** ``p~``, ``v_r``, ``v~`` (eq:wr; ``|Lambda_p p~|`` and ``|v~|`` limited).
4. **Adaptation** (:mod:`.adaptation`): filters, prediction error, theta-hat and P. The regressor
   uses the current ``v_i`` and the throttles commanded for the interval that just ended, passed
   through the vehicle's nominal motor lag (``regressor_motor_lag``: what produced the measured
   specific force). Paused (theta-hat and P frozen, filters still running)
   while the probe or the accelerometer is invalid and for ``adaptation_holdoff_s`` after.
5. **Force command** ``f_r`` (eq:f_ctrl; PID/PD: PX4 form, see below), ``|f_r + g|`` limited.
6. **Desired attitude** (:mod:`.attitude`) and, if ``omega_d_feedforward`` is on (default off, see
   :mod:`.config`), ``omega_d``, ``omega_d'``: the desired frame's rate
   ``log(R_d,prev^T R_d)/dt`` is limited to ``omega_d_max`` and passed through two cascaded
   first-order low-passes at ``omega_d_cutoff_hz``; ``omega_d`` is the second stage's output and
   ``omega_d'`` its exact derivative ``(x_1 - x_2) 2 pi f_c`` (a dirty derivative of a smoothed
   signal, limited to ``omega_d_dot_max``). The reference yaw rate is not used: the change of
   ``R_d`` already contains it.
7. **Moment command** (eq:wr, eq:m_ctrl) with the constrained quaternion error, limited per axis.
8. **Thruster allocation** at the current attitude (eq:f_proj, :mod:`.allocation`).
9. A non-finite command (impossible for finite sanitised inputs, but guarded) is replaced by the
   previous command and flagged.

The baselines (PX4 multicopter velocity control)
------------------------------------------------
``pid``/``pd``: velocity setpoint ``v_sp = v_r`` (PX4's position P loop with feed-forward);
``acc_sp = K_v (v_sp - v) + I - K_D a_f`` with the integral ``I' = K_I (v_sp - v)`` and the
derivative on the measurement (``a_f``: the measured velocity differenced and low-passed at
``derivative_cutoff_hz``); ``f_r = -g + a_d + acc_sp``. Anti-windup: ``I`` is clamped per axis, and
an axis is frozen while the allocation saturated on the previous tick and integrating would
push further into the unachieved force (``(v_sp - v)_i (R residual)_i > 0``). Then the same
desired attitude, allocation and moment law, with theta-hat = theta_0 constant.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .. import layout as L
from ..forces import I_CL0, I_CL1, regressor
from ..frames import GRAVITY_MPS2, euler_from_quat, quat_to_rotmat
from ..vehicle import PARAMETER_NAMES
from . import adaptation as ad
from .allocation import allocate_thrusters
from .attitude import desired_attitude, desired_frame_rate
from .config import CONTROLLER_KINDS
from .tracking import (
    force_command,
    limit_norm,
    moment_command,
    quat_error_from_quats,
    reference_angular_acceleration,
    reference_angular_rate,
    reference_velocity,
)

N_THETA = 8

KIND_COMPOSITE, KIND_COMPOSITE_PCONST, KIND_TRACKING_ONLY, KIND_PID, KIND_PD = range(5)
assert CONTROLLER_KINDS == ("composite", "composite_pconst", "tracking_only", "pid", "pd")

GYRO_RANGE_RADPS = 35.0
POSITION_PLAUSIBLE_M = 1e6
VELOCITY_PLAUSIBLE_MPS = 1e3
ACCEL_PLAUSIBLE_MPS2 = 1e3

# fault bits in diag['fault_flags']
FAULT_POSITION = 1
FAULT_VELOCITY = 2
FAULT_ATTITUDE = 4
FAULT_GYRO = 8
FAULT_ACCEL = 16
FAULT_PROBE = 32
FAULT_REFERENCE = 64
FAULT_COMMAND = 128
FAULT_ADAPTATION = 256
FAULT_DT = 512


class _Offsets:
    def __init__(self):
        self.n = 0

    def take(self, size: int) -> int:
        off = self.n
        self.n += size
        return off


# --- params layout -------------------------------------------------------------------------------
_p = _Offsets()
P_KIND = _p.take(1)
P_ADAPT_MODE = _p.take(1)
P_K_V = _p.take(3)
P_LAMBDA_P = _p.take(3)
P_LAMBDA_Q = _p.take(3)
P_K_OMEGA = _p.take(3)
P_K_I = _p.take(3)
P_K_D = _p.take(3)
P_INT_LIMIT = _p.take(3)
P_J = _p.take(9)
P_MODEL = _p.take(3)
P_PRIOR = _p.take(ad.PRIOR_SIZE)        # the adaptation's prior (adaptation.PRIOR_* layout):
P_THETA0 = P_PRIOR + ad.PRIOR_THETA0    #   theta_0
P_THETA_INIT = P_PRIOR + ad.PRIOR_THETA_INIT
P_LOWER = P_PRIOR + ad.PRIOR_LOWER      #   bounds of theta-hat
P_UPPER = P_PRIOR + ad.PRIOR_UPPER
P_GAMMA0 = P_PRIOR + ad.PRIOR_GAMMA0    #   P0^-1, row-major
P_P0 = P_PRIOR + ad.PRIOR_P0            #   P0, row-major
P_LAMBDA = _p.take(1)
P_SIGMA = _p.take(1)
P_LOWPASS_HZ = _p.take(1)
P_GAMMA_LYAP = _p.take(1)
P_TRACE_MAX = _p.take(1)
P_HOLDOFF_S = _p.take(1)
P_ALPHA_MIN = _p.take(1)
P_ALPHA_MAX = _p.take(1)
P_V_LO = _p.take(1)
P_V_HI = _p.take(1)
P_TILT_MAX = _p.take(1)
P_MIN_LIFT = _p.take(1)
P_ACC_MAX = _p.take(1)
P_VCORR_MAX = _p.take(1)
P_VERR_MAX = _p.take(1)
P_WD_ON = _p.take(1)
P_WD_HZ = _p.take(1)
P_WD_MAX = _p.take(1)
P_WD_DOT_MAX = _p.take(1)
P_TAU_MAX = _p.take(3)
P_U_MAX = _p.take(1)
P_VPROBE_MAX = _p.take(1)
P_WIND_TAU = _p.take(1)
P_WIND_FADE = _p.take(1)
P_DERIV_HZ = _p.take(1)
P_DT_NOMINAL = _p.take(1)
P_MOTOR_LAG_ON = _p.take(1)
P_MOTOR_TAU = _p.take(2)                # nominal motor time constants: pusher, lift (s)
P_SIZE = _p.n

# --- state layout --------------------------------------------------------------------------------
_s = _Offsets()
S_ADAPT = _s.take(ad.MEM_SIZE)          # the adaptation's memory (adaptation.MEM_* layout):
S_THETA = S_ADAPT + ad.MEM_THETA        #   theta-hat
S_GAMMA = S_ADAPT + ad.MEM_GAMMA        #   information matrix P^-1, row-major
S_W_F = S_ADAPT + ad.MEM_W              #   filtered regressor W = [Phi]_f, row-major
S_AM_F = S_ADAPT + ad.MEM_A_M           #   filtered specific force a_m, body
S_FILT_INIT = _s.take(1)
S_INT = _s.take(3)                      # PID integral term, m/s^2 NED
S_V_PREV = _s.take(3)
S_VDOT_F = _s.take(3)
S_VDOT_INIT = _s.take(1)
S_U_PREV = _s.take(2)                   # throttles commanded for the current interval
S_TAU_PREV = _s.take(3)
S_Q_D_PREV = _s.take(4)
S_WD_X1 = _s.take(3)
S_WD_X2 = _s.take(3)
S_HAVE_QD = _s.take(1)
S_Y_I_PREV = _s.take(3)
S_HAVE_Y_I = _s.take(1)
S_WIND_EST = _s.take(3)
S_HAVE_WIND = _s.take(1)
S_VALID_TIME = _s.take(1)               # time the probe and accelerometer have been valid, s
S_P_LAST = _s.take(3)
S_V_LAST = _s.take(3)
S_Q_LAST = _s.take(4)
S_OMEGA_LAST = _s.take(3)
S_HAVE_MEAS = _s.take(1)
S_REF_LAST = _s.take(L.REF_SIZE)
S_HAVE_REF = _s.take(1)
S_SAT_PREV = _s.take(2)
S_RES_PREV_W = _s.take(3)
S_TIME = _s.take(1)
S_STEPS = _s.take(1)
S_U_EST = _s.take(2)                    # throttles the motors are estimated to deliver (nominal lag)
# The filter and lag gains depend only on dt and the parameters: they are computed when dt changes
# (every tick of the Python API, whose dt jitters by rounding; once per run in the simulator).
GAIN_LOWPASS, GAIN_WIND, GAIN_FADE, GAIN_MOTOR_X, GAIN_MOTOR_Z, GAIN_OMEGA_D, GAIN_DERIV, GAIN_FORGET_A, \
    GAIN_FORGET_B = range(9)
S_GAINS_DT = _s.take(1)                 # the dt (s) the gains were computed for; 0: not yet
S_GAINS = _s.take(9)                    # the gains, GAIN_* order
S_ACTIVE_SET = _s.take(1)               # bit mask of the bounds the last projection held
S_WORK = _s.take(ad.WORK_SIZE)          # the adaptation's scratch (no meaning between ticks)
S_SIZE = _s.n

# --- diagnostics layout --------------------------------------------------------------------------
_DIAG_SPEC = (
    ("P_TILDE", ("p_tilde_N_m", "p_tilde_E_m", "p_tilde_D_m")),
    ("V_TILDE", ("v_tilde_N_mps", "v_tilde_E_mps", "v_tilde_D_mps")),
    ("V_R", ("v_r_N_mps", "v_r_E_mps", "v_r_D_mps")),
    ("Q_TILDE", ("q_tilde_0", "q_tilde_x", "q_tilde_y", "q_tilde_z")),
    ("F_R", ("f_r_N_mps2", "f_r_E_mps2", "f_r_D_mps2")),
    ("Q_D", ("q_d_w", "q_d_x", "q_d_y", "q_d_z")),
    ("OMEGA_D", ("omega_d_x_radps", "omega_d_y_radps", "omega_d_z_radps")),
    ("OMEGA_R", ("omega_r_x_radps", "omega_r_y_radps", "omega_r_z_radps")),
    ("ALPHA_D", ("alpha_d_rad",)),
    ("AIRSPEED", ("ctrl_airspeed_mps",)),
    ("BLEND", ("blend_weight_wing",)),
    ("V_I_USED", ("ctrl_v_i_x_mps", "ctrl_v_i_y_mps", "ctrl_v_i_z_mps")),
    ("WIND_EST", ("wind_est_N_mps", "wind_est_E_mps", "wind_est_D_mps")),
    ("THETA_HAT", tuple(f"theta_hat_{n}" for n in PARAMETER_NAMES)),
    ("P_DIAG", tuple(f"P_diag_{n}" for n in PARAMETER_NAMES)),
    ("PRED_ERR", ("pred_err_x_mps2", "pred_err_y_mps2", "pred_err_z_mps2")),
    ("A_M", ("a_m_x_mps2", "a_m_y_mps2", "a_m_z_mps2")),
    ("W_THETA", ("W_theta_x_mps2", "W_theta_y_mps2", "W_theta_z_mps2")),
    ("ALLOC_RES", ("alloc_residual_x_mps2", "alloc_residual_y_mps2", "alloc_residual_z_mps2")),
    ("SAT_X", ("sat_u_x",)),
    ("SAT_Z", ("sat_u_z",)),
    ("PROBE_VALID", ("probe_valid_used",)),
    ("ADAPT_ACTIVE", ("adaptation_active",)),
    ("PROJ_ACTIVE", ("projection_active_bounds",)),
    ("LYAP_V", ("lyap_velocity_term_m2ps2",)),
    ("LYAP_Q", ("lyap_attitude_term",)),
    ("INTEGRATOR", ("integrator_N_mps2", "integrator_E_mps2", "integrator_D_mps2")),
    ("FAULTS", ("fault_flags",)),
)
_d = _Offsets()
_DIAG_SIZES = dict((name, len(cols)) for name, cols in _DIAG_SPEC)
DIAG_P_TILDE = _d.take(_DIAG_SIZES["P_TILDE"])
DIAG_V_TILDE = _d.take(_DIAG_SIZES["V_TILDE"])
DIAG_V_R = _d.take(_DIAG_SIZES["V_R"])
DIAG_Q_TILDE = _d.take(_DIAG_SIZES["Q_TILDE"])
DIAG_F_R = _d.take(_DIAG_SIZES["F_R"])
DIAG_Q_D = _d.take(_DIAG_SIZES["Q_D"])
DIAG_OMEGA_D = _d.take(_DIAG_SIZES["OMEGA_D"])
DIAG_OMEGA_R = _d.take(_DIAG_SIZES["OMEGA_R"])
DIAG_ALPHA_D = _d.take(_DIAG_SIZES["ALPHA_D"])
DIAG_AIRSPEED = _d.take(_DIAG_SIZES["AIRSPEED"])
DIAG_BLEND = _d.take(_DIAG_SIZES["BLEND"])
DIAG_V_I_USED = _d.take(_DIAG_SIZES["V_I_USED"])
DIAG_WIND_EST = _d.take(_DIAG_SIZES["WIND_EST"])
DIAG_THETA_HAT = _d.take(_DIAG_SIZES["THETA_HAT"])
DIAG_P_DIAG = _d.take(_DIAG_SIZES["P_DIAG"])
DIAG_PRED_ERR = _d.take(_DIAG_SIZES["PRED_ERR"])
DIAG_A_M = _d.take(_DIAG_SIZES["A_M"])
DIAG_W_THETA = _d.take(_DIAG_SIZES["W_THETA"])
DIAG_ALLOC_RES = _d.take(_DIAG_SIZES["ALLOC_RES"])
DIAG_SAT_X = _d.take(_DIAG_SIZES["SAT_X"])
DIAG_SAT_Z = _d.take(_DIAG_SIZES["SAT_Z"])
DIAG_PROBE_VALID = _d.take(_DIAG_SIZES["PROBE_VALID"])
DIAG_ADAPT_ACTIVE = _d.take(_DIAG_SIZES["ADAPT_ACTIVE"])
DIAG_PROJ_ACTIVE = _d.take(_DIAG_SIZES["PROJ_ACTIVE"])
DIAG_LYAP_V = _d.take(_DIAG_SIZES["LYAP_V"])
DIAG_LYAP_Q = _d.take(_DIAG_SIZES["LYAP_Q"])
DIAG_INTEGRATOR = _d.take(_DIAG_SIZES["INTEGRATOR"])
DIAG_FAULTS = _d.take(_DIAG_SIZES["FAULTS"])
DIAG_SIZE = _d.n
CONTROLLER_DIAG_COLUMNS: tuple[str, ...] = tuple(c for _, cols in _DIAG_SPEC for c in cols)
"""Names of the ``diag`` entries, in order, with units in the names. ``sat_u_*``: -1 (throttle at
0, the row wanted the other sign), +1 (at the limit), 0; ``fault_flags``: sum of the ``FAULT_*``
bits of this module; ``lyap_*``: the tracking terms of the Lyapunov function (the parameter
term needs the truth, see :func:`vtoladapt.control.adaptation.lyapunov_function`)."""
assert len(CONTROLLER_DIAG_COLUMNS) == DIAG_SIZE
assert tuple(n for n, _ in _DIAG_SPEC) == tuple(
    name[len("DIAG_"):] for name, _ in sorted(
        ((n, v) for n, v in globals().items() if n.startswith("DIAG_") and n != "DIAG_SIZE"),
        key=lambda kv: kv[1])), "DIAG_* offsets out of order"

_ADAPT_MODE_OF_KIND = (ad.ADAPT_COMPOSITE, ad.ADAPT_PCONST, ad.ADAPT_TRACKING, ad.ADAPT_NONE, ad.ADAPT_NONE)


# --- conversion from the configuration (Python, once per run) ------------------------------------

def _vector(name: str, value, n: int = N_THETA) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} = {a.tolist()}: must be finite")
    return a


def theta_bound_half_widths(theta_0, theta_std, bound_fraction, bound_sigmas: float) -> np.ndarray:
    """Half-widths of the theta-hat box: ``max(bound_fraction |theta_0|, bound_sigmas |std|)``.

    The one rule for the bounds, whether theta_0 comes from the vehicle file or a fitted posterior.
    Never narrower than ``1e-13 |theta_0|`` (1e-13 where theta_0 = 0): well above rounding, far
    below any real bound, so a degenerate setting cannot give a zero-width box that freezes
    theta-hat.
    """
    th0 = np.asarray(theta_0, dtype=float)
    half = np.maximum(np.asarray(bound_fraction, dtype=float) * np.abs(th0),
                      bound_sigmas * np.abs(np.asarray(theta_std, dtype=float)))
    return np.maximum(half, 1e-13 * np.where(th0 != 0.0, np.abs(th0), 1.0))


def default_theta_bounds(vehicle, theta_0=None, theta_std=None) -> tuple[np.ndarray, np.ndarray]:
    """Box bounds of theta-hat: ``theta_0 +- max(bound_fraction |theta_0|, bound_sigmas std)``.

    ``bound_fraction``, ``bound_sigmas`` from ``vehicle.adaptation``; ``std`` defaults to
    ``vehicle.theta_std_scaled`` (Table I), all in the adaptation scaling
    (:func:`theta_bound_half_widths`).
    """
    th0 = vehicle.theta_scaled if theta_0 is None else _vector("theta_0", theta_0)
    std = vehicle.theta_std_scaled if theta_std is None else _vector("theta_std", theta_std)
    half = theta_bound_half_widths(th0, std, vehicle.adaptation.bound_fraction,
                                   vehicle.adaptation.bound_sigmas)
    return th0 - half, th0 + half


def controller_params(config, vehicle, theta_0=None, P0_diag=None, theta_lower=None, theta_upper=None,
                      theta_init=None) -> np.ndarray:
    """Kernel parameter array from a :class:`~.config.ControllerConfig` and the controller's vehicle model.

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
    lam_max_P0 = float(np.linalg.eigvalsh(P0).max())
    if config.sigma * lam_max_P0 / config.loop_rate_hz >= 1.0:
        raise ValueError(f"sigma = {config.sigma}: the explicit sigma step needs sigma * max eig(P0) * dt < 1, "
                         f"here {config.sigma * lam_max_P0 / config.loop_rate_hz:.3g}; lower sigma or P0")
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

    p = np.zeros(P_SIZE)
    p[P_KIND] = config.kind_id
    p[P_ADAPT_MODE] = _ADAPT_MODE_OF_KIND[config.kind_id]
    p[P_K_V:P_K_V + 3] = config.K_v
    p[P_LAMBDA_P:P_LAMBDA_P + 3] = config.Lambda_p
    p[P_LAMBDA_Q:P_LAMBDA_Q + 3] = config.Lambda_q
    p[P_K_OMEGA:P_K_OMEGA + 3] = K_omega
    p[P_K_I:P_K_I + 3] = config.K_I if config.kind == "pid" else (0.0, 0.0, 0.0)
    p[P_K_D:P_K_D + 3] = config.K_D
    p[P_INT_LIMIT:P_INT_LIMIT + 3] = config.integrator_limit_mps2
    p[P_J:P_J + 9] = J.ravel()
    p[P_MODEL:P_MODEL + 3] = vehicle.model_kernel
    p[P_THETA0:P_THETA0 + N_THETA] = th0
    p[P_THETA_INIT:P_THETA_INIT + N_THETA] = init
    p[P_LOWER:P_LOWER + N_THETA] = lo
    p[P_UPPER:P_UPPER + N_THETA] = hi
    p[P_GAMMA0:P_GAMMA0 + N_THETA ** 2] = Gamma0.ravel()
    p[P_P0:P_P0 + N_THETA ** 2] = P0.ravel()
    p[P_LAMBDA] = config.forgetting_lambda
    p[P_SIGMA] = config.sigma
    p[P_LOWPASS_HZ] = config.lowpass_cutoff_hz
    p[P_GAMMA_LYAP] = config.gamma
    p[P_TRACE_MAX] = config.information_trace_max
    p[P_HOLDOFF_S] = config.adaptation_holdoff_s
    p[P_ALPHA_MIN] = alpha_min
    p[P_ALPHA_MAX] = alpha_max
    p[P_V_LO] = V_lo
    p[P_V_HI] = V_hi
    p[P_TILT_MAX] = np.radians(config.tilt_max_deg)
    p[P_MIN_LIFT] = config.min_lift_mps2
    p[P_ACC_MAX] = config.accel_max_mps2
    p[P_VCORR_MAX] = config.velocity_correction_max_mps
    p[P_VERR_MAX] = config.velocity_error_max_mps
    p[P_WD_ON] = 1.0 if config.omega_d_feedforward else 0.0
    p[P_WD_HZ] = config.omega_d_cutoff_hz
    p[P_WD_MAX] = config.omega_d_max_radps
    p[P_WD_DOT_MAX] = config.omega_d_dot_max_radps2
    p[P_TAU_MAX:P_TAU_MAX + 3] = tau_max
    p[P_U_MAX] = u_max
    p[P_VPROBE_MAX] = config.probe_airspeed_max_mps
    p[P_WIND_TAU] = config.wind_estimate_time_constant_s
    p[P_WIND_FADE] = config.wind_estimate_fade_s
    p[P_DERIV_HZ] = config.derivative_cutoff_hz
    p[P_DT_NOMINAL] = 1.0 / config.loop_rate_hz
    p[P_MOTOR_LAG_ON] = 1.0 if config.regressor_motor_lag else 0.0
    p[P_MOTOR_TAU] = vehicle.actuators.pusher_motor_time_constant_s
    p[P_MOTOR_TAU + 1] = vehicle.actuators.lift_motor_time_constant_s
    return p


# --- state ---------------------------------------------------------------------------------------

@njit(cache=True)
def controller_initial_state(params) -> np.ndarray:
    """The controller's state before its first tick: theta-hat = theta_init, P = P0, filters empty."""
    s = np.zeros(S_SIZE)
    for i in range(N_THETA):
        s[S_THETA + i] = params[P_THETA_INIT + i]
    for i in range(N_THETA * N_THETA):
        s[S_GAMMA + i] = params[P_GAMMA0 + i]
    s[S_Q_D_PREV] = 1.0
    s[S_Q_LAST] = 1.0
    # the filters start from the first sample, so no settling time is needed at start-up
    s[S_VALID_TIME] = params[P_HOLDOFF_S]
    return s


@njit(cache=True)
def state_theta_hat(state) -> np.ndarray:
    """theta-hat (8,) in the adaptation scaling (a view into ``state``)."""
    return state[S_THETA:S_THETA + N_THETA]


@njit(cache=True)
def set_state_theta_hat(state, theta) -> None:
    """Overwrite theta-hat (e.g. a random initial estimate); the caller keeps it inside the bounds."""
    for i in range(N_THETA):
        state[S_THETA + i] = theta[i]


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
def state_integrator(state) -> np.ndarray:
    """The PID integral term (3,), m/s^2 NED (a view into ``state``)."""
    return state[S_INT:S_INT + 3]


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


# --- the step --------------------------------------------------------------------------------------
# The step reads its arrays by offset into scalars and tuples and calls kernels that take and
# return those: an array view handed to a compiled function costs two atomic reference-count
# updates (about 30 ns here); the only arrays it passes on are params and state, to the adaptation.

@njit(cache=True)
def _vec3(a, o) -> tuple:
    return (a[o], a[o + 1], a[o + 2])


@njit(cache=True)
def _plausible(x, bound) -> bool:
    """Every entry of the tuple ``x`` finite and within ``+-bound`` (``bound = inf``: finite)."""
    ok = True
    for i in range(len(x)):
        ok = ok and np.isfinite(x[i]) and abs(x[i]) <= bound
    return ok


@njit(cache=True)
def _rotation_rows(q) -> tuple:
    """``R(q)`` (:func:`vtoladapt.frames.quat_to_rotmat`) as three row 3-tuples."""
    R = quat_to_rotmat(q)
    return ((R[0, 0], R[0, 1], R[0, 2]), (R[1, 0], R[1, 1], R[1, 2]), (R[2, 0], R[2, 1], R[2, 2]))


@njit(cache=True)
def _rows_times(R, v) -> tuple:
    """``R v`` for ``R`` as three row 3-tuples (body to world for ``R_WB``)."""
    return (R[0][0] * v[0] + R[0][1] * v[1] + R[0][2] * v[2],
            R[1][0] * v[0] + R[1][1] * v[1] + R[1][2] * v[2],
            R[2][0] * v[0] + R[2][1] * v[1] + R[2][2] * v[2])


@njit(cache=True)
def _rows_transpose_times(R, v) -> tuple:
    """``R^T v`` for ``R`` as three row 3-tuples (world to body for ``R_WB``)."""
    return (R[0][0] * v[0] + R[1][0] * v[1] + R[2][0] * v[2],
            R[0][1] * v[0] + R[1][1] * v[1] + R[2][1] * v[2],
            R[0][2] * v[0] + R[1][2] * v[1] + R[2][2] * v[2])


@njit(cache=True)
def _wrap_angle(a) -> float:
    """``a`` in (-pi, pi] (unchanged if already there)."""
    if -np.pi < a <= np.pi:
        return a
    return np.arctan2(np.sin(a), np.cos(a))


@njit(cache=True)
def _update_gains(params, state, dt) -> None:
    """Store the gains of the filters and lags for a tick of ``dt`` (``GAIN_*``) in ``state``."""
    g = S_GAINS
    state[g + GAIN_LOWPASS] = ad.lowpass_gain(params[P_LOWPASS_HZ], dt)
    state[g + GAIN_WIND] = 1.0 - np.exp(-dt / params[P_WIND_TAU])
    state[g + GAIN_FADE] = np.exp(-dt / params[P_WIND_FADE])
    state[g + GAIN_MOTOR_X] = np.exp(-dt / params[P_MOTOR_TAU])
    state[g + GAIN_MOTOR_Z] = np.exp(-dt / params[P_MOTOR_TAU + 1])
    state[g + GAIN_OMEGA_D] = ad.lowpass_gain(params[P_WD_HZ], dt)
    state[g + GAIN_DERIV] = ad.lowpass_gain(params[P_DERIV_HZ], dt)
    state[g + GAIN_FORGET_A], state[g + GAIN_FORGET_B] = ad.forgetting_weights(params[P_LAMBDA], dt)
    state[S_GAINS_DT] = dt


@njit(cache=True)
def _pid_force(params, state, kind, v_W, v_tilde, a_d, dt) -> tuple:
    """The baselines' force command ``f_r`` (PX4 velocity control, see the module notes), m/s^2 NED."""
    if state[S_VDOT_INIT] > 0.0:
        c_d = state[S_GAINS + GAIN_DERIV]
        for i in range(3):
            state[S_VDOT_F + i] = ad.lowpass(state[S_VDOT_F + i], (v_W[i] - state[S_V_PREV + i]) / dt, c_d)
    state[S_VDOT_INIT] = 1.0
    saturated = state[S_SAT_PREV] != 0.0 or state[S_SAT_PREV + 1] != 0.0
    v_err = (-v_tilde[0], -v_tilde[1], -v_tilde[2])
    if kind == KIND_PID:
        for i in range(3):
            frozen = saturated and v_err[i] * state[S_RES_PREV_W + i] > 0.0
            if not frozen:
                lim = params[P_INT_LIMIT + i]
                state[S_INT + i] = min(max(state[S_INT + i] + params[P_K_I + i] * v_err[i] * dt, -lim), lim)
    return (a_d[0] + params[P_K_V] * v_err[0] + state[S_INT] - params[P_K_D] * state[S_VDOT_F],
            a_d[1] + params[P_K_V + 1] * v_err[1] + state[S_INT + 1] - params[P_K_D + 1] * state[S_VDOT_F + 1],
            a_d[2] + params[P_K_V + 2] * v_err[2] + state[S_INT + 2] - params[P_K_D + 2] * state[S_VDOT_F + 2]
            - GRAVITY_MPS2)


@njit(cache=True)
def controller_step(params, state, meas, ref, dt, cmd, diag) -> None:
    """One controller tick (see the module notes).

    Reads ``meas`` (``MEAS_*``) and ``ref`` (``REF_*``), writes ``cmd`` (``CMD_*``) and ``diag``
    (:data:`CONTROLLER_DIAG_COLUMNS`), updates ``state`` in place. ``dt`` (s) outside ``(0, 0.1]``
    or not finite is replaced (nominal rate, or 0.1 s) and flagged.
    """
    kind = int(params[P_KIND])
    mode = int(params[P_ADAPT_MODE])
    faults = 0
    if not (dt > 0.0 and dt <= 0.1):
        faults |= FAULT_DT
        dt = params[P_DT_NOMINAL] if not dt > 0.1 else 0.1
    if not state[S_GAINS_DT] == dt:
        _update_gains(params, state, dt)
    u_max = params[P_U_MAX]

    # 1. sanitise the measurement: every group falls back to its last good value
    x = _vec3(meas, L.MEAS_P_W)
    if _plausible(x, POSITION_PLAUSIBLE_M):
        state[S_P_LAST], state[S_P_LAST + 1], state[S_P_LAST + 2] = x
    else:
        faults |= FAULT_POSITION
    x = _vec3(meas, L.MEAS_V_W)
    if _plausible(x, VELOCITY_PLAUSIBLE_MPS):
        state[S_V_LAST], state[S_V_LAST + 1], state[S_V_LAST + 2] = x
    else:
        faults |= FAULT_VELOCITY
    q = (meas[L.MEAS_Q_WB], meas[L.MEAS_Q_WB + 1], meas[L.MEAS_Q_WB + 2], meas[L.MEAS_Q_WB + 3])
    qn = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) if _plausible(q, np.inf) else 0.0
    if 0.5 < qn < 1.5:
        for i in range(4):
            state[S_Q_LAST + i] = q[i] / qn
    else:
        faults |= FAULT_ATTITUDE
    x = _vec3(meas, L.MEAS_OMEGA_B)
    if _plausible(x, np.inf):
        for i in range(3):
            state[S_OMEGA_LAST + i] = min(max(x[i], -GYRO_RANGE_RADPS), GYRO_RANGE_RADPS)
    else:
        faults |= FAULT_GYRO
    accel = _vec3(meas, L.MEAS_ACCEL_B)
    accel_ok = _plausible(accel, ACCEL_PLAUSIBLE_MPS2)
    if not accel_ok:
        faults |= FAULT_ACCEL
    p_W = _vec3(state, S_P_LAST)
    v_W = _vec3(state, S_V_LAST)
    q_WB = (state[S_Q_LAST], state[S_Q_LAST + 1], state[S_Q_LAST + 2], state[S_Q_LAST + 3])
    omega = _vec3(state, S_OMEGA_LAST)
    R = _rotation_rows(q_WB)

    # sanitise the reference (groups: position, velocity, acceleration, yaw)
    have_ref = state[S_HAVE_REF] > 0.0
    ok_ref = True
    for off, bound in ((L.REF_P_W, POSITION_PLAUSIBLE_M), (L.REF_V_W, VELOCITY_PLAUSIBLE_MPS),
                       (L.REF_A_W, ACCEL_PLAUSIBLE_MPS2)):
        x = _vec3(ref, off)
        if _plausible(x, bound):
            state[S_REF_LAST + off], state[S_REF_LAST + off + 1], state[S_REF_LAST + off + 2] = x
        else:
            ok_ref = False
            if off == L.REF_P_W and not have_ref:
                # no good reference yet: hold where we are
                state[S_REF_LAST + off], state[S_REF_LAST + off + 1], state[S_REF_LAST + off + 2] = p_W
    if np.isfinite(ref[L.REF_YAW]):
        state[S_REF_LAST + L.REF_YAW] = _wrap_angle(ref[L.REF_YAW])
    else:
        ok_ref = False
        if not have_ref:
            # no good reference yet: face where we face
            state[S_REF_LAST + L.REF_YAW] = euler_from_quat(q_WB)[0]
    if not ok_ref:
        faults |= FAULT_REFERENCE
    state[S_HAVE_REF] = 1.0
    p_d = _vec3(state, S_REF_LAST + L.REF_P_W)
    v_d = _vec3(state, S_REF_LAST + L.REF_V_W)
    a_d = _vec3(state, S_REF_LAST + L.REF_A_W)
    yaw_d = state[S_REF_LAST + L.REF_YAW]

    # 2. incident velocity: probe, or the fallback from the wind estimate
    v_i = _vec3(meas, L.MEAS_V_I_B)
    all_finite = _plausible(v_i, np.inf)
    V_probe = np.sqrt(v_i[0] * v_i[0] + v_i[1] * v_i[1] + v_i[2] * v_i[2])
    probe_ok = meas[L.MEAS_V_I_VALID] == 1.0 and all_finite and V_probe <= params[P_VPROBE_MAX]
    # A finite reading flagged invalid only because the airspeed is low (the pressure probe's
    # q_inf floor, the probe's minimum airspeed) still says "the air is nearly still": use it.
    # Below the hover-blend airspeed the aerodynamic columns of Phi are ~V^2 ~ 0, so C_Tz keeps
    # adapting in hover instead of pausing whenever the fan is off.
    if not probe_ok and meas[L.MEAS_V_I_VALID] == 0.0 and all_finite and V_probe < params[P_V_LO]:
        probe_ok = True
    if meas[L.MEAS_V_I_VALID] != 1.0:
        faults |= FAULT_PROBE  # the sensor's own flag is always reported, even when the reading is used
    if probe_ok:
        cw = state[S_GAINS + GAIN_WIND]
        v_i_probe_W = _rows_times(R, v_i)
        for i in range(3):
            w_i = v_W[i] - v_i_probe_W[i]
            if state[S_HAVE_WIND] > 0.0:
                state[S_WIND_EST + i] = ad.lowpass(state[S_WIND_EST + i], w_i, cw)
            else:
                state[S_WIND_EST + i] = w_i
        state[S_HAVE_WIND] = 1.0
    else:
        faults |= FAULT_PROBE
        # a stale estimate must not outlive the wind: fade toward still air while the probe is out
        fade = state[S_GAINS + GAIN_FADE]
        for i in range(3):
            state[S_WIND_EST + i] = ad.flush_tiny(state[S_WIND_EST + i] * fade)
        d = (v_W[0] - state[S_WIND_EST], v_W[1] - state[S_WIND_EST + 1], v_W[2] - state[S_WIND_EST + 2])
        v_i = _rows_transpose_times(R, d)
    v_i_W = _rows_times(R, v_i)
    airspeed = np.sqrt(v_i[0] ** 2 + v_i[1] ** 2 + v_i[2] ** 2)

    # 3. tracking errors (eq:wr)
    p_tilde = (p_W[0] - p_d[0], p_W[1] - p_d[1], p_W[2] - p_d[2])
    v_r, v_r_dot, _ = reference_velocity(p_tilde, v_d, a_d, v_W, _vec3(params, P_LAMBDA_P), params[P_VCORR_MAX])
    v_tilde_raw = (v_W[0] - v_r[0], v_W[1] - v_r[1], v_W[2] - v_r[2])
    v_tilde, _ = limit_norm(v_tilde_raw, params[P_VERR_MAX])

    # 4. adaptation: filters, prediction error, theta-hat and P
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
    model = _vec3(params, P_MODEL)
    Phi = regressor(v_i, state[S_U_EST], state[S_U_EST + 1], model)
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
    adapt_active = (mode != ad.ADAPT_NONE and state[S_FILT_INIT] > 0.0 and probe_ok and accel_ok
                    and state[S_VALID_TIME] >= params[P_HOLDOFF_S] - 1e-12)
    n_active = 0
    p_diag = S_WORK + ad.WK_P_DIAG
    if adapt_active:
        n_active, active_set, e = ad.adaptation_step(
            mode, state, S_ADAPT, S_WORK, params, P_PRIOR, Phi, R, v_tilde, dt,
            state[S_GAINS + GAIN_FORGET_A], state[S_GAINS + GAIN_FORGET_B], params[P_SIGMA], params[P_TRACE_MAX],
            int(state[S_ACTIVE_SET]))
        state[S_ACTIVE_SET] = active_set
        if n_active < 0:
            faults |= FAULT_ADAPTATION
    else:
        e = ad.prediction_error(state, S_W_F, state, S_THETA, state, S_AM_F)
        if not (mode == ad.ADAPT_COMPOSITE
                and ad.cholesky_lower(state, S_GAMMA, state, S_WORK + ad.WK_L, N_THETA)):
            if mode == ad.ADAPT_COMPOSITE:
                faults |= FAULT_ADAPTATION
            for i in range(N_THETA):
                state[p_diag + i] = params[P_P0 + N_THETA * i + i]
        else:
            ad.inverse_factor(state, S_WORK + ad.WK_L, state, S_WORK + ad.WK_M)
            ad.factor_diag(state, S_WORK + ad.WK_M, state, p_diag)
    theta = (state[S_THETA], state[S_THETA + 1], state[S_THETA + 2], state[S_THETA + 3], state[S_THETA + 4],
             state[S_THETA + 5], state[S_THETA + 6], state[S_THETA + 7])

    # 5. force command
    if kind == KIND_PID or kind == KIND_PD:
        f_r = _pid_force(params, state, kind, v_W, v_tilde, a_d, dt)
    else:
        f_r = force_command(v_r_dot, v_tilde, _vec3(params, P_K_V))
    for i in range(3):
        state[S_V_PREV + i] = v_W[i]
    f_r, _ = limit_norm((f_r[0], f_r[1], f_r[2] + GRAVITY_MPS2), params[P_ACC_MAX])
    f_r = (f_r[0], f_r[1], f_r[2] - GRAVITY_MPS2)

    # 6. desired attitude and the desired frame's rate
    q_d, y_i, alpha_d, w_blend, formed = desired_attitude(
        f_r, v_i_W, yaw_d, theta[I_CL0], theta[I_CL1], model[0], params[P_ALPHA_MIN],
        params[P_ALPHA_MAX], params[P_V_LO], params[P_V_HI], params[P_TILT_MAX], params[P_MIN_LIFT],
        _vec3(state, S_Y_I_PREV), state[S_HAVE_Y_I] > 0.0)
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
    x1 = _vec3(state, S_WD_X1)
    omega_d = _vec3(state, S_WD_X2)
    k_wd = 2.0 * np.pi * params[P_WD_HZ]
    omega_d_dot, _ = limit_norm((k_wd * (x1[0] - omega_d[0]), k_wd * (x1[1] - omega_d[1]),
                                 k_wd * (x1[2] - omega_d[2])), params[P_WD_DOT_MAX])

    # 7. moment command (eq:wr, eq:m_ctrl)
    q_tilde = quat_error_from_quats(q_d, q_WB)
    if params[P_WD_ON] > 0.0:
        # omega_d and its rate in body axes: R~^T omega_d, R~ = R_d^T R
        Rt = _rotation_rows(q_tilde)
        omega_d_B = _rows_transpose_times(Rt, omega_d)
        omega_d_dot_B = _rows_transpose_times(Rt, omega_d_dot)
    else:
        # without the feed-forward omega_d = omega_d' = 0 in every frame
        omega_d_B = (0.0, 0.0, 0.0)
        omega_d_dot_B = (0.0, 0.0, 0.0)
    Lq = _vec3(params, P_LAMBDA_Q)
    omega_r = reference_angular_rate(omega_d_B, q_tilde, Lq)
    omega_r_dot = reference_angular_acceleration(q_tilde, omega, omega_d_B, omega_d_dot_B, Lq)
    J = (_vec3(params, P_J), _vec3(params, P_J + 3), _vec3(params, P_J + 6))
    tau = moment_command(J, omega, omega_r, omega_r_dot, _vec3(params, P_K_OMEGA))
    tau = (min(max(tau[0], -params[P_TAU_MAX]), params[P_TAU_MAX]),
           min(max(tau[1], -params[P_TAU_MAX + 1]), params[P_TAU_MAX + 1]),
           min(max(tau[2], -params[P_TAU_MAX + 2]), params[P_TAU_MAX + 2]))

    # 8. thruster allocation at the current attitude (eq:f_proj)
    f_rb = _rows_transpose_times(R, f_r)
    u_x, u_z, res, sat_x, sat_z = allocate_thrusters(f_rb, v_i, theta, model, u_max)

    # 9. output, with a last guard against non-finite values
    if not (np.isfinite(u_x) and np.isfinite(u_z) and _plausible(tau, np.inf)):
        faults |= FAULT_COMMAND
        u_x = state[S_U_PREV]
        u_z = state[S_U_PREV + 1]
        tau = _vec3(state, S_TAU_PREV)
    cmd[L.CMD_U_X] = min(max(u_x, 0.0), u_max)
    cmd[L.CMD_U_Z] = min(max(u_z, 0.0), u_max)
    for i in range(3):
        cmd[L.CMD_TAU_B + i] = tau[i]
    state[S_U_PREV] = cmd[L.CMD_U_X]
    state[S_U_PREV + 1] = cmd[L.CMD_U_Z]
    res_W = _rows_times(R, res)
    for i in range(3):
        state[S_TAU_PREV + i] = tau[i]
        state[S_RES_PREV_W + i] = res_W[i]
    state[S_SAT_PREV] = sat_x
    state[S_SAT_PREV + 1] = sat_z
    state[S_TIME] += dt
    state[S_STEPS] += 1.0
    state[S_HAVE_MEAS] = 1.0

    # diagnostics
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
        diag[DIAG_INTEGRATOR + i] = state[S_INT + i]
    for i in range(4):
        diag[DIAG_Q_TILDE + i] = q_tilde[i]
        diag[DIAG_Q_D + i] = q_d[i]
    diag[DIAG_ALPHA_D] = alpha_d
    diag[DIAG_AIRSPEED] = airspeed
    diag[DIAG_BLEND] = w_blend
    for i in range(N_THETA):
        diag[DIAG_P_DIAG + i] = state[p_diag + i]
        diag[DIAG_THETA_HAT + i] = theta[i]
    diag[DIAG_SAT_X] = sat_x
    diag[DIAG_SAT_Z] = sat_z
    diag[DIAG_PROBE_VALID] = 1.0 if probe_ok else 0.0
    diag[DIAG_ADAPT_ACTIVE] = 1.0 if adapt_active else 0.0
    diag[DIAG_PROJ_ACTIVE] = n_active
    diag[DIAG_LYAP_V] = 0.5 * (v_tilde_raw[0] ** 2 + v_tilde_raw[1] ** 2 + v_tilde_raw[2] ** 2)
    diag[DIAG_LYAP_Q] = (2.0 - 2.0 * q_tilde[0]) / params[P_GAMMA_LYAP]
    diag[DIAG_FAULTS] = faults


__all__ = ["CONTROLLER_DIAG_COLUMNS", "DIAG_SIZE", "KIND_COMPOSITE", "KIND_COMPOSITE_PCONST", "KIND_PD",
           "KIND_PID", "KIND_TRACKING_ONLY", "P_SIZE", "S_SIZE", "controller_initial_state",
           "controller_params", "controller_step", "default_theta_bounds", "set_state_theta_hat",
           "theta_bound_half_widths",
           "state_P", "state_P_inv", "state_filtered_accel", "state_filtered_regressor",
           "state_integrator", "state_last_command", "state_theta_hat", "state_wind_estimate"]
