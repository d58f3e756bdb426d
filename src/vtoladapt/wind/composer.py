"""The composed wind: the package's parts (fan array, constant wind, gusts, Dryden turbulence) and any
registered from outside, one wind.

:class:`WindConfig` (a scenario's ``[wind]`` table) holds the parts' settings;
:meth:`WindConfig.assemble` lays out the run's parts (a :class:`vtoladapt.parts.Assembly`: their
parameter blocks one after another, the package's first in :data:`WIND_PARAMS`'s order, and the
table the compiled loop calls them through); :func:`wind_at` is the compiled wind of one tick.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from numba import njit

from ..components import component_tables
from ..config import ConfigError, Validated, build, setting
from ..layout import W_V_W, WIND_SIZE, BlockLayout, Field
from ..parts import T_D0, T_D1, T_P0, T_P1, T_S0, T_S1, Assembly, draw
from . import dryden, fan_array, gusts
from .constant import PARAMS as CONSTANT_PARAMS
from .dryden import TURBULENCE_PARAMS, TurbulenceConfig
from .fan_array import FAN_PARAMS, FanArrayConfig, bearing_unit
from .gusts import GUSTS_PARAMS, MAX_GUSTS, GustConfig
from .registry import BUILTIN_WIND_PARTS, WIND_KIND, WIND_PARTS, load_wind_step

WIND_PARAMS = BlockLayout("wind parameters (the package's parts, which lead every run's wind parameters)", [
    Field("FAN_ARRAY", FAN_PARAMS.size, "-", "the fan array (vtoladapt.wind.fan_array.FAN_PARAMS)"),
    Field("CONSTANT", CONSTANT_PARAMS.size, "m/s", "constant wind, NED (vtoladapt.wind.constant.PARAMS)"),
    Field("GUSTS", GUSTS_PARAMS.size, "-", "the gusts (vtoladapt.wind.gusts.GUSTS_PARAMS)"),
    Field("TURBULENCE", TURBULENCE_PARAMS.size, "-", "Dryden (vtoladapt.wind.dryden.TURBULENCE_PARAMS)"),
])
"""The package's parts' blocks, in the order they are called; a part registered from outside
follows them."""
_FAN, _GUSTS = WIND_PARAMS.offsets("FAN_ARRAY", "GUSTS")
WIND_KERNEL_SIZE = WIND_PARAMS.size

WIND_DRAWS_PER_STEP = dryden.TURBULENCE_DRAWS_PER_STEP
"""Standard normals the package's parts consume per step (all of them the turbulence's)."""
WIND_DRAWS_INITIAL = dryden.TURBULENCE_DRAWS_INITIAL
"""Standard normals the package's parts draw for their initial state (the turbulence's)."""


@dataclass(frozen=True)
class WindConfig(Validated):
    """All the wind of a scenario; the parts add up. Load with :meth:`from_mapping`.

    ``parts`` holds the settings of parts registered from outside the package (``("id", settings)``
    pairs, in registration order), each from its ``[wind.<id>]`` table.
    """

    config_section = "wind"

    constant_mps: tuple[float, ...] = setting("m/s", "constant wind vector, NED",
                                              default=(0.0, 0.0, 0.0), ge=-60.0, le=60.0, length=3)
    fan_array: FanArrayConfig = setting("-", "fan-array wind", default=FanArrayConfig())
    turbulence: TurbulenceConfig = setting("-", "Dryden turbulence", default=TurbulenceConfig())
    gusts: tuple[GustConfig, ...] = setting("-", "discrete gusts ([[wind.gusts]] entries)",
                                            default=(), max_items=MAX_GUSTS)  # counted before they are built
    parts: Any = setting("-", "wind parts registered from outside the package, each from its [wind.<id>] table: "
                         "(id, settings) pairs", default=())

    def _check(self, source: str) -> None:
        if len(self.gusts) > MAX_GUSTS:
            raise ConfigError(f"{source}: [wind] gusts: {len(self.gusts)} entries; at most "
                              f"{MAX_GUSTS} are allowed")
        if not isinstance(self.parts, tuple):
            raise ConfigError(f"{source}: [wind] parts = {self.parts!r}: must be a tuple of (id, settings) pairs")
        seen = set()
        for entry in self.parts:
            if not (isinstance(entry, tuple) and len(entry) == 2 and isinstance(entry[0], str)):
                raise ConfigError(f"{source}: [wind] parts: {entry!r}: must be an (id, settings) pair")
            part_id, settings = entry
            _check_user_part(part_id, source)
            cls = WIND_PARTS.module(part_id).Settings
            if not isinstance(settings, cls):
                raise ConfigError(f"{source}: [wind.{part_id}] = {settings!r}: must be a {cls.__name__}")
            if part_id in seen:
                raise ConfigError(f"{source}: [wind.{part_id}] given twice")
            seen.add(part_id)

    @classmethod
    def component_tables(cls, data: Mapping[str, Any], *, source: str, section: str) -> tuple[dict, dict]:
        """Take the tables of parts registered from outside (``[wind.<id>]``) out of ``data`` and build
        them (:func:`vtoladapt.config.build`'s hook): ``(the rest, {"parts": ((id, settings), ...)})``
        (:func:`vtoladapt.components.component_tables`; the built-in parts are this table's own keys)."""
        rest, parts = component_tables(
            data, WIND_PARTS, lambda key: WIND_PARTS.module(key).Settings,
            own={f.name for f in dataclasses.fields(cls)}, skip=BUILTIN_WIND_PARTS, no_table="wind part",
            source=source, section=section, refused="parts",
            refusal=lambda _: (f"{source}: [{section}] parts: not a key; a registered wind part's settings go in "
                               f"its own table, [{section}.<id>]"))
        return rest, {"parts": parts}

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], *, source: str = "<config>",
                     section: str = "wind") -> "WindConfig":
        """Build from a scenario's ``[wind]`` table (with ``[wind.fan_array]``,
        ``[wind.turbulence]``, ``[[wind.gusts]]`` and a table per part registered from outside).

        Raises
        ------
        ConfigError
            Naming the file, the table (``wind.gusts[2]`` for the third gust) and the key.
        """
        return build(cls, data, source=source, section=section)

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
        multiplied by ``scale``; speeds and the turbulence are unchanged (and so are the parts
        registered from outside, which the package cannot know how to stretch).
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

    def settings_of(self, part_id: str) -> Any:
        """The settings of part ``part_id`` in this configuration (``None`` for a part it does not use)."""
        info = WIND_PARTS[part_id]
        if info.field is not None:
            return getattr(self, info.field)
        return dict(self.parts).get(part_id)

    def part_ids(self) -> tuple[str, ...]:
        """The parts a run of this wind calls, in order: the package's, then the configured others."""
        used = dict(self.parts)
        return tuple(i for i in WIND_PARTS if i in BUILTIN_WIND_PARTS or i in used)

    def assemble(self) -> Assembly:
        """The run's wind parts: parameter blocks, part table (:class:`vtoladapt.parts.Assembly`).

        Raises
        ------
        ConfigError
            If the configuration was built without validation and does not fit the kernel (an
            invalid schedule, too many breakpoints or gusts).
        """
        self.fan_array._check("WindConfig")
        self._check("WindConfig")
        ids = self.part_ids()
        modules = [WIND_PARTS.module(i) for i in ids]
        blocks = [m.pack(self.settings_of(i), self) for i, m in zip(ids, modules)]
        assembly = Assembly(WIND_KIND, modules, blocks, ids)
        lead = assembly.params_layout.fields[:len(WIND_PARAMS.fields)]
        if [(f.name, f.size) for f in lead] != [(f.name, f.size) for f in WIND_PARAMS.fields]:
            raise RuntimeError(f"wind parts {ids}: the package's parts must come first, as WIND_PARAMS declares")
        return assembly

    def to_kernel(self) -> np.ndarray:
        """The run's wind parameter array (the package's parts first, laid out as :data:`WIND_PARAMS`)."""
        return self.assemble().params


