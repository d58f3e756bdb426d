"""Scenario files: everything one simulation run needs, validated before anything runs.

A scenario (TOML) names the vehicle, the plant's own truth and effects, the wind (fan-array
schedule, turbulence, gusts), the sensors, the controller and its settings, the reference, the
duration and the seed. :func:`load_scenario` validates the whole file (unknown keys, ranges,
unknown controller names, throttle schedules outside [0, 100] %) and raises
:class:`~vtoladapt.config.ConfigError` naming the file, the key and the value before any output
is written. See README "Writing a scenario".
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from ..config import (NAME_PATTERN, PATH_PATTERN, ApplicableKeys, ConfigError, Validated, build, read_toml,
                      refuse_internal_keys, setting)
from ..control.settings import (SCENARIO_DT_DEFAULT_S, SCENARIO_DT_RANGE_S, ControllerConfig,
                                check_rate_matches_dt, rate_from_dt)
from ..control.registry import controller_ids, theta_adaptive_ids
from ..file_kinds import check_file_kind
from .faults import MAX_FAULTS, FaultConfig
from .monitor import EnvelopeConfig
from .output import OutputConfig
from .plant import PlantConfig
from ..sensors import SensorsConfig
from ..vehicle import Vehicle, load_vehicle
from ..wind import WindConfig

SCENARIO_DIR = Path(__file__).resolve().parent.parent / "scenarios"
MAX_WAYPOINTS = 100_000
"""Most rows of ``[reference] waypoints``: one every 36 ms over the longest run (3600 s); checked before
the rows are, so a file of millions of them is refused at once."""


@dataclass(frozen=True)
class InitialCondition(Validated):
    """Where the run starts; motors start at the plant's hover trim unless ``trimmed_motors`` is false."""

    config_section = "initial"

    position_m: tuple[float, ...] = setting("m", "initial position, NED", default=(0.0, 0.0, -1.5), ge=-1e4, le=1e4,
                                          length=3)
    velocity_mps: tuple[float, ...] = setting("m/s", "initial velocity, NED", default=(0.0, 0.0, 0.0),
                                              ge=-100.0, le=100.0, length=3)
    yaw_deg: float = setting("deg", "initial heading (0 = north)", default=0.0, ge=-360.0, le=360.0)
    pitch_deg: float = setting("deg", "initial pitch", default=0.0, ge=-90.0, le=90.0)
    roll_deg: float = setting("deg", "initial roll", default=0.0, ge=-180.0, le=180.0)
    trimmed_motors: bool = setting("-", "start the motors at the plant's hover trim", default=True)


@dataclass(frozen=True)
class ReferenceConfig(Validated):
    """The position reference the controller tracks."""

    config_section = "reference"

    kind: str = setting("-", "hold a point, or fly through timed waypoints", default="hold",
                        choices=("hold", "waypoints"))
    position_m: tuple[float, ...] = setting("m", "held position, NED (kind = hold)",
                                            default=(0.0, 0.0, -1.5), ge=-1e4, le=1e4, length=3)
    yaw_deg: float = setting("deg", "held heading (0 = north, facing the fan array)", default=0.0,
                             ge=-360.0, le=360.0)
    waypoints: tuple[tuple[float, ...], ...] = setting(
        "s, m", "rows [t_s, north_m, east_m, down_m] (kind = waypoints); min-jerk between rows",
        default=(), ge=-1e4, le=1e4, max_items=MAX_WAYPOINTS)

    @staticmethod
    def keys_for(data) -> "Optional[ApplicableKeys]":
        """The keys a reference of this ``kind`` uses (:func:`vtoladapt.config.build` refuses the
        others: waypoints under ``kind = 'hold'`` were read, held in memory and ignored)."""
        kind = data.get("kind", "hold")
        if kind == "hold":
            return ApplicableKeys(("kind", "position_m", "yaw_deg"), "kind = 'hold'")
        if kind == "waypoints":
            return ApplicableKeys(("kind", "waypoints", "yaw_deg"), "kind = 'waypoints'")
        return None

    def _check(self, source: str) -> None:
        if self.kind != "waypoints":
            if self.waypoints:  # made in Python: what a file's keys_for refuses
                raise ConfigError(f"{source}: [reference] waypoints: {len(self.waypoints)} rows with kind = "
                                  f"{self.kind!r}, which ignores them; allowed: waypoints with kind = 'waypoints'")
            return
        if len(self.waypoints) < 2:
            raise ConfigError(f"{source}: [reference] waypoints: kind = 'waypoints' needs at least two rows")
        last = -math.inf
        for i, row in enumerate(self.waypoints):
            if len(row) != 4:
                raise ConfigError(f"{source}: [reference] waypoints[{i}] = {list(row)}: must be "
                                  "[t_s, north_m, east_m, down_m]")
            if not row[0] > last:
                raise ConfigError(f"{source}: [reference] waypoints[{i}] = {list(row)}: times must increase")
            last = row[0]


