"""The JSBSim plant engine beside the native one, in the same run: closed-loop real-time factors.

The scenario is :mod:`bench_sim`'s (composite controller, every sensor, Dryden turbulence, the fan ramping
to 70 %), shortened to 10 s because the JSBSim loop is Python around JSBSim; both engines fly it at a 1 kHz
plant, after a warm-up run of each (kernels loaded, JSBSim's aircraft written once per run as in use), best
of three by wall time and by process CPU time. The ratio native / JSBSim is what a shared machine reports
fairly. Without the optional dependency jsbsim the module reports the native rows only.
"""
from __future__ import annotations

import time
from dataclasses import replace

from bench_sim import SCENARIO

DURATION_S = 10.0


def _best(scenario, simulate) -> tuple[float, float]:
    walls, cpus = [], []
    for _ in range(3):
        t0 = time.perf_counter()
        c0 = time.process_time()
        simulate(scenario)
        cpus.append(time.process_time() - c0)
        walls.append(time.perf_counter() - t0)
    return min(walls), min(cpus)


def run() -> list[tuple[str, float, str]]:
    """Rows ``(name, value, unit)`` for ``benchmarks/run_benchmarks.py``."""
    from vtoladapt.sim.driver import simulate
    from vtoladapt.sim.jsbsim_engine import jsbsim_available
    from vtoladapt.sim.scenario import scenario_from_mapping

    base = scenario_from_mapping({**SCENARIO, "duration_s": DURATION_S}, "bench_jsbsim")
    engines = ("native", "jsbsim") if jsbsim_available() else ("native",)
    rows = []
    cpu_of = {}
    for engine in engines:
        sc = replace(base, plant=replace(base.plant, engine=engine))
        simulate(replace(sc, duration_s=1.0))  # warm-up
        wall, cpu = _best(sc, simulate)
        cpu_of[engine] = cpu
        rows.append((f"{DURATION_S:g} s closed loop, {engine} engine, 1 kHz plant, wall time", wall * 1e3, "ms"))
        rows.append((f"real-time factor, {engine} engine", DURATION_S / wall, "x"))
        rows.append((f"real-time factor by CPU time, {engine} engine", DURATION_S / cpu, "x"))
    if "jsbsim" in cpu_of:
        rows.append(("JSBSim engine CPU time / native engine CPU time", cpu_of["jsbsim"] / cpu_of["native"], "ratio"))
    return rows


if __name__ == "__main__":
    for name, value, unit in run():
        print(f"{name:90s} {value:12.4g} {unit}")
