"""Sensors of the closed-loop simulator: IMU, motion capture, attitude estimate and airflow probe.

The controller never sees the plant state; it sees the measurement array of
:mod:`vtoladapt.layout` (``MEAS_*``) that :func:`sensors_step` writes every control tick from
the true state. Each sensor is configured in a sub-table of a scenario's ``[sensors]`` table
(``imu``, ``mocap``, ``attitude``, ``probe``) and each switches to a perfect sensor with
``ideal = true``. The defaults are realistic for the paper's set-up:

* **IMU** (``[sensors.imu]``), sampled at the control rate. White noise with the datasheet
  densities of a Pixhawk-class MEMS IMU (ICM-20689 / BMI088 class: gyro ~0.007 deg/s/sqrt(Hz),
  accelerometer ~175 ug/sqrt(Hz)); a sample averaged over one tick ``dt`` has standard deviation
  ``density / sqrt(dt) = density * sqrt(rate)`` (0.11 deg/s and 0.027 m/s^2 at 250 Hz). Constant
  biases, drawn once per run, stand for what the autopilot's start-up calibration leaves
  (0.1 deg/s, 0.05 m/s^2, 1 sigma); an optional bias random walk (off by default). Outputs
  saturate at the full-scale range (2000 deg/s, 16 g). The accelerometer measures the specific
  force ``a - g`` in body axes (:func:`specific_force_B`), so at rest and level it reads
  ``[0, 0, -9.80665]`` (FRD).
* **Motion capture** (``[sensors.mocap]``): position noise 0.5 mm (Vicon / OptiTrack class),
  velocity either with its own noise (``velocity_from = "direct"``, 0.02 m/s: what the
  autopilot's estimator fusing the motion capture delivers) or by differencing the noisy
  positions with a first-order low-pass (``"differentiate"``). Both are delayed by
  ``latency_s`` (12 ms = 3 ticks at 250 Hz: camera processing plus the link to the autopilot),
  rounded to a whole number of ticks and kept in a ring buffer in the sensor state.
* **Attitude estimate** (``[sensors.attitude]``): the true ``q_WB`` rotated by a small random
  body-axis rotation of 0.2 deg (1 sigma per axis), drawn each tick.
* **Airflow probe** (``[sensors.probe]``), ``model = "ideal_noise"``: the true incident velocity
  through a first-order lag (3 ms: the SDP33's "< 3 ms" response, Sensirion datasheet; Shi et al.
  2020, Sec. Airflow Sensing) plus white noise (0.1 m/s per axis). A reading drops out with
  ``dropout_probability`` per tick (``MEAS_V_I_VALID = 0`` and NaN values, to exercise the
  controller's fallback); below ``min_airspeed_mps`` the reading is kept but flagged invalid
  (``MEAS_V_I_VALID = 0``), as flow angles are meaningless there. ``model = "pressure"``: the
  paper's sensor end to end (tip pressures, three SDP33 sensors, the flight computer's single-k or
  spline calibration, see :class:`ProbeConfig`); the calibration's own validity flag (low dynamic
  pressure, flow outside the calibrated cone) also marks a reading invalid.

Lags are discretised exactly for an input held at its current value over the tick
(``y <- y + (1 - exp(-dt / tau)) (u - y)``), like the SDP33 model in
:mod:`vtoladapt.probe.sensor`.

Randomness
----------
Only from the ``numpy.random.Generator`` passed in. :func:`sensors_initial_state` draws
``SENSOR_DRAWS_INITIAL`` standard normals (gyro bias xyz, accelerometer bias xyz); every
:func:`sensors_step` draws ``SENSOR_NORMALS_PER_STEP`` standard normals and then one uniform, in
this fixed order: gyro noise xyz, accelerometer noise xyz, gyro bias walk xyz, accelerometer bias
walk xyz, mocap position NED, mocap velocity NED, attitude rotation xyz, probe xyz, probe dropout
(uniform). Every channel draws whether it is ideal or not, so making one sensor ideal never
changes the noise of the others: a run differs from another only where its settings differ.

Layouts
-------
The parameter array is one block per sensor (:data:`IMU_PARAMS`, :data:`MOCAP_PARAMS`,
:data:`ATTITUDE_PARAMS`, :data:`PROBE_PARAMS`, composed in :data:`SENSOR_PARAMS`; the pressure
probe appends :data:`PRESSURE_PROBE_PARAMS`), the state array is :data:`SENSOR_STATE`, all
declared with :class:`vtoladapt.layout.BlockLayout`; the kernels' offsets are derived from them.

The sensor interface
--------------------
A sensor suite is three things; the simulator and the tools here use nothing else:

1. **Settings**: a frozen dataclass whose fields are declared with
   :func:`vtoladapt.config.setting` (unit, meaning, allowed values), built from a TOML table with
   :func:`vtoladapt.config.build`, with a ``to_kernel()`` that returns the suite's float64
   parameter array, laid out with a :class:`~vtoladapt.layout.BlockLayout` whose offsets the
   kernels bind at import.
2. ``initial_state(params, rng) -> state``: a fresh state array; it may draw from ``rng`` (a
   fixed number of draws), e.g. the run's constant biases.
3. A compiled ``step(params, state, t, dt, x_true, specific_force_B, v_i_B_true, rng, meas_out)``
   (``numba.njit``) that writes every slot of ``meas_out`` (layout
   :data:`vtoladapt.layout.MEASUREMENT`: position, velocity, attitude, body rate, specific force,
   incident velocity and its validity flag) from the truth it is given, and advances ``state`` in
   place. Randomness only from ``rng``, a fixed number of draws per call whatever the settings,
   so a setting changes nothing but what it is about.

:func:`run_sensor_model` drives any such suite over a recorded truth;
``tests/test_sensor_interface.py`` writes a suite of its own (a GNSS-class receiver instead of
motion capture) and holds it and :func:`sensors_step` to the same contract. The closed loop
(:mod:`vtoladapt.sim.loop`) calls :func:`sensors_step`. A new model of one channel goes
into it the way the pressure probe did: its settings in that channel's config class, its block
in the layouts above, a compiled function called from :func:`sensors_step` (for the probe, a
``_probe_<model>`` function selected by ``PROBE_MODELS``) that draws a fixed number of random
numbers after the existing channels' draws, so existing runs stay bit-identical.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Optional

import numpy as np
from numba import njit

from . import layout
from .config import PATH_PATTERN, Validated, build, setting
from .frames import GRAVITY_MPS2
from .probe import (ProbeTip, SDP33Sensor, calibrate_tip, incident_velocity_from_pressures,
                    load_calibration, probe_differential_pressures, sdp33_sensor_step)
from .layout import BlockLayout, Field
from .probe.sensor import SENSOR_KERNEL_SIZE, SENSOR_OFFSET_PA
from .probe.tip import TIP_KERNEL_SIZE

MICRO_G_MPS2 = 1e-6 * GRAVITY_MPS2
"""One micro-g in m/s^2."""

MOCAP_RING_SIZE = 128
"""Ticks of motion-capture history kept for the latency (127 ticks of delay at most)."""

SENSOR_DRAWS_INITIAL = 6
SENSOR_NORMALS_PER_STEP = 24
SENSOR_UNIFORMS_PER_STEP = 1

PROBE_MODELS = ("ideal_noise", "pressure")
VELOCITY_SOURCES = ("direct", "differentiate")

PROBE_MODEL_IDEAL_NOISE = PROBE_MODELS.index("ideal_noise")
PROBE_MODEL_PRESSURE = PROBE_MODELS.index("pressure")
TIP_CALIBRATION_CONE_DEG = 20.0

# --- kernel parameter layout: one block per sensor ----------------------------------------------
IMU_PARAMS = BlockLayout("IMU parameters", [
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
MOCAP_PARAMS = BlockLayout("motion-capture parameters", [
    Field("IDEAL", 1, "-", "1.0: perfect, undelayed position and velocity"),
    Field("POS_STD", 1, "m", "position noise per axis"),
    Field("VEL_DIFF", 1, "-", "1.0: velocity by differencing positions; 0.0: direct noise"),
    Field("VEL_STD", 1, "m/s", "velocity noise per axis (direct)"),
    Field("VEL_LP_HZ", 1, "Hz", "low-pass cut-off of the differenced velocity (0: none)"),
    Field("LATENCY", 1, "s", "delay of position and velocity"),
])
ATTITUDE_PARAMS = BlockLayout("attitude-estimate parameters", [
    Field("IDEAL", 1, "-", "1.0: perfect attitude"),
    Field("STD", 1, "rad", "small-rotation noise per body axis"),
])
PROBE_PARAMS = BlockLayout("airflow-probe parameters", [
    Field("IDEAL", 1, "-", "1.0: perfect, always valid incident velocity"),
    Field("MODEL", 1, "-", "index into PROBE_MODELS"),
    Field("STD", 1, "m/s", "white noise per body axis (ideal_noise)"),
    Field("TAU", 1, "s", "first-order lag (ideal_noise)"),
    Field("DROPOUT", 1, "-", "probability per tick of an invalid reading"),
    Field("MIN_V", 1, "m/s", "readings below this airspeed are flagged invalid"),
])
SENSOR_PARAMS = BlockLayout("sensor parameters", [
    Field("IMU", IMU_PARAMS.size, "-", "IMU_PARAMS"),
    Field("MOCAP", MOCAP_PARAMS.size, "-", "MOCAP_PARAMS"),
    Field("ATTITUDE", ATTITUDE_PARAMS.size, "-", "ATTITUDE_PARAMS"),
    Field("PROBE", PROBE_PARAMS.size, "-", "PROBE_PARAMS"),
])
"""The sensors' parameter array (the pressure probe appends :data:`PRESSURE_PROBE_PARAMS`)."""
(_IMU_IDEAL, _GYRO_DENSITY, _ACCEL_DENSITY, _GYRO_BIAS_STD, _ACCEL_BIAS_STD, _GYRO_WALK, _ACCEL_WALK,
 _GYRO_RANGE, _ACCEL_RANGE) = SENSOR_PARAMS.nested(
    "IMU", IMU_PARAMS, "IDEAL", "GYRO_DENSITY", "ACCEL_DENSITY", "GYRO_BIAS_STD", "ACCEL_BIAS_STD",
    "GYRO_WALK", "ACCEL_WALK", "GYRO_RANGE", "ACCEL_RANGE")