@dataclass(frozen=True)
class ControllerPrior(Validated):
    """Where the controller's model starts: theta_0, P0, and the initial theta-hat."""

    config_section = "controller_prior"

    posterior: Optional[str] = setting(
        "-", "posterior.json from `vtoladapt fit` (path relative to the scenario); default: the "
        "vehicle's Table I", default=None, pattern=PATH_PATTERN)
    initial_theta: str = setting(
        "-", "theta-hat(0): 'theta0' (= theta_0), or 'random' (uniform within +-random_fraction of "
        "theta_0, clipped to the bounds, drawn from the scenario seed)", default="theta0",
        choices=("theta0", "random"))
    random_fraction: float = setting("-", "half-width of the random initial theta-hat, relative", default=0.3,
                                     gt=0.0, lt=1.0)


@dataclass(frozen=True)
class ExperimentConfig(Validated):
    """What ``vtoladapt run`` does with the scenario: one run, or one of the paper's experiments."""

    config_section = "experiment"

    kind: str = setting("-", "'single' run; 'convergence': repeated runs from random theta-hat(0) "
                        "(Fig. parameter_convergence); 'comparison': the same run per controller "
                        "(Figs. tracking_comparison)", default="single",
                        choices=("single", "convergence", "comparison"))
    runs: int = setting("-", "number of random-start runs (kind = convergence)", default=7, ge=2, le=1000)
    variants: int = setting(
        "-", "seeded variants the experiment is also flown over (1: the single-seed experiment only); "
        "variant i has seed i of SeedSequence([seed, 0xD157]) and so its own plant draw, turbulence "
        "and sensor noise (vtoladapt.experiments.distribution)", default=1, ge=1, le=10000)
    controllers: tuple[str, ...] = setting(
        "-", "controllers compared (kind = comparison); default (empty): every registered controller",
        default=(), choices=controller_ids)

    def __post_init__(self) -> None:
        # the default is every controller registered when the configuration is made (a law registered
        # after import included), not a list frozen at import
        if not self.controllers:
            object.__setattr__(self, "controllers", controller_ids())
        super().__post_init__()

    def _check(self, source: str) -> None:
        if len(set(self.controllers)) != len(self.controllers) or not self.controllers:
            raise ConfigError(f"{source}: [experiment] controllers = {list(self.controllers)}: "
                              "must be a non-empty list without repeats")


