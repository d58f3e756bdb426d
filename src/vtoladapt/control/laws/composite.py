"""The paper's composite adaptive law (controller I): eq:f_ctrl with theta-hat from eq:th_adapt and eq:P_adapt.

Force: ``f_r = v_r' - K_v v~ - g`` (eq:f_ctrl, :func:`vtoladapt.control.tracking.force_command`).
Estimator: theta-hat and the information matrix ``P^-1`` are updated every tick the front end
allows (``may_adapt``) by :func:`vtoladapt.control.adaptation.adaptation_step` in its composite
mode (tracking and prediction error, P from eq:P_adapt with forgetting toward P0).

Settings (``[controller.composite]``), defaults and why: ``forgetting_lambda = 0.5 1/s`` is a 2 s
memory, short next to the 5 s fan steps of the comparison experiment; in excited directions the
estimator's time constant is then about ``1/lambda`` = 2 s. ``sigma = 1e-4``: the smallest
excitation the adaptation must follow is the pusher column (``u_x^2`` ~ 0.07 at 9 m/s, ``W^T W``
~ 4e-3), and the sigma bias is ``sigma / (W^T W + sigma)``, 2.4 % there; robustness in unexcited
directions comes from the projection bounds, not from sigma.

Options beyond the paper (measured, defaults are the shipped law)
------------------------------------------------------------------
``forgetting = "paper"`` is the paper's eq:P_adapt, ``(P^-1)' = W^T W - lambda P^-1``: the
information decays in every direction, so P grows without bound where the regressor does not
excite. Measured (README, "Deviations from the paper"; ``docs/measure_windup.py``, 10 seeds): on
the paper's two 50-70 s experiments it is better than the shipped law (RMS velocity error -0.002
m/s, p95 prediction error 0.018 -> 0.012 g), but in a 600 s still-air hover P's largest
eigenvalue reaches 3e9 (only the noise in the incident-velocity estimate stops it) and theta-hat
of the aerodynamic coefficients sits at its projection bounds; with an ideal probe (the true,
near-zero incident velocity) P reaches 1e19, C_Tz drifts by 30 % and the RMS velocity error is
4x the shipped law's. The default therefore stays ``"prior"``, which keeps P <= P0.
``forgetting = "directional"`` forgets only the information along the directions the current
regressor excites (:func:`vtoladapt.control.adaptation.directional_information_update`), so
unexcited directions keep their information and theta-hat does not wander along them.
``validity_gating = true`` weights the prediction-error term and the information increment by
:func:`._adaptive.model_validity` (measured alpha against the vehicle's believed stall angle) and
drops the tracking term while the mixer saturates. Measured over 5 seeds (README, "Adaptation where
the model is wrong"): directional forgetting cuts the across-run spread of theta-hat in the
paper's convergence experiment (C_Tz 6x, C_D0 1.6x) at equal tracking and prediction error on the
paper's two scenarios (within 1 %; +3 % in the 8-11 m/s bin), but costs 5-14 % of prediction error
on the PX4 airframe (saturated 30 % of the time) and above 11 m/s. Gating is worse wherever the
model is wrong (near stall +18 % p95): the forgetting law's local re-fit of theta-hat is what keeps
the prediction error small there, and gating stops it. Neither is the best on the paper's
scenarios by the prediction-error and tracking measures, so the shipped law stays the default.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ...config import Validated, setting
from ...layout import BlockLayout, Field
from .. import adaptation as ad
from ..blocks import D_LAW, P_K_V, P_LAW, S_LAW, T_DT, T_NEW_DT, T_V_R_DOT, T_V_TILDE, law_offsets
from ..tracking import force_command
from . import LawContext, check_sigma_step, finish, law_update, tick3
from ._adaptive import DIAG, adaptive_estimate, model_validity, saturated


@dataclass(frozen=True)
class CompositeSettings(Validated):
    """The composite law's own gains (the ``[controller.composite]`` table)."""

    forgetting_lambda: float = setting("1/s", "forgetting factor lambda (eq:P_adapt, information form "
                                       "forgetting toward P0)", default=0.5, ge=0.0, le=100.0)
    sigma: float = setting("adaptation units", "sigma-modification toward theta_0 (eq:th_adapt)",
                           default=1e-4, ge=0.0, le=100.0)
    information_trace_max: float = setting(
        "adaptation units", "cap on trace(P^-1 - P0^-1): bounds P below for any regressor",
        default=1e6, gt=0.0)
    forgetting: str = setting(
        "-", "how eq:P_adapt forgets: 'prior' (every direction relaxes toward P0 at lambda, the shipped "
        "law), 'directional' (only the directions the current regressor excites are forgotten; "
        "unexcited ones keep their information), 'paper' (the paper's P' = -P W^T W P + lambda P: "
        "unexcited directions of P grow without bound)", default="prior",
        choices=("prior", "directional", "paper"))
    validity_gating: bool = setting(
        "-", "weight the prediction-error term and the information increment by the model's validity "
        "(measured alpha against the vehicle's believed stall angle), and drop the tracking term while "
        "the mixer saturates; false: the paper's law", default=False)
    adaptation_gain_scale: float = setting(
        "-", "multiplier of the adaptation gain P0 (the vehicle's prior or a posterior): k P0 adapts every "
        "direction k times faster (in the Kalman view, the measurement noise R divided by k); 1: P0 as given",
        default=1.0, gt=0.0, le=1e6)
    estimator: str = setting(
        "-", "'paper': the paper's eq:th_adapt and eq:P_adapt (information form, forgetting toward P0); 'kalman': "
        "Neural-Fly's Kalman form (vtoladapt.control.kalman: P a covariance, measurement noise R from the "
        "accelerometer, process noise Q per weight, regularisation toward the prior; forgetting_lambda, sigma, "
        "forgetting, information_trace_max and adaptation_gain_scale are then unused)", default="paper",
        choices=("paper", "kalman"))
    regularisation_lambda: float = setting(
        "1/s", "Kalman form: rate at which the weights relax toward the prior (Neural-Fly's lambda; their "
        "correlation time is 1/lambda)", default=0.1, gt=0.0, le=100.0)
    kalman_time_scale_s: float = setting(
        "s", "Kalman form: every physics column adapts with this time constant at its reference excitation "
        "(sets its Q and P0; the default was chosen on tuning draws 150-155 of the envelope campaign)",
        default=0.3, gt=0.0, le=1e4)
    accel_noise_density_ug_rtHz: float = setting(
        "ug/sqrt(Hz)", "Kalman form: the accelerometer's white-noise density the controller believes (the data "
        "sheet's, ICM-20689 / BMI088 class; never the plant's setting): R", default=175.0, gt=0.0, le=1e6)
    measurement_noise_scale: float = setting(
        "-", "Kalman form: multiplier of R (1: the accelerometer's noise only; larger: an unmodelled force the "
        "estimator should not chase; the default was chosen on tuning draws 150-155 of the envelope campaign)",
        default=1000.0, gt=0.0, le=1e9)
    process_noise_scale: float = setting(
        "-", "Kalman form: multiplier of Q and P0 (every weight's drift and prior variance)", default=1.0,
        gt=0.0, le=1e9)