(_MOCAP_IDEAL, _MOCAP_POS_STD, _MOCAP_VEL_DIFF, _MOCAP_VEL_STD, _MOCAP_VEL_LP_HZ, _MOCAP_LATENCY) = \
    SENSOR_PARAMS.nested("MOCAP", MOCAP_PARAMS, "IDEAL", "POS_STD", "VEL_DIFF", "VEL_STD", "VEL_LP_HZ",
                         "LATENCY")
_ATT_IDEAL, _ATT_STD = SENSOR_PARAMS.nested("ATTITUDE", ATTITUDE_PARAMS, "IDEAL", "STD")
_PROBE_IDEAL, _PROBE_MODEL, _PROBE_STD, _PROBE_TAU, _PROBE_DROPOUT, _PROBE_MIN_V = SENSOR_PARAMS.nested(
    "PROBE", PROBE_PARAMS, "IDEAL", "MODEL", "STD", "TAU", "DROPOUT", "MIN_V")
SENSORS_KERNEL_SIZE = SENSOR_PARAMS.size

SDP33_KERNEL_SIZE = SENSOR_KERNEL_SIZE
PRESSURE_PROBE_PARAMS = BlockLayout("pressure-probe parameters (after SENSOR_PARAMS)", [
    Field("RHO_TRUE", 1, "kg/m^3", "true air density (makes the pressures)"),
    Field("RHO_ASSUMED", 1, "kg/m^3", "the flight computer's density (turns them back into a speed)"),
    Field("TIP", TIP_KERNEL_SIZE, "-", "ProbeTip.to_kernel()"),
    Field("SDP", SDP33_KERNEL_SIZE, "-", "SDP33Sensor.to_kernel(), with the run's drawn offsets"),
    Field("CAL", 0, "-", "the calibration's to_kernel(), to the end of the array (its length varies)"),
])
"""Appended to the parameter array for ``model = "pressure"`` only."""
_PP_RHO_TRUE, _PP_RHO_ASSUMED, _PP_TIP, _PP_SDP, _PP_CAL = (
    SENSORS_KERNEL_SIZE + o for o in PRESSURE_PROBE_PARAMS.offsets("RHO_TRUE", "RHO_ASSUMED", "TIP", "SDP", "CAL"))

