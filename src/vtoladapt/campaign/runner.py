"""Monte-Carlo campaigns: many runs of one scenario with varied seeds and parameters, on Dask.

``vtoladapt campaign SCENARIO --runs N --vary plant.coefficients.CL1=2.8:3.6 --out DIR`` draws
``N`` variants of the scenario (each a new seed and, per ``--vary``, a value uniform in
``[lo, hi]`` for a dotted scenario key), validates every variant before anything runs, then runs
them on a Dask cluster: a local one by default (one process per core), or an existing scheduler
(``--scheduler tcp://host:8786``) when a campaign outgrows one machine, or in this process
on one thread per core (``--scheduler none``: no worker processes to start). It writes
``campaign.parquet`` (one row per run: the drawn values and the run's metrics),
``summary.json`` and a histogram figure.

The local cluster's scheduler, workers and status page listen on ``127.0.0.1`` only (another
address with ``--listen``); connecting to a given scheduler gives up after
:data:`~vtoladapt.campaign.cluster.SCHEDULER_CONNECT_TIMEOUT_S` with a one-line error; a Ctrl-C
reaches this process only, never the local cluster's workers (:mod:`vtoladapt.campaign.cluster`).

All draws come from ``numpy.random.default_rng(scenario seed)``: the same command gives the same
campaign, whatever the cluster.

A campaign file (a TOML file holding one ``[campaign]`` table, e.g. ``scenarios/envelope.toml``;
``vtoladapt campaign FILE --out DIR``) names a base scenario, the controllers and what varies:
ranges (``[[campaign.vary]]``: Latin hypercube or uniform, optionally relative to the vehicle's
Table I, a vector set by one number, reported in bands or angle sectors), discrete choices
(``[campaign.choices]``) and fixed changes (``[campaign.set]``). Every draw is flown by every
controller on the same seed; the rows and the summary are those of
:mod:`vtoladapt.experiments.envelope` (README "Campaign files").
"""
from __future__ import annotations

import copy
import math
import os
import re
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Optional

import numpy as np

from .cluster import LOOPBACK, check_listen, check_scheduler, run_on_dask
from ..config import (PATH_PATTERN, ConfigError, Validated, build, check_flag, read_toml, refuse_internal_keys,
                     setting)
from ..control.registry import controller_ids
from ..outputs import OutputDir, add_force_argument, output_path, write_json, write_parquet


@dataclass(frozen=True)
class Variation:
    """A scenario key drawn uniformly in ``[low, high]`` for each run."""

    key: str
    low: float
    high: float

    @classmethod
    def parse(cls, text: str) -> "Variation":
        """``"plant.coefficients.CL1=2.8:3.6"`` -> Variation."""
        try:
            key, rng = text.split("=", 1)
            low, high = (float(v) for v in rng.split(":"))
            if not key.strip() or any(not part for part in key.strip().split(".")):
                raise ValueError(key)
        except ValueError:
            raise ConfigError(f"--vary {text!r}: expected KEY=LOW:HIGH, e.g. plant.coefficients.CL1=2.8:3.6") \
                from None
        if not (math.isfinite(low) and math.isfinite(high) and low <= high):
            raise ConfigError(f"--vary {text!r}: need finite LOW <= HIGH")
        return cls(key.strip(), low, high)


@dataclass(frozen=True)
class RunSpec:
    """One run of a campaign: the scenario mapping to validate and run, and what was drawn.

    A campaign file's runs also name their ``controller`` (every controller of a draw shares
    ``index``, ``mapping`` and seed) and the draw's condition ``groups`` (group name -> label).
    """

    index: int
    mapping: dict
    source: str
    drawn: dict
    controller: Optional[str] = None
    groups: dict = field(default_factory=dict)


MAX_CAMPAIGN_RUNS = 100_000
"""Most runs of a campaign (``--runs``), or draws of a campaign file (each flown by every controller)."""
CAMPAIGN_OWNED_KEYS = ("seed", "experiment", "controller.kind")
"""Scenario keys a campaign sets itself (each run's seed, single runs, the controller flown)."""


def check_runs_flag(runs: int) -> int:
    """``--runs``: a whole number 1 to :data:`MAX_CAMPAIGN_RUNS`, for a scenario and a campaign file alike."""
    return check_flag("--runs", runs, ge=1, le=MAX_CAMPAIGN_RUNS, integer=True)


def keys_overlap(a: str, b: str) -> bool:
    """Whether writing dotted key ``a`` and dotted key ``b`` touch the same value (equal, or one
    a table holding the other: ``wind.fan_array`` and ``wind.fan_array.schedule``)."""
    return a == b or a.startswith(b + ".") or b.startswith(a + ".")


def _set_dotted(mapping: dict, key: str, value, where: str) -> None:
    parts = key.split(".")
    node = mapping
    for p in parts[:-1]:
        node = node.setdefault(p, {})
        if not isinstance(node, dict):
            raise ConfigError(f"{where}: {key!r}: '{p}' is not a table in the scenario; allowed: a key "
                              "inside one of the scenario's tables")
    node[parts[-1]] = value


