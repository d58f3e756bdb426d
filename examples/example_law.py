"""Example law: eq:f_ctrl with theta-hat held at its start and the shared K_v scaled by its own gain."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from vtoladapt.config import setting
from vtoladapt.control.frontend import prediction_error
from vtoladapt.control.layouts import P_K_V, P_LAW, S_LAW, law_offsets
from vtoladapt.control.laws import LawContext
from vtoladapt.control.tracking import force_command
from vtoladapt.layout import BlockLayout, Field


@dataclass(frozen=True)
class ExampleSettings:
    """The example law's own gains (``[controller.example]``)."""

    gain_scale: float = setting("-", "factor on the shared velocity gain K_v", default=1.0, gt=0.0)


Settings = ExampleSettings
PARAMS = BlockLayout("example parameters", [Field("SCALE", 1, "-", "factor on K_v")])
STATE = BlockLayout("example state", [Field("TICKS", 1, "-", "ticks flown")])
(P_SCALE,) = law_offsets(PARAMS, P_LAW, "SCALE")
(S_TICKS,) = law_offsets(STATE, S_LAW, "TICKS")


def fill_params(settings: ExampleSettings, ctx: LawContext) -> np.ndarray:
    """The scale factor."""
    return PARAMS.pack(SCALE=settings.gain_scale)


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """No tick flown yet (zeros already say so)."""


@njit(cache=True)
def update(params, state, diag, dt, new_dt, may_adapt, Phi, R, v_W, v_r_dot, v_tilde, a_d) -> tuple:
    """eq:f_ctrl with K_v scaled; theta-hat is never adapted."""
    state[S_TICKS] += 1.0
    s = params[P_SCALE]
    K_v = (s * params[P_K_V], s * params[P_K_V + 1], s * params[P_K_V + 2])
    return force_command(v_r_dot, v_tilde, K_v), prediction_error(state), False, 0