# --- state layout -----------------------------------------------------------------------------
MOCAP_SAMPLE = BlockLayout("motion-capture ring entry", [
    Field("P_W", 3, "m", "true position, NED"),
    Field("V_W", 3, "m/s", "true velocity, NED"),
])
SENSOR_STATE = BlockLayout("sensor state", [
    Field("INIT", 1, "-", "0.0 until the first step has filled the buffers"),
    Field("GYRO_BIAS", 3, "rad/s", "gyro bias"),
    Field("ACCEL_BIAS", 3, "m/s^2", "accelerometer bias"),
    Field("PROBE", 3, "m/s or Pa", "probe model state: lagged incident velocity (ideal_noise) or the "
          "SDP33 filter states (pressure)"),
    Field("PREV_P", 3, "m", "previous delayed noisy mocap position"),
    Field("VEL_F", 3, "m/s", "low-passed differenced mocap velocity"),
    Field("DT_KEY", 1, "s", "dt the cached coefficients below were computed for (0: none yet)"),
    Field("INV_SQRT_DT", 1, "1/sqrt(s)", "1 / sqrt(dt): white-noise density -> per-sample sigma"),
    Field("SQRT_DT", 1, "sqrt(s)", "sqrt(dt): random-walk density -> per-step increment"),
    Field("MOCAP_GAIN", 1, "-", "1 - exp(-2 pi f_c dt) of the differenced-velocity low-pass"),
    Field("PROBE_GAIN", 1, "-", "1 - exp(-dt / tau) of the probe lag"),
    Field("DELAY", 1, "ticks", "mocap latency in whole ticks"),
    Field("RING_HEAD", 1, "-", "ring slot written this tick"),
    Field("Q_TRUE", 3, "Pa", "scratch of the pressure probe: true [q_inf, q_alpha, q_beta] this tick"),
    Field("Q_MEAS", 3, "Pa", "scratch of the pressure probe: the SDP33 readings this tick"),
    Field("RING", MOCAP_SAMPLE.size * MOCAP_RING_SIZE, "-", "MOCAP_RING_SIZE entries of MOCAP_SAMPLE"),
])
"""The sensors' state array, built by :func:`sensors_initial_state`."""
(_ST_INIT, _ST_GYRO_BIAS, _ST_ACCEL_BIAS, _ST_PROBE, _ST_PREV_P, _ST_VEL_F, _ST_DT_KEY, _ST_INV_SQRT_DT,
 _ST_SQRT_DT, _ST_MOCAP_GAIN, _ST_PROBE_GAIN, _ST_DELAY, _ST_RING_HEAD, _ST_Q_TRUE, _ST_Q_MEAS,
 _ST_RING) = SENSOR_STATE.offsets(
    "INIT", "GYRO_BIAS", "ACCEL_BIAS", "PROBE", "PREV_P", "VEL_F", "DT_KEY", "INV_SQRT_DT", "SQRT_DT",
    "MOCAP_GAIN", "PROBE_GAIN", "DELAY", "RING_HEAD", "Q_TRUE", "Q_MEAS", "RING")