def _check_variations(variations: list[Variation]) -> None:
    """Refuse ``--vary`` keys the campaign sets itself or that another ``--vary`` also draws (the
    later draw silently replaced the earlier one, and ``--vary experiment.runs`` was dropped)."""
    owned = ", ".join(CAMPAIGN_OWNED_KEYS)
    for i, v in enumerate(variations):
        if any(keys_overlap(v.key, o) for o in CAMPAIGN_OWNED_KEYS):
            raise ConfigError(f"--vary {v.key}={v.low:g}:{v.high:g}: {v.key!r} is set by the campaign itself "
                              f"(--seed, single runs, --controller); allowed: any key but {owned}")
        for w in variations[:i]:
            if keys_overlap(v.key, w.key):
                raise ConfigError(f"--vary {w.key}={w.low:g}:{w.high:g} and --vary {v.key}={v.low:g}:{v.high:g}: "
                                  "both draw the same value; allowed: each key in one --vary")


def plan_campaign(scenario_path: str | Path, runs: int, variations: list[Variation],
                  seed: Optional[int] = None, controller: Optional[str] = None) -> list[RunSpec]:
    """Draw and validate every run before any runs (a bad key or value fails here, naming it).

    A campaign flies single runs of one controller: a scenario whose ``[experiment]`` is a
    comparison or convergence study needs ``controller`` (``--controller``), rather than
    silently flying only its ``[controller] kind``.
    """
    from ..config import check_value
    from ..control.settings import ControllerConfig
    from ..ceilings import check_campaign_runs
    from ..preflight import check_flyable
    from ..sim.limits import check_worker_runs
    from ..sim.scenario import Scenario, scenario_from_mapping

    runs = check_runs_flag(runs)
    _check_variations(variations)
    if seed is not None:
        seed = check_value(Scenario, "seed", seed, "--seed")
    path = Path(scenario_path)
    base = read_toml(path)
    from ..file_kinds import check_file_kind

    check_file_kind(path, base, "scenario", "`vtoladapt campaign`")  # or a campaign file, dispatched before
    refuse_internal_keys(base, str(path))
    base_scenario = scenario_from_mapping(base, str(path))
    if controller is not None:
        controller = check_value(ControllerConfig, "kind", controller, "--controller")
        base = copy.deepcopy(base)
        base.setdefault("controller", {})["kind"] = controller
        base_scenario = scenario_from_mapping(base, str(path))
    elif base_scenario.experiment.kind != "single":
        raise ConfigError(
            f"{path}: [experiment] kind = {base_scenario.experiment.kind!r}: a campaign flies "
            f"single runs of one controller and would fly only [controller] kind = "
            f"{base_scenario.controller.kind!r}; pass --controller ID to say which")
    check_campaign_runs(runs, base)
    check_worker_runs(base_scenario, f"{path} (each campaign run)", workers=os.cpu_count() or 1)
    rng = np.random.default_rng(base_scenario.seed if seed is None else seed)
    specs = []
    for i in range(runs):
        mapping = copy.deepcopy(base)
        drawn = {"seed": int(rng.integers(0, 2**31 - 1))}
        mapping["seed"] = drawn["seed"]
        for v in variations:
            drawn[v.key] = float(rng.uniform(v.low, v.high))
            _set_dotted(mapping, v.key, drawn[v.key], f"--vary {v.key}")
        mapping["experiment"] = {"kind": "single"}
        where = f"{path} (campaign run {i}, {drawn})"
        check_flyable(scenario_from_mapping(mapping, where, source_path=path), where)  # before --out is claimed
        specs.append(RunSpec(i, mapping, str(path), drawn))
    return specs


# --- campaign files: a [campaign] table -----------------------------------------------------------
SAMPLINGS = ("latin_hypercube", "uniform")
DOTTED_KEY_PATTERN = r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*"
LABEL_PATTERN = r"[^\x00\n]{0,64}"


