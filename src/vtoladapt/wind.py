"""Wind acting on the simulated aircraft: fan array, constant wind, discrete gusts, Dryden turbulence.

The total wind velocity (NED, m/s) is the sum of four parts, each set in a scenario's ``[wind]``
table (see :class:`WindConfig`):

* **Fan array** (the paper's CAST wind tunnel): a throttle schedule ``[[t_s, throttle_pct], ...]``
  and a mean wind speed linear in throttle, ``V = max_speed_mps * throttle / 100`` (12.9 m/s at
  100 %; 30 / 50 / 70 % give 3.9 / 6.5 / 9.0 m/s, the paper's "about 4, 6.5 and 9 m/s"). The wind
  blows from the array toward the vehicle; by default the array is north of the vehicle, so
  ``v_w = (-V, 0, 0)``. An optional first-order spin-up lag of the fans is solved in closed form,
  so the mean wind is a pure function of time (:func:`fan_mean_wind_speed`).
* **Constant wind**, a fixed NED vector.
* **Gusts**: ``"one_minus_cosine"`` (``A (1 - cos(2 pi (t - t0) / T)) / 2`` for ``t0 <= t <= t0 + T``:
  rises to ``A`` at mid-gust and returns to zero, the CS-25 / FAR-25 discrete-gust shape) or
  ``"step"`` (``A`` for ``t0 <= t < t0 + T``).
* **Dryden turbulence** in the MIL-F-8785C form (below).

Dryden turbulence (MIL-F-8785C)
-------------------------------
Frozen turbulence convected past the aircraft at airspeed ``V``: a spatial frequency ``Omega``
(rad/m) is met at the temporal frequency ``omega = V Omega`` (rad/s). The one-sided spatial
spectra, with ``int_0^inf Phi(Omega) dOmega = sigma^2``, are

    Phi_u(Omega) = sigma_u^2 (2 L_u / pi) / (1 + (L_u Omega)^2)
    Phi_v(Omega) = sigma_v^2 (L_v / pi) (1 + 3 (L_v Omega)^2) / (1 + (L_v Omega)^2)^2
    Phi_w(Omega) = sigma_w^2 (L_w / pi) (1 + 3 (L_w Omega)^2) / (1 + (L_w Omega)^2)^2

(in Hz: ``S(f) = (2 pi / V) Phi(2 pi f / V)``, see :func:`dryden_psd`), whose autocorrelations in
time are ``R_u(tau) = sigma_u^2 exp(-|tau| / T_u)`` and
``R_v(tau) = sigma_v^2 exp(-|tau| / T_v) (1 - |tau| / (2 T_v))`` with ``T = L / V``.

Low-altitude model (h < 1000 ft, h in feet, W20 = wind speed at 20 ft)::

    L_w = h,   L_u = L_v = h / (0.177 + 0.000823 h)^1.2
    sigma_w = 0.1 W20,   sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4

(see :func:`dryden_low_altitude`). W20 is 15 / 30 / 45 kt for light / moderate / severe
turbulence. The intensities may instead be given directly, or as a fraction of the mean wind speed
(the turbulence intensity of a wind tunnel, so a fan array that is off gives no turbulence).

Components: ``u`` along the horizontal mean wind direction (fixed once from the fan-array direction
and the constant wind), ``v`` horizontal and 90 degrees to its right, ``w`` down.
``V`` is the magnitude of the mean wind (fan plus constant; for a vehicle holding position this is
its airspeed) with a floor, or a fixed ``convection_speed_mps``.

Discretisation (exact at the sample instants for ``V``, ``sigma``, ``L`` held over a step): every
filter state is normalised to unit stationary variance and the output is scaled by ``sigma``.
With ``x = V dt / L``:

* ``u``: ``s <- exp(-x) s + sqrt(1 - exp(-2x)) n``.
* ``v`` and ``w``: two cascaded first-order stages ``s2' = -a s2 + 2 sqrt(a) n(t)``,
  ``s1' = -a s1 + a s2`` (``a = V / L``), output ``c1 s1 + c2 s2`` with
  ``c1 = (1 - sqrt 3) / 2``, ``c2 = sqrt 3 / 2``. This realises the transfer function
  ``(1 + sqrt 3 T s) / (1 + T s)^2`` with unit variance and the autocorrelation above. The state
  transition is ``exp(-x) [[1, x], [0, 1]]`` and the noise covariance over a step is
  ``[[1 - e^{-2x}(1 + 2x + 2x^2), 1 - e^{-2x}(1 + 2x)], [., 2 (1 - e^{-2x})]]`` (series for small
  ``x``, where these cancel), drawn through its Cholesky factor.

The sampled sequence therefore has exactly the Dryden autocorrelation at multiples of ``dt``; its
spectrum is the continuous Dryden spectrum folded at the Nyquist frequency. The first call of
:func:`wind_step` draws the filter states from their stationary distribution, so the turbulence
is statistically stationary from t = 0. The step coefficients are kept in the state and
recomputed only when ``V dt`` changes (while the fan spins up, or when ``dt`` changes).

Kernels and randomness
----------------------
:meth:`WindConfig.to_kernel` converts the configuration once to a float64 array;
:func:`wind_initial_state`, :func:`wind_step`, :func:`fan_mean_wind_speed` and
:func:`fan_throttle_pct` are compiled. Every :func:`wind_step` call draws exactly
``WIND_DRAWS_PER_STEP`` standard normals (and ``WIND_DRAWS_FIRST_STEP`` on the first call),
whether turbulence is on or not, so switching turbulence on or off never shifts the random stream
of anything else sharing the generator.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from numba import njit

from .config import ConfigError, build, setting

FT_M = 0.3048
"""One foot in metres."""
KNOT_MPS = 1852.0 / 3600.0
"""One knot in m/s."""

FAN_MAX_SPEED_MPS = 12.9
"""Wind speed of the CAST fan array at 100 % throttle (Shi et al. 2020, Sec. Experiments)."""

MAX_BREAKPOINTS = 64
"""Largest number of schedule breakpoints the kernel holds (after expanding ``"hold"`` steps)."""
MAX_GUSTS = 16
"""Largest number of gusts the kernel holds."""

WIND_DRAWS_PER_STEP = 5
WIND_DRAWS_FIRST_STEP = 10

GUST_SHAPES = ("one_minus_cosine", "step")
PAPER_PROFILES = ("convergence", "comparison")

# --- kernel parameter layout (private to this module) -------------------------------------------
_FAN_N = 0            # number of breakpoints (piecewise-linear form)
_FAN_MAX_SPEED = 1    # m/s at 100 %
_FAN_DIR = 2          # unit vector (N, E) the fan wind blows toward (2)
_FAN_TAU = 4          # spin-up time constant, s (0: none)
_CONST = 5            # constant wind, NED, m/s (3)
_TURB_ON = 8          # 1.0 if turbulence is on
_TURB_FRACTION = 9    # 1.0: sigma = _TURB_SIGMA * |mean wind|; 0.0: sigma = _TURB_SIGMA (m/s)
_TURB_SIGMA = 10      # sigma_u, sigma_v, sigma_w (m/s) or fractions of the mean wind (3)
_TURB_L = 13          # L_u, L_v, L_w, m (3)
_TURB_V_FIXED = 16    # convection speed, m/s, if >= 0; < 0: use |mean wind|
_TURB_V_MIN = 17      # floor of the convection speed, m/s
_TURB_AXIS = 18       # unit vector (N, E) of the turbulence u axis (2)
_N_GUSTS = 20
_FAN_T = 21                                 # breakpoint times, s
_FAN_U = _FAN_T + MAX_BREAKPOINTS           # breakpoint throttles, %
_FAN_Y = _FAN_U + MAX_BREAKPOINTS           # lagged throttle at each breakpoint, %
_GUST = _FAN_Y + MAX_BREAKPOINTS            # per gust: shape, t0, T, A_N, A_E, A_D
_GUST_STRIDE = 6
WIND_KERNEL_SIZE = _GUST + _GUST_STRIDE * MAX_GUSTS

# --- turbulence state layout -------------------------------------------------------------------
_S_INIT = 0   # 0.0 until the first step has drawn the stationary initial state
_S_U = 1      # normalised u filter state
_S_V = 2      # normalised v filter states s1, s2 (2)
_S_W = 4      # normalised w filter states s1, s2 (2)
_S_KEY = 6    # V dt the cached coefficients below were computed for (-1: none yet)
_S_COEF_U = 7   # u filter: exp(-x), sqrt(1 - exp(-2x)) (2)
_S_COEF_V = 9   # v filter: x, exp(-x), Cholesky l11, l21, l22 of the step noise covariance (5)
_S_COEF_W = 14  # w filter: same (5)
WIND_STATE_SIZE = 19

_C1 = 0.5 * (1.0 - math.sqrt(3.0))
_C2 = 0.5 * math.sqrt(3.0)
_SERIES_X = 0.1


# ==================================================================================================
# Configuration
# ==================================================================================================

@dataclass(frozen=True)
class FanArrayConfig:
    """The fan array: a throttle schedule and the wind it makes.

    ``schedule`` is a list of breakpoints ``[t_s, throttle_pct]``. With ``interpolation =
    "linear"`` the throttle is piecewise linear between breakpoints, and two breakpoints at the
    same time make a step (the throttle just before, then from that time on). With ``"hold"`` each
    throttle holds until the next breakpoint (steps only). Before the first breakpoint the first
    throttle holds, after the last the last. An empty schedule is a fan array that is off.
    Instead of a schedule, ``profile`` names one of the paper's two experiments
    (:func:`convergence_schedule`, :func:`comparison_schedule` with their default lengths).
    """

    schedule: tuple[tuple[float, ...], ...] = setting(
        "[s, %]", "breakpoints [t_s, throttle_pct]; times non-decreasing, throttle 0-100",
        default=())
    profile: str | None = setting(
        "-", "the paper's profile instead of a schedule: 'convergence' (still air 10 s, then 30, "
        "50, 70 % for 20 s each) or 'comparison' (off 5 s; 30 % 10 s; 40, 50, 60 % 5 s each; "
        "70 % 10 s; off from 40 s)", default=None, choices=PAPER_PROFILES)
    interpolation: str = setting(
        "-", "'linear': ramps between breakpoints (repeat a time for a step); 'hold': steps",
        default="linear", choices=("linear", "hold"))
    max_speed_mps: float = setting("m/s", "mean wind speed at 100 % throttle (CAST: 12.9)",
                                   default=FAN_MAX_SPEED_MPS, gt=0.0, le=60.0)
    array_bearing_deg: float = setting(
        "deg", "compass bearing of the array seen from the vehicle = where the wind comes from "
        "(0: north, so v_w = (-V, 0, 0); 90: east)", default=0.0, ge=-360.0, le=360.0)
    spin_up_time_constant_s: float = setting(
        "s", "first-order lag from throttle to wind speed (0: the wind follows the throttle at once)",
        default=0.0, ge=0.0, le=60.0)

    def _check(self, source: str) -> None:
        where = f"{source}: [wind.fan_array] schedule"
        if self.profile is not None:
            if self.schedule:
                raise ConfigError(f"{source}: [wind.fan_array] profile = {self.profile!r} and a "
                                  "schedule: give one or the other")
            if self.interpolation != "linear":
                raise ConfigError(f"{source}: [wind.fan_array] profile = {self.profile!r} with "
                                  f"interpolation = {self.interpolation!r}: a profile brings its "
                                  "own steps; leave interpolation at 'linear'")
        previous_t = -math.inf
        repeats = 0
        for i, entry in enumerate(self.schedule):
            text = f"{where}[{i}] = {list(entry)}"
            if len(entry) != 2:
                raise ConfigError(f"{text}: must be [t_s, throttle_pct]")
            t, pct = entry
            if t < 0.0:
                raise ConfigError(f"{text}: time {t:g} s is negative; allowed: >= 0 s")
            if not 0.0 <= pct <= 100.0:
                raise ConfigError(f"{text}: throttle {pct:g} % outside the allowed 0 to 100 %")
            if t < previous_t:
                raise ConfigError(
                    f"{text}: time {t:g} s is before the previous breakpoint's {previous_t:g} s; "
                    "times must not decrease")
            if t == previous_t:
                if self.interpolation == "hold":
                    raise ConfigError(
                        f"{text}: time {t:g} s repeats; with interpolation = 'hold' times must "
                        "increase strictly (each breakpoint already starts a step)")
                repeats += 1
                if repeats > 1:
                    raise ConfigError(
                        f"{text}: a third breakpoint at {t:g} s; a step needs exactly two "
                        "(the throttle before and after)")
            else:
                repeats = 0
            previous_t = t
        n = len(self.linear_breakpoints())
        if n > MAX_BREAKPOINTS:
            raise ConfigError(
                f"{where}: {len(self.schedule)} breakpoints make {n} in piecewise-linear form; "
                f"at most {MAX_BREAKPOINTS} are allowed")

    def linear_breakpoints(self) -> tuple[tuple[float, float], ...]:
        """The schedule as piecewise-linear breakpoints (``"hold"`` steps become repeated times)."""
        if self.profile is not None:
            return paper_schedule(self.profile)
        pts = [(float(t), float(u)) for t, u in self.schedule]
        if self.interpolation == "linear" or not pts:
            return tuple(pts)
        out = [pts[0]]
        for t, u in pts[1:]:
            out.append((t, out[-1][1]))
            out.append((t, u))
        return tuple(out)


@dataclass(frozen=True)
class TurbulenceConfig:
    """Dryden turbulence (MIL-F-8785C); give exactly one intensity and at most one length source.

    Intensity: ``w20_mps`` (low-altitude model with ``altitude_m``), ``sigma_mps`` directly, or
    ``mean_wind_fraction`` (sigma = fraction x |mean wind|, a wind tunnel's turbulence
    intensity). Length scales: ``length_scale_m`` directly, else the low-altitude model at
    ``altitude_m``.
    """

    enabled: bool = setting("-", "add Dryden turbulence", default=False)
    w20_mps: float | None = setting(
        "m/s", "wind speed at 20 ft (light 7.7, moderate 15.4, severe 23.2 m/s)", default=None,
        ge=0.0, le=60.0)
    sigma_mps: tuple[float, ...] | None = setting(
        "m/s", "intensities sigma_u, sigma_v, sigma_w", default=None, ge=0.0, le=30.0, length=3)
    mean_wind_fraction: tuple[float, ...] | None = setting(
        "-", "intensities as fractions of the mean wind speed (u, v, w)", default=None, ge=0.0,
        le=1.0, length=3)
    altitude_m: float = setting(
        "m", "height above ground for the low-altitude length scales and W20 intensities",
        default=2.0, gt=0.0, le=1000.0 * FT_M)
    length_scale_m: tuple[float, ...] | None = setting(
        "m", "length scales L_u, L_v, L_w (overrides the altitude model)", default=None, gt=0.0,
        le=10000.0, length=3)
    convection_speed_mps: float | None = setting(
        "m/s", "airspeed at which the frozen field is convected (default: |mean wind|)",
        default=None, ge=0.0, le=100.0)
    min_convection_speed_mps: float = setting(
        "m/s", "floor on |mean wind| as convection speed (0: turbulence freezes in still air)",
        default=0.5, ge=0.0, le=100.0)

    def _check(self, source: str) -> None:
        given = [k for k in ("w20_mps", "sigma_mps", "mean_wind_fraction")
                 if getattr(self, k) is not None]
        if self.enabled and len(given) != 1:
            raise ConfigError(
                f"{source}: [wind.turbulence] enabled = true needs exactly one of w20_mps, "
                f"sigma_mps, mean_wind_fraction; got {', '.join(given) if given else 'none'}")
        if len(given) > 1:
            raise ConfigError(
                f"{source}: [wind.turbulence] {', '.join(given)}: give only one intensity source")

    def intensities_and_lengths(self) -> tuple[np.ndarray, np.ndarray]:
        """``(sigma, L)``: sigma in m/s (or fractions, for ``mean_wind_fraction``) and L in m."""
        sigma_lo, length_lo = dryden_low_altitude(self.altitude_m, self.w20_mps or 0.0)
        if self.sigma_mps is not None:
            sigma = np.array(self.sigma_mps, dtype=float)
        elif self.mean_wind_fraction is not None:
            sigma = np.array(self.mean_wind_fraction, dtype=float)
        else:
            sigma = sigma_lo
        length = (np.array(self.length_scale_m, dtype=float) if self.length_scale_m is not None
                  else length_lo)
        return sigma, length


@dataclass(frozen=True)
class GustConfig:
    """One discrete gust (an entry of ``[[wind.gusts]]``)."""

    shape: str = setting("-", "'one_minus_cosine' (up to A and back to zero) or 'step'",
                         choices=GUST_SHAPES)
    start_s: float = setting("s", "start time", ge=0.0, le=3600.0)
    duration_s: float = setting("s", "duration", gt=0.0, le=3600.0)
    amplitude_mps: tuple[float, ...] = setting("m/s", "peak wind vector, NED", ge=-60.0, le=60.0, length=3)


@dataclass(frozen=True)
class WindConfig:
    """All the wind of a scenario; the parts add up. Load with :meth:`from_mapping`."""

    constant_mps: tuple[float, ...] = setting("m/s", "constant wind vector, NED",
                                              default=(0.0, 0.0, 0.0), ge=-60.0, le=60.0, length=3)
    fan_array: FanArrayConfig = setting("-", "fan-array wind", default=FanArrayConfig())
    turbulence: TurbulenceConfig = setting("-", "Dryden turbulence", default=TurbulenceConfig())
    gusts: tuple[GustConfig, ...] = setting("-", "discrete gusts ([[wind.gusts]] entries)",
                                            default=())

    def _check(self, source: str) -> None:
        if len(self.gusts) > MAX_GUSTS:
            raise ConfigError(f"{source}: [wind] gusts: {len(self.gusts)} entries; at most "
                              f"{MAX_GUSTS} are allowed")

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], *, source: str = "<config>",
                     section: str = "wind") -> "WindConfig":
        """Build from a scenario's ``[wind]`` table (with ``[wind.fan_array]``,
        ``[wind.turbulence]`` and ``[[wind.gusts]]``).

        Raises
        ------
        ConfigError
            Naming the file, the table (``wind.gusts[2]`` for the third gust) and the key.
        """
        if not isinstance(data, Mapping):
            raise ConfigError(f"{source}: [{section}] must be a table, got {data!r}")
        rest = dict(data)
        raw_gusts = rest.pop("gusts", [])
        if not isinstance(raw_gusts, (list, tuple)):
            raise ConfigError(f"{source}: [{section}] gusts = {raw_gusts!r}: must be a list of "
                              "tables ([[wind.gusts]])")
        gusts = tuple(build(GustConfig, g, source=source, section=f"{section}.gusts[{i}]")
                      for i, g in enumerate(raw_gusts))
        cfg = build(cls, rest, source=source, section=section)
        cfg = dataclasses.replace(cfg, gusts=gusts)
        cfg._check(source)
        return cfg

    def turbulence_axis_NE(self) -> np.ndarray:
        """Unit (N, E) vector of the turbulence ``u`` axis: the mean wind's horizontal direction.

        Taken from the fan wind at full throttle plus the constant wind (north if both vanish),
        fixed over the run so the axes never jump.
        """
        fan = self.fan_array
        on = bool(fan.schedule) or fan.profile is not None
        d = -_bearing_unit(fan.array_bearing_deg) * (fan.max_speed_mps if on else 0.0)
        h = d + np.array(self.constant_mps[:2], dtype=float)
        n = float(np.hypot(h[0], h[1]))
        if n < 1e-9:
            return -_bearing_unit(fan.array_bearing_deg)
        return h / n

    def time_scaled(self, scale: float) -> "WindConfig":
        """The same wind with every time stretched by ``scale`` (> 0), for quick looks and tests.

        Schedule times, the fan spin-up time constant and the gusts' start and duration are
        multiplied by ``scale``; speeds and the turbulence are unchanged.
        """
        if not (scale > 0.0 and math.isfinite(scale)):
            raise ValueError(f"scale = {scale!r}: must be a finite number > 0")
        fan = self.fan_array
        fan = dataclasses.replace(
            fan, schedule=tuple((t * scale, u) for t, u in fan.linear_breakpoints()),
            profile=None, interpolation="linear",
            spin_up_time_constant_s=fan.spin_up_time_constant_s * scale)
        gusts = tuple(dataclasses.replace(g, start_s=g.start_s * scale,
                                          duration_s=g.duration_s * scale) for g in self.gusts)
        return dataclasses.replace(self, fan_array=fan, gusts=gusts)

    def to_kernel(self) -> np.ndarray:
        """The configuration as the float64 array the wind kernels take.

        Raises
        ------
        ConfigError
            If the configuration was built without validation and does not fit the kernel (an
            invalid schedule, too many breakpoints or gusts).
        """
        self.fan_array._check("WindConfig.to_kernel")
        self._check("WindConfig.to_kernel")
        p = np.zeros(WIND_KERNEL_SIZE)
        fan = self.fan_array
        pts = fan.linear_breakpoints()
        n = len(pts)
        p[_FAN_N] = n
        p[_FAN_MAX_SPEED] = fan.max_speed_mps
        p[_FAN_DIR:_FAN_DIR + 2] = -_bearing_unit(fan.array_bearing_deg)
        p[_FAN_TAU] = fan.spin_up_time_constant_s
        if n:
            t = np.array([q[0] for q in pts])
            u = np.array([q[1] for q in pts])
            p[_FAN_T:_FAN_T + n] = t
            p[_FAN_U:_FAN_U + n] = u
            p[_FAN_Y:_FAN_Y + n] = _lagged_breakpoints(t, u, fan.spin_up_time_constant_s)
        p[_CONST:_CONST + 3] = self.constant_mps
        turb = self.turbulence
        p[_TURB_ON] = 1.0 if turb.enabled else 0.0
        sigma, length = turb.intensities_and_lengths()
        p[_TURB_FRACTION] = 1.0 if turb.mean_wind_fraction is not None else 0.0
        p[_TURB_SIGMA:_TURB_SIGMA + 3] = sigma
        p[_TURB_L:_TURB_L + 3] = length
        p[_TURB_V_FIXED] = -1.0 if turb.convection_speed_mps is None else turb.convection_speed_mps
        p[_TURB_V_MIN] = turb.min_convection_speed_mps
        p[_TURB_AXIS:_TURB_AXIS + 2] = self.turbulence_axis_NE()
        p[_N_GUSTS] = len(self.gusts)
        for i, g in enumerate(self.gusts):
            k = _GUST + _GUST_STRIDE * i
            p[k] = GUST_SHAPES.index(g.shape)
            p[k + 1] = g.start_s
            p[k + 2] = g.duration_s
            p[k + 3:k + 6] = g.amplitude_mps
        return p


def _bearing_unit(bearing_deg: float) -> np.ndarray:
    b = math.radians(bearing_deg)
    return np.array([math.cos(b), math.sin(b)])


def _lagged_breakpoints(t: np.ndarray, u: np.ndarray, tau_s: float) -> np.ndarray:
    """Fan speed (as throttle, %) after the spin-up lag at each breakpoint, starting settled."""
    y = np.empty_like(u)
    y[0] = u[0]
    for k in range(len(t) - 1):
        y[k + 1] = _lag_on_segment(y[k], u[k], u[k + 1], t[k + 1] - t[k], t[k + 1] - t[k], tau_s)
    return y


@njit(cache=True, inline="always")
def _lag_on_segment(y0: float, u0: float, u1: float, seg_s: float, elapsed_s: float,
                    tau_s: float) -> float:
    """Closed-form ``y' = (u - y) / tau`` for ``u`` linear from ``u0`` to ``u1`` over ``seg_s``."""
    if tau_s <= 0.0:
        if seg_s <= 0.0:
            return u1
        return u0 + (u1 - u0) * elapsed_s / seg_s
    if seg_s <= 0.0:
        return y0
    slope = (u1 - u0) / seg_s
    u = u0 + slope * elapsed_s
    return u - slope * tau_s + (y0 - u0 + slope * tau_s) * np.exp(-elapsed_s / tau_s)