Settings = CompositeSettings
"""The law interface's name for the settings class."""

TUNABLE = (("forgetting_lambda", 0.05, 20.0, True), ("sigma", 1e-6, 1.0, True),
           ("adaptation_gain_scale", 1e-2, 1e3, True), ("measurement_noise_scale", 1e-2, 1e6, True),
           ("process_noise_scale", 1e-3, 1e3, True), ("kalman_time_scale_s", 0.05, 20.0, True),
           ("regularisation_lambda", 1e-3, 5.0, True))
"""The gains ``vtoladapt tune`` searches (:mod:`vtoladapt.experiments.tuning`): (setting, low, high, log scale).
The paper form's gains (lambda, sigma, the P0 multiplier) and the Kalman form's (R and Q multipliers, the time
scale, the regularisation) are all listed; each form ignores the other's."""


PARAMS = BlockLayout("composite parameters", [
    Field("LAMBDA", 1, "1/s", "forgetting factor"),
    Field("SIGMA", 1, "adaptation units", "sigma-modification"),
    Field("TRACE_MAX", 1, "adaptation units", "cap on trace(P^-1 - P0^-1)"),
    Field("DIRECTIONAL", 1, "-", "1: directional forgetting"),
    Field("GATING", 1, "-", "1: model-validity gating"),
    Field("TOWARD_PRIOR", 1, "-", "1: forgetting toward P0; 0: the paper's pure forgetting"),
    Field("ALPHA_TRUST", 1, "rad", "model fully trusted up to this |alpha| (believed stall - margin)"),
    Field("ALPHA_STALL", 1, "rad", "model not trusted from this |alpha| on (believed stall)"),
    Field("KALMAN", 1, "-", "1: the Kalman form (vtoladapt.control.kalman)"),
    Field("KF_LAMBDA", 1, "1/s", "Kalman form: regularisation toward the prior"),
])
STATE = BlockLayout("composite state", [
    Field("ACTIVE_SET", 1, "-", "bit mask of the bounds the last projection held"),
    Field("FORGET", 2, "-", "forgetting weights (a, b) for the current dt (Kalman form: a^2 and the process "
          "noise's factor (1 - a^2)/(2 lambda))"),
])
(P_LAMBDA, P_SIGMA, P_TRACE_MAX, P_DIRECTIONAL, P_GATING, P_TOWARD_PRIOR, P_ALPHA_TRUST, P_ALPHA_STALL, P_KALMAN,
 P_KF_LAMBDA) = law_offsets(PARAMS, P_LAW, "LAMBDA", "SIGMA", "TRACE_MAX", "DIRECTIONAL", "GATING", "TOWARD_PRIOR",
                            "ALPHA_TRUST", "ALPHA_STALL", "KALMAN", "KF_LAMBDA")