@dataclass(frozen=True)
class VaryEntry(Validated):
    """A ``[[campaign.vary]]`` entry: scenario keys drawn in ``[low, high]`` for every draw."""

    config_section = "campaign.vary"

    keys: tuple[str, ...] = setting("-", "dotted scenario keys (e.g. plant.stall_angle_deg), each drawn on its own",
                                    pattern=DOTTED_KEY_PATTERN)
    low: float = setting("the key's unit", "lower end of the range (a factor when relative_to_vehicle)")
    high: float = setting("the key's unit", "upper end of the range (a factor when relative_to_vehicle)")
    relative_to_vehicle: bool = setting(
        "-", "low and high are factors on the draw's vehicle's [force_model] value (keys "
        "plant.coefficients.<name>)", default=False)
    components: Optional[tuple[float, ...]] = setting(
        "-", "write the drawn x as the list [c1 x, c2 x, ...]: one number sets a vector key", default=None,
        ge=-1e3, le=1e3)
    label: str = setting("-", "the dimension's name in tables and figures (default: its key)", default="",
                         pattern=LABEL_PATTERN)
    bands: int = setting("-", "report the targets in this many equal bands of the range (0: no breakdown)",
                         default=0, ge=0, le=12)
    angle: bool = setting("-", "the range is a full circle of angles: bands are sectors centred on low, "
                          "low + width, ... (so 4 bands of 0-360 deg are N, E, S, W)", default=False)

    def _check(self, source: str) -> None:
        where = f"{source}: [[campaign.vary]] keys = {list(self.keys)}"
        if not self.keys or len(set(self.keys)) != len(self.keys):
            raise ConfigError(f"{where}: must name at least one key, without repeats")
        if not self.low <= self.high:
            raise ConfigError(f"{where}: low = {self.low:g}, high = {self.high:g}: need low <= high")
        for k in self.keys:
            if any(k == o or k.startswith(o + ".") for o in CAMPAIGN_OWNED_KEYS):
                raise ConfigError(f"{where}: {k!r} is set by the campaign itself; allowed: any key but "
                                  f"{', '.join(CAMPAIGN_OWNED_KEYS)}")
            if self.relative_to_vehicle and not re.fullmatch(r"plant\.coefficients\.\w+", k):
                raise ConfigError(f"{where}: relative_to_vehicle = true: {k!r} is not a key "
                                  "plant.coefficients.<name>; allowed: the plant's coefficients")
        if self.components is not None and not self.components:
            raise ConfigError(f"{where}: components = []: give one factor per element of the vector")
        if (self.bands or self.angle) and len(self.keys) != 1:
            raise ConfigError(f"{where}: bands/angle need exactly one key, got {len(self.keys)}")
        if self.angle and not self.bands:
            raise ConfigError(f"{where}: angle = true needs bands >= 1 (the sectors it reports)")

    @property
    def name(self) -> str:
        """The dimension's name in tables: ``label``, or the (first) key."""
        return self.label or self.keys[0]

    def band(self, x: float, unit: Optional[str]) -> str:
        """The label of the band (or sector) holding ``x``: ``"[12,14) deg"``, ``"[315,45) deg"``."""
        width = (self.high - self.low) / self.bands
        suffix = f" {unit}" if unit else ""
        if width <= 0:
            return f"[{self.low:g},{self.high:g}]{suffix}"
        if self.angle:
            span = self.high - self.low
            k = int(math.floor(((x - self.low + width / 2) % span) / width)) % self.bands
            lo = self.low + (k - 0.5) * width
            lo = lo + span if lo < self.low else lo
            hi = self.low + (k + 0.5) * width
            return f"[{lo:g},{hi:g}){suffix}"
        k = min(int((x - self.low) / width), self.bands - 1)
        lo, hi = self.low + k * width, self.low + (k + 1) * width
        return f"[{lo:g},{hi:g}{']' if k == self.bands - 1 else ')'}{suffix}"


@dataclass(frozen=True)
class CampaignConfig(Validated):
    """A campaign file's ``[campaign]`` table; its ``set`` and ``choices`` sub-tables are free-form
    (dotted scenario keys) and read by :func:`load_campaign_file`."""

    config_section = "campaign"

    base: str = setting("-", "scenario every draw starts from (path relative to the campaign file)",
                        pattern=PATH_PATTERN)
    runs: int = setting("-", "number of draws, each flown by every controller", ge=1, le=MAX_CAMPAIGN_RUNS)
    seed: int = setting("-", "seed of every draw: numpy.random.default_rng(seed)", ge=0, le=2**63 - 1)
    controllers: tuple[str, ...] = setting("-", "controllers flying every draw (same seed, same conditions)",
                                           choices=controller_ids)
    sampling: str = setting("-", "'latin_hypercube': every dimension stratified into runs equal strata "
                            "(choices: each option equally often); 'uniform': independent draws",
                            default="latin_hypercube", choices=SAMPLINGS)
    description: str = setting("-", "what the campaign is for", default="")
    vary: tuple[VaryEntry, ...] = setting("-", "[[campaign.vary]] entries: ranges drawn per draw", default=())

    def _check(self, source: str) -> None:
        if not self.controllers or len(set(self.controllers)) != len(self.controllers):
            raise ConfigError(f"{source}: [campaign] controllers = {list(self.controllers)}: must be a "
                              f"non-empty list without repeats; allowed: {', '.join(controller_ids())}")
        keys = [k for v in self.vary for k in v.keys]
        if len(set(keys)) != len(keys):
            dup = next(k for k in keys if keys.count(k) > 1)
            raise ConfigError(f"{source}: [[campaign.vary]] {dup!r}: drawn twice; allowed: each key once")


@dataclass(frozen=True)
class CampaignFile:
    """A validated campaign file: its ``[campaign]`` table, fixed ``set`` values and ``choices``."""

    path: Path
    config: CampaignConfig
    set_values: dict
    """dotted scenario key -> value, applied to the base scenario of every draw."""
    choices: dict
    """dimension -> option name -> {dotted scenario key: value}; each draw picks one option per dimension."""

    @property
    def base_path(self) -> Path:
        """The base scenario's path."""
        base = Path(self.config.base)
        return base if base.is_absolute() else self.path.parent / base


