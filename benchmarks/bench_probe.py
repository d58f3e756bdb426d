"""Per-call cost of the probe kernels inside compiled loops.

``run()`` returns ``(name, value, unit)`` rows: the median over repeats of the time per call of
``incident_velocity_from_pressures`` (single-k and calibrated models) and of
``probe_differential_pressures``, each called in an ``njit`` loop with inputs that change every
call (so nothing is hoisted). Runs in a few seconds (plus Numba compilation on a cold cache).
"""
from __future__ import annotations

import time

import numpy as np
from numba import njit

from vtoladapt.probe import (
    ProbeTip,
    incident_velocity_from_pressures,
    probe_differential_pressures,
    simulate_calibration_sweep,
)
from vtoladapt.probe.calibration import fit_single_k, fit_spline_calibration


@njit
def _loop_estimate(q, rho, calibration, n_calls):
    out = np.empty(3)
    acc = 0.0
    m = q.shape[0]
    for i in range(n_calls):
        ok = incident_velocity_from_pressures(q[i % m], rho, calibration, out)
        acc += out[0] + out[2] + (1.0 if ok else 0.0)
    return acc


@njit
def _loop_forward(v, rho, tip, n_calls):
    out = np.empty(3)
    acc = 0.0
    m = v.shape[0]
    for i in range(n_calls):
        probe_differential_pressures(v[i % m], rho, tip, out)
        acc += out[0] + out[1] + out[2]
    return acc


def _median_us_per_call(fn, args, n_calls: int, repeats: int) -> float:
    fn(*args[:-1], 10)  # compile / warm up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(*args[:-1], n_calls)
        times.append((time.perf_counter() - t0) / n_calls * 1e6)
    return float(np.median(times))


def run() -> list[tuple[str, float, str]]:
    """Time the probe kernels; return ``(name, microseconds per call, "us/call")`` rows."""
    rng = np.random.default_rng(1)
    tip = ProbeTip()
    data = simulate_calibration_sweep(tip, rng, n_rings=10, n_test=200)
    single_k = fit_single_k(data).to_kernel()
    spline = fit_spline_calibration(data, smoothing=1e-8).to_kernel()
    q = np.ascontiguousarray(data.q_Pa)
    v = np.ascontiguousarray(data.v_i_B)
    n_calls, repeats = 200_000, 15
    rows = [
        ("probe.incident_velocity_from_pressures[single_k]",
         _median_us_per_call(_loop_estimate, (q, 1.225, single_k, n_calls), n_calls, repeats),
         "us/call"),
        ("probe.incident_velocity_from_pressures[calibrated]",
         _median_us_per_call(_loop_estimate, (q, 1.225, spline, n_calls), n_calls, repeats),
         "us/call"),
        ("probe.probe_differential_pressures",
         _median_us_per_call(_loop_forward, (v, 1.225, tip.to_kernel(), n_calls), n_calls,
                             repeats),
         "us/call"),
    ]
    return rows


if __name__ == "__main__":
    for name, value, unit in run():
        print(f"{name:<55} {value:10.4f} {unit}")
