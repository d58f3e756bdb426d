"""What the controller formed, rebuilt from a simulator log: the basis input rows and the measured force.

For each sample: the basis input block (:data:`vtoladapt.bases.INPUT`) from the incident flow the
controller used (``ctrl_v_i_*``) and whether it was the probe's (``probe_valid_used``), the throttle
commands passed through the vehicle's nominal motor lag as the controller does
(:func:`lagged_throttles`), the measured attitude, rates and velocity; and the accelerometer (body,
m/s^2), the force a basis must predict (the *target* only; no input is derived from it).

Both the experiments (the constant-weights ceiling and the prediction yardstick,
:mod:`vtoladapt.experiments.ceiling`, :mod:`vtoladapt.experiments.yardstick`) and the training of a
basis (:mod:`vtoladapt.learn.data`, which adds PX4 logs) read a log this way; it lives with the bases,
below both, so that the experiments do not reach up into the learning that runs campaigns of them, and
the learning does not load the experiments to read a log. It needs only the bases and the log's columns
(the log is any object with ``SimulationResult``'s ``time_s``, ``columns_like`` and ``metadata``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..config import ConfigError
from . import input_rows

SIM_COLUMNS = {
    "v_i": ("ctrl_v_i_x_mps", "ctrl_v_i_y_mps", "ctrl_v_i_z_mps"),
    "valid": ("probe_valid_used",),
    "u": ("cmd_u_x_frac", "cmd_u_z_frac"),
    "q": ("meas_q_w", "meas_q_x", "meas_q_y", "meas_q_z"),
    "omega": ("meas_omega_x_radps", "meas_omega_y_radps", "meas_omega_z_radps"),
    "v": ("meas_v_N_mps", "meas_v_E_mps", "meas_v_D_mps"),
    "f": ("meas_accel_x_mps2", "meas_accel_y_mps2", "meas_accel_z_mps2"),
}
"""The simulator log's columns a training sample is built from (README "Log columns")."""


@dataclass(eq=False)
class Flight:
    """One flight's samples: basis input rows ``x`` (N, INPUT.size), measured force ``f`` (N, 3), and
    where they came from (``vehicle`` name, ``source`` file, ``info``: the draw's seed and conditions)."""

    x: np.ndarray
    f: np.ndarray
    vehicle: str
    source: str
    info: dict


def lagged_throttles(u_cmd: np.ndarray, dt: float, tau_x: float, tau_z: float) -> np.ndarray:
    """The throttles that produced each tick's measured force: the command held over the previous
    tick through a first-order lag (the controller's ``basis_input``; the first two ticks and after
    a non-finite command: the previous command itself)."""
    u_prev = np.vstack([u_cmd[:1], u_cmd[:-1]])
    a = np.array([np.exp(-dt / tau_x), np.exp(-dt / tau_z)])
    out = np.empty_like(u_prev)
    est = u_prev[0].copy()
    for t in range(len(u_prev)):
        if t >= 2 and np.all(np.isfinite(est)):
            est = u_prev[t] + (est - u_prev[t]) * a
        else:  # the start, or after a gap in the log (NaN): the lag restarts from the command
            est = u_prev[t].copy()
        out[t] = est
    return out


def _select(t_s: np.ndarray, skip_s: float, stride: int) -> np.ndarray:
    if len(t_s) == 0:
        return np.zeros(0, dtype=np.intp)
    idx = np.flatnonzero(t_s >= t_s[0] + skip_s)
    return idx[::stride]


def flight_from_result(result, vehicle, source: str = "", skip_s: float = 1.0, stride: int = 5,
                       info: Optional[dict] = None) -> Flight:
    """A :class:`Flight` from a simulator log (``SimulationResult``) flown by ``vehicle``."""
    missing = [c for cols in (("t_s",), *SIM_COLUMNS.values()) for c in cols if c not in result]
    if missing:
        raise ConfigError(f"{source or 'log'}: not a controller log: missing columns {', '.join(missing[:4])}")
    t = result.time_s
    if len(t) == 0:
        raise ConfigError(f"{source or 'log'}: 0 rows; allowed: a log of a flight (at least one row)")
    if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0.0)):
        raise ConfigError(f"{source or 'log'}: t_s is not finite and increasing; allowed: a log's tick times")
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.004
    cols = {k: result.columns_like(v) for k, v in SIM_COLUMNS.items()}
    act = vehicle.actuators
    u = lagged_throttles(cols["u"], dt, act.pusher_motor_time_constant_s, act.lift_motor_time_constant_s)
    sel = _select(t, skip_s, stride)
    x = input_rows(cols["v_i"][sel], u[sel, 0], u[sel, 1], vehicle.model_kernel, valid=cols["valid"][sel, 0],
                   q_WB=cols["q"][sel], omega_B=cols["omega"][sel], v_W=cols["v"][sel])
    f = cols["f"][sel]
    ok = np.all(np.isfinite(x), axis=1) & np.all(np.isfinite(f), axis=1)
    meta = dict(getattr(result, "metadata", {}) or {})
    return Flight(x[ok], f[ok], str(meta.get("vehicle", vehicle.name)), source,
                  info if info is not None else {"seed": meta.get("seed"), "scenario": meta.get("scenario")})