def _flatten(table: dict, prefix: str = "") -> list[tuple[str, object]]:
    """``{"wind": {"fan_array": {"schedule": x}}}`` and ``{"wind.fan_array.schedule": x}`` alike
    -> ``[("wind.fan_array.schedule", x)]`` (a key written both ways appears twice)."""
    out = []
    for k, v in table.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        out += _flatten(v, key) if isinstance(v, dict) else [(key, v)]
    return out


def _check_dotted(source: str, section: str, table) -> dict:
    if not isinstance(table, dict):
        raise ConfigError(f"{source}: [{section}] = {table!r:.60}: must be a table of scenario keys")
    flat: dict = {}
    for key, value in _flatten(table):
        clash = next((k for k in flat if keys_overlap(k, key)), None)
        if clash is not None:  # "plant.stall_angle_deg" = 14 beside [..plant] stall_angle_deg = 15
            shown = repr(key) if clash == key else f"{clash!r} and {key!r}"
            raise ConfigError(f"{source}: [{section}] {shown}: the same value written twice (as a dotted key "
                              "and in a nested table); allowed: each scenario key once")
        flat[key] = value
    for key in flat:
        if not re.fullmatch(DOTTED_KEY_PATTERN, key):
            raise ConfigError(f"{source}: [{section}] {key!r}: not a dotted scenario key; allowed: "
                              "names of letters, digits and '_' joined by '.'")
        if any(key == o or key.startswith(o + ".") for o in CAMPAIGN_OWNED_KEYS):
            raise ConfigError(f"{source}: [{section}] {key!r}: set by the campaign itself; allowed: "
                              f"any key but {', '.join(CAMPAIGN_OWNED_KEYS)}")
    return flat


def is_campaign_file(path: str | Path) -> bool:
    """Whether the TOML file at ``path`` is a campaign file (has a ``[campaign]`` table)."""
    return "campaign" in read_toml(path)


def load_campaign_file(path: str | Path) -> CampaignFile:
    """Read and validate a campaign file (one-line :class:`ConfigError` naming file, table, key,
    value and what is allowed). Each draw's scenario is validated by :func:`plan_campaign_file`."""
    path = Path(path)
    data = read_toml(path)
    unknown = [k for k in data if k != "campaign"]
    if unknown:
        raise ConfigError(f"{path}: {unknown[0]} = {data[unknown[0]]!r:.60}: unknown key; a campaign file "
                          "holds only a [campaign] table (scenario keys go in [campaign.set] or the base scenario)")
    raw = data["campaign"]
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: campaign = {raw!r:.60}: must be a table ([campaign])")
    raw = dict(raw)
    set_values = _check_dotted(str(path), "campaign.set", raw.pop("set", {}))
    raw_choices = raw.pop("choices", {})
    if not isinstance(raw_choices, dict):
        raise ConfigError(f"{path}: [campaign] choices = {raw_choices!r:.60}: must be a table of "
                          "[campaign.choices.<dimension>.<option>] tables")
    choices = {}
    for dim, options in raw_choices.items():
        if not re.fullmatch(LABEL_PATTERN, dim) or not isinstance(options, dict) or not options or \
                not all(isinstance(o, dict) for o in options.values()):
            raise ConfigError(f"{path}: [campaign.choices.{dim}] = {options!r:.60}: must hold one or more "
                              f"option tables [campaign.choices.{dim}.<option>] of scenario keys")
        choices[dim] = {name: _check_dotted(str(path), f"campaign.choices.{dim}.{name}", opt)
                        for name, opt in options.items()}
    config = build(CampaignConfig, raw, source=str(path), section="campaign")
    names = [v.name for v in config.vary if v.bands] + list(choices)
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise ConfigError(f"{path}: [campaign] {dup!r}: two dimensions report under this name; give "
                          "each [[campaign.vary]] a distinct label")
    _refuse_conflicts(path, set_values, choices, config.vary)
    return CampaignFile(path, config, set_values, choices)


def _refuse_conflicts(path: Path, set_values: dict, choices: dict, vary: tuple[VaryEntry, ...]) -> None:
    """Refuse a scenario key written in two places of a campaign file: a draw applies
    ``[campaign.set]``, then the choices in order, then the ``[[campaign.vary]]`` draws, so the
    later silently replaced the earlier, and a draw reported ``choice.vehicle =
    px4_standard_vtol`` while it flew the vehicle another choice had set. The options of one
    choice dimension are alternatives: they may (and usually do) write the same keys."""
    places = [("[campaign.set]", "set", list(set_values))]
    places += [(f"[campaign.choices.{dim}.{name}]", f"choice {dim}", list(option))
               for dim, options in choices.items() for name, option in options.items()]
    places += [(f"[[campaign.vary]] keys = {list(v.keys)}", f"vary {j}", list(v.keys)) for j, v in enumerate(vary)]
    for i, (place, owner, keys) in enumerate(places):
        for earlier, earlier_owner, earlier_keys in places[:i]:
            if owner == earlier_owner:
                continue
            for key in keys:
                clash = next((k for k in earlier_keys if keys_overlap(k, key)), None)
                if clash is not None:
                    shown = repr(key) if clash == key else f"{clash!r} / {key!r}"
                    raise ConfigError(
                        f"{path}: {earlier} and {place}: both set {shown} (the later would silently "
                        "replace the earlier); allowed: each scenario key in one place ([campaign.set], one "
                        "[campaign.choices] dimension or one [[campaign.vary]] entry)")


