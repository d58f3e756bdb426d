"""The PX4-style velocity PID (the paper's controller IV), with theta-hat = theta_0 held constant.

Velocity setpoint ``v_sp = v_r`` (PX4's position P loop with feed-forward);
``acc_sp = K_v (v_sp - v) + I - K_D a_f`` with the integral ``I' = K_I (v_sp - v)`` and the
derivative on the measurement (``a_f``: the measured velocity differenced and low-passed at
``derivative_cutoff_hz``); ``f_r = -g + ff + acc_sp``. Anti-windup: ``I`` is clamped per axis, and
an axis is frozen while the allocation saturated on the previous tick and integrating would
push further into the unachieved force (``(v_sp - v)_i (R residual)_i > 0``). Then the same
desired attitude, allocation and moment law as every law, with theta-hat constant.

The reference feed-forward ``ff`` (``feedforward``)
---------------------------------------------------
``"v_r_dot"`` (default): ``ff = v_r' = a_d - Lambda_p (v - v_d)``, the derivative of the velocity
setpoint, exactly what eq:f_ctrl feeds forward in every other law (composite, P const,
tracking-error, nominal, INDI, L1 all take it from the front end, the saturation of
``|Lambda_p p~|`` included). With it, ``K_I = K_D = 0`` makes this law *identical* to ``nominal``
(eq:f_ctrl with theta_0), so the comparison's baselines differ from the adaptive laws only by
what replaces adaptation (an integral, a derivative), not by the shape of the tracking loop.
Linearised in hover and without the integral, the horizontal position error obeys
``(1 + K_D) s^2 + (K_v + Lambda_p) s + K_v Lambda_p = 0``: damping 0.96 with the defaults,
against the adaptive laws' ``s^2 + (K_v + Lambda_p) s + K_v Lambda_p``, 1.05. That is what the
paper's "the equivalent gains used in all five controllers are held the same" needs. (The paper's
own PID, ``f_r = -g - K_P v~ - K_D v~' - K_I int v~``, is written on ``v~ = v - v_r`` and feeds
no acceleration forward at all; it does not say what Pixhawk's implementation added.)

``"a_d"``: ``ff = a_d`` only, as PX4's multicopter position controller does (its acceleration
setpoint feed-forward; the position P loop's correction enters the velocity setpoint but is not
differentiated). Without the integral the loop is then ``(1 + K_D) s^2 + K_v s + K_v Lambda_p``:
damping 0.63 with the defaults, a slower, more oscillatory return to the path with the same
"equivalent" gains. Kept to fly a PX4-faithful baseline; the measured effect on the comparison is
in the README (section "Using the controller in your own loop").

Settings (``[controller.pid]``), defaults and why: ``K_I = (0.4, 0.4, 2.0) 1/s^2`` and
``K_D = (0.2, 0.2, 0.0)`` are PX4's ``MPC_XY_VEL_I_ACC``, ``MPC_Z_VEL_I_ACC``,
``MPC_XY_VEL_D_ACC``, ``MPC_Z_VEL_D_ACC`` defaults; the derivative is filtered at 5 Hz (PX4
``MPC_VELD_LP``). The integral time ``K_v/K_I`` = 4.5 s horizontally is what makes a PID slow to
follow the fan-array steps, which is the paper's point. The velocity P gain is the shared ``K_v``
(the "equivalent gains" of the paper's comparison).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ...config import Validated, setting
from ...frames import GRAVITY_MPS2
from ...layout import BlockLayout, Field
from .. import filters
from ..blocks import (D_LAW, P_K_V, P_LAW, S_LAW, S_RES_PREV_W, S_SAT_PREV, S_V_PREV, T_A_D, T_DT, T_NEW_DT,
                      T_V_R_DOT, T_V_TILDE, T_V_W, law_offsets)
from . import LawContext, finish, law_update, tick3


FEEDFORWARD_CHOICES = ("v_r_dot", "a_d")
"""Values of ``feedforward`` (module notes): the derivative of the velocity setpoint, or ``a_d`` only."""
FEEDFORWARD_DOC = ("reference feed-forward of the force command: 'v_r_dot' = a_d - Lambda_p (v - v_d), as "
                   "eq:f_ctrl in every other law (the fair comparison); 'a_d' = the desired acceleration "
                   "only, as PX4")


@dataclass(frozen=True)
class PIDSettings(Validated):
    """The PID's own gains (the ``[controller.pid]`` table)."""

    K_I: tuple[float, ...] = setting("1/s^2", "velocity-error integral gain, NED", default=(0.4, 0.4, 2.0),
                                     ge=0.0, length=3)
    K_D: tuple[float, ...] = setting("-", "velocity-derivative gain on the measured acceleration, NED",
                                     default=(0.2, 0.2, 0.0), ge=0.0, length=3)
    integrator_limit_mps2: tuple[float, ...] = setting(
        "m/s^2", "clamp of the integral term per axis, NED", default=(4.0, 4.0, 5.0), ge=0.0, length=3)
    derivative_cutoff_hz: float = setting("Hz", "low-pass on the measured acceleration", default=5.0, gt=0.0)
    feedforward: str = setting("-", FEEDFORWARD_DOC, default="v_r_dot", choices=FEEDFORWARD_CHOICES)


Settings = PIDSettings
"""The law interface's name for the settings class."""

TUNABLE = (("K_I[0:2]", 0.05, 20.0, True), ("K_I[2]", 0.2, 40.0, True), ("K_D[0:2]", 0.0, 2.0, False),
           ("derivative_cutoff_hz", 0.5, 40.0, True))
