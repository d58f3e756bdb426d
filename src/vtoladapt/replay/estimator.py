"""Open-loop replay: the controller's force model and composite adaptation run on a log's data.

For every sample of a :class:`~.flightlog.FlightLog` the regressor ``Phi(v_i_B, u_x, u_z)`` of the
force model is evaluated at the log's incident velocity and throttles, both it and the measured
specific force pass through the adaptation's low-pass ``[.]_f`` (eq:prediction_error), and the
composite law updates theta-hat and its information matrix (eq:th_adapt, eq:P_adapt) exactly as
the controller does (the same compiled steps of :mod:`vtoladapt.control.adaptation`, with the
same forgetting toward the prior, sigma-modification and projection on the bounds).

Open loop means there is no reference trajectory: the tracking term ``Phi^T R^T v~`` of
eq:th_adapt is zero (``v~ = 0``), so theta-hat moves only with the prediction error, which is
what a log can say something about. Alongside, the same filtered regressor predicts the force
with the vehicle's published theta_0 (no adaptation), so the report shows what adaptation buys.

Samples are *used* (they adapt theta-hat and enter the metrics) when every input is finite and
the land detector does not say the vehicle is on the ground (its reaction force is not in the
model); a non-finite input resets the filters, which restart from the next finite sample, and
adaptation resumes ``holdoff_s`` later (as the controller's ``adaptation_holdoff_s``).

The loop is one compiled function (:func:`replay_kernel`), so a 10-minute log at 250 Hz replays
in well under a second once compiled.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import forces
from ..control.adaptation import (
    ADAPT_COMPOSITE,
    ADAPT_NONE,
    MEM_A_M,
    MEM_GAMMA,
    MEM_SIZE,
    MEM_THETA,
    MEM_W,
    PRIOR_GAMMA0,
    PRIOR_LOWER,
    PRIOR_P0,
    PRIOR_SIZE,
    PRIOR_THETA0,
    PRIOR_THETA_INIT,
    PRIOR_UPPER,
    WK_P_DIAG,
    WORK_SIZE,
    adaptation_step,
    forgetting_weights,
    lowpass,
    lowpass_gain,
    prediction_error,
)
from ..config import setting
from ..control.kernel import default_theta_bounds
from ..models import THROTTLE_FULL_PCT, theta_from_scaled
from ..vehicle import PARAMETER_NAMES, Vehicle
from .flightlog import FlightLog, ReplayError

N_THETA = forces.N_THETA
_IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


@dataclass(frozen=True)
class ReplaySettings:
    """The adaptation's settings for a replay (defaults: the controller's, see ``ControllerConfig``)."""

    adapt: bool = setting("-", "run the composite adaptation (False: theta-hat stays at theta_0)",
                          default=True)
    lowpass_cutoff_hz: float = setting("Hz", "first-order filter [.]_f on the specific force and Phi "
                                       "(eq:prediction_error)", default=10.0, gt=0.0)
    forgetting_lambda: float = setting("1/s", "forgetting factor lambda (eq:P_adapt, toward P0)",
                                       default=0.5, ge=0.0, le=100.0)
    sigma: float = setting("adaptation units", "sigma-modification toward theta_0 (eq:th_adapt)",
                           default=1e-4, ge=0.0, le=100.0)
    information_trace_max: float = setting("adaptation units", "cap on trace(P^-1 - P0^-1)",
                                           default=1e6, gt=0.0)
    holdoff_s: float = setting("s", "adaptation resumes this long after the inputs are finite again "
                               "(the filters re-settle)", default=0.05, ge=0.0)
    motor_lag: bool = setting("-", "pass the logged throttle commands through the vehicle's nominal "
                              "motor lag before Phi (as the controller does)", default=True)
    use_landed: bool = setting("-", "also adapt on and score samples the land detector flags as "
                               "on the ground", default=False)

    def __post_init__(self) -> None:
        for name, lo, strict in (("lowpass_cutoff_hz", 0.0, True), ("forgetting_lambda", 0.0, False),
                                 ("sigma", 0.0, False), ("information_trace_max", 0.0, True),
                                 ("holdoff_s", 0.0, False)):
            v = getattr(self, name)
            if not np.isfinite(v) or v < lo or (strict and v == lo):
                raise ReplayError(f"{name} = {v!r}: must be finite and {'>' if strict else '>='} {lo:g}")


@dataclass(frozen=True, eq=False)
class ReplayResult:
    """Time series of a replay (rows match the :class:`FlightLog`'s grid) and the prior used.

    Forces are per unit mass, body FRD, m/s^2; theta in the adaptation scaling (see
    :mod:`vtoladapt.models`) unless a name says Table I.
    """

    log: FlightLog
    vehicle: Vehicle
    settings: ReplaySettings
    theta_0: np.ndarray          # (8,) prior mean (adaptation scaling)
    theta_lower: np.ndarray      # (8,) bounds of theta-hat
    theta_upper: np.ndarray
    theta_hat: np.ndarray        # (n, 8) theta-hat after each sample's update
    P_diag: np.ndarray           # (n, 8) diag(P) after each update
    e_mps2: np.ndarray           # (n, 3) prediction error W theta-hat - a_m before the update (eq:prediction_error)
    e_prior_mps2: np.ndarray     # (n, 3) the same with theta_0 (no adaptation)
    a_m_f_mps2: np.ndarray       # (n, 3) filtered measured specific force [a_m]_f
    f_pred_mps2: np.ndarray      # (n, 3) unfiltered prediction Phi theta-hat
    f_pred_prior_mps2: np.ndarray  # (n, 3) unfiltered prediction Phi theta_0
    used: np.ndarray             # (n,) bool: sample adapted theta-hat / is scored
    adapting: np.ndarray         # (n,) bool: the adaptation stepped on this sample

    @property
    def theta_hat_table(self) -> np.ndarray:
        """theta-hat (n, 8) in Table I units (throttle in percent)."""
        return theta_from_scaled(self.theta_hat, self.vehicle.force_model.k1)


@njit(cache=True)
def replay_kernel(v_i_B, u_x, u_z, f_meas, use, dt, model, prior, c_f, forget_a, forget_b, sigma,
                  trace_max, lag_x, lag_z, holdoff_steps, mode,
                  theta_out, p_diag_out, e_out, e0_out, am_out, fp_out, fp0_out, adapting_out) -> None:
    """The replay loop (see the module notes); plain arrays in, outputs written in place.

    ``u_x``, ``u_z`` are throttle fractions; ``lag_x``, ``lag_z`` the per-sample factors
    ``exp(-dt / tau)`` of the motor lag (0: none); ``use`` (uint8) marks samples allowed to adapt;
    ``mode`` is ``ADAPT_COMPOSITE`` or ``ADAPT_NONE``. Rows with a non-finite input get NaN.
    """
    n = v_i_B.shape[0]
    x = np.zeros(MEM_SIZE + WORK_SIZE)
    w = MEM_SIZE
    for k in range(N_THETA):
        x[MEM_THETA + k] = prior[PRIOR_THETA_INIT + k]
    for k in range(N_THETA * N_THETA):
        x[MEM_GAMMA + k] = prior[PRIOR_GAMMA0 + k]
    v_zero = np.zeros(3)
    filt_init = False
    valid_steps = 0
    active_set = 0
    ux_est = 0.0
    uz_est = 0.0
    for t in range(n):
        finite = (np.isfinite(u_x[t]) and np.isfinite(u_z[t]) and np.isfinite(f_meas[t, 0])
                  and np.isfinite(f_meas[t, 1]) and np.isfinite(f_meas[t, 2]) and np.isfinite(v_i_B[t, 0])
                  and np.isfinite(v_i_B[t, 1]) and np.isfinite(v_i_B[t, 2]))
        if not finite:
            filt_init = False
            valid_steps = 0
            for k in range(N_THETA):
                theta_out[t, k] = x[MEM_THETA + k]
                p_diag_out[t, k] = np.nan
            for r in range(3):
                e_out[t, r] = np.nan
                e0_out[t, r] = np.nan
                am_out[t, r] = np.nan
                fp_out[t, r] = np.nan
                fp0_out[t, r] = np.nan
            adapting_out[t] = 0
            continue
        # motors lag their commands: the accelerometer feels the lagged throttle
        if filt_init:
            ux_est = u_x[t] + (ux_est - u_x[t]) * lag_x
            uz_est = u_z[t] + (uz_est - u_z[t]) * lag_z
        else:
            ux_est = u_x[t]
            uz_est = u_z[t]
        Phi = forces.regressor(v_i_B[t], ux_est, uz_est, model)
        if filt_init:
            for r in range(3):
                for k in range(N_THETA):
                    x[MEM_W + N_THETA * r + k] = lowpass(x[MEM_W + N_THETA * r + k], Phi[r][k], c_f)
                x[MEM_A_M + r] = lowpass(x[MEM_A_M + r], f_meas[t, r], c_f)
        else:
            for r in range(3):
                for k in range(N_THETA):
                    x[MEM_W + N_THETA * r + k] = Phi[r][k]
                x[MEM_A_M + r] = f_meas[t, r]
            filt_init = True
        for r in range(3):
            s = 0.0
            s0 = 0.0
            for k in range(N_THETA):
                s += Phi[r][k] * x[MEM_THETA + k]
                s0 += Phi[r][k] * prior[PRIOR_THETA0 + k]
            fp_out[t, r] = s
            fp0_out[t, r] = s0
            am_out[t, r] = x[MEM_A_M + r]
        e0 = prediction_error(x, MEM_W, prior, PRIOR_THETA0, x, MEM_A_M)
        if mode != ADAPT_NONE and use[t] != 0 and valid_steps >= holdoff_steps:
            n_active, active_set, e = adaptation_step(mode, x, 0, w, prior, 0, Phi, _IDENTITY, v_zero, dt,
                                                      forget_a, forget_b, sigma, trace_max, active_set)
            adapting_out[t] = 1 if n_active >= -1 else 0
            for k in range(N_THETA):
                p_diag_out[t, k] = x[w + WK_P_DIAG + k]
        else:
            e = prediction_error(x, MEM_W, x, MEM_THETA, x, MEM_A_M)
            adapting_out[t] = 0
            for k in range(N_THETA):
                p_diag_out[t, k] = np.nan
        valid_steps += 1
        for k in range(N_THETA):
            theta_out[t, k] = x[MEM_THETA + k]
        for r in range(3):
            e_out[t, r] = e[r]
            e0_out[t, r] = e0[r]


def theta_bounds(vehicle: Vehicle, theta_0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The controller's box for theta-hat around ``theta_0`` (the controller's own rule,
    :func:`vtoladapt.control.kernel.default_theta_bounds`, with the vehicle's Table I std)."""
    return default_theta_bounds(vehicle, np.asarray(theta_0, dtype=float))


def prior_array(vehicle: Vehicle, theta_init: np.ndarray | None = None) -> np.ndarray:
    """The adaptation's prior block (``PRIOR_*`` layout): theta_0, theta-hat at the start, bounds, P0^-1, P0."""
    th0 = vehicle.theta_scaled.copy()
    lo, hi = theta_bounds(vehicle, th0)
    init = th0 if theta_init is None else np.asarray(theta_init, dtype=float)
    if init.shape != (N_THETA,) or not np.all(np.isfinite(init)):
        raise ReplayError(f"theta_init = {np.asarray(init).tolist()}: must be 8 finite numbers (adaptation scaling)")
    P0 = np.diag(np.asarray(vehicle.adaptation.P0_diag, dtype=float))
    p = np.zeros(PRIOR_SIZE)
    p[PRIOR_THETA0:PRIOR_THETA0 + N_THETA] = th0
    p[PRIOR_THETA_INIT:PRIOR_THETA_INIT + N_THETA] = np.clip(init, lo, hi)
    p[PRIOR_LOWER:PRIOR_LOWER + N_THETA] = lo
    p[PRIOR_UPPER:PRIOR_UPPER + N_THETA] = hi
    p[PRIOR_GAMMA0:PRIOR_GAMMA0 + N_THETA ** 2] = np.linalg.inv(P0).ravel()
    p[PRIOR_P0:PRIOR_P0 + N_THETA ** 2] = P0.ravel()
    return p


def run_replay(log: FlightLog, vehicle: Vehicle, settings: ReplaySettings = ReplaySettings(),
               theta_init: np.ndarray | None = None) -> ReplayResult:
    """Replay the force model and the composite adaptation open-loop on ``log`` (module notes).

    Parameters
    ----------
    log : FlightLog
    vehicle : Vehicle
        Supplies the force model, theta_0 (Table I means), P0 (Table III), the bounds and the
        nominal motor lags.
    settings : ReplaySettings
    theta_init : array (8,), optional
        theta-hat at the start (adaptation scaling); default theta_0.
    """
    if log.n < 2:
        raise ReplayError(f"{log.source}: {log.n} samples, need at least 2")
    dt = 1.0 / log.rate_hz
    prior = prior_array(vehicle, theta_init)
    a, b = forgetting_weights(settings.forgetting_lambda, dt)
    if settings.motor_lag:
        lag_x = float(np.exp(-dt / vehicle.actuators.pusher_motor_time_constant_s))
        lag_z = float(np.exp(-dt / vehicle.actuators.lift_motor_time_constant_s))
    else:
        lag_x = lag_z = 0.0
    use = (np.ones(log.n, dtype=bool) if settings.use_landed else ~log.landed)
    n = log.n
    out = {k: np.empty((n, N_THETA)) for k in ("theta", "p")}
    out.update({k: np.empty((n, 3)) for k in ("e", "e0", "am", "fp", "fp0")})
    adapting = np.zeros(n, dtype=np.uint8)
    replay_kernel(np.ascontiguousarray(log.v_i_B_mps), np.ascontiguousarray(log.throttle_x_pct / THROTTLE_FULL_PCT),
                  np.ascontiguousarray(log.throttle_z_pct / THROTTLE_FULL_PCT), np.ascontiguousarray(log.f_meas_B_mps2),
                  use.astype(np.uint8), dt, np.ascontiguousarray(vehicle.model_kernel, dtype=float), prior,
                  lowpass_gain(settings.lowpass_cutoff_hz, dt), a, b, settings.sigma, settings.information_trace_max,
                  lag_x, lag_z, int(np.ceil(settings.holdoff_s * log.rate_hz - 1e-9)),
                  ADAPT_COMPOSITE if settings.adapt else ADAPT_NONE,
                  out["theta"], out["p"], out["e"], out["e0"], out["am"], out["fp"], out["fp0"], adapting)
    finite = np.all(np.isfinite(out["e"]), axis=1)
    return ReplayResult(log=log, vehicle=vehicle, settings=settings,
                        theta_0=prior[PRIOR_THETA0:PRIOR_THETA0 + N_THETA].copy(),
                        theta_lower=prior[PRIOR_LOWER:PRIOR_LOWER + N_THETA].copy(),
                        theta_upper=prior[PRIOR_UPPER:PRIOR_UPPER + N_THETA].copy(),
                        theta_hat=out["theta"], P_diag=out["p"], e_mps2=out["e"], e_prior_mps2=out["e0"],
                        a_m_f_mps2=out["am"], f_pred_mps2=out["fp"], f_pred_prior_mps2=out["fp0"],
                        used=use & finite, adapting=adapting.astype(bool))


__all__ = ["PARAMETER_NAMES", "ReplayResult", "ReplaySettings", "prior_array", "replay_kernel",
           "run_replay", "theta_bounds"]