_RING_P, _RING_V = MOCAP_SAMPLE.offsets("P_W", "V_W")
_RING_STRIDE = MOCAP_SAMPLE.size
SENSORS_STATE_SIZE = SENSOR_STATE.size


# ==================================================================================================
# Configuration
# ==================================================================================================

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


@dataclass(frozen=True)
class AttitudeConfig(Validated):
    """Attitude estimate ``q_WB`` (``[sensors.attitude]``)."""

    config_section = "sensors.attitude"

    ideal: bool = setting("-", "perfect attitude", default=False)
    noise_std_deg: float = setting("deg", "small-rotation noise per body axis, each tick",
                                   default=0.2, ge=0.0, le=10.0)


@dataclass(frozen=True)
class ProbeConfig(Validated):
    """Airflow probe: incident velocity in body axes (``[sensors.probe]``).

    ``model = "ideal_noise"``: lagged truth plus white noise. ``model = "pressure"``: the paper's
    sensor end to end: the tip's port pressures at the true incident flow
    (:func:`vtoladapt.probe.probe_differential_pressures`), three SDP33 sensors (lag, offset,
    noise, quantisation; :func:`vtoladapt.probe.sdp33_sensor_step`), and the flight computer's
    calibration inverting them (:func:`vtoladapt.probe.incident_velocity_from_pressures`):
    ``calibration = "single_k"`` (the paper's eq:aoa) or ``"calibrated"`` (our spline), fitted
    to the simulated tip, or loaded from ``calibration_file`` (a ``vtoladapt probe calibrate``
    output; ``calibration`` picks the model in it).
    """

    config_section = "sensors.probe"

    ideal: bool = setting("-", "perfect, always valid incident velocity", default=False)
    model: str = setting("-", "'ideal_noise': truth, lag and noise; 'pressure': tip, SDP33 sensors and "
                         "calibration", default="ideal_noise", choices=PROBE_MODELS)
    noise_std_mps: float = setting("m/s", "white noise per body axis (ideal_noise)", default=0.1, ge=0.0, le=10.0)
    time_constant_s: float = setting("s", "first-order lag (ideal_noise; SDP33 response < 3 ms)",
                                     default=0.003, ge=0.0, le=1.0)
    dropout_probability: float = setting(
        "-", "probability per tick of an invalid reading (NaN values, valid flag 0)",
        default=0.0, ge=0.0, le=1.0)
    min_airspeed_mps: float = setting(
        "m/s", "readings below this airspeed are flagged invalid (values kept)", default=1.0,
        ge=0.0, le=100.0)
    tip: ProbeTip = setting("-", "tip geometry (pressure)", default=ProbeTip())
    sdp33: SDP33Sensor = setting("-", "the three differential-pressure sensors (pressure)",
                                 default=SDP33Sensor())
    sdp33_offset_std_Pa: float = setting(
        "Pa", "zero offsets drawn per run from the scenario seed, added to sdp33.offset_Pa "
        "(pressure; SDP33 datasheet: 0.2 Pa)", default=0.2, ge=0.0, le=50.0)
    calibration: str = setting("-", "the flight computer's calibration (pressure)", default="calibrated",
                               choices=("single_k", "calibrated"))
    calibration_file: Optional[str] = setting(
        "-", "calibration.json from `vtoladapt probe calibrate` (pressure); default: fitted to the "
        "simulated tip", default=None, pattern=PATH_PATTERN)

    def describe(self) -> str:
        """One line on the probe model, for logs and reports."""
        if self.ideal:
            return "ideal (true incident velocity, always valid)"
        if self.model == "pressure":
            source = self.calibration_file or "the simulated tip's own tunnel calibration"
            return (f"pressure model (tip port angle {self.tip.port_angle_deg:g} deg, SDP33 noise "
                    f"{self.sdp33.noise_std_Pa:g} Pa, offsets {self.sdp33_offset_std_Pa:g} Pa std, lag "
                    f"{1e3 * self.sdp33.time_constant_s:g} ms); flight computer uses the "
                    f"'{self.calibration}' calibration ({source}); dropout "
                    f"{self.dropout_probability:g} per tick")
        return (f"{self.model}: noise {self.noise_std_mps:g} m/s per axis, lag "
                f"{1e3 * self.time_constant_s:g} ms, dropout {self.dropout_probability:g} per tick, "
                f"valid above {self.min_airspeed_mps:g} m/s")

    def calibration_path(self, base_dir: Optional[Path] = None) -> Optional[Path]:
        """``calibration_file`` resolved against ``base_dir`` (the scenario's folder) if relative, or None."""
        if self.calibration_file is None:
            return None
        path = Path(self.calibration_file)
        return base_dir / path if base_dir is not None and not path.is_absolute() else path

    def calibration_kernel(self, base_dir: Optional[Path] = None) -> np.ndarray:
        """The flight computer's calibration as a kernel array (pressure model)."""
        path = self.calibration_path(base_dir)
        if path is not None:
            return load_calibration(path, model=self.calibration).to_kernel()
        return _tip_calibration(self.tip)[self.calibration].to_kernel()