def dryden_low_altitude(altitude_m: float, w20_mps: float) -> tuple[np.ndarray, np.ndarray]:
    """MIL-F-8785C low-altitude Dryden intensities and length scales.

    Parameters
    ----------
    altitude_m : float
        Height above ground (m), in (0, 304.8] (the model holds below 1000 ft).
    w20_mps : float
        Wind speed at 20 ft (m/s): 15 / 30 / 45 kt for light / moderate / severe turbulence.

    Returns
    -------
    sigma_mps : numpy.ndarray, shape (3,)
        ``sigma_u, sigma_v, sigma_w`` (m/s): ``sigma_w = 0.1 W20``,
        ``sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4`` (h in ft).
    length_m : numpy.ndarray, shape (3,)
        ``L_u = L_v = h / (0.177 + 0.000823 h)^1.2``, ``L_w = h`` (computed in ft, returned in m).
    """
    if not 0.0 < altitude_m <= 1000.0 * FT_M:
        raise ValueError(f"altitude_m = {altitude_m!r}: the low-altitude model needs 0 < h <= "
                         "304.8 m (1000 ft)")
    h_ft = altitude_m / FT_M
    base = 0.177 + 0.000823 * h_ft
    sigma_w = 0.1 * w20_mps
    sigma_uv = sigma_w / base**0.4
    L_uv_ft = h_ft / base**1.2
    return (np.array([sigma_uv, sigma_uv, sigma_w]),
            np.array([L_uv_ft, L_uv_ft, h_ft]) * FT_M)


