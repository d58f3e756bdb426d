"""The composite law with adaptation off: theta-hat = theta_0 for the whole run.

The force command of eq:f_ctrl (as :mod:`.composite`) flown with the prior model: theta-hat is
set to theta_0 at the start (whatever the initial theta-hat asked for) and never adapted, so P
plays no part. The prediction error of theta_0 is still logged (``pred_err_*``), which shows
how far the prior model is from the measured specific force. It has no settings of its own.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...config import Validated
from ...layout import BlockLayout
from ..blocks import A_N, A_THETA, A_THETA0, P_K_V, T_V_R_DOT, T_V_TILDE
from ..tracking import force_command
from . import LawContext, finish, law_update, tick3


@dataclass(frozen=True)
class NominalSettings(Validated):
    """The nominal law has no settings of its own (the ``[controller.nominal]`` table is empty)."""


Settings = NominalSettings
"""The law interface's name for the settings class."""

TUNABLE = ()
"""No gain of its own: nothing for ``vtoladapt tune`` to search (:mod:`vtoladapt.experiments.tuning`)."""

PARAMS = BlockLayout("nominal parameters", [])
STATE = BlockLayout("nominal state", [])
DIAG = BlockLayout("nominal diagnostics", [])


def fill_params(settings: NominalSettings, ctx: LawContext) -> np.ndarray:
    """No parameters beyond the shared ones."""
    return PARAMS.pack()


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """theta-hat = theta_0."""
    n, th, th0 = int(params[A_N]), int(params[A_THETA]), int(params[A_THETA0])
    state[th:th + n] = params[th0:th0 + n]


@law_update
def update(params, state, tick, diag):
    """eq:f_ctrl with the constant theta-hat; see the law interface."""
    K_v = (params[P_K_V], params[P_K_V + 1], params[P_K_V + 2])
    finish(tick, force_command(tick3(tick, T_V_R_DOT), tick3(tick, T_V_TILDE), K_v), False, 0)
