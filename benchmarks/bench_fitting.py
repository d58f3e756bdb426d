"""Benchmarks of the fitting feature.

Rows:

* ``table1_fit_wall_s``: a full Table I fit (all eight coefficients plus k1, k2, and the noise)
  of the default virtual-tunnel data set (caltech_vtol, seed 0, 511 rows) with the default
  sampler settings, until converged (R-hat < 1.01, chain > 50 tau). Target: < 60 s on the
  2-core machine. Median of 2 runs after a short warm-up fit (each run is several seconds,
  so more would break the 30 s budget of a benchmark file).
* ``table1_fit_cpu_s``: the same, process CPU time (robust to other jobs on a shared machine).
* ``regressor_rows_throughput``: rows per second of :func:`vtoladapt.forces.regressor_rows`
  (the control regressor the fit uses), 10 000 random rows, median of 20 calls.
* ``table1_logpost_per_walker_us``: one log-posterior evaluation (sufficient statistics of the
  sparse regressor + 8x8 Cholesky) per walker, 16 walkers per call, median of 50 calls.
"""
from __future__ import annotations

import time

import numpy as np

import vtoladapt
from vtoladapt import forces
from vtoladapt.fitting import bayes, tunnel


def _median_time(fn, n):
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def run() -> list[tuple[str, float, str]]:
    veh = vtoladapt.load_vehicle("caltech_vtol")
    rows = []
    data = tunnel.run_virtual_tunnel(veh, np.random.default_rng(0), seed=0).data
    bayes.fit_table1(data, veh, np.random.default_rng(1), settings=bayes.SamplerSettings.fast())
    wall, cpu = [], []
    for seed in (1, 2):
        t0, c0 = time.perf_counter(), time.process_time()
        fit = bayes.fit_table1(data, veh, np.random.default_rng(seed))
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        if not fit.marginal.converged:
            rows.append(("table1_fit_not_converged_seed", float(seed), "-"))
    rows.append(("table1_fit_wall_s", float(np.median(wall)), "s"))
    rows.append(("table1_fit_cpu_s", float(np.median(cpu)), "s"))

    rng = np.random.default_rng(0)
    n = 10_000
    v = rng.normal(0.0, 6.0, (n, 3))
    ux, uz = rng.random(n), rng.random(n)
    model = veh.model_kernel
    forces.regressor_rows(v[:10], ux[:10], uz[:10], model)
    t = _median_time(lambda: forces.regressor_rows(v, ux, uz, model), 20)
    rows.append(("regressor_rows_throughput", n / t, "rows/s"))

    td = bayes.prepare_table1_data(data, veh)
    problem = bayes.table1_problem(td)
    phi = np.tile([1.42, 3.2, -1.7, 0.0105], (16, 1)) + 1e-3 * rng.standard_normal((16, 4))
    problem.log_posterior(phi)
    t = _median_time(lambda: problem.log_posterior(phi), 50)
    rows.append(("table1_logpost_per_walker_us", t / 16 * 1e6, "us"))
    return rows


if __name__ == "__main__":
    for name, value, unit in run():
        print(f"{name:34s} {value:14.4g} {unit}")