def dryden_psd(component: str, f_hz, sigma_mps: float, length_m: float,
               airspeed_mps: float) -> np.ndarray:
    """One-sided Dryden power spectral density in time, (m/s)^2 / Hz (MIL-F-8785C).

    ``S(f) = (2 pi / V) Phi(Omega = 2 pi f / V)`` with ``Phi`` the spatial spectra in the module
    notes, so ``int_0^inf S(f) df = sigma^2``.

    Parameters
    ----------
    component : {"u", "v", "w"}
    f_hz : array_like
        Frequencies (Hz), >= 0.
    sigma_mps, length_m, airspeed_mps : float
        Intensity (m/s), length scale (m), convection airspeed (m/s, > 0).
    """
    if component not in ("u", "v", "w"):
        raise ValueError(f"component = {component!r}: allowed 'u', 'v', 'w'")
    if not airspeed_mps > 0.0:
        raise ValueError(f"airspeed_mps = {airspeed_mps!r}: must be > 0")
    omega = 2.0 * np.pi * np.asarray(f_hz, dtype=float) / airspeed_mps
    lo2 = (length_m * omega) ** 2
    if component == "u":
        phi = sigma_mps**2 * (2.0 * length_m / np.pi) / (1.0 + lo2)
    else:
        phi = sigma_mps**2 * (length_m / np.pi) * (1.0 + 3.0 * lo2) / (1.0 + lo2) ** 2
    return 2.0 * np.pi / airspeed_mps * phi


