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


Settings = CompositeSettings
"""The law interface's name for the settings class."""

TUNABLE = (("forgetting_lambda", 0.05, 20.0, True), ("sigma", 1e-6, 1.0, True),
           ("adaptation_gain_scale", 1e-2, 1e3, True))
"""The gains ``vtoladapt tune`` searches (:mod:`vtoladapt.experiments.tuning`): (setting, low, high, log scale)."""


PARAMS = BlockLayout("composite parameters", [
    Field("LAMBDA", 1, "1/s", "forgetting factor"),
    Field("SIGMA", 1, "adaptation units", "sigma-modification"),
    Field("TRACE_MAX", 1, "adaptation units", "cap on trace(P^-1 - P0^-1)"),
    Field("DIRECTIONAL", 1, "-", "1: directional forgetting"),
    Field("GATING", 1, "-", "1: model-validity gating"),
    Field("TOWARD_PRIOR", 1, "-", "1: forgetting toward P0; 0: the paper's pure forgetting"),
    Field("ALPHA_TRUST", 1, "rad", "model fully trusted up to this |alpha| (believed stall - margin)"),
    Field("ALPHA_STALL", 1, "rad", "model not trusted from this |alpha| on (believed stall)"),
])
STATE = BlockLayout("composite state", [
    Field("ACTIVE_SET", 1, "-", "bit mask of the bounds the last projection held"),
    Field("FORGET", 2, "-", "forgetting weights (a, b) for the current dt"),
])
P_LAMBDA, P_SIGMA, P_TRACE_MAX, P_DIRECTIONAL, P_GATING, P_TOWARD_PRIOR, P_ALPHA_TRUST, P_ALPHA_STALL = law_offsets(
    PARAMS, P_LAW, "LAMBDA", "SIGMA", "TRACE_MAX", "DIRECTIONAL", "GATING", "TOWARD_PRIOR", "ALPHA_TRUST",
    "ALPHA_STALL")
S_ACTIVE_SET, S_FORGET = law_offsets(STATE, S_LAW, "ACTIVE_SET", "FORGET")
(D_PROJ_ACTIVE,) = law_offsets(DIAG, D_LAW, "PROJ_ACTIVE")


def fill_params(settings: CompositeSettings, ctx: LawContext) -> np.ndarray:
    """The law's parameter block; ``ValueError`` if sigma makes the explicit sigma step unstable."""
    check_sigma_step(settings.sigma, ctx, "controller.composite")
    env = ctx.vehicle.envelope
    return PARAMS.pack(LAMBDA=settings.forgetting_lambda, SIGMA=settings.sigma,
                       TRACE_MAX=settings.information_trace_max,
                       DIRECTIONAL=float(settings.forgetting == "directional"),
                       GATING=float(settings.validity_gating), TOWARD_PRIOR=float(settings.forgetting != "paper"),
                       ALPHA_TRUST=np.radians(env.alpha_protect_deg), ALPHA_STALL=np.radians(env.stall_angle_deg))


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """Nothing beyond the shared start (theta-hat = theta_init, P = P0): no bound held yet."""


@law_update
def update(params, state, tick, diag):
    """Adapt theta-hat and P, then the force command (eq:f_ctrl); see the law interface."""
    if tick[T_NEW_DT] > 0.0:
        state[S_FORGET], state[S_FORGET + 1] = ad.forgetting_weights(params[P_LAMBDA], tick[T_DT])
    w_pred = 1.0
    w_track = 1.0
    if params[P_GATING] > 0.0:
        w_pred = model_validity(params, state, params[P_ALPHA_TRUST], params[P_ALPHA_STALL])
        w_track = 0.0 if saturated(state) else w_pred
    adapt_active, faults = adaptive_estimate(
        ad.ADAPT_COMPOSITE, params, state, tick, diag, S_ACTIVE_SET, D_PROJ_ACTIVE, state[S_FORGET],
        state[S_FORGET + 1], params[P_SIGMA], params[P_TRACE_MAX], w_track, w_pred, params[P_DIRECTIONAL] > 0.0, 1.0,
        params[P_TOWARD_PRIOR])
    K_v = (params[P_K_V], params[P_K_V + 1], params[P_K_V + 2])
    finish(tick, force_command(tick3(tick, T_V_R_DOT), tick3(tick, T_V_TILDE), K_v), adapt_active, faults)
