"""A wind shear: a horizontal wind growing with height, with white gusting (a user's wind part)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vtoladapt.config import Validated, setting
from vtoladapt.layout import W_MEAN_W, W_V_W, BlockLayout, Field
from vtoladapt.wind.registry import wind_step


@dataclass(frozen=True)
class ShearSettings(Validated):
    """The ``[wind.shear]`` table."""

    config_section = "wind.shear"

    speed_mps: float = setting("m/s", "wind speed at the reference height (p_D = 0)", default=5.0, ge=0.0, le=60.0)
    bearing_deg: float = setting("deg", "where the wind comes from (0: north)", default=0.0, ge=-360.0, le=360.0)
    shear_per_s: float = setting("1/s", "speed gained per metre of height", default=0.2, ge=-10.0, le=10.0)
    gust_std_mps: float = setting("m/s", "white gusting per axis", default=0.0, ge=0.0, le=10.0)


Settings = ShearSettings
PARAMS = BlockLayout("shear parameters", [
    Field("SPEED", 1, "m/s", "wind speed at the reference height"),
    Field("DIR", 2, "-", "unit (N, E) vector the wind blows toward"),
    Field("SHEAR", 1, "1/s", "speed gained per metre of height"),
    Field("GUST_STD", 1, "m/s", "white gusting per axis"),
])
STATE = BlockLayout("shear state", [Field("STEPS", 1, "-", "steps taken")])
NORMALS_PER_STEP = 3      # the gusting, xyz, drawn whatever gust_std_mps is
UNIFORMS_PER_STEP = 0
_SPEED, _DIR, _SHEAR, _GUST_STD = PARAMS.offsets("SPEED", "DIR", "SHEAR", "GUST_STD")
(_STEPS,) = STATE.offsets("STEPS")


def pack(settings: ShearSettings, wind) -> np.ndarray:
    """The parameter block, once per run (``wind`` is the scenario's whole WindConfig)."""
    b = math.radians(settings.bearing_deg)
    return PARAMS.pack(SPEED=settings.speed_mps, DIR=(-math.cos(b), -math.sin(b)),
                       SHEAR=settings.shear_per_s, GUST_STD=settings.gust_std_mps)


def initial_state(params: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """No step taken yet; draws nothing."""
    return np.zeros(STATE.size)


@wind_step
def step(params, state, t, dt, p_W, draws, wind):
    """Add the shear at the vehicle's height (its steady part also to the mean wind) and the gusting."""
    height = -p_W[2]  # p_W is NED
    speed = params[_SPEED] + params[_SHEAR] * height
    for j in range(2):
        wind[W_V_W + j] += speed * params[_DIR + j]
        wind[W_MEAN_W + j] += speed * params[_DIR + j]
    for j in range(3):
        wind[W_V_W + j] += params[_GUST_STD] * draws[j]
    state[_STEPS] += 1.0
