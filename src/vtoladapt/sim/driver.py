"""Run a scenario: build the kernel arrays once, run the compiled loop, return a typed result."""
from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from typing import Callable, Optional, Sequence

import numpy as np

from .. import layout
from .._numba_abi import has_disk_cache
from ..config import ConfigError
from ..errors import check_interrupt
from ..frames import quat_from_euler
from ..layout import BlockLayout
from ..parts import Assembly
from .mixer import mixer_params
from .plant import PlantConfig, hover_trim_motor
from .results import SimulationResult
from .scenario import Scenario
from ..vehicle import Vehicle

ProgressCallback = Callable[[float, float], None]
"""Called as ``progress(simulated_s, duration_s)`` between chunks of a run."""

CHUNK_S = 5.0


def chunk_ticks(dt_s: float) -> int:
    """Ticks per chunk of :func:`simulate` (about :data:`CHUNK_S` of flight): the loop returns to Python
    between chunks (progress, Ctrl-C), and chunk ``c`` times its ticks from ``c chunk dt``
    (:func:`vtoladapt.sim.loop.tick_time`)."""
    return max(1, int(round(CHUNK_S / dt_s)))


@dataclass
class PreparedRun:
    """Everything the compiled loop needs for one scenario, as plain arrays (built once).

    ``wind_parts`` and ``sensor_parts`` are the run's wind parts and sensor channels
    (:class:`vtoladapt.parts.Assembly`: their parameter layout and the table the loop calls them
    through); their parameter and state arrays are ``wind_params``, ``wind_state``,
    ``sensor_params``, ``sensor_state``. ``controller_fns`` holds the addresses of the controller's law
    ``update`` and basis ``regressor`` (:func:`vtoladapt.control.step.function_table`; they live
    in their modules for the process). ``log_layout`` is the layout of the run's log
    rows (:func:`vtoladapt.sim.loop.log_layout`).
    """

    scenario: Scenario
    vehicle: Vehicle
    x0: np.ndarray
    plant_params: np.ndarray
    mixer_params: np.ndarray
    controller_params: np.ndarray
    controller_state: np.ndarray
    controller_fns: np.ndarray
    wind_parts: Assembly
    wind_params: np.ndarray
    wind_state: np.ndarray
    sensor_parts: Assembly
    sensor_params: np.ndarray
    sensor_state: np.ndarray
    reference_table: np.ndarray
    fault_schedule: np.ndarray
    fault_state: np.ndarray
    envelope: np.ndarray
    theta_true: np.ndarray
    gamma: float
    rng: np.random.Generator
    prior_description: str
    plant_coefficients: dict
    log_layout: BlockLayout
    basis_id: str = "paper"
    plant_config: Optional[PlantConfig] = None
    """The run's resolved plant config (draws made concrete): what the JSBSim engine writes its aircraft from."""
    jsbsim_plant: Optional[object] = None
    """The run's :class:`vtoladapt.sim.jsbsim_engine.JSBSimPlant`, made at its first chunk (``[plant] engine =
    "jsbsim"``); None on the native engine."""

    def scratch(self) -> tuple:
        """Fresh scratch of a tick: ``(truth, meas, cmd, diag, motor_cmd, work)``, zeros (the loop's
        ``scratch`` argument; a new one per chunk of ticks)."""
        from .loop import TICK_WORK_SIZE, diagnostics_columns

        return (np.zeros(layout.TRUTH_SIZE), np.zeros(layout.MEAS_SIZE), np.zeros(layout.CMD_SIZE),
                np.zeros(len(diagnostics_columns(self.controller_params))), np.zeros(layout.PLANT_INPUT_SIZE),
                np.zeros(TICK_WORK_SIZE))

    def wind(self) -> tuple:
        """The loop's ``wind`` argument: ``(table, params, state, draws)`` (fresh draws scratch)."""
        return self.wind_parts.table, self.wind_params, self.wind_state, np.zeros(self.wind_parts.draws_size)

    def sensors(self) -> tuple:
        """The loop's ``sensors`` argument: ``(table, params, state, draws)`` (fresh draws scratch)."""
        return self.sensor_parts.table, self.sensor_params, self.sensor_state, np.zeros(self.sensor_parts.draws_size)


