"""The airflow-probe channel (``[sensors.probe]``): the incident velocity in body axes, and its validity.

``model = "ideal_noise"``: the true incident velocity through a first-order lag (3 ms: the SDP33's
"< 3 ms" response, Sensirion datasheet; Shi et al. 2020, Sec. Airflow Sensing) plus white noise
(0.1 m/s per axis). ``model = "pressure"``: the paper's sensor end to end: the tip's port pressures
at the true incident flow (:func:`vtoladapt.probe.tip.probe_differential_pressures`), three SDP33
sensors (lag, offset, noise, quantisation; :func:`vtoladapt.probe.sensor.sdp33_sensor_step_drawn`)
and the flight computer's calibration inverting them
(:func:`vtoladapt.probe.estimation.incident_velocity_from_pressures`), whose own validity flag (low
dynamic pressure, flow outside the calibrated cone) also marks a reading invalid. Either way a
reading drops out with ``dropout_probability`` per tick (``MEAS_V_I_VALID = 0`` and NaN values, to
exercise the controller's fallback), and below ``min_airspeed_mps`` it is kept but flagged invalid,
as flow angles are meaningless there. Lags are discretised exactly for an input held over the tick
(``y <- y + (1 - exp(-dt / tau)) (u - y)``).

A sensor channel (:mod:`vtoladapt.sensors.registry`): writes ``V_I_B`` and ``V_I_VALID``; every step
consumes three standard normals (the model's noise: per body axis, or per SDP33 sensor) then one
uniform (the dropout), whatever the model. The pressure model also draws the three sensors' zero
offsets when the run starts (:func:`initial_state`, that model only).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
from numba import njit

from .. import layout
from ..config import PATH_PATTERN, Validated, setting
from ..layout import BlockLayout, Field
from ..probe.calibration import calibrate_tip, load_calibration
from ..probe.estimation import incident_velocity_from_pressures
from ..probe.sensor import SENSOR_KERNEL_SIZE, SENSOR_OFFSET_PA, SDP33Sensor, sdp33_sensor_step_drawn
from ..probe.tip import TIP_KERNEL_SIZE, ProbeTip, probe_differential_pressures
from .registry import sensor_step

PROBE_MODELS = ("ideal_noise", "pressure")
PROBE_MODEL_IDEAL_NOISE = PROBE_MODELS.index("ideal_noise")
PROBE_MODEL_PRESSURE = PROBE_MODELS.index("pressure")
TIP_CALIBRATION_CONE_DEG = 20.0


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

    @property
    def pressure(self) -> bool:
        """The pressure model, and not ideal: the model with a tip, sensors and calibration."""
        return self.model == "pressure" and not self.ideal

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


# --- the channel (vtoladapt.parts) --------------------------------------------------------------
Settings = ProbeConfig
WRITES = ("V_I_B", "V_I_VALID")
DRAWS = BlockLayout("airflow-probe draws per step", [
    Field("NOISE", 3, "-", "standard normals: noise per body axis (ideal_noise) or per SDP33 sensor (pressure)"),
    Field("DROPOUT", 1, "-", "uniform on [0, 1): the reading drops out below dropout_probability"),
])
_D_NOISE, _D_DROPOUT = DRAWS.offsets("NOISE", "DROPOUT")
NORMALS_PER_STEP = DRAWS.field("NOISE").size
UNIFORMS_PER_STEP = DRAWS.field("DROPOUT").size

SDP33_KERNEL_SIZE = SENSOR_KERNEL_SIZE
PARAMS = BlockLayout("airflow-probe parameters", [
    Field("IDEAL", 1, "-", "1.0: perfect, always valid incident velocity"),
    Field("MODEL", 1, "-", "index into PROBE_MODELS"),
    Field("STD", 1, "m/s", "white noise per body axis (ideal_noise)"),
    Field("TAU", 1, "s", "first-order lag (ideal_noise)"),
    Field("DROPOUT", 1, "-", "probability per tick of an invalid reading"),
    Field("MIN_V", 1, "m/s", "readings below this airspeed are flagged invalid"),
    Field("RHO_TRUE", 1, "kg/m^3", "true air density, makes the pressures (pressure)"),
    Field("RHO_ASSUMED", 1, "kg/m^3", "the flight computer's density, turns them back into a speed (pressure)"),
    Field("OFFSET_STD", 1, "Pa", "std of the SDP33 zero offsets drawn per run (pressure)"),
    Field("TIP", TIP_KERNEL_SIZE, "-", "ProbeTip.to_kernel() (pressure)"),
    Field("SDP", SDP33_KERNEL_SIZE, "-", "SDP33Sensor.to_kernel(), before the run's drawn offsets (pressure)"),
    Field("CAL", 0, "-", "the calibration's to_kernel(), to the end of the array (pressure; its length varies)"),
])
"""The channel's parameters; the pressure model's calibration runs to the end of the array."""
(_IDEAL, _MODEL, _STD, _TAU, _DROPOUT, _MIN_V, _RHO_TRUE, _RHO_ASSUMED, _OFFSET_STD, _TIP, _SDP,
 _CAL) = PARAMS.offsets(*(f.name for f in PARAMS.fields))

STATE = BlockLayout("airflow-probe state", [
    Field("INIT", 1, "-", "0.0 until the first step has settled the lag"),
    Field("LAG", 3, "m/s or Pa", "model state: lagged incident velocity (ideal_noise) or the SDP33 filter "
          "states (pressure)"),
    Field("DT_KEY", 1, "s", "dt the cached gain below was computed for (0: none yet)"),
    Field("GAIN", 1, "-", "1 - exp(-dt / tau) of the ideal_noise lag"),
    Field("Q_TRUE", 3, "Pa", "scratch of the pressure model: true [q_inf, q_alpha, q_beta] this tick"),
    Field("Q_MEAS", 3, "Pa", "scratch of the pressure model: the SDP33 readings this tick"),
    Field("SDP", SDP33_KERNEL_SIZE, "-", "the SDP33 parameters with this run's drawn zero offsets (pressure)"),
])
_S_INIT, _S_LAG, _S_DT_KEY, _S_GAIN, _S_Q_TRUE, _S_Q_MEAS, _S_SDP = STATE.offsets(*(f.name for f in STATE.fields))

_V_I = layout.MEAS_V_I_B
_VALID = layout.MEAS_V_I_VALID
_TRUE_V_I = layout.TRUTH_V_I_B


def pack(settings: ProbeConfig, context) -> np.ndarray:
    """The channel's parameter block; the pressure model's (densities from ``context``, a
    :class:`~vtoladapt.sensors.SensorContext`) ends in the calibration."""
    p = PARAMS.pack(IDEAL=float(settings.ideal), MODEL=PROBE_MODELS.index(settings.model), STD=settings.noise_std_mps,
                    TAU=settings.time_constant_s, DROPOUT=settings.dropout_probability,
                    MIN_V=settings.min_airspeed_mps)
    if not settings.pressure:
        return p
    PARAMS.view(p, "RHO_TRUE")[0] = context.air_density_true_kgpm3
    PARAMS.view(p, "RHO_ASSUMED")[0] = context.air_density_assumed_kgpm3
    PARAMS.view(p, "OFFSET_STD")[0] = settings.sdp33_offset_std_Pa
    PARAMS.view(p, "TIP")[:] = settings.tip.to_kernel()
    PARAMS.view(p, "SDP")[:] = settings.sdp33.to_kernel()
    return np.concatenate((p, settings.calibration_kernel(context.base_dir)))


def initial_state(params: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A fresh state; the pressure model draws the three SDP33 zero offsets (three standard normals
    from ``rng``, added to the sensors' own ``offset_Pa``), the other model draws nothing."""
    state = np.zeros(STATE.size)
    sdp = STATE.view(state, "SDP")
    sdp[:] = PARAMS.view(params, "SDP")
    if params[_MODEL] == PROBE_MODEL_PRESSURE and params[_IDEAL] == 0.0:
        offsets = params[_OFFSET_STD] * rng.standard_normal(3)
        sdp[SENSOR_OFFSET_PA:SENSOR_OFFSET_PA + 3] += offsets
    return state


