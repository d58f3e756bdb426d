"""Settings of the Gymnasium environment (``gymnasium.make("vtoladapt/Hold-v0", **settings)``).

Every keyword of ``gymnasium.make`` / ``gymnasium.make_vec`` for ``vtoladapt/Hold-v0`` is a field
of :class:`HoldEnvConfig`, validated by :func:`vtoladapt.config.build`: an unknown keyword or a
value outside its range raises one :class:`~vtoladapt.config.ConfigError` line naming the
keyword, the value and what is allowed.

The randomisation lives here and not in the scenario schema: each episode is the base scenario
with its plant coefficients and fan-array wind redrawn (:func:`episode_scenario`), so every
episode is itself a valid scenario that ``vtoladapt run`` can replay.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Optional

import numpy as np

from ..config import ConfigError, Validated, build, setting
from ..sim.plant import PlantCoefficients
from ..sim.scenario import Scenario, load_scenario, scenario_from_mapping
from ..vehicle import PARAMETER_NAMES

ENV_ID = "vtoladapt/Hold-v0"
DEFAULT_SCENARIO = "gym_hold"
"""The shipped scenario an episode starts from unless ``scenario`` is given."""

RANDOMIZED_COEFFICIENTS: tuple[str, ...] = (*PARAMETER_NAMES, "k1", "k2")
"""The plant's force-model coefficients an episode redraws, in the order they are drawn."""

# Lower limits the scenario schema puts on the true coefficients (PlantCoefficients), kept
# strictly inside so a drawn plant is always a valid one.
_COEFFICIENT_FLOOR = {"CTx": 1e-9, "CTz": 1e-9, "CS": 0.0, "CD0": 0.0, "CD2": 0.0, "CL1": 1e-9,
                      "k1": 0.05, "k2": math.pi / 2 + 0.01}
_COEFFICIENT_CEIL = {"k1": 1.95}


@dataclass(frozen=True)
class HoldEnvConfig(Validated):
    """Keyword arguments of ``vtoladapt/Hold-v0`` (and its vector version)."""

    scenario: Any = setting(
        "-", "base scenario: a shipped scenario's name, a path to a scenario TOML, a mapping of one "
        "(as in a TOML file) or a Scenario; its duration is the episode length, its seed is unused "
        "(each reset draws one)", default=DEFAULT_SCENARIO)
    residual: bool = setting(
        "-", "False: the action is the whole command; True: the action is a bounded residual added "
        "to the command of the scenario's [controller] (composite in gym_hold)", default=False)
    residual_scale: float = setting(
        "-", "residual at action +-1, as a fraction of the command's range (u_max for throttles, "
        "tau_max for moments)", default=0.1, gt=0.0, le=1.0)
    randomize: bool = setting("-", "redraw the plant and wind at every reset (False: the scenario "
                              "as written)", default=True)
    coefficient_sigmas: float = setting(
        "-", "plant force-model coefficients drawn from N(mean, (sigmas * std)^2) of the vehicle's "
        "Table I posterior ([force_model_std]); 0 keeps the scenario's plant", default=1.0, ge=0.0,
        le=100.0)
    fan_throttle_scale: tuple[float, ...] = setting(
        "-", "range [lo, hi] of a factor drawn uniformly per episode that multiplies every "
        "throttle of the fan schedule (clipped to 100 %)", default=(0.5, 1.0), ge=0.0, le=10.0,
        length=2)
    array_bearing_deg: Optional[tuple[float, ...]] = setting(
        "deg", "range [lo, hi] of the fan array's bearing drawn uniformly per episode (where the "
        "wind comes from; 0 = north, the held heading); None keeps the scenario's",
        default=(-20.0, 20.0), ge=-360.0, le=360.0, length=2)
    max_position_error_m: float = setting(
        "m", "the episode terminates when the true position leaves this box (each NED axis) "
        "around the reference", default=3.0, gt=0.0, le=100.0)
    max_tilt_deg: float = setting("deg", "the episode terminates when the body z axis tilts more "
                                  "than this from the vertical", default=80.0, gt=0.0, le=180.0)
    action_cost: float = setting(
        "-", "weight c_a of the action penalty c_a sum(a^2) / 5 in the reward", default=0.01, ge=0.0,
        le=100.0)

    def _check(self, source: str) -> None:
        lo, hi = self.fan_throttle_scale
        if lo > hi:
            raise ConfigError(f"{source}: fan_throttle_scale = {list(self.fan_throttle_scale)}: "
                              "must be [lo, hi] with lo <= hi")
        if self.array_bearing_deg is not None and self.array_bearing_deg[0] > self.array_bearing_deg[1]:
            raise ConfigError(f"{source}: array_bearing_deg = {list(self.array_bearing_deg)}: must be "
                              "[lo, hi] with lo <= hi")

    def base_scenario(self, source: str = ENV_ID) -> Scenario:
        """The validated base scenario named by :attr:`scenario`."""
        sc = self.scenario
        if isinstance(sc, Scenario):
            return sc
        if isinstance(sc, Mapping):
            return scenario_from_mapping(dict(sc), f"{source} scenario mapping")
        if isinstance(sc, (str, Path)):
            return load_scenario(sc)
        raise ConfigError(f"{source}: scenario = {sc!r}: must be a shipped scenario's name, a path "
                          "to a scenario TOML, a mapping or a Scenario")


