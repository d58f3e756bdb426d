"""The composite law with adaptation off: theta-hat = theta_0 for the whole run.

The force command of eq:f_ctrl (as :mod:`.composite`) flown with the prior model: theta-hat is
set to theta_0 at the start (whatever the initial theta-hat asked for) and never adapted, so P
plays no part. The prediction error of theta_0 is still logged (``pred_err_*``), which shows
how far the prior model is from the measured specific force. It has no settings of its own.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ...config import Validated
from ...layout import BlockLayout
from ..frontend import prediction_error
from ..layouts import N_THETA, P_K_V, P_THETA0, S_THETA
from ..tracking import force_command
from . import LawContext


@dataclass(frozen=True)
class NominalSettings(Validated):
    """The nominal law has no settings of its own (the ``[controller.nominal]`` table is empty)."""


Settings = NominalSettings
"""The law interface's name for the settings class."""

TUNABLE = ()
"""No gain of its own: nothing for ``vtoladapt tune`` to search (:mod:`vtoladapt.experiments.tuning`)."""

PARAMS = BlockLayout("nominal parameters", [])
STATE = BlockLayout("nominal state", [])


def fill_params(settings: NominalSettings, ctx: LawContext) -> np.ndarray:
    """No parameters beyond the shared ones."""
    return PARAMS.pack()


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """theta-hat = theta_0."""
    state[S_THETA:S_THETA + N_THETA] = params[P_THETA0:P_THETA0 + N_THETA]


@njit(cache=True)
def update(params, state, diag, dt, new_dt, may_adapt, Phi, R, v_W, v_r_dot, v_tilde, a_d) -> tuple:
    """eq:f_ctrl with the constant theta-hat; see the law interface."""
    K_v = (params[P_K_V], params[P_K_V + 1], params[P_K_V + 2])
    return force_command(v_r_dot, v_tilde, K_v), prediction_error(state), False, 0
