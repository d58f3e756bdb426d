"""Open-loop replay: the controller's force model and composite adaptation run on a log's data.

For every sample of a :class:`~.flightlog.FlightLog` the regressor ``Phi(x)`` of the controller's
force-model basis (:mod:`vtoladapt.bases`; the vehicle's, the paper's by default) is evaluated at
the log's incident velocity, throttles, attitude and velocity (the logs' body rates are not read: a
basis that reads ``OMEGA_B`` gets NaN, and its samples are not used), both it and the measured
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

from ..bases import IN_U, IN_V_I_B, BasisSpec, describe_basis, input_rows
from ..config import setting
from ..control import adaptation as ad
from ..control import filters
from ..control.step import default_theta_bounds
from ..models import THROTTLE_FULL_PCT
from ..vehicle import PARAMETER_NAMES, Vehicle
from .flightlog import FlightLog, ReplayError

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
    theta_0: np.ndarray          # (p,) prior mean (adaptation scaling), p the basis's parameters
    theta_lower: np.ndarray      # (p,) bounds of theta-hat
    theta_upper: np.ndarray
    theta_hat: np.ndarray        # (n, p) theta-hat after each sample's update
    P_diag: np.ndarray           # (n, p) diag(P) after each update
    e_mps2: np.ndarray           # (n, 3) prediction error W theta-hat - a_m before the update (eq:prediction_error)
    e_prior_mps2: np.ndarray     # (n, 3) the same with theta_0 (no adaptation)
    a_m_f_mps2: np.ndarray       # (n, 3) filtered measured specific force [a_m]_f
    f_pred_mps2: np.ndarray      # (n, 3) unfiltered prediction Phi theta-hat
    f_pred_prior_mps2: np.ndarray  # (n, 3) unfiltered prediction Phi theta_0
    used: np.ndarray             # (n,) bool: sample adapted theta-hat / is scored
    adapting: np.ndarray         # (n,) bool: the adaptation stepped on this sample
    basis: BasisSpec | None = None   # the force-model basis (names, units, scaling)

    @property
    def names(self) -> tuple[str, ...]:
        """The basis's parameter names (theta-hat's columns)."""
        return PARAMETER_NAMES if self.basis is None else self.basis.names

    @property
    def theta_hat_table(self) -> np.ndarray:
        """theta-hat (n, p) in Table I units (throttle in percent)."""
        return self.basis.from_scaled(self.theta_hat)


@njit(cache=True)
def replay_kernel(regressor, block, x_in, u_x, u_z, f_meas, use, dt, at, x, prior, c_f, forget_a, forget_b,
                  sigma, trace_max, lag_x, lag_z, holdoff_steps, mode, theta_out, p_diag_out, e_out, e0_out, am_out,
                  fp_out, fp0_out, adapting_out) -> None:
    """The replay loop (see the module notes); plain arrays in, outputs written in place.

    ``regressor`` and ``block`` are the basis's compiled regressor (a first-class function) and
    constants; ``x_in`` its input rows (:func:`vtoladapt.bases.input_rows`, the throttles are set here
    after the motor lag); ``u_x``, ``u_z`` are throttle fractions; ``lag_x``, ``lag_z`` the per-sample
    factors ``exp(-dt / tau)`` of the motor lag (0: none); ``use`` (uint8) marks samples allowed to
    adapt; ``at`` the adaptation's offsets table for its memory and scratch in ``x`` (zeros) and its
    prior in ``prior`` (:func:`replay_arrays`); ``mode`` is ``ADAPT_COMPOSITE`` or ``ADAPT_NONE``.
    Rows with a non-finite input or regressor get NaN.
    """
    n_samples = x_in.shape[0]
    n = int(at[ad.AT_N])
    th, gam, wf, am = int(at[ad.AT_THETA]), int(at[ad.AT_GAMMA]), int(at[ad.AT_W]), int(at[ad.AT_A_M])
    th0, init, gam0 = int(at[ad.AT_THETA0]), int(at[ad.AT_THETA_INIT]), int(at[ad.AT_GAMMA0])
    p_diag = int(at[ad.AT_P_DIAG])
    Phi = np.zeros(3 * n)
    work = np.zeros(1)
    for k in range(n):
        x[th + k] = prior[init + k]
    for k in range(n * n):
        x[gam + k] = prior[gam0 + k]
    v_zero = (0.0, 0.0, 0.0)
    filt_init = False
    valid_steps = 0
    active_set = 0
    ux_est = 0.0
    uz_est = 0.0
    for t in range(n_samples):
        xt = x_in[t]
        finite = (np.isfinite(u_x[t]) and np.isfinite(u_z[t]) and np.isfinite(f_meas[t, 0])
                  and np.isfinite(f_meas[t, 1]) and np.isfinite(f_meas[t, 2]) and np.isfinite(xt[IN_V_I_B])
                  and np.isfinite(xt[IN_V_I_B + 1]) and np.isfinite(xt[IN_V_I_B + 2]))
        if finite:
            # motors lag their commands: the accelerometer feels the lagged throttle
            if filt_init:
                ux_est = u_x[t] + (ux_est - u_x[t]) * lag_x
                uz_est = u_z[t] + (uz_est - u_z[t]) * lag_z
            else:
                ux_est = u_x[t]
                uz_est = u_z[t]
            xt[IN_U] = ux_est
            xt[IN_U + 1] = uz_est
            regressor(block, xt, Phi, work)
            for k in range(3 * n):
                finite = finite and np.isfinite(Phi[k])
        if not finite:
            filt_init = False
            valid_steps = 0
            for k in range(n):
                theta_out[t, k] = x[th + k]
                p_diag_out[t, k] = np.nan
            for r in range(3):
                e_out[t, r] = np.nan
                e0_out[t, r] = np.nan
                am_out[t, r] = np.nan
                fp_out[t, r] = np.nan
                fp0_out[t, r] = np.nan
            adapting_out[t] = 0
            continue
        if filt_init:
            for k in range(3 * n):
                x[wf + k] = filters.lowpass(x[wf + k], Phi[k], c_f)
            for r in range(3):
                x[am + r] = filters.lowpass(x[am + r], f_meas[t, r], c_f)
        else:
            for k in range(3 * n):
                x[wf + k] = Phi[k]
            for r in range(3):
                x[am + r] = f_meas[t, r]
            filt_init = True
        for r in range(3):
            s = 0.0
            s0 = 0.0
            for k in range(n):
                s += Phi[n * r + k] * x[th + k]
                s0 += Phi[n * r + k] * prior[th0 + k]
            fp_out[t, r] = s
            fp0_out[t, r] = s0
            am_out[t, r] = x[am + r]
        e0 = ad.prediction_error(x, wf, prior, th0, x, am, n)
        if mode != ad.ADAPT_NONE and use[t] != 0 and valid_steps >= holdoff_steps:
            n_active, active_set, e = ad.adaptation_step(mode, at, 0, x, prior, Phi, 0, _IDENTITY, v_zero, dt,
                                                         forget_a, forget_b, sigma, trace_max, active_set)
            adapting_out[t] = 1 if n_active >= -1 else 0
            for k in range(n):
                p_diag_out[t, k] = x[p_diag + k]
        else:
            e = ad.prediction_error(x, wf, x, th, x, am, n)
            adapting_out[t] = 0
            for k in range(n):
                p_diag_out[t, k] = np.nan
        valid_steps += 1
        for k in range(n):
            theta_out[t, k] = x[th + k]
        for r in range(3):
            e_out[t, r] = e[r]
            e0_out[t, r] = e0[r]


def theta_bounds(vehicle: Vehicle, theta_0: np.ndarray, basis: BasisSpec | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The controller's box for theta-hat around ``theta_0`` (the controller's own rule,
    :func:`vtoladapt.control.step.default_theta_bounds`, with the basis's std and signs)."""
    return default_theta_bounds(vehicle, np.asarray(theta_0, dtype=float), basis=basis)