S_ACTIVE_SET, S_FORGET = law_offsets(STATE, S_LAW, "ACTIVE_SET", "FORGET")
(D_PROJ_ACTIVE,) = law_offsets(DIAG, D_LAW, "PROJ_ACTIVE")


def fill_params(settings: CompositeSettings, ctx: LawContext) -> np.ndarray:
    """The law's parameter block; ``ValueError`` if sigma makes the explicit sigma step unstable."""
    kalman = settings.estimator == "kalman"
    if not kalman:
        # the Kalman form has no sigma step (its regularisation is part of the exact predict step)
        check_sigma_step(settings.sigma, ctx, "controller.composite")
    env = ctx.vehicle.envelope
    return PARAMS.pack(LAMBDA=settings.forgetting_lambda, SIGMA=settings.sigma,
                       TRACE_MAX=settings.information_trace_max,
                       DIRECTIONAL=float(settings.forgetting == "directional"),
                       GATING=float(settings.validity_gating), TOWARD_PRIOR=float(settings.forgetting != "paper"),
                       ALPHA_TRUST=np.radians(env.alpha_protect_deg), ALPHA_STALL=np.radians(env.stall_angle_deg),
                       KALMAN=float(kalman), KF_LAMBDA=settings.regularisation_lambda)


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """Nothing beyond the shared start (theta-hat = theta_init, P = P0): no bound held yet."""


@njit(cache=True, inline="always")
def composite_estimate(params, state, tick, diag) -> tuple:
    """The composite law's estimator for this tick (the paper's form or the Kalman form): theta-hat and P updated,
    ``(adapt_active, faults)`` returned. Shared with :mod:`.composite_indi`, whose parameter, state and
    diagnostics blocks begin with this law's."""
    kalman = params[P_KALMAN] > 0.0
    if tick[T_NEW_DT] > 0.0:
        if kalman:
            # a^2 = exp(-2 lambda dt) and (1 - a^2)/(2 lambda): the covariance's decay and the process noise's factor
            state[S_FORGET], state[S_FORGET + 1] = ad.forgetting_weights(2.0 * params[P_KF_LAMBDA], tick[T_DT])
        else:
            state[S_FORGET], state[S_FORGET + 1] = ad.forgetting_weights(params[P_LAMBDA], tick[T_DT])
    w_pred = 1.0
    w_track = 1.0
    if params[P_GATING] > 0.0:
        w_pred = model_validity(params, state, params[P_ALPHA_TRUST], params[P_ALPHA_STALL])
        w_track = 0.0 if saturated(state) else w_pred
    return adaptive_estimate(
        ad.ADAPT_KALMAN if kalman else ad.ADAPT_COMPOSITE, params, state, tick, diag, S_ACTIVE_SET, D_PROJ_ACTIVE,
        state[S_FORGET], state[S_FORGET + 1], params[P_SIGMA], params[P_TRACE_MAX], w_track, w_pred,
        params[P_DIRECTIONAL] > 0.0, 1.0, params[P_TOWARD_PRIOR])


@law_update
def update(params, state, tick, diag):
    """Adapt theta-hat and P, then the force command (eq:f_ctrl); see the law interface."""
    adapt_active, faults = composite_estimate(params, state, tick, diag)
    K_v = (params[P_K_V], params[P_K_V + 1], params[P_K_V + 2])
    finish(tick, force_command(tick3(tick, T_V_R_DOT), tick3(tick, T_V_TILDE), K_v), adapt_active, faults)
