"""Motor mixer: collective lift, pusher throttle and body moment command -> five motor commands.

The mixer belongs to the flight computer, so it uses the vehicle's nominal geometry and Table I
thrust coefficient, never the plant's truth. Each lift rotor ``i`` at body ``(x_i, y_i)`` gives
thrust ``T_i`` along body -z, so

    T_total = sum T_i,  tau_x = -sum y_i T_i,  tau_y = sum x_i T_i,  tau_z = -sum s_i k_m T_i

(``s_i = +1`` for a rotor turning clockwise seen from above, ``k_m`` its torque per thrust). The
mixer inverts this 4x4 map. When a motor would leave ``[0, T_max]`` it gives up yaw first, then
shifts the collective, then clips (roll and pitch, which hold the attitude, are kept longest),
as PX4's multicopter mixer does, and reports that it saturated.

From Python call :func:`motor_commands` and :func:`lift_collective`: they check their inputs and
call the compiled :func:`mix` and :func:`applied_collective`, which the compiled loop calls
directly and which read their arrays unchecked (a wrong shape reads past the end).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..layout import CMD_SIZE, CMD_TAU_B, CMD_U_X, CMD_U_Z, MOTOR_PUSHER, N_LIFT, N_MOTORS, BlockLayout, Field
from ..vehicle import Vehicle, lift_allocation_matrix

MIXER_PARAMS = BlockLayout("mixer parameters", [
    Field("INV", 16, "-", "4x4 inverse of the allocation matrix, row-major"),
    Field("T_UNIT", 1, "N", "thrust of one lift rotor at full throttle"),
    Field("TOTAL_UNIT", 1, "N", "total lift at full collective (4 x T_UNIT)"),
    Field("U_MAX", 1, "-", "throttle limit, fraction"),
])
"""The mixer's kernel parameter array (:func:`mixer_params`)."""
MX_INV, MX_T_UNIT, MX_TOTAL_UNIT, MX_U_MAX = MIXER_PARAMS.offsets("INV", "T_UNIT", "TOTAL_UNIT", "U_MAX")
MX_SIZE = MIXER_PARAMS.size


def mixer_params(vehicle: Vehicle) -> np.ndarray:
    """Kernel parameters of the mixer from the vehicle's nominal geometry and Table I."""
    A = lift_allocation_matrix(vehicle.geometry, vehicle.actuators.yaw_torque_per_thrust_m)
    if abs(np.linalg.det(A)) < 1e-12:  # a Vehicle refuses such a layout when it is made
        raise ValueError("lift rotor layout cannot produce independent roll, pitch and yaw moments")
    t_unit = vehicle.mass.mass_kg * vehicle.theta_scaled[1] / N_LIFT
    return MIXER_PARAMS.pack(INV=np.linalg.inv(A).ravel(), T_UNIT=t_unit, TOTAL_UNIT=N_LIFT * t_unit,
                             U_MAX=vehicle.actuators.throttle_max_pct / 100.0)


@njit(cache=True, _nrt=False)
def _solve(p, T_total, tx, ty, tz) -> tuple:
    """The four lift-rotor thrusts (N) of a collective and body moments: the inverse allocation, as a tuple."""
    o = MX_INV
    return (p[o] * T_total + p[o + 1] * tx + p[o + 2] * ty + p[o + 3] * tz,
            p[o + 4] * T_total + p[o + 5] * tx + p[o + 6] * ty + p[o + 7] * tz,
            p[o + 8] * T_total + p[o + 9] * tx + p[o + 10] * ty + p[o + 11] * tz,
            p[o + 12] * T_total + p[o + 13] * tx + p[o + 14] * ty + p[o + 15] * tz)


