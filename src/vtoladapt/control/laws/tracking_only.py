"""Adaptation on the tracking error only (the paper's controller III): ``theta-hat' = k P0 Phi^T R^T v~``.

As :mod:`.composite` without the prediction-error term and with a constant-shape gain ``k P0``.
The paper's law is ``k = 1`` and no sigma-modification; both are the defaults except where the
motor lag makes ``k = 1`` unstable (the gain rule below).

Why the paper's gain limit-cycles, and the gain rule
----------------------------------------------------
Linearised at a trim with theta~ small, the force error is ``-R Phi theta~`` and this law gives
``theta~' = k P0 Phi^T R^T v~``: an integral action on ``v~`` with the integral gain matrix
``k_I = k R Phi P0 Phi^T R^T`` (1/s^2). Through the first-order motor lag ``tau`` the loop along
one axis is ``tau s^3 + s^2 + K_v s + k_I``, stable iff ``K_v > tau k_I`` (Routh-Hurwitz). At 9
m/s with Table III's P0, ``k_I`` along north is about 58 /s^2 and ``tau k_I`` = 2.3 > K_v = 1.8
(the 40 ms pusher): the paper's gain is unstable there, and the simulator shows a 0.2 m/s limit
cycle of period 0.76 s, while in hover and at 4 m/s it is stable.

``gain_rule = "routh"`` (default) scales the gain so that the criterion holds with margin
``loop_gain_margin`` on every axis: ``k = min(1, k_I_max / trace(Phi P0 Phi^T))`` with
``k_I_max = min(K_v) / (margin * max(tau_pusher, tau_lift))``. The trace bounds the largest
eigenvalue of ``R Phi P0 Phi^T R^T``, so every axis' ``k_I`` is below ``k_I_max``. Where the
paper's gain is stable with that margin (hover, low wind) ``k = 1`` is the paper's law; above it
this is the normalised gradient law of robust adaptive control (Ioannou & Sun, *Robust Adaptive
Control*, sec. 4.3), normalised by the loop gain the motor lag allows. ``"paper"``: ``k = 1``.

Measured (plant equal to the model, 40 ms pusher, max ``|v~|`` over the last 5 s of a 20 s hold):
the paper's gain 0.20 m/s at 9 m/s and 0.23 m/s at 12 m/s (limit cycles); the rule 5e-5 and 6e-5
m/s. On paper_comparison (5 seeds) RMS ``|v~|`` 0.058 m/s against the paper gain's 0.063.

Sigma (``[controller.tracking_only] sigma``, default 0): the paper's law III has none, and it is
off by default. With ``sigma = 1e-4`` (the composite law's value) the RMS ``|v~|`` on
paper_comparison changes by -0.7 % (5 seeds): a negligible effect either way.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ...config import Validated, setting
from ...layout import BlockLayout, Field
from .. import adaptation as ad
from ..blocks import A_N, A_P0, A_PHI, D_LAW, P_K_V, P_LAW, S_LAW, T_DT, T_V_R_DOT, T_V_TILDE, law_offsets
from ..tracking import force_command
from . import LawContext, check_sigma_step, finish, law_update, tick3
from ._adaptive import DIAG, adaptive_estimate


@dataclass(frozen=True)
class TrackingOnlySettings(Validated):
    """The tracking-error law's own gains (the ``[controller.tracking_only]`` table)."""

    sigma: float = setting("adaptation units", "sigma-modification toward theta_0 (not in the paper's law "
                           "III; 0: the paper's law)", default=0.0, ge=0.0, le=100.0)
    gain_rule: str = setting("-", "'routh': the gain k P0 with k <= 1 keeping K_v > margin * tau_motor * k_I on "
                             "every axis (stable through the motor lag); 'paper': P0 always", default="routh",
                             choices=("routh", "paper"))
    loop_gain_margin: float = setting("-", "gain margin of the 'routh' rule: k_I <= min(K_v) / (margin * "
                                      "max motor time constant)", default=2.0, ge=1.0, le=100.0)
    adaptation_gain_scale: float = setting(
        "-", "multiplier of the adaptation gain P0 (the vehicle's prior or a posterior): k P0 adapts every "
        "direction k times faster (in the Kalman view, the measurement noise R divided by k); 1: P0 as given",
        default=1.0, gt=0.0, le=1e6)