@functools.lru_cache(maxsize=8)
def _tip_calibration(tip: ProbeTip) -> dict:
    """Both calibrations of a simulated tip (deterministic, ~1 s, so fitted once per tip).

    Over a 20-degree cone, the range of the NASA five-hole probe calibrations and more than the
    flight envelope's flow angles; a 30-degree grid would bend the single k toward large angles
    (3 deg error at alpha = 12 deg instead of 0.75 deg).
    """
    return calibrate_tip(tip, cone_max_deg=TIP_CALIBRATION_CONE_DEG)


@dataclass(frozen=True)
class SensorsConfig(Validated):
    """All the sensors of a scenario (``[sensors]``)."""

    config_section = "sensors"

    imu: ImuConfig = setting("-", "IMU", default=ImuConfig())
    mocap: MocapConfig = setting("-", "motion capture", default=MocapConfig())
    attitude: AttitudeConfig = setting("-", "attitude estimate", default=AttitudeConfig())
    probe: ProbeConfig = setting("-", "airflow probe", default=ProbeConfig())

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], *, source: str = "<config>",
                     section: str = "sensors") -> "SensorsConfig":
        """Build from a scenario's ``[sensors]`` table.

        Raises
        ------
        ConfigError
            Naming the file, the table (e.g. ``sensors.imu``), the key and what is allowed.
        """
        return build(cls, data, source=source, section=section)

    @classmethod
    def all_ideal(cls) -> "SensorsConfig":
        """Every sensor perfect: the measurement is the truth."""
        return cls(imu=ImuConfig(ideal=True), mocap=MocapConfig(ideal=True),
                   attitude=AttitudeConfig(ideal=True), probe=ProbeConfig(ideal=True))

    def to_kernel(self, air_density_true_kgpm3: float = 1.225, air_density_assumed_kgpm3: float = 1.225,
                  base_dir: Optional[Path] = None) -> np.ndarray:
        """The configuration as the float64 array the sensor kernels take (SI units, radians).

        The densities matter for the pressure probe only: the true air makes the pressures, the
        flight computer's assumed density turns them back into a speed. ``base_dir`` resolves a
        relative ``probe.calibration_file``.
        """
        probe_extra = np.zeros(0)
        if self.probe.model == "pressure" and not self.probe.ideal:
            probe_extra = np.concatenate((
                [air_density_true_kgpm3, air_density_assumed_kgpm3], self.probe.tip.to_kernel(),
                self.probe.sdp33.to_kernel(), self.probe.calibration_kernel(base_dir)))
        p = np.zeros(SENSORS_KERNEL_SIZE + probe_extra.size)
        p[SENSORS_KERNEL_SIZE:] = probe_extra
        imu, mocap, att, probe = self.imu, self.mocap, self.attitude, self.probe
        d2r = math.pi / 180.0
        p[_IMU_IDEAL] = float(imu.ideal)
        p[_GYRO_DENSITY] = imu.gyro_noise_density_dps_rtHz * d2r
        p[_ACCEL_DENSITY] = imu.accel_noise_density_ug_rtHz * MICRO_G_MPS2
        p[_GYRO_BIAS_STD] = imu.gyro_bias_std_dps * d2r
        p[_ACCEL_BIAS_STD] = imu.accel_bias_std_mps2
        p[_GYRO_WALK] = imu.gyro_bias_random_walk_dps_rts * d2r
        p[_ACCEL_WALK] = imu.accel_bias_random_walk_mps2_rts
        p[_GYRO_RANGE] = imu.gyro_range_dps * d2r
        p[_ACCEL_RANGE] = imu.accel_range_mps2
        p[_MOCAP_IDEAL] = float(mocap.ideal)
        p[_MOCAP_POS_STD] = mocap.position_noise_std_m
        p[_MOCAP_VEL_DIFF] = float(mocap.velocity_from == "differentiate")
        p[_MOCAP_VEL_STD] = mocap.velocity_noise_std_mps
        p[_MOCAP_VEL_LP_HZ] = mocap.velocity_lowpass_hz
        p[_MOCAP_LATENCY] = mocap.latency_s
        p[_ATT_IDEAL] = float(att.ideal)
        p[_ATT_STD] = att.noise_std_deg * d2r
        p[_PROBE_IDEAL] = float(probe.ideal)
        p[_PROBE_MODEL] = PROBE_MODELS.index(probe.model)
        p[_PROBE_STD] = probe.noise_std_mps
        p[_PROBE_TAU] = probe.time_constant_s
        p[_PROBE_DROPOUT] = probe.dropout_probability
        p[_PROBE_MIN_V] = probe.min_airspeed_mps
        return p


def draw_probe_offsets(params: np.ndarray, offset_std_Pa: float, rng: np.random.Generator) -> np.ndarray:
    """Add per-run SDP33 zero offsets (three normals from ``rng``) to a pressure probe's parameters.

    Called once per run after :func:`sensors_initial_state`, and only for the pressure model,
    so the other sensors' random streams are the same whichever probe model is chosen.
    """
    offsets = offset_std_Pa * rng.standard_normal(3)
    params[_PP_SDP + SENSOR_OFFSET_PA:_PP_SDP + SENSOR_OFFSET_PA + 3] += offsets
    return offsets


