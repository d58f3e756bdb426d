"""The IMU channel (``[sensors.imu]``): gyroscope and accelerometer, sampled at the control rate.

White noise with the datasheet densities of a Pixhawk-class MEMS IMU (ICM-20689 / BMI088 class:
gyro ~0.007 deg/s/sqrt(Hz), accelerometer ~175 ug/sqrt(Hz)); a sample averaged over one tick ``dt``
has standard deviation ``density / sqrt(dt) = density * sqrt(rate)`` (0.11 deg/s and 0.027 m/s^2 at
250 Hz). Constant biases, drawn once per run (:func:`initial_state`, six standard normals), stand
for what the autopilot's start-up calibration leaves (0.1 deg/s, 0.05 m/s^2, 1 sigma); an optional
bias random walk (off by default). Outputs saturate at the full-scale range (2000 deg/s, 16 g). The
accelerometer measures the specific force ``a - g`` in body axes (:func:`specific_force_B`), so at
rest and level it reads ``[0, 0, -9.80665]`` (FRD).

A sensor channel (:mod:`vtoladapt.sensors.registry`): writes ``OMEGA_B`` and ``ACCEL_B``; every
step consumes twelve standard normals (gyro noise xyz, accelerometer noise xyz, gyro bias walk xyz,
accelerometer bias walk xyz), ideal or not.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import layout
from ..config import Validated, setting
from ..frames import GRAVITY_MPS2
from ..layout import BlockLayout, Field
from .registry import sensor_step

MICRO_G_MPS2 = 1e-6 * GRAVITY_MPS2
"""One micro-g in m/s^2."""


@dataclass(frozen=True)
class ImuConfig(Validated):
    """Gyroscope and accelerometer, sampled at the control rate (``[sensors.imu]``)."""

    config_section = "sensors.imu"

    ideal: bool = setting("-", "perfect IMU (true rate and specific force)", default=False)
    gyro_noise_density_dps_rtHz: float = setting(
        "deg/s/sqrt(Hz)", "gyro white-noise density (ICM-20689 / BMI088 class)", default=0.007,
        ge=0.0, le=10.0)
    accel_noise_density_ug_rtHz: float = setting(
        "ug/sqrt(Hz)", "accelerometer white-noise density (ICM-20689 / BMI088 class)",
        default=175.0, ge=0.0, le=1e5)
    gyro_bias_std_dps: float = setting(
        "deg/s", "std of the constant gyro bias left after start-up calibration", default=0.1,
        ge=0.0, le=100.0)
    accel_bias_std_mps2: float = setting(
        "m/s^2", "std of the constant accelerometer bias left after calibration", default=0.05,
        ge=0.0, le=10.0)
    gyro_bias_random_walk_dps_rts: float = setting(
        "deg/s/sqrt(s)", "gyro bias random walk (0: constant bias)", default=0.0, ge=0.0, le=10.0)
    accel_bias_random_walk_mps2_rts: float = setting(
        "m/s^2/sqrt(s)", "accelerometer bias random walk (0: constant bias)", default=0.0, ge=0.0, le=10.0)
    gyro_range_dps: float = setting("deg/s", "gyro full-scale range", default=2000.0, gt=0.0, le=1e4)
    accel_range_mps2: float = setting("m/s^2", "accelerometer full-scale range (16 g)",
                                      default=16.0 * GRAVITY_MPS2, gt=0.0, le=1e4)


# --- the channel (vtoladapt.parts) --------------------------------------------------------------
Settings = ImuConfig
WRITES = ("OMEGA_B", "ACCEL_B")
DRAWS = BlockLayout("IMU draws per step (standard normals)", [
    Field("GYRO_NOISE", 3, "-", "gyro white noise, xyz"),
    Field("ACCEL_NOISE", 3, "-", "accelerometer white noise, xyz"),
    Field("GYRO_WALK", 3, "-", "gyro bias random-walk increment, xyz"),
    Field("ACCEL_WALK", 3, "-", "accelerometer bias random-walk increment, xyz"),
])
_D_GYRO_NOISE, _D_ACCEL_NOISE, _D_GYRO_WALK, _D_ACCEL_WALK = DRAWS.offsets(*(f.name for f in DRAWS.fields))
NORMALS_PER_STEP = DRAWS.size
UNIFORMS_PER_STEP = 0

PARAMS = BlockLayout("IMU parameters", [
    Field("IDEAL", 1, "-", "1.0: perfect IMU"),
    Field("GYRO_DENSITY", 1, "rad/s/sqrt(Hz)", "gyro white-noise density"),
    Field("ACCEL_DENSITY", 1, "m/s^2/sqrt(Hz)", "accelerometer white-noise density"),
    Field("GYRO_BIAS_STD", 1, "rad/s", "std of the constant gyro bias"),
    Field("ACCEL_BIAS_STD", 1, "m/s^2", "std of the constant accelerometer bias"),
    Field("GYRO_WALK", 1, "rad/s/sqrt(s)", "gyro bias random walk"),
    Field("ACCEL_WALK", 1, "m/s^2/sqrt(s)", "accelerometer bias random walk"),
    Field("GYRO_RANGE", 1, "rad/s", "gyro full-scale range"),
    Field("ACCEL_RANGE", 1, "m/s^2", "accelerometer full-scale range"),
])
(_IDEAL, _GYRO_DENSITY, _ACCEL_DENSITY, _GYRO_BIAS_STD, _ACCEL_BIAS_STD, _GYRO_WALK, _ACCEL_WALK, _GYRO_RANGE,
 _ACCEL_RANGE) = PARAMS.offsets(*(f.name for f in PARAMS.fields))

STATE = BlockLayout("IMU state", [
    Field("GYRO_BIAS", 3, "rad/s", "gyro bias"),
    Field("ACCEL_BIAS", 3, "m/s^2", "accelerometer bias"),
    Field("DT_KEY", 1, "s", "dt the cached coefficients below were computed for (0: none yet)"),
    Field("INV_SQRT_DT", 1, "1/sqrt(s)", "1 / sqrt(dt): white-noise density -> per-sample sigma"),
    Field("SQRT_DT", 1, "sqrt(s)", "sqrt(dt): random-walk density -> per-step increment"),
])
_S_GYRO_BIAS, _S_ACCEL_BIAS, _S_DT_KEY, _S_INV_SQRT_DT, _S_SQRT_DT = STATE.offsets(
    "GYRO_BIAS", "ACCEL_BIAS", "DT_KEY", "INV_SQRT_DT", "SQRT_DT")
DRAWS_INITIAL = STATE.field("GYRO_BIAS").size + STATE.field("ACCEL_BIAS").size
"""Standard normals :func:`initial_state` draws: the gyro then the accelerometer bias, xyz."""

_OMEGA = layout.MEAS_OMEGA_B
_ACCEL = layout.MEAS_ACCEL_B
_X_OMEGA = layout.X_OMEGA_B
_F_B = layout.TRUTH_F_B


def pack(settings: ImuConfig, context) -> np.ndarray:
    """The channel's parameter block (SI units, radians)."""
    d2r = math.pi / 180.0
    return PARAMS.pack(
        IDEAL=float(settings.ideal), GYRO_DENSITY=settings.gyro_noise_density_dps_rtHz * d2r,
        ACCEL_DENSITY=settings.accel_noise_density_ug_rtHz * MICRO_G_MPS2,
        GYRO_BIAS_STD=settings.gyro_bias_std_dps * d2r,
        ACCEL_BIAS_STD=settings.accel_bias_std_mps2, GYRO_WALK=settings.gyro_bias_random_walk_dps_rts * d2r,
        ACCEL_WALK=settings.accel_bias_random_walk_mps2_rts, GYRO_RANGE=settings.gyro_range_dps * d2r,
        ACCEL_RANGE=settings.accel_range_mps2)


