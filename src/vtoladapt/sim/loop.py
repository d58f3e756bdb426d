"""The compiled closed-loop simulation: plant, wind, sensors, controller and mixer at 250 Hz.

Per controller tick ``k`` (time ``t = k dt``), in this order:

0. the divergence monitor checks the state against the scenario's envelope
   (:mod:`vtoladapt.sim.monitor`); outside it, the run stops before this tick;
1. the wind model advances and gives the wind at the vehicle, held over the tick;
2. the sensors sample the true state, the true specific force and the true incident flow, and the
   scenario's active sensor faults alter the measurement (:mod:`vtoladapt.sim.faults`);
3. the controller computes its command from the measurement and the reference (its output is
   held until the next tick, as on a flight computer);
4. the mixer turns the command into five motor commands (if it saturated, the controller is told the
   collective it actually sent), and the active actuator faults alter them;
5. one log row is written;
6. the plant advances by ``dt`` with ``n_sub`` fixed RK4 substeps (default 1 kHz).

Steps 1-3 are :func:`tick_sense`, steps 4-6 :func:`tick_actuate`; :func:`run_closed_loop` calls
the two in turn, and the Gymnasium environment (:mod:`vtoladapt.gym`) acts between them. The loop
sees only kernel arrays; :mod:`vtoladapt.sim.driver` builds them from a scenario.

The kernels a tick runs -- the tick functions here, the controller step and the adaptive laws'
updates, the plant, sensor, wind, mixer, fault and envelope kernels -- are compiled without Numba's
reference counting (``_nrt=False``). They allocate nothing and keep no array beyond the call, yet
Numba increments the count of every array argument on entry and decrements it on every exit, and
its pruning leaves these pairs in any function with several exits or an inlined callee: about 110
atomic increments and as many decrements per tick (counted in the LLVM IR), about 20 of them in
the controller step. A kernel compiled this way cannot allocate (``np.empty`` in it fails to
compile), so these kernels take their scratch from the caller and pass tuples between them.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..control.step import controller_lyapunov, controller_step, set_last_command
from ..forces import airflow_angles
from ..layout import (
    CMD_SIZE,
    COMMAND_COLUMNS,
    MEAS_SIZE,
    MEASUREMENT_COLUMNS,
    MOTOR_PUSHER,
    N_MOTORS,
    REF_SIZE,
    REFERENCE_COLUMNS,
    STATE_COLUMNS,
    WIND_COLUMNS,
    X_P_W,
    X_SIZE,
)
from .faults import active_mask, apply_actuator_faults, apply_measurement_faults
from .mixer import MX_U_MAX, applied_collective, mix
from .monitor import REASON_OK, check_envelope
from .plant import RK4_WORK_SIZE, plant_advance, plant_first_stage
from ..sensors import sensors_step
from ..wind import wind_step

_LOG_HEAD: tuple[str, ...] = (
    ("t_s",) + STATE_COLUMNS + WIND_COLUMNS
    + ("v_i_x_mps", "v_i_y_mps", "v_i_z_mps", "airspeed_mps", "alpha_rad", "beta_rad",
       "f_B_x_mps2", "f_B_y_mps2", "f_B_z_mps2")
    + MEASUREMENT_COLUMNS + REFERENCE_COLUMNS + COMMAND_COLUMNS
    + ("motor1_cmd_frac", "motor2_cmd_frac", "motor3_cmd_frac", "motor4_cmd_frac", "pusher_cmd_frac",
       "mixer_saturated"))
_LOG_TAIL: tuple[str, ...] = ("lyapunov_V", "faults_active")


def log_columns(diag_columns) -> tuple[str, ...]:
    """Names of a run's log columns, in order, units in the names (README, "Log columns"): the controller's
    diagnostics (``vtoladapt.control.step.diagnostics_columns`` of its parameters) are the run's law's and basis's."""
    return _LOG_HEAD + tuple(diag_columns) + _LOG_TAIL


def log_size(n_diag: int) -> int:
    """The log row's length for ``n_diag`` diagnostics columns."""
    return len(_LOG_HEAD) + n_diag + len(_LOG_TAIL)


