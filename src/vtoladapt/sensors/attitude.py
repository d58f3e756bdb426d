"""The attitude-estimate channel (``[sensors.attitude]``): the true ``q_WB`` rotated by a small random
body-axis rotation, 0.2 deg (1 sigma per axis), drawn each tick.

A sensor channel (:mod:`vtoladapt.sensors.registry`): writes ``Q_WB``; every step consumes three
standard normals (the rotation's body-axis components), ideal or not.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import layout
from ..config import Validated, setting
from ..layout import BlockLayout, Field
from .registry import sensor_step


@dataclass(frozen=True)
class AttitudeConfig(Validated):
    """Attitude estimate ``q_WB`` (``[sensors.attitude]``)."""

    config_section = "sensors.attitude"

    ideal: bool = setting("-", "perfect attitude", default=False)
    noise_std_deg: float = setting("deg", "small-rotation noise per body axis, each tick",
                                   default=0.2, ge=0.0, le=10.0)


# --- the channel (vtoladapt.parts) --------------------------------------------------------------
Settings = AttitudeConfig
WRITES = ("Q_WB",)
DRAWS = BlockLayout("attitude draws per step (standard normals)", [
    Field("ROTATION", 3, "-", "the small rotation's body-axis components"),
])
(_D_ROTATION,) = DRAWS.offsets("ROTATION")
NORMALS_PER_STEP = DRAWS.size
UNIFORMS_PER_STEP = 0

PARAMS = BlockLayout("attitude-estimate parameters", [
    Field("IDEAL", 1, "-", "1.0: perfect attitude"),
    Field("STD", 1, "rad", "small-rotation noise per body axis"),
])
_IDEAL, _STD = PARAMS.offsets("IDEAL", "STD")
STATE = BlockLayout("attitude-estimate state", [])

_Q = layout.X_Q_WB
_M = layout.MEAS_Q_WB


def pack(settings: AttitudeConfig, context) -> np.ndarray:
    """The channel's parameter block (radians)."""
    return PARAMS.pack(IDEAL=float(settings.ideal), STD=settings.noise_std_deg * (math.pi / 180.0))


def initial_state(params: np.ndarray, rng) -> np.ndarray:
    """No state."""
    return np.zeros(0)


@sensor_step
def step(params, state, t, dt, x_true, truth, draws, meas):
    """``q_meas = q_true * dq``, ``dq`` a small rotation about body axes."""
    s = params[_STD]
    r0 = s * draws[_D_ROTATION]
    r1 = s * draws[_D_ROTATION + 1]
    r2 = s * draws[_D_ROTATION + 2]
    if params[_IDEAL] != 0.0:
        for i in range(4):
            meas[_M + i] = x_true[_Q + i]
        return
    angle = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    c = np.cos(0.5 * angle)
    k = 0.5 if angle < 1e-12 else np.sin(0.5 * angle) / angle
    d0, d1, d2, d3 = c, k * r0, k * r1, k * r2
    q0, q1, q2, q3 = x_true[_Q], x_true[_Q + 1], x_true[_Q + 2], x_true[_Q + 3]
    w = q0 * d0 - q1 * d1 - q2 * d2 - q3 * d3
    x = q0 * d1 + q1 * d0 + q2 * d3 - q3 * d2
    y = q0 * d2 - q1 * d3 + q2 * d0 + q3 * d1
    z = q0 * d3 + q1 * d2 - q2 * d1 + q3 * d0
    norm = np.sqrt(w * w + x * x + y * y + z * z)
    meas[_M] = w / norm
    meas[_M + 1] = x / norm
    meas[_M + 2] = y / norm
    meas[_M + 3] = z / norm
