"""The composite law with P held at P0 (the paper's controller II).

As :mod:`.composite`, with ``P' = 0``: P stays P0, and ``theta-hat' = P0 tau`` is solved exactly
over each tick with the regressor held (gain ``phi(dt P0 W^T W) P0``, see
:mod:`vtoladapt.control.adaptation`), so the law does not depend on the tick. (Until issue #25 a
backward-Euler step, gain ``(P0^-1 + dt W^T W)^-1``: 183 instead of 200 along C_Tz in hover.)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...config import Validated, setting
from ...layout import BlockLayout, Field
from .. import adaptation as ad
from ..blocks import D_LAW, P_K_V, P_LAW, S_LAW, T_DT, T_V_R_DOT, T_V_TILDE, law_offsets
from ..tracking import force_command
from . import LawContext, check_sigma_step, finish, law_update, tick3
from ._adaptive import DIAG, adaptive_estimate


@dataclass(frozen=True)
class CompositePConstSettings(Validated):
    """The constant-P composite law's own gains (the ``[controller.composite_pconst]`` table)."""

    sigma: float = setting("adaptation units", "sigma-modification toward theta_0 (eq:th_adapt)",
                           default=1e-4, ge=0.0, le=100.0)
    adaptation_gain_scale: float = setting(
        "-", "multiplier of the adaptation gain P0 (the vehicle's prior or a posterior): k P0 adapts every "
        "direction k times faster (in the Kalman view, the measurement noise R divided by k); 1: P0 as given",
        default=1.0, gt=0.0, le=1e6)


Settings = CompositePConstSettings
"""The law interface's name for the settings class."""

TUNABLE = (("sigma", 1e-6, 1.0, True), ("adaptation_gain_scale", 1e-2, 1e3, True))
"""The gains ``vtoladapt tune`` searches (:mod:`vtoladapt.experiments.tuning`): (setting, low, high, log scale).
Its adaptation gain is P0 itself, the vehicle's prior (Table III), times ``adaptation_gain_scale``."""


PARAMS = BlockLayout("composite_pconst parameters", [
    Field("SIGMA", 1, "adaptation units", "sigma-modification"),
])
STATE = BlockLayout("composite_pconst state", [
    Field("ACTIVE_SET", 1, "-", "bit mask of the bounds the last projection held"),
])
(P_SIGMA,) = law_offsets(PARAMS, P_LAW, "SIGMA")
(S_ACTIVE_SET,) = law_offsets(STATE, S_LAW, "ACTIVE_SET")
(D_PROJ_ACTIVE,) = law_offsets(DIAG, D_LAW, "PROJ_ACTIVE")


def fill_params(settings: CompositePConstSettings, ctx: LawContext) -> np.ndarray:
    """The law's parameter block; ``ValueError`` if sigma makes the explicit sigma step unstable."""
    check_sigma_step(settings.sigma, ctx, "controller.composite_pconst")
    return PARAMS.pack(SIGMA=settings.sigma)


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """Nothing beyond the shared start (theta-hat = theta_init, P = P0)."""


@law_update
def update(params, state, tick, diag):
    """Adapt theta-hat with P = P0, then the force command (eq:f_ctrl); see the law interface."""
    adapt_active, faults = adaptive_estimate(
        ad.ADAPT_PCONST, params, state, tick, diag, S_ACTIVE_SET, D_PROJ_ACTIVE, 1.0, tick[T_DT], params[P_SIGMA],
        np.inf)
    K_v = (params[P_K_V], params[P_K_V + 1], params[P_K_V + 2])
    finish(tick, force_command(tick3(tick, T_V_R_DOT), tick3(tick, T_V_TILDE), K_v), adapt_active, faults)
