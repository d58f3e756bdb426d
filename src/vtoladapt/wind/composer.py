"""The composed wind: fan array + constant wind + gusts + Dryden turbulence, one wind model.

:class:`WindConfig` (a scenario's ``[wind]`` table) holds the parts' settings;
:meth:`WindConfig.to_kernel` packs them into one parameter array, :data:`WIND_PARAMS`, whose
blocks are the parts' own layouts; :func:`wind_initial_state` and :func:`wind_step` are the
compiled model the closed loop calls (the interface is in :mod:`vtoladapt.wind`).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np
from numba import njit

from ..config import ConfigError, Validated, build, setting
from ..layout import BlockLayout, Field
from . import dryden, fan_array, gusts
from .dryden import TURBULENCE_PARAMS, TURBULENCE_STATE, TurbulenceConfig, pack_turbulence
from .fan_array import FAN_PARAMS, FanArrayConfig, bearing_unit, pack_fan_array
from .gusts import GUSTS_PARAMS, MAX_GUSTS, GustConfig, pack_gusts

WIND_PARAMS = BlockLayout("wind parameters", [
    Field("FAN", FAN_PARAMS.size, "-", "the fan array (vtoladapt.wind.fan_array.FAN_PARAMS)"),
    Field("CONST", 3, "m/s", "constant wind, NED"),
    Field("TURBULENCE", TURBULENCE_PARAMS.size, "-", "Dryden (vtoladapt.wind.dryden.TURBULENCE_PARAMS)"),
    Field("GUSTS", GUSTS_PARAMS.size, "-", "the gusts (vtoladapt.wind.gusts.GUSTS_PARAMS)"),
])
"""The wind's parameter array: one block per part."""
_FAN, _CONST, _TURB, _GUSTS = WIND_PARAMS.offsets("FAN", "CONST", "TURBULENCE", "GUSTS")
WIND_KERNEL_SIZE = WIND_PARAMS.size

WIND_STATE = BlockLayout("wind state", [
    Field("TURBULENCE", TURBULENCE_STATE.size, "-", "Dryden filters (vtoladapt.wind.dryden.TURBULENCE_STATE)"),
])
"""The wind's state array (only the turbulence has state)."""
(_S_TURB,) = WIND_STATE.offsets("TURBULENCE")
WIND_STATE_SIZE = WIND_STATE.size

WIND_DRAWS_PER_STEP = dryden.TURBULENCE_DRAWS_PER_STEP
"""Standard normals every :func:`wind_step` call draws."""
WIND_DRAWS_FIRST_STEP = dryden.TURBULENCE_DRAWS_FIRST_STEP + dryden.TURBULENCE_DRAWS_PER_STEP
"""Standard normals the first :func:`wind_step` call draws."""


@dataclass(frozen=True)
class WindConfig(Validated):
    """All the wind of a scenario; the parts add up. Load with :meth:`from_mapping`."""

    config_section = "wind"

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
        if len(raw_gusts) > MAX_GUSTS:  # before building them: a million entries is not read
            raise ConfigError(f"{source}: [wind] gusts: {len(raw_gusts)} entries; at most "
                              f"{MAX_GUSTS} are allowed")
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
        d = -bearing_unit(fan.array_bearing_deg) * (fan.max_speed_mps if on else 0.0)
        h = d + np.array(self.constant_mps[:2], dtype=float)
        n = float(np.hypot(h[0], h[1]))
        if n < 1e-9:
            return -bearing_unit(fan.array_bearing_deg)
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
        """The configuration as the float64 array the wind kernels take (layout :data:`WIND_PARAMS`).

        Raises
        ------
        ConfigError
            If the configuration was built without validation and does not fit the kernel (an
            invalid schedule, too many breakpoints or gusts).
        """
        self.fan_array._check("WindConfig.to_kernel")
        self._check("WindConfig.to_kernel")
        return WIND_PARAMS.pack(
            FAN=pack_fan_array(self.fan_array), CONST=self.constant_mps,
            TURBULENCE=pack_turbulence(self.turbulence, self.turbulence_axis_NE()),
            GUSTS=pack_gusts(self.gusts))



# --- kernels ------------------------------------------------------------------------------------

@njit(cache=True)
def fan_throttle_pct(params: np.ndarray, t: float) -> float:
    """Commanded fan-array throttle (%) at time ``t`` (s): the schedule, without the spin-up lag."""
    return fan_array.throttle_pct(params, _FAN, t)