@njit(cache=True, _nrt=False)
def mix(cmd, p, motor_cmd) -> bool:
    """Motor commands (fractions, lift rotors 1-4 then pusher) from a controller command (compiled, unchecked).

    ``cmd``: float64 array in the ``CMD_*`` layout; ``p``: :func:`mixer_params`; writes ``motor_cmd``
    (``N_MOTORS``). From Python use :func:`motor_commands`, which checks them.
    Returns True if any limit was hit (yaw reduced, collective shifted or a motor clipped).
    Non-finite inputs are treated as zero so that the motors never receive NaN. The thrusts are
    tuples, not arrays: the mixer runs every tick and an array would be allocated each time.
    """
    u_max = p[MX_U_MAX]
    T_max = p[MX_T_UNIT] * u_max * u_max
    uz = cmd[CMD_U_Z] if np.isfinite(cmd[CMD_U_Z]) else 0.0
    uz = min(max(uz, 0.0), u_max)
    T_total = p[MX_TOTAL_UNIT] * uz * uz
    tx = cmd[CMD_TAU_B] if np.isfinite(cmd[CMD_TAU_B]) else 0.0
    ty = cmd[CMD_TAU_B + 1] if np.isfinite(cmd[CMD_TAU_B + 1]) else 0.0
    tz = cmd[CMD_TAU_B + 2] if np.isfinite(cmd[CMD_TAU_B + 2]) else 0.0
    T = _solve(p, T_total, tx, ty, tz)
    saturated = False
    lo = min(T[0], T[1], T[2], T[3])
    hi = max(T[0], T[1], T[2], T[3])
    if lo < 0.0 or hi > T_max:
        saturated = True
        # largest yaw fraction s in [0, 1] that keeps every rotor inside the limits
        T0 = _solve(p, T_total, tx, ty, 0.0)
        s = 1.0
        for i in range(N_LIFT):
            d = T[i] - T0[i]
            if d > 0.0 and T[i] > T_max:
                s = min(s, max(T_max - T0[i], 0.0) / d)
            elif d < 0.0 and T[i] < 0.0:
                s = min(s, max(T0[i], 0.0) / -d)  # T0 + s d >= 0
        T = (T0[0] + s * (T[0] - T0[0]), T0[1] + s * (T[1] - T0[1]), T0[2] + s * (T[2] - T0[2]),
             T0[3] + s * (T[3] - T0[3]))
        lo = min(T[0], T[1], T[2], T[3])
        hi = max(T[0], T[1], T[2], T[3])
        # shift the collective to bring roll/pitch inside, if the spread fits at all
        if hi - lo <= T_max:
            if lo < 0.0:
                T = (T[0] - lo, T[1] - lo, T[2] - lo, T[3] - lo)
            elif hi > T_max:
                shift = hi - T_max
                T = (T[0] - shift, T[1] - shift, T[2] - shift, T[3] - shift)
    for i in range(N_LIFT):
        Ti = min(max(T[i], 0.0), T_max)
        motor_cmd[i] = np.sqrt(Ti / p[MX_T_UNIT])
    ux = cmd[CMD_U_X] if np.isfinite(cmd[CMD_U_X]) else 0.0
    motor_cmd[MOTOR_PUSHER] = min(max(ux, 0.0), u_max)
    return saturated


@njit(cache=True, _nrt=False)
def applied_collective(motor_cmd) -> float:
    """The collective the lift-rotor commands amount to: ``sqrt(mean u_i^2)`` (total thrust = that of
    four rotors at this throttle). Equals the commanded collective unless the mixer saturated.
    Compiled and unchecked (reads ``motor_cmd[0:4]``); from Python use :func:`lift_collective`."""
    s = 0.0
    for i in range(N_LIFT):
        s += motor_cmd[i] * motor_cmd[i]
    return np.sqrt(s / N_LIFT)


def _float_vector(name: str, value, sizes: tuple[int, ...]) -> np.ndarray:
    """``value`` as a contiguous float64 vector of one of ``sizes`` entries, all finite; else a one-line error."""
    try:
        a = np.ascontiguousarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name}: expected an array of numbers, got {type(value).__name__}") from None
    if a.ndim != 1 or a.size not in sizes:
        raise ValueError(f"{name}: has shape {a.shape}; allowed: " + " or ".join(f"({n},)" for n in sizes))
    bad = np.flatnonzero(~np.isfinite(a))
    if bad.size:
        raise ValueError(f"{name}[{bad[0]}] = {float(a[bad[0]])!r}: must be finite")
    return a


def motor_commands(command, mixer) -> tuple[np.ndarray, bool]:
    """Five motor commands (fractions: lift rotors 1-4, then the pusher) for a controller command.

    ``command``: a :class:`vtoladapt.control.Command` (what ``Controller.step`` returns) or a float
    array in its ``CMD_*`` layout; ``mixer``: the :class:`~vtoladapt.vehicle.Vehicle` whose geometry
    mixes (the controller's model) or its :func:`mixer_params`. Returns ``(motor_cmd, saturated)``:
    a new array of ``N_MOTORS`` and whether a limit was hit (yaw given up, collective shifted, a
    motor clipped). Shape, type and finiteness are checked (TypeError or ValueError otherwise),
    then the compiled :func:`mix` runs.
    """
    from ..control.api import Command

    cmd = _float_vector("command", command.array if isinstance(command, Command) else command, (CMD_SIZE,))
    p = mixer_params(mixer) if isinstance(mixer, Vehicle) else _float_vector("mixer params", mixer, (MX_SIZE,))
    if not p[MX_T_UNIT] > 0.0 or not 0.0 < p[MX_U_MAX] <= 1.0:
        raise ValueError("mixer params: not from mixer_params (thrust per rotor must be > 0 and the throttle "
                         "limit in (0, 1])")
    out = np.zeros(N_MOTORS)
    saturated = mix(cmd, p, out)
    return out, bool(saturated)


def lift_collective(motor_cmd) -> float:
    """The collective (fraction) the four lift-rotor commands amount to, ``sqrt(mean u_i^2)``: what
    ``Controller.report_applied`` takes (times 100, in percent) after a saturated mix.

    ``motor_cmd``: the ``N_MOTORS`` commands of :func:`motor_commands` or the ``N_LIFT`` lift-rotor
    ones, finite fractions in [0, 1]; anything else raises TypeError or ValueError. Then the
    compiled :func:`applied_collective` runs.
    """
    u = _float_vector("motor_cmd", motor_cmd, (N_MOTORS, N_LIFT))
    if np.any(u < 0.0) or np.any(u > 1.0):
        i = int(np.flatnonzero((u < 0.0) | (u > 1.0))[0])
        raise ValueError(f"motor_cmd[{i}] = {float(u[i])!r}: out of range; allowed: 0 to 1 (fraction)")
    return float(applied_collective(u))
