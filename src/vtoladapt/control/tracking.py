"""Tracking control laws: reference velocity and rate (eq:wr), force (eq:f_ctrl), moment (eq:m_ctrl).

Frames: positions, velocities and forces in world NED; rates and moments in body FRD. The
desired frame's rate ``omega_d`` is expressed in the desired frame (``R_d' = R_d S(omega_d)``), so
``R~^T omega_d`` is the same rate in body axes (``R~ = R_d^T R``); the rate laws take it (and
``R~^T omega_d'``) in body axes.

Derivatives the paper leaves implicit
-------------------------------------
* ``v_r' = p_d'' - Lambda_p p~'`` with ``p~' = v - p_d'`` from the measured velocity (exact).
  When the position correction is saturated at ``|Lambda_p p~| = c_max`` the derivative of the
  saturated vector ``c_max c / |c|`` is used, so ``v_r'`` stays the true derivative of ``v_r``.
* ``omega_r'`` is differentiated analytically: with ``R~' = R~ S(omega - R~^T omega_d)`` and
  ``q~_v' = (q~_0 I + S(q~_v)) (omega - R~^T omega_d) / 2``,

      omega_r' = -omega x (R~^T omega_d) + R~^T omega_d' - Lambda_q (q~_0 I + S(q~_v)) (omega - R~^T omega_d) / 2

  (checked against finite differences in the tests). ``omega_d`` and ``omega_d'`` come from the
  history of ``R_d`` (see :mod:`~vtoladapt.control.attitude`).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..frames import GRAVITY_MPS2


@njit(cache=True)
def reference_velocity(p_tilde_W, v_d_W, a_d_W, v_W, Lambda_p, corr_max_mps, v_r_W=None,
                       v_r_dot_W=None) -> tuple:
    """Reference velocity ``v_r = p_d' - Lambda_p p~`` and its derivative (eq:wr).

    Parameters
    ----------
    p_tilde_W : (3,) position error ``p - p_d`` (m, NED).
    v_d_W, a_d_W : (3,) desired velocity (m/s) and acceleration (m/s^2), NED.
    v_W : (3,) measured velocity (m/s, NED), for ``p~' = v - p_d'``.
    Lambda_p : (3,) diagonal gain (1/s).
    corr_max_mps : float, limit on ``|Lambda_p p~|`` (m/s).
    v_r_W, v_r_dot_W : (3,) arrays, optional: also receive ``v_r`` (m/s) and ``v_r'`` (m/s^2).

    Returns
    -------
    (v_r_W, v_r_dot_W, saturated)
        3-tuples, and True if the position correction was saturated.
    """
    c0 = Lambda_p[0] * p_tilde_W[0]
    c1 = Lambda_p[1] * p_tilde_W[1]
    c2 = Lambda_p[2] * p_tilde_W[2]
    cd0 = Lambda_p[0] * (v_W[0] - v_d_W[0])
    cd1 = Lambda_p[1] * (v_W[1] - v_d_W[1])
    cd2 = Lambda_p[2] * (v_W[2] - v_d_W[2])
    n = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    saturated = not n <= corr_max_mps
    if not saturated:
        v_r = (v_d_W[0] - c0, v_d_W[1] - c1, v_d_W[2] - c2)
        v_r_dot = (a_d_W[0] - cd0, a_d_W[1] - cd1, a_d_W[2] - cd2)
    else:
        # d/dt (c_max c/|c|) = c_max/|c| (I - u u^T) c', u = c/|c|
        s = corr_max_mps / n
        ucd = (c0 * cd0 + c1 * cd1 + c2 * cd2) / n
        v_r = (v_d_W[0] - s * c0, v_d_W[1] - s * c1, v_d_W[2] - s * c2)
        v_r_dot = (a_d_W[0] - s * (cd0 - c0 / n * ucd), a_d_W[1] - s * (cd1 - c1 / n * ucd),
                   a_d_W[2] - s * (cd2 - c2 / n * ucd))
    if v_r_W is not None:
        v_r_W[0], v_r_W[1], v_r_W[2] = v_r
    if v_r_dot_W is not None:
        v_r_dot_W[0], v_r_dot_W[1], v_r_dot_W[2] = v_r_dot
    return v_r, v_r_dot, saturated


@njit(cache=True)
def force_command(v_r_dot_W, v_tilde_W, K_v) -> tuple:
    """Force command per unit mass ``f_r = -g + v_r' - K_v v~`` (eq:f_ctrl), m/s^2 NED, as a 3-tuple."""
    return (v_r_dot_W[0] - K_v[0] * v_tilde_W[0], v_r_dot_W[1] - K_v[1] * v_tilde_W[1],
            v_r_dot_W[2] - K_v[2] * v_tilde_W[2] - GRAVITY_MPS2)


@njit(cache=True)
def limit_norm(x, x_max) -> tuple:
    """``x`` (3-vector) scaled so that ``|x| <= x_max``: ``(x_limited, was_scaled)``."""
    n = np.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
    if n > x_max:
        s = x_max / n
        return (x[0] * s, x[1] * s, x[2] * s), True
    return (x[0], x[1], x[2]), False