@njit(cache=True)
def fan_mean_wind_speed(params: np.ndarray, t: float) -> float:
    """Mean fan-array wind speed (m/s) at time ``t`` (s): linear in the throttle after the lag.

    ``V = max_speed_mps * y / 100`` where ``y`` is the throttle passed through the first-order
    spin-up lag (solved in closed form over the piecewise-linear schedule, starting settled).
    """
    return fan_array.mean_speed_mps(params, _FAN, t)


@njit(cache=True, inline="always")
def _mean_wind(params: np.ndarray, t: float) -> tuple:
    v_fan = fan_array.mean_speed_mps(params, _FAN, t)
    dN, dE = fan_array.direction_NE(params, _FAN)
    return v_fan * dN + params[_CONST], v_fan * dE + params[_CONST + 1], params[_CONST + 2]


@njit(cache=True)
def mean_wind_W(params: np.ndarray, t: float, out_v_W: np.ndarray) -> None:
    """Mean wind (fan array plus constant wind, NED, m/s) at ``t``: no gusts, no turbulence."""
    out_v_W[0], out_v_W[1], out_v_W[2] = _mean_wind(params, t)


@njit(cache=True)
def gust_wind_W(params: np.ndarray, t: float, out_v_W: np.ndarray) -> None:
    """Sum of the discrete gusts (NED, m/s) at time ``t``."""
    out_v_W[0] = 0.0
    out_v_W[1] = 0.0
    out_v_W[2] = 0.0
    gusts.add_gusts(params, _GUSTS, t, out_v_W)


@njit(cache=True)
def wind_initial_state(params: np.ndarray) -> np.ndarray:
    """A fresh wind state (turbulence filters; drawn from their stationary law on the first step)."""
    state = np.zeros(WIND_STATE_SIZE)
    dryden.turbulence_initial_state(state, _S_TURB)
    return state


@njit(cache=True, _nrt=False)
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
        Vehicle position, NED (m). The parts here are uniform in space and do not use it; it is
        part of the interface so a spatially varying field can be added without changing callers.
    rng : numpy.random.Generator
        Exactly ``WIND_DRAWS_PER_STEP`` standard normals per call (``WIND_DRAWS_FIRST_STEP`` on
        the first), whatever the configuration.
    out_v_wind_W : numpy.ndarray, shape (3,)
        Receives the wind velocity, NED (m/s): mean (fan + constant) + gusts + turbulence.
    """
    m0, m1, m2 = _mean_wind(params, t)
    out_v_wind_W[0] = m0
    out_v_wind_W[1] = m1
    out_v_wind_W[2] = m2
    gusts.add_gusts(params, _GUSTS, t, out_v_wind_W)
    dryden.turbulence_step(params, _TURB, state, _S_TURB, m0, m1, m2, dt, rng, out_v_wind_W)


@njit(cache=True)
def _run_wind_model(step, params, state, t0, dt, n, p_W, rng, out):
    v = np.empty(3)
    for k in range(n):
        step(params, state, t0 + k * dt, dt, p_W, rng, v)
        out[k, 0] = v[0]
        out[k, 1] = v[1]
        out[k, 2] = v[2]


def run_wind_model(step: Callable, params: np.ndarray, state: np.ndarray, n_steps: int, dt_s: float,
                   rng: np.random.Generator, t0_s: float = 0.0, p_W=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Drive any wind model (the interface of :mod:`vtoladapt.wind`) at a fixed point.

    Parameters
    ----------
    step : compiled function
        ``step(params, state, t, dt, p_W, rng, out_v_wind_W)``, e.g. :func:`wind_step`.
    params, state : numpy.ndarray
        The model's parameter array and its state (advanced in place).
    n_steps : int
        Number of ticks.
    dt_s : float
        Tick (s), > 0.
    rng : numpy.random.Generator
        Source of the model's draws.
    t0_s : float
        Time of the first tick (s).
    p_W : sequence of 3 float
        The fixed point, NED (m).

    Returns
    -------
    numpy.ndarray, shape (n_steps, 3)
        Wind velocity at each tick, NED (m/s).
    """
    if not dt_s > 0.0:
        raise ValueError(f"dt_s = {dt_s!r}: must be > 0")
    out = np.empty((int(n_steps), 3))
    _run_wind_model(step, np.asarray(params, dtype=float), state, float(t0_s), float(dt_s), int(n_steps),
                    np.asarray(p_W, dtype=float), rng, out)
    return out


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
    out = run_wind_model(wind_step, params, wind_initial_state(params), n_steps, dt_s, rng, t0_s)
    return t0_s + dt_s * np.arange(int(n_steps)), out
