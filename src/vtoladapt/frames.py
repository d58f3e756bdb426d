"""Frames, rotations and the quaternion error: the one place these conventions are stated.

Conventions (used everywhere in vtoladapt)
-------------------------------------------
* World frame **W**: North-East-Down (NED), origin fixed. Gravity is ``g_W = [0, 0, +9.80665]``.
* Body frame **B**: Forward-Right-Down (FRD), origin at the centre of mass.
* ``R_WB`` maps body-frame coordinates to world-frame coordinates: ``v_W = R_WB @ v_B``. It is
  the paper's attitude ``R`` (eq:pos_dyn: ``v_dot = g + R f_b``).
* Quaternions are Hamilton, **scalar first** ``q = [w, x, y, z]``, unit norm, and ``q_WB``
  represents the same rotation as ``R_WB``. ``scipy.spatial.transform.Rotation`` uses scalar
  last; convert with ``q[[1, 2, 3, 0]]``.
* ``S(a)`` is the skew map with ``S(a) @ b == cross(a, b)`` (eq:att_dyn).
* Euler angles, where a user gives them, are yaw-pitch-roll (3-2-1, intrinsic) in radians.

All functions here are Numba-compiled and take and return 1-D / 3x3 float64 arrays, so the
simulator, the controller and plain Python share one implementation.
"""
from __future__ import annotations

import numpy as np
from numba import njit

GRAVITY_MPS2 = 9.80665
"""Standard gravity (m/s^2)."""


@njit(cache=True)
def gravity_W() -> np.ndarray:
    """Gravity vector in the NED world frame (m/s^2); the paper's ``g``."""
    return np.array([0.0, 0.0, GRAVITY_MPS2])


@njit(cache=True)
def skew(a: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix ``S(a)`` with ``S(a) @ b = a x b`` (eq:att_dyn)."""
    S = np.zeros((3, 3))
    S[0, 1] = -a[2]
    S[0, 2] = a[1]
    S[1, 0] = a[2]
    S[1, 2] = -a[0]
    S[2, 0] = -a[1]
    S[2, 1] = a[0]
    return S


@njit(cache=True)
def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two 3-vectors without NumPy's broadcasting overhead."""
    out = np.empty(3)
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


@njit(cache=True)
def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternion along ``q``; the identity if ``q`` is zero or not finite."""
    n = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    out = np.empty(4)
    if not (n > 1e-300) or not np.isfinite(n):
        out[0] = 1.0
        out[1] = 0.0
        out[2] = 0.0
        out[3] = 0.0
        return out
    for i in range(4):
        out[i] = q[i] / n
    return out


@njit(cache=True)
def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product ``p * q`` (scalar first); ``R(p*q) = R(p) R(q)``."""
    out = np.empty(4)
    out[0] = p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3]
    out[1] = p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2]
    out[2] = p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1]
    out[3] = p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0]
    return out


@njit(cache=True)
def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate (the inverse of a unit quaternion)."""
    out = np.empty(4)
    out[0] = q[0]
    out[1] = -q[1]
    out[2] = -q[2]
    out[3] = -q[3]
    return out


@njit(cache=True)
def quat_to_rotmat_rows(q) -> tuple:
    """:func:`quat_to_rotmat` as three row 3-tuples: no array allocated (the controller's every tick)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return ((1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)),
            (2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)),
            (2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)))


@njit(cache=True)
def rows_times(R, v) -> tuple:
    """``R v`` for ``R`` as three row 3-tuples (body to world for ``R_WB``)."""
    return (R[0][0] * v[0] + R[0][1] * v[1] + R[0][2] * v[2],
            R[1][0] * v[0] + R[1][1] * v[1] + R[1][2] * v[2],
            R[2][0] * v[0] + R[2][1] * v[1] + R[2][2] * v[2])


@njit(cache=True)
def rows_transpose_times(R, v) -> tuple:
    """``R^T v`` for ``R`` as three row 3-tuples (world to body for ``R_WB``)."""
    return (R[0][0] * v[0] + R[1][0] * v[1] + R[2][0] * v[2],
            R[0][1] * v[0] + R[1][1] * v[1] + R[2][1] * v[2],
            R[0][2] * v[0] + R[1][2] * v[1] + R[2][2] * v[2])