_C_STATE = 1
_C_WIND = _C_STATE + X_SIZE
_C_VI = _C_WIND + 3
_C_FB = _C_VI + 6
_C_MEAS = _C_FB + 3
_C_REF = _C_MEAS + MEAS_SIZE
_C_CMD = _C_REF + REF_SIZE
_C_MOTOR = _C_CMD + CMD_SIZE
_C_DIAG = _C_MOTOR + N_MOTORS + 1
assert _C_DIAG == len(_LOG_HEAD)


@njit(cache=True, nogil=True, _nrt=False)
def tick_sense(x, plant_p, ctrl_fns, ctrl_p, ctrl_state, wind_p, wind_state, sens_p, sens_state, ref, t, dt, rng,
               run_controller, v_wind, f_B, v_i, meas, cmd, diag, work) -> None:
    """First half of controller tick at time ``t``: steps 1-3 of the module docstring.

    Advances the wind, evaluates the plant's first RK4 stage (true specific force ``f_B`` and
    incident flow ``v_i``, kept in ``work`` for :func:`tick_actuate`), samples the sensors into
    ``meas`` and, if ``run_controller``, runs the controller on ``meas`` and ``ref`` into ``cmd``
    and ``diag``. A caller that supplies the command itself (the Gymnasium environment's direct
    mode) passes ``run_controller=False`` and fills ``cmd`` before :func:`tick_actuate`.
    """
    wind_step(wind_p, wind_state, t, dt, x[X_P_W:X_P_W + 3], rng, v_wind)
    plant_first_stage(x, v_wind, plant_p, f_B, v_i, work)
    sensors_step(sens_p, sens_state, t, dt, x, f_B, v_i, rng, meas)
    if run_controller:
        controller_step(ctrl_fns, ctrl_p, ctrl_state, meas, ref, dt, cmd, diag)


@njit(cache=True, nogil=True, _nrt=False)
def report_mixed(ctrl_state, motor_cmd, saturated) -> None:
    """Tell the controller what the mixer sent when it saturated: the pusher throttle and the collective
    the four lift-rotor commands amount to (:func:`vtoladapt.sim.mixer.applied_collective`).

    The flight computer owns the mixer, so this is its own output, not the plant's truth (actuator
    faults act after it). A saturated mixer shifts the collective to keep roll and pitch; the
    adaptation's regressor (eq:prediction_error) must see that thrust, not the collective the
    controller asked for. Unsaturated, the two are equal and the controller's own record stands.
    """
    if saturated:
        set_last_command(ctrl_state, motor_cmd[MOTOR_PUSHER], applied_collective(motor_cmd))


@njit(cache=True, nogil=True, _nrt=False)
def tick_actuate(x, plant_p, mixer_p, ctrl_p, ctrl_state, ref, t, dt, n_sub, v_wind, f_B, v_i, meas, cmd, diag,
                 motor_cmd, work, theta_true, gamma, row) -> None:
    """Second half of the tick at time ``t``: steps 4-6 (mix ``cmd``, log, advance the plant by ``dt``).

    ``row`` is the tick's log row (length :func:`log_size`), or an empty array to skip logging.
    ``work`` must hold the first RK4 stage :func:`tick_sense` evaluated at this ``x``.
    """
    saturated = mix(cmd, mixer_p, motor_cmd)
    report_mixed(ctrl_state, motor_cmd, saturated)
    tick_log_advance(x, plant_p, ctrl_p, ctrl_state, ref, t, dt, n_sub, v_wind, f_B, v_i, meas, cmd, diag, motor_cmd,
                     saturated, 0.0, work, theta_true, gamma, row)


@njit(cache=True, nogil=True, _nrt=False)
def tick_log_advance(x, plant_p, ctrl_p, ctrl_state, ref, t, dt, n_sub, v_wind, f_B, v_i, meas, cmd, diag,
                     motor_cmd, saturated, faults_active, work, theta_true, gamma, row) -> None:
    """Steps 5-6 of the tick: log the tick into ``row`` (unless empty), advance the plant with ``motor_cmd``."""
    if row.shape[0] > 0:
        row[0] = t
        for i in range(X_SIZE):
            row[_C_STATE + i] = x[i]
        for i in range(3):
            row[_C_WIND + i] = v_wind[i]
            row[_C_VI + i] = v_i[i]
            row[_C_FB + i] = f_B[i]
        V, alpha, beta = airflow_angles(v_i)
        row[_C_VI + 3] = V
        row[_C_VI + 4] = alpha
        row[_C_VI + 5] = beta
        for i in range(MEAS_SIZE):
            row[_C_MEAS + i] = meas[i]
        for i in range(REF_SIZE):
            row[_C_REF + i] = ref[i]
        for i in range(CMD_SIZE):
            row[_C_CMD + i] = cmd[i]
        for i in range(N_MOTORS):
            row[_C_MOTOR + i] = motor_cmd[i]
        row[_C_MOTOR + N_MOTORS] = 1.0 if saturated else 0.0
        n_diag = diag.shape[0]
        for i in range(n_diag):
            row[_C_DIAG + i] = diag[i]
        row[_C_DIAG + n_diag] = controller_lyapunov(ctrl_p, ctrl_state, diag, theta_true, gamma)
        row[_C_DIAG + n_diag + 1] = faults_active
    plant_advance(x, motor_cmd, v_wind, plant_p, dt / n_sub, n_sub, True, work)