def latin_hypercube(rng: np.random.Generator, n: int, d: int) -> np.ndarray:
    """``n`` points in ``[0, 1)^d`` with exactly one in each of the ``n`` equal strata of every
    dimension (McKay et al. 1979): a random permutation of the strata per dimension, a uniform
    position inside each stratum."""
    u = np.empty((n, d))
    for j in range(d):
        u[:, j] = (rng.permutation(n) + rng.random(n)) / n
    return u


def plan_campaign_file(path: str | Path, runs: Optional[int] = None,
                       seed: Optional[int] = None) -> tuple[CampaignFile, list[RunSpec]]:
    """Draw and validate every run of a campaign file before any runs: ``runs`` draws (default
    ``[campaign] runs``), each flown by every ``[campaign] controllers`` entry on the same seed.

    Per draw, from ``numpy.random.default_rng(seed or [campaign] seed)``: a run seed, then one
    point of a Latin hypercube (or uniform) over the dimensions, the ``[[campaign.vary]]`` keys
    first, then the ``[campaign.choices]`` (an option is the stratum ``floor(u n_options)``).
    """
    from ..config import check_value
    from ..ceilings import check_campaign_runs
    from ..preflight import check_all
    from ..sim.limits import check_worker_runs
    from ..sim.scenario import scenario_from_mapping

    cf = load_campaign_file(path)
    cfg = cf.config
    runs = cfg.runs if runs is None else check_runs_flag(runs)
    seed = cfg.seed if seed is None else check_value(CampaignConfig, "seed", seed, "--seed")
    at_base = f"{cf.path}: [campaign] base = {cfg.base!r}"
    try:
        base = read_toml(cf.base_path)
        refuse_internal_keys(base, str(cf.base_path))
    except ConfigError as exc:
        raise ConfigError(f"{at_base}: {exc}") from None
    if "campaign" in base:
        raise ConfigError(f"{at_base}: is itself a campaign file; allowed: a scenario file")
    # the base, [campaign.set] and each choice option are validated in turn, each on top of the
    # ones before, so an error names the table where its value was written (the vehicle lookup
    # named the base scenario for a vehicle a choice option had set)
    base = {**base, "experiment": {"kind": "single"}}
    _validate_written(cf, base, f"{at_base} ({cf.base_path})")
    for key, value in cf.set_values.items():
        _set_dotted(base, key, copy.deepcopy(value), f"{cf.path}: [campaign.set]")
    base_scenario = _validate_written(cf, base, f"{cf.path}: [campaign.set]")
    for dim, options in cf.choices.items():
        for name, option in options.items():
            mapping = copy.deepcopy(base)
            table = f"{cf.path}: [campaign.choices.{dim}.{name}]"
            for key, value in option.items():
                _set_dotted(mapping, key, copy.deepcopy(value), table)
            _validate_written(cf, mapping, table)
    source = str(cf.base_path)
    where = f"{cf.path} ([campaign] base {cfg.base} with [campaign.set])"
    check_campaign_runs(runs * len(cfg.controllers), base)
    check_worker_runs(base_scenario, f"{where} (each campaign run)", workers=os.cpu_count() or 1)

    dims = [(v, k) for v in cfg.vary for k in v.keys]
    rng = np.random.default_rng(seed)
    seeds = rng.integers(0, 2**31 - 1, size=runs)
    n_dims = len(dims) + len(cf.choices)
    u = latin_hypercube(rng, runs, n_dims) if cfg.sampling == "latin_hypercube" else rng.random((runs, n_dims))
    specs: list[RunSpec] = []
    for i in range(runs):
        mapping = copy.deepcopy(base)
        drawn: dict = {"seed": int(seeds[i])}
        groups: dict = {}
        mapping["seed"] = drawn["seed"]
        mapping["experiment"] = {"kind": "single"}
        for j, (dim, options) in enumerate(cf.choices.items()):
            names = list(options)
            pick = names[min(int(u[i, len(dims) + j] * len(names)), len(names) - 1)]
            for key, value in options[pick].items():
                _set_dotted(mapping, key, copy.deepcopy(value), f"{cf.path}: [campaign.choices.{dim}.{pick}]")
            drawn[f"choice.{dim}"] = pick
            groups[dim] = pick
        vehicle = None
        if any(v.relative_to_vehicle for v, _ in dims):
            vehicle = scenario_from_mapping(mapping, f"{cf.path} (campaign draw {i})",
                                            source_path=cf.base_path).load_vehicle()
        for j, (v, key) in enumerate(dims):
            x = v.low + float(u[i, j]) * (v.high - v.low)
            value = x
            if v.relative_to_vehicle:
                name = key.rsplit(".", 1)[1]
                if not hasattr(vehicle.force_model, name):
                    raise ConfigError(f"{cf.path}: [[campaign.vary]] {key!r}: relative_to_vehicle: the vehicle's "
                                      f"[force_model] has no {name!r}")
                value = x * getattr(vehicle.force_model, name)
            _set_dotted(mapping, key, [c * value for c in v.components] if v.components is not None else value,
                        f"{cf.path}: [[campaign.vary]]")
            drawn[key] = value
            if v.relative_to_vehicle:
                drawn[f"{key}:factor"] = x
            if v.bands:
                groups[v.name] = v.band(x, _setting_unit(key))
        mapping["controller"] = {**mapping.get("controller", {}), "kind": cfg.controllers[0]}
        shown = {k: (round(val, 4) if isinstance(val, float) else val) for k, val in drawn.items()}
        where = f"{cf.path} (campaign draw {i}: {shown})"
        sc = scenario_from_mapping(mapping, where, source_path=cf.base_path)
        check_all((replace(sc, controller=replace(sc.controller, kind=cid)), f"{where}, controller {cid!r}")
                  for cid in cfg.controllers)  # every run's setup, before --out is claimed
        specs += [RunSpec(i, mapping, source, drawn, cid, groups) for cid in cfg.controllers]
    return cf, specs


