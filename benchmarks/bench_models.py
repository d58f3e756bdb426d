"""Benchmarks of the force model: one evaluation from Python, and the kernels inside a compiled loop.

Operating point: the paper's aircraft at 9 m/s, alpha = 5 deg, u_x = 20 %, u_z = 58 % (every term of
the model active). Python-level figures are the median over batches of calls after warm-up; the
compiled figures time an njit loop that calls the kernel with a varying input (so nothing is hoisted)
and divide by the number of calls. NumPy's ``np.cross`` on two 3-vectors, timed in the same run, is
the yardstick for "one small NumPy call" on this machine.
"""
from __future__ import annotations

import time

import numpy as np
from numba import njit

import vtoladapt
from vtoladapt import forces, models

N_BATCH = 200          # calls per timed batch (Python level)
N_REPEATS = 101        # batches; the median is reported
N_COMPILED = 200_000   # calls per compiled loop
N_COMPILED_REPEATS = 15


def _median_per_call_s(fn, n_inner: int = N_BATCH, repeats: int = N_REPEATS) -> float:
    fn(n_inner)  # warm-up (and compilation)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(n_inner)
        times.append((time.perf_counter() - t0) / n_inner)
    return float(np.median(times))


@njit
def _loop_body_force(v, u_x, u_z, theta, model, n) -> float:
    out = np.empty(3)
    acc = 0.0
    for k in range(n):
        v[0] = 8.9 + 1e-3 * (k & 7)
        forces.body_force(v, u_x, u_z, theta, model, out)
        acc += out[2]
    return acc


@njit
def _loop_regressor(v, u_x, u_z, model, n) -> float:
    Phi = np.empty((3, 8))
    acc = 0.0
    for k in range(n):
        v[0] = 8.9 + 1e-3 * (k & 7)
        forces.regressor(v, u_x, u_z, model, Phi)
        acc += Phi[2, 7]
    return acc


@njit
def _loop_jacobian(v, u_x, u_z, theta, model, n) -> float:
    J_v = np.empty((3, 3))
    J_u = np.empty((3, 2))
    acc = 0.0
    for k in range(n):
        v[0] = 8.9 + 1e-3 * (k & 7)
        forces.body_force_jacobian(v, u_x, u_z, theta, model, J_v, J_u)
        acc += J_v[0, 0]
    return acc


def run() -> list[tuple[str, float, str]]:
    veh = vtoladapt.load_vehicle("caltech_vtol")
    a = np.radians(5.0)
    v = 9.0 * np.array([np.cos(a), 0.0, np.sin(a)])
    ux_pct, uz_pct = 20.0, 58.0
    theta, model = veh.theta_scaled.copy(), veh.model_kernel.copy()

    def py_body_force(n):
        f = models.body_force
        for _ in range(n):
            f(v, ux_pct, uz_pct, veh)

    def py_regressor(n):
        f = models.regressor
        for _ in range(n):
            f(v, ux_pct, uz_pct, veh)

    x, y = np.array([1.0, 2.0, 3.0]), np.array([-0.5, 0.25, 2.0])

    def py_cross(n):
        c = np.cross
        for _ in range(n):
            c(x, y)

    t_cross = _median_per_call_s(py_cross)
    t_bf = _median_per_call_s(py_body_force)
    t_phi = _median_per_call_s(py_regressor)

    vv = v.copy()
    compiled = {
        "forces.body_force in njit loop": lambda n: _loop_body_force(vv, 0.2, 0.58, theta, model, n),
        "forces.regressor in njit loop": lambda n: _loop_regressor(vv, 0.2, 0.58, model, n),
        "forces.body_force_jacobian in njit loop":
            lambda n: _loop_jacobian(vv, 0.2, 0.58, theta, model, n),
    }
    rows = [
        ("np.cross (two 3-vectors), yardstick", t_cross * 1e6, "us/call"),
        ("models.body_force from Python", t_bf * 1e6, "us/call"),
        ("models.regressor from Python", t_phi * 1e6, "us/call"),
    ]
    for name, fn in compiled.items():
        rows.append((name, _median_per_call_s(fn, N_COMPILED, N_COMPILED_REPEATS) * 1e9, "ns/call"))
    rows += [
        ("models.body_force / np.cross", t_bf / t_cross, "ratio"),
        ("models.regressor / np.cross", t_phi / t_cross, "ratio"),
        ("compiled body_force / np.cross", rows[3][1] * 1e-9 / t_cross, "ratio"),
    ]
    return rows


if __name__ == "__main__":
    for row in run():
        print(f"{row[0]:<45s} {row[1]:>10.4g} {row[2]}")