# ==================================================================================================
# The paper's fan-array profiles
# ==================================================================================================

def _levels_schedule(levels: Sequence[tuple[float, float]], ramp_s: float) -> tuple:
    """Breakpoints for throttle levels ``(start_s, pct)`` (first level from t = 0)."""
    if ramp_s < 0.0:
        raise ValueError(f"ramp_s = {ramp_s!r}: must be >= 0")
    pts = [(0.0, float(levels[0][1]))]
    for (t_prev, _), (t, pct) in zip(levels[:-1], levels[1:]):
        if ramp_s > 0.0 and t - t_prev < ramp_s:
            raise ValueError(f"ramp_s = {ramp_s:g} s is longer than the level starting at "
                             f"{t_prev:g} s ({t - t_prev:g} s)")
        pts.append((float(t), pts[-1][1]))
        pts.append((float(t + ramp_s), float(pct)))
    return tuple(pts)


def convergence_schedule(hover_s: float = 10.0, level_s: float = 20.0,
                         levels_pct: Sequence[float] = (30.0, 50.0, 70.0),
                         ramp_s: float = 0.0) -> tuple[tuple[float, float], ...]:
    """The convergence experiment (Fig. parameter_convergence): still air, then 30, 50, 70 %.

    Parameters
    ----------
    hover_s : float
        Hover in still air (fan off) before the first level (s).
    level_s : float
        Time at each throttle level (s); the schedule ends at ``hover_s + 3 level_s`` still at
        the last level.
    levels_pct : sequence of float
        Throttle levels (%).
    ramp_s : float
        Throttle ramp between levels (s); 0 for steps.

    Returns
    -------
    tuple of (t_s, throttle_pct)
        Breakpoints for ``interpolation = "linear"``.
    """
    levels = [(0.0, 0.0)] + [(hover_s + i * level_s, p) for i, p in enumerate(levels_pct)]
    pts = _levels_schedule(levels, ramp_s)
    return pts + ((hover_s + len(levels_pct) * level_s, pts[-1][1]),)