def _validate_written(cf: CampaignFile, mapping: dict, where: str):
    """The scenario of ``mapping`` (the scenario so far with the values written at ``where`` in
    the campaign file), or a one-line ConfigError naming ``where``. The scenario so far has
    passed, so a vehicle that fails to load is the one written there: it is reported as
    ``where``'s ``vehicle = ...`` (the lookup itself names only the base scenario's file)."""
    from ..sim.scenario import Scenario, file_relative_vehicle, scenario_from_mapping

    scenario = build(Scenario, file_relative_vehicle({**mapping, "source_path": str(cf.base_path)}, cf.base_path),
                     source=where)
    try:
        scenario.load_vehicle()
    except ConfigError as exc:
        reason = str(exc).removeprefix(f"{cf.base_path}: ").removeprefix(f"vehicle {scenario.vehicle!r}: ")
        # the value as written there, not as resolved against the base scenario's folder
        raise ConfigError(f"{where}: vehicle = {mapping.get('vehicle', scenario.vehicle)!r}: {reason}") from None
    return scenario_from_mapping(mapping, where, source_path=cf.base_path)


def _run_controller(spec: RunSpec) -> dict:
    """One controller's run of a campaign-file draw, reduced to its row (the envelope metrics)."""
    from ..experiments.envelope import envelope_run_metrics
    from ..sim.scenario import scenario_from_mapping
    from ..sim.driver import simulate

    mapping = dict(spec.mapping)
    mapping["controller"] = {**spec.mapping.get("controller", {}), "kind": spec.controller}
    scenario = scenario_from_mapping(mapping, spec.source, source_path=spec.source)
    result = simulate(scenario)
    return {"run": spec.index, "controller": spec.controller, **spec.drawn,
            **{f"group.{k}": v for k, v in spec.groups.items()}, **envelope_run_metrics(result, scenario)}


def run_one(spec: RunSpec) -> dict:
    """Run one campaign member (executed on a Dask worker) and return its row."""
    from ..experiments import fan_throttle_series
    from ..sim.run_metrics import run_metrics
    from ..sim.scenario import scenario_from_mapping
    from ..sim.driver import simulate

    if spec.controller is not None:
        return _run_controller(spec)
    scenario = scenario_from_mapping(spec.mapping, spec.source, source_path=spec.source)
    result = simulate(scenario)
    row = {"run": spec.index, **spec.drawn}
    if len(result) > 1:  # a run that diverged at once has no metrics, only its divergence
        # one column per scalar metric (the per-airspeed-bin prediction error is a mapping: left out)
        row.update({k: v for k, v in run_metrics(result, fan_throttle_series(scenario, result.time_s)).items()
                    if not isinstance(v, dict)})
    row["wall_time_s"] = result.metadata["wall_time_s"]
    row["diverged"] = float(result.diverged)
    row["diverged_at_s"] = result.diverged_at_s if result.diverged else float("nan")
    return row


CAMPAIGN_OUTPUTS = ("campaign.parquet", "summary.json", "fig_campaign.png")
MAX_WORKERS = 1024
"""Most local worker processes or threads (each holds one run's log)."""


