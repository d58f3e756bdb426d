"""Benchmarks of the controller step: through the Python API, and inside a compiled loop.

Targets (issue 4): one ``composite`` step through ``Controller.step`` <= 10 us median; the same
step inside an njit loop <= 2 us; with the learned basis (issue 23) <= 3 us; the composite law's Kalman form
with the learned basis (issue 34) <= 3 us.

Operating point: hover facing a 9 m/s headwind at the wing solution's attitude (adaptation, wing
attitude and allocation all active). The accelerometer reading is made consistent with the
controller's own model at its own command (as if the plant were the model), and the controller
is settled for 1000 ticks first, so theta-hat sits inside its bounds (the typical case). A second
row times the worst case: an inconsistent reading that drives all eight parameters onto their
bounds, so the projection runs every tick.

Each row is the median over repeats of the mean time per step. ``*_cpu`` rows use process CPU
time (robust to other jobs on a shared machine), the others wall time.
"""
from __future__ import annotations

import time

import numpy as np
from numba import njit

import vtoladapt
from vtoladapt import forces
from vtoladapt import layout as L
from vtoladapt.control import Controller, ControllerConfig, Measurement, Reference
from vtoladapt.control.laws.composite import CompositeSettings
from vtoladapt.control.laws.composite_indi import CompositeIndiSettings
from vtoladapt.control.step import (controller_functions, controller_initial_state, controller_params, controller_step,
                                    diagnostics_size)
from vtoladapt.sim.allocation import ALLOC_WORK_SIZE, allocate, allocator_params


def _operating_point(veh, consistent: bool = True):
    pitch = np.radians(15.0)
    q = np.array([np.cos(pitch / 2), 0.0, np.sin(pitch / 2), 0.0])
    v_i_B = 9.0 * np.array([np.cos(pitch), 0.0, np.sin(pitch)])
    meas = Measurement.from_parts(p_W=(0.01, -0.02, -1.49), v_W=(0.02, 0.0, -0.01), q_WB=q,
                                  omega_B=(0.01, -0.02, 0.005), accel_B=(-0.5, 0.02, -9.7), v_i_B=v_i_B)
    ref = Reference.hold((0.0, 0.0, -1.5))
    if consistent:
        ctrl = Controller(veh, ControllerConfig())
        f = np.empty(3)
        for k in range(1000):
            cmd = ctrl.step(0.004 * k, meas, ref)
            forces.body_force(v_i_B, cmd.u_x, cmd.u_z, veh.theta_scaled, veh.model_kernel, f)
            meas.accel_B = f
    return meas, ref


# Not cached: Numba would reuse a cached loop, with the controller compiled into it, until this
# file changes, however the package changes (the package's own cache guard does not reach here).
@njit
def _loop(fns, params, state, meas, ref, dt, cmd, diag, n) -> float:
    acc = 0.0
    a0 = meas[L.MEAS_ACCEL_B]
    for k in range(n):
        meas[L.MEAS_ACCEL_B] = a0 + 1e-6 * (k % 7)   # vary an input so nothing is hoisted
        controller_step(fns, params, state, meas, ref, dt, cmd, diag)
        acc += cmd[1]
    meas[L.MEAS_ACCEL_B] = a0
    return acc


@njit(_nrt=False)
def _fc_loop(fns, params, state, meas, ref, dt, cmd, diag, alloc_p, act, work, n) -> float:
    """The flight computer's tick without the plant: the controller step, then the allocator."""
    for _ in range(n):
        controller_step(fns, params, state, meas, ref, dt, cmd, diag)
        allocate(cmd, meas, alloc_p, act, work, 0)
    return cmd[0]


def _median_per_call(fn, n_inner: int, repeats: int, clock=time.perf_counter) -> float:
    times = []
    for _ in range(repeats):
        t0 = clock()
        fn(n_inner)
        times.append((clock() - t0) / n_inner)
    return float(np.median(times))


def _settled_state(veh, kind, meas, ref, n=1000, basis=None, law=None):
    config = ControllerConfig(kind=kind, basis=basis) if law is None else ControllerConfig(kind=kind, basis=basis,
                                                                                           **{kind: law})
    params = controller_params(config, veh)
    state = controller_initial_state(params)
    cmd = np.zeros(L.CMD_SIZE)
    diag = np.zeros(diagnostics_size(params))
    fns = controller_functions(params)
    _loop(fns, params, state, meas.array, ref.array, 0.004, cmd, diag, n)
    return fns, params, state, cmd, diag