@dataclass(frozen=True)
class AllocationConfig(Validated):
    """How the flight computer realises the controller's lift and moment (:mod:`vtoladapt.sim.allocation`)."""

    config_section = "allocation"

    surfaces: bool = setting("-", "the allocator uses the vehicle's control surfaces (false: they stay neutral "
                             "and the lift rotors make every moment, the airframe before issue #24)", default=True)
    effectiveness: str = setting("-", "the airframe's effectiveness the allocator believes (a member of the "
                                 "'effectiveness' kind); empty: the vehicle file's effectiveness", default="")
    method: str = setting("-", "the solver: 'bounded_lsq' (weighted bounded least squares, redistributes what "
                          "one actuator cannot do) or 'px4' (PX4's sequential desaturation: the surfaces by "
                          "pseudo-inverse, the lift rotors desaturated thrust, roll, pitch first and yaw last)",
                          default="bounded_lsq", choices=("bounded_lsq", "px4"))
    airmode: int = setting("-", "PX4's MC_AIRMODE, for method = 'px4' only: 0 disabled (thrust only falls), "
                           "1 roll/pitch (thrust may rise to keep them), 2 roll/pitch/yaw", default=0, ge=0, le=2)

    def _check(self, source: str) -> None:
        from .allocation import EFFECTIVENESS  # looked up at use: a user's airframe may be registered late

        if self.effectiveness and self.effectiveness not in EFFECTIVENESS:
            raise ConfigError(f"{source}: [allocation] effectiveness = {self.effectiveness!r}: unknown; allowed: "
                              + ", ".join(repr(i) for i in EFFECTIVENESS.ids()))


