"""The compiled controller step: the shared front end, the law's update, the shared back end.

The simulator calls it every tick inside its compiled loop::

    fns = controller_functions(params)          # Python, once per run
    controller_step(fns, params, state, meas, ref, dt, cmd, diag)   # float64 1-D arrays, dt float

* ``fns``: the law's ``update`` and the basis's ``regressor``, Numba first-class functions of
  their kinds' fixed signatures (:data:`vtoladapt.control.laws.UPDATE_SIGNATURE`,
  :data:`vtoladapt.bases.REGRESSOR_SIGNATURE`): the step is compiled and cached once for every
  law and basis, a user's included, and calls them indirectly (a few ns);
* ``params``: from :func:`controller_params` (built once; the law and the basis are keys in it);
* ``state``: the controller's memory, from :func:`controller_initial_state`, updated in place;
* ``meas``: :mod:`vtoladapt.layout` ``MEAS_*``; ``ref``: ``REF_*``; ``cmd`` (output): ``CMD_*``
  (``u_x``, ``u_z`` as fractions, ``tau_B`` in N m); ``diag`` (output): named by
  :func:`diagnostics_columns` of ``params`` (units in the names), of length :func:`diagnostics_size`.

The array layouts are in :mod:`.blocks` (shared blocks, the per-tick block, the per-run layout of
a law and a basis) and in each law's module (its own blocks); outside them use the accessors
(:func:`state_theta_hat`, :func:`state_P_inv`, :func:`state_P`, :func:`set_state_theta_hat`, ...),
which take ``params`` too because the blocks sized by the basis are found through it.

The step is compiled without Numba's reference counting, as every kernel of the simulator's tick
(:mod:`vtoladapt.sim.loop`): a law's ``update`` and a basis's ``regressor`` must not allocate
arrays (their scratch lives in the state, and values pass between functions as tuples).
"""
from __future__ import annotations

import numpy as np
from numba import njit, types

from .. import _numba_abi
# the bounds rule is the models layer's (a posterior file's prior uses it below the controller); named here too
from ..scaling import theta_bound_half_widths, theta_bounds  # noqa: F401
from ..parts import PART_ROW, T_C, function_loader
from ..bases import REGRESSOR_SIGNATURE, BasisSpec, basis_key, basis_module, basis_of_key, describe_basis
from . import adaptation as ad
from .linalg import spd_inverse
from .backend import back_end, default_law_diagnostics
from .blocks import (
    A_A_M, A_BASIS, A_BASIS_SIZE, A_BASIS_WORK_SIZE, A_COVARIANCE, A_D_THETA_HAT, A_DIAG_SIZE, A_GAMMA, A_GAMMA0,
    A_INFO_SUM, A_N, A_P0, A_STATE_SIZE, A_THETA, A_THETA_INIT, A_W, CONTROL_AT, DIAG_Q_TILDE, DIAG_V_TILDE,
    P_BASIS_KEY, P_HOLDOFF_S, P_LAW_KEY, S_LAW, S_Q_D_PREV, S_Q_LAST, S_TICK, S_U_PREV, S_VALID_TIME, S_WIND_EST,
    SHARED_PARAMS, TICK_SIZE, ControllerLayout, controller_layout,
)
from .frontend import front_end
from .kalman import kalman_prior
from .laws import UPDATE_SIGNATURE, LawContext
from .registry import ControllerInfo, law_key, law_of_key

# Numba marks first-class function types experimental: vtoladapt._numba_abi silences that warning (the
# step's use of them, functions of one fixed signature passed as arguments and called, is the documented one).
LAW_FUNCTION = types.FunctionType(UPDATE_SIGNATURE)
BASIS_FUNCTION = types.FunctionType(REGRESSOR_SIGNATURE)


