"""Speed of the Gymnasium environment vtoladapt/Hold-v0: environment steps per wall-clock second.

The shipped ``gym_hold`` scenario (plant RK4 at 250 Hz, pressure probe, Dryden turbulence), in
residual mode (so every step also runs the composite controller) unless said otherwise:

* for reference, the compiled loop itself (``simulate`` of the same scenario): ticks per second;
* single environment (``HoldEnv``, the raw class, no wrappers), direct and residual mode;
* vector environment (``HoldVectorEnv``): 64 and 256 environments on one thread and on one thread
  per core, and 256 with the plant at 1 kHz; steady state (no episode ends in the timed steps);
* a whole 20 s episode of 256 environments, the autoreset of all of them included;
* the reset cost per episode (drawing and preparing its scenario, sensing tick 0);
* where a vector env-step's time goes (256 environments): the compiled batch step alone on one
  thread, and the Python around it per ``step`` call (the same call with the compiled step
  replaced by nothing).

Each rate is the best of five timed repeats: the machine is shared, and the best repeat is the
one least disturbed. CPU time per env-step (this process's CPU time, all threads, per
env-step) says what a core does while it runs and depends little on the machine's load; the
wall-clock rate on ``n`` idle cores is about ``n / (CPU time per env-step)``, and lower on a busy
machine. One env-step is one controller tick of one environment (4 ms of flight at 250 Hz).
Actions are small random residuals drawn before the clock starts.
"""
from __future__ import annotations

import os
import time

import numpy as np

REPEATS = 5


def _best_rate(step, n_steps: int, per_step: int, setup=None) -> tuple[float, float]:
    """Best of :data:`REPEATS` timings of ``n_steps`` calls of ``step(k)``: env-steps per second of
    wall-clock time and per second of this process's CPU time (all its threads).

    ``setup()``, if given, runs untimed before each repeat (a reset).
    """
    best_wall = best_cpu = 0.0
    for _ in range(REPEATS):
        if setup is not None:
            setup()
        t0, c0 = time.perf_counter(), time.process_time()
        for k in range(n_steps):
            step(k)
        best_wall = max(best_wall, n_steps * per_step / (time.perf_counter() - t0))
        best_cpu = max(best_cpu, n_steps * per_step / max(time.process_time() - c0, 1e-9))
    return best_wall, best_cpu


def _loop_rows() -> list[tuple[str, float, str]]:
    from vtoladapt.sim.scenario import load_scenario
    from vtoladapt.sim.driver import simulate

    sc = load_scenario("gym_hold")
    simulate(sc.replace(duration_s=0.5))
    wall, cpu = _best_rate(lambda k: simulate(sc), 1, sc.n_ticks)
    return [("compiled loop (simulate gym_hold, composite, 1 thread): ticks per s", wall, "1/s"),
            ("compiled loop: CPU time per tick (logging and result building included)", 1e6 / cpu, "us")]


def _single_rows() -> list[tuple[str, float, str]]:
    from vtoladapt.gym import HoldEnv
    from vtoladapt.gym.spaces import OBS_CMD

    rows = []
    n = 1000
    # direct mode flies open loop: hold the controller's first command, in a box wide enough
    # that the episode does not end within n steps of a reset
    hover = HoldEnv(residual=True).reset(seed=0)[0][OBS_CMD:OBS_CMD + 5]
    for residual in (False, True):
        env = HoldEnv(residual=residual, max_position_error_m=100.0, max_tilt_deg=180.0)
        actions = np.random.default_rng(0).uniform(-0.1, 0.1, (n, 5))
        if not residual:
            actions = np.tile(hover, (n, 1))
        rate, cpu = _best_rate(lambda k: env.step(actions[k]), n, 1, setup=lambda: env.reset(seed=0))
        name = f"single env, {'residual' if residual else 'direct'} mode"
        rows.append((f"{name}: env-steps per s", rate, "1/s"))
        rows.append((f"{name}: CPU time per env-step", 1e6 / cpu, "us"))
        env.close()
    return rows