def prepare(scenario: Scenario) -> PreparedRun:
    """Convert a validated scenario into kernel arrays. All random draws come from the scenario seed.

    The draws, in order: a random initial theta-hat (if asked), the sensor channels' initial states
    (the IMU biases; the pressure probe's offsets), the wind parts' (the turbulence's stationary
    start); then the loop's, tick by tick.
    """
    from ..control.api import controller_arrays
    from ..control.trajectory import trajectory_from_reference
    from ..sensors import SensorContext
    from .faults import SURFACE_KINDS, faults_to_kernel
    from .loop import diagnostics_columns, log_layout
    from ..bases import truth_of
    from ..control.step import controller_functions, function_table

    vehicle = scenario.load_vehicle()
    if scenario.plant.engine == "jsbsim":
        from .jsbsim_engine import require_jsbsim

        require_jsbsim(scenario.source_path or f"scenario {scenario.name!r}")
    try:
        plant = scenario.plant.resolved(vehicle, scenario.seed)
    except ConfigError as exc:  # a per-surface list of another length than the vehicle's surfaces
        raise ConfigError(f"{scenario.source_path or f'scenario {scenario.name!r}'}: {exc}") from None
    rng = np.random.default_rng(scenario.seed)
    ctrl_vehicle, theta0, P0_diag, lower, upper, prior_description = controller_prior(scenario, vehicle)
    basis = controller_basis(scenario, ctrl_vehicle)
    theta_init = None
    if scenario.controller_prior.initial_theta == "random":
        frac = scenario.controller_prior.random_fraction
        theta_init = np.clip(theta0 * (1.0 + frac * rng.uniform(-1.0, 1.0, size=theta0.shape)), lower, upper)
    where = scenario.source_path or f"scenario {scenario.name!r}"
    # the controller's checks and nominal tick assume its loop rate: it must be the rate the run steps it at
    scenario.check_loop_rate(where)
    try:
        ctrl_params, ctrl_state = controller_arrays(
            ctrl_vehicle, scenario.controller, theta_0=theta0, P0_diag=P0_diag, theta_lower=lower,
            theta_upper=upper, theta_init=theta_init, basis=basis)
    except ConfigError as exc:  # a rule needing the prior (the sigma step's P0): the scenario's mistake
        raise ConfigError(f"{where}: {exc}") from None
    ic = scenario.initial
    motors = hover_trim_motor(vehicle, plant) if ic.trimmed_motors else np.zeros(layout.N_MOTORS)
    q0 = quat_from_euler(np.radians(ic.yaw_deg), np.radians(ic.pitch_deg), np.radians(ic.roll_deg))
    x0 = layout.pack_state(ic.position_m, ic.velocity_mps, q0, (0.0, 0.0, 0.0), motors)
    plant_density = plant.air_density_kgpm3 or vehicle.envelope.air_density_kgpm3  # the resolved truth (a draw)
    sensor_parts = scenario.sensors.assemble(SensorContext(plant_density, vehicle.envelope.air_density_kgpm3,
                                                           scenario.base_dir))
    wind_parts = scenario.wind.assemble()
    times = np.arange(scenario.n_ticks) * scenario.dt_control_s
    reference = trajectory_from_reference(scenario.reference).reference_table(times)
    sensor_state = sensor_parts.initial_state(rng)
    wind_state = wind_parts.initial_state(rng)
    for i, f in enumerate(scenario.faults):
        if f.kind in SURFACE_KINDS and f.surface > len(vehicle.surfaces):
            n = len(vehicle.surfaces)
            allowed = f"1 to {n}" if n else "no surface fault (the vehicle has no [[surfaces]])"
            raise ConfigError(f"{where}: [faults][{i}] {f.kind}: surface = {f.surface}: {vehicle.name} has "
                              f"{n} control surfaces; allowed: {allowed}")
    fault_schedule, fault_state = faults_to_kernel(scenario.faults, scenario.dt_control_s)
    mixer = allocation_params(scenario, ctrl_vehicle, where)
    # the plant's truth in the controller's basis, for the logged Lyapunov function only (empty where the
    # basis has none: the function's parameter term is then left out)
    theta_true = truth_of(basis, plant.true_coefficients(vehicle))
    return PreparedRun(
        scenario=scenario, vehicle=vehicle, x0=x0, fault_schedule=fault_schedule, fault_state=fault_state,
        envelope=scenario.envelope.to_kernel(),
        plant_params=plant.to_kernel(vehicle), mixer_params=mixer,
        controller_params=ctrl_params, controller_state=ctrl_state,
        controller_fns=function_table(controller_functions(ctrl_params)),
        wind_parts=wind_parts, wind_params=wind_parts.params, wind_state=wind_state,
        sensor_parts=sensor_parts, sensor_params=sensor_parts.params, sensor_state=sensor_state,
        reference_table=reference, theta_true=np.zeros(0) if theta_true is None else theta_true,
        gamma=scenario.controller.gamma, rng=rng, prior_description=prior_description,
        plant_coefficients=plant.true_coefficients(vehicle), log_layout=log_layout(diagnostics_columns(ctrl_params)),
        basis_id=basis.id, plant_config=plant)


