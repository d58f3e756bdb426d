"""The flight computer's control allocator: collective lift and body moment -> lift rotors and surfaces.

It replaces the lift-rotor mixer of the airframe before issue #24 and works as PX4's control allocator
does for a standard VTOL (``ControlAllocator`` with ``ActuatorEffectivenessStandardVTOL``): an
*effectiveness matrix* ``B`` maps the actuators ``a`` (four lift-rotor thrusts in N, then the control
surfaces' deflections in rad) to what they produce, ``y = B a = [T, tau_x, tau_y, tau_z]`` (total lift
along body -z in N, body moment in N m), and a solver finds the actuators for the asked ``y``. The
matrix is scheduled with airspeed: the surfaces' columns are their moment derivatives times the dynamic
pressure the flight computer measures (``rho_0 |v_i|^2 / 2``, the airflow probe's incident velocity and
the vehicle file's air density; an invalid or non-finite reading counts as still air, so the surfaces are
then left neutral), which is what PX4's airspeed scaling of the surfaces does. In hover the surfaces'
columns vanish and the rotors do everything; at speed the surfaces take their share.

**The problem solved every tick** (normalised: each output row divided by the lift rotors' authority in
it, ``s_k``, and weighted by ``w_k``; each actuator divided by its scale ``r_i``, its range over its effort
weight -- :data:`ROTOR_EFFORT_WEIGHT` for the lift rotors, 1 for the surfaces):

    P(y, w):  minimise  sum_k w_k^2 (B a - y)_k^2 / s_k^2 + eps sum_i (a_i - p_i)^2 / r_i^2   over lo <= a <= hi,

with ``p`` the preferred actuators (the four rotors sharing the asked lift equally, surfaces neutral) and
``eps`` (:data:`ALLOCATION_EPS`) small. The effort weight makes the rotors' differential thrust the
costlier way to a moment, so wherever the surfaces can make it they do (at speed, as on a real standard
VTOL) and the rotors take what they cannot (in hover, where the surfaces' columns vanish, or past their
limits). **Stage 1**: ``P(y, (1, 1, 1, 1))``. A feasible demand is met to
``~eps`` (exactly, for every purpose), and of the actuators that meet it the least deflected are chosen;
that is every tick where nothing saturates. **Priority** (only when stage 1 cannot meet the demand):
thrust, roll and pitch before yaw, as PX4's allocator does. **Stage 2** ``P(y, (1, 1, 1, 0))`` finds the
thrust, roll and pitch ``y1`` the actuators can give with yaw ignored (if even those cannot all be met,
they share the shortfall in proportion to the rotors' authority); **stage 3** ``P((y1, y_yaw), (1, 1, 1,
1/H))`` with ``H`` = :data:`HOLD_WEIGHT` then gives yaw what is left while holding ``y1`` (each held
output gives way by ``~1/H^2`` of yaw's remaining error: a priority, not a hard constraint, so that the
least-deflection term keeps its meaning in every stage). What one actuator cannot do the others take (redistribution: each stage is a bounded least
squares, not a clip). The allocator keeps no state,
so nothing winds up in it, and it reports what it achieved: the applied collective goes back to the
adaptation (:func:`vtoladapt.sim.loop.report_mixed`) and the asked and achieved ``[T, tau]`` go to the log.

The solver (:func:`solve_box_lsq`) is a primal active-set method on the box; each of its steps solves the
free actuators through the 4 x 4 system ``B_F B_F^T + eps I`` (the push-through form of the normal
equations), so a tick with no bound reached costs one 4 x 4 solve.

An airframe gives its effectiveness through the ``"effectiveness"`` component kind
(:data:`EFFECTIVENESS`): the package's ``"lift_rotors_surfaces"`` (four lift rotors, a pass-through pusher
and the vehicle file's surfaces); a user's airframe registers its own module with a function
``effectiveness(vehicle) -> Effectiveness``. The solver is the same for every airframe.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import ModuleType

import numpy as np
from numba import njit

from ..components import Registry
from ..layout import (ACTUATORS, ACT_SURFACE, CMD_TAU_B, CMD_U_X, CMD_U_Z, MEAS_V_I_B, MEAS_V_I_VALID, MOTOR_PUSHER, N_LIFT,
                      N_SURFACES, BlockLayout, Field)

N_OUT = 4
"""Allocated outputs: total lift (N) and the three body moments (N m)."""
N_ALLOC = ACTUATORS.field("LIFT").size + ACTUATORS.field("SURFACE").size
"""Allocated actuators: the lift rotors' thrusts (N), then the surfaces' deflections (rad)."""
ALLOCATION_EPS = 1e-9
"""Weight of the least-deflection term against the (normalised) demand error."""
HOLD_WEIGHT = 1000.0
"""Stage 3's weight on the thrust, roll and pitch found in stage 2 against yaw's."""
ROTOR_EFFORT_WEIGHT = 10.0
"""How much costlier a lift rotor's deviation from its share of the lift is than a surface's deflection, each
in its own range (the least-deflection term's weight, squared: 100)."""
SATURATION_TOL = 1e-6
"""A demand counts as met when every output's error is below this fraction of the rotors' authority in it."""
MAX_ITERATIONS = 4 * N_ALLOC
"""Active-set changes at most per tick (each adds or drops one bound; a box QP of 8 needs far fewer)."""

ALLOC_PARAMS = BlockLayout("allocator parameters", [
    Field("B0", N_OUT * N_ALLOC, "-", "normalised effectiveness at zero dynamic pressure, row-major"),
    Field("BQ", N_OUT * N_ALLOC, "1/Pa", "normalised effectiveness per pascal of dynamic pressure, row-major"),
    Field("ROW_SCALE", N_OUT, "N, N m", "output k's normalisation: its error counts as (B a - y)_k / ROW_SCALE_k"),
    Field("COL_RANGE", N_ALLOC, "N, rad", "actuator i's scale (its range over its effort weight): the normalised "
          "actuator is a_i / COL_RANGE_i"),
    Field("LO", N_ALLOC, "N, rad", "actuator lower bounds"),
    Field("HI", N_ALLOC, "N, rad", "actuator upper bounds"),
    Field("PREF_SHARE", N_ALLOC, "-", "preferred actuator per newton of asked lift"),
    Field("EPS", 1, "-", "weight of the least-deflection term"),
    Field("T_UNIT", 1, "N", "thrust of one lift rotor at full throttle (the vehicle file's)"),
    Field("TOTAL_UNIT", 1, "N", "total lift at full collective (N_LIFT x T_UNIT)"),
    Field("U_MAX", 1, "-", "throttle limit, fraction"),
    Field("RHO", 1, "kg/m^3", "air density the flight computer assumes (the vehicle file's)"),
    Field("METHOD", 1, "-", "the solver: METHOD_BOUNDED_LSQ (0) or METHOD_PX4 (1, sequential desaturation)"),
    Field("AIRMODE", 1, "-", "PX4's MC_AIRMODE for METHOD_PX4: 0 disabled, 1 roll/pitch, 2 roll/pitch/yaw"),
    Field("PX4_MIX", N_LIFT * N_OUT, "-", "METHOD_PX4: the lift rotors' normalised pseudo-inverse (rotor i's "
          "thrust fraction per normalised [T, roll, pitch, yaw] setpoint), row-major N_LIFT x N_OUT"),
    Field("PX4_SCALE", N_OUT, "1/N, 1/(N m)", "METHOD_PX4: normalised setpoint per newton (thrust) or newton "
          "metre (moments): PX4's control allocation scale"),
    Field("PX4_ROTOR_MAX", N_LIFT, "N", "METHOD_PX4: each lift rotor's largest thrust (its thrust fraction's unit)"),
    Field("PX4_SURF_MIX", N_SURFACES * 3, "rad Pa/(N m)", "METHOD_PX4: pseudo-inverse of the surfaces' moment "
          "per pascal and radian, row-major N_SURFACES x 3 (divided by the tick's dynamic pressure)"),
    Field("PX4_QBAR_MIN", 1, "Pa", "METHOD_PX4: below this dynamic pressure the surfaces stay neutral (the "
          "vehicle's hover_blend_airspeed_mps[0])"),
])
"""The allocator's kernel parameter array (:func:`allocator_params`)."""
(AL_B0, AL_BQ, AL_ROW_SCALE, AL_COL_RANGE, AL_LO, AL_HI, AL_PREF_SHARE, AL_EPS, AL_T_UNIT, AL_TOTAL_UNIT,
 AL_U_MAX, AL_RHO, AL_METHOD, AL_AIRMODE, AL_PX4_MIX, AL_PX4_SCALE, AL_PX4_ROTOR_MAX, AL_PX4_SURF_MIX,
 AL_PX4_QBAR_MIN) = ALLOC_PARAMS.offsets(*(f.name for f in ALLOC_PARAMS.fields))
AL_SIZE = ALLOC_PARAMS.size
METHODS = ("bounded_lsq", "px4")
"""``[allocation] method``: the weighted bounded least squares (default) or PX4's sequential desaturation."""
METHOD_BOUNDED_LSQ = METHODS.index("bounded_lsq")
"""The kernel's code of each method: its position in :data:`METHODS` (the parameters' ``METHOD``)."""
METHOD_PX4 = METHODS.index("px4")
PX4_YAW_HEADROOM = 0.15
"""PX4's temporary headroom above the rotors' upper bound while yaw is desaturated (a fraction of their range)."""
PX4_MIN_DESATURATION_ENTRY = 0.2
"""PX4 does not desaturate through an actuator whose normalised mix entry on the axis is below this."""
PX4_MIX_ZERO = 1e-3
"""Normalised mix entries below this are set to zero, as PX4 does after normalising."""

ALLOC_REPORT = BlockLayout("allocation report", [
    Field("ASKED", N_OUT, "N, N m", "asked total lift and body moment",
          columns=("alloc_asked_T_N", "alloc_asked_tau_x_Nm", "alloc_asked_tau_y_Nm", "alloc_asked_tau_z_Nm")),
    Field("ACHIEVED", N_OUT, "N, N m", "what the allocated actuators produce by the allocator's model",
          columns=("alloc_achieved_T_N", "alloc_achieved_tau_x_Nm", "alloc_achieved_tau_y_Nm",
                   "alloc_achieved_tau_z_Nm")),
    Field("QBAR", 1, "Pa", "dynamic pressure the effectiveness was scheduled with", columns=("alloc_qbar_Pa",)),
    Field("UNMET_LIFT_ATTITUDE", 1, "-", "1.0 when even thrust, roll and pitch could not all be met (stage 2 "
          "saturated), not only yaw", columns=("alloc_unmet_lift_attitude",)),
])
"""What the allocator reports each tick (logged)."""
ALLOC_WORK = BlockLayout("allocator work", [
    Field("B", N_OUT * N_ALLOC, "-", "this tick's normalised effectiveness, row-major"),
    Field("Y", N_OUT, "-", "normalised demand"),
    Field("A", N_ALLOC, "-", "normalised actuators (the iterate)"),
    Field("P", N_ALLOC, "-", "normalised preferred actuators"),
    Field("LO", N_ALLOC, "-", "normalised lower bounds"),
    Field("HI", N_ALLOC, "-", "normalised upper bounds"),
    Field("STATE", N_ALLOC, "-", "0 free, -1 at its lower bound, +1 at its upper bound"),
    Field("TRIAL", N_ALLOC, "-", "the free actuators' minimiser for the current bounds"),
    Field("M", N_OUT * N_OUT, "-", "the 4 x 4 system and its Cholesky factor"),
    Field("R", N_OUT, "-", "residual / right-hand side"),
    Field("YAW_ROW", N_ALLOC + 1, "-", "the yaw row of B and its demand, kept while stage 2 ignores yaw"),
    Field("REPORT", ALLOC_REPORT.size, "-", "the tick's ALLOC_REPORT"),
])
"""Scratch of :func:`allocate` (part of the tick's work array; nothing in it outlives a tick but the report)."""
(_A_B, _A_Y, _A_A, _A_P, _A_LO, _A_HI, _A_STATE, _A_TRIAL, _A_M, _A_R, _A_YAW_ROW, _A_REPORT) = ALLOC_WORK.offsets(
    *(f.name for f in ALLOC_WORK.fields))
ALLOC_WORK_SIZE = ALLOC_WORK.size
_R_ASKED, _R_ACHIEVED, _R_QBAR, _R_UNMET_LA = ALLOC_REPORT.offsets("ASKED", "ACHIEVED", "QBAR", "UNMET_LIFT_ATTITUDE")
ALLOC_REPORT_OFFSET = _A_REPORT
"""Where the report lies in :data:`ALLOC_WORK`."""


# --- the generic solver -------------------------------------------------------------------------------
@njit(cache=True, nogil=True, _nrt=False)
def _free_minimiser(w, o, eps) -> None:
    """The minimiser over the free actuators with the bound ones held: ``TRIAL`` (bound ones copied).

    ``d_F = B_F^T (B_F B_F^T + eps I)^{-1} r`` with ``r = y - B a_fixed - B_F p_F``: the push-through form
    of ``(B_F^T B_F + eps I) d_F = B_F^T r``.
    """
    B = o + _A_B
    M = o + _A_M
    R = o + _A_R
    for k in range(N_OUT):
        r = w[o + _A_Y + k]
        for i in range(N_ALLOC):
            st = w[o + _A_STATE + i]
            r -= w[B + k * N_ALLOC + i] * (w[o + _A_P + i] if st == 0.0 else w[o + _A_A + i])
        w[R + k] = r
        for m in range(k + 1):
            s = eps if m == k else 0.0
            for i in range(N_ALLOC):
                if w[o + _A_STATE + i] == 0.0:
                    s += w[B + k * N_ALLOC + i] * w[B + m * N_ALLOC + i]
            w[M + k * N_OUT + m] = s
    # Cholesky M = L L^T in place (lower triangle), then solve L L^T z = r into R
    for k in range(N_OUT):
        s = w[M + k * N_OUT + k]
        for m in range(k):
            s -= w[M + k * N_OUT + m] ** 2
        lkk = np.sqrt(max(s, 1e-300))
        w[M + k * N_OUT + k] = lkk
        for j in range(k + 1, N_OUT):
            s = w[M + j * N_OUT + k]
            for m in range(k):
                s -= w[M + j * N_OUT + m] * w[M + k * N_OUT + m]
            w[M + j * N_OUT + k] = s / lkk
    for k in range(N_OUT):
        s = w[R + k]
        for m in range(k):
            s -= w[M + k * N_OUT + m] * w[R + m]
        w[R + k] = s / w[M + k * N_OUT + k]
    for k in range(N_OUT - 1, -1, -1):
        s = w[R + k]
        for m in range(k + 1, N_OUT):
            s -= w[M + m * N_OUT + k] * w[R + m]
        w[R + k] = s / w[M + k * N_OUT + k]
    for i in range(N_ALLOC):
        if w[o + _A_STATE + i] == 0.0:
            d = 0.0
            for k in range(N_OUT):
                d += w[B + k * N_ALLOC + i] * w[R + k]
            w[o + _A_TRIAL + i] = w[o + _A_P + i] + d
        else:
            w[o + _A_TRIAL + i] = w[o + _A_A + i]


@njit(cache=True, nogil=True, _nrt=False)
def solve_box_lsq(w, o, eps) -> int:
    """Minimise ``|B a - y|^2 + eps |a - p|^2`` over ``LO <= a <= HI`` (all in ``w[o:]``'s ALLOC_WORK,
    normalised); the solution is left in ``A``. Returns the active-set iterations used.

    Primal active set: start from the unconstrained minimiser clipped to the box (its clipped actuators
    held at their bounds); solve for the free actuators; if that leaves the box, step toward it as far as
    the box allows and hold the actuator that blocks; else release the held actuator whose multiplier has
    the wrong sign (the gradient pushing it back inside), or stop when none has: the KKT conditions of
    this strictly convex problem, so the minimum.
    """
    for i in range(N_ALLOC):
        # an actuator with no range (a surface the airframe lacks, or switched off) is held from the start
        fixed = w[o + _A_LO + i] == w[o + _A_HI + i]
        w[o + _A_STATE + i] = -1.0 if fixed else 0.0
        w[o + _A_A + i] = w[o + _A_LO + i]
    _free_minimiser(w, o, eps)
    clipped = False
    for i in range(N_ALLOC):
        if w[o + _A_STATE + i] != 0.0:
            continue
        t = w[o + _A_TRIAL + i]
        lo = w[o + _A_LO + i]
        hi = w[o + _A_HI + i]
        if t < lo:
            w[o + _A_A + i] = lo
            w[o + _A_STATE + i] = -1.0
            clipped = True
        elif t > hi:
            w[o + _A_A + i] = hi
            w[o + _A_STATE + i] = 1.0
            clipped = True
        else:
            w[o + _A_A + i] = t
    if not clipped:
        return 0  # the unconstrained minimiser is inside the box: it is the solution (every unsaturated tick)
    it = 0
    while it < MAX_ITERATIONS:
        it += 1
        _free_minimiser(w, o, eps)
        # largest step toward TRIAL inside the box
        step = 1.0
        block = -1
        for i in range(N_ALLOC):
            if w[o + _A_STATE + i] != 0.0:
                continue
            a = w[o + _A_A + i]
            t = w[o + _A_TRIAL + i]
            if t < w[o + _A_LO + i]:
                s = (w[o + _A_LO + i] - a) / (t - a) if t != a else 0.0
                if s < step:
                    step = s
                    block = i
            elif t > w[o + _A_HI + i]:
                s = (w[o + _A_HI + i] - a) / (t - a) if t != a else 0.0
                if s < step:
                    step = s
                    block = i
        step = max(step, 0.0)
        for i in range(N_ALLOC):
            if w[o + _A_STATE + i] == 0.0:
                w[o + _A_A + i] += step * (w[o + _A_TRIAL + i] - w[o + _A_A + i])
        if block >= 0:
            if w[o + _A_TRIAL + block] < w[o + _A_LO + block]:
                w[o + _A_A + block] = w[o + _A_LO + block]
                w[o + _A_STATE + block] = -1.0
            else:
                w[o + _A_A + block] = w[o + _A_HI + block]
                w[o + _A_STATE + block] = 1.0
            continue
        # at the minimiser of this face: check the held actuators' multipliers (gradient of the objective)
        B = o + _A_B
        R = o + _A_R
        for k in range(N_OUT):
            r = -w[o + _A_Y + k]
            for i in range(N_ALLOC):
                r += w[B + k * N_ALLOC + i] * w[o + _A_A + i]
            w[R + k] = r
        worst = 0.0
        release = -1
        for i in range(N_ALLOC):
            st = w[o + _A_STATE + i]
            if st == 0.0 or w[o + _A_LO + i] == w[o + _A_HI + i]:
                continue
            g = eps * (w[o + _A_A + i] - w[o + _A_P + i])
            for k in range(N_OUT):
                g += w[B + k * N_ALLOC + i] * w[R + k]
            # at the lower bound (st = -1) the gradient must be >= 0, at the upper (+1) <= 0; else moving
            # inside lowers the objective: st g > 0 is how wrong the held actuator is
            v = st * g
            if v > 1e-13 and v > worst:
                worst = v
                release = i
        if release < 0:
            break
        w[o + _A_STATE + release] = 0.0
    return it


@njit(cache=True, nogil=True, _nrt=False)
def _unmet(w, o, n_rows) -> float:
    """The largest normalised error ``|B a - y|_k`` of the first ``n_rows`` outputs at the iterate."""
    worst = 0.0
    for k in range(n_rows):
        y = -w[o + _A_Y + k]
        for i in range(N_ALLOC):
            y += w[o + _A_B + k * N_ALLOC + i] * w[o + _A_A + i]
        worst = max(worst, abs(y))
    return worst


@njit(cache=True, nogil=True, _nrt=False)
def allocate(cmd, meas, p, act_cmd, w, o) -> bool:
    """Actuator commands (lift rotors and pusher as throttle fractions, surfaces in rad) for a controller
    command (compiled, unchecked).

    ``cmd``: the controller's command (``CMD_*``); ``meas``: the tick's measurement (its incident velocity
    schedules the surfaces); ``p``: :func:`allocator_params`; writes ``act_cmd[0:N_ACTUATORS]`` and the
    report in ``w[o + ALLOC_REPORT_OFFSET:]`` (``w[o:]`` is :data:`ALLOC_WORK` scratch). Returns True when
    the asked lift and moment could not all be met (the allocator saturated). Non-finite command entries
    count as zero so that the actuators never receive NaN.
    """
    u_max = p[AL_U_MAX]
    uz = cmd[CMD_U_Z] if np.isfinite(cmd[CMD_U_Z]) else 0.0
    uz = min(max(uz, 0.0), u_max)
    T = p[AL_TOTAL_UNIT] * uz * uz
    vx = meas[MEAS_V_I_B]
    vy = meas[MEAS_V_I_B + 1]
    vz = meas[MEAS_V_I_B + 2]
    V2 = vx * vx + vy * vy + vz * vz
    qbar = 0.5 * p[AL_RHO] * V2 if (meas[MEAS_V_I_VALID] > 0.0 and np.isfinite(V2)) else 0.0
    rep = o + _A_REPORT
    w[rep + _R_ASKED] = T
    for k in range(3):
        t = cmd[CMD_TAU_B + k]
        w[rep + _R_ASKED + 1 + k] = t if np.isfinite(t) else 0.0
    w[rep + _R_QBAR] = qbar
    for k in range(N_OUT):
        w[o + _A_Y + k] = w[rep + _R_ASKED + k] / p[AL_ROW_SCALE + k]
        for i in range(N_ALLOC):
            j = k * N_ALLOC + i
            w[o + _A_B + j] = p[AL_B0 + j] + qbar * p[AL_BQ + j]
    for i in range(N_ALLOC):
        r = p[AL_COL_RANGE + i]
        w[o + _A_P + i] = p[AL_PREF_SHARE + i] * T / r
        w[o + _A_LO + i] = p[AL_LO + i] / r
        w[o + _A_HI + i] = p[AL_HI + i] / r
    if p[AL_METHOD] == METHOD_PX4:
        _allocate_px4(p, w, o, qbar)
        saturated = _unmet(w, o, N_OUT) > SATURATION_TOL
        w[rep + _R_UNMET_LA] = 1.0 if _unmet(w, o, N_OUT - 1) > SATURATION_TOL else 0.0
    else:
        saturated = _allocate_bounded_lsq(w, o, p[AL_EPS], rep)
    for k in range(N_OUT):
        y = 0.0
        for i in range(N_ALLOC):
            j = k * N_ALLOC + i
            y += (p[AL_B0 + j] + qbar * p[AL_BQ + j]) * w[o + _A_A + i]
        w[rep + _R_ACHIEVED + k] = y * p[AL_ROW_SCALE + k]
    t_unit = p[AL_T_UNIT]
    for i in range(N_LIFT):
        Ti = min(max(w[o + _A_A + i] * p[AL_COL_RANGE + i], 0.0), t_unit * u_max * u_max)
        act_cmd[i] = np.sqrt(Ti / t_unit)
    for j in range(N_SURFACES):
        act_cmd[ACT_SURFACE + j] = w[o + _A_A + N_LIFT + j] * p[AL_COL_RANGE + N_LIFT + j]
    ux = cmd[CMD_U_X] if np.isfinite(cmd[CMD_U_X]) else 0.0
    act_cmd[MOTOR_PUSHER] = min(max(ux, 0.0), u_max)
    return saturated


@njit(cache=True, nogil=True, _nrt=False)
def _allocate_bounded_lsq(w, o, eps, rep) -> bool:
    """The weighted bounded least squares in stages (module docstring) on the tick's ``w[o:]``; True when
    stage 1 could not meet the demand."""
    solve_box_lsq(w, o, eps)
    saturated = _unmet(w, o, N_OUT) > SATURATION_TOL
    w[rep + _R_UNMET_LA] = 0.0
    if saturated:
        # stage 2: thrust, roll and pitch with yaw ignored (its row and demand kept aside)
        yaw = N_OUT - 1
        for i in range(N_ALLOC):
            w[o + _A_YAW_ROW + i] = w[o + _A_B + yaw * N_ALLOC + i]
            w[o + _A_B + yaw * N_ALLOC + i] = 0.0
        w[o + _A_YAW_ROW + N_ALLOC] = w[o + _A_Y + yaw]
        w[o + _A_Y + yaw] = 0.0
        solve_box_lsq(w, o, eps)
        w[rep + _R_UNMET_LA] = 1.0 if _unmet(w, o, yaw) > SATURATION_TOL else 0.0
        # stage 3: hold what stage 2 achieved and give yaw, weighted 1/H, the rest
        for k in range(yaw):
            y = 0.0
            for i in range(N_ALLOC):
                y += w[o + _A_B + k * N_ALLOC + i] * w[o + _A_A + i]
            w[o + _A_Y + k] = y
        for i in range(N_ALLOC):
            w[o + _A_B + yaw * N_ALLOC + i] = w[o + _A_YAW_ROW + i] / HOLD_WEIGHT
        w[o + _A_Y + yaw] = w[o + _A_YAW_ROW + N_ALLOC] / HOLD_WEIGHT
        solve_box_lsq(w, o, eps)
        # stage 3 restored yaw's row scaled by 1/H: the achieved outputs are computed from the parameters
    return saturated


# --- PX4's sequential desaturation ---------------------------------------------------------------------
@njit(cache=True, nogil=True, _nrt=False)
def _px4_gain(p, sp, so, axis, hi_extra) -> float:
    """PX4's desaturation gain along the mix column ``axis`` for the rotor setpoints ``sp[so:so+N_LIFT]``
    (thrust fractions, bounds ``[lo, 1 + hi_extra]``): of the gains that bring each saturated rotor back to
    its bound, the sum of the most negative and the most positive (zero where none): a compromise
    when rotors need opposite moves. Rotors whose entry is below :data:`PX4_MIN_DESATURATION_ENTRY` are
    not used (a weak entry would ask a large gain)."""
    k_min = 0.0
    k_max = 0.0
    for i in range(N_LIFT):
        d = p[AL_PX4_MIX + i * N_OUT + axis]
        if abs(d) < PX4_MIN_DESATURATION_ENTRY:
            continue
        lo = p[AL_LO + i] / p[AL_PX4_ROTOR_MAX + i]
        hi = 1.0 + hi_extra
        v = sp[so + i]
        k = 0.0
        if v < lo:
            k = (lo - v) / d
        elif v > hi:
            k = (hi - v) / d
        else:
            continue
        k_min = min(k_min, k)
        k_max = max(k_max, k)
    return k_min + k_max


@njit(cache=True, nogil=True, _nrt=False)
def _px4_desaturate(p, sp, so, axis, reduce_thrust_only, hi_extra) -> None:
    """Move the rotor setpoints along the mix column ``axis`` by PX4's gain, then by half the gain that is
    left (PX4's two steps). ``reduce_thrust_only`` (thrust axis): skip when the first gain would add thrust
    (our thrust column is positive: lift is along -z, PX4's is negative)."""
    g = _px4_gain(p, sp, so, axis, hi_extra)
    if reduce_thrust_only and g > 0.0:
        return
    for i in range(N_LIFT):
        sp[so + i] += g * p[AL_PX4_MIX + i * N_OUT + axis]
    g = 0.5 * _px4_gain(p, sp, so, axis, hi_extra)
    for i in range(N_LIFT):
        sp[so + i] += g * p[AL_PX4_MIX + i * N_OUT + axis]


@njit(cache=True, nogil=True, _nrt=False)
def _allocate_px4(p, w, o, qbar) -> None:
    """PX4's allocation of the tick (module docstring of :func:`allocator_params`'s ``method="px4"``): the
    surfaces by the pseudo-inverse of their scheduled moment columns, clipped; the lift rotors by PX4's
    sequential desaturation of what the surfaces left. Leaves the actuators, normalised as the bounded
    least squares' (``a_i / COL_RANGE_i``), in ``A``."""
    T0 = 0
    YAW = N_OUT - 1
    # the surfaces (PX4's fixed-wing allocation: pseudo-inverse and clip); neutral at low dynamic pressure
    for j in range(N_SURFACES):
        d = 0.0
        if qbar >= p[AL_PX4_QBAR_MIN] and qbar > 0.0:
            for k in range(3):
                d += p[AL_PX4_SURF_MIX + 3 * j + k] * w[o + _A_Y + 1 + k] * p[AL_ROW_SCALE + 1 + k]
            d /= qbar
        i = N_LIFT + j
        d = min(max(d, p[AL_LO + i]), p[AL_HI + i])
        w[o + _A_A + i] = d / p[AL_COL_RANGE + i]
    # what the rotors are asked: the demand less what the surfaces make (lift too: their CZ)
    c = o + _A_R  # the normalised setpoint [T, roll, pitch, yaw], PX4's units
    for k in range(N_OUT):
        y = w[o + _A_Y + k]
        for j in range(N_SURFACES):
            y -= w[o + _A_B + k * N_ALLOC + N_LIFT + j] * w[o + _A_A + N_LIFT + j]
        w[c + k] = y * p[AL_ROW_SCALE + k] * p[AL_PX4_SCALE + k]
    sp = o + _A_TRIAL   # the rotors' thrust fractions
    airmode = p[AL_AIRMODE]
    for i in range(N_LIFT):
        s = 0.0
        for k in range(N_OUT):
            if k == YAW and airmode != 2.0:
                continue
            s += p[AL_PX4_MIX + i * N_OUT + k] * w[c + k]
        w[sp + i] = s
    if airmode == 2.0:      # roll, pitch and yaw airmode: thrust moves either way, then yaw gives way
        _px4_desaturate(p, w, sp, T0, False, 0.0)
        _px4_desaturate(p, w, sp, YAW, False, 0.0)
    else:
        if airmode == 1.0:  # roll/pitch airmode: thrust may rise to keep roll and pitch
            _px4_desaturate(p, w, sp, T0, False, 0.0)
        else:               # airmode off: thrust may only fall, then roll and pitch give way
            _px4_desaturate(p, w, sp, T0, True, 0.0)
            _px4_desaturate(p, w, sp, 1, False, 0.0)
            _px4_desaturate(p, w, sp, 2, False, 0.0)
        # yaw last, with a temporary headroom above full thrust, then thrust falls back inside
        for i in range(N_LIFT):
            w[sp + i] += p[AL_PX4_MIX + i * N_OUT + YAW] * w[c + YAW]
        _px4_desaturate(p, w, sp, YAW, False, PX4_YAW_HEADROOM)
        _px4_desaturate(p, w, sp, T0, True, 0.0)
    for i in range(N_LIFT):
        lo = p[AL_LO + i] / p[AL_PX4_ROTOR_MAX + i]
        x = min(max(w[sp + i], lo), 1.0)
        w[o + _A_A + i] = x * p[AL_PX4_ROTOR_MAX + i] / p[AL_COL_RANGE + i]


# --- effectiveness: the component kind ----------------------------------------------------------------
@dataclass(frozen=True)
class Effectiveness:
    """An airframe's effectiveness for the allocator, in physical units.

    ``B0`` (4 x 8) and ``B_per_Pa`` (4 x 8): ``[T, tau_x, tau_y, tau_z] = (B0 + qbar B_per_Pa) a`` for the
    actuators ``a`` (:data:`N_LIFT` lift-rotor thrusts in N, then :data:`N_SURFACES` surface deflections in
    rad); ``lower``/``upper``: the actuators' bounds (equal bounds: an actuator the airframe lacks);
    ``preferred_share``: the preferred actuator per newton of asked lift; ``t_unit_N``: one lift rotor's
    thrust at full throttle; ``throttle_max``: the throttle limit (fraction).
    """

    B0: np.ndarray
    B_per_Pa: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    preferred_share: np.ndarray
    t_unit_N: float
    throttle_max: float


@dataclass(frozen=True)
class EffectivenessInfo:
    """A member of the ``"effectiveness"`` kind: ``id``, a one-line ``description`` and the ``module``
    (relative to :mod:`vtoladapt.sim`, or absolute) whose ``effectiveness(vehicle) -> Effectiveness`` builds
    the airframe's matrices from a vehicle (the flight computer's: never the plant's truth)."""

    id: str
    description: str
    module: str


def _check_effectiveness_module(module: ModuleType) -> None:
    if not callable(getattr(module, "effectiveness", None)):
        raise TypeError(f"effectiveness module {module.__name__!r} has no function effectiveness(vehicle)")


EFFECTIVENESS: Registry = Registry("effectiveness", _check_effectiveness_module, (
    EffectivenessInfo("lift_rotors_surfaces", "four lift rotors (thrust, roll, pitch, yaw), a pass-through "
                      "pusher and the vehicle file's [[surfaces]] scheduled with dynamic pressure",
                      "effectiveness"),
    EffectivenessInfo("px4_ca", "four lift rotors and the surfaces as PX4's CA_* airframe parameters describe "
                      "them (the vehicle file's [effectiveness_settings.px4_ca]): a PX4 build's belief",
                      "effectiveness_px4"),
), package=__package__)
"""The airframes the allocator knows (:mod:`vtoladapt.components`: register a user's with
``register("effectiveness", EffectivenessInfo(...))``)."""


def px4_mix(B_rotors_per_fraction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """PX4's normalised pseudo-inverse of the lift rotors' effectiveness (``ControlAllocationPseudoInverse``).

    ``B_rotors_per_fraction`` (N_OUT x N_LIFT): ``[T, tau_x, tau_y, tau_z]`` per unit thrust fraction of each
    rotor. Returns ``(mix, scale)``: ``mix`` (N_LIFT x N_OUT) with ``mix @ (scale * y) = pinv(B) @ y`` for
    every ``y`` up to the entries PX4 zeroes (below :data:`PX4_MIX_ZERO`). The scales are PX4's: roll and
    pitch share one, ``sqrt(|column|^2 / (n / 2))`` over the rotors acting on the axis, the larger of the
    two; yaw its column's largest entry; thrust the mean magnitude of the thrust column's non-zero entries.
    They fix the units of :data:`PX4_MIN_DESATURATION_ENTRY` (a normalised quad's entries are about 1).
    """
    M = np.linalg.pinv(np.asarray(B_rotors_per_fraction, dtype=float))
    scale = np.ones(N_OUT)
    rp = []
    for k in (1, 2):
        n = int(np.count_nonzero(np.abs(M[:, k]) > PX4_MIX_ZERO))
        rp.append(math.sqrt(float(M[:, k] @ M[:, k]) / (n / 2.0)) if n else 1.0)
    scale[1] = scale[2] = max(rp)
    yaw_max = float(M[:, 3].max())
    scale[3] = yaw_max if yaw_max > 0.0 else 1.0
    thrust = np.abs(M[:, 0])
    scale[0] = float(thrust[thrust > 0.0].mean()) if np.any(thrust > 0.0) else 1.0
    mix = M / scale[None, :]
    mix[np.abs(mix) < PX4_MIX_ZERO] = 0.0
    return mix, scale


def effectiveness_of(vehicle, effectiveness_id: str | None = None) -> Effectiveness:
    """The :class:`Effectiveness` of ``vehicle`` through ``effectiveness_id`` (default: the vehicle file's
    ``effectiveness``)."""
    eid = effectiveness_id or getattr(vehicle, "effectiveness", "") or "lift_rotors_surfaces"
    eff = EFFECTIVENESS.module(eid).effectiveness(vehicle)
    if not isinstance(eff, Effectiveness):
        raise TypeError(f"effectiveness {eid!r}: effectiveness(vehicle) returned {type(eff).__name__}, "
                        "not an Effectiveness")
    for name, shape in (("B0", (N_OUT, N_ALLOC)), ("B_per_Pa", (N_OUT, N_ALLOC)), ("lower", (N_ALLOC,)),
                        ("upper", (N_ALLOC,)), ("preferred_share", (N_ALLOC,))):
        a = np.asarray(getattr(eff, name), dtype=float)
        if a.shape != shape or not np.all(np.isfinite(a)):
            raise ValueError(f"effectiveness {eid!r}: {name} has shape {a.shape} or non-finite entries; "
                             f"allowed: finite, shape {shape}")
    return eff


def allocator_params(vehicle, surfaces: bool = True, effectiveness_id: str | None = None,
                     method: str = "bounded_lsq", airmode: int = 0) -> np.ndarray:
    """The allocator's kernel parameters for ``vehicle`` (the flight computer's model), through the
    effectiveness ``effectiveness_id`` (default: the vehicle file's ``effectiveness``). ``surfaces=False``
    flies without them: their columns are zeroed and their bounds closed, so the rotors do every moment
    (the airframe before #24).

    ``method``: ``"bounded_lsq"`` (the weighted bounded least squares of the module docstring) or ``"px4"``,
    PX4's ``ControlAllocationSequentialDesaturation`` with ``airmode`` its ``MC_AIRMODE`` (0, 1, 2). With
    ``"px4"`` the surfaces take the moment first, as PX4's fixed-wing allocation does (the pseudo-inverse of
    their moment columns at the tick's dynamic pressure, clipped to their limits; neutral below the dynamic
    pressure of the vehicle's ``hover_blend_airspeed_mps[0]``), and the lift rotors take the rest of the lift
    and moment: PX4's multicopter allocation, the normalised pseudo-inverse (:func:`px4_mix`) desaturated
    axis by axis -- airmode 0: thrust only down, then roll, then pitch; yaw last, with a temporary
    :data:`PX4_YAW_HEADROOM` above full thrust, then thrust down again; airmode 1: thrust either way,
    then yaw as in 0; airmode 2: yaw mixed with the rest, thrust either way, then yaw -- and clipped.
    """
    if method not in METHODS:
        raise ValueError(f"method = {method!r}: unknown; allowed: {', '.join(METHODS)}")
    if airmode not in (0, 1, 2):
        raise ValueError(f"airmode = {airmode!r}: allowed: 0, 1, 2 (PX4's MC_AIRMODE)")
    eff = effectiveness_of(vehicle, effectiveness_id)
    B0 = np.array(eff.B0, dtype=float).reshape(N_OUT, N_ALLOC)
    Bq = np.array(eff.B_per_Pa, dtype=float).reshape(N_OUT, N_ALLOC)
    lo = np.array(eff.lower, dtype=float)
    hi = np.array(eff.upper, dtype=float)
    if not surfaces:
        Bq = np.zeros_like(Bq)
        B0[:, N_LIFT:] = 0.0
        lo[N_LIFT:] = 0.0
        hi[N_LIFT:] = 0.0
    col_range = np.maximum(hi - lo, 0.0)
    col_range[col_range == 0.0] = 1.0
    col_range[:N_LIFT] /= ROTOR_EFFORT_WEIGHT
    # each output normalised by what the lift rotors can do in it (all four at full thrust, with its sign)
    row_scale = np.abs(B0[:, :N_LIFT]) @ hi[:N_LIFT]
    row_scale[row_scale == 0.0] = 1.0
    W = 1.0 / row_scale
    rotor_max = hi[:N_LIFT].copy()
    if np.any(rotor_max <= 0.0):
        raise ValueError(f"effectiveness: every lift rotor needs an upper bound > 0; got {rotor_max.tolist()}")
    mix, scale = px4_mix(B0[:, :N_LIFT] * rotor_max[None, :])
    surf_moment = Bq[1:, N_LIFT:].copy()
    surf_moment[:, hi[N_LIFT:] <= lo[N_LIFT:]] = 0.0   # a surface the airframe lacks (or switched off)
    surf_mix = np.linalg.pinv(surf_moment) if np.any(surf_moment) else np.zeros((N_SURFACES, 3))
    v_min = vehicle.envelope.hover_blend_airspeed_mps[0]
    return ALLOC_PARAMS.pack(
        B0=(W[:, None] * B0 * col_range[None, :]).ravel(), BQ=(W[:, None] * Bq * col_range[None, :]).ravel(),
        ROW_SCALE=1.0 / W, COL_RANGE=col_range, LO=lo, HI=hi, PREF_SHARE=np.array(eff.preferred_share, dtype=float),
        EPS=ALLOCATION_EPS, T_UNIT=eff.t_unit_N, TOTAL_UNIT=N_LIFT * eff.t_unit_N, U_MAX=eff.throttle_max,
        RHO=vehicle.envelope.air_density_kgpm3, METHOD=float(METHODS.index(method)), AIRMODE=float(airmode),
        PX4_MIX=mix.ravel(), PX4_SCALE=scale, PX4_ROTOR_MAX=rotor_max, PX4_SURF_MIX=surf_mix.ravel(),
        PX4_QBAR_MIN=0.5 * vehicle.envelope.air_density_kgpm3 * v_min * v_min)


def allocation_problem(p: np.ndarray, asked, qbar_Pa: float) -> dict:
    """The weighted bounded least-squares problem of :func:`allocate`'s stage 1 for ``asked = [T, tau_x,
    tau_y, tau_z]`` at dynamic pressure ``qbar_Pa``, in physical units: ``B`` (4 x 8), ``row_weight`` (4:
    the error of output k counts times it), ``col_weight`` (8: the least-deflection term's weight of
    actuator i, before ``eps``), ``preferred``, ``lower``, ``upper``, ``eps``, ``hold_weight`` (stage 3's
    ``H``). For checking the solver against an independent one (the tests use
    ``scipy.optimize.lsq_linear``, stages 2 and 3 built from this)."""
    p = np.asarray(p, dtype=float)
    g = lambda name: p[ALLOC_PARAMS.slice(name)]  # noqa: E731
    col_range = g("COL_RANGE")
    row_scale = g("ROW_SCALE")
    Bn = (g("B0") + qbar_Pa * g("BQ")).reshape(N_OUT, N_ALLOC)
    B = Bn * row_scale[:, None] / col_range[None, :]
    return {"B": B, "row_weight": 1.0 / row_scale, "col_weight": 1.0 / col_range,
            "preferred": g("PREF_SHARE") * float(asked[0]), "lower": g("LO").copy(), "upper": g("HI").copy(),
            "eps": float(g("EPS")[0]), "hold_weight": HOLD_WEIGHT}