def replay_arrays(spec: BasisSpec, vehicle: Vehicle, theta_init: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, int]:
    """``(at, prior, size)``: the adaptation's offsets table (memory then scratch in one array of ``size``),
    and its prior block (``prior_layout``): theta_0, theta-hat at the start, bounds, P0^-1, P0."""
    n = spec.n
    th0 = spec.theta_scaled.copy()
    lo, hi = theta_bounds(vehicle, th0, spec)
    init = th0 if theta_init is None else np.asarray(theta_init, dtype=float)
    if init.shape != (n,) or not np.all(np.isfinite(init)):
        raise ReplayError(f"theta_init = {np.asarray(init).tolist()}: must be {n} finite numbers (adaptation "
                          f"scaling, the {spec.id} basis's {', '.join(spec.names)})")
    P0 = np.diag(np.asarray(spec.P0_diag, dtype=float))
    at, x, _ = ad.standalone_arrays(n)
    prior = ad.prior_layout(n).pack(THETA0=th0, THETA_INIT=np.clip(init, lo, hi), LOWER=lo, UPPER=hi,
                                    GAMMA0=np.linalg.inv(P0).ravel(), P0=P0.ravel())
    return at, prior, x.size


def run_replay(log: FlightLog, vehicle: Vehicle, settings: ReplaySettings = ReplaySettings(),
               theta_init: np.ndarray | None = None, basis: BasisSpec | None = None) -> ReplayResult:
    """Replay the force model and the composite adaptation open-loop on ``log`` (module notes).

    Parameters
    ----------
    log : FlightLog
    vehicle : Vehicle
        Supplies the force model, the nominal motor lags and, through its basis, theta_0, P0 and the
        bounds (the paper's: Table I means, Table III).
    settings : ReplaySettings
    theta_init : array (p,), optional
        theta-hat at the start (adaptation scaling); default theta_0.
    basis : BasisSpec, optional
        The force-model basis; default the vehicle's (:func:`vtoladapt.bases.describe_basis`).
    """
    if log.n < 2:
        raise ReplayError(f"{log.source}: {log.n} samples, need at least 2")
    spec = describe_basis(vehicle) if basis is None else basis
    dt = 1.0 / log.rate_hz
    at, prior, size = replay_arrays(spec, vehicle, theta_init)
    a, b = ad.forgetting_weights(settings.forgetting_lambda, dt)
    if settings.motor_lag:
        lag_x = float(np.exp(-dt / vehicle.actuators.pusher_motor_time_constant_s))
        lag_z = float(np.exp(-dt / vehicle.actuators.lift_motor_time_constant_s))
    else:
        lag_x = lag_z = 0.0
    use = (np.ones(log.n, dtype=bool) if settings.use_landed else ~log.landed)
    n = log.n
    p = spec.n
    out = {k: np.empty((n, p)) for k in ("theta", "p")}
    out.update({k: np.empty((n, 3)) for k in ("e", "e0", "am", "fp", "fp0")})
    adapting = np.zeros(n, dtype=np.uint8)
    u_x = np.ascontiguousarray(log.throttle_x_pct / THROTTLE_FULL_PCT)
    u_z = np.ascontiguousarray(log.throttle_z_pct / THROTTLE_FULL_PCT)
    # the basis's inputs from the log: the incident flow (valid where the pitot gave it), attitude and
    # velocity; the logs' body rates are not read (NaN)
    x_in = input_rows(log.v_i_B_mps, u_x, u_z, vehicle.model_kernel, valid=log.v_i_from_pitot, q_WB=log.q_WB,
                      omega_B=np.full((n, 3), np.nan), v_W=log.v_W_mps)
    replay_kernel(spec.regressor, np.array(spec.block), x_in, u_x, u_z,
                  np.ascontiguousarray(log.f_meas_B_mps2), use.astype(np.uint8), dt, at, np.zeros(size), prior,
                  filters.lowpass_gain(settings.lowpass_cutoff_hz, dt), a, b, settings.sigma,
                  settings.information_trace_max,
                  lag_x, lag_z, int(np.ceil(settings.holdoff_s * log.rate_hz - 1e-9)),
                  ad.ADAPT_COMPOSITE if settings.adapt else ad.ADAPT_NONE,
                  out["theta"], out["p"], out["e"], out["e0"], out["am"], out["fp"], out["fp0"], adapting)
    finite = np.all(np.isfinite(out["e"]), axis=1)
    prior_layout = ad.prior_layout(p)
    return ReplayResult(log=log, vehicle=vehicle, settings=settings,
                        theta_0=prior_layout.view(prior, "THETA0").copy(),
                        theta_lower=prior_layout.view(prior, "LOWER").copy(),
                        theta_upper=prior_layout.view(prior, "UPPER").copy(),
                        theta_hat=out["theta"], P_diag=out["p"], e_mps2=out["e"], e_prior_mps2=out["e0"],
                        a_m_f_mps2=out["am"], f_pred_mps2=out["fp"], f_pred_prior_mps2=out["fp0"],
                        used=use & finite, adapting=adapting.astype(bool), basis=spec)


__all__ = ["PARAMETER_NAMES", "ReplayResult", "ReplaySettings", "replay_arrays", "replay_kernel", "run_replay",
           "theta_bounds"]
