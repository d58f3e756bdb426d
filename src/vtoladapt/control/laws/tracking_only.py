"""Adaptation on the tracking error only (the paper's controller III): ``theta-hat' = P0 Phi^T R^T v~``.

As :mod:`.composite` without the prediction-error term and with P = P0. The sigma-modification
toward theta_0 (eq:th_adapt's last term) is kept, as in the composite laws: it is this law's
``[controller.tracking_only] sigma`` (set it to 0 for the paper's pure tracking-error law).
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
class TrackingOnlySettings:
    """The tracking-error law's own gains (the ``[controller.tracking_only]`` table)."""

    sigma: float = setting("adaptation units", "sigma-modification toward theta_0, as in eq:th_adapt "
                           "(0: the pure tracking-error law)", default=1e-4, ge=0.0, le=100.0)


Settings = TrackingOnlySettings
"""The law interface's name for the settings class."""


PARAMS = BlockLayout("tracking_only parameters", [
    Field("SIGMA", 1, "adaptation units", "sigma-modification"),
])
STATE = BlockLayout("tracking_only state", [
    Field("ACTIVE_SET", 1, "-", "bit mask of the bounds the last projection held"),
    Field("WORK", ad.WORK.size, "-", "the adaptation's scratch (no meaning between ticks)"),
])
(P_SIGMA,) = law_offsets(PARAMS, P_LAW, "SIGMA")
S_ACTIVE_SET, S_WORK = law_offsets(STATE, S_LAW, "ACTIVE_SET", "WORK")


def fill_params(settings: TrackingOnlySettings, ctx: LawContext) -> np.ndarray:
    """The law's parameter block; ``ValueError`` if sigma makes the explicit sigma step unstable."""
    check_sigma_step(settings.sigma, ctx, "controller.tracking_only")
    return PARAMS.pack(SIGMA=settings.sigma)


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """Nothing beyond the shared start (theta-hat = theta_init, P = P0)."""


@njit(cache=True)
def update(params, state, diag, dt, new_dt, may_adapt, Phi, R, v_W, v_r_dot, v_tilde, a_d) -> tuple:
    """Adapt theta-hat on the tracking error, then the force command (eq:f_ctrl); see the law interface."""
    e, adapt_active, faults = adaptive_estimate(
        ad.ADAPT_TRACKING, params, state, diag, S_ACTIVE_SET, S_WORK, may_adapt, Phi, R, v_tilde, dt,
        1.0, dt, params[P_SIGMA], np.inf)
    K_v = (params[P_K_V], params[P_K_V + 1], params[P_K_V + 2])
    return force_command(v_r_dot, v_tilde, K_v), e, adapt_active, faults
