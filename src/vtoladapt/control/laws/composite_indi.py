"""The composite law with INDI's measured residual on top of the adapted model (not in the paper; issue #34).

Force: ``f_r = v_r' - K_v v~ - g + R e`` with ``e = W theta-hat - a_m`` the prediction error of the *adapted*
model (eq:prediction_error) through INDI's fault handling (:func:`.indi.increment_at`: gated on the
accelerometer, limited, faded while it is invalid, blended in at start-up). theta-hat and P are adapted exactly
as by the composite law (:func:`.composite.composite_estimate`; its ``estimator`` setting chooses the paper's
form or the Kalman form).

Why. The composite law rejects a force error only inside span(Phi) and only as fast as theta-hat moves: at low
airspeed the horizontal columns are near zero, so nothing integrates a horizontal residual there, and while the
probe is out it does not adapt at all. INDI's increment is the residual the accelerometer measures, whatever
its cause, at the filter's bandwidth. Here the model carries what it can explain (theta-hat) and the increment
the rest: with ``theta-hat`` right the increment is the filter's noise; with a force outside span(Phi) the
increment cancels it (``tests/test_control_composite_indi.py``: the composite law keeps a steady velocity
error of ``d / K_v`` for a constant force ``d`` its columns cannot express, this law none).

Interplay. The increment is formed from ``e``, which the adaptation also drives to zero: as theta-hat learns
the part of a residual inside span(Phi), the increment hands that part over to the model, so the model's
feed-forward is what remains when the accelerometer is lost. Time-scale separation as for INDI (the shared
filter at least 3 x max K_v, checked).

Settings (``[controller.composite_indi]``): the composite law's, and INDI's ``increment_limit_mps2``,
``fault_fade_s``, ``reentry_blend_s`` (:mod:`.indi`, same defaults and reasons).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...config import setting
from ...layout import BlockLayout, Field
from ..blocks import D_LAW, P_K_V, P_LAW, S_LAW, T_ACCEL_OK, T_DT, T_E, T_NEW_DT, T_V_R_DOT, T_V_TILDE, law_offsets
from ..tracking import force_command
from . import LawContext, composite, finish, indi, law_update, tick3, tick_R


@dataclass(frozen=True)
class CompositeIndiSettings(composite.CompositeSettings):
    """The composite law's settings and INDI's fault handling (the ``[controller.composite_indi]`` table)."""

    increment_limit_mps2: float = setting(
        "m/s^2", "limit on |R (W theta-hat - a_m)|, the increment added to the composite command",
        default=5.0, gt=0.0)
    fault_fade_s: float = setting(
        "s", "while the accelerometer is invalid the last increment fades toward zero with this time constant",
        default=1.0, gt=0.0)
    reentry_blend_s: float = setting(
        "s", "at start-up and when the sensors are valid again the increment blends in over this time (0: at once)",
        default=0.1, ge=0.0)


Settings = CompositeIndiSettings
"""The law interface's name for the settings class."""

TUNABLE = composite.TUNABLE + (("increment_limit_mps2", 1.0, 30.0, True),)
"""The gains ``vtoladapt tune`` searches: the composite law's (both estimator forms) and INDI's limit."""

# the composite law's blocks first (its kernels address them at the same offsets), then INDI's
PARAMS = BlockLayout("composite_indi parameters", [*composite.PARAMS.fields, *indi.PARAMS.fields])
STATE = BlockLayout("composite_indi state", [*composite.STATE.fields, *indi.STATE.fields])
DIAG = BlockLayout("composite_indi diagnostics", [*composite.DIAG.fields, *indi.DIAG.fields])
P_INC_LIMIT, P_FADE_S, P_BLEND_S = law_offsets(PARAMS, P_LAW, "INC_LIMIT", "FADE_S", "BLEND_S")
S_INCREMENT, S_WEIGHT, S_FADE, S_BLEND_STEP = law_offsets(STATE, S_LAW, "INCREMENT", "WEIGHT", "FADE", "BLEND_STEP")
(D_INCREMENT,) = law_offsets(DIAG, D_LAW, "INCREMENT")


def fill_params(settings: CompositeIndiSettings, ctx: LawContext) -> np.ndarray:
    """The composite law's parameters, then INDI's; ``ConfigError`` as either law's checks."""
    indi.check_config(settings, ctx.config, "")
    own = composite.fill_params(settings, ctx)
    return np.concatenate([own, indi.PARAMS.pack(INC_LIMIT=settings.increment_limit_mps2,
                                                 FADE_S=settings.fault_fade_s, BLEND_S=settings.reentry_blend_s)])


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """Nothing beyond the shared start: no bound held, no increment, blend weight 0."""


@law_update
def update(params, state, tick, diag):
    """Adapt theta-hat and P as the composite law, then its command plus the measured residual (module notes)."""
    adapt_active, faults = composite.composite_estimate(params, state, tick, diag)
    if tick[T_NEW_DT] > 0.0:
        dt = tick[T_DT]
        state[S_FADE] = np.exp(-dt / params[P_FADE_S])
        blend_s = params[P_BLEND_S]
        state[S_BLEND_STEP] = min(1.0, dt / blend_s) if blend_s > 0.0 else 1.0
    inc = indi.increment_at(params, state, tick[T_ACCEL_OK] > 0.0, tick_R(tick), tick3(tick, T_E), P_INC_LIMIT,
                            S_INCREMENT, S_WEIGHT, S_FADE, S_BLEND_STEP)
    K_v = (params[P_K_V], params[P_K_V + 1], params[P_K_V + 2])
    nominal = force_command(tick3(tick, T_V_R_DOT), tick3(tick, T_V_TILDE), K_v)
    for i in range(3):
        diag[D_INCREMENT + i] = inc[i]
    finish(tick, (nominal[0] + inc[0], nominal[1] + inc[1], nominal[2] + inc[2]), adapt_active, faults)