"""The gains ``vtoladapt tune`` searches (:mod:`vtoladapt.experiments.tuning`): (setting, low, high, log scale);
``[0:2]``: north and east together."""


PARAMS = BlockLayout("pid parameters", [
    Field("K_I", 3, "1/s^2", "velocity-error integral gain (0: no integral, the PD)"),
    Field("K_D", 3, "-", "velocity-derivative gain"),
    Field("INT_LIMIT", 3, "m/s^2", "clamp of the integral term"),
    Field("DERIV_HZ", 1, "Hz", "low-pass on the measured acceleration"),
    Field("FF_V_R_DOT", 1, "-", "1: feed forward v_r' (eq:f_ctrl's), 0: a_d only"),
])
STATE = BlockLayout("pid state", [
    Field("INTEGRATOR", 3, "m/s^2", "integral term, NED"),
    Field("VDOT_F", 3, "m/s^2", "filtered measured acceleration, NED"),
    Field("VDOT_INIT", 1, "-", "1 once the derivative filter has a sample"),
    Field("DERIV_GAIN", 1, "-", "gain of the derivative low-pass for the current dt"),
])
DIAG = BlockLayout("pid diagnostics", [
    Field("INTEGRATOR", 3, "m/s^2", "the integral term, NED (0 for the PD)",
          columns=("integrator_N_mps2", "integrator_E_mps2", "integrator_D_mps2")),
])
P_K_I, P_K_D, P_INT_LIMIT, P_DERIV_HZ, P_FF_V_R_DOT = law_offsets(PARAMS, P_LAW, "K_I", "K_D", "INT_LIMIT",
                                                                 "DERIV_HZ", "FF_V_R_DOT")
S_INT, S_VDOT_F, S_VDOT_INIT, S_DERIV_GAIN = law_offsets(STATE, S_LAW, "INTEGRATOR", "VDOT_F", "VDOT_INIT",
                                                         "DERIV_GAIN")
(D_INTEGRATOR,) = law_offsets(DIAG, D_LAW, "INTEGRATOR")


def fill_params(settings: PIDSettings, ctx: LawContext) -> np.ndarray:
    """The law's parameter block."""
    return PARAMS.pack(K_I=settings.K_I, K_D=settings.K_D, INT_LIMIT=settings.integrator_limit_mps2,
                       DERIV_HZ=settings.derivative_cutoff_hz,
                       FF_V_R_DOT=feedforward_flag(settings.feedforward))


def feedforward_flag(feedforward: str) -> float:
    """The parameter ``FF_V_R_DOT`` for a ``feedforward`` setting (1.0: v_r', 0.0: a_d)."""
    return 1.0 if feedforward == "v_r_dot" else 0.0


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """Integral and derivative filter empty (the shared start holds theta-hat = theta_init)."""


@njit(cache=True, inline="always")
def pid_force(params, state, integrate, v_W, v_tilde, ff, dt) -> tuple:
    """The force command ``f_r`` of the module notes, m/s^2 NED, with feed-forward ``ff`` (m/s^2 NED);
    the integral moves only if ``integrate``."""
    if state[S_VDOT_INIT] > 0.0:
        c_d = state[S_DERIV_GAIN]
        for i in range(3):
            state[S_VDOT_F + i] = filters.lowpass(state[S_VDOT_F + i], (v_W[i] - state[S_V_PREV + i]) / dt, c_d)
    state[S_VDOT_INIT] = 1.0
    saturated = state[S_SAT_PREV] != 0.0 or state[S_SAT_PREV + 1] != 0.0
    v_err = (-v_tilde[0], -v_tilde[1], -v_tilde[2])
    if integrate:
        for i in range(3):
            frozen = saturated and v_err[i] * state[S_RES_PREV_W + i] > 0.0
            if not frozen:
                lim = params[P_INT_LIMIT + i]
                state[S_INT + i] = min(max(state[S_INT + i] + params[P_K_I + i] * v_err[i] * dt, -lim), lim)
    return (ff[0] + params[P_K_V] * v_err[0] + state[S_INT] - params[P_K_D] * state[S_VDOT_F],
            ff[1] + params[P_K_V + 1] * v_err[1] + state[S_INT + 1] - params[P_K_D + 1] * state[S_VDOT_F + 1],
            ff[2] + params[P_K_V + 2] * v_err[2] + state[S_INT + 2] - params[P_K_D + 2] * state[S_VDOT_F + 2]
            - GRAVITY_MPS2)


@njit(cache=True, inline="always")
def pid_update(params, state, tick, diag, integrate) -> None:
    """The PID's (``integrate``) or PD's tick: the force command into the tick, the integral's diagnostics."""
    dt = tick[T_DT]
    if tick[T_NEW_DT] > 0.0:
        state[S_DERIV_GAIN] = filters.lowpass_gain(params[P_DERIV_HZ], dt)
    if params[P_FF_V_R_DOT] != 0.0:
        ff = tick3(tick, T_V_R_DOT)
    else:
        ff = tick3(tick, T_A_D)
    f_r = pid_force(params, state, integrate, tick3(tick, T_V_W), tick3(tick, T_V_TILDE), ff, dt)
    for i in range(3):
        diag[D_INTEGRATOR + i] = state[S_INT + i]
    finish(tick, f_r, False, 0)


@law_update
def update(params, state, tick, diag):
    """The PID force command (module notes); theta-hat is not adapted. See the law interface."""
    pid_update(params, state, tick, diag, True)
