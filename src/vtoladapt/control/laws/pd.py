"""The PID without its integral (the paper's controller V).

Exactly :mod:`.pid` with the integral left out: the same parameter, state and diagnostics blocks, with the
integral gain fixed at 0 (a PD has none to set) and the integrator never moving. Its
``feedforward`` setting is the PID's (``"v_r_dot"`` by default, the fair comparison; see
:mod:`.pid`): with ``K_D = 0`` and ``"v_r_dot"`` the PD is exactly ``nominal``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...config import Validated, setting
from . import LawContext, law_update
from .pid import DIAG, FEEDFORWARD_CHOICES, FEEDFORWARD_DOC, PARAMS, STATE, feedforward_flag, pid_update


@dataclass(frozen=True)
class PDSettings(Validated):
    """The PD's own gains (the ``[controller.pd]`` table)."""

    K_D: tuple[float, ...] = setting("-", "velocity-derivative gain on the measured acceleration, NED",
                                     default=(0.2, 0.2, 0.0), ge=0.0, length=3)
    derivative_cutoff_hz: float = setting("Hz", "low-pass on the measured acceleration", default=5.0, gt=0.0)
    feedforward: str = setting("-", FEEDFORWARD_DOC, default="v_r_dot", choices=FEEDFORWARD_CHOICES)


Settings = PDSettings
"""The law interface's name for the settings class."""

TUNABLE = (("K_D[0:2]", 0.0, 2.0, False), ("K_D[2]", 0.0, 2.0, False), ("derivative_cutoff_hz", 0.5, 40.0, True))
"""The gains ``vtoladapt tune`` searches (:mod:`vtoladapt.experiments.tuning`): (setting, low, high, log scale)."""


def fill_params(settings: PDSettings, ctx: LawContext) -> np.ndarray:
    """The PID's parameter block with no integral (``K_I`` = 0, limit 0)."""
    return PARAMS.pack(K_D=settings.K_D, DERIV_HZ=settings.derivative_cutoff_hz,
                       FF_V_R_DOT=feedforward_flag(settings.feedforward))


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """Derivative filter empty (the shared start holds theta-hat = theta_init)."""


@law_update
def update(params, state, tick, diag):
    """The PD force command (:mod:`.pid` without the integral). See the law interface."""
    pid_update(params, state, tick, diag, False)
