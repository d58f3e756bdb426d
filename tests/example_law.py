"""An example control law from outside the package: eq:f_ctrl with theta-hat held and the shared K_v scaled.

This module is what README "Adding a controller" shows: one module meeting the law interface
(:mod:`vtoladapt.control`), registered by ``vtoladapt.components.register("law", INFO)``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vtoladapt.config import Validated, setting
from vtoladapt.control.blocks import D_LAW, P_K_V, P_LAW, S_LAW, T_V_R_DOT, T_V_TILDE, law_offsets
from vtoladapt.control.laws import LawContext, finish, law_update, tick3
from vtoladapt.control.registry import ControllerInfo
from vtoladapt.control.tracking import force_command
from vtoladapt.layout import BlockLayout, Field


@dataclass(frozen=True)
class ExampleSettings(Validated):
    """The example law's own gains (``[controller.example]``)."""

    gain_scale: float = setting("-", "factor on the shared velocity gain K_v", default=1.0, gt=0.0, le=10.0)


Settings = ExampleSettings
PARAMS = BlockLayout("example parameters", [Field("SCALE", 1, "-", "factor on K_v")])
STATE = BlockLayout("example state", [Field("TICKS", 1, "-", "ticks flown")])
DIAG = BlockLayout("example diagnostics", [Field("SCALED_K_V_N", 1, "1/s", "the velocity gain flown, north",
                                                 columns=("example_K_v_N_per_s",))])
(P_SCALE,) = law_offsets(PARAMS, P_LAW, "SCALE")
(S_TICKS,) = law_offsets(STATE, S_LAW, "TICKS")
(D_K_V_N,) = law_offsets(DIAG, D_LAW, "SCALED_K_V_N")


def fill_params(settings: ExampleSettings, ctx: LawContext) -> np.ndarray:
    """The scale factor."""
    return PARAMS.pack(SCALE=settings.gain_scale)


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """No tick flown yet (zeros already say so)."""


@law_update
def update(params, state, tick, diag):
    """eq:f_ctrl with K_v scaled; theta-hat is never adapted."""
    state[S_TICKS] += 1.0
    s = params[P_SCALE]
    K_v = (s * params[P_K_V], s * params[P_K_V + 1], s * params[P_K_V + 2])
    diag[D_K_V_N] = K_v[0]
    finish(tick, force_command(tick3(tick, T_V_R_DOT), tick3(tick, T_V_TILDE), K_v), False, 0)


INFO = ControllerInfo("example", "Example (scaled K_v)", "tab:olive", False, False,
                      "a user's minimal law: eq:f_ctrl with its own gain factor", __name__)
