"""The flight computer's mixer: controller command -> actuator commands, through the control allocator.

The controller outputs a collective lift throttle, a pusher throttle and a body moment; the allocator
(:mod:`vtoladapt.sim.allocation`) turns them into the four lift rotors' throttles, the pusher's and the
control surfaces' deflections, on the vehicle's nominal model (never the plant's truth), with the surfaces'
effectiveness scheduled by the measured dynamic pressure. This module keeps the mixer's Python entry points:
:func:`mixer_params` (the allocator's kernel parameters), :func:`motor_commands` and :func:`lift_collective`,
which check their inputs and call the compiled :func:`vtoladapt.sim.allocation.allocate` and
:func:`applied_collective`; the compiled loop calls those directly, unchecked.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..layout import CMD_SIZE, MEAS_SIZE, MEAS_V_I_VALID, N_ACTUATORS, N_LIFT, N_MOTORS
from ..vehicle import Vehicle
from .allocation import AL_SIZE, AL_T_UNIT, AL_U_MAX, ALLOC_REPORT, ALLOC_REPORT_OFFSET, ALLOC_WORK_SIZE, \
    allocate, allocator_params

MX_SIZE = AL_SIZE
MX_U_MAX = AL_U_MAX
"""Where the throttle limit lies in the mixer's parameters (the actuator faults read it)."""


def mixer_params(vehicle: Vehicle, surfaces: bool = True, effectiveness: str | None = None,
                 method: str = "bounded_lsq", airmode: int = 0) -> np.ndarray:
    """Kernel parameters of the mixer (the allocator's, :func:`vtoladapt.sim.allocation.allocator_params`)
    from the vehicle's nominal model through the effectiveness ``effectiveness`` (default: the vehicle
    file's); ``surfaces=False``: rotors only; ``method``/``airmode``: the solver (``[allocation]``)."""
    return allocator_params(vehicle, surfaces=surfaces, effectiveness_id=effectiveness, method=method,
                            airmode=airmode)


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


def motor_commands(command, mixer, measurement=None, report: bool = False):
    """Actuator commands (lift rotors 1-4 and pusher as throttle fractions, then the surfaces in rad) for a
    controller command.

    ``command``: a :class:`vtoladapt.control.Command` (what ``Controller.step`` returns) or a float array
    in its ``CMD_*`` layout; ``mixer``: the :class:`~vtoladapt.vehicle.Vehicle` whose model allocates (the
    controller's) or its :func:`mixer_params`; ``measurement``: the tick's measurement array (its airflow
    reading schedules the surfaces; default: none, i.e. still air, rotors only). Returns ``(act_cmd,
    saturated)``: a new array of ``N_ACTUATORS`` and whether the asked lift and moment could not all be met;
    with ``report=True`` also a dict of the allocator's report (asked and achieved lift and moment, the
    dynamic pressure). Shape, type and finiteness are checked (TypeError or ValueError otherwise), then
    the compiled :func:`~vtoladapt.sim.allocation.allocate` runs.
    """
    from ..control.api import Command

    cmd = _float_vector("command", command.array if isinstance(command, Command) else command, (CMD_SIZE,))
    p = mixer_params(mixer) if isinstance(mixer, Vehicle) else _float_vector("mixer params", mixer, (MX_SIZE,))
    if not p[AL_T_UNIT] > 0.0 or not 0.0 < p[AL_U_MAX] <= 1.0:
        raise ValueError("mixer params: not from mixer_params (thrust per rotor must be > 0 and the throttle "
                         "limit in (0, 1])")
    if measurement is None:
        meas = np.zeros(MEAS_SIZE)
        meas[MEAS_V_I_VALID] = 0.0
    else:
        meas = np.ascontiguousarray(measurement, dtype=np.float64)
        if meas.shape != (MEAS_SIZE,):
            raise ValueError(f"measurement: has shape {meas.shape}; allowed: ({MEAS_SIZE},)")
    out = np.zeros(N_ACTUATORS)
    work = np.zeros(ALLOC_WORK_SIZE)
    saturated = bool(allocate(cmd, meas, p, out, work, 0))
    if not report:
        return out, saturated
    rep = work[ALLOC_REPORT_OFFSET:ALLOC_REPORT_OFFSET + ALLOC_REPORT.size]
    return out, saturated, {f.name.lower(): rep[ALLOC_REPORT.slice(f.name)].copy() for f in ALLOC_REPORT.fields}


def lift_collective(motor_cmd) -> float:
    """The collective (fraction) the four lift-rotor commands amount to, ``sqrt(mean u_i^2)``: what
    ``Controller.report_applied`` takes (times 100, in percent) after a saturated mix.

    ``motor_cmd``: the ``N_ACTUATORS`` commands of :func:`motor_commands`, the ``N_MOTORS`` motor ones or
    the ``N_LIFT`` lift-rotor ones; the rotors' must be finite fractions in [0, 1]; anything else raises
    TypeError or ValueError. Then the compiled :func:`applied_collective` runs.
    """
    u = _float_vector("motor_cmd", motor_cmd, (N_ACTUATORS, N_MOTORS, N_LIFT))[:N_MOTORS]
    if np.any(u < 0.0) or np.any(u > 1.0):
        i = int(np.flatnonzero((u < 0.0) | (u > 1.0))[0])
        raise ValueError(f"motor_cmd[{i}] = {float(u[i])!r}: out of range; allowed: 0 to 1 (fraction)")
    return float(applied_collective(u))
