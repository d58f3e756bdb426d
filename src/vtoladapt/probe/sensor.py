"""Model of the three Sensirion SDP33 differential pressure sensors of the airflow probe.

Each of the three channels (q_inf, q_alpha, q_beta) is, in this order:

1. a first-order lag with time constant ``tau`` (the paper: "fast response (< 3 ms)"; the
   default ``tau = 1 ms`` reaches 95 % of a step in 3 ms), discretised exactly for an input held
   over the step: ``x <- x + (1 - exp(-dt / tau)) (q_true - x)``;
2. a constant offset (the paper: "almost no zero-pressure offset and drift (0.2 Pa)");
3. white Gaussian noise of standard deviation ``sigma`` (default 0.2 Pa);
4. quantisation to the sensor's resolution (the SDP33's scale factor is 20 counts/Pa, so
   0.05 Pa) and saturation at its range (+-1500 Pa).

Sources: Shi et al., ICRA 2020, Sec. "Airflow Sensing"; Sensirion SDP33 datasheet (range
1500 Pa, response time < 3 ms) and the PX4/ArduPilot SDP3x drivers (scale factor 20 /Pa).

Randomness comes only from the ``numpy.random.Generator`` passed in; each call draws exactly
three standard normals (also with zero noise), so runs with the same seed are identical bit for
bit whatever the settings.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from vtoladapt.config import setting
from vtoladapt.layout import BlockLayout, Field
from vtoladapt.probe.errors import ProbeError, require_number

SENSOR_PARAMS = BlockLayout("SDP33 parameters", [
    Field("TIME_CONSTANT", 1, "s", "first-order lag"),
    Field("NOISE_STD", 1, "Pa", "white measurement noise"),
    Field("OFFSET", 3, "Pa", "zero offsets of the q_inf, q_alpha, q_beta channels"),
    Field("RESOLUTION", 1, "Pa", "quantisation step"),
    Field("RANGE", 1, "Pa", "full-scale range"),
])
"""Layout of the sensor kernel array (:meth:`SDP33Sensor.to_kernel`)."""
(SENSOR_TIME_CONSTANT_S, SENSOR_NOISE_STD_PA, SENSOR_OFFSET_PA, SENSOR_RESOLUTION_PA,
 SENSOR_RANGE_PA) = SENSOR_PARAMS.offsets("TIME_CONSTANT", "NOISE_STD", "OFFSET", "RESOLUTION", "RANGE")
SENSOR_KERNEL_SIZE = SENSOR_PARAMS.size


@dataclass(frozen=True)
class SDP33Sensor:
    """Noise, offset, quantisation and lag of the probe's three SDP33 sensors.

    Parameters
    ----------
    noise_std_Pa : float
        Standard deviation of the white measurement noise (Pa), >= 0.
    offset_Pa : tuple of 3 float
        Constant offsets of the q_inf, q_alpha, q_beta channels (Pa).
    time_constant_s : float
        First-order lag time constant (s), >= 0 (0: no lag).
    resolution_Pa : float
        Quantisation step (Pa), >= 0 (0: no quantisation).
    range_Pa : float
        Output saturates at +-range_Pa (Pa), > 0.
    """

    noise_std_Pa: float = setting("Pa", "white measurement noise, standard deviation",
                                  default=0.2, ge=0.0)
    offset_Pa: tuple[float, float, float] = setting(
        "Pa", "constant offsets of the q_inf, q_alpha, q_beta channels",
        default=(0.0, 0.0, 0.0), length=3)
    time_constant_s: float = setting("s", "first-order lag time constant (95 % in 3 tau)",
                                     default=1.0e-3, ge=0.0)
    resolution_Pa: float = setting("Pa", "quantisation step (SDP33: 1/20 Pa)", default=0.05,
                                   ge=0.0)
    range_Pa: float = setting("Pa", "output saturation, +-range", default=1500.0, gt=0.0)

    def __post_init__(self) -> None:
        where = "SDP33Sensor"
        require_number(where, "noise_std_Pa", self.noise_std_Pa, ge=0.0, unit="Pa")
        if len(tuple(self.offset_Pa)) != 3:
            raise ProbeError(f"{where}: offset_Pa = {self.offset_Pa!r}: must have 3 elements "
                             "(q_inf, q_alpha, q_beta channels, Pa)")
        for i, v in enumerate(self.offset_Pa):
            require_number(where, f"offset_Pa[{i}]", v, unit="Pa")
        object.__setattr__(self, "offset_Pa", tuple(float(v) for v in self.offset_Pa))
        require_number(where, "time_constant_s", self.time_constant_s, ge=0.0, unit="s")
        require_number(where, "resolution_Pa", self.resolution_Pa, ge=0.0, unit="Pa")
        require_number(where, "range_Pa", self.range_Pa, gt=0.0, unit="Pa")

    @classmethod
    def with_random_offsets(cls, rng: np.random.Generator, offset_std_Pa: float = 0.2,
                            **kwargs) -> "SDP33Sensor":
        """A sensor whose three offsets are drawn ``N(0, offset_std_Pa^2)`` from ``rng``.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of randomness (three standard normals are drawn).
        offset_std_Pa : float
            Standard deviation of the offsets (Pa); the paper quotes 0.2 Pa.
        **kwargs
            Other :class:`SDP33Sensor` fields.

        Returns
        -------
        SDP33Sensor
        """
        offsets = tuple(float(x) for x in offset_std_Pa * rng.standard_normal(3))
        return cls(offset_Pa=offsets, **kwargs)

    def to_kernel(self) -> np.ndarray:
        """Sensor parameters as the float64 array :func:`sdp33_sensor_step` takes.

        Returns
        -------
        numpy.ndarray
            ``[tau_s, noise_std_Pa, offset_inf, offset_alpha, offset_beta, resolution_Pa,
            range_Pa]``.
        """
        return SENSOR_PARAMS.pack(TIME_CONSTANT=self.time_constant_s, NOISE_STD=self.noise_std_Pa,
                                  OFFSET=self.offset_Pa, RESOLUTION=self.resolution_Pa,
                                  RANGE=self.range_Pa)

    def initial_state(self, q_true=None) -> np.ndarray:
        """A lag state: settled at ``q_true`` (Pa, shape (3,)) if given, else zeros."""
        if q_true is None:
            return np.zeros(3)
        return np.array(q_true, dtype=float).reshape(3).copy()

    def noise_variance_Pa2(self) -> float:
        """Variance of one output sample about its mean (Pa^2): noise plus quantisation.

        ``sigma^2 + step^2 / 12`` (the uniform quantisation-error approximation, good when
        ``sigma`` is not much smaller than the step).
        """
        return self.noise_std_Pa ** 2 + self.resolution_Pa ** 2 / 12.0


# inline="always" here and below: the simulator's airflow-probe channel calls these every tick, and
# as separate calls their array arguments' reference counting cost more than their arithmetic.
@njit(cache=True, inline="always")
def sdp33_sensor_step_drawn(q_true, state, sensor, dt, normals, out_q):
    """:func:`sdp33_sensor_step` with its three standard normals given (``normals[0:3]``, one per sensor)."""
    tau = sensor[SENSOR_TIME_CONSTANT_S]
    if tau > 0.0 and dt > 0.0:
        a = 1.0 - np.exp(-dt / tau)
    else:
        a = 1.0
    sigma = sensor[SENSOR_NOISE_STD_PA]
    step = sensor[SENSOR_RESOLUTION_PA]
    full = sensor[SENSOR_RANGE_PA]
    for i in range(3):
        z = normals[i]
        x = q_true[i]
        if not np.isfinite(x):
            out_q[i] = np.nan
            continue
        if np.isfinite(state[i]):
            state[i] += a * (x - state[i])
        else:
            state[i] = x
        m = state[i] + sensor[SENSOR_OFFSET_PA + i] + sigma * z
        if m > full:
            m = full
        elif m < -full:
            m = -full
        if step > 0.0:
            m = np.floor(m / step + 0.5) * step
        out_q[i] = m


@njit(cache=True, inline="always")
def sdp33_sensor_step(q_true, state, sensor, dt, rng, out_q):
    """Advance the three sensors by ``dt`` and write their readings.

    Parameters
    ----------
    q_true : float64[3]
        True ``[q_inf, q_alpha, q_beta]`` at the probe (Pa), held over the step.
    state : float64[3]
        Lag state (Pa), updated in place. A non-finite state entry is reset to ``q_true``.
    sensor : float64[7]
        :meth:`SDP33Sensor.to_kernel`.
    dt : float
        Time step (s); ``dt <= 0`` or ``tau == 0`` means no lag.
    rng : numpy.random.Generator
        Noise source; exactly three standard normals are drawn per call.
    out_q : float64[3]
        Written: readings (Pa) = quantise(clip(state + offset + noise)). A channel whose
        ``q_true`` is not finite reads NaN (and its state is left unchanged);
        :func:`~vtoladapt.probe.estimation.incident_velocity_from_pressures` flags that.
    """
    z0 = rng.standard_normal()
    z1 = rng.standard_normal()
    z2 = rng.standard_normal()
    sdp33_sensor_step_drawn(q_true, state, sensor, dt, (z0, z1, z2), out_q)


@njit(cache=True)
def _sensor_run(q_true, state, sensor, dt, rng, out):
    """Step the sensor ``out.shape[0]`` times with a constant input; rows of ``out`` = readings."""
    for k in range(out.shape[0]):
        sdp33_sensor_step(q_true, state, sensor, dt, rng, out[k])


def sensor_response(sensor: SDP33Sensor, q_true, n_steps: int, dt: float,
                    rng: np.random.Generator, state=None) -> np.ndarray:
    """Readings of the sensor over ``n_steps`` steps of ``dt`` with a constant true input.

    Parameters
    ----------
    sensor : SDP33Sensor
    q_true : array_like, shape (3,)
        True differential pressures (Pa).
    n_steps : int
        Number of steps.
    dt : float
        Step (s).
    rng : numpy.random.Generator
    state : array_like, shape (3,), optional
        Initial lag state (Pa); default: settled at ``q_true``. Not modified.

    Returns
    -------
    numpy.ndarray, shape (n_steps, 3)
    """
    q = np.asarray(q_true, dtype=float).reshape(3).copy()
    x = sensor.initial_state(q if state is None else state)
    out = np.empty((int(n_steps), 3))
    _sensor_run(q, x, sensor.to_kernel(), float(dt), rng, out)
    return out


def steady_state_fraction(dt: float, tau: float) -> float:
    """Fraction of a step the lag reaches after one step: ``1 - exp(-dt / tau)``."""
    return 1.0 if tau <= 0.0 or dt <= 0.0 else 1.0 - math.exp(-dt / tau)