def drawn_offsets_Pa(params: np.ndarray, state: np.ndarray) -> np.ndarray:
    """The zero offsets this run drew for the three SDP33 sensors (Pa; zeros for the other model)."""
    return (STATE.view(state, "SDP")[SENSOR_OFFSET_PA:SENSOR_OFFSET_PA + 3]
            - PARAMS.view(params, "SDP")[SENSOR_OFFSET_PA:SENSOR_OFFSET_PA + 3])


@njit(cache=True, inline="always")
def _ideal_noise(params, state, v_i_true, normals, meas):
    """``model = "ideal_noise"``: lagged truth plus white noise."""
    gain = state[_S_GAIN]
    for j in range(3):
        state[_S_LAG + j] += gain * (v_i_true[j] - state[_S_LAG + j])
        meas[_V_I + j] = state[_S_LAG + j] + params[_STD] * normals[j]


@njit(cache=True, inline="always")
def _pressure(params, state, dt, v_i_true, normals, meas) -> bool:
    """``model = "pressure"``: tip pressures, SDP33 sensors, calibration; the calibration's validity."""
    q_true = state[_S_Q_TRUE:_S_Q_TRUE + 3]  # scratch in the state: no allocation per tick
    q_meas = state[_S_Q_MEAS:_S_Q_MEAS + 3]
    probe_differential_pressures(v_i_true, params[_RHO_TRUE], params[_TIP:_TIP + 3], q_true)
    sdp33_sensor_step_drawn(q_true, state[_S_LAG:_S_LAG + 3], state[_S_SDP:_S_SDP + SDP33_KERNEL_SIZE], dt,
                            normals, q_meas)
    return incident_velocity_from_pressures(q_meas, params[_RHO_ASSUMED], params[_CAL:], meas[_V_I:_V_I + 3])