def comparison_schedule(hover_s: float = 5.0, first_level_s: float = 10.0, step_s: float = 5.0,
                        top_s: float = 10.0, ramp_s: float = 0.0) -> tuple[tuple[float, float], ...]:
    """The comparison experiment (Figs. tracking_comparison*): fan off; 30 % for 10 s; +10 %
    every 5 s up to 70 %; 10 s at 70 %; fan off.

    The fan goes off at ``hover_s + first_level_s + 3 step_s + top_s`` (40 s by default);
    simulate ~10 s longer to see the response to the wind dropping.

    Returns
    -------
    tuple of (t_s, throttle_pct)
        Breakpoints for ``interpolation = "linear"``.
    """
    levels = [(0.0, 0.0), (hover_s, 30.0)]
    t = hover_s + first_level_s
    for pct in (40.0, 50.0, 60.0, 70.0):
        levels.append((t, pct))
        t += step_s if pct < 70.0 else top_s
    levels.append((t, 0.0))
    return _levels_schedule(levels, ramp_s)


def paper_schedule(profile: str, **kwargs) -> tuple[tuple[float, float], ...]:
    """Breakpoints of the paper's ``"convergence"`` or ``"comparison"`` profile.

    ``kwargs`` go to :func:`convergence_schedule` or :func:`comparison_schedule`.
    """
    makers = {"convergence": convergence_schedule, "comparison": comparison_schedule}
    if profile not in makers:
        raise ValueError(f"profile = {profile!r}: allowed {', '.join(map(repr, makers))}")
    return makers[profile](**kwargs)


