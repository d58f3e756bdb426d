"""Tracking control laws: reference velocity and rate (eq:wr), force (eq:f_ctrl), moment (eq:m_ctrl).

Frames: positions, velocities and forces in world NED; rates and moments in body FRD. The
desired frame's rate ``omega_d`` is expressed in the desired frame (``R_d' = R_d S(omega_d)``), so
``R~^T omega_d`` is the same rate in body axes (``R~ = R_d^T R``).

Derivatives the paper leaves implicit
-------------------------------------
* ``v_r' = p_d'' - Lambda_p p~'`` with ``p~' = v - p_d'`` from the measured velocity (exact).
  When the position correction is saturated at ``|Lambda_p p~| = c_max`` the derivative of the
  saturated vector ``c_max c / |c|`` is used, so ``v_r'`` stays the true derivative of ``v_r``.
* ``omega_r'`` is differentiated analytically: with ``R~' = R~ S(omega - R~^T omega_d)`` and
  ``q~_v' = (q~_0 I + S(q~_v)) (omega - R~^T omega_d) / 2``,

      omega_r' = -omega x (R~^T omega_d) + R~^T omega_d' - Lambda_q (q~_0 I + S(q~_v)) (omega - R~^T omega_d) / 2

  (checked against finite differences in the tests). ``omega_d`` and ``omega_d'`` come from the
  history of ``R_d`` (see :mod:`.attitude`).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..frames import GRAVITY_MPS2


@njit(cache=True)
def reference_velocity(p_tilde_W, v_d_W, a_d_W, v_W, Lambda_p, corr_max_mps, v_r_W, v_r_dot_W) -> bool:
    """Reference velocity ``v_r = p_d' - Lambda_p p~`` and its derivative (eq:wr).

    Parameters
    ----------
    p_tilde_W : (3,) position error ``p - p_d`` (m, NED).
    v_d_W, a_d_W : (3,) desired velocity (m/s) and acceleration (m/s^2), NED.
    v_W : (3,) measured velocity (m/s, NED), for ``p~' = v - p_d'``.
    Lambda_p : (3,) diagonal gain (1/s).
    corr_max_mps : float, limit on ``|Lambda_p p~|`` (m/s).
    v_r_W, v_r_dot_W : (3,) outputs (m/s, m/s^2).

    Returns
    -------
    bool
        True if the position correction was saturated.
    """
    c = np.empty(3)
    cd = np.empty(3)
    n2 = 0.0
    for i in range(3):
        c[i] = Lambda_p[i] * p_tilde_W[i]
        cd[i] = Lambda_p[i] * (v_W[i] - v_d_W[i])
        n2 += c[i] * c[i]
    n = np.sqrt(n2)
    if n <= corr_max_mps:
        for i in range(3):
            v_r_W[i] = v_d_W[i] - c[i]
            v_r_dot_W[i] = a_d_W[i] - cd[i]
        return False
    # d/dt (c_max c/|c|) = c_max/|c| (I - u u^T) c', u = c/|c|
    s = corr_max_mps / n
    ucd = (c[0] * cd[0] + c[1] * cd[1] + c[2] * cd[2]) / n
    for i in range(3):
        v_r_W[i] = v_d_W[i] - s * c[i]
        v_r_dot_W[i] = a_d_W[i] - s * (cd[i] - c[i] / n * ucd)
    return True


@njit(cache=True)
def force_command(v_r_dot_W, v_tilde_W, K_v, f_r_W) -> None:
    """Force command per unit mass ``f_r = -g + v_r' - K_v v~`` (eq:f_ctrl), m/s^2 NED."""
    for i in range(3):
        f_r_W[i] = v_r_dot_W[i] - K_v[i] * v_tilde_W[i]
    f_r_W[2] -= GRAVITY_MPS2


@njit(cache=True)
def limit_norm(x, x_max) -> bool:
    """Scale ``x`` in place so that ``|x| <= x_max``; True if it was scaled."""
    n = np.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
    if n > x_max:
        s = x_max / n
        for i in range(3):
            x[i] *= s
        return True
    return False