Settings = TrackingOnlySettings
"""The law interface's name for the settings class."""

TUNABLE = (("loop_gain_margin", 1.0, 8.0, True), ("sigma", 1e-6, 1.0, True), ("adaptation_gain_scale", 1e-2, 1e3, True))
"""The gains ``vtoladapt tune`` searches (:mod:`vtoladapt.experiments.tuning`): (setting, low, high, log scale).
The margin sets the gain ``k P0`` (``k <= 1``) of the Routh rule."""


PARAMS = BlockLayout("tracking_only parameters", [
    Field("SIGMA", 1, "adaptation units", "sigma-modification"),
    Field("K_I_MAX", 1, "1/s^2", "largest integral gain the Routh rule allows (inf: the paper's P0)"),
])
STATE = BlockLayout("tracking_only state", [
    Field("ACTIVE_SET", 1, "-", "bit mask of the bounds the last projection held"),
])
P_SIGMA, P_K_I_MAX = law_offsets(PARAMS, P_LAW, "SIGMA", "K_I_MAX")
(S_ACTIVE_SET,) = law_offsets(STATE, S_LAW, "ACTIVE_SET")
(D_PROJ_ACTIVE,) = law_offsets(DIAG, D_LAW, "PROJ_ACTIVE")


def integral_gain_limit(settings: TrackingOnlySettings, K_v, vehicle) -> float:
    """``k_I_max = min(K_v) / (margin * max motor time constant)`` (1/s^2); inf for the 'paper' rule."""
    if settings.gain_rule == "paper":
        return np.inf
    act = vehicle.actuators
    tau = max(act.pusher_motor_time_constant_s, act.lift_motor_time_constant_s)
    return float(min(K_v)) / (settings.loop_gain_margin * tau)


def fill_params(settings: TrackingOnlySettings, ctx: LawContext) -> np.ndarray:
    """The law's parameter block; ``ValueError`` if sigma makes the explicit sigma step unstable."""
    check_sigma_step(settings.sigma, ctx, "controller.tracking_only")
    return PARAMS.pack(SIGMA=settings.sigma, K_I_MAX=integral_gain_limit(settings, ctx.config.K_v, ctx.vehicle))


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """Nothing beyond the shared start (theta-hat = theta_init, P = P0)."""


@njit(cache=True, _nrt=False)
def gain_scale(params, state) -> float:
    """The Routh rule's ``k = min(1, k_I_max / trace(Phi P0 Phi^T))`` (see the module notes), with this tick's
    unfiltered regressor ``Phi``."""
    k_I_max = params[P_K_I_MAX]
    if not np.isfinite(k_I_max):
        return 1.0
    n = int(params[A_N])
    if n == ad.N_SLOT_0:
        t = _trace_phi_p0_phi(params, state, ad.N_SLOT_0)
    elif n == ad.N_SLOT_1:
        t = _trace_phi_p0_phi(params, state, ad.N_SLOT_1)
    elif n == ad.N_SLOT_2:
        t = _trace_phi_p0_phi(params, state, ad.N_SLOT_2)
    else:
        t = _trace_phi_p0_phi(params, state, n)
    return 1.0 if t <= k_I_max else k_I_max / t


@njit(cache=True, inline="always")
def _trace_phi_p0_phi(params, state, n) -> float:
    """``trace(Phi P0 Phi^T)`` for n parameters (inlined: a specialised n gives loops of constant length)."""
    p0 = int(params[A_P0])
    phi = int(params[A_PHI])
    t = 0.0
    for r in range(3):
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += params[p0 + n * i + j] * state[phi + n * r + j]
            t += state[phi + n * r + i] * s
    return t


@law_update
def update(params, state, tick, diag):
    """Adapt theta-hat on the tracking error, then the force command (eq:f_ctrl); see the law interface."""
    adapt_active, faults = adaptive_estimate(
        ad.ADAPT_TRACKING, params, state, tick, diag, S_ACTIVE_SET, D_PROJ_ACTIVE, 1.0, tick[T_DT], params[P_SIGMA],
        np.inf, 1.0, 1.0, False, gain_scale(params, state))
    K_v = (params[P_K_V], params[P_K_V + 1], params[P_K_V + 2])
    finish(tick, force_command(tick3(tick, T_V_R_DOT), tick3(tick, T_V_TILDE), K_v), adapt_active, faults)