@njit(cache=True, _nrt=False)
def controller_step(fns, params, state, meas, ref, dt, cmd, diag) -> None:
    """One controller tick: front end, the law's update, back end (see :mod:`vtoladapt.control`).

    ``fns = (law update, basis regressor)`` (:func:`controller_functions`). Reads ``meas``
    (``MEAS_*``) and ``ref`` (``REF_*``), writes ``cmd`` (``CMD_*``) and ``diag``
    (:func:`diagnostics_columns`), updates ``state`` in place. ``dt`` (s) outside ``(0, 0.1]`` or
    not finite is replaced (nominal rate, or 0.1 s) and flagged.
    """
    front_end(fns, params, state, meas, ref, dt)
    default_law_diagnostics(params, diag)
    fns[0](params, state, state[S_TICK:S_TICK + TICK_SIZE], diag)
    back_end(params, state, cmd, diag)


_load_law = function_loader(UPDATE_SIGNATURE)
_load_basis = function_loader(REGRESSOR_SIGNATURE)


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def functions_at(table):
    """``(law update, basis regressor)`` as first-class functions from the controller's function table
    (:func:`function_table`), inside compiled code. A kernel that Python calls once per step takes the
    table, not the tuple: Numba unboxes a tuple of functions from Python objects on every call (some
    10 us), an int64 array for nothing (:mod:`vtoladapt.parts`)."""
    return (_load_law(table, 0), _load_basis(table, 1))


@njit(cache=True, _nrt=False)
def controller_step_at(table, params, state, meas, ref, dt, cmd, diag) -> None:
    """:func:`controller_step` with its two functions given by their table (:func:`function_table`).

    For a caller in Python that steps once per call (the :class:`~vtoladapt.control.api.Controller`).
    The addresses are valid in the process that took them, while the functions live.
    """
    controller_step(functions_at(table), params, state, meas, ref, dt, cmd, diag)


def function_table(fns) -> np.ndarray:
    """The controller's function table: ``fns = (law update, basis regressor)`` (:func:`controller_functions`)
    as two rows of a :data:`vtoladapt.parts.PART_ROW` table (the C entry points of the two ``cfunc``
    objects; the other columns are unused). The simulator's loop and the Gymnasium environment hand it
    to the tick beside the wind parts' and sensor channels' tables. Keep ``fns`` alive while it is used
    (a law's or basis's module holds its function for the process)."""
    table = np.zeros((2, PART_ROW.size), dtype=np.int64)
    table[0, T_C] = _numba_abi.c_address(fns[0], UPDATE_SIGNATURE)
    table[1, T_C] = _numba_abi.c_address(fns[1], REGRESSOR_SIGNATURE)
    return table


# --- what a parameter array was built for (Python) -------------------------------------------------

def law_of_params(params: np.ndarray) -> ControllerInfo:
    """The registry entry of the law a parameter array was built for."""
    return law_of_key(float(params[P_LAW_KEY]))


def basis_block(params: np.ndarray) -> np.ndarray:
    """The basis's constants as stored in a parameter array (a copy)."""
    b = int(params[A_BASIS])
    return np.array(params[b:b + int(params[A_BASIS_SIZE])])


def basis_names(params: np.ndarray) -> tuple[str, ...]:
    """The names of the n parameters of the basis a parameter array was built for."""
    info = basis_of_key(float(params[P_BASIS_KEY]))
    return tuple(basis_module(info.id).parameter_names(basis_block(params)))


def controller_functions(params: np.ndarray) -> tuple:
    """``(law update, basis regressor)`` of a parameter array: what the loop passes to :func:`controller_step`."""
    law = law_of_params(params).law
    basis = basis_module(basis_of_key(float(params[P_BASIS_KEY])).id)
    return (law.update, basis.regressor)


def layout_of_params(params: np.ndarray) -> ControllerLayout:
    """The whole declared layout (:func:`.blocks.controller_layout`) a parameter array was built with."""
    return controller_layout(int(params[A_N]), law_of_params(params).law, basis_names(params),
                             int(params[A_BASIS_SIZE]), int(params[A_BASIS_WORK_SIZE]))