@njit(cache=True)
def quat_error_from_quats(q_d, q) -> tuple:
    """Constrained quaternion error of ``R~ = R_d^T R`` from the two quaternions: ``q_d^* q``, ``q~_0 >= 0``.

    The same rotation as :func:`vtoladapt.frames.quat_error_constrained` (checked in the tests),
    without forming and multiplying the rotation matrices. Returns a 4-tuple (scalar first).
    """
    a0, a1, a2, a3 = q_d[0], -q_d[1], -q_d[2], -q_d[3]
    b0, b1, b2, b3 = q[0], q[1], q[2], q[3]
    e0 = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
    e1 = a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2
    e2 = a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1
    e3 = a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0
    n = np.sqrt(e0 ** 2 + e1 ** 2 + e2 ** 2 + e3 ** 2)
    s = (-1.0 if e0 < 0.0 else 1.0) / n
    return (e0 * s, e1 * s, e2 * s, e3 * s)


@njit(cache=True)
def reference_angular_rate(omega_d_B, q_tilde, Lambda_q) -> tuple:
    """Reference body rate ``omega_r = R~^T omega_d - Lambda_q q~_v`` (eq:wr), rad/s, as a 3-tuple.

    ``omega_d_B = R~^T omega_d``: the desired frame's rate in body axes (``R~ = R_d^T R``);
    ``q_tilde = [q~_0, q~_v]`` the quaternion of ``R~`` with ``q~_0 >= 0``.
    """
    return (omega_d_B[0] - Lambda_q[0] * q_tilde[1], omega_d_B[1] - Lambda_q[1] * q_tilde[2],
            omega_d_B[2] - Lambda_q[2] * q_tilde[3])


@njit(cache=True)
def reference_angular_acceleration(q_tilde, omega_B, omega_d_B, omega_d_dot_B, Lambda_q) -> tuple:
    """Time derivative of eq:wr's ``omega_r`` along the measured rate (see the module notes), rad/s^2.

    ``omega_d_B = R~^T omega_d`` and ``omega_d_dot_B = R~^T omega_d'`` (body axes); returns a 3-tuple.
    """
    wd0, wd1, wd2 = omega_d_B[0], omega_d_B[1], omega_d_B[2]
    we0 = omega_B[0] - wd0
    we1 = omega_B[1] - wd1
    we2 = omega_B[2] - wd2
    q0, qx, qy, qz = q_tilde[0], q_tilde[1], q_tilde[2], q_tilde[3]
    # q~_v' = (q0 I + S(q_v)) w_e / 2
    qd0 = 0.5 * (q0 * we0 + qy * we2 - qz * we1)
    qd1 = 0.5 * (q0 * we1 + qz * we0 - qx * we2)
    qd2 = 0.5 * (q0 * we2 + qx * we1 - qy * we0)
    # -omega x wd
    c0 = -(omega_B[1] * wd2 - omega_B[2] * wd1)
    c1 = -(omega_B[2] * wd0 - omega_B[0] * wd2)
    c2 = -(omega_B[0] * wd1 - omega_B[1] * wd0)
    return (c0 + omega_d_dot_B[0] - Lambda_q[0] * qd0, c1 + omega_d_dot_B[1] - Lambda_q[1] * qd1,
            c2 + omega_d_dot_B[2] - Lambda_q[2] * qd2)


@njit(cache=True)
def moment_command(J, omega_B, omega_r_B, omega_r_dot_B, K_omega) -> tuple:
    """Moment command ``tau = J omega_r' - S(J omega) omega_r - K_omega (omega - omega_r)`` (eq:m_ctrl), N m.

    ``J`` is the controller's model of the inertia (kg m^2, three row 3-tuples), never the plant's
    truth. Returns a 3-tuple.
    """
    j0, j1, j2 = J[0], J[1], J[2]
    h0 = j0[0] * omega_B[0] + j0[1] * omega_B[1] + j0[2] * omega_B[2]
    h1 = j1[0] * omega_B[0] + j1[1] * omega_B[1] + j1[2] * omega_B[2]
    h2 = j2[0] * omega_B[0] + j2[1] * omega_B[1] + j2[2] * omega_B[2]
    # S(h) omega_r = h x omega_r
    s0 = h1 * omega_r_B[2] - h2 * omega_r_B[1]
    s1 = h2 * omega_r_B[0] - h0 * omega_r_B[2]
    s2 = h0 * omega_r_B[1] - h1 * omega_r_B[0]
    return ((j0[0] * omega_r_dot_B[0] + j0[1] * omega_r_dot_B[1] + j0[2] * omega_r_dot_B[2]
             - K_omega[0] * (omega_B[0] - omega_r_B[0])) - s0,
            (j1[0] * omega_r_dot_B[0] + j1[1] * omega_r_dot_B[1] + j1[2] * omega_r_dot_B[2]
             - K_omega[1] * (omega_B[1] - omega_r_B[1])) - s1,
            (j2[0] * omega_r_dot_B[0] + j2[1] * omega_r_dot_B[1] + j2[2] * omega_r_dot_B[2]
             - K_omega[2] * (omega_B[2] - omega_r_B[2])) - s2)


__all__ = ["force_command", "limit_norm", "moment_command", "quat_error_from_quats", "reference_angular_acceleration",
           "reference_angular_rate", "reference_velocity"]