@sensor_step
def step(params, state, t, dt, x_true, truth, draws, meas):
    """This tick's incident velocity and its validity flag."""
    v_i_true = truth[_TRUE_V_I:_TRUE_V_I + 3]
    if state[_S_INIT] == 0.0:
        # the lag settles at the first truth seen (for the pressure model this seeds the SDP33 filter
        # states, in Pa, with the incident velocity in m/s: the first tick's reading is off by it)
        for j in range(3):
            state[_S_LAG + j] = v_i_true[j]
        state[_S_INIT] = 1.0
    if dt != state[_S_DT_KEY]:
        tau = params[_TAU]
        state[_S_GAIN] = 1.0 if tau <= 0.0 else -np.expm1(-dt / tau)
        state[_S_DT_KEY] = dt
    if params[_IDEAL] != 0.0:
        for j in range(3):
            meas[_V_I + j] = v_i_true[j]
        meas[_VALID] = 1.0
        return
    normals = draws[_D_NOISE:_D_NOISE + 3]
    model_valid = True
    if params[_MODEL] == PROBE_MODEL_PRESSURE:
        model_valid = _pressure(params, state, dt, v_i_true, normals, meas)
    else:
        _ideal_noise(params, state, v_i_true, normals, meas)
    if draws[_D_DROPOUT] < params[_DROPOUT]:
        for j in range(3):
            meas[_V_I + j] = np.nan
        meas[_VALID] = 0.0
        return
    v0 = meas[_V_I]
    v1 = meas[_V_I + 1]
    v2 = meas[_V_I + 2]
    airspeed = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    meas[_VALID] = 1.0 if (model_valid and airspeed >= params[_MIN_V]) else 0.0