@njit(cache=True, nogil=True)
def run_closed_loop(x, plant_p, mixer_p, ctrl_fns, ctrl_p, ctrl_state, wind_p, wind_state, sens_p, sens_state,
                    ref_table, t0, dt, n_sub, rng, theta_true, gamma, faults, fault_state, envelope,
                    log) -> tuple:
    """Simulate up to ``ref_table.shape[0]`` controller ticks from time ``t0``, one row of ``log`` per tick.

    Returns ``(ticks_done, reason)``: all ticks and ``REASON_OK``, or, when the state leaves the
    ``envelope`` (:func:`vtoladapt.sim.monitor.check_envelope`), the ticks completed before it and the
    reason code; ``x`` is then the offending state and only ``log[:ticks_done]`` is written.
    ``faults`` is the fault schedule (``(n, FAULT_ROW_SIZE)``, possibly empty) and ``fault_state``
    its state (:mod:`vtoladapt.sim.faults`). ``ctrl_fns`` are the controller's law and basis functions
    (:func:`vtoladapt.control.step.controller_functions` of ``ctrl_p``).

    ``x``, ``ctrl_state``, ``wind_state``, ``sens_state`` and ``fault_state`` are advanced in
    place, so a run can be continued. The loop releases the GIL: runs with their own arrays and
    generators advance in parallel threads (:func:`vtoladapt.sim.driver.simulate_many`).
    ``theta_true`` (the plant's linear-model coefficients) is used only for the Lyapunov function
    in the log, never by the controller. Each tick is :func:`tick_sense` (with the controller run
    here, after the sensor faults) then the mixer, the actuator faults and
    :func:`tick_log_advance`: the same steps as the Gymnasium environment's :func:`tick_actuate`.
    """
    n_ticks = ref_table.shape[0]
    v_wind = np.zeros(3)
    f_B = np.empty(3)
    v_i = np.empty(3)
    meas = np.empty(MEAS_SIZE)
    cmd = np.zeros(CMD_SIZE)
    diag = np.zeros(log.shape[1] - _C_DIAG - len(_LOG_TAIL))
    motor_cmd = np.zeros(N_MOTORS)
    work = np.empty(RK4_WORK_SIZE)
    u_max = mixer_p[MX_U_MAX]
    for k in range(n_ticks):
        ref = ref_table[k]
        reason = check_envelope(x, envelope, ref)
        if reason != REASON_OK:
            return k, reason
        t = t0 + k * dt
        tick_sense(x, plant_p, ctrl_fns, ctrl_p, ctrl_state, wind_p, wind_state, sens_p, sens_state, ref, t, dt,
                   rng, False, v_wind, f_B, v_i, meas, cmd, diag, work)
        apply_measurement_faults(faults, fault_state, t, dt, meas)
        controller_step(ctrl_fns, ctrl_p, ctrl_state, meas, ref, dt, cmd, diag)
        saturated = mix(cmd, mixer_p, motor_cmd)
        report_mixed(ctrl_state, motor_cmd, saturated)
        apply_actuator_faults(faults, fault_state, t, u_max, motor_cmd)
        tick_log_advance(x, plant_p, ctrl_p, ctrl_state, ref, t, dt, n_sub, v_wind, f_B, v_i, meas, cmd, diag,
                         motor_cmd, saturated, active_mask(faults, t), work, theta_true, gamma, log[k])
    return n_ticks, check_envelope(x, envelope, ref_table[n_ticks - 1])
