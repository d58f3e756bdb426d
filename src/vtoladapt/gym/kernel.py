"""The environment's compiled batch step: many runs of the closed loop advanced one tick each.

One environment step is one controller tick (``dt_control_s``, 4 ms at 250 Hz) split where the
agent acts: the action becomes the command of tick ``k`` (second half,
:func:`vtoladapt.compiled_loop.tick_actuate`: mixer and plant), then the first half of tick
``k + 1`` (:func:`vtoladapt.compiled_loop.tick_sense`: wind, sensors and, in residual mode, the
composite controller) gives the next observation. Both halves are the simulator's own, so a run
whose residual is zero is the simulator's run, bit for bit.

:func:`step_batch` advances environments ``lo .. hi-1`` of stacked arrays (one row per
environment) and releases the GIL, so contiguous chunks of a batch step in parallel threads.
Each environment draws its noise from its own ``numpy.random.Generator``, handed in as a
``numba.typed.List`` per chunk (unboxed once when stored, not at every call as a tuple of
generators would be: that costs tens of microseconds per generator).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..compiled_loop import tick_actuate, tick_sense
from ..control.kernel import state_last_command
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

_OBS_LOW = OBS_LOW.astype(np.float64)
_OBS_HIGH = OBS_HIGH.astype(np.float64)


@njit(cache=True, inline="always")
def _clip(v, lo, hi):
    return min(max(v, lo), hi)


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def step_batch(lo, hi, rngs, op, actions, mode, residual_scale, u_max, tau_max, max_err_m, cos_tilt_max,
               action_cost, ref_table, dt, n_sub, n_ticks,
               X, PLANT, MIXER, CTRL_P, CTRL_S, WIND_P, WIND_S, SENS_P, SENS_S,
               V_WIND, F_B, V_I, MEAS, CMD, BASE, DIAG, MOTOR, WORK, K,
               obs, reward, terminated, truncated) -> None:
    """Advance environments ``lo .. hi-1`` by ``op[i]`` (:data:`OP_STEP`, :data:`OP_BEGIN`, :data:`OP_SKIP`).

    Arrays in capitals are stacked per environment (row ``i``) and advanced in place; ``rngs[i - lo]``
    is environment ``i``'s generator. ``ref_table`` (``n_ticks + 1`` rows) is shared; ``K[i]`` is
    the tick environment ``i`` senses next. Outputs per environment: ``obs`` (float32 rows),
    ``reward``, ``terminated`` (true position outside ``max_err_m`` of the reference on any NED
    axis, tilt beyond ``acos(cos_tilt_max)``, or a non-finite state), ``truncated`` (the
    scenario's last tick reached, not terminated).
    """
    no_row = np.empty(0)
    no_theta = np.empty(0)
    residual = mode == MODE_RESIDUAL
    for i in range(lo, hi):
        o = op[i]
        if o == OP_SKIP:
            continue
        rng = rngs[i - lo]
        x = X[i]
        k = K[i]
        r = 0.0
        done = False
        if o == OP_STEP:
            a = actions[i]
            _command_from_action(mode, a, BASE[i], u_max, tau_max, residual_scale, CMD[i])
            if residual:
                # the adaptation's regressor must see the throttles actually applied
                u_prev = state_last_command(CTRL_S[i])
                u_prev[0] = CMD[i, CMD_U_X]
                u_prev[1] = CMD[i, CMD_U_Z]
            tick_actuate(x, PLANT[i], MIXER[i], CTRL_S[i], ref_table[k], k * dt, dt, n_sub, V_WIND[i], F_B[i],
                         V_I[i], MEAS[i], CMD[i], DIAG[i], MOTOR[i], WORK[i], no_theta, 0.0, no_row)
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
                    BASE[i, j] = CMD[i, j]
            if not finite:
                _observe(MEAS[i], ref_table[k], BASE[i], u_max, tau_max, obs[i])
                reward[i] = r
                terminated[i] = True
                truncated[i] = False
                continue
        t = k * dt
        tick_sense(x, PLANT[i], CTRL_P[i], CTRL_S[i], WIND_P[i], WIND_S[i], SENS_P[i], SENS_S[i], ref_table[k],
                   t, dt, rng, residual, V_WIND[i], F_B[i], V_I[i], MEAS[i], BASE[i] if residual else CMD[i],
                   DIAG[i], WORK[i])
        _observe(MEAS[i], ref_table[k], BASE[i], u_max, tau_max, obs[i])
        reward[i] = r
        terminated[i] = done
        truncated[i] = (not done) and k >= n_ticks
