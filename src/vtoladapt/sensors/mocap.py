"""The motion-capture channel (``[sensors.mocap]``): position and velocity, delayed.

Position noise 0.5 mm (Vicon / OptiTrack class), velocity either with its own noise
(``velocity_from = "direct"``, 0.02 m/s: what the autopilot's estimator fusing the motion capture
delivers) or by differencing the noisy positions with a first-order low-pass
(``"differentiate"``). Both are delayed by ``latency_s`` (12 ms = 3 ticks at 250 Hz: camera
processing plus the link to the autopilot), rounded to a whole number of ticks and kept in a ring
buffer in the channel's state. The first step fills the buffer with the truth it is given.

A sensor channel (:mod:`vtoladapt.sensors.registry`): writes ``P_W`` and ``V_W``; every step
consumes six standard normals (position NED, velocity NED), ideal or not.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import layout
from ..config import Validated, setting
from ..layout import BlockLayout, Field
from .registry import sensor_step

MOCAP_RING_SIZE = 128
"""Ticks of motion-capture history kept for the latency (127 ticks of delay at most)."""

VELOCITY_SOURCES = ("direct", "differentiate")


@dataclass(frozen=True)
class MocapConfig(Validated):
    """Motion-capture position and velocity (``[sensors.mocap]``)."""

    config_section = "sensors.mocap"

    ideal: bool = setting("-", "perfect, undelayed position and velocity", default=False)
    position_noise_std_m: float = setting("m", "position noise per axis (Vicon/OptiTrack ~0.5 mm)",
                                          default=0.0005, ge=0.0, le=10.0)
    velocity_from: str = setting(
        "-", "'direct': truth plus noise; 'differentiate': difference of the noisy positions, "
        "low-passed", default="direct", choices=VELOCITY_SOURCES)
    velocity_noise_std_mps: float = setting(
        "m/s", "velocity noise per axis ('direct')", default=0.02, ge=0.0, le=10.0)
    velocity_lowpass_hz: float = setting(
        "Hz", "first-order low-pass cut-off on the differenced velocity ('differentiate'; "
        "0: none)", default=20.0, ge=0.0, le=1e4)
    latency_s: float = setting(
        "s", "delay of position and velocity, rounded to whole control ticks", default=0.012,
        ge=0.0, le=0.25)


def latency_ticks(latency_s: float, dt_s: float) -> int:
    """Whole control ticks of delay for a latency (nearest, halves up), as the kernel rounds it."""
    return int(latency_s / dt_s + 0.5)


# --- the channel (vtoladapt.parts) --------------------------------------------------------------
Settings = MocapConfig
WRITES = ("P_W", "V_W")
DRAWS = BlockLayout("motion-capture draws per step (standard normals)", [
    Field("POSITION", 3, "-", "position noise, NED"),
    Field("VELOCITY", 3, "-", "velocity noise, NED (drawn also when differencing)"),
])
_D_POSITION, _D_VELOCITY = DRAWS.offsets("POSITION", "VELOCITY")
NORMALS_PER_STEP = DRAWS.size
UNIFORMS_PER_STEP = 0

PARAMS = BlockLayout("motion-capture parameters", [
    Field("IDEAL", 1, "-", "1.0: perfect, undelayed position and velocity"),
    Field("POS_STD", 1, "m", "position noise per axis"),
    Field("VEL_DIFF", 1, "-", "1.0: velocity by differencing positions; 0.0: direct noise"),
    Field("VEL_STD", 1, "m/s", "velocity noise per axis (direct)"),
    Field("VEL_LP_HZ", 1, "Hz", "low-pass cut-off of the differenced velocity (0: none)"),
    Field("LATENCY", 1, "s", "delay of position and velocity"),
])
_IDEAL, _POS_STD, _VEL_DIFF, _VEL_STD, _VEL_LP_HZ, _LATENCY = PARAMS.offsets(*(f.name for f in PARAMS.fields))

SAMPLE = BlockLayout("motion-capture ring entry", [
    Field("P_W", 3, "m", "true position, NED"),
    Field("V_W", 3, "m/s", "true velocity, NED"),
])
_RING_P, _RING_V = SAMPLE.offsets("P_W", "V_W")
_RING_STRIDE = SAMPLE.size

STATE = BlockLayout("motion-capture state", [
    Field("INIT", 1, "-", "0.0 until the first step has filled the ring and the filter"),
    Field("PREV_P", 3, "m", "previous delayed noisy position"),
    Field("VEL_F", 3, "m/s", "low-passed differenced velocity"),
    Field("DT_KEY", 1, "s", "dt the cached coefficients below were computed for (0: none yet)"),
    Field("GAIN", 1, "-", "1 - exp(-2 pi f_c dt) of the differenced-velocity low-pass"),
    Field("DELAY", 1, "ticks", "latency in whole ticks"),
    Field("RING_HEAD", 1, "-", "ring slot written this tick"),
    Field("RING", SAMPLE.size * MOCAP_RING_SIZE, "-", "MOCAP_RING_SIZE entries of SAMPLE"),
])
_S_INIT, _S_PREV_P, _S_VEL_F, _S_DT_KEY, _S_GAIN, _S_DELAY, _S_RING_HEAD, _S_RING = STATE.offsets(
    *(f.name for f in STATE.fields))

_MEAS_P = layout.MEAS_P_W
_MEAS_V = layout.MEAS_V_W
_X_P = layout.X_P_W
_X_V = layout.X_V_W


def pack(settings: MocapConfig, context) -> np.ndarray:
    """The channel's parameter block."""
    return PARAMS.pack(IDEAL=float(settings.ideal), POS_STD=settings.position_noise_std_m,
                       VEL_DIFF=float(settings.velocity_from == "differentiate"),
                       VEL_STD=settings.velocity_noise_std_mps, VEL_LP_HZ=settings.velocity_lowpass_hz,
                       LATENCY=settings.latency_s)


