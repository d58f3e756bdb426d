"""Position references: what the controller is asked to track, as ``REF_*`` rows.

Every reference is a :class:`PositionReference` with one method the simulator uses,
``reference_table(t_s) -> (N, layout.REF_SIZE)`` (precomputed before a run), and
``reference(t)`` for one time. Rows hold position, velocity and acceleration (NED) and the
heading and its rate, mutually consistent (the velocity is the derivative of the position).

* :class:`Hold`: a fixed point and heading.
* :class:`MinJerkWaypoints`: rest-to-rest minimum-jerk segments through timed waypoints
  (``s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5``: position, velocity and acceleration continuous,
  zero velocity and acceleration at every waypoint); heading interpolated the same way.
* :class:`VelocityProfile`: a velocity that moves between timed knot values along the same
  minimum-jerk blend (acceleration continuous), the position its exact integral.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from .. import layout as L


def _min_jerk(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``S = int s``, ``s``, ``s'``, ``s''`` of the minimum-jerk blend at ``tau`` in [0, 1]."""
    t = np.clip(tau, 0.0, 1.0)
    t2 = t * t
    t3 = t2 * t
    S = 2.5 * t2 * t2 - 3.0 * t3 * t2 + t3 * t3
    s = 10.0 * t3 - 15.0 * t2 * t2 + 6.0 * t3 * t2
    ds = 30.0 * t2 - 60.0 * t3 + 30.0 * t2 * t2
    dds = 60.0 * t - 180.0 * t2 + 120.0 * t3
    return S, s, ds, dds


def _times(t_s) -> np.ndarray:
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise ValueError("times must be a finite 1-D array (s)")
    return t


class PositionReference(ABC):
    """Interface of every reference: a table of ``REF_*`` rows for given times."""

    @abstractmethod
    def reference_table(self, t_s) -> np.ndarray:
        """``(N, layout.REF_SIZE)`` reference rows at the times ``t_s`` (s)."""

    def reference(self, t: float) -> np.ndarray:
        """One ``REF_*`` row at time ``t`` (s)."""
        return self.reference_table(np.array([float(t)]))[0]


class Hold(PositionReference):
    """Hold ``position_m`` (NED) at heading ``yaw_rad``."""

    def __init__(self, position_m, yaw_rad: float = 0.0):
        p = np.asarray(position_m, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"position_m = {position_m!r}: must be 3 finite numbers (m, NED)")
        if not math.isfinite(yaw_rad):
            raise ValueError(f"yaw_rad = {yaw_rad!r}: must be finite")
        self.position_m = p
        self.yaw_rad = float(yaw_rad)

    def reference_table(self, t_s) -> np.ndarray:
        """``(N, layout.REF_SIZE)`` reference rows at the times ``t_s`` (s)."""
        t = _times(t_s)
        out = np.zeros((t.size, L.REF_SIZE))
        out[:, L.REF_P_W:L.REF_P_W + 3] = self.position_m
        out[:, L.REF_YAW] = self.yaw_rad
        return out


class MinJerkWaypoints(PositionReference):
    """Rest-to-rest minimum-jerk flight through ``positions_m[k]`` at ``times_s[k]``.

    Before the first time the first waypoint is held, after the last the last one.
    ``yaw_rad`` is one heading or one per waypoint (interpolated along the shorter way).
    """

    def __init__(self, times_s, positions_m, yaw_rad=0.0):
        t = _times(times_s)
        p = np.asarray(positions_m, dtype=float)
        if t.size < 2 or p.shape != (t.size, 3) or not np.all(np.isfinite(p)):
            raise ValueError(f"positions_m must be ({t.size}, 3) finite (m, NED) for {t.size} times, "
                             f"at least two; got shape {p.shape}")
        if not np.all(np.diff(t) > 0):
            raise ValueError(f"times_s = {t.tolist()}: must increase")
        yaw = np.broadcast_to(np.asarray(yaw_rad, dtype=float), (t.size,)).copy()
        if not np.all(np.isfinite(yaw)):
            raise ValueError("yaw_rad must be finite")
        # unwrap so each segment turns the short way
        yaw = np.concatenate([[yaw[0]], yaw[0] + np.cumsum(np.angle(np.exp(1j * np.diff(yaw))))])
        self.times_s, self.positions_m, self.yaw_rad = t, p, yaw

    def reference_table(self, t_s) -> np.ndarray:
        """``(N, layout.REF_SIZE)`` reference rows at the times ``t_s`` (s)."""
        t = _times(t_s)
        tk, pk, yk = self.times_s, self.positions_m, self.yaw_rad
        k = np.clip(np.searchsorted(tk, t, side="right") - 1, 0, tk.size - 2)
        T = tk[k + 1] - tk[k]
        tau = (t - tk[k]) / T
        _, s, ds, dds = _min_jerk(tau)
        dp = pk[k + 1] - pk[k]
        dy = yk[k + 1] - yk[k]
        out = np.zeros((t.size, L.REF_SIZE))
        out[:, L.REF_P_W:L.REF_P_W + 3] = pk[k] + dp * s[:, None]
        out[:, L.REF_V_W:L.REF_V_W + 3] = dp * (ds / T)[:, None]
        out[:, L.REF_A_W:L.REF_A_W + 3] = dp * (dds / T**2)[:, None]
        out[:, L.REF_YAW] = np.angle(np.exp(1j * (yk[k] + dy * s)))
        out[:, L.REF_YAW_RATE] = dy * ds / T
        return out