@dataclass(frozen=True)
class Scenario(Validated):
    """A validated scenario (see the module docstring)."""

    name: str = setting("-", "short identifier, used in output file names", pattern=NAME_PATTERN)
    vehicle: str = setting("-", "shipped vehicle name or path to a vehicle TOML", pattern=PATH_PATTERN)
    duration_s: float = setting("s", "simulated time", gt=0.0, le=3600.0)
    seed: int = setting("-", "seed of every random draw in the run", default=0, ge=0, le=2**63 - 1)
    description: str = setting("-", "what the scenario is for", default="")
    dt_control_s: float = setting("s", "controller period (250 Hz in the paper); the controller's [controller] "
                                  "loop_rate_hz is 1/dt_control_s (set from it)", default=SCENARIO_DT_DEFAULT_S,
                                  ge=SCENARIO_DT_RANGE_S[0], le=SCENARIO_DT_RANGE_S[1])
    plant_substeps: int = setting("-", "RK4 plant steps per controller period (4 -> 1 kHz)", default=4,
                                  ge=1, le=100)
    initial: InitialCondition = setting("-", "initial condition", default=InitialCondition())
    reference: ReferenceConfig = setting("-", "position reference", default=ReferenceConfig())
    plant: PlantConfig = setting("-", "the simulated aircraft's own truth", default=PlantConfig())
    wind: WindConfig = setting("-", "wind: fan array, turbulence, gusts", default=WindConfig())
    sensors: SensorsConfig = setting("-", "sensor models", default=SensorsConfig())
    controller: ControllerConfig = setting("-", "controller and gains", default=ControllerConfig())
    controller_prior: ControllerPrior = setting("-", "controller's initial model", default=ControllerPrior())
    experiment: ExperimentConfig = setting("-", "single run or one of the paper's experiments",
                                           default=ExperimentConfig())
    envelope: EnvelopeConfig = setting("-", "where the run stops as diverged", default=EnvelopeConfig())
    allocation: AllocationConfig = setting("-", "the control allocator", default=AllocationConfig())
    faults: tuple[FaultConfig, ...] = setting("-", "injected faults ([[faults]] entries, each with start_s "
                                              "and end_s)", default=(), max_items=MAX_FAULTS)
    output: OutputConfig = setting("-", "what `vtoladapt run` keeps of the log", default=OutputConfig())
    source_path: str = setting("-", "file the scenario was read from", default="")

    def _check(self, source: str) -> None:
        if self.experiment.kind == "convergence" and self.controller.kind not in theta_adaptive_ids():
            raise ConfigError(f"{source}: [controller] kind = {self.controller.kind!r}: a convergence experiment "
                              f"judges how theta-hat converges; allowed: {', '.join(theta_adaptive_ids())} "
                              f"(the others hold theta-hat = theta_0)")
        self.check_loop_rate(source)
        self.output.check_rate(self.dt_control_s, source)
        if self.experiment.kind == "comparison":  # each compared law flies these shared settings
            for kind in self.experiment.controllers:
                self.controller.check_law(kind, source)
        self._check_delays(source)

    def _check_delays(self, source: str) -> None:
        """Delays kept in ring buffers of whole ticks must fit them at this run's ``dt_control_s``
        (checked here, naming the file, rather than by the kernel when the run has started)."""
        from .faults import LATENCY_RING_TICKS, MAX_FAULTS
        from ..sensors import MOCAP_RING_SIZE, latency_ticks

        dt = self.dt_control_s
        latency = self.sensors.mocap.latency_s
        if not self.sensors.mocap.ideal and latency_ticks(latency, dt) >= MOCAP_RING_SIZE:
            raise ConfigError(f"{source}: [sensors.mocap] latency_s = {latency:g}: {latency_ticks(latency, dt)} "
                              f"ticks at dt_control_s = {dt:g} s; allowed: at most {MOCAP_RING_SIZE - 1} ticks "
                              f"(< {(MOCAP_RING_SIZE - 0.5) * dt:.4g} s)")
        if len(self.faults) > MAX_FAULTS:
            raise ConfigError(f"{source}: [[faults]]: {len(self.faults)} entries; allowed: at most {MAX_FAULTS}")
        for i, f in enumerate(self.faults):
            if f.kind == "mocap_latency" and round(f.extra_latency_s / dt) >= LATENCY_RING_TICKS:
                raise ConfigError(f"{source}: [faults][{i}] mocap_latency: extra_latency_s = {f.extra_latency_s:g}: "
                                  f"allowed: at most {(LATENCY_RING_TICKS - 1) * dt:.4g} s "
                                  f"({LATENCY_RING_TICKS - 1} ticks) at dt_control_s = {dt:g} s")

    def check_loop_rate(self, source: str) -> None:
        """A :class:`ConfigError` unless the controller's ``loop_rate_hz`` is ``1 / dt_control_s``: the
        rate its stability checks and its nominal tick assume is the rate the run steps it at."""
        check_rate_matches_dt(self.controller.loop_rate_hz, self.dt_control_s, source)

    @property
    def n_ticks(self) -> int:
        """Number of controller ticks in the run (``duration_s / dt_control_s``, rounded)."""
        return int(round(self.duration_s / self.dt_control_s))

    def load_vehicle(self) -> Vehicle:
        """The vehicle named by the scenario: a shipped name, or a path.

        A relative path written in a scenario file was resolved against that file when it was read
        (:func:`scenario_from_mapping`), so the one held here is relative to the working directory,
        as a path given in Python (``replace(scenario, vehicle="my_plane.toml")``) or on the command
        line (``--vehicle``) is: resolving such a path against the shipped scenario's folder made
        ``examples/own_vehicle.py --out out/own_vehicle`` look for the vehicle inside the package
        (issue #37)."""
        try:
            return load_vehicle(self.vehicle)
        except ConfigError as exc:
            # an unknown name is the scenario file's mistake: say which file holds the key
            if self.source_path and str(self.source_path) not in str(exc):
                raise ConfigError(f"{self.source_path}: {exc}") from None
            raise

    @property
    def base_dir(self) -> Optional[Path]:
        """The folder of the file the scenario was read from (its relative paths start there), or None."""
        return Path(self.source_path).parent if self.source_path else None

    def posterior_path(self) -> Optional[Path]:
        """Path of the ``[controller_prior] posterior`` file (relative to the scenario), or None."""
        if self.controller_prior.posterior is None:
            return None
        path = Path(self.controller_prior.posterior)
        return self.base_dir / path if self.base_dir is not None and not path.is_absolute() else path

    def replace(self, **changes) -> "Scenario":
        """A copy with the given fields changed (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)


def scenario_from_mapping(data: dict, source: str, *, source_path: str | Path | None = None) -> Scenario:
    """Validate a parsed scenario mapping; errors name ``source``.

    ``source_path`` is the file the scenario's relative paths (``vehicle``, ``[controller_prior]
    posterior``) are resolved against; without it, the mapping's own ``source_path`` or else
    ``source``. Pass it whenever ``source`` is a description rather than a path (e.g. "c.toml
    (campaign draw 3)"), or the paths would be resolved against that text.
    """
    data = dict(data)
    if source_path is not None:
        data["source_path"] = str(source_path)
    else:
        data.setdefault("source_path", source)
    data = file_relative_vehicle(data, data["source_path"])
    rate_from_dt(data, source, dt_default=SCENARIO_DT_DEFAULT_S)
    scenario = build(Scenario, data, source=source)
    scenario.load_vehicle()  # fail now, naming the file, if the vehicle is unknown
    posterior = scenario.posterior_path()
    if posterior is not None and not posterior.exists():
        raise ConfigError(f"{source}: [controller_prior] posterior = {scenario.controller_prior.posterior!r}: "
                          f"file not found ({posterior})")
    # checked here, as the posterior is, rather than when the run is set up (where the message named
    # only the missing file, not the scenario or the key)
    path = scenario.sensors.probe.calibration_path(scenario.base_dir)
    if path is not None:
        calibration = scenario.sensors.probe.calibration_file
        if not path.is_file():
            raise ConfigError(f"{source}: [sensors.probe] calibration_file = {calibration!r}: file not found "
                              f"({path}); allowed: a 'vtoladapt probe calibrate' calibration.json")
    return scenario


def file_relative_vehicle(data: dict, source_path) -> dict:
    """``data`` with a relative vehicle path (``vehicle = "my_plane.toml"``) made relative to the
    folder of ``source_path``, the file it was written in; a shipped name or an absolute path is
    left as it is. After this the scenario's ``vehicle`` is a path from the working directory."""
    vehicle = data.get("vehicle")
    if isinstance(vehicle, str) and source_path:
        path = Path(vehicle)
        if path.suffix == ".toml" and not path.is_absolute():
            return {**data, "vehicle": str(Path(str(source_path)).parent / path)}
    return data


def shipped_scenario_names() -> list[str]:
    """The names :func:`load_scenario` accepts for the shipped scenarios (``faults/...`` included;
    the shipped campaign files, which hold a ``[campaign]`` table, and the tuned settings files of
    ``tuned/``, which hold a ``[tuning]`` table, are not scenarios)."""
    return sorted(p.relative_to(SCENARIO_DIR).with_suffix("").as_posix() for p in SCENARIO_DIR.rglob("*.toml")
                  if not {"campaign", "tuning"} & set(read_toml(p)))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a scenario by path, or by the name of one shipped in ``vtoladapt/scenarios``."""
    path = Path(name_or_path)
    if not path.exists():
        shipped = SCENARIO_DIR / f"{name_or_path}.toml"
        if shipped.exists():
            path = shipped
        else:
            raise ConfigError(f"scenario {str(name_or_path)!r}: file not found; shipped scenarios: "
                              f"{', '.join(shipped_scenario_names())}")
    data = read_toml(path)
    if "campaign" in data:
        raise ConfigError(f"{path}: a campaign file ([campaign] table), not a scenario; "
                          f"run it with: vtoladapt campaign {path} --out DIR")
    if "tuning" in data:
        raise ConfigError(f"{path}: a tuned settings file ([tuning] table), not a scenario; "
                          f"fly it with: vtoladapt run SCENARIO --tuned {path} --out DIR")
    check_file_kind(path, data, "scenario", "`vtoladapt run` (and load_scenario)")
    refuse_internal_keys(data, str(path))
    return scenario_from_mapping(data, str(path), source_path=path)
