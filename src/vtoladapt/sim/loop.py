"""The compiled closed-loop simulation: plant, wind, sensors, controller and mixer at 250 Hz.

Per controller tick ``k`` (time ``t = k dt``), in this order:

0. the divergence monitor checks the state against the scenario's envelope
   (:mod:`vtoladapt.sim.monitor`); outside it, the tick does not happen;
1. the random numbers of the tick's wind parts and sensor channels are drawn, part by part
   (:func:`vtoladapt.parts.draw`);
2. the wind parts give the wind at the vehicle, held over the tick (:func:`vtoladapt.wind.wind_at`);
3. the plant's first RK4 stage gives the true specific force and incident flow; the sensor channels
   sample them and the state (:func:`vtoladapt.sensors.sensors_at`), and the scenario's active sensor
   faults alter the measurement (:mod:`vtoladapt.sim.faults`);
4. the controller computes its command from the measurement and the reference (its output is
   held until the next tick, as on a flight computer);
5. the mixer's control allocator (:mod:`vtoladapt.sim.allocation`) turns the command into actuator
   commands -- four lift rotors, the pusher, the control surfaces -- (if it saturated, the controller is
   told the collective it actually sent), and the active actuator faults alter them and set the
   actuators' condition (a surface lost, a servo slowed);
6. one log row is written (if the caller keeps a log);
7. the plant advances by ``dt`` with ``n_sub`` fixed RK4 substeps (default 1 kHz).

Steps 0-4 are :func:`tick_sense`, steps 5-7 :func:`tick_actuate`: the one tick of the package.
:func:`run_closed_loop` (``simulate``, the long-run writer) calls the two in turn; the Gymnasium
environment (:mod:`vtoladapt.gym`) calls the same two and acts between them. The loop sees only
kernel arrays; :mod:`vtoladapt.sim.driver` builds them from a scenario. It is compiled for no
particular wind part or sensor channel: each kind arrives as a *part table*
(:class:`vtoladapt.parts.Assembly`) through which the tick calls the configured parts' compiled
steps, the package's and a user's alike.

Arguments travel in small tuples, one per component: ``wind = (table, params, state, draws)`` and
``sensors`` likewise; ``faults = (schedule, state)``; ``controller = (fns, params, state)``, where
``fns`` is the controller's function table (its law's ``update`` and its basis's ``regressor``:
:func:`vtoladapt.control.step.function_table`); ``log = (row, theta_true, gamma)``. The log row's
layout (:func:`log_layout`) is built per run from the blocks it records: a fixed head (time, state, wind, flow, specific force,
measurement, reference, command, motors), the controller's diagnostics (their columns come from the
controller, :func:`diagnostics_columns`) and a fixed tail (Lyapunov function, active faults).

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

from ..control.step import controller_lyapunov, controller_step, functions_at, set_last_command
from ..forces import airflow_angles
from ..layout import (
    CMD_SIZE,
    COMMAND_COLUMNS,
    MEAS_SIZE,
    MEASUREMENT_COLUMNS,
    ACTUATORS,
    MOTOR_PUSHER,
    N_ACTUATORS,
    REF_SIZE,
    REFERENCE_COLUMNS,
    STATE_COLUMNS,
    TRUTH,
    TRUTH_F_B,
    TRUTH_V_I_B,
    TRUTH_V_WIND_W,
    TRUTH_WIND,
    WIND_COLUMNS,
    WIND_SIZE,
    X_P_W,
    X_SIZE,
    BlockLayout,
    Field,
)
from ..parts import draw
from ..sensors.suite import sensors_at
from ..wind.composer import wind_at
from .faults import active_mask, apply_actuator_faults, apply_measurement_faults
from .allocation import ALLOC_REPORT, ALLOC_WORK, ALLOC_WORK_SIZE, allocate
from .mixer import MX_U_MAX, applied_collective
from .monitor import REASON_OK, check_envelope
from .plant import RK4_WORK_SIZE, plant_advance, plant_first_stage

TICK_WORK = BlockLayout("tick work", [
    Field("RK4", RK4_WORK_SIZE, "-", "the plant's RK4 work (vtoladapt.sim.plant.RK4_WORK); first, so the plant's "
          "kernels index it from 0"),
    Field("ALLOC", ALLOC_WORK_SIZE, "-", "the allocator's work (vtoladapt.sim.allocation.ALLOC_WORK)"),
])
"""The ``work`` array the two halves of a tick share (one per run, reused every tick)."""
(_TW_ALLOC,) = TICK_WORK.offsets("ALLOC")
TICK_WORK_SIZE = TICK_WORK.size
(_TW_REPORT,) = TICK_WORK.nested("ALLOC", ALLOC_WORK, "REPORT")
_N_ALLOC_REPORT = ALLOC_REPORT.size

# --- the log row -----------------------------------------------------------------------------------
LOG_HEAD = BlockLayout("log row, before the controller's diagnostics", [
    Field("T", 1, "s", "time of the tick", columns=("t_s",)),
    Field("STATE", X_SIZE, "-", "true plant state at the start of the tick (vtoladapt.layout.STATE)",
          columns=STATE_COLUMNS),
    Field("WIND", 3, "m/s", "wind at the vehicle, NED", columns=WIND_COLUMNS),
    Field("FLOW", 6, "m/s, rad", "true incident velocity (body FRD), airspeed, angle of attack, sideslip",
          columns=("v_i_x_mps", "v_i_y_mps", "v_i_z_mps", "airspeed_mps", "alpha_rad", "beta_rad")),
    Field("F_B", 3, "m/s^2", "true specific force, body FRD", columns=TRUTH.field("F_B").column_names),
    Field("MEAS", MEAS_SIZE, "-", "the measurement the controller saw (vtoladapt.layout.MEASUREMENT)",
          columns=MEASUREMENT_COLUMNS),
    Field("REF", REF_SIZE, "-", "the reference (vtoladapt.layout.REFERENCE)", columns=REFERENCE_COLUMNS),
    Field("CMD", CMD_SIZE, "-", "the controller's command (vtoladapt.layout.COMMAND)", columns=COMMAND_COLUMNS),
    Field("MOTOR_CMD", N_ACTUATORS, "-", "actuator commands after the mixer and the actuator faults (ACTUATORS)",
          columns=ACTUATORS.columns),
    Field("SATURATED", 1, "-", "1.0 if the allocator could not meet the asked lift and moment",
          columns=("mixer_saturated",)),
    Field("ALLOC", ALLOC_REPORT.size, "N, N m, Pa", "the allocator's report: asked and achieved lift and moment, "
          "the dynamic pressure it scheduled with (vtoladapt.sim.allocation.ALLOC_REPORT)",
          columns=ALLOC_REPORT.columns),
])
LOG_TAIL = BlockLayout("log row, after the controller's diagnostics", [
    Field("LYAPUNOV", 1, "-", "the theorem's Lyapunov function at the plant's true theta", columns=("lyapunov_V",)),
    Field("FAULTS", 1, "-", "bit i set while entry i of the fault schedule is active", columns=("faults_active",)),
])
(_L_T, _L_STATE, _L_WIND, _L_FLOW, _L_F_B, _L_MEAS, _L_REF, _L_CMD, _L_MOTOR, _L_SAT, _L_ALLOC) = LOG_HEAD.offsets(
    *(f.name for f in LOG_HEAD.fields))
_L_DIAG = LOG_HEAD.size
_LT_LYAP, _LT_FAULTS = LOG_TAIL.offsets("LYAPUNOV", "FAULTS")


def diagnostics_columns(controller_params) -> tuple[str, ...]:
    """The columns of the controller's diagnostics (the ``diag`` array) for a controller parameter array:
    its law's and its basis's (:func:`vtoladapt.control.step.diagnostics_columns`)."""
    from ..control.step import diagnostics_columns as columns_of

    return columns_of(controller_params)


def log_layout(diag_columns) -> BlockLayout:
    """The log row of a run: :data:`LOG_HEAD`, the controller's diagnostics, :data:`LOG_TAIL`."""
    cols = tuple(diag_columns)
    return BlockLayout("log row", [*LOG_HEAD.fields, Field("DIAG", len(cols), "-", "the controller's diagnostics",
                                                           columns=cols), *LOG_TAIL.fields])