def paper_fan_array(profile: str, spin_up_time_constant_s: float = 0.0, **kwargs) -> FanArrayConfig:
    """A :class:`FanArrayConfig` for ``profile`` = ``"convergence"`` or ``"comparison"``.

    ``kwargs`` (segment lengths, ``ramp_s``) go to :func:`convergence_schedule` or
    :func:`comparison_schedule`; the result carries the explicit schedule.
    """
    cfg = FanArrayConfig(schedule=paper_schedule(profile, **kwargs), interpolation="linear",
                         spin_up_time_constant_s=spin_up_time_constant_s)
    cfg._check(f"paper_fan_array({profile!r})")
    return cfg


# ==================================================================================================
# Kernels
# ==================================================================================================

@njit(cache=True, inline="always")
def _segment(params: np.ndarray, t: float) -> int:
    """Index k of the last breakpoint with ``t_k <= t`` (-1 before the first)."""
    n = int(params[_FAN_N])
    lo = 0
    hi = n  # invariant: answer in [lo - 1, hi - 1]
    while lo < hi:
        mid = (lo + hi) // 2
        if params[_FAN_T + mid] <= t:
            lo = mid + 1
        else:
            hi = mid
    return lo - 1


@njit(cache=True)
def fan_throttle_pct(params: np.ndarray, t: float) -> float:
    """Commanded fan-array throttle (%) at time ``t`` (s): the schedule, without the spin-up lag."""
    n = int(params[_FAN_N])
    if n == 0:
        return 0.0
    k = _segment(params, t)
    if k < 0:
        return params[_FAN_U]
    if k >= n - 1:
        return params[_FAN_U + n - 1]
    t0 = params[_FAN_T + k]
    t1 = params[_FAN_T + k + 1]
    u0 = params[_FAN_U + k]
    return u0 + (params[_FAN_U + k + 1] - u0) * (t - t0) / (t1 - t0)


