"""Incident velocity <-> (airspeed, angle of attack, sideslip), and flow-angle errors.

Conventions (project-wide, eq:vi and eq:alphabeta)
--------------------------------------------------
``v_i_B`` is the velocity of the vehicle relative to the air, in body axes FRD (x forward,
y right, z down); the air flows onto the vehicle as ``-v_i_B``. The probe points along body +x.

* ``V = |v_i_B|``
* ``alpha = atan2(v_iz, v_ix)``
* ``beta = asin(v_iy / V)``

so that ``v_i_B = V [cos(alpha) cos(beta), sin(beta), sin(alpha) cos(beta)]``.

A wind-tunnel probe calibration is usually given as cone angle ``Theta`` (between the probe axis
and the flow) and roll angle ``Phi`` (of the flow about the probe axis). With ``Phi = 0`` a pure
positive angle of attack and ``Phi = +90 deg`` a pure positive sideslip,
``v_i_B / V = [cos(Theta), sin(Theta) sin(Phi), sin(Theta) cos(Phi)]``, i.e.
``tan(alpha) = tan(Theta) cos(Phi)`` and ``sin(beta) = sin(Theta) sin(Phi)``.
"""
from __future__ import annotations

import numpy as np


def v_i_from_airspeed_angles(V_mps, alpha_rad, beta_rad) -> np.ndarray:
    """Incident velocity in body axes from airspeed and flow angles (eq:alphabeta inverted).

    Parameters
    ----------
    V_mps, alpha_rad, beta_rad : float or array_like
        Airspeed (m/s), angle of attack and sideslip (rad); broadcast together.

    Returns
    -------
    numpy.ndarray
        ``v_i_B`` (m/s), shape ``broadcast_shape + (3,)``.
    """
    V = np.asarray(V_mps, dtype=float)
    a = np.asarray(alpha_rad, dtype=float)
    b = np.asarray(beta_rad, dtype=float)
    V, a, b = np.broadcast_arrays(V, a, b)
    return np.stack([V * np.cos(a) * np.cos(b), V * np.sin(b), V * np.sin(a) * np.cos(b)], axis=-1)


def airspeed_angles_from_v_i(v_i_B) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Airspeed, angle of attack and sideslip from the incident velocity (eq:alphabeta).

    Parameters
    ----------
    v_i_B : array_like, shape (..., 3)
        Incident velocity in body axes (m/s).

    Returns
    -------
    V_mps, alpha_rad, beta_rad : numpy.ndarray
        Shape ``v_i_B.shape[:-1]``. Where ``V == 0`` both angles are 0.
    """
    v = np.asarray(v_i_B, dtype=float)
    V = np.linalg.norm(v, axis=-1)
    alpha = np.arctan2(v[..., 2], v[..., 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(V > 0.0, v[..., 1] / np.where(V > 0.0, V, 1.0), 0.0)
    beta = np.arcsin(np.clip(s, -1.0, 1.0))
    return V, alpha, beta


def cone_roll_to_alpha_beta(theta_rad, phi_rad) -> tuple[np.ndarray, np.ndarray]:
    """Angle of attack and sideslip from a tunnel's cone and roll angles.

    ``tan(alpha) = tan(Theta) cos(Phi)``, ``sin(beta) = sin(Theta) sin(Phi)``: ``Phi = 0`` is a
    pure positive angle of attack, ``Phi = +90 deg`` a pure positive sideslip (see the module
    docstring).

    Parameters
    ----------
    theta_rad, phi_rad : array_like
        Cone angle and roll angle (rad).

    Returns
    -------
    alpha_rad, beta_rad : numpy.ndarray
    """
    th = np.asarray(theta_rad, dtype=float)
    ph = np.asarray(phi_rad, dtype=float)
    alpha = np.arctan2(np.sin(th) * np.cos(ph), np.cos(th))
    beta = np.arcsin(np.clip(np.sin(th) * np.sin(ph), -1.0, 1.0))
    return alpha, beta


def flow_angle_error_rad(v_est_B, v_true_B) -> np.ndarray:
    """Angle between estimated and true flow directions (rad), robust for small angles.

    Uses ``atan2(|a x b|, a . b)``, accurate down to rounding (``arccos`` of a dot product loses
    about 1e-8 rad near zero).

    Parameters
    ----------
    v_est_B, v_true_B : array_like, shape (..., 3)

    Returns
    -------
    numpy.ndarray
        Shape ``(...)``; NaN where either vector is zero.
    """
    a = np.asarray(v_est_B, dtype=float)
    b = np.asarray(v_true_B, dtype=float)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    dot = np.sum(a * b, axis=-1)
    out = np.arctan2(cross, dot)
    zero = (np.linalg.norm(a, axis=-1) == 0.0) | (np.linalg.norm(b, axis=-1) == 0.0)
    return np.where(zero, np.nan, out)