def make_config(kwargs: Mapping[str, Any], source: str = ENV_ID) -> HoldEnvConfig:
    """Validate the environment's keyword arguments (errors name ``source`` and the keyword)."""
    data = dict(kwargs)
    scenario = data.pop("scenario", DEFAULT_SCENARIO)
    cfg = build(HoldEnvConfig, data, source=source)
    cfg = dataclasses.replace(cfg, scenario=scenario)
    base = cfg.base_scenario(source)
    if base.n_ticks < 1:
        raise ConfigError(f"{source}: scenario {base.name!r}: duration_s = {base.duration_s}: "
                          "shorter than one controller tick")
    return dataclasses.replace(cfg, scenario=base)


def episode_scenario(cfg: HoldEnvConfig, base: Scenario, rng: np.random.Generator) -> Scenario:
    """The scenario of one episode: ``base`` with its plant and wind redrawn, and a run seed.

    Draws from ``rng``, in this order: the ten force-model coefficients
    (:data:`RANDOMIZED_COEFFICIENTS`, standard normals; only if ``randomize`` and
    ``coefficient_sigmas > 0``), the fan throttle factor and the array bearing (one uniform each,
    only if ``randomize``; the bearing only if a range is set), then the run's seed (one integer).
    The run's own noise (turbulence, sensors) then comes from that seed, as in ``vtoladapt run``.
    """
    scenario = base
    if cfg.randomize:
        vehicle = base.load_vehicle()
        if cfg.coefficient_sigmas > 0.0:
            truth = base.plant.true_coefficients(vehicle)
            z = rng.standard_normal(len(RANDOMIZED_COEFFICIENTS))
            drawn = {}
            for name, zi in zip(RANDOMIZED_COEFFICIENTS, z):
                value = truth[name] + cfg.coefficient_sigmas * getattr(vehicle.force_model_std, name) * zi
                value = max(value, _COEFFICIENT_FLOOR.get(name, -math.inf))
                drawn[name] = float(min(value, _COEFFICIENT_CEIL.get(name, math.inf)))
            plant = dataclasses.replace(base.plant, coefficients=PlantCoefficients(**drawn))
            scenario = scenario.replace(plant=plant)
        fan = base.wind.fan_array
        scale = rng.uniform(*cfg.fan_throttle_scale)
        bearing = fan.array_bearing_deg
        if cfg.array_bearing_deg is not None:
            bearing = float(rng.uniform(*cfg.array_bearing_deg))
        schedule = tuple((t, float(min(100.0, u * scale))) for t, u in fan.linear_breakpoints())
        fan = dataclasses.replace(fan, schedule=schedule, profile=None, interpolation="linear",
                                  array_bearing_deg=bearing)
        scenario = scenario.replace(wind=dataclasses.replace(base.wind, fan_array=fan))
    seed = int(rng.integers(0, 2**63 - 1))
    return scenario.replace(seed=seed)