def allocation_params(scenario: Scenario, vehicle: Vehicle, where: str) -> np.ndarray:
    """The flight computer's allocator parameters: the scenario's ``[allocation]`` (its effectiveness, else
    the vehicle file's) on the controller's ``vehicle``; an unknown effectiveness is the file's mistake."""
    from .allocation import EFFECTIVENESS

    al = scenario.allocation
    eid = al.effectiveness or vehicle.effectiveness
    if eid not in EFFECTIVENESS:
        field = "[allocation] effectiveness" if al.effectiveness else f"{vehicle.source_path or vehicle.name}: effectiveness"
        raise ConfigError(f"{where}: {field} = {eid!r}: unknown; allowed: "
                          + ", ".join(repr(i) for i in EFFECTIVENESS.ids()))
    return mixer_params(vehicle, al.surfaces, eid, al.method, al.airmode)


def controller_basis(scenario: Scenario, vehicle: Vehicle):
    """The force-model basis the controller adapts (:class:`vtoladapt.bases.BasisSpec`): the scenario's
    ``[controller] basis``, else the vehicle's; an unknown id is the scenario file's mistake."""
    from ..bases import describe_basis

    try:
        return describe_basis(vehicle, scenario.controller.basis)
    except ConfigError as exc:
        where = scenario.source_path or f"scenario {scenario.name!r}"
        raise ConfigError(f"{where}: {exc}") from None


def controller_prior(scenario: Scenario, vehicle: Vehicle):
    """The flight computer's model: ``(vehicle, theta_0, P0 diagonal, lower, upper, description)``.

    Without a posterior it is the basis's prior for the vehicle (the paper's: Table I, Table III).
    With one, the vehicle's force model becomes the posterior's (its k1, k2 too, so the regressor
    and theta_0 agree) and P0 and the theta-hat bounds follow
    :func:`vtoladapt.bases.posterior.controller_prior`; the posterior must be of the controller's basis. The
    plant keeps its own truth either way.
    """
    from ..control.step import default_theta_bounds

    path = scenario.posterior_path()
    if path is None:
        basis = controller_basis(scenario, vehicle)
        theta0 = basis.theta_scaled.copy()
        lower, upper = default_theta_bounds(vehicle, theta0, basis=basis)
        return vehicle, theta0, np.array(basis.P0_diag), lower, upper, \
            f"{basis.source} (published means)"
    from ..bases.posterior import apply_posterior

    ctrl_vehicle, (theta0, P0, lower, upper) = apply_posterior(vehicle, path, basis=scenario.controller.basis)
    return ctrl_vehicle, theta0, P0, lower, upper, f"posterior {path}"


def run_chunk(run: PreparedRun, x: np.ndarray, k0: int, k1: int, log: np.ndarray) -> tuple[int, int]:
    """Advance ``run`` (state ``x``) over ticks ``k0 .. k1-1`` into ``log`` (``k1 - k0`` rows).

    Returns ``(ticks_done, reason)`` of :func:`vtoladapt.sim.loop.run_closed_loop`. Raises
    KeyboardInterrupt first if Ctrl-C was pressed (:func:`vtoladapt.errors.check_interrupt`): a
    Ctrl-C Python dropped inside a C callback still stops every caller's run at its next chunk.
    """
    from ..control.step import controller_functions
    from .loop import run_closed_loop

    check_interrupt()
    sc = run.scenario
    if sc.plant.engine == "jsbsim":
        from .jsbsim_engine import JSBSimPlant, run_chunk_jsbsim

        if run.jsbsim_plant is None:
            run.jsbsim_plant = JSBSimPlant(run.vehicle, run.plant_config, x, sc.dt_control_s / sc.plant_substeps)
        return run_chunk_jsbsim(run, run.jsbsim_plant, x, k0, k1, log)
    done, reason = run_closed_loop(
        x, run.scratch(), run.plant_params, run.mixer_params, run.wind(), run.sensors(),
        (run.fault_schedule, run.fault_state), run.envelope,
        (run.controller_fns, run.controller_params, run.controller_state), run.reference_table[k0:k1],
        k0 * sc.dt_control_s, sc.dt_control_s, sc.plant_substeps, run.rng, run.theta_true, run.gamma, log)
    return int(done), int(reason)