def log_size(n_diag: int) -> int:
    """The log row's length for ``n_diag`` diagnostics columns (a run's own: ``PreparedRun.log_layout``)."""
    return LOG_HEAD.size + n_diag + LOG_TAIL.size


@njit(cache=True, nogil=True, inline="always")
def tick_time(k, dt, chunk_ticks) -> float:
    """The time of tick ``k`` exactly as :func:`vtoladapt.sim.driver.simulate` computes it: the run goes
    in chunks of ``chunk_ticks`` ticks, chunk ``c`` starting at ``t0 = k0 dt`` (``k0 = c chunk_ticks``)
    and its ticks at ``t0 + (k - k0) dt``, which may differ from ``k dt`` in the last bit. A caller that
    steps tick by tick (the Gymnasium environment) uses it to stay the simulator's run, bit for bit."""
    k0 = (k // chunk_ticks) * chunk_ticks
    return k0 * dt + (k - k0) * dt


@njit(cache=True, nogil=True, _nrt=False)
def tick_sense(x, truth, meas, work, plant_p, wind, sensors, faults, envelope, controller, ref, t, dt, rng,
               run_controller, cmd, diag) -> int:
    """First half of controller tick at time ``t``: steps 0-4 of the module docstring.

    Returns the envelope's reason code (:func:`vtoladapt.sim.monitor.check_envelope`): if not
    ``REASON_OK`` the state has left the envelope and nothing else happened. Otherwise draws the
    parts' random numbers, writes the wind and the plant's first RK4 stage (true specific force and
    incident flow) into ``truth`` (the stage is kept in ``work`` for :func:`tick_actuate`), samples
    the sensors into ``meas``, applies the active sensor faults and, if ``run_controller``, runs the
    controller on ``meas`` and ``ref`` into ``cmd`` and ``diag``. A caller that supplies the command
    itself (the Gymnasium environment's direct mode) passes ``run_controller=False`` and fills ``cmd``
    before :func:`tick_actuate`.
    """
    reason = check_envelope(x, envelope, ref)
    if reason != REASON_OK:
        return reason
    wind_table, wind_p, wind_s, wind_draws = wind
    sensor_table, sensor_p, sensor_s, sensor_draws = sensors
    draw(rng, wind_table, wind_draws)
    draw(rng, sensor_table, sensor_draws)
    wind_at(wind_table, wind_p, wind_s, t, dt, x[X_P_W:X_P_W + 3], wind_draws,
            truth[TRUTH_WIND:TRUTH_WIND + WIND_SIZE])
    plant_first_stage(x, truth[TRUTH_V_WIND_W:TRUTH_V_WIND_W + 3], plant_p, truth[TRUTH_F_B:TRUTH_F_B + 3],
                      truth[TRUTH_V_I_B:TRUTH_V_I_B + 3], work)
    sensors_at(sensor_table, sensor_p, sensor_s, t, dt, x, truth, sensor_draws, meas)
    apply_measurement_faults(faults[0], faults[1], t, dt, meas)
    if run_controller:
        controller_step(functions_at(controller[0]), controller[1], controller[2], meas, ref, dt, cmd, diag)
    return REASON_OK


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
def tick_actuate(x, truth, meas, work, plant_p, mixer_p, faults, controller, ref, cmd, diag, motor_cmd, t, dt,
                 n_sub, log) -> None:
    """Second half of the tick at time ``t``: steps 5-7 (allocate ``cmd``, actuator faults, log, advance the
    plant by ``dt``).

    ``motor_cmd`` is the plant input (:data:`vtoladapt.layout.PLANT_INPUT`): the allocator writes its
    actuator commands, the actuator faults the rest.

    ``log`` is ``(row, theta_true, gamma)``: the tick's log row (:func:`log_layout`) or an empty
    array to keep none, the plant's true theta and the Lyapunov function's attitude weight.
    ``work`` (:data:`TICK_WORK`) must hold the first RK4 stage :func:`tick_sense` evaluated at this ``x``.
    """
    saturated = allocate(cmd, meas, mixer_p, motor_cmd, work, _TW_ALLOC)
    report_mixed(controller[2], motor_cmd, saturated)
    apply_actuator_faults(faults[0], faults[1], t, mixer_p[MX_U_MAX], motor_cmd)
    row = log[0]
    if row.shape[0] > 0:
        write_log_row(row, x, truth, meas, ref, cmd, diag, motor_cmd, saturated, active_mask(faults[0], t),
                      controller, log[1], log[2], t, work)
    plant_advance(x, motor_cmd, truth[TRUTH_V_WIND_W:TRUTH_V_WIND_W + 3], plant_p, dt / n_sub, n_sub, True, work)


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def write_log_row(row, x, truth, meas, ref, cmd, diag, motor_cmd, saturated, faults_active, controller, theta_true,
                  gamma, t, work) -> None:
    """One log row (:func:`log_layout` with ``diag.shape[0]`` diagnostics)."""
    row[_L_T] = t
    for i in range(X_SIZE):
        row[_L_STATE + i] = x[i]
    for i in range(3):
        row[_L_WIND + i] = truth[TRUTH_V_WIND_W + i]
        row[_L_FLOW + i] = truth[TRUTH_V_I_B + i]
        row[_L_F_B + i] = truth[TRUTH_F_B + i]
    V, alpha, beta = airflow_angles(truth[TRUTH_V_I_B:TRUTH_V_I_B + 3])
    row[_L_FLOW + 3] = V
    row[_L_FLOW + 4] = alpha
    row[_L_FLOW + 5] = beta
    for i in range(MEAS_SIZE):
        row[_L_MEAS + i] = meas[i]
    for i in range(REF_SIZE):
        row[_L_REF + i] = ref[i]
    for i in range(CMD_SIZE):
        row[_L_CMD + i] = cmd[i]
    for i in range(N_ACTUATORS):
        row[_L_MOTOR + i] = motor_cmd[i]
    row[_L_SAT] = 1.0 if saturated else 0.0
    for i in range(_N_ALLOC_REPORT):
        row[_L_ALLOC + i] = work[_TW_REPORT + i]
    n_diag = diag.shape[0]
    for i in range(n_diag):
        row[_L_DIAG + i] = diag[i]
    tail = _L_DIAG + n_diag
    row[tail + _LT_LYAP] = controller_lyapunov(controller[1], controller[2], diag, theta_true, gamma)
    row[tail + _LT_FAULTS] = faults_active


@njit(cache=True, nogil=True)
def run_closed_loop(x, scratch, plant_p, mixer_p, wind, sensors, faults, envelope, controller, ref_table, t0, dt,
                    n_sub, rng, theta_true, gamma, log) -> tuple:
    """Simulate up to ``ref_table.shape[0]`` controller ticks from time ``t0``, one row of ``log`` per tick.

    Returns ``(ticks_done, reason)``: all ticks and ``REASON_OK``, or, when the state leaves the
    ``envelope`` (:func:`vtoladapt.sim.monitor.check_envelope`), the ticks completed before it and the
    reason code; ``x`` is then the offending state and only ``log[:ticks_done]`` is written.
    ``scratch`` is ``(truth, meas, cmd, diag, motor_cmd, work)``, what the two halves of a tick hand
    each other (:class:`vtoladapt.sim.driver.PreparedRun` makes it); ``wind``, ``sensors``, ``faults``
    and ``controller`` are the component tuples of the module docstring.

    ``x``, the parts' and the controller's states and the fault state are advanced in place, so a
    run can be continued. The loop releases the GIL: runs with their own arrays and generators
    advance in parallel threads (:func:`vtoladapt.sim.driver.simulate_many`). ``theta_true`` (the
    plant's linear-model coefficients) is used only for the Lyapunov function in the log, never by
    the controller.
    """
    truth, meas, cmd, diag, motor_cmd, work = scratch
    n_ticks = ref_table.shape[0]
    for k in range(n_ticks):
        ref = ref_table[k]
        t = t0 + k * dt
        reason = tick_sense(x, truth, meas, work, plant_p, wind, sensors, faults, envelope, controller, ref, t, dt,
                            rng, True, cmd, diag)
        if reason != REASON_OK:
            return k, reason
        tick_actuate(x, truth, meas, work, plant_p, mixer_p, faults, controller, ref, cmd, diag, motor_cmd, t, dt,
                     n_sub, (log[k], theta_true, gamma))
    return n_ticks, check_envelope(x, envelope, ref_table[n_ticks - 1])