@njit(cache=True, inline="always")
def _fan_speed_fraction(params: np.ndarray, t: float) -> float:
    """Fan wind speed as a fraction of ``max_speed``, after the spin-up lag."""
    n = int(params[_FAN_N])
    if n == 0:
        return 0.0
    tau = params[_FAN_TAU]
    k = _segment(params, t)
    if k < 0:
        return 0.01 * params[_FAN_U]
    y0 = params[_FAN_Y + k]
    u0 = params[_FAN_U + k]
    t0 = params[_FAN_T + k]
    if k >= n - 1:
        return 0.01 * _lag_on_segment(y0, u0, u0, 1.0, t - t0, tau)
    t1 = params[_FAN_T + k + 1]
    return 0.01 * _lag_on_segment(y0, u0, params[_FAN_U + k + 1], t1 - t0, t - t0, tau)


@njit(cache=True)
def fan_mean_wind_speed(params: np.ndarray, t: float) -> float:
    """Mean fan-array wind speed (m/s) at time ``t`` (s): linear in the throttle after the lag.

    ``V = max_speed_mps * y / 100`` where ``y`` is the throttle passed through the first-order
    spin-up lag (solved in closed form over the piecewise-linear schedule, starting settled).
    """
    return params[_FAN_MAX_SPEED] * _fan_speed_fraction(params, t)


@njit(cache=True)
def mean_wind_W(params: np.ndarray, t: float, out_v_W: np.ndarray) -> None:
    """Mean wind (fan array plus constant wind, NED, m/s) at ``t``: no gusts, no turbulence."""
    v = fan_mean_wind_speed(params, t)
    out_v_W[0] = v * params[_FAN_DIR] + params[_CONST]
    out_v_W[1] = v * params[_FAN_DIR + 1] + params[_CONST + 1]
    out_v_W[2] = params[_CONST + 2]


@njit(cache=True)
def gust_wind_W(params: np.ndarray, t: float, out_v_W: np.ndarray) -> None:
    """Sum of the discrete gusts (NED, m/s) at time ``t``."""
    out_v_W[0] = 0.0
    out_v_W[1] = 0.0
    out_v_W[2] = 0.0
    _add_gusts(params, t, out_v_W)


@njit(cache=True, inline="always")
def _add_gusts(params: np.ndarray, t: float, out_v_W: np.ndarray) -> None:
    for i in range(int(params[_N_GUSTS])):
        k = _GUST + _GUST_STRIDE * i
        t0 = params[k + 1]
        dur = params[k + 2]
        if t < t0 or t > t0 + dur:
            continue
        if params[k] == 0.0:
            s = 0.5 * (1.0 - np.cos(2.0 * np.pi * (t - t0) / dur))
        elif t < t0 + dur:
            s = 1.0
        else:
            s = 0.0
        for j in range(3):
            out_v_W[j] += s * params[k + 3 + j]


@njit(cache=True, inline="always")
def _two_pole_noise_cov(x: float) -> tuple:
    """Noise covariance ``(q11, q12, q22)`` of the normalised two-pole Dryden filter over ``x = a dt``."""
    if x < _SERIES_X:
        # 1 - e^{-2x}(...) cancels for small x; integrate the series of 4 s^m e^{-2s} instead.
        q11 = 0.0
        q12 = 0.0
        term = 1.0  # (-2)^n / n!
        xn = 1.0    # x^n
        for n in range(16):
            q11 += term * xn * x * x * x / (n + 3)
            q12 += term * xn * x * x / (n + 2)
            term *= -2.0 / (n + 1)
            xn *= x
        q11 *= 4.0
        q12 *= 4.0
    else:
        e2 = np.exp(-2.0 * x)
        q11 = 1.0 - e2 * (1.0 + 2.0 * x + 2.0 * x * x)
        q12 = 1.0 - e2 * (1.0 + 2.0 * x)
    q22 = -2.0 * np.expm1(-2.0 * x)
    return q11, q12, q22


@njit(cache=True, inline="always")
def _two_pole_coefficients(state: np.ndarray, c: int, x: float) -> None:
    """Store ``x, exp(-x)`` and the Cholesky factor of the step noise covariance at ``state[c:c+5]``."""
    q11, q12, q22 = _two_pole_noise_cov(x)
    l11 = np.sqrt(q11)
    l21 = q12 / l11 if l11 > 0.0 else 0.0
    state[c] = x
    state[c + 1] = np.exp(-x)
    state[c + 2] = l11
    state[c + 3] = l21
    state[c + 4] = np.sqrt(max(q22 - l21 * l21, 0.0))


@njit(cache=True, inline="always")
def _two_pole_advance(state: np.ndarray, i: int, c: int, n1: float, n2: float) -> None:
    """Advance the normalised two-pole filter states ``state[i], state[i+1]`` one step."""
    x = state[c]
    e = state[c + 1]
    s1 = state[i]
    s2 = state[i + 1]
    # state transition exp(A dt) = e^{-x} [[1, x], [0, 1]] for s1' = -a s1 + a s2, s2' = -a s2
    state[i] = e * (s1 + x * s2) + state[c + 2] * n1
    state[i + 1] = e * s2 + state[c + 3] * n1 + state[c + 4] * n2


@njit(cache=True)
def wind_initial_state(params: np.ndarray) -> np.ndarray:
    """A fresh wind state (turbulence filters; drawn from their stationary law on the first step)."""
    state = np.zeros(WIND_STATE_SIZE)
    state[_S_KEY] = -1.0
    return state