def imu_biases(state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Current IMU biases in a sensor state: ``(gyro_bias_radps, accel_bias_mps2)``, copies."""
    return (np.array(state[_ST_GYRO_BIAS:_ST_GYRO_BIAS + 3]),
            np.array(state[_ST_ACCEL_BIAS:_ST_ACCEL_BIAS + 3]))


def latency_ticks(latency_s: float, dt_s: float) -> int:
    """Whole control ticks of delay for a latency (nearest, halves up), as the kernel rounds it."""
    return int(latency_s / dt_s + 0.5)


# ==================================================================================================
# Kernels
# ==================================================================================================

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


@njit(cache=True)
def sensors_initial_state(params: np.ndarray, rng) -> np.ndarray:
    """A fresh sensor state; draws the constant IMU biases (six standard normals) from ``rng``."""
    state = np.zeros(SENSORS_STATE_SIZE)
    for j in range(3):
        state[_ST_GYRO_BIAS + j] = params[_GYRO_BIAS_STD] * rng.standard_normal()
    for j in range(3):
        state[_ST_ACCEL_BIAS + j] = params[_ACCEL_BIAS_STD] * rng.standard_normal()
    return state


@njit(cache=True, inline="always")
def _clip(x: float, limit: float) -> float:
    return min(limit, max(-limit, x))


@njit(cache=True, inline="always")
def _imu_step(params, state, dt, x_true, specific_force_B, rng, meas_out):
    ideal = params[_IMU_IDEAL] != 0.0
    sq = state[_ST_INV_SQRT_DT]
    for j in range(3):
        n = rng.standard_normal()
        w = x_true[layout.X_OMEGA_B + j]
        if not ideal:
            w = _clip(w + state[_ST_GYRO_BIAS + j] + params[_GYRO_DENSITY] * sq * n,
                      params[_GYRO_RANGE])
        meas_out[layout.MEAS_OMEGA_B + j] = w
    for j in range(3):
        n = rng.standard_normal()
        f = specific_force_B[j]
        if not ideal:
            f = _clip(f + state[_ST_ACCEL_BIAS + j] + params[_ACCEL_DENSITY] * sq * n,
                      params[_ACCEL_RANGE])
        meas_out[layout.MEAS_ACCEL_B + j] = f
    # biases walk after this tick's reading: b_{k+1} = b_k + q sqrt(dt) n
    sdt = state[_ST_SQRT_DT]
    for j in range(3):
        state[_ST_GYRO_BIAS + j] += params[_GYRO_WALK] * sdt * rng.standard_normal()
    for j in range(3):
        state[_ST_ACCEL_BIAS + j] += params[_ACCEL_WALK] * sdt * rng.standard_normal()


@njit(cache=True, inline="always")
def _mocap_step(params, state, dt, x_true, rng, meas_out):
    n_delay = int(state[_ST_DELAY])
    head = (int(state[_ST_RING_HEAD]) + 1) % MOCAP_RING_SIZE
    state[_ST_RING_HEAD] = head
    k = _ST_RING + _RING_STRIDE * head
    for j in range(3):
        state[k + _RING_P + j] = x_true[layout.X_P_W + j]
        state[k + _RING_V + j] = x_true[layout.X_V_W + j]
    d = _ST_RING + _RING_STRIDE * ((head - n_delay) % MOCAP_RING_SIZE)
    ideal = params[_MOCAP_IDEAL] != 0.0
    for j in range(3):
        n = rng.standard_normal()
        if ideal:
            meas_out[layout.MEAS_P_W + j] = x_true[layout.X_P_W + j]
        else:
            meas_out[layout.MEAS_P_W + j] = state[d + _RING_P + j] + params[_MOCAP_POS_STD] * n
    differentiate = params[_MOCAP_VEL_DIFF] != 0.0
    gain = state[_ST_MOCAP_GAIN]
    for j in range(3):
        n = rng.standard_normal()
        if ideal:
            meas_out[layout.MEAS_V_W + j] = x_true[layout.X_V_W + j]
        elif differentiate:
            p_now = meas_out[layout.MEAS_P_W + j]
            raw = (p_now - state[_ST_PREV_P + j]) / dt
            state[_ST_PREV_P + j] = p_now
            state[_ST_VEL_F + j] += gain * (raw - state[_ST_VEL_F + j])
            meas_out[layout.MEAS_V_W + j] = state[_ST_VEL_F + j]
        else:
            meas_out[layout.MEAS_V_W + j] = state[d + _RING_V + j] + params[_MOCAP_VEL_STD] * n


@njit(cache=True, inline="always")
def _attitude_step(params, x_true, rng, meas_out):
    s = params[_ATT_STD]
    r0 = s * rng.standard_normal()
    r1 = s * rng.standard_normal()
    r2 = s * rng.standard_normal()
    q = x_true[layout.X_Q_WB:layout.X_Q_WB + 4]
    m = layout.MEAS_Q_WB
    if params[_ATT_IDEAL] != 0.0:
        for i in range(4):
            meas_out[m + i] = q[i]
        return
    angle = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    c = np.cos(0.5 * angle)
    k = 0.5 if angle < 1e-12 else np.sin(0.5 * angle) / angle
    d0, d1, d2, d3 = c, k * r0, k * r1, k * r2
    # q_meas = q_true * dq: a small rotation about body axes
    w = q[0] * d0 - q[1] * d1 - q[2] * d2 - q[3] * d3
    x = q[0] * d1 + q[1] * d0 + q[2] * d3 - q[3] * d2
    y = q[0] * d2 - q[1] * d3 + q[2] * d0 + q[3] * d1
    z = q[0] * d3 + q[1] * d2 - q[2] * d1 + q[3] * d0
    norm = np.sqrt(w * w + x * x + y * y + z * z)
    meas_out[m] = w / norm
    meas_out[m + 1] = x / norm
    meas_out[m + 2] = y / norm
    meas_out[m + 3] = z / norm


@njit(cache=True, inline="always")
def _probe_ideal_noise(params, state, dt, v_i_B_true, rng, meas_out):
    """``model = "ideal_noise"``: lagged truth plus white noise; draws three normals."""
    gain = state[_ST_PROBE_GAIN]
    for j in range(3):
        n = rng.standard_normal()
        state[_ST_PROBE + j] += gain * (v_i_B_true[j] - state[_ST_PROBE + j])
        meas_out[layout.MEAS_V_I_B + j] = state[_ST_PROBE + j] + params[_PROBE_STD] * n


@njit(cache=True, inline="always")
def _probe_pressure(params, state, dt, v_i_B_true, rng, meas_out) -> bool:
    """``model = "pressure"``: tip pressures, SDP33 sensors, calibration; draws three normals."""
    q_true = state[_ST_Q_TRUE:_ST_Q_TRUE + 3]  # scratch in the state: no allocation per tick
    q_meas = state[_ST_Q_MEAS:_ST_Q_MEAS + 3]
    probe_differential_pressures(v_i_B_true, params[_PP_RHO_TRUE], params[_PP_TIP:_PP_TIP + 3], q_true)
    sdp33_sensor_step(q_true, state[_ST_PROBE:_ST_PROBE + 3], params[_PP_SDP:_PP_SDP + SDP33_KERNEL_SIZE],
                      dt, rng, q_meas)
    return incident_velocity_from_pressures(q_meas, params[_PP_RHO_ASSUMED], params[_PP_CAL:],
                                            meas_out[layout.MEAS_V_I_B:layout.MEAS_V_I_B + 3])


@njit(cache=True, inline="always")
def _probe_step(params, state, dt, v_i_B_true, rng, meas_out):
    m = layout.MEAS_V_I_B
    # One function per probe model (selected by params[_PROBE_MODEL]). Each draws exactly three
    # normals so the dropout draw below keeps its place.
    model_valid = True
    if params[_PROBE_MODEL] == PROBE_MODEL_PRESSURE:
        model_valid = _probe_pressure(params, state, dt, v_i_B_true, rng, meas_out)
    else:
        _probe_ideal_noise(params, state, dt, v_i_B_true, rng, meas_out)
    u = rng.random()
    if params[_PROBE_IDEAL] != 0.0:
        for j in range(3):
            meas_out[m + j] = v_i_B_true[j]
        meas_out[layout.MEAS_V_I_VALID] = 1.0
        return
    if u < params[_PROBE_DROPOUT]:
        for j in range(3):
            meas_out[m + j] = np.nan
        meas_out[layout.MEAS_V_I_VALID] = 0.0
        return
    v0 = meas_out[m]
    v1 = meas_out[m + 1]
    v2 = meas_out[m + 2]
    airspeed = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    meas_out[layout.MEAS_V_I_VALID] = 1.0 if (model_valid and airspeed >= params[_PROBE_MIN_V]) else 0.0


@njit(cache=True, inline="always")
def _dt_coefficients(params, state, dt):
    """Coefficients that depend on the tick only, recomputed when ``dt`` changes."""
    n_delay = int(params[_MOCAP_LATENCY] / dt + 0.5)
    if n_delay >= MOCAP_RING_SIZE:
        raise ValueError("sensors: mocap latency_s / dt exceeds the ring buffer "
                         "(MOCAP_RING_SIZE - 1 ticks)")
    state[_ST_DELAY] = n_delay
    state[_ST_INV_SQRT_DT] = 1.0 / np.sqrt(dt)
    state[_ST_SQRT_DT] = np.sqrt(dt)
    fc = params[_MOCAP_VEL_LP_HZ]
    state[_ST_MOCAP_GAIN] = 1.0 if fc <= 0.0 else -np.expm1(-2.0 * np.pi * fc * dt)
    tau = params[_PROBE_TAU]
    state[_ST_PROBE_GAIN] = 1.0 if tau <= 0.0 else -np.expm1(-dt / tau)
    state[_ST_DT_KEY] = dt


@njit(cache=True, inline="always")
def _first_step(state, x_true, v_i_B_true):
    """Fill the latency buffer and settle the lags at the first truth seen."""
    for s in range(MOCAP_RING_SIZE):
        k = _ST_RING + _RING_STRIDE * s
        for j in range(3):
            state[k + _RING_P + j] = x_true[layout.X_P_W + j]
            state[k + _RING_V + j] = x_true[layout.X_V_W + j]
    state[_ST_RING_HEAD] = MOCAP_RING_SIZE - 1  # the first step writes slot 0
    for j in range(3):
        state[_ST_PREV_P + j] = x_true[layout.X_P_W + j]
        state[_ST_VEL_F + j] = x_true[layout.X_V_W + j]
        state[_ST_PROBE + j] = v_i_B_true[j]
    state[_ST_INIT] = 1.0


@njit(cache=True, _nrt=False)
def sensors_step(params: np.ndarray, state: np.ndarray, t: float, dt: float, x_true: np.ndarray,
                 specific_force_B: np.ndarray, v_i_B_true: np.ndarray, rng,
                 meas_out: np.ndarray) -> None:
    """Write one tick's measurement from the truth and advance the sensor state.

    Parameters
    ----------
    params : numpy.ndarray
        From :meth:`SensorsConfig.to_kernel`.
    state : numpy.ndarray
        From :func:`sensors_initial_state`; updated in place. The first call settles the lags
        and fills the latency buffer with the truth it is given.
    t : float
        Time of this tick (s). The sensors are time-invariant; it is part of the interface.
    dt : float
        Control tick (s), > 0; sets the per-sample noise ``density / sqrt(dt)``, the lags and the
        latency in ticks (``round(latency_s / dt)``).
    x_true : numpy.ndarray, shape (layout.X_SIZE,)
        True plant state.
    specific_force_B : numpy.ndarray, shape (3,)
        True specific force ``a - g`` in body axes (m/s^2), see :func:`specific_force_B`.
    v_i_B_true : numpy.ndarray, shape (3,)
        True incident velocity in body axes (m/s).
    rng : numpy.random.Generator
        ``SENSOR_NORMALS_PER_STEP`` normals then one uniform per call, whatever the settings.
    meas_out : numpy.ndarray, shape (layout.MEAS_SIZE,)
        Receives the measurement (``layout.MEAS_*``).
    """
    if state[_ST_INIT] == 0.0:
        _first_step(state, x_true, v_i_B_true)
    if dt != state[_ST_DT_KEY]:
        _dt_coefficients(params, state, dt)
    _imu_step(params, state, dt, x_true, specific_force_B, rng, meas_out)
    _mocap_step(params, state, dt, x_true, rng, meas_out)
    _attitude_step(params, x_true, rng, meas_out)
    _probe_step(params, state, dt, v_i_B_true, rng, meas_out)


@njit(cache=True)
def _run_sensor_model(step, params, state, t0, dt, X, F, VI, rng, out):
    for k in range(X.shape[0]):
        row = out[k]
        row[:] = np.nan  # a slot the model does not write stays NaN
        step(params, state, t0 + k * dt, dt, X[k], F[k], VI[k], rng, row)


def run_sensor_model(step: Callable, params: np.ndarray, state: np.ndarray, dt_s: float,
                     x_true: np.ndarray, specific_force_B: np.ndarray, v_i_B_true: np.ndarray,
                     rng: np.random.Generator, t0_s: float = 0.0) -> np.ndarray:
    """Drive any sensor suite (the interface in this module's docstring) over a recorded truth.

    Parameters
    ----------
    step : compiled function
        ``step(params, state, t, dt, x_true, specific_force_B, v_i_B_true, rng, meas_out)``,
        e.g. :func:`sensors_step`.
    params, state : numpy.ndarray
        The suite's parameter array and its state (advanced in place).
    dt_s : float
        Control tick (s), > 0.
    x_true : numpy.ndarray, shape (T, layout.X_SIZE)
        True plant state at each tick.
    specific_force_B, v_i_B_true : numpy.ndarray, shape (T, 3)
        True specific force (m/s^2) and incident velocity (m/s), body axes.
    rng : numpy.random.Generator
        Source of the suite's draws.
    t0_s : float
        Time of the first tick (s).

    Returns
    -------
    numpy.ndarray, shape (T, layout.MEAS_SIZE)
        The measurements; a slot the suite did not write is NaN.
    """
    if not dt_s > 0.0:
        raise ValueError(f"dt_s = {dt_s!r}: must be > 0")
    X = np.ascontiguousarray(x_true, dtype=float)
    F = np.ascontiguousarray(specific_force_B, dtype=float)
    VI = np.ascontiguousarray(v_i_B_true, dtype=float)
    if X.ndim != 2 or X.shape[1] != layout.X_SIZE or F.shape != (X.shape[0], 3) or VI.shape != F.shape:
        raise ValueError(f"x_true {X.shape}, specific_force_B {F.shape}, v_i_B_true {VI.shape}: expected "
                         f"(T, {layout.X_SIZE}), (T, 3), (T, 3)")
    out = np.empty((X.shape[0], layout.MEAS_SIZE))
    _run_sensor_model(step, np.asarray(params, dtype=float), state, float(t0_s), float(dt_s), X, F, VI, rng, out)
    return out