def check_dt(params: np.ndarray, dt_s: float) -> None:
    """``ValueError`` if the latency in ``params`` (the channel's block) is more whole ticks of
    ``dt_s`` than the ring buffer keeps: the step, a C kernel, cannot raise, so this is checked
    before it runs (by :func:`vtoladapt.sensors.run_sensor_model`; a scenario checks its own)."""
    ticks = latency_ticks(float(params[_LATENCY]), dt_s)
    if params[_IDEAL] == 0.0 and ticks >= MOCAP_RING_SIZE:
        raise ValueError(f"sensors: mocap latency_s = {params[_LATENCY]:g}: {ticks} ticks at dt = {dt_s:g} s "
                         f"exceeds the ring buffer (at most MOCAP_RING_SIZE - 1 = {MOCAP_RING_SIZE - 1} ticks)")


def initial_state(params: np.ndarray, rng) -> np.ndarray:
    """A fresh state (the first step fills it); no draws."""
    return np.zeros(STATE.size)


@njit(cache=True, inline="always")
def _first_step(state, x_true):
    """Fill the latency ring and settle the velocity filter at the first truth seen."""
    for s in range(MOCAP_RING_SIZE):
        k = _S_RING + _RING_STRIDE * s
        for j in range(3):
            state[k + _RING_P + j] = x_true[_X_P + j]
            state[k + _RING_V + j] = x_true[_X_V + j]
    state[_S_RING_HEAD] = MOCAP_RING_SIZE - 1  # the first step writes slot 0
    for j in range(3):
        state[_S_PREV_P + j] = x_true[_X_P + j]
        state[_S_VEL_F + j] = x_true[_X_V + j]
    state[_S_INIT] = 1.0


@njit(cache=True, inline="always")
def _dt_coefficients(params, state, dt):
    """Coefficients that depend on the tick only, recomputed when ``dt`` changes."""
    # a latency beyond the ring is refused when the run is assembled (its settings and the tick are
    # known then); the step is a C kernel and cannot raise, so the clamp only keeps it inside the ring
    n_delay = min(int(params[_LATENCY] / dt + 0.5), MOCAP_RING_SIZE - 1)
    state[_S_DELAY] = n_delay
    fc = params[_VEL_LP_HZ]
    state[_S_GAIN] = 1.0 if fc <= 0.0 else -np.expm1(-2.0 * np.pi * fc * dt)
    state[_S_DT_KEY] = dt


@sensor_step
def step(params, state, t, dt, x_true, truth, draws, meas):
    """This tick's delayed, noisy position and velocity."""
    if state[_S_INIT] == 0.0:
        _first_step(state, x_true)
    if dt != state[_S_DT_KEY]:
        _dt_coefficients(params, state, dt)
    n_delay = int(state[_S_DELAY])
    head = (int(state[_S_RING_HEAD]) + 1) % MOCAP_RING_SIZE
    state[_S_RING_HEAD] = head
    k = _S_RING + _RING_STRIDE * head
    for j in range(3):
        state[k + _RING_P + j] = x_true[_X_P + j]
        state[k + _RING_V + j] = x_true[_X_V + j]
    d = _S_RING + _RING_STRIDE * ((head - n_delay) % MOCAP_RING_SIZE)
    ideal = params[_IDEAL] != 0.0
    for j in range(3):
        if ideal:
            meas[_MEAS_P + j] = x_true[_X_P + j]
        else:
            meas[_MEAS_P + j] = state[d + _RING_P + j] + params[_POS_STD] * draws[_D_POSITION + j]
    differentiate = params[_VEL_DIFF] != 0.0
    gain = state[_S_GAIN]
    for j in range(3):
        if ideal:
            meas[_MEAS_V + j] = x_true[_X_V + j]
        elif differentiate:
            p_now = meas[_MEAS_P + j]
            raw = (p_now - state[_S_PREV_P + j]) / dt
            state[_S_PREV_P + j] = p_now
            state[_S_VEL_F + j] += gain * (raw - state[_S_VEL_F + j])
            meas[_MEAS_V + j] = state[_S_VEL_F + j]
        else:
            meas[_MEAS_V + j] = state[d + _RING_V + j] + params[_VEL_STD] * draws[_D_VELOCITY + j]