@njit(cache=True)
def wind_step(params: np.ndarray, state: np.ndarray, t: float, dt: float, p_W: np.ndarray,
              rng, out_v_wind_W: np.ndarray) -> None:
    """Write the total wind at time ``t`` and advance the turbulence to ``t + dt``.

    Parameters
    ----------
    params : numpy.ndarray
        From :meth:`WindConfig.to_kernel`.
    state : numpy.ndarray
        From :func:`wind_initial_state`; updated in place.
    t, dt : float
        Time of this tick and the step to the next (s). Any ``dt > 0`` is exact.
    p_W : numpy.ndarray, shape (3,)
        Vehicle position, NED (m). The models here are uniform in space and do not use it; it is
        part of the interface so a spatially varying field can be added without changing callers.
    rng : numpy.random.Generator
        Exactly ``WIND_DRAWS_PER_STEP`` standard normals per call (``WIND_DRAWS_FIRST_STEP`` on
        the first), whatever the configuration.
    out_v_wind_W : numpy.ndarray, shape (3,)
        Receives the wind velocity, NED (m/s): mean (fan + constant) + gusts + turbulence.
    """
    v_fan = params[_FAN_MAX_SPEED] * _fan_speed_fraction(params, t)
    m0 = v_fan * params[_FAN_DIR] + params[_CONST]
    m1 = v_fan * params[_FAN_DIR + 1] + params[_CONST + 1]
    m2 = params[_CONST + 2]
    out_v_wind_W[0] = m0
    out_v_wind_W[1] = m1
    out_v_wind_W[2] = m2
    _add_gusts(params, t, out_v_wind_W)

    if state[_S_INIT] == 0.0:
        # stationary start: s_u ~ N(0, 1); (s1, s2) ~ N(0, [[1, 1], [1, 2]])
        a = rng.standard_normal()
        b1 = rng.standard_normal()
        b2 = rng.standard_normal()
        c1 = rng.standard_normal()
        c2 = rng.standard_normal()
        state[_S_U] = a
        state[_S_V] = b1
        state[_S_V + 1] = b1 + b2
        state[_S_W] = c1
        state[_S_W + 1] = c1 + c2
        state[_S_INIT] = 1.0
    n_u = rng.standard_normal()
    n_v1 = rng.standard_normal()
    n_v2 = rng.standard_normal()
    n_w1 = rng.standard_normal()
    n_w2 = rng.standard_normal()
    if params[_TURB_ON] == 0.0:
        return

    speed = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    scale = speed if params[_TURB_FRACTION] != 0.0 else 1.0
    su = params[_TURB_SIGMA] * scale
    sv = params[_TURB_SIGMA + 1] * scale
    sw = params[_TURB_SIGMA + 2] * scale
    tu = su * state[_S_U]
    tv = sv * (_C1 * state[_S_V] + _C2 * state[_S_V + 1])
    tw = sw * (_C1 * state[_S_W] + _C2 * state[_S_W + 1])
    eN = params[_TURB_AXIS]
    eE = params[_TURB_AXIS + 1]
    # u along the mean wind, v 90 degrees to its right (east of north), w down
    out_v_wind_W[0] += tu * eN - tv * eE
    out_v_wind_W[1] += tu * eE + tv * eN
    out_v_wind_W[2] += tw

    V = params[_TURB_V_FIXED]
    if V < 0.0:
        V = max(speed, params[_TURB_V_MIN])
    key = V * dt
    if key != state[_S_KEY]:
        # the coefficients depend on V dt / L only: recompute when the mean wind or dt changes
        xu = key / params[_TURB_L]
        em1 = np.expm1(-xu)
        state[_S_COEF_U] = 1.0 + em1
        state[_S_COEF_U + 1] = np.sqrt(-em1 * (2.0 + em1))   # sqrt(1 - exp(-2x))
        _two_pole_coefficients(state, _S_COEF_V, key / params[_TURB_L + 1])
        _two_pole_coefficients(state, _S_COEF_W, key / params[_TURB_L + 2])
        state[_S_KEY] = key
    state[_S_U] = state[_S_COEF_U] * state[_S_U] + state[_S_COEF_U + 1] * n_u
    _two_pole_advance(state, _S_V, _S_COEF_V, n_v1, n_v2)
    _two_pole_advance(state, _S_W, _S_COEF_W, n_w1, n_w2)


@njit(cache=True)
def _wind_series(params, state, t0, dt, n, p_W, rng, out):
    v = np.empty(3)
    for k in range(n):
        wind_step(params, state, t0 + k * dt, dt, p_W, rng, v)
        out[k, 0] = v[0]
        out[k, 1] = v[1]
        out[k, 2] = v[2]


def wind_series(config: WindConfig | np.ndarray, n_steps: int, dt_s: float,
                rng: np.random.Generator, t0_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Wind at a fixed point over ``n_steps`` ticks, for plots, tests and scenario previews.

    Parameters
    ----------
    config : WindConfig or numpy.ndarray
        A configuration or its kernel array.
    n_steps : int
        Number of ticks.
    dt_s : float
        Tick (s), > 0.
    rng : numpy.random.Generator
        Source of the turbulence draws.
    t0_s : float
        Time of the first tick (s).

    Returns
    -------
    t_s : numpy.ndarray, shape (n_steps,)
    v_wind_W : numpy.ndarray, shape (n_steps, 3)
        NED, m/s.
    """
    if not dt_s > 0.0:
        raise ValueError(f"dt_s = {dt_s!r}: must be > 0")
    params = config.to_kernel() if isinstance(config, WindConfig) else np.asarray(config, float)
    out = np.empty((int(n_steps), 3))
    _wind_series(params, wind_initial_state(params), float(t0_s), float(dt_s), int(n_steps),
                 np.zeros(3), rng, out)
    return t0_s + dt_s * np.arange(int(n_steps)), out