def simulate(scenario: Scenario, progress: Optional[ProgressCallback] = None) -> SimulationResult:
    """Run ``scenario`` and return its :class:`SimulationResult` (log and metadata).

    A run whose state leaves the scenario's ``[envelope]`` stops there: the result holds the
    ticks before it, and ``result.diverged_at_s`` / ``result.divergence_reason`` say when and why
    (:mod:`vtoladapt.sim.monitor`); nothing is raised (``result.raise_if_diverged()`` does).
    """
    from .limits import check_in_memory_runs

    check_in_memory_runs([scenario], scenario.source_path or f"scenario {scenario.name!r}")
    run = prepare(scenario)
    n = scenario.n_ticks
    log = np.empty((n, run.log_layout.size))
    x = run.x0.copy()
    chunk = chunk_ticks(scenario.dt_control_s)
    wall0 = time.perf_counter()
    n_done, reason = n, 0
    for k0 in range(0, n, chunk):
        k1 = min(n, k0 + chunk)
        done, reason = run_chunk(run, x, k0, k1, log[k0:k1])
        if reason != 0:
            n_done = k0 + done
            break
        if progress is not None:
            progress(k1 * scenario.dt_control_s, scenario.duration_s)
    if reason != 0:
        # a view, not a copy: the rows never written were never touched, so they hold no memory
        log = log[:n_done]
    metadata = run_metadata(run, x, n_done, reason, k1 - 1, time.perf_counter() - wall0)
    return SimulationResult(run.log_layout.columns, log, metadata)


def run_metadata(run: PreparedRun, x: np.ndarray, n_done: int, reason: int, k_last: int, wall: float) -> dict:
    """The metadata of a finished run (:attr:`SimulationResult.metadata`): ``n_done`` ticks, ended by
    envelope ``reason`` (0: none) with state ``x``, ``k_last`` the last tick of the chunk it ended in."""
    from ..control.step import basis_names, information_sum

    scenario = run.scenario
    diverged_at_s = None
    why = None
    if reason != 0:
        diverged_at_s = n_done * scenario.dt_control_s
        # the row the failed check read: the tick's own, or the chunk's last for the check after it
        why = scenario.envelope.describe_violation(reason, x, diverged_at_s,
                                                   run.reference_table[min(n_done, k_last)])
    return {
        "scenario": scenario.name, "scenario_path": scenario.source_path, "vehicle": run.vehicle.name,
        "controller": scenario.controller.kind, "seed": scenario.seed, "plant_engine": scenario.plant.engine,
        "basis": run.basis_id, "theta_names": list(basis_names(run.controller_params)),
        "dt_control_s": scenario.dt_control_s, "plant_substeps": scenario.plant_substeps,
        "duration_s": scenario.duration_s, "wall_time_s": wall,
        "controller_prior": run.prior_description,
        "Lambda_p": list(scenario.controller.Lambda_p),
        "velocity_correction_max_mps": scenario.controller.velocity_correction_max_mps,
        "probe_model": scenario.sensors.probe.describe(),
        "theta_true_scaled": run.theta_true.tolist(),
        "diverged_at_s": diverged_at_s, "divergence_reason": why,
        "faults": [dataclasses.asdict(f) for f in scenario.faults],
        "plant_coefficients": run.plant_coefficients,
        # the adaptation's un-forgotten information sum (identifiability; zero for non-adaptive laws)
        "information_sum": information_sum(run.controller_params, run.controller_state).tolist(),
    }


