"""A scenario's sensor suite: the channels of ``[sensors]``, laid out for the compiled loop.

:class:`SensorsConfig` (a scenario's ``[sensors]`` table) holds the package's channels' settings
(``[sensors.imu]``, ``.mocap``, ``.attitude``, ``.probe``), those of channels registered from
outside (their own tables) and ``channels``, the suite that runs; :meth:`SensorsConfig.assemble`
lays the suite out (a :class:`vtoladapt.parts.Assembly`) and :func:`sensors_at` is its compiled
step: every channel writes its fields of the measurement.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Optional

import numpy as np
from numba import njit

from .. import layout
from ..components import component_tables
from ..config import ConfigError, Validated, build, setting
from ..parts import T_D0, T_D1, T_P0, T_P1, T_S0, T_S1, Assembly, draw
from .airflow_probe import ProbeConfig
from .attitude import AttitudeConfig
from .imu import ImuConfig
from .mocap import MocapConfig
from .registry import BUILTIN_SENSOR_CHANNELS, SENSOR_CHANNELS, SENSOR_KIND, load_sensor_step


@dataclass(frozen=True)
class SensorContext:
    """What a channel's ``pack`` may need beyond its settings.

    ``air_density_true_kgpm3`` makes the pressures a pressure probe sees;
    ``air_density_assumed_kgpm3`` is the flight computer's (turns them back into a speed);
    ``base_dir`` resolves a relative file named in the settings (the scenario's folder).
    """

    air_density_true_kgpm3: float = 1.225
    air_density_assumed_kgpm3: float = 1.225
    base_dir: Optional[Path] = None


@dataclass(frozen=True)
class SensorsConfig(Validated):
    """All the sensors of a scenario (``[sensors]``).

    ``channels`` is the suite that runs, in order; ``parts`` holds the settings of channels
    registered from outside the package (``("id", settings)`` pairs), each from its
    ``[sensors.<id>]`` table (a listed channel without a table runs with its defaults).
    """

    config_section = "sensors"

    imu: ImuConfig = setting("-", "IMU", default=ImuConfig())
    mocap: MocapConfig = setting("-", "motion capture", default=MocapConfig())
    attitude: AttitudeConfig = setting("-", "attitude estimate", default=AttitudeConfig())
    probe: ProbeConfig = setting("-", "airflow probe", default=ProbeConfig())
    channels: tuple[str, ...] = setting(
        "-", "the channels that make the measurement, in the order they run (and draw); together they "
        "write each of its fields once", default=BUILTIN_SENSOR_CHANNELS)
    parts: Any = setting("-", "channels registered from outside the package, each from its [sensors.<id>] table: "
                         "(id, settings) pairs", default=())

    def _check(self, source: str) -> None:
        registered = list(SENSOR_CHANNELS)
        for c in self.channels:
            if c not in registered:
                raise ConfigError(f"{source}: [sensors] channels: {c!r}: not a registered sensor channel; "
                                  f"registered: {', '.join(registered)}")
        if len(set(self.channels)) != len(self.channels):
            raise ConfigError(f"{source}: [sensors] channels = {list(self.channels)}: a channel is listed twice")
        if not isinstance(self.parts, tuple):
            raise ConfigError(f"{source}: [sensors] parts = {self.parts!r}: must be a tuple of (id, settings) pairs")
        for entry in self.parts:
            if not (isinstance(entry, tuple) and len(entry) == 2 and isinstance(entry[0], str)):
                raise ConfigError(f"{source}: [sensors] parts: {entry!r}: must be an (id, settings) pair")
            part_id, settings = entry
            if part_id in BUILTIN_SENSOR_CHANNELS or part_id not in registered:
                raise ConfigError(f"{source}: [sensors.{part_id}]: not a sensor channel registered from outside "
                                  "the package")
            if part_id not in self.channels:
                raise ConfigError(f"{source}: [sensors.{part_id}]: the channel is not in [sensors] channels = "
                                  f"{list(self.channels)}; list it there to fly it")
            cls = SENSOR_CHANNELS.module(part_id).Settings
            if not isinstance(settings, cls):
                raise ConfigError(f"{source}: [sensors.{part_id}] = {settings!r}: must be a {cls.__name__}")
        written: dict[str, str] = {}
        for c in self.channels:
            for name in SENSOR_CHANNELS.module(c).WRITES:
                if name not in layout.MEASUREMENT:
                    raise ConfigError(f"{source}: [sensors] channel {c!r} writes {name!r}, not a field of the "
                                      f"measurement ({', '.join(f.name for f in layout.MEASUREMENT.fields)})")
                if name in written:
                    raise ConfigError(f"{source}: [sensors] channels {written[name]!r} and {c!r} both write the "
                                      f"measurement's {name}; keep one of them in [sensors] channels")
                written[name] = c
        missing = [f.name for f in layout.MEASUREMENT.fields if f.name not in written]
        if missing:
            raise ConfigError(f"{source}: [sensors] channels = {list(self.channels)}: nothing writes the "
                              f"measurement's {', '.join(missing)}")

    @classmethod
    def component_tables(cls, data: Mapping[str, Any], *, source: str, section: str) -> tuple[dict, dict]:
        """Take the tables of channels registered from outside (``[sensors.<id>]``) out of ``data`` and
        build them (:func:`vtoladapt.config.build`'s hook; :func:`vtoladapt.components.component_tables`)."""
        listed = data.get("channels", BUILTIN_SENSOR_CHANNELS)
        rest, parts = component_tables(
            data, SENSOR_CHANNELS, lambda key: SENSOR_CHANNELS.module(key).Settings,
            own={f.name for f in dataclasses.fields(cls)}, source=source, section=section, refused="parts",
            refusal=lambda _: (f"{source}: [{section}] parts: not a key; a registered channel's settings go in its "
                               f"own table, [{section}.<id>]"),
            listed=[k for k in listed if k not in BUILTIN_SENSOR_CHANNELS] if isinstance(listed, (list, tuple)) else ())
        return rest, {"parts": parts}

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

    def settings_of(self, channel: str) -> Any:
        """The settings of ``channel`` in this configuration."""
        info = SENSOR_CHANNELS[channel]
        if info.field is not None:
            return getattr(self, info.field)
        return dict(self.parts)[channel]

    def assemble(self, context: SensorContext = SensorContext()) -> Assembly:
        """The suite laid out for the compiled loop (:class:`vtoladapt.parts.Assembly`)."""
        modules = [SENSOR_CHANNELS.module(c) for c in self.channels]
        blocks = [m.pack(self.settings_of(c), context) for c, m in zip(self.channels, modules)]
        return Assembly(SENSOR_KIND, modules, blocks, self.channels)

    def to_kernel(self, air_density_true_kgpm3: float = 1.225, air_density_assumed_kgpm3: float = 1.225,
                  base_dir: Optional[Path] = None) -> np.ndarray:
        """The suite's parameter array (its channels' blocks in order; see :meth:`assemble`)."""
        return self.assemble(SensorContext(air_density_true_kgpm3, air_density_assumed_kgpm3, base_dir)).params


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def sensors_at(table, params, state, t, dt, x_true, truth, draws, meas) -> None:
    """One tick's measurement (``meas``, :data:`vtoladapt.layout.MEASUREMENT`) from every channel of
    ``table``, each writing its fields from the truth (``x_true``, ``truth``) with its ``draws``."""
    for j in range(table.shape[0]):
        step = load_sensor_step(table, j)
        step(params[table[j, T_P0]:table[j, T_P1]], state[table[j, T_S0]:table[j, T_S1]], t, dt, x_true, truth,
             draws[table[j, T_D0]:table[j, T_D1]], meas)


@njit(cache=True)
def _run_sensor_model(table, params, state, t0, dt, X, T, rng, draws, out):
    for k in range(X.shape[0]):
        row = out[k]
        row[:] = np.nan  # a slot no channel writes stays NaN
        draw(rng, table, draws)
        sensors_at(table, params, state, t0 + k * dt, dt, X[k], T[k], draws, row)


def run_sensor_model(assembly: Assembly, state: np.ndarray, dt_s: float, x_true: np.ndarray,
                     specific_force_B: np.ndarray, v_i_B_true: np.ndarray, rng: np.random.Generator,
                     t0_s: float = 0.0, params: Optional[np.ndarray] = None) -> np.ndarray:
    """Drive any sensor channels (an :class:`~vtoladapt.parts.Assembly`, yours or the package's) over a
    recorded truth, drawing as the closed loop draws.

    Parameters
    ----------
    assembly : vtoladapt.parts.Assembly
        From :meth:`SensorsConfig.assemble`, or one made of any channels.
    state : numpy.ndarray
        The channels' state (:meth:`~vtoladapt.parts.Assembly.initial_state`), advanced in place.
    dt_s : float
        Control tick (s), > 0.
    x_true : numpy.ndarray, shape (T, layout.X_SIZE)
        True plant state at each tick.
    specific_force_B, v_i_B_true : numpy.ndarray, shape (T, 3)
        True specific force (m/s^2) and incident velocity (m/s), body axes.
    rng : numpy.random.Generator
        Source of the channels' draws.
    t0_s : float
        Time of the first tick (s).
    params : numpy.ndarray, optional
        The channels' parameters; default ``assembly.params``.

    Returns
    -------
    numpy.ndarray, shape (T, layout.MEAS_SIZE)
        The measurements; a slot no channel wrote is NaN.
    """
    if not dt_s > 0.0:
        raise ValueError(f"dt_s = {dt_s!r}: must be > 0")
    X = np.ascontiguousarray(x_true, dtype=float)
    F = np.ascontiguousarray(specific_force_B, dtype=float)
    VI = np.ascontiguousarray(v_i_B_true, dtype=float)
    if X.ndim != 2 or X.shape[1] != layout.X_SIZE or F.shape != (X.shape[0], 3) or VI.shape != F.shape:
        raise ValueError(f"x_true {X.shape}, specific_force_B {F.shape}, v_i_B_true {VI.shape}: expected "
                         f"(T, {layout.X_SIZE}), (T, 3), (T, 3)")
    truth = np.zeros((X.shape[0], layout.TRUTH_SIZE))
    layout.TRUTH.view(truth, "F_B")[:] = F
    layout.TRUTH.view(truth, "V_I_B")[:] = VI
    params = assembly.params if params is None else np.ascontiguousarray(params, dtype=float)
    for part_id, module in zip(assembly.ids, assembly.modules):
        if hasattr(module, "check_dt"):  # a limit that depends on the tick (the mocap's latency ring)
            module.check_dt(assembly.block(params, part_id), float(dt_s))
    out = np.empty((X.shape[0], layout.MEAS_SIZE))
    _run_sensor_model(assembly.table, params, state, float(t0_s), float(dt_s), X, truth, rng,
                      np.zeros(assembly.draws_size), out)
    return out