def _vector_rows() -> list[tuple[str, float, str]]:
    from vtoladapt.gym import HoldVectorEnv
    from vtoladapt.sim.scenario import load_scenario

    cores = os.cpu_count() or 1
    rows = []
    khz = load_scenario("gym_hold").replace(plant_substeps=4)
    for num_envs, workers, steps, scenario, label in (
            (64, 1, 400, "gym_hold", ""), (64, cores, 400, "gym_hold", ""), (256, 1, 100, "gym_hold", ""),
            (256, cores, 100, "gym_hold", ""), (256, cores, 100, khz, ", plant at 1 kHz")):
        venv = HoldVectorEnv(num_envs=num_envs, workers=workers, residual=True, scenario=scenario)
        venv.reset(seed=0)
        actions = np.random.default_rng(1).uniform(-0.1, 0.1, (steps, num_envs, 5)).astype(np.float32)
        for a in actions[:10]:
            venv.step(a)
        wall, cpu = _best_rate(lambda k: venv.step(actions[k]), steps, num_envs)
        name = f"vector env, {num_envs} envs on {workers} thread(s){label}"
        rows.append((f"{name}: env-steps per s", wall, "1/s"))
        rows.append((f"{name}: CPU time per env-step", 1e6 / cpu, "us"))
        venv.close()

    num_envs = 256
    venv = HoldVectorEnv(num_envs=num_envs, workers=cores, residual=True)
    t0 = time.perf_counter()
    venv.reset(seed=1)
    reset_wall = time.perf_counter() - t0
    steps = venv.max_steps + 1  # the last step autoresets every environment
    zero = np.zeros((num_envs, 5), dtype=np.float32)
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(steps):
        venv.step(zero)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    venv.close()
    name = f"vector env, {num_envs} envs on {cores} thread(s), whole 20 s episode incl. autoreset"
    rows.append((f"{name}: env-steps per s", steps * num_envs / wall, "1/s"))
    rows.append((f"{name}: CPU time per env-step", cpu / (steps * num_envs) * 1e6, "us"))
    rows.append(("reset cost per episode (draw, prepare, sense tick 0)", reset_wall / num_envs * 1e3, "ms"))
    return rows


def _split_rows() -> list[tuple[str, float, str]]:
    from vtoladapt.gym import HoldVectorEnv
    from vtoladapt.gym.batch_kernel import OP_STEP

    num_envs, steps = 256, 100
    actions = np.random.default_rng(1).uniform(-0.1, 0.1, (steps, num_envs, 5)).astype(np.float32)
    venv = HoldVectorEnv(num_envs=num_envs, workers=1, residual=True)
    venv.reset(seed=0)
    for a in actions[:10]:
        venv.step(a)
    chunk = venv._batch.chunks[0]  # one thread: one chunk of all the environments

    def kernel_only(k):
        chunk.op[:] = OP_STEP
        chunk.run()

    _, kernel_cpu = _best_rate(kernel_only, steps, num_envs)
    venv.close()
    name = f"vector env-step split, {num_envs} envs"
    rows = [(f"{name}: compiled batch step alone, 1 thread, CPU time per env-step", 1e6 / kernel_cpu, "us")]
    for workers in sorted({1, os.cpu_count() or 1}):
        venv = HoldVectorEnv(num_envs=num_envs, workers=workers, residual=True)
        venv.reset(seed=0)
        for c in venv._batch.chunks:
            c.run = lambda: None  # what remains of step() is the Python (and thread hand-off) around it
        wall, python_cpu = _best_rate(lambda k: venv.step(actions[k]), steps, 1)
        venv.close()
        rows.append((f"{name}: Python around it, {workers} thread(s), CPU time per step call", 1e6 / python_cpu, "us"))
        rows.append((f"{name}: Python around it, {workers} thread(s), wall time per step call", 1e6 / wall, "us"))
    return rows


def run() -> list[tuple[str, float, str]]:
    """Rows ``(name, value, unit)`` for ``benchmarks/run_benchmarks.py``."""
    return _loop_rows() + _single_rows() + _vector_rows() + _split_rows()


if __name__ == "__main__":
    for name, value, unit in run():
        print(f"{name:90s} {value:12.4g} {unit}")