def simulate_many(scenarios: Sequence[Scenario], workers: Optional[int] = None,
                  progress: Optional[ProgressCallback] = None) -> list[SimulationResult]:
    """Run several scenarios side by side on ``workers`` threads (default: one per core).

    The compiled loop releases the GIL and every run owns its arrays and its generator (seeded
    by its own scenario), so each result is bit-identical to ``simulate(scenario)``, whatever
    the number of workers or the order the runs finish in. Results come back in the order of
    ``scenarios``. ``progress(simulated_s, total_s)`` is called with the sum over all runs.
    """
    from concurrent.futures import ThreadPoolExecutor

    from .limits import check_in_memory_runs

    scenarios = list(scenarios)
    check_in_memory_runs(scenarios, "simulate_many")  # every result is held until all are returned
    if workers is None:
        workers = os.cpu_count() or 1
    if workers < 1:
        raise ValueError(f"simulate_many: workers = {workers}: must be >= 1")
    total_s = sum(sc.duration_s for sc in scenarios)
    done_s = [0.0] * len(scenarios)
    lock = threading.Lock()

    def run(i: int) -> SimulationResult:
        def report(sim_s: float, _duration_s: float) -> None:
            with lock:
                done_s[i] = sim_s
                progress(sum(done_s), total_s)
        return simulate(scenarios[i], report if progress is not None else None)

    with ThreadPoolExecutor(max_workers=min(workers, max(1, len(scenarios)))) as pool:
        return list(pool.map(run, range(len(scenarios))))


def _controller_step_compiled() -> None:
    """Compile (or load) the controller step for the simulator loop's argument types."""
    from ..control.step import controller_functions, controller_step, diagnostics_size
    from .scenario import scenario_from_mapping

    run = prepare(scenario_from_mapping({"name": "warm-up", "vehicle": "caltech_vtol", "duration_s": 0.004},
                                        "<warm-up>"))
    meas = np.zeros(layout.MEAS_SIZE)
    meas[layout.MEAS_Q_WB] = 1.0
    p = run.controller_params
    controller_step(controller_functions(p), p, run.controller_state, meas, run.reference_table[0], 0.004,
                    np.zeros(layout.CMD_SIZE), np.zeros(diagnostics_size(p)))


def _plant_wind_sensors_compiled(run: PreparedRun) -> None:
    """Compile (or load) the plant, wind and sensor kernels for the simulator loop's argument types."""
    from ..sensors import run_sensor_model
    from ..wind import run_wind_model
    from .plant import RK4_WORK_SIZE, plant_advance, plant_first_stage

    x = run.x0.copy()
    truth = np.zeros(layout.TRUTH_SIZE)
    v_wind = truth[layout.TRUTH_V_WIND_W:layout.TRUTH_V_WIND_W + 3]
    work = np.zeros(RK4_WORK_SIZE)
    run_wind_model(run.wind_parts, run.wind_state.copy(), 1, 0.004, np.random.default_rng(0))
    plant_first_stage(x, v_wind, run.plant_params, truth[layout.TRUTH_F_B:layout.TRUTH_F_B + 3],
                      truth[layout.TRUTH_V_I_B:layout.TRUTH_V_I_B + 3], work)
    plant_advance(x, np.zeros(layout.PLANT_INPUT_SIZE), v_wind, run.plant_params, 0.001, 1, True, work)
    run_sensor_model(run.sensor_parts, run.sensor_state.copy(), 0.004, x[None, :], np.zeros((1, 3)),
                     np.zeros((1, 3)), np.random.default_rng(0))


def load_kernels(scenario: Scenario) -> None:
    """Load the simulator's compiled kernels from Numba's on-disk cache, compiling what is missing.

    Compiling everything in one process takes about a minute, so on a cold cache the controller
    step (a third of that) compiles in a second process while this one compiles the plant, wind
    and sensors; the loop, compiled last, loads the controller from the cache the other process
    wrote. On a warm cache nothing is started and only the loop's cached code is loaded.
    """
    from ..control.step import controller_step
    from .loop import run_closed_loop

    helper = None
    if not has_disk_cache(run_closed_loop) and not has_disk_cache(controller_step):
        try:
            helper = subprocess.Popen([sys.executable, "-c",
                                       "from vtoladapt.sim.driver import _controller_step_compiled as c; c()"],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        except OSError:
            helper = None  # no second process: compile everything here
    short = scenario.replace(duration_s=min(scenario.duration_s, 0.1))
    if helper is not None:
        try:
            _plant_wind_sensors_compiled(prepare(short))
            helper.wait()
        except BaseException:  # Ctrl-C or an error: the second compiler must not outlive us
            helper.kill()
            helper.wait()
            raise
    simulate(short)  # warm: loads the loop alone (its callees are linked into its cached code)
