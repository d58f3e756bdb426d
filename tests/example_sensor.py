"""A GNSS receiver in place of the motion capture: fixes at its own rate, noisy, quantised (a user's sensor)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vtoladapt.config import Validated, setting
from vtoladapt.layout import MEAS_P_W, MEAS_V_W, X_P_W, X_V_W, BlockLayout, Field
from vtoladapt.sensors.registry import sensor_step


@dataclass(frozen=True)
class GnssSettings(Validated):
    """The ``[sensors.gnss]`` table (RTK-class defaults)."""

    config_section = "sensors.gnss"

    position_noise_std_m: float = setting("m", "position noise per axis", default=0.02, ge=0.0, le=100.0)
    position_quantum_m: float = setting("m", "position resolution", default=0.001, gt=0.0, le=10.0)
    velocity_noise_std_mps: float = setting("m/s", "velocity noise per axis", default=0.03, ge=0.0, le=10.0)
    rate_hz: float = setting("Hz", "fixes per second; the last fix holds in between", default=50.0, gt=0.0,
                             le=1000.0)


Settings = GnssSettings
WRITES = ("P_W", "V_W")   # the measurement fields it writes: the motion capture's
PARAMS = BlockLayout("GNSS parameters", [
    Field("POS_STD", 1, "m", "position noise per axis"),
    Field("POS_QUANTUM", 1, "m", "position resolution"),
    Field("VEL_STD", 1, "m/s", "velocity noise per axis"),
    Field("PERIOD", 1, "s", "time between fixes"),
])
STATE = BlockLayout("GNSS state", [
    Field("NEXT_FIX", 1, "s", "time of the next fix"),
    Field("P_W", 3, "m", "the last fix's position, NED"),
    Field("V_W", 3, "m/s", "the last fix's velocity, NED"),
])
DRAWS = BlockLayout("GNSS draws per step (standard normals, drawn every tick, fix or not)", [
    Field("POSITION", 3, "-", "position noise, NED"),
    Field("VELOCITY", 3, "-", "velocity noise, NED"),
])
NORMALS_PER_STEP = DRAWS.size
UNIFORMS_PER_STEP = 0
_D_POSITION, _D_VELOCITY = DRAWS.offsets("POSITION", "VELOCITY")
_POS_STD, _POS_QUANTUM, _VEL_STD, _PERIOD = PARAMS.offsets("POS_STD", "POS_QUANTUM", "VEL_STD", "PERIOD")
_NEXT_FIX, _FIX_P, _FIX_V = STATE.offsets("NEXT_FIX", "P_W", "V_W")


def pack(settings: GnssSettings, context) -> np.ndarray:
    """The parameter block, once per run (``context``: densities and the scenario's folder, unused)."""
    return PARAMS.pack(POS_STD=settings.position_noise_std_m, POS_QUANTUM=settings.position_quantum_m,
                       VEL_STD=settings.velocity_noise_std_mps, PERIOD=1.0 / settings.rate_hz)


def initial_state(params: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The first fix is due at once; draws nothing."""
    return np.zeros(STATE.size)


@sensor_step
def step(params, state, t, dt, x_true, truth, draws, meas):
    """A new fix when one is due (noisy, quantised), else the last one."""
    if t >= state[_NEXT_FIX]:
        q = params[_POS_QUANTUM]
        for j in range(3):
            p = x_true[X_P_W + j] + params[_POS_STD] * draws[_D_POSITION + j]
            state[_FIX_P + j] = q * np.round(p / q)
            state[_FIX_V + j] = x_true[X_V_W + j] + params[_VEL_STD] * draws[_D_VELOCITY + j]
        state[_NEXT_FIX] = t + params[_PERIOD] - 0.5 * dt  # half a tick early: no fix lost to rounding
    for j in range(3):
        meas[MEAS_P_W + j] = state[_FIX_P + j]
        meas[MEAS_V_W + j] = state[_FIX_V + j]