@njit(cache=True)
def quat_error_from_quats(q_d, q) -> np.ndarray:
    """Constrained quaternion error of ``R~ = R_d^T R`` from the two quaternions: ``q_d^* q``, ``q~_0 >= 0``.

    The same rotation as :func:`vtoladapt.frames.quat_error_constrained` (checked in the tests),
    without forming and multiplying the rotation matrices.
    """
    a0, a1, a2, a3 = q_d[0], -q_d[1], -q_d[2], -q_d[3]
    b0, b1, b2, b3 = q[0], q[1], q[2], q[3]
    out = np.empty(4)
    out[0] = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
    out[1] = a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2
    out[2] = a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1
    out[3] = a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0
    n = np.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2 + out[3] ** 2)
    s = (-1.0 if out[0] < 0.0 else 1.0) / n
    for i in range(4):
        out[i] *= s
    return out


@njit(cache=True)
def reference_angular_rate(R_tilde, q_tilde, omega_d, Lambda_q, omega_r_B) -> None:
    """Reference body rate ``omega_r = R~^T omega_d - Lambda_q q~_v`` (eq:wr), rad/s.

    ``R_tilde = R_d^T R``, ``q_tilde = [q~_0, q~_v]`` its quaternion with ``q~_0 >= 0``.
    """
    for i in range(3):
        omega_r_B[i] = (R_tilde[0, i] * omega_d[0] + R_tilde[1, i] * omega_d[1]
                        + R_tilde[2, i] * omega_d[2]) - Lambda_q[i] * q_tilde[1 + i]


@njit(cache=True)
def reference_angular_acceleration(R_tilde, q_tilde, omega_B, omega_d, omega_d_dot, Lambda_q,
                                   omega_r_dot_B) -> None:
    """Time derivative of eq:wr's ``omega_r`` along the measured rate (see the module notes), rad/s^2."""
    wd = np.empty(3)
    wdd = np.empty(3)
    for i in range(3):
        wd[i] = R_tilde[0, i] * omega_d[0] + R_tilde[1, i] * omega_d[1] + R_tilde[2, i] * omega_d[2]
        wdd[i] = (R_tilde[0, i] * omega_d_dot[0] + R_tilde[1, i] * omega_d_dot[1]
                  + R_tilde[2, i] * omega_d_dot[2])
    we0 = omega_B[0] - wd[0]
    we1 = omega_B[1] - wd[1]
    we2 = omega_B[2] - wd[2]
    q0, qx, qy, qz = q_tilde[0], q_tilde[1], q_tilde[2], q_tilde[3]
    # q~_v' = (q0 I + S(q_v)) w_e / 2
    qd0 = 0.5 * (q0 * we0 + qy * we2 - qz * we1)
    qd1 = 0.5 * (q0 * we1 + qz * we0 - qx * we2)
    qd2 = 0.5 * (q0 * we2 + qx * we1 - qy * we0)
    # -omega x wd
    c0 = -(omega_B[1] * wd[2] - omega_B[2] * wd[1])
    c1 = -(omega_B[2] * wd[0] - omega_B[0] * wd[2])
    c2 = -(omega_B[0] * wd[1] - omega_B[1] * wd[0])
    omega_r_dot_B[0] = c0 + wdd[0] - Lambda_q[0] * qd0
    omega_r_dot_B[1] = c1 + wdd[1] - Lambda_q[1] * qd1
    omega_r_dot_B[2] = c2 + wdd[2] - Lambda_q[2] * qd2


@njit(cache=True)
def moment_command(J, omega_B, omega_r_B, omega_r_dot_B, K_omega, tau_B) -> None:
    """Moment command ``tau = J omega_r' - S(J omega) omega_r - K_omega (omega - omega_r)`` (eq:m_ctrl), N m.

    ``J`` is the controller's model of the inertia (3x3, kg m^2), never the plant's truth.
    """
    h = np.empty(3)
    for i in range(3):
        h[i] = J[i, 0] * omega_B[0] + J[i, 1] * omega_B[1] + J[i, 2] * omega_B[2]
    # S(h) omega_r = h x omega_r
    s0 = h[1] * omega_r_B[2] - h[2] * omega_r_B[1]
    s1 = h[2] * omega_r_B[0] - h[0] * omega_r_B[2]
    s2 = h[0] * omega_r_B[1] - h[1] * omega_r_B[0]
    for i in range(3):
        tau_B[i] = (J[i, 0] * omega_r_dot_B[0] + J[i, 1] * omega_r_dot_B[1] + J[i, 2] * omega_r_dot_B[2]
                    - K_omega[i] * (omega_B[i] - omega_r_B[i]))
    tau_B[0] -= s0
    tau_B[1] -= s1
    tau_B[2] -= s2


__all__ = ["force_command", "limit_norm", "moment_command", "quat_error_from_quats", "reference_angular_acceleration",
           "reference_angular_rate", "reference_velocity"]
