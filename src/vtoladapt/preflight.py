"""Every check of a run's setup, made before its output folder is touched.

Validation of a scenario's tables (:mod:`vtoladapt.config`) cannot see what needs the built
vehicle and plant: whether the plant can hover on its lift rotors, whether the controller's
law accepts the prior, whether a calibration file holds a usable calibration, whether the
initial state is inside the ``[envelope]``. :func:`check_flyable` builds each run exactly as the
simulator will (:func:`vtoladapt.sim.driver.prepare`, for two ticks) and checks the first state
against the envelope, so any setup error is raised here, naming the file (or the campaign draw),
instead of after ``--out`` was claimed: a command that ends with exit 2 changes nothing on disk.
A short run costs about 2 ms once the kernels are loaded.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Iterable

from .config import ConfigError
from .sim.scenario import Scenario


def _named(exc: ConfigError, where: str) -> ConfigError:
    text = str(exc)
    return ConfigError(text if text.startswith(where) else f"{where}: {text}")


def check_flyable(scenario: Scenario, where: str) -> None:
    """Raise a one-line :class:`ConfigError` naming ``where`` if the run of ``scenario`` cannot be
    set up (anything :func:`~vtoladapt.sim.driver.prepare` refuses) or starts outside its envelope."""
    from .sim.monitor import check_envelope
    from .sim.driver import prepare

    short = replace(scenario, duration_s=2.0 * scenario.dt_control_s)
    try:
        run = prepare(short)
    except ConfigError as exc:
        raise _named(exc, where) from None
    _check_plant_step(scenario, run.vehicle, where)
    ref = run.reference_table[0]
    code = check_envelope(run.x0, run.envelope, ref)
    if code:
        why = scenario.envelope.describe_violation(code, run.x0, 0.0, ref)
        raise ConfigError(f"{where}: [initial] the run starts outside its [envelope]: {why}; allowed: an "
                          "initial state (and reference) inside every [envelope] limit")


RK4_STEP_PER_TIME_CONSTANT_MAX = 2.5
"""Largest plant step over a motor's time constant: classical RK4 is stable for the lag's
``-h / tau`` down to -2.785; beyond it a motor's speed oscillates and grows without bound."""


def _check_plant_step(scenario: Scenario, vehicle, where: str) -> None:
    plant = scenario.plant
    if not plant.motor_lag:
        return
    h = scenario.dt_control_s / scenario.plant_substeps
    for name in ("lift_motor_time_constant_s", "pusher_motor_time_constant_s"):
        tau = getattr(plant, name)
        source = f"[plant] {name}"
        if tau is None:
            tau, source = getattr(vehicle.actuators, name), f"the vehicle's [actuators] {name}"
        if h > RK4_STEP_PER_TIME_CONSTANT_MAX * tau:
            need = math.ceil(scenario.dt_control_s / (RK4_STEP_PER_TIME_CONSTANT_MAX * tau))
            raise ConfigError(f"{where}: plant_substeps = {scenario.plant_substeps}: the plant's RK4 step "
                              f"dt_control_s / plant_substeps = {h:g} s is unstable for {source} = {tau:g} s; "
                              f"allowed: plant_substeps >= {need} (a step of at most "
                              f"{RK4_STEP_PER_TIME_CONSTANT_MAX:g} time constants)")


def experiment_runs(scenario: Scenario, variants: int | None = None) -> list[Scenario]:
    """Every run ``vtoladapt run`` flies for ``scenario``: the experiment's (one, one per compared
    controller, or the convergence study's) and, for an experiment with ``variants`` > 1 (default
    ``[experiment] variants``), the same for every seeded variant (each has its own plant draw)."""
    from .experiments.distribution import convergence_runs, variant_seeds

    def runs_of(sc: Scenario) -> list[Scenario]:
        kind = sc.experiment.kind
        if kind == "comparison":
            return [replace(sc, controller=replace(sc.controller, kind=cid)) for cid in sc.experiment.controllers]
        if kind == "convergence":
            return convergence_runs(sc)
        return [sc]

    runs = runs_of(scenario)
    n = scenario.experiment.variants if variants is None else variants
    if scenario.experiment.kind != "single" and n > 1:
        for seed in variant_seeds(scenario.seed, n):
            runs += runs_of(replace(scenario, seed=seed))
    return runs


def check_experiment(scenario: Scenario, where: str, variants: int | None = None) -> None:
    """:func:`check_flyable` for every run of :func:`experiment_runs`; the message names the run."""
    check_all(((sc, _run_name(sc, scenario, where)) for sc in experiment_runs(scenario, variants)))


def check_all(runs: Iterable[tuple[Scenario, str]]) -> None:
    """:func:`check_flyable` for each ``(scenario, where)``; a run identical to one checked is skipped."""
    seen = set()
    for sc, where in runs:
        if sc in seen:
            continue
        seen.add(sc)
        check_flyable(sc, where)


def _run_name(run: Scenario, scenario: Scenario, where: str) -> str:
    parts = []
    if scenario.experiment.kind == "comparison":
        parts.append(f"controller {run.controller.kind!r}")
    if run.seed != scenario.seed:
        parts.append(f"seed {run.seed}")
    return f"{where} ({', '.join(parts)})" if parts else where