def run_campaign(specs: list[RunSpec], out: Path, scheduler: Optional[str] = "local",
                 n_workers: Optional[int] = None, show_progress: bool = True,
                 listen: str = LOOPBACK, campaign: Optional[dict] = None) -> list[dict]:
    """Run the planned campaign and write ``campaign.parquet``, ``summary.json``, ``fig_campaign.png``.

    ``scheduler``: ``"local"`` (a LocalCluster, one single-threaded process per core, every
    socket on ``listen``), ``"none"`` (in this process, ``n_workers`` threads, default one per
    core), or a scheduler address. Runs of a campaign file (specs naming a controller) write one
    row per draw and controller and the envelope summary
    (:func:`vtoladapt.experiments.envelope.envelope_summary`, with ``campaign`` merged into its
    ``campaign`` entry) and its figure.
    """
    if n_workers is not None:
        check_flag("--workers", n_workers, ge=1, le=MAX_WORKERS, integer=True)
    out = Path(out)
    wall0 = time.perf_counter()
    rows: list[dict] = []
    if scheduler in (None, "none"):
        # the compiled loop releases the GIL: threads give every core a run without new processes
        from concurrent.futures import ThreadPoolExecutor, as_completed

        pool = ThreadPoolExecutor(max_workers=n_workers if n_workers is not None else os.cpu_count() or 1)
        bar = _progress(len(specs), show_progress)
        try:
            for fut in as_completed([pool.submit(run_one, spec) for spec in specs]):
                rows.append(fut.result())
                bar.update(1)
        finally:
            bar.close()
            # on an error or Ctrl-C no queued run starts; running ones finish their chunk
            pool.shutdown(wait=False, cancel_futures=True)
    else:
        bars = []

        def started() -> None:  # the bar appears once the cluster is up
            bars.append(_progress(len(specs), show_progress))

        def done(row: dict) -> None:
            rows.append(row)
            bars[0].update(1)
        try:
            run_on_dask(run_one, specs, scheduler, n_workers, listen, started, done)
        finally:
            for bar in bars:
                bar.close()
    out.mkdir(parents=True, exist_ok=True)
    if specs and specs[0].controller is not None:
        order = {s.controller: i for i, s in enumerate(specs) if s.index == specs[0].index}
        rows.sort(key=lambda r: (r["run"], order.get(r["controller"], len(order))))
        _write_envelope_outputs(rows, out, dict(campaign or {}, wall_time_s=time.perf_counter() - wall0))
        return rows
    rows.sort(key=lambda r: r["run"])
    _write_outputs(rows, out, tuple(k for k in specs[0].drawn if k != "seed") if specs else ())
    return rows


def _write_envelope_outputs(rows: list[dict], out: Path, campaign: dict) -> dict:
    """``campaign.parquet`` (one row per draw and controller), ``summary.json`` (the envelope
    targets' fractions) and ``fig_campaign.png`` (the fractions with their intervals)."""
    import pyarrow as pa

    from ..experiments.envelope import envelope_summary, figure_envelope

    keys = list(dict.fromkeys(k for r in rows for k in r))
    columns = {k: [r.get(k) for r in rows] for k in keys}
    write_parquet(pa.table(columns), out / "campaign.parquet")
    summary = envelope_summary(columns, campaign)
    write_json(out / "summary.json", summary)
    figure_envelope(summary, out / "fig_campaign.png")
    return summary


class _NoProgress:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, show: bool):
    if not show:
        return _NoProgress()
    from ..progress import progress_bar

    return progress_bar(total=total, unit="run", desc="campaign")


def _write_outputs(rows: list[dict], out: Path, varied: tuple[str, ...] = ()) -> None:
    import pyarrow as pa

    keys = list(dict.fromkeys(k for r in rows for k in r))
    rows = [{k: r.get(k, float("nan")) for k in keys} for r in rows]  # a run diverged at once has no metrics
    table = pa.table({k: [r.get(k, float("nan")) for r in rows] for k in keys})
    write_parquet(table, out / "campaign.parquet")
    summary = {}
    for k in keys:
        vals = np.array([r.get(k, np.nan) for r in rows], dtype=float)
        if k == "run" or not np.isfinite(vals).any():
            continue
        summary[k] = {"mean": float(np.nanmean(vals)), "std": float(np.nanstd(vals)),
                      "min": float(np.nanmin(vals)), "p95": float(np.nanpercentile(vals, 95)),
                      "max": float(np.nanmax(vals))}
    diverged = int(sum(r.get("diverged", 0.0) for r in rows))
    write_json(out / "summary.json", {"runs": len(rows), "diverged_runs": diverged, "columns": summary})
    figure_campaign_png(rows, out / "fig_campaign.png", varied)


def figure_campaign_png(rows: list[dict], path: Path, varied: list[str] | tuple[str, ...] = ()) -> Path:
    """The campaign's figure: metric histograms (whole-number counts) and each metric against
    every varied scenario key, with the key's unit from the scenario's declarations."""
    from ..experiments import figure_campaign

    return figure_campaign(rows, path, varied, {k: u for k in varied if (u := _setting_unit(k))})


def _setting_unit(dotted_key: str) -> str | None:
    """The declared unit of a dotted scenario key (``plant.stall_angle_deg`` -> ``deg``), or None."""
    import dataclasses

    from ..sim.scenario import Scenario

    cls = Scenario
    parts = dotted_key.split(".")
    for i, part in enumerate(parts):
        fields = {f.name: f for f in dataclasses.fields(cls)} if dataclasses.is_dataclass(cls) else {}
        f = fields.get(part)
        if f is None:
            return None
        if i == len(parts) - 1:
            unit = f.metadata.get("unit")
            return unit if unit and unit != "-" else None
        default = f.default if f.default is not dataclasses.MISSING else None
        if default is None and f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        cls = type(default)
    return None


