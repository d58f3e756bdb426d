"""The environment's compiled batch step: many runs of the closed loop advanced one tick each.

One environment step is one controller tick (``dt_control_s``, 4 ms at 250 Hz) split where the
agent acts: the action becomes the command of tick ``k`` (second half,
:func:`vtoladapt.sim.loop.tick_actuate`: mixer and plant), then the first half of tick
``k + 1`` (:func:`vtoladapt.sim.loop.tick_sense`: wind, sensors and, in residual mode, the
composite controller) gives the next observation. Both halves are the simulator's own, so a run
whose residual is zero is the simulator's run, bit for bit.

:func:`step_batch` advances a chunk of environments held in one 2-D array, one row per
environment: every array of a run (plant state, the kernels' parameters and states, the scratch
the two halves of a tick hand each other) is a block of that row (:data:`BLOCKS`), so an
environment's state is one contiguous stretch of memory, taken apart by slicing inside the
compiled code (no per-step copies, and one array to unbox per call instead of twenty); the
read-only blocks most environments share (:data:`SHARED_BLOCKS`) are rows of a second, small
table instead. It releases the GIL, so chunks step in parallel threads. While it steps environment ``i`` it
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
from llvmlite import ir
from llvmlite.binding import llvm_version_info
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from ..sim.loop import tick_actuate, tick_sense
from ..control.step import functions_at, set_last_command
from ..layout import CMD_SIZE, CMD_TAU_B, CMD_U_X, CMD_U_Z, MEAS_OMEGA_B, MEAS_P_W, MEAS_Q_WB, MEAS_V_I_B, \
    MEAS_V_I_VALID, MEAS_V_W, REF_P_W, X_P_W, X_Q_WB, X_SIZE
from .spaces import OBS_CMD, OBS_HIGH, OBS_LOW, OBS_OMEGA, OBS_P_ERR, OBS_Q, OBS_V, OBS_V_I, OBS_V_I_VALID

MODE_DIRECT = 0
MODE_RESIDUAL = 1

OP_SKIP = 0
"""Leave the environment as it is (outputs untouched)."""
OP_STEP = 1
"""Apply the action over tick ``k``, then sense tick ``k + 1``."""
OP_BEGIN = 2
"""A freshly loaded run: sense tick 0 only (reward 0, not done)."""

BLOCKS: tuple[str, ...] = ("x", "v_wind", "f_B", "v_i", "meas", "cmd", "base", "diag", "motor", "work",
                           "plant_params", "controller_state", "wind_params", "wind_state", "sensor_params",
                           "sensor_state")
"""The blocks of an environment's row, in order: the plant state and the scratch of a tick first
(touched by every step), then the parameters and states of :class:`vtoladapt.sim.driver.PreparedRun`."""
(B_X, B_V_WIND, B_F_B, B_V_I, B_MEAS, B_CMD, B_BASE, B_DIAG, B_MOTOR, B_WORK, B_PLANT, B_CTRL_S, B_WIND_P,
 B_WIND_S, B_SENS_P, B_SENS_S) = range(len(BLOCKS))
SHARED_BLOCKS: tuple[str, ...] = ("mixer_params", "controller_params")
"""Read-only blocks that environments of a chunk usually have in common (the episode draw changes
the plant and the wind, not the controller or the mixer): each distinct value is stored once per
chunk, in a table row that environment ``i`` finds at ``pidx[i]`` (2 of an environment's 12 kB
that a step reads, so fewer cache misses at many environments)."""
O_SHARED = len(BLOCKS) + 1
"""Where the shared table's column offsets start in ``off`` (after the row's)."""
S_MIXER, S_CTRL_P = range(len(SHARED_BLOCKS))

# Entries of the settings array of step_batch (one float array, not nine scalar arguments).
(SET_MODE, SET_RESIDUAL_SCALE, SET_U_MAX, SET_MAX_ERR_M, SET_COS_TILT_MAX, SET_ACTION_COST, SET_DT_S,
 SET_N_SUB, SET_N_TICKS, SET_PREFETCH_END) = range(10)
SETTINGS_SIZE = 10

_CACHE_LINE_DOUBLES = 8

_OBS_LOW = OBS_LOW.astype(np.float64)
_OBS_HIGH = OBS_HIGH.astype(np.float64)


# LLVM names the intrinsic by its pointer type: "p0" since pointers became opaque (LLVM 17 has
# only those), "p0i8" for the typed i8* of the LLVM 14-15 under older numba releases.
_PREFETCH_INTRINSIC = "llvm.prefetch.p0" if llvm_version_info[0] >= 17 else "llvm.prefetch.p0i8"


@intrinsic
def _prefetch(typingctx, array2d, i, j):
    """Ask the CPU to bring ``array2d[i, j]``'s cache line into its caches (LLVM's ``llvm.prefetch``;
    a hint: no fault, no effect on results)."""
    sig = types.void(array2d, i, j)

    def codegen(context, builder, signature, args):
        aty = signature.args[0]
        ary = context.make_array(aty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer2(context, builder, ary.data, cgutils.unpack_tuple(builder, ary.shape),
                                        cgutils.unpack_tuple(builder, ary.strides), aty.layout,
                                        [args[1], args[2]])
        i8p = builder.bitcast(ptr, ir.IntType(8).as_pointer())
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [i8p.type, i32, i32, i32]),
                                            _PREFETCH_INTRINSIC)
        # read, locality 2 (towards L2, not L1: the next environment's ~10 kB would evict the
        # current one's from a 32 kB L1), data cache
        builder.call(fn, [i8p, i32(0), i32(2), i32(1)])
        return context.get_dummy_value()

    return sig, codegen


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
              truncated, empty, ctrl_fns) -> None:
    """Environment ``i`` of :func:`step_batch`, operation ``o`` (not :data:`OP_SKIP`), its generator
    ``rng``. Allocates nothing (compiled without reference counting)."""
    no_row = empty  # no log row, no theta_true: the environment logs nothing
    no_theta = empty
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
    prefetch_end = int(settings[SET_PREFETCH_END])
    n = S.shape[0]
    if i + 1 < n:
        for j in range(0, prefetch_end, _CACHE_LINE_DOUBLES):
            _prefetch(S, i + 1, j)
        if pidx[i + 1] != pidx[i]:
            for j in range(0, off[O_SHARED + len(SHARED_BLOCKS)], _CACHE_LINE_DOUBLES):
                _prefetch(P, pidx[i + 1], j)
    row = S[i]
    shared = P[pidx[i]]
    mixer_p = shared[off[O_SHARED + S_MIXER]:off[O_SHARED + S_MIXER + 1]]
    ctrl_p = shared[off[O_SHARED + S_CTRL_P]:off[O_SHARED + S_CTRL_P + 1]]
    x = row[off[B_X]:off[B_X + 1]]
    v_wind = row[off[B_V_WIND]:off[B_V_WIND + 1]]
    f_B = row[off[B_F_B]:off[B_F_B + 1]]
    v_i = row[off[B_V_I]:off[B_V_I + 1]]
    meas = row[off[B_MEAS]:off[B_MEAS + 1]]
    cmd = row[off[B_CMD]:off[B_CMD + 1]]
    base = row[off[B_BASE]:off[B_BASE + 1]]
    diag = row[off[B_DIAG]:off[B_DIAG + 1]]
    work = row[off[B_WORK]:off[B_WORK + 1]]
    plant_p = row[off[B_PLANT]:off[B_PLANT + 1]]
    ctrl_s = row[off[B_CTRL_S]:off[B_CTRL_S + 1]]
    k = K[i]
    r = 0.0
    done = False
    if o == OP_STEP:
        a = actions[i]
        _command_from_action(mode, a, base, u_max, tau_max, residual_scale, cmd)
        if residual:
            # the adaptation's regressor must see the throttles actually applied
            set_last_command(ctrl_s, cmd[CMD_U_X], cmd[CMD_U_Z])
        tick_actuate(x, plant_p, mixer_p, ctrl_p, ctrl_s, ref_table[k], k * dt, dt, n_sub,
                     v_wind, f_B, v_i, meas, cmd, diag, row[off[B_MOTOR]:off[B_MOTOR + 1]], work, no_theta,
                     0.0, no_row)
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
    t = k * dt
    tick_sense(x, plant_p, ctrl_fns, ctrl_p, ctrl_s, row[off[B_WIND_P]:off[B_WIND_P + 1]],
               row[off[B_WIND_S]:off[B_WIND_S + 1]], row[off[B_SENS_P]:off[B_SENS_P + 1]],
               row[off[B_SENS_S]:off[B_SENS_S + 1]], ref_table[k], t, dt, rng, residual, v_wind, f_B, v_i,
               meas, base if residual else cmd, diag, work)
    _observe(meas, ref_table[k], base, u_max, tau_max, obs[i])
    reward[i] = r
    terminated[i] = done
    truncated[i] = (not done) and k >= n_ticks


@njit(cache=True, nogil=True)
def step_batch(rngs, op, actions, settings, tau_max, ref_table, S, off, P, pidx, K, obs, reward, terminated,
               truncated, empty, ctrl_addresses) -> None:
    """Advance every environment ``i`` of a chunk by ``op[i]`` (:data:`OP_STEP`, :data:`OP_BEGIN`, :data:`OP_SKIP`).

    ``S`` holds one row per environment, block ``b`` of :data:`BLOCKS` in columns
    ``off[b] .. off[b + 1] - 1``, advanced in place; row ``pidx[i]`` of ``P`` holds environment
    ``i``'s :data:`SHARED_BLOCKS`, block ``b`` in columns ``off[O_SHARED + b] ..
    off[O_SHARED + b + 1] - 1`` (read only); ``rngs[i]`` is environment ``i``'s generator,
    ``K[i]`` the tick it senses next, ``actions[i]`` its action. ``settings`` holds the ``SET_*``
    entries (mode, scales, limits, ``dt``, substeps, ticks per episode, the prefetched length of
    a row); ``ref_table`` (``n_ticks + 1`` rows) is shared. Outputs per environment: ``obs``
    (float32 rows), ``reward``, ``terminated`` (true position outside ``max_err_m`` of the
    reference on any NED axis, tilt beyond ``acos(cos_tilt_max)``, or a non-finite state),
    ``truncated`` (the scenario's last tick reached, not terminated). ``empty`` is an empty
    float array (the log row and true theta the environment does not keep). ``ctrl_addresses`` are the
    addresses of the controller's law and basis functions (:func:`vtoladapt.control.step.function_addresses`
    of :func:`~vtoladapt.control.step.controller_functions`), shared by the chunk.

    Each environment steps in :func:`_step_env`, compiled without Numba's reference counting as
    the tick's kernels are (:mod:`vtoladapt.sim.loop`): its twenty-odd row slices would
    otherwise cost an atomic increment and decrement each. This loop keeps it only to take each
    generator out of the typed list.
    """
    n = S.shape[0]
    ctrl_fns = functions_at(ctrl_addresses)
    for i in range(n):
        if op[i] == OP_SKIP:
            continue
        _step_env(rngs[i], i, op[i], actions, settings, tau_max, ref_table, S, off, P, pidx, K, obs, reward,
                  terminated, truncated, empty, ctrl_fns)
