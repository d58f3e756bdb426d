"""Discrete gusts: ``"one_minus_cosine"`` and ``"step"`` shapes added to the wind.

``"one_minus_cosine"``: ``A (1 - cos(2 pi (t - t0) / T)) / 2`` for ``t0 <= t <= t0 + T``: rises
to ``A`` at mid-gust and returns to zero, the CS-25 / FAR-25 discrete-gust shape. ``"step"``:
``A`` for ``t0 <= t < t0 + T``. ``A`` is a wind vector (NED, m/s); the gusts of a scenario add up.

A wind part (:mod:`vtoladapt.wind.registry`, the interface of :mod:`vtoladapt.parts`), not a steady
one (the turbulence does not scale with a gust): :func:`pack_gusts` lays the gusts out as
:data:`GUSTS_PARAMS` (each entry :data:`GUST_PARAMS`), :func:`add_gusts` reads them at a base offset
``o``, and :func:`step` adds them to the tick's wind.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numba import njit

from ..config import Validated, setting
from ..layout import W_V_W, BlockLayout, Field
from .registry import wind_step

GUST_SHAPES = ("one_minus_cosine", "step")
MAX_GUSTS = 16
"""Largest number of gusts the kernel holds."""

GUST_PARAMS = BlockLayout("one gust", [
    Field("SHAPE", 1, "-", "index into GUST_SHAPES"),
    Field("START", 1, "s", "start time t0"),
    Field("DURATION", 1, "s", "duration T"),
    Field("AMPLITUDE", 3, "m/s", "peak wind vector A, NED"),
])
"""One entry of the gust table."""
GUSTS_PARAMS = BlockLayout("gusts", [
    Field("N", 1, "-", "number of gusts"),
    Field("TABLE", MAX_GUSTS * GUST_PARAMS.size, "-", "MAX_GUSTS entries laid out as GUST_PARAMS"),
])
"""The gusts' block of the wind parameter array."""
_N, _TABLE = GUSTS_PARAMS.offsets("N", "TABLE")
_SHAPE, _START, _DURATION, _AMPLITUDE = GUST_PARAMS.offsets("SHAPE", "START", "DURATION", "AMPLITUDE")
_STRIDE = GUST_PARAMS.size


@dataclass(frozen=True)
class GustConfig(Validated):
    """One discrete gust (an entry of ``[[wind.gusts]]``)."""

    config_section = "wind.gusts"

    shape: str = setting("-", "'one_minus_cosine' (up to A and back to zero) or 'step'",
                         choices=GUST_SHAPES)
    start_s: float = setting("s", "start time", ge=0.0, le=3600.0)
    duration_s: float = setting("s", "duration", gt=0.0, le=3600.0)
    amplitude_mps: tuple[float, ...] = setting("m/s", "peak wind vector, NED", ge=-60.0, le=60.0, length=3)


def pack_gusts(gusts: Sequence[GustConfig]) -> np.ndarray:
    """The gusts as their kernel block (layout :data:`GUSTS_PARAMS`)."""
    if len(gusts) > MAX_GUSTS:
        raise ValueError(f"{len(gusts)} gusts: at most {MAX_GUSTS} are allowed")
    p = np.zeros(GUSTS_PARAMS.size)
    p[_N] = len(gusts)
    for i, g in enumerate(gusts):
        k = _TABLE + _STRIDE * i
        p[k + _SHAPE] = GUST_SHAPES.index(g.shape)
        p[k + _START] = g.start_s
        p[k + _DURATION] = g.duration_s
        p[k + _AMPLITUDE:k + _AMPLITUDE + 3] = g.amplitude_mps
    return p


@njit(cache=True, inline="always")
def add_gusts(params: np.ndarray, o: int, t: float, out_v_W: np.ndarray) -> None:
    """Add the gusts' wind at time ``t`` (NED, m/s) to ``out_v_W``; the block starts at ``params[o]``."""
    for i in range(int(params[o + _N])):
        k = o + _TABLE + _STRIDE * i
        t0 = params[k + _START]
        dur = params[k + _DURATION]
        if t < t0 or t > t0 + dur:
            continue
        if params[k + _SHAPE] == 0.0:
            s = 0.5 * (1.0 - np.cos(2.0 * np.pi * (t - t0) / dur))
        elif t < t0 + dur:
            s = 1.0
        else:
            s = 0.0
        for j in range(3):
            out_v_W[j] += s * params[k + _AMPLITUDE + j]


# --- the part (vtoladapt.parts) -----------------------------------------------------------------
Settings = GustConfig
PARAMS = GUSTS_PARAMS
STATE = BlockLayout("gusts state", [])
NORMALS_PER_STEP = 0
UNIFORMS_PER_STEP = 0


def pack(settings: Sequence[GustConfig], wind) -> np.ndarray:
    """The part's parameter block: :func:`pack_gusts` of ``[[wind.gusts]]``."""
    return pack_gusts(settings)


def initial_state(params: np.ndarray, rng) -> np.ndarray:
    """No state: a gust is a function of time."""
    return np.zeros(0)


@wind_step
def step(params, state, t, dt, p_W, draws, wind):
    """Add the gusts' wind at ``t`` to the tick's wind (NED, m/s)."""
    add_gusts(params, 0, t, wind[W_V_W:W_V_W + 3])