class VelocityProfile(PositionReference):
    """Fly the velocities ``velocities_mps[k]`` (NED) reached at ``times_s[k]``, from ``start_position_m``.

    Between knots the velocity follows the minimum-jerk blend; before the first knot it is
    ``velocities_mps[0]``, after the last ``velocities_mps[-1]``. The position starts at
    ``start_position_m`` at ``times_s[0]`` and is the exact integral of the velocity.
    """

    def __init__(self, start_position_m, times_s, velocities_mps, yaw_rad: float = 0.0):
        t = _times(times_s)
        v = np.asarray(velocities_mps, dtype=float)
        p0 = np.asarray(start_position_m, dtype=float)
        if t.size < 1 or v.shape != (t.size, 3) or not np.all(np.isfinite(v)):
            raise ValueError(f"velocities_mps must be ({t.size}, 3) finite (m/s, NED); got {v.shape}")
        if p0.shape != (3,) or not np.all(np.isfinite(p0)):
            raise ValueError("start_position_m must be 3 finite numbers (m, NED)")
        if t.size > 1 and not np.all(np.diff(t) > 0):
            raise ValueError(f"times_s = {t.tolist()}: must increase")
        if not math.isfinite(yaw_rad):
            raise ValueError("yaw_rad must be finite")
        self.times_s, self.velocities_mps, self.yaw_rad = t, v, float(yaw_rad)
        # position at each knot: int over a segment = T (v_k + (v_k+1 - v_k) S(1)), S(1) = 1/2
        seg = np.diff(t)[:, None] * 0.5 * (v[:-1] + v[1:])
        self._p_knots = p0 + np.vstack([np.zeros(3), np.cumsum(seg, axis=0)])

    def reference_table(self, t_s) -> np.ndarray:
        """``(N, layout.REF_SIZE)`` reference rows at the times ``t_s`` (s)."""
        t = _times(t_s)
        tk, vk, pk = self.times_s, self.velocities_mps, self._p_knots
        out = np.zeros((t.size, L.REF_SIZE))
        out[:, L.REF_YAW] = self.yaw_rad
        before = t < tk[0]
        after = t >= tk[-1]
        out[before, 0:3] = pk[0] + vk[0] * (t[before] - tk[0])[:, None]
        out[before, 3:6] = vk[0]
        out[after, 0:3] = pk[-1] + vk[-1] * (t[after] - tk[-1])[:, None]
        out[after, 3:6] = vk[-1]
        mid = ~(before | after)
        if tk.size > 1 and mid.any():
            tm = t[mid]
            k = np.clip(np.searchsorted(tk, tm, side="right") - 1, 0, tk.size - 2)
            T = tk[k + 1] - tk[k]
            tau = (tm - tk[k]) / T
            S, s, ds, _ = _min_jerk(tau)
            dv = vk[k + 1] - vk[k]
            out[mid, L.REF_P_W:L.REF_P_W + 3] = pk[k] + T[:, None] * (vk[k] * tau[:, None] + dv * S[:, None])
            out[mid, L.REF_V_W:L.REF_V_W + 3] = vk[k] + dv * s[:, None]
            out[mid, L.REF_A_W:L.REF_A_W + 3] = dv * (ds / T)[:, None]
        return out


def trajectory_from_reference(reference_config) -> PositionReference:
    """The reference of a scenario's ``[reference]`` table (kind ``hold`` or ``waypoints``)."""
    yaw = math.radians(reference_config.yaw_deg)
    if reference_config.kind == "hold":
        return Hold(reference_config.position_m, yaw)
    if reference_config.kind == "waypoints":
        rows = np.asarray(reference_config.waypoints, dtype=float)
        return MinJerkWaypoints(rows[:, 0], rows[:, 1:4], yaw)
    raise ValueError(f"reference kind {reference_config.kind!r}: must be 'hold' or 'waypoints'")


__all__ = ["Hold", "MinJerkWaypoints", "PositionReference", "VelocityProfile", "trajectory_from_reference"]