def register_cli(subparsers) -> None:
    """Add the ``campaign`` sub-command to ``subparsers`` (its handler raises on bad input)."""
    p = subparsers.add_parser("campaign", help="Monte-Carlo campaign of a scenario on Dask",
                              description=__doc__.split("\n\n")[1])
    p.add_argument("scenario", help="scenario TOML, or a campaign file (a [campaign] table: base scenario, "
                                    "controllers, draws, variations; e.g. scenarios/envelope.toml)")
    p.add_argument("--runs", type=int, default=None,
                   help=f"number of runs, 1 to {MAX_CAMPAIGN_RUNS} (required for a scenario; for a campaign file: "
                        "draws, default its [campaign] runs)")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=LOW:HIGH",
                   help="draw this dotted scenario key uniformly per run (repeatable)")
    p.add_argument("--out", type=output_path, required=True, help="output directory")
    p.add_argument("--scheduler", default="local",
                   help="'local' (default: a local Dask cluster), 'none' (this process, threads) or an address")
    p.add_argument("--listen", default=LOOPBACK, metavar="HOST",
                   help=f"address the local cluster's scheduler, workers and status page listen on "
                        f"(default {LOOPBACK}: this machine only)")
    p.add_argument("--controller", default=None,
                   help="controller to fly (required for a comparison or convergence scenario)")
    p.add_argument("--workers", type=int, default=None,
                   help="local cluster processes or in-process threads (default: cores)")
    p.add_argument("--seed", type=int, default=None, help="campaign seed (default: the scenario's)")
    p.add_argument("--quiet", action="store_true")
    add_force_argument(p)
    p.set_defaults(handler=_cmd_campaign)


def _cmd_campaign(args) -> int:
    if is_campaign_file(args.scenario):
        return _cmd_campaign_file(args)
    if args.runs is None:
        raise ConfigError(f"--runs: required with a scenario file ({args.scenario} has no [campaign] "
                          f"table); allowed: a whole number >= 1 and <= {MAX_CAMPAIGN_RUNS}")
    check_runs_flag(args.runs)  # before the draws: 200 000 of them took minutes to validate
    variations = [Variation.parse(v) for v in args.vary]
    _check_variations(variations)
    check_scheduler(args.scheduler)
    check_listen(args.listen)
    target = OutputDir(args.out, "campaign", force=args.force, planned=CAMPAIGN_OUTPUTS)
    if args.workers is not None:
        check_flag("--workers", args.workers, ge=1, le=MAX_WORKERS, integer=True)
    specs = plan_campaign(args.scenario, args.runs, variations, args.seed, args.controller)
    with target:
        rows = run_campaign(specs, target.path, args.scheduler, args.workers, not args.quiet,
                            listen=args.listen)
    v = np.array([r.get("vel_err_rms_mps", np.nan) for r in rows])  # a run diverged at once has none
    n_div = int(sum(r.get("diverged", 0.0) for r in rows))
    mean, top = (f"{np.nanmean(v):.4f}", f"{np.nanmax(v):.4f}") if np.isfinite(v).any() else ("-", "-")
    print(f"{len(rows)} runs ({n_div} diverged): RMS velocity error mean {mean} m/s, max {top} m/s; "
          f"wrote {args.out}/campaign.parquet, summary.json, fig_campaign.png")
    return 0


def _cmd_campaign_file(args) -> int:
    """``vtoladapt campaign FILE --out DIR`` for a campaign file: every draw flown by every controller."""
    for flag, value in (("--vary", args.vary), ("--controller", args.controller)):
        if value:
            raise ConfigError(f"{flag} {value if isinstance(value, str) else value[0]!r}: not with a campaign "
                              f"file ({args.scenario} has a [campaign] table); allowed: set it in the file's "
                              "[[campaign.vary]] or [campaign] controllers")
    if args.runs is not None:
        check_runs_flag(args.runs)
    check_scheduler(args.scheduler)
    check_listen(args.listen)
    target = OutputDir(args.out, "campaign", force=args.force, planned=CAMPAIGN_OUTPUTS)
    if args.workers is not None:
        check_flag("--workers", args.workers, ge=1, le=MAX_WORKERS, integer=True)
    cf, specs = plan_campaign_file(args.scenario, args.runs, args.seed)
    info = {"file": str(args.scenario), "base": cf.config.base,
            "seed": cf.config.seed if args.seed is None else args.seed,
            "sampling": cf.config.sampling, "description": cf.config.description,
            "duration_s": float(specs[0].mapping.get("duration_s", float("nan")))}
    with target:
        run_campaign(specs, target.path, args.scheduler, args.workers, not args.quiet,
                     listen=args.listen, campaign=info)
    import json

    from ..experiments.envelope import TARGETS

    summary = json.loads((Path(args.out) / "summary.json").read_text())
    n_draws = summary["campaign"]["draws"]
    print(f"{n_draws} draws x {len(cf.config.controllers)} controllers; targets (fraction of draws, 95 % CI):")
    for name in TARGETS:
        t = summary["targets"][name]
        if t["fraction"] is None:
            print(f"  {name}: not judged")
        else:
            print(f"  {name}: {t['fraction']:.2f} ({t['successes']}/{t['n']}) "
                  f"[{t['ci95'][0]:.2f}, {t['ci95'][1]:.2f}]")
    print(f"wrote {args.out}/campaign.parquet, summary.json, fig_campaign.png")
    return 0
