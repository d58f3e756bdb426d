"""Closed-loop simulation speed, and start-up time of ``vtoladapt run``.

* in-process: 60 s simulated with the composite controller, every sensor on (pressure probe), Dryden
  turbulence on; hover, then the fan ramps to 70 % (10-20 s), holds, and ramps off (45-50 s);
  after a warm-up run (no start-up, no compilation): wall time and the
  real-time factor, with the plant at 1 kHz (the default) and at 250 Hz (one RK4 step per tick),
  best of five; and the same by process CPU time, which other jobs on a shared machine inflate
  far less than the wall time; at 1 kHz also with the control surfaces off (``[allocation] surfaces
  = false``: the rotors make every moment, the surfaces stay neutral), interleaved with the runs with
  them on, and the ratio on/off (a ratio is what a shared machine reports fairly);
* runs side by side (:func:`vtoladapt.sim.driver.simulate_many`, one thread per core): simulated
  seconds per wall-clock second over 8 runs;
* the loop's parts in compiled loops (per controller tick);
* ``vtoladapt run`` of a 1 s scenario as a new process: warm (kernels cached on disk) and cold
  (an empty Numba cache directory, so everything compiles).

Set ``VTOLADAPT_BENCH_COLD=0`` to skip the cold start (it takes about a minute).
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

SCENARIO = {
    "name": "bench", "vehicle": "caltech_vtol", "duration_s": 60.0, "seed": 1,
    "wind": {"fan_array": {"schedule": [[0, 0], [10, 0], [20, 70], [45, 70], [50, 0], [60, 0]]},
             "turbulence": {"enabled": True, "mean_wind_fraction": [0.05, 0.05, 0.03]}},
    "sensors": {"probe": {"model": "pressure"}},
    "controller": {"kind": "composite"},
}


def _loop_rows() -> list[tuple[str, float, str]]:
    from vtoladapt.sim.scenario import scenario_from_mapping
    from vtoladapt.sim.driver import simulate

    scenario = scenario_from_mapping(SCENARIO, "bench_sim")
    rows = []
    # surfaces on and off, interleaved (the same load on both): best of five each
    on_off = {True: [], False: []}
    for surfaces in (True, False):
        simulate(replace(scenario, duration_s=1.0, allocation=replace(scenario.allocation, surfaces=surfaces)))
    for _ in range(5):
        for surfaces in (True, False):
            sc = replace(scenario, allocation=replace(scenario.allocation, surfaces=surfaces))
            c0 = time.process_time()
            simulate(sc)
            on_off[surfaces].append(time.process_time() - c0)
    rows.append(("60 s closed loop, 1 kHz plant, surfaces off, process CPU time", min(on_off[False]) * 1e3, "ms"))
    rows.append(("closed loop CPU time, surfaces on / off (best of five each, interleaved)",
                 min(on_off[True]) / min(on_off[False]), "ratio"))
    for substeps, label in ((4, "1 kHz plant"), (1, "250 Hz plant")):
        sc = replace(scenario, plant_substeps=substeps)
        simulate(replace(sc, duration_s=1.0))  # warm-up: load or compile the kernels
        walls = []
        cpus = []
        for _ in range(5):
            t0 = time.perf_counter()
            c0 = time.process_time()
            simulate(sc)
            cpus.append(time.process_time() - c0)
            walls.append(time.perf_counter() - t0)
        wall = min(walls)
        cpu = min(cpus)
        rows.append((f"60 s closed loop, composite, all sensors+turbulence, {label}", wall * 1e3, "ms"))
        rows.append((f"real-time factor, {label}", 60.0 / wall, "x"))
        rows.append((f"60 s closed loop, {label}, process CPU time", cpu * 1e3, "ms"))
        rows.append((f"real-time factor by CPU time, {label}", 60.0 / cpu, "x"))
    return rows


def _basis_rows() -> list[tuple[str, float, str]]:
    """The same 60 s closed loop (1 kHz plant) adapting the extended and the learned basis (issue #23:
    >= 600x real time with the learned one), and the shipped learned bases' training time (recorded in
    their files when ``vtoladapt learn-basis`` made them)."""
    from vtoladapt.bases.learned import TRAINED_DIR
    from vtoladapt.bases.netfile import read_net
    from vtoladapt.sim.scenario import scenario_from_mapping
    from vtoladapt.sim.driver import simulate

    rows = []
    for basis in ("extended", "learned"):
        sc = scenario_from_mapping({**SCENARIO, "controller": {"kind": "composite", "basis": basis}}, "bench_sim")
        simulate(replace(sc, duration_s=1.0))
        walls, cpus = [], []
        for _ in range(5):
            t0 = time.perf_counter()
            c0 = time.process_time()
            simulate(sc)
            cpus.append(time.process_time() - c0)
            walls.append(time.perf_counter() - t0)
        rows.append((f"real-time factor, 1 kHz plant, {basis} basis", 60.0 / min(walls), "x"))
        rows.append((f"real-time factor by CPU time, 1 kHz plant, {basis} basis", 60.0 / min(cpus), "x"))
    for path in sorted(TRAINED_DIR.glob("*.npz")):
        s = read_net(path).meta["summary"]
        rows.append((f"training time of the shipped learned basis {path.stem} ({s['flights']} flights, "
                     f"{s['iterations']} L-BFGS iterations)", float(s["train_seconds"]), "s"))
    return rows


def _many_rows() -> list[tuple[str, float, str]]:
    """Throughput of simulate_many: 8 seeds of the 60 s run on one thread per core."""
    from vtoladapt.sim.scenario import scenario_from_mapping
    from vtoladapt.sim.driver import simulate_many

    scenario = scenario_from_mapping(SCENARIO, "bench_sim")
    runs = [replace(scenario, seed=s) for s in range(8)]
    workers = os.cpu_count() or 1
    simulate_many([replace(r, duration_s=1.0) for r in runs[:workers]])
    t0 = time.perf_counter()
    simulate_many(runs)
    wall = time.perf_counter() - t0
    return [(f"simulate_many, 8 x 60 s on {workers} threads: simulated s per wall s", 8 * 60.0 / wall, "x")]


def _part_rows() -> list[tuple[str, float, str]]:
    from numba import njit

    from vtoladapt import layout
    from vtoladapt.control.step import controller_functions, controller_step, diagnostics_size
    from vtoladapt.parts import draw
    from vtoladapt.sensors import sensors_at
    from vtoladapt.sim.driver import prepare
    from vtoladapt.sim.allocation import ALLOC_WORK_SIZE, allocate
    from vtoladapt.sim.plant import RK4_WORK_SIZE, plant_advance, plant_first_stage, plant_input
    from vtoladapt.sim.scenario import scenario_from_mapping
    from vtoladapt.wind import wind_at

    run = prepare(scenario_from_mapping(SCENARIO, "bench_sim"))

    @njit
    def plant_tick(x, m, w, p, n):
        f = np.empty(3)
        v_i = np.empty(3)
        work = np.zeros(RK4_WORK_SIZE)
        for _ in range(n):
            plant_first_stage(x, w, p, f, v_i, work)
            plant_advance(x, m, w, p, 0.001, 4, True, work)

    @njit
    def ctrl(fns, p, s, meas, ref, cmd, diag, n):
        for _ in range(n):
            controller_step(fns, p, s, meas, ref, 0.004, cmd, diag)

    # without reference counting, as the tick that calls them (the slices the inlined part calls take
    # would otherwise cost an atomic increment and decrement each)
    @njit(_nrt=False)
    def sens(table, p, s, draws, x, truth, rng, meas, n):
        for k in range(n):
            draw(rng, table, draws)
            sensors_at(table, p, s, k * 0.004, 0.004, x, truth, draws, meas)

    @njit(_nrt=False)
    def wind(table, p, s, draws, pos, rng, out, n):
        for k in range(n):
            draw(rng, table, draws)
            wind_at(table, p, s, k * 0.004, 0.004, pos, draws, out)

    @njit(_nrt=False)
    def alloc(cmd, meas, p, act, w, n):
        for _ in range(n):
            allocate(cmd, meas, p, act, w, 0)

    x = run.x0.copy()
    motors = plant_input([0.58, 0.58, 0.58, 0.58, 0.2, 0.05, -0.03, 0.02, 0.0])
    v_wind = np.array([-9.0, 0.0, 0.0])
    meas = np.zeros(layout.MEAS_SIZE)
    meas[layout.MEAS_Q_WB] = 1.0
    meas[layout.MEAS_V_I_B] = 9.0
    meas[layout.MEAS_V_I_VALID] = 1.0
    meas[layout.MEAS_ACCEL_B + 2] = -9.8
    rng = np.random.default_rng(0)
    cmd = np.zeros(layout.CMD_SIZE)
    diag = np.zeros(diagnostics_size(run.controller_params))
    out = np.zeros(layout.WIND_SIZE)
    truth = layout.TRUTH.pack(F_B=[0.0, 0.0, -9.8], V_I_B=[9.0, 0.0, 0.5])
    sensor_table, sp, _, sd = run.sensors()
    wind_table, wp, _, wd = run.wind()

    def per_call(fn, *args, n=5000):
        fn(*args, 10)
        best = np.inf
        for _ in range(5):
            t0 = time.perf_counter()
            fn(*args, n)
            best = min(best, (time.perf_counter() - t0) / n)
        return best * 1e6

    return [
        ("plant, one 4 ms tick at 1 kHz (4 RK4 steps, first stage included)", per_call(plant_tick, x, motors, v_wind, run.plant_params), "us/tick"),
        ("controller_step (composite, compiled)", per_call(ctrl, controller_functions(run.controller_params),
                                                           run.controller_params, run.controller_state,
                                                           meas, run.reference_table[0], cmd, diag), "us/tick"),
        ("allocator, a demand it meets (9 m/s flow, surfaces on)",
         per_call(alloc, np.array([0.2, 0.6, 0.05, -0.08, 0.01]), meas, run.mixer_params, np.zeros(layout.N_ACTUATORS),
                  np.zeros(ALLOC_WORK_SIZE)), "us/tick"),
        ("allocator, a demand it cannot meet (three stages)",
         per_call(alloc, np.array([0.2, 0.95, 3.0, -2.0, 1.0]), meas, run.mixer_params, np.zeros(layout.N_ACTUATORS),
                  np.zeros(ALLOC_WORK_SIZE)), "us/tick"),
        ("sensors: four channels (all on, pressure probe), draws included",
         per_call(sens, sensor_table, sp, run.sensor_state, sd, x, truth, rng, meas), "us/tick"),
        ("wind: four parts (fan + Dryden), draws included",
         per_call(wind, wind_table, wp, run.wind_state, wd, x[:3], rng, out), "us/tick"),
    ]


def _cli_start_rows() -> list[tuple[str, float, str]]:
    from vtoladapt.config import read_toml  # noqa: F401  (imports the package before timing)

    rows = []
    exe = [sys.executable, "-m", "vtoladapt.cli"]
    with tempfile.TemporaryDirectory() as tmp:
        scen = Path(tmp) / "s.toml"
        scen.write_text('name = "start"\nvehicle = "caltech_vtol"\nduration_s = 1.0\n')
        cmd = exe + ["run", str(scen), "--out", str(Path(tmp) / "out"), "--quiet"]
        subprocess.run(cmd, check=True, capture_output=True)  # make sure the on-disk cache is filled
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        rows.append(("vtoladapt run, 1 s scenario, warm start (new process)", time.perf_counter() - t0, "s"))
        if os.environ.get("VTOLADAPT_BENCH_COLD", "1") != "0":
            env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / "numba_cache"))
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True, env=env)
            rows.append(("vtoladapt run, 1 s scenario, cold start (empty Numba cache)",
                         time.perf_counter() - t0, "s"))
    return rows


def run() -> list[tuple[str, float, str]]:
    return _loop_rows() + _basis_rows() + _many_rows() + _part_rows() + _cli_start_rows()


if __name__ == "__main__":
    for name, value, unit in run():
        print(f"{name:70s} {value:10.3f} {unit}")