def run() -> list[tuple[str, float, str]]:
    veh = vtoladapt.load_vehicle("caltech_vtol")
    meas, ref = _operating_point(veh)
    rows = []

    ctrl = Controller(veh, ControllerConfig(kind="composite"))
    clock_t = [0.0]

    def api_steps(n):
        step = ctrl.step
        tt = clock_t[0]
        for _ in range(n):
            tt += 0.004
            step(tt, meas, ref)
        clock_t[0] = tt

    api_steps(1000)
    rows.append(("composite_step_python_api_median", 1e6 * _median_per_call(api_steps, 2000, 15), "us"))
    rows.append(("composite_step_python_api_median_cpu",
                 1e6 * _median_per_call(api_steps, 2000, 15, time.process_time), "us"))

    m = meas.array.copy()
    r = ref.array.copy()
    for kind in ("composite", "composite_pconst", "tracking_only", "pid", "pd"):
        fns, params, state, cmd, diag = _settled_state(veh, kind, meas, ref)

        def loop(n, fns=fns, params=params, state=state, cmd=cmd, diag=diag):
            _loop(fns, params, state, m, r, 0.004, cmd, diag, n)

        rows.append((f"{kind}_step_njit_loop_median", 1e6 * _median_per_call(loop, 20000, 15), "us"))
        rows.append((f"{kind}_step_njit_loop_median_cpu",
                     1e6 * _median_per_call(loop, 20000, 15, time.process_time), "us"))

    # issue #23: the same step adapting the extended physics basis (13) and the learned one (13 + h; target <= 3 us)
    for basis in ("extended", "learned"):
        fns, params, state, cmd, diag = _settled_state(veh, "composite", meas, ref, basis=basis)

        def loop(n, fns=fns, params=params, state=state, cmd=cmd, diag=diag):
            _loop(fns, params, state, m, r, 0.004, cmd, diag, n)

        rows.append((f"composite_{basis}_basis_step_njit_loop_median", 1e6 * _median_per_call(loop, 20000, 15), "us"))
        rows.append((f"composite_{basis}_basis_step_njit_loop_median_cpu",
                     1e6 * _median_per_call(loop, 20000, 15, time.process_time), "us"))

    # issue #34: the composite law's Kalman form (3 x 3 innovation update, no n x n factorisation; target <= 3 us
    # with the learned basis) and composite_indi on top of it
    for kind, settings in (("composite", CompositeSettings(estimator="kalman")),
                           ("composite_indi", CompositeIndiSettings(estimator="kalman"))):
        for basis in ("paper", "learned"):
            fns, params, state, cmd, diag = _settled_state(veh, kind, meas, ref, basis=basis, law=settings)

            def loop(n, fns=fns, params=params, state=state, cmd=cmd, diag=diag):
                _loop(fns, params, state, m, r, 0.004, cmd, diag, n)

            rows.append((f"{kind}_kalman_{basis}_basis_step_njit_loop_median_cpu",
                         1e6 * _median_per_call(loop, 20000, 15, time.process_time), "us"))

    # the flight computer's step: the controller and the allocator that realises its moment, at 9 m/s,
    # surfaces on against off (the controller's law is the same; only the allocation differs)
    fns, params, state, cmd, diag = _settled_state(veh, "composite", meas, ref)
    act = np.zeros(L.N_ACTUATORS)
    work = np.zeros(ALLOC_WORK_SIZE)
    per = {}
    for surfaces in (True, False):
        ap = allocator_params(veh, surfaces=surfaces)
        _fc_loop(fns, params, state, m, r, 0.004, cmd, diag, ap, act, work, 10)
        per[surfaces] = 1e6 * _median_per_call(
            lambda n, ap=ap: _fc_loop(fns, params, state, m, r, 0.004, cmd, diag, ap, act, work, n), 20000, 15,
            time.process_time)
        rows.append((f"composite_step_plus_allocation_surfaces_{'on' if surfaces else 'off'}_median_cpu",
                     per[surfaces], "us"))
    rows.append(("step_plus_allocation_surfaces_on_over_off", per[True] / per[False], "ratio"))

    bad, _ = _operating_point(veh, consistent=False)
    fns, params, state, cmd, diag = _settled_state(veh, "composite", bad, ref, n=5000)
    mb = bad.array.copy()
    rows.append(("composite_step_njit_loop_all_bounds_active_median_cpu",
                 1e6 * _median_per_call(lambda n: _loop(fns, params, state, mb, r, 0.004, cmd, diag, n),
                                        20000, 15, time.process_time), "us"))
    return rows


if __name__ == "__main__":
    for name, value, unit in run():
        print(f"{name:58s} {value:8.3f} {unit}")