def diagnostics_columns(params: np.ndarray) -> tuple[str, ...]:
    """The names of a run's ``diag`` entries, in order, units in the names: the shared ones
    (:data:`.blocks.SHARED_DIAG`), the law's own (its ``DIAG``), then ``theta_hat_<name>`` and
    ``P_diag_<name>`` per parameter of the basis."""
    return layout_of_params(params).diag.columns


def diagnostics_size(params: np.ndarray) -> int:
    """The length of a run's ``diag`` array."""
    return int(params[A_DIAG_SIZE])


def diagnostics_size_for(n: int, law_id: str | None = None) -> int:
    """The length of a ``diag`` array for a basis of ``n`` parameters and law ``law_id`` (default: the registered
    law with the most diagnostics), before any parameters exist (the simulator's memory budget)."""
    from .blocks import SHARED_DIAG
    from .registry import CONTROLLERS

    ids = [law_id] if law_id is not None else list(CONTROLLERS)
    return SHARED_DIAG.size + max(CONTROLLERS.module(k).DIAG.size for k in ids) + 2 * n


# --- parameters and state from the configuration (Python, once per run) ---------------------------

def _vector(name: str, value, n: int) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} = {a.tolist()}: must be finite")
    return a


def default_theta_bounds(vehicle, theta_0=None, theta_std=None, basis: BasisSpec | None = None
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Box bounds of theta-hat (:func:`vtoladapt.scaling.theta_bounds`) with the basis's ``bound_fraction``,
    ``bound_sigmas`` and signs (default: the vehicle's basis, :func:`vtoladapt.bases.describe_basis`).

    ``theta_0`` and ``std`` default to the basis's prior (Table I for the paper's), all in the adaptation scaling.
    """
    spec = describe_basis(vehicle) if basis is None else basis
    th0 = spec.theta_scaled if theta_0 is None else _vector("theta_0", theta_0, spec.n)
    std = spec.std_scaled if theta_std is None else _vector("theta_std", theta_std, spec.n)
    return theta_bounds(th0, std, spec.bound_fraction, spec.bound_sigmas, spec.sign)


def initial_gain(P0_diag, n: int) -> np.ndarray:
    """``P0`` (n, n) from its diagonal or a full SPD matrix; ``ValueError`` naming what is wrong."""
    P0 = np.asarray(P0_diag, dtype=float)
    if P0.shape == (n,):
        if not np.all(P0 > 0) or not np.all(np.isfinite(P0)):
            raise ValueError(f"P0_diag = {P0.tolist()}: every entry must be finite and > 0")
        return np.diag(P0)
    if P0.shape == (n, n):
        if not np.all(np.isfinite(P0)) or not np.allclose(P0, P0.T, rtol=1e-10, atol=0.0):
            raise ValueError(f"P0 ({n}x{n}) must be finite and symmetric")
        P0 = 0.5 * (P0 + P0.T)
        try:
            np.linalg.cholesky(P0)
        except np.linalg.LinAlgError:
            raise ValueError(f"P0 ({n}x{n}) must be positive definite") from None
        return P0
    raise ValueError(f"P0_diag must have shape ({n},) or ({n}, {n}) (the basis has {n} parameters), got {P0.shape}")


def controller_params(config, vehicle, theta_0=None, P0_diag=None, theta_lower=None, theta_upper=None,
                      theta_init=None, basis: BasisSpec | None = None) -> np.ndarray:
    """Kernel parameter array from a :class:`~.settings.ControllerConfig` and the controller's vehicle model.

    The shared block (:data:`.blocks.SHARED_PARAMS`), the law's own (its ``fill_params`` from its
    ``[controller.<kind>]`` settings), the adaptation's prior and the basis's constants
    (:func:`.blocks.controller_layout`).

    Parameters
    ----------
    config : ControllerConfig
    vehicle : Vehicle
        The controller's model of the aircraft (inertia, force model, limits), never the plant.
    theta_0 : array (n,), optional
        Prior mean (adaptation scaling); default the basis's (Table I for the paper's).
    P0_diag : array (n,) or (n, n), optional
        Initial gain P0: its diagonal, or a full SPD matrix (a fitted posterior covariance);
        default the basis's (Table III for the paper's). An adaptive law's ``adaptation_gain_scale``
        multiplies it.
    theta_lower, theta_upper : array (n,), optional
        Bounds of theta-hat; default :func:`default_theta_bounds`.
    theta_init : array (n,), optional
        theta-hat at the start; default ``theta_0``; clipped into the bounds.
    basis : BasisSpec, optional
        The force-model basis; default ``config.basis`` (or the vehicle's) for this vehicle.

    Raises
    ------
    ValueError
        Naming the argument, if a shape, a value or the bounds are invalid.
    """
    spec = describe_basis(vehicle, config.basis) if basis is None else basis
    n = spec.n
    th0 = spec.theta_scaled.copy() if theta_0 is None else _vector("theta_0", theta_0, n)
    kalman = getattr(config.law_settings, "estimator", "paper") == "kalman"
    Q = np.zeros(n)
    R_meas = np.zeros(3)
    if kalman:
        # the Kalman form (vtoladapt.control.kalman): P0, Q and R from the basis, the vehicle model and the
        # accelerometer the controller believes; a P0 given here is taken as the covariance itself
        kp = kalman_prior(spec, vehicle, config.law_settings, config.lowpass_cutoff_hz, 1.0 / config.loop_rate_hz)
        P0 = kp["P0"] if P0_diag is None else initial_gain(P0_diag, n)
        Q, R_meas = kp["Q"], kp["R"]
    else:
        P0 = initial_gain(spec.P0_diag if P0_diag is None else P0_diag, n)
        # an adaptive law's adaptation gain multiplier (its ``adaptation_gain_scale``; 1: P0 as given, bit for bit)
        gain_scale = float(getattr(config.law_settings, "adaptation_gain_scale", 1.0))
        if gain_scale != 1.0:
            P0 = P0 * gain_scale
    Gamma0 = np.linalg.inv(P0)
    Gamma0 = 0.5 * (Gamma0 + Gamma0.T)
    lo_d, hi_d = default_theta_bounds(vehicle, th0, basis=spec)
    lo = lo_d if theta_lower is None else _vector("theta_lower", theta_lower, n)
    hi = hi_d if theta_upper is None else _vector("theta_upper", theta_upper, n)
    if not np.all(lo < hi):
        raise ValueError(f"theta bounds: lower {lo.tolist()} must be below upper {hi.tolist()}")
    if not np.all((lo <= th0) & (th0 <= hi)):
        raise ValueError(f"theta_0 = {th0.tolist()} must lie within the bounds [{lo.tolist()}, {hi.tolist()}]")
    init = th0 if theta_init is None else _vector("theta_init", theta_init, n)
    init = np.clip(init, lo, hi)

    law = config.info.law
    layout = controller_layout(n, law, spec.names, spec.block.size, spec.work_size)
    at = layout.at.copy()
    if kalman:
        # the GAMMA slot holds P (read by controller_initial_state, state_P, state_P_inv, controller_lyapunov)
        at[CONTROL_AT.offset("ADAPTATION") + ad.AT_COVARIANCE] = 1.0
    shared = _shared_params(config, vehicle, at, law_key(config.kind), basis_key(spec.id))
    ctx = LawContext(config=config, vehicle=vehicle, theta_0=th0, P0=P0, dt_nominal_s=1.0 / config.loop_rate_hz,
                     basis=spec)
    own = np.asarray(law.fill_params(config.law_settings, ctx), dtype=float)
    if own.shape != (law.PARAMS.size,):
        raise ValueError(f"{law.__name__}.fill_params returned shape {own.shape}, its PARAMS need "
                         f"({law.PARAMS.size},)")
    prior = layout.prior.pack(THETA0=th0, THETA_INIT=init, LOWER=lo, UPPER=hi, GAMMA0=Gamma0.ravel(),
                              P0=P0.ravel(), Q=Q, R_MEAS=R_meas)
    return layout.params.pack(SHARED=shared, LAW=own, PRIOR=prior, BASIS=spec.block)


def _shared_params(config, vehicle, at: np.ndarray, law: float, basis: float) -> np.ndarray:
    """The shared block: the ``[controller]`` gains with the vehicle's limits, and the keys and offsets."""
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
    return SHARED_PARAMS.pack(
        LAW_KEY=law, BASIS_KEY=basis, AT=at, K_V=config.K_v, LAMBDA_P=config.Lambda_p, LAMBDA_Q=config.Lambda_q,
        K_OMEGA=K_omega, J=J.ravel(), MODEL=vehicle.model_kernel,
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


def controller_initial_state(params) -> np.ndarray:
    """The controller's state before its first tick: theta-hat = theta_init, P = P0, filters empty.

    The shared block, then the law's own (zeros, then its ``init_state``), then the blocks sized by the basis.
    """
    law = law_of_params(params).law
    n = int(params[A_N])
    s = np.zeros(int(params[A_STATE_SIZE]))
    th, init = int(params[A_THETA]), int(params[A_THETA_INIT])
    gam, gam0 = int(params[A_GAMMA]), int(params[A_GAMMA0])
    s[th:th + n] = params[init:init + n]
    if params[A_COVARIANCE] > 0.0:
        # the Kalman form starts from P = P0
        s[gam:gam + n * n] = params[int(params[A_P0]):int(params[A_P0]) + n * n]
    else:
        s[gam:gam + n * n] = params[gam0:gam0 + n * n]
    s[S_Q_D_PREV] = 1.0
    s[S_Q_LAST] = 1.0
    # the filters start from the first sample, so no settling time is needed at start-up
    s[S_VALID_TIME] = params[P_HOLDOFF_S]
    law.init_state(params, s)
    return s


# --- state accessors (the shared block; a law's own fields: ControllerState.law_field) ------------

@njit(cache=True)
def estimate_offsets(params) -> tuple:
    """``(n, theta-hat's offset, P^-1's offset)`` in the state (for a caller that reads them every tick)."""
    return int(params[A_N]), int(params[A_THETA]), int(params[A_GAMMA])


@njit(cache=True)
def state_theta_hat(params, state) -> np.ndarray:
    """theta-hat (n,) in the adaptation scaling (a view into ``state``)."""
    n, th, _ = estimate_offsets(params)
    return state[th:th + n]


@njit(cache=True)
def set_state_theta_hat(params, state, theta) -> None:
    """Overwrite theta-hat (e.g. a random initial estimate); the caller keeps it inside the bounds."""
    n, th, _ = estimate_offsets(params)
    for i in range(n):
        state[th + i] = theta[i]


def information_sum(params, state) -> np.ndarray:
    """The un-forgotten information ``sum w_pred W^T W dt`` (n, n) the adaptive law accumulated (a copy).

    Zero for a law that never adapts; see :func:`vtoladapt.experiments.metrics.identifiability`.
    """
    n, o = int(params[A_N]), int(params[A_INFO_SUM])
    return np.array(state[o:o + n * n]).reshape((n, n))


@njit(cache=True)
def state_P_inv(params, state) -> np.ndarray:
    """The information matrix ``P^-1`` (n, n): a view into ``state``, or, for the Kalman form (which holds P),
    its inverse by Cholesky (a new array)."""
    n, _, gam = estimate_offsets(params)
    if params[A_COVARIANCE] > 0.0:
        G = np.empty(n * n)
        if not spd_inverse(state, gam, G, 0, np.empty(2 * n * n), 0, n):
            G[:] = np.nan
        return G.reshape((n, n))
    return state[gam:gam + n * n].reshape((n, n))


@njit(cache=True)
def state_P(params, state) -> np.ndarray:
    """The adaptation gain ``P`` (n, n), from the information matrix by Cholesky, or the Kalman form's
    covariance (a new array either way)."""
    n, _, gam = estimate_offsets(params)
    P = np.empty(n * n)
    if params[A_COVARIANCE] > 0.0:
        P[:] = state[gam:gam + n * n]
    elif not spd_inverse(state, gam, P, 0, np.empty(2 * n * n), 0, n):
        P[:] = np.nan
    return P.reshape((n, n))


@njit(cache=True)
def state_filtered_accel(params, state) -> np.ndarray:
    """The filtered specific force a_m (3,), m/s^2 body (a view into ``state``)."""
    o = int(params[A_A_M])
    return state[o:o + 3]


@njit(cache=True)
def state_filtered_regressor(params, state) -> np.ndarray:
    """The filtered regressor W (3, n) (a view into ``state``)."""
    n, o = int(params[A_N]), int(params[A_W])
    return state[o:o + 3 * n].reshape((3, n))


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


@njit(cache=True, _nrt=False)
def controller_lyapunov(params, state, diag, theta_true, gamma) -> float:
    """The proof's ``V`` (:func:`vtoladapt.control.adaptation.lyapunov_at`) of this tick: the tracking terms
    from ``diag`` and theta-hat, ``P^-1`` from ``state``; ``theta_true`` (the plant's, in the basis; empty for
    a basis without a plant truth, which leaves the parameter term out) comes from the simulator only."""
    _, th, gam = estimate_offsets(params)
    if params[A_COVARIANCE] > 0.0:
        # the Kalman form holds P, not P^-1: V's parameter term is left out (V of the tracking terms only)
        return ad.lyapunov_at(diag[DIAG_V_TILDE], diag[DIAG_V_TILDE + 1], diag[DIAG_V_TILDE + 2], diag[DIAG_Q_TILDE],
                              state, th, state, gam, theta_true[:0], gamma)
    return ad.lyapunov_at(diag[DIAG_V_TILDE], diag[DIAG_V_TILDE + 1], diag[DIAG_V_TILDE + 2], diag[DIAG_Q_TILDE],
                          state, th, state, gam, theta_true, gamma)


def state_law_field(state: np.ndarray, params: np.ndarray, name: str) -> np.ndarray:
    """Field ``name`` of the law's own state block (its ``STATE`` layout), as a view into ``state``."""
    layout = law_of_params(params).law.STATE
    o = S_LAW + layout.offset(name)
    return state[o:o + layout.field(name).size]


def theta_hat_of_diag(params, diag) -> np.ndarray:
    """theta-hat from a ``diag`` array or a log's diagnostics rows (last axis), a view."""
    n, d = int(params[A_N]), int(params[A_D_THETA_HAT])
    return diag[..., d:d + n]


__all__ = ["BASIS_FUNCTION", "LAW_FUNCTION", "basis_block", "basis_names", "controller_functions",
           "controller_initial_state", "controller_lyapunov", "controller_params", "controller_step",
           "controller_step_at", "default_theta_bounds", "diagnostics_columns", "diagnostics_size", "diagnostics_size_for",
           "estimate_offsets", "function_table", "functions_at", "information_sum", "initial_gain", "law_of_params",
           "layout_of_params", "set_last_command", "set_state_theta_hat", "state_P", "state_P_inv",
           "state_filtered_accel", "state_filtered_regressor", "state_last_command", "state_law_field",
           "state_theta_hat", "state_wind_estimate", "theta_bound_half_widths", "theta_bounds", "theta_hat_of_diag"]
