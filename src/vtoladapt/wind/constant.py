"""A constant wind vector (``[wind] constant_mps``, NED, m/s): the simplest wind part.

A steady part (:mod:`vtoladapt.wind.registry`, the interface of :mod:`vtoladapt.parts`): it adds its
vector to the tick's wind and to its mean, so the turbulence is convected by it and scales with it.
Its settings are the ``constant_mps`` key of ``[wind]`` itself, not a table of its own.
"""
from __future__ import annotations

import numpy as np

from ..layout import W_MEAN_W, W_V_W, BlockLayout, Field
from .registry import wind_step

Settings = None
"""No table of its own: :attr:`vtoladapt.wind.WindConfig.constant_mps` holds the vector."""
PARAMS = BlockLayout("constant wind", [Field("V_W", 3, "m/s", "the constant wind vector, NED")])
(_V_W,) = PARAMS.offsets("V_W")
STATE = BlockLayout("constant wind state", [])
NORMALS_PER_STEP = 0
UNIFORMS_PER_STEP = 0


def pack(settings, wind) -> np.ndarray:
    """The vector ``settings`` (``[wind] constant_mps``) as the part's block."""
    return PARAMS.pack(V_W=settings)


def initial_state(params: np.ndarray, rng) -> np.ndarray:
    """No state."""
    return np.zeros(0)


@wind_step
def step(params, state, t, dt, p_W, draws, wind):
    """Add the constant vector to the tick's wind and to its mean."""
    for j in range(3):
        wind[W_V_W + j] += params[_V_W + j]
        wind[W_MEAN_W + j] += params[_V_W + j]