def _check_user_part(part_id: str, source: str) -> None:
    """A ``ConfigError`` unless ``part_id`` is a wind part registered from outside the package."""
    try:
        info = WIND_PARTS[part_id]
    except KeyError:
        raise ConfigError(f"{source}: [wind.{part_id}]: not a registered wind part; registered: "
                          f"{', '.join(WIND_PARTS)}") from None
    if info.field is not None:
        raise ConfigError(f"{source}: [wind] parts: {part_id!r} is the package's own; set it in [wind] itself")


# --- kernels ------------------------------------------------------------------------------------

@njit(cache=True, nogil=True, _nrt=False, inline="always")
def wind_at(table, params, state, t, dt, p_W, draws, wind) -> None:
    """The tick's wind (a :data:`vtoladapt.layout.WIND` array, written) from every part of ``table``.

    ``draws`` holds the parts' random numbers for this step (:func:`vtoladapt.parts.draw`); each part
    advances its ``state`` block to ``t + dt``.
    """
    for i in range(WIND_SIZE):
        wind[i] = 0.0
    for j in range(table.shape[0]):
        step = load_wind_step(table, j)
        step(params[table[j, T_P0]:table[j, T_P1]], state[table[j, T_S0]:table[j, T_S1]], t, dt, p_W,
             draws[table[j, T_D0]:table[j, T_D1]], wind)