def initial_state(params: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A fresh state: the run's constant biases, ``DRAWS_INITIAL`` standard normals from ``rng``."""
    state = np.zeros(STATE.size)
    for j in range(3):
        state[_S_GYRO_BIAS + j] = params[_GYRO_BIAS_STD] * rng.standard_normal()
    for j in range(3):
        state[_S_ACCEL_BIAS + j] = params[_ACCEL_BIAS_STD] * rng.standard_normal()
    return state


def biases(state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Current biases in the channel's state: ``(gyro_bias_radps, accel_bias_mps2)``, copies."""
    return np.array(STATE.view(state, "GYRO_BIAS")), np.array(STATE.view(state, "ACCEL_BIAS"))


@njit(cache=True)
def specific_force_B(a_W: np.ndarray, R_WB: np.ndarray) -> np.ndarray:
    """Specific force ``R^T (a - g)`` in body axes (m/s^2): what an accelerometer measures.

    ``a_W`` is the acceleration (NED, m/s^2) and ``g = [0, 0, 9.80665]`` (NED), so at rest and
    level it is ``[0, 0, -9.80665]`` and in free fall zero.
    """
    d0 = a_W[0]
    d1 = a_W[1]
    d2 = a_W[2] - GRAVITY_MPS2
    out = np.empty(3)
    for j in range(3):
        out[j] = R_WB[0, j] * d0 + R_WB[1, j] * d1 + R_WB[2, j] * d2
    return out


@njit(cache=True, inline="always")
def _clip(x: float, limit: float) -> float:
    return min(limit, max(-limit, x))


@sensor_step
def step(params, state, t, dt, x_true, truth, draws, meas):
    """Gyro and accelerometer readings of this tick; the biases then walk by one step."""
    if dt != state[_S_DT_KEY]:
        state[_S_INV_SQRT_DT] = 1.0 / np.sqrt(dt)
        state[_S_SQRT_DT] = np.sqrt(dt)
        state[_S_DT_KEY] = dt
    ideal = params[_IDEAL] != 0.0
    sq = state[_S_INV_SQRT_DT]
    for j in range(3):
        w = x_true[_X_OMEGA + j]
        if not ideal:
            w = _clip(w + state[_S_GYRO_BIAS + j] + params[_GYRO_DENSITY] * sq * draws[_D_GYRO_NOISE + j],
                      params[_GYRO_RANGE])
        meas[_OMEGA + j] = w
    for j in range(3):
        f = truth[_F_B + j]
        if not ideal:
            f = _clip(f + state[_S_ACCEL_BIAS + j] + params[_ACCEL_DENSITY] * sq * draws[_D_ACCEL_NOISE + j],
                      params[_ACCEL_RANGE])
        meas[_ACCEL + j] = f
    # biases walk after this tick's reading: b_{k+1} = b_k + q sqrt(dt) n
    sdt = state[_S_SQRT_DT]
    for j in range(3):
        state[_S_GYRO_BIAS + j] += params[_GYRO_WALK] * sdt * draws[_D_GYRO_WALK + j]
    for j in range(3):
        state[_S_ACCEL_BIAS + j] += params[_ACCEL_WALK] * sdt * draws[_D_ACCEL_WALK + j]
