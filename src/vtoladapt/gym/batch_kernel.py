"""The environment's compiled batch step: many runs of the closed loop advanced one tick each.

One environment step is one controller tick (``dt_control_s``, 4 ms at 250 Hz) split where the
agent acts: the action becomes the command of tick ``k`` (second half,
:func:`vtoladapt.sim.loop.tick_actuate`: mixer, actuator faults and plant), then the first half of
tick ``k + 1`` (:func:`vtoladapt.sim.loop.tick_sense`: envelope, wind, sensors, sensor faults and, in
residual mode, the composite controller) gives the next observation. Both halves are the
simulator's own tick, so the scenario's ``[[faults]]`` and ``[envelope]`` act as in ``vtoladapt
run``, and a run whose residual is zero is the simulator's run, bit for bit.

:func:`step_batch` advances a chunk of environments held in one 2-D array, one row per
environment: every array of a run (plant state, the kernels' parameters and states, the scratch
the two halves of a tick hand each other) is a block of that row (:data:`ROW_BLOCKS`; the row's
layout is built per batch, as the blocks' sizes depend on the scenario, and handed to the kernel as
its bounds), so an environment's state is one contiguous stretch of memory, taken apart by slicing
inside the compiled code (no per-step copies, and one array to unbox per call instead of twenty);
the read-only blocks most environments share (:data:`SHARED_BLOCKS`) are rows of a second, small
table instead, the envelope and the fault schedule among them. The wind parts', sensor channels' and
controller's function tables, the same for every environment of a batch, are one int64 array. It
releases the GIL, so chunks step in parallel threads. While it steps environment ``i`` it
prefetches the hot part of row ``i + 1``: 256 environments hold about 4 MB, more than a core's
L2 cache, and without the prefetch each step waits for some 150 cache lines from L3 one miss at a
time (measured: about 40 % of a step at 256 environments).

Each environment draws its noise from its own ``numpy.random.Generator``, handed in as a
``numba.typed.List`` per chunk (unboxed once when stored, not at every call as a tuple of
generators would be: that costs tens of microseconds per generator). The draws stay the
simulator's own, in its order, so a zero residual reproduces ``vtoladapt run`` bit for bit.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .._numba_abi import prefetch as _prefetch
from ..control.step import set_last_command
from ..layout import (CMD_SIZE, CMD_TAU_B, CMD_U_X, CMD_U_Z, MEAS_OMEGA_B, MEAS_P_W, MEAS_Q_WB, MEAS_V_I_B,
                      MEAS_V_I_VALID, MEAS_V_W, REF_P_W, X_P_W, X_Q_WB, X_SIZE, BlockLayout, Field)
from ..sim.loop import tick_actuate, tick_sense, tick_time
from ..sim.faults import FAULT_ROW_SIZE
from ..sim.monitor import REASON_OK
from .spaces import OBS_CMD, OBS_HIGH, OBS_LOW, OBS_OMEGA, OBS_P_ERR, OBS_Q, OBS_V, OBS_V_I, OBS_V_I_VALID

MODES = ("direct", "residual")
MODE_DIRECT = MODES.index("direct")
MODE_RESIDUAL = MODES.index("residual")

OPERATIONS = ("skip", "step", "begin")
"""What :func:`step_batch` does to an environment: leave it as it is (outputs untouched); apply the
action over tick ``k``, then sense tick ``k + 1``; sense tick 0 of a freshly loaded run only
(reward 0, not done)."""
OP_SKIP = OPERATIONS.index("skip")
OP_STEP = OPERATIONS.index("step")
OP_BEGIN = OPERATIONS.index("begin")

ROW_BLOCKS: tuple[Field, ...] = (
    Field("X", 0, "-", "plant state (vtoladapt.layout.STATE)"),
    Field("TRUTH", 0, "-", "the tick's wind, specific force and incident velocity (vtoladapt.layout.TRUTH)"),
    Field("MEAS", 0, "-", "measurement (vtoladapt.layout.MEASUREMENT)"),
    Field("CMD", 0, "-", "command applied over the tick (vtoladapt.layout.COMMAND)"),
    Field("BASE", 0, "-", "the command the action modifies (residual: the controller's; direct: the last)"),
    Field("DIAG", 0, "-", "the controller's diagnostics"),
    Field("MOTOR", 0, "-", "motor commands"),
    Field("WORK", 0, "-", "the tick's work array (vtoladapt.sim.loop.TICK_WORK)"),
    Field("WIND_DRAWS", 0, "-", "the wind parts' random numbers of the tick"),
    Field("SENSOR_DRAWS", 0, "-", "the sensor channels' random numbers of the tick"),
    Field("PLANT_PARAMS", 0, "-", "the plant's parameters"),
    Field("CONTROLLER_STATE", 0, "-", "the controller's state"),
    Field("WIND_PARAMS", 0, "-", "the wind parts' parameters"),
    Field("WIND_STATE", 0, "-", "the wind parts' state"),
    Field("SENSOR_PARAMS", 0, "-", "the sensor channels' parameters"),
    Field("SENSOR_STATE", 0, "-", "the sensor channels' state"),
    Field("FAULT_STATE", 0, "-", "the fault schedule's state"),
)
"""The blocks of an environment's row, in order (their sizes, 0 here, are the batch's: see
:func:`vtoladapt.gym.batch.row_layouts`): the plant state and the scratch of a tick first (touched by
every step), then the parameters and states of :class:`vtoladapt.sim.driver.PreparedRun`."""
SHARED_BLOCKS: tuple[Field, ...] = (
    Field("MIXER_PARAMS", 0, "-", "the mixer's parameters"),
    Field("CONTROLLER_PARAMS", 0, "-", "the controller's parameters"),
    Field("ENVELOPE", 0, "-", "the scenario's envelope (vtoladapt.sim.monitor.ENVELOPE_PARAMS)"),
    Field("FAULT_SCHEDULE", 0, "-", "the fault schedule, rows of vtoladapt.sim.faults.FAULT_ROW one after another"),
)
"""Read-only blocks that environments of a chunk usually have in common (the episode draw changes
the plant and the wind, not the controller or the mixer): each distinct value is stored once per
chunk, in a table row that environment ``i`` finds at ``pidx[i]`` (2 of an environment's 12 kB
that a step reads, so fewer cache misses at many environments)."""

TABLES: tuple[str, ...] = ("WIND_TABLE", "SENSOR_TABLE", "CONTROLLER_FNS")
"""The function tables every environment of a batch shares (:class:`vtoladapt.parts.Assembly`'s part
tables and the controller's), one after another in the ``tables`` argument."""

BOUNDS = BlockLayout("bounds of a row's and a shared row's blocks", [
    *(Field(f.name, 1, "-", f"first column of the row's {f.name} block") for f in ROW_BLOCKS),
    Field("ROW_END", 1, "-", "the row's width"),
    *(Field(f.name, 1, "-", f"first column of the shared table's {f.name} block") for f in SHARED_BLOCKS),
    Field("SHARED_END", 1, "-", "the shared table's width"),
    *(Field(name, 1, "-", f"first row of the {name.lower().replace('_', ' ')} in the function tables")
      for name in TABLES),
    Field("TABLES_END", 1, "-", "the function tables' rows"),
])
"""The kernel's ``off`` array: block ``B`` of a row spans columns ``off[B] .. off[B + 1] - 1`` (each
block's end is the next one's start), the row's :data:`ROW_BLOCKS` then the shared table's, then the
rows of each of :data:`TABLES` in the ``tables`` argument."""
(B_X, B_TRUTH, B_MEAS, B_CMD, B_BASE, B_DIAG, B_MOTOR, B_WORK, B_WIND_D, B_SENS_D, B_PLANT, B_CTRL_S, B_WIND_P,
 B_WIND_S, B_SENS_P, B_SENS_S, B_FAULT_S, B_ROW_END, B_MIXER, B_CTRL_P, B_ENVELOPE, B_FAULTS, B_SHARED_END,
 B_WIND_TABLE, B_SENSOR_TABLE, B_CTRL_FNS, B_TABLES_END) = BOUNDS.offsets(*(f.name for f in BOUNDS.fields))

SETTINGS = BlockLayout("settings of step_batch", [
    Field("MODE", 1, "-", "index into MODES"),
    Field("RESIDUAL_SCALE", 1, "-", "residual at action +-1, as a fraction of the command's range"),
    Field("U_MAX", 1, "-", "throttle limit, fraction"),
    Field("MAX_ERR_M", 1, "m", "the episode ends when the true position leaves this box around the reference"),
    Field("COS_TILT_MAX", 1, "-", "cosine of the largest tilt before the episode ends"),
    Field("ACTION_COST", 1, "-", "weight of the action penalty in the reward"),
    Field("DT_S", 1, "s", "controller tick"),
    Field("N_SUB", 1, "-", "plant RK4 substeps per tick"),
    Field("N_TICKS", 1, "-", "ticks per episode"),
    Field("CHUNK_TICKS", 1, "-", "ticks per chunk of vtoladapt.sim.driver.simulate: tick times are computed as there"),
    Field("PREFETCH_END", 1, "-", "the next row is prefetched from column 0 to here..."),
    Field("PREFETCH_RESUME", 1, "-", "...and from here (after the motion-capture ring, which a step touches twice)"),
    Field("PREFETCH_STOP", 1, "-", "...to here"),
])
"""The ``settings`` array of :func:`step_batch` (one float array, not a dozen scalar arguments)."""
(SET_MODE, SET_RESIDUAL_SCALE, SET_U_MAX, SET_MAX_ERR_M, SET_COS_TILT_MAX, SET_ACTION_COST, SET_DT_S, SET_N_SUB,
 SET_N_TICKS, SET_CHUNK_TICKS, SET_PREFETCH_END, SET_PREFETCH_RESUME, SET_PREFETCH_STOP) = SETTINGS.offsets(
    *(f.name for f in SETTINGS.fields))
SETTINGS_SIZE = SETTINGS.size

_CACHE_LINE_DOUBLES = 8

_OBS_LOW = OBS_LOW.astype(np.float64)
_OBS_HIGH = OBS_HIGH.astype(np.float64)


@njit(cache=True, inline="always")
def _clip(v, lo, hi):
    return min(max(v, lo), hi)


@njit(cache=True, nogil=True, _nrt=False)
def _command_from_action(mode, a, base, u_max, tau_max, residual_scale, cmd) -> None:
    """The command of this tick from the action (see :mod:`vtoladapt.gym.spaces`)."""
    if mode == MODE_RESIDUAL:
        cmd[CMD_U_X] = _clip(base[CMD_U_X] + a[0] * residual_scale * u_max, 0.0, u_max)
        cmd[CMD_U_Z] = _clip(base[CMD_U_Z] + a[1] * residual_scale * u_max, 0.0, u_max)
        for j in range(3):
            cmd[CMD_TAU_B + j] = _clip(base[CMD_TAU_B + j] + a[2 + j] * residual_scale * tau_max[j],
                                       -tau_max[j], tau_max[j])
    else:
        cmd[CMD_U_X] = 0.5 * (_clip(a[0], -1.0, 1.0) + 1.0) * u_max
        cmd[CMD_U_Z] = 0.5 * (_clip(a[1], -1.0, 1.0) + 1.0) * u_max
        for j in range(3):
            cmd[CMD_TAU_B + j] = _clip(a[2 + j], -1.0, 1.0) * tau_max[j]


@njit(cache=True, inline="always")
def _put(obs, j, v) -> None:
    obs[j] = 0.0 if np.isnan(v) else _clip(v, _OBS_LOW[j], _OBS_HIGH[j])


@njit(cache=True, nogil=True, _nrt=False)
def _observe(meas, ref, base, u_max, tau_max, obs) -> None:
    """Write the observation (float32, clipped to its bounds, NaN -> 0) of one environment."""
    for j in range(3):
        _put(obs, OBS_P_ERR + j, meas[MEAS_P_W + j] - ref[REF_P_W + j])
        _put(obs, OBS_V + j, meas[MEAS_V_W + j])
        _put(obs, OBS_OMEGA + j, meas[MEAS_OMEGA_B + j])
        _put(obs, OBS_V_I + j, meas[MEAS_V_I_B + j])
    for j in range(4):
        _put(obs, OBS_Q + j, meas[MEAS_Q_WB + j])
    _put(obs, OBS_V_I_VALID, meas[MEAS_V_I_VALID])
    _put(obs, OBS_CMD, 2.0 * base[CMD_U_X] / u_max - 1.0)
    _put(obs, OBS_CMD + 1, 2.0 * base[CMD_U_Z] / u_max - 1.0)
    for j in range(3):
        _put(obs, OBS_CMD + 2 + j, base[CMD_TAU_B + j] / tau_max[j])


@njit(cache=True, nogil=True, _nrt=False)
def _step_env(rng, i, o, actions, settings, tau_max, ref_table, S, off, P, pidx, K, obs, reward, terminated,
              truncated, tables, empty) -> None:
    """Environment ``i`` of :func:`step_batch`, operation ``o`` (not :data:`OP_SKIP`), its generator
    ``rng``. Allocates nothing (compiled without reference counting)."""
    no_log = (empty, empty, 0.0)  # no log row, no theta_true: the environment logs nothing
    wind_table = tables[off[B_WIND_TABLE]:off[B_WIND_TABLE + 1]]
    sensor_table = tables[off[B_SENSOR_TABLE]:off[B_SENSOR_TABLE + 1]]
    ctrl_fns = tables[off[B_CTRL_FNS]:off[B_CTRL_FNS + 1]]
    mode = int(settings[SET_MODE])
    residual = mode == MODE_RESIDUAL
    residual_scale = settings[SET_RESIDUAL_SCALE]
    u_max = settings[SET_U_MAX]
    max_err_m = settings[SET_MAX_ERR_M]
    cos_tilt_max = settings[SET_COS_TILT_MAX]
    action_cost = settings[SET_ACTION_COST]
    dt = settings[SET_DT_S]
    n_sub = int(settings[SET_N_SUB])
    n_ticks = int(settings[SET_N_TICKS])
    chunk_ticks = int(settings[SET_CHUNK_TICKS])
    n = S.shape[0]
    if i + 1 < n:
        for j in range(0, int(settings[SET_PREFETCH_END]), _CACHE_LINE_DOUBLES):
            _prefetch(S, i + 1, j)
        for j in range(int(settings[SET_PREFETCH_RESUME]), int(settings[SET_PREFETCH_STOP]), _CACHE_LINE_DOUBLES):
            _prefetch(S, i + 1, j)
        if pidx[i + 1] != pidx[i]:
            for j in range(0, off[B_SHARED_END], _CACHE_LINE_DOUBLES):
                _prefetch(P, pidx[i + 1], j)
    row = S[i]
    shared = P[pidx[i]]
    mixer_p = shared[off[B_MIXER]:off[B_MIXER + 1]]
    ctrl_p = shared[off[B_CTRL_P]:off[B_CTRL_P + 1]]
    envelope = shared[off[B_ENVELOPE]:off[B_ENVELOPE + 1]]
    schedule = shared[off[B_FAULTS]:off[B_FAULTS + 1]]
    fault_schedule = schedule.reshape((schedule.shape[0] // FAULT_ROW_SIZE, FAULT_ROW_SIZE))
    x = row[off[B_X]:off[B_X + 1]]
    truth = row[off[B_TRUTH]:off[B_TRUTH + 1]]
    meas = row[off[B_MEAS]:off[B_MEAS + 1]]
    cmd = row[off[B_CMD]:off[B_CMD + 1]]
    base = row[off[B_BASE]:off[B_BASE + 1]]
    diag = row[off[B_DIAG]:off[B_DIAG + 1]]
    work = row[off[B_WORK]:off[B_WORK + 1]]
    plant_p = row[off[B_PLANT]:off[B_PLANT + 1]]
    ctrl_s = row[off[B_CTRL_S]:off[B_CTRL_S + 1]]
    faults = (fault_schedule, row[off[B_FAULT_S]:off[B_FAULT_S + 1]])
    k = K[i]
    r = 0.0
    done = False
    if o == OP_STEP:
        a = actions[i]
        _command_from_action(mode, a, base, u_max, tau_max, residual_scale, cmd)
        if residual:
            # the adaptation's regressor must see the throttles actually applied
            set_last_command(ctrl_s, cmd[CMD_U_X], cmd[CMD_U_Z])
        tick_actuate(x, truth, meas, work, plant_p, mixer_p, faults, (ctrl_fns, ctrl_p, ctrl_s), ref_table[k], cmd, diag,
                     row[off[B_MOTOR]:off[B_MOTOR + 1]], tick_time(k, dt, chunk_ticks), dt, n_sub, no_log)
        k += 1
        K[i] = k
        finite = True
        for j in range(X_SIZE):
            if not np.isfinite(x[j]):
                finite = False
        a2 = 0.0
        for j in range(CMD_SIZE):
            a2 += a[j] * a[j]
        penalty = action_cost * a2 / CMD_SIZE
        if not finite:
            done = True
            r = -penalty
        else:
            e2 = 0.0
            for j in range(3):
                e = x[X_P_W + j] - ref_table[k, REF_P_W + j]
                e2 += e * e
                if abs(e) > max_err_m:
                    done = True
            qw, qx, qy, qz = x[X_Q_WB], x[X_Q_WB + 1], x[X_Q_WB + 2], x[X_Q_WB + 3]
            cos_tilt = (qw * qw - qx * qx - qy * qy + qz * qz) / (qw * qw + qx * qx + qy * qy + qz * qz)
            if cos_tilt < cos_tilt_max:
                done = True
            r = 1.0 - min(np.sqrt(e2) / max_err_m, 1.0) - penalty
        if not residual:
            for j in range(CMD_SIZE):
                base[j] = cmd[j]
        if not finite:
            _observe(meas, ref_table[k], base, u_max, tau_max, obs[i])
            reward[i] = r
            terminated[i] = True
            truncated[i] = False
            return
    t = tick_time(k, dt, chunk_ticks)
    reason = tick_sense(x, truth, meas, work, plant_p,
                        (wind_table, row[off[B_WIND_P]:off[B_WIND_P + 1]], row[off[B_WIND_S]:off[B_WIND_S + 1]],
                         row[off[B_WIND_D]:off[B_WIND_D + 1]]),
                        (sensor_table, row[off[B_SENS_P]:off[B_SENS_P + 1]], row[off[B_SENS_S]:off[B_SENS_S + 1]],
                         row[off[B_SENS_D]:off[B_SENS_D + 1]]),
                        faults, envelope, (ctrl_fns, ctrl_p, ctrl_s), ref_table[k], t, dt, rng, residual,
                        base if residual else cmd, diag)
    if reason != REASON_OK:
        done = True  # the scenario's [envelope] ends the episode, as it ends a run: nothing was sensed
    _observe(meas, ref_table[k], base, u_max, tau_max, obs[i])
    reward[i] = r
    terminated[i] = done
    truncated[i] = (not done) and k >= n_ticks


@njit(cache=True, nogil=True)
def step_batch(rngs, op, actions, settings, tau_max, ref_table, S, off, P, pidx, K, obs, reward, terminated,
               truncated, tables, empty) -> None:
    """Advance every environment ``i`` of a chunk by ``op[i]`` (:data:`OP_STEP`, :data:`OP_BEGIN`, :data:`OP_SKIP`).

    ``S`` holds one row per environment, block ``B`` of :data:`ROW_BLOCKS` in columns
    ``off[B] .. off[B + 1] - 1`` (``off`` laid out as :data:`BOUNDS`), advanced in place; row
    ``pidx[i]`` of ``P`` holds environment ``i``'s :data:`SHARED_BLOCKS` (read only); ``rngs[i]`` is
    environment ``i``'s generator, ``K[i]`` the tick it senses next, ``actions[i]`` its action.
    ``settings`` is laid out as :data:`SETTINGS` (mode, scales, limits, ``dt``, substeps, ticks per
    episode, what to prefetch of a row); ``ref_table`` (``n_ticks + 1`` rows) is shared, and so are the
    function tables, ``tables``, whose rows ``off`` bounds as :data:`TABLES` (the wind parts', the
    sensor channels', the controller's: :class:`vtoladapt.parts.Assembly`). Outputs per
    environment: ``obs`` (float32 rows), ``reward``, ``terminated`` (true position outside
    ``max_err_m`` of the reference on any NED axis, tilt beyond ``acos(cos_tilt_max)``, a non-finite
    state, or the state outside the scenario's envelope), ``truncated`` (the scenario's last tick
    reached, not terminated). ``empty`` is an empty float array (the log row and true theta the
    environment does not keep).

    Each environment steps in :func:`_step_env`, compiled without Numba's reference counting as
    the tick's kernels are (:mod:`vtoladapt.sim.loop`): its twenty-odd row slices would
    otherwise cost an atomic increment and decrement each. This loop keeps it only to take each
    generator out of the typed list.
    """
    n = S.shape[0]
    for i in range(n):
        if op[i] == OP_SKIP:
            continue
        _step_env(rngs[i], i, op[i], actions, settings, tau_max, ref_table, S, off, P, pidx, K, obs, reward,
                  terminated, truncated, tables, empty)
