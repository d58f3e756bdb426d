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
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ...config import setting
from ...layout import BlockLayout, Field
from .. import adaptation as ad
from ..layouts import P_K_V, P_LAW, S_LAW, law_offsets
from ..tracking import force_command
from . import LawContext, check_sigma_step
from ._adaptive import adaptive_estimate


@dataclass(frozen=True)
class CompositeSettings:
    """The composite law's own gains (the ``[controller.composite]`` table)."""

    forgetting_lambda: float = setting("1/s", "forgetting factor lambda (eq:P_adapt, information form "
                                       "forgetting toward P0)", default=0.5, ge=0.0, le=100.0)
    sigma: float = setting("adaptation units", "sigma-modification toward theta_0 (eq:th_adapt)",
                           default=1e-4, ge=0.0, le=100.0)
    information_trace_max: float = setting(
        "adaptation units", "cap on trace(P^-1 - P0^-1): bounds P below for any regressor",
        default=1e6, gt=0.0)


Settings = CompositeSettings
"""The law interface's name for the settings class."""


PARAMS = BlockLayout("composite parameters", [
    Field("LAMBDA", 1, "1/s", "forgetting factor"),
    Field("SIGMA", 1, "adaptation units", "sigma-modification"),
    Field("TRACE_MAX", 1, "adaptation units", "cap on trace(P^-1 - P0^-1)"),
])
STATE = BlockLayout("composite state", [
    Field("ACTIVE_SET", 1, "-", "bit mask of the bounds the last projection held"),
    Field("FORGET", 2, "-", "forgetting weights (a, b) for the current dt"),
    Field("WORK", ad.WORK.size, "-", "the adaptation's scratch (no meaning between ticks)"),
])
P_LAMBDA, P_SIGMA, P_TRACE_MAX = law_offsets(PARAMS, P_LAW, "LAMBDA", "SIGMA", "TRACE_MAX")
S_ACTIVE_SET, S_FORGET, S_WORK = law_offsets(STATE, S_LAW, "ACTIVE_SET", "FORGET", "WORK")


def fill_params(settings: CompositeSettings, ctx: LawContext) -> np.ndarray:
    """The law's parameter block; ``ValueError`` if sigma makes the explicit sigma step unstable."""
    check_sigma_step(settings.sigma, ctx, "controller.composite")
    return PARAMS.pack(LAMBDA=settings.forgetting_lambda, SIGMA=settings.sigma,
                       TRACE_MAX=settings.information_trace_max)


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """Nothing beyond the shared start (theta-hat = theta_init, P = P0): no bound held yet."""


@njit(cache=True)
def update(params, state, diag, dt, new_dt, may_adapt, Phi, R, v_W, v_r_dot, v_tilde, a_d) -> tuple:
    """Adapt theta-hat and P, then the force command (eq:f_ctrl); see the law interface."""
    if new_dt:
        state[S_FORGET], state[S_FORGET + 1] = ad.forgetting_weights(params[P_LAMBDA], dt)
    e, adapt_active, faults = adaptive_estimate(
        ad.ADAPT_COMPOSITE, params, state, diag, S_ACTIVE_SET, S_WORK, may_adapt, Phi, R, v_tilde, dt,
        state[S_FORGET], state[S_FORGET + 1], params[P_SIGMA], params[P_TRACE_MAX])
    K_v = (params[P_K_V], params[P_K_V + 1], params[P_K_V + 2])
    return force_command(v_r_dot, v_tilde, K_v), e, adapt_active, faults