@njit(cache=True)
def quat_to_rotmat(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion ``q_WB`` -> ``R_WB``."""
    rows = quat_to_rotmat_rows(q)
    R = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            R[i, j] = rows[i][j]
    return R


def quats_to_rotmats(q_WB: np.ndarray) -> np.ndarray:
    """``R_WB`` (n, 3, 3) of quaternions ``q_WB`` (n, 4), scalar first: :func:`quat_to_rotmat` for a
    whole history at once (NumPy, not compiled). Unnormalised input gives the same formula's
    matrix, which is what an orthonormality check of a logged history needs."""
    q = np.asarray(q_WB, dtype=float)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    R = np.empty((q.shape[0], 3, 3))
    R[:, 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[:, 0, 1] = 2.0 * (x * y - w * z)
    R[:, 0, 2] = 2.0 * (x * z + w * y)
    R[:, 1, 0] = 2.0 * (x * y + w * z)
    R[:, 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[:, 1, 2] = 2.0 * (y * z - w * x)
    R[:, 2, 0] = 2.0 * (x * z - w * y)
    R[:, 2, 1] = 2.0 * (y * z + w * x)
    R[:, 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return R


@njit(cache=True)
def rotmat_rows_to_quat(R_rows) -> tuple:
    """Unit quaternion (scalar first, ``w >= 0``, a 4-tuple) of a rotation given as three row 3-tuples.

    Shepperd's method: pick the largest of ``w, x, y, z`` to divide by, so the result stays
    accurate near 180-degree rotations where ``w -> 0``; then normalised as :func:`quat_normalize`
    (the identity if the norm is zero or not finite). On tuples: the controller calls it every tick.
    """
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R_rows
    tr = r00 + r11 + r22
    if tr >= r00 and tr >= r11 and tr >= r22:
        s = 2.0 * np.sqrt(max(1.0 + tr, 0.0))
        q0, q1, q2, q3 = 0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * np.sqrt(max(1.0 + r00 - r11 - r22, 0.0))
        q0, q1, q2, q3 = (r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s
    elif r11 >= r22:
        s = 2.0 * np.sqrt(max(1.0 - r00 + r11 - r22, 0.0))
        q0, q1, q2, q3 = (r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s
    else:
        s = 2.0 * np.sqrt(max(1.0 - r00 - r11 + r22, 0.0))
        q0, q1, q2, q3 = (r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s
    if q0 < 0.0:
        q0, q1, q2, q3 = -q0, -q1, -q2, -q3
    n = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    if not (n > 1e-300) or not np.isfinite(n):
        return (1.0, 0.0, 0.0, 0.0)
    return (q0 / n, q1 / n, q2 / n, q3 / n)


@njit(cache=True)
def rotmat_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (scalar first, ``w >= 0``) of a rotation matrix (:func:`rotmat_rows_to_quat`)."""
    q = rotmat_rows_to_quat(((R[0, 0], R[0, 1], R[0, 2]), (R[1, 0], R[1, 1], R[1, 2]),
                             (R[2, 0], R[2, 1], R[2, 2])))
    out = np.empty(4)
    for i in range(4):
        out[i] = q[i]
    return out


@njit(cache=True)
def quat_from_euler(yaw_rad: float, pitch_rad: float, roll_rad: float) -> np.ndarray:
    """``q_WB`` from yaw-pitch-roll (3-2-1 intrinsic) angles in radians."""
    cy, sy = np.cos(0.5 * yaw_rad), np.sin(0.5 * yaw_rad)
    cp, sp = np.cos(0.5 * pitch_rad), np.sin(0.5 * pitch_rad)
    cr, sr = np.cos(0.5 * roll_rad), np.sin(0.5 * roll_rad)
    q = np.empty(4)
    q[0] = cr * cp * cy + sr * sp * sy
    q[1] = sr * cp * cy - cr * sp * sy
    q[2] = cr * sp * cy + sr * cp * sy
    q[3] = cr * cp * sy - sr * sp * cy
    return q


@njit(cache=True)
def yaw_pitch_roll(q) -> tuple:
    """:func:`euler_from_quat` as a 3-tuple: no array allocated (the controller's kernels allocate nothing)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    s = 2.0 * (w * y - z * x)
    return (np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)),
            np.arcsin(min(1.0, max(-1.0, s))),
            np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y)))


@njit(cache=True)
def euler_from_quat(q: np.ndarray) -> np.ndarray:
    """Yaw, pitch, roll (3-2-1 intrinsic, radians) of ``q_WB``; pitch clipped to +-pi/2."""
    ypr = yaw_pitch_roll(q)
    out = np.empty(3)
    out[0], out[1], out[2] = ypr
    return out


@njit(cache=True)
def rotmat_from_axis_angle(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rotation by ``angle_rad`` about the unit vector ``axis`` (Rodrigues' formula)."""
    K = skew(axis)
    return np.eye(3) + np.sin(angle_rad) * K + (1.0 - np.cos(angle_rad)) * (K @ K)


@njit(cache=True)
def quat_error_constrained(R_d: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Constrained quaternion error ``[q0~, qv~]`` of ``R~ = R_d^T R`` with ``q0~ >= 0`` (eq:wr).

    The sign of a quaternion is free; choosing ``q0~ >= 0`` picks the shorter of the two
    rotations, so ``-Lambda_q qv~`` in eq:wr always turns the short way round. At exactly
    180 degrees both are equally short and the vector part is returned as it comes.
    """
    return rotmat_to_quat(R_d.T @ R)


@njit(cache=True)
def orthonormalize(R: np.ndarray) -> np.ndarray:
    """Project a slightly drifted ``R`` back onto SO(3) through its quaternion.

    Returns ``R`` itself (to round-off) for a rotation matrix, and always a matrix orthonormal to
    round-off with det +1. It is not the nearest rotation (the polar factor): for a drift of size
    ``eps`` the result differs from it by up to a few ``eps`` (first order), which is harmless for
    the round-off drift of integration.
    """
    return quat_to_rotmat(rotmat_to_quat(R))