@njit(cache=True)
def fan_throttle_pct(params: np.ndarray, t: float) -> float:
    """Commanded fan-array throttle (%) at time ``t`` (s): the schedule, without the spin-up lag.
    ``params``: a wind parameter array (:meth:`WindConfig.to_kernel`)."""
    return fan_array.throttle_pct(params, _FAN, t)


@njit(cache=True)
def fan_mean_wind_speed(params: np.ndarray, t: float) -> float:
    """Mean fan-array wind speed (m/s) at time ``t`` (s): linear in the throttle after the lag.

    ``V = max_speed_mps * y / 100`` where ``y`` is the throttle passed through the first-order
    spin-up lag (solved in closed form over the piecewise-linear schedule, starting settled).
    ``params``: a wind parameter array (:meth:`WindConfig.to_kernel`).
    """
    return fan_array.mean_speed_mps(params, _FAN, t)


@njit(cache=True)
def gust_wind_W(params: np.ndarray, t: float, out_v_W: np.ndarray) -> None:
    """Sum of the discrete gusts (NED, m/s) at time ``t``."""
    out_v_W[0] = 0.0
    out_v_W[1] = 0.0
    out_v_W[2] = 0.0
    gusts.add_gusts(params, _GUSTS, t, out_v_W)


@njit(cache=True)
def _run_wind_model(table, params, state, t0, dt, n, p_W, rng, draws, wind, out):
    for k in range(n):
        draw(rng, table, draws)
        wind_at(table, params, state, t0 + k * dt, dt, p_W, draws, wind)
        for j in range(3):
            out[k, j] = wind[W_V_W + j]


def run_wind_model(assembly: Assembly, state: np.ndarray, n_steps: int, dt_s: float, rng: np.random.Generator,
                   t0_s: float = 0.0, p_W=(0.0, 0.0, 0.0), params=None) -> np.ndarray:
    """Drive any wind parts (an :class:`~vtoladapt.parts.Assembly`, yours or the package's) at a fixed point.

    Parameters
    ----------
    assembly : vtoladapt.parts.Assembly
        From :meth:`WindConfig.assemble`, or one made of any wind parts.
    state : numpy.ndarray
        The parts' state (:meth:`~vtoladapt.parts.Assembly.initial_state`), advanced in place.
    n_steps : int
        Number of ticks.
    dt_s : float
        Tick (s), > 0.
    rng : numpy.random.Generator
        Source of the parts' draws, drawn as the closed loop draws them.
    t0_s : float
        Time of the first tick (s).
    p_W : sequence of 3 float
        The fixed point, NED (m).
    params : numpy.ndarray, optional
        The parts' parameters; default ``assembly.params``.

    Returns
    -------
    numpy.ndarray, shape (n_steps, 3)
        Wind velocity at each tick, NED (m/s).
    """
    if not dt_s > 0.0:
        raise ValueError(f"dt_s = {dt_s!r}: must be > 0")
    params = assembly.params if params is None else np.ascontiguousarray(params, dtype=float)
    out = np.empty((int(n_steps), 3))
    _run_wind_model(assembly.table, params, state, float(t0_s), float(dt_s), int(n_steps),
                    np.asarray(p_W, dtype=float), rng, np.zeros(assembly.draws_size), np.zeros(WIND_SIZE), out)
    return out


def wind_series(config: WindConfig, n_steps: int, dt_s: float, rng: np.random.Generator,
                t0_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Wind at a fixed point over ``n_steps`` ticks, for plots, tests and scenario previews.

    Parameters
    ----------
    config : WindConfig
    n_steps : int
        Number of ticks.
    dt_s : float
        Tick (s), > 0.
    rng : numpy.random.Generator
        Source of the initial turbulence and its draws, in the closed loop's order.
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
    assembly = config.assemble()
    out = run_wind_model(assembly, assembly.initial_state(rng), n_steps, dt_s, rng, t0_s)
    return t0_s + dt_s * np.arange(int(n_steps)), out
