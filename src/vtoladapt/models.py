"""The paper's force model as a user-facing API (throttle in percent, a :class:`Vehicle`).

>>> import numpy as np, vtoladapt
>>> from vtoladapt import models
>>> veh = vtoladapt.load_vehicle("caltech_vtol")
>>> f_b = models.body_force(np.array([9.0, 0.0, 0.787]), 20.0, 58.0, veh)   # m/s^2, body FRD
>>> Phi = models.regressor(np.array([9.0, 0.0, 0.787]), 20.0, 58.0, veh)    # 3 x 8
>>> bool(np.allclose(Phi @ models.scaled_theta(veh), f_b))
True

Parameter scaling for adaptation (the one place it is defined)
-------------------------------------------------------------
Table I gives the thrust and side-force coefficients with throttle ``u`` in percent
(``C_Tz u_z^2`` = 9.81 m/s^2 at u_z ~ 58 %). Inside the regressor and adaptation the throttle is a
fraction in [0, 1], so the adapted parameters are

    CTx_s = CTx * 100^2,  CTz_s = CTz * 100^2,  CS_s = CS * 100^k1,  aero coefficients unchanged.

``CTz_s`` (28.7 m/s^2 for the paper's aircraft) is then the full-throttle acceleration, and all
eight regressor columns are of order 1-10 in flight, which is the scaling in which Table III's P0
is well conditioned (see the experiments' report).
"""
from __future__ import annotations

import numpy as np

from . import forces
from .vehicle import PARAMETER_NAMES, Vehicle

THROTTLE_FULL_PCT = 100.0
"""Throttle in percent that corresponds to a fraction of 1 in the kernels."""


def theta_scale(k1: float) -> np.ndarray:
    """Per-parameter factors with ``theta_scaled = theta_table * theta_scale(k1)``."""
    return np.array([THROTTLE_FULL_PCT**2, THROTTLE_FULL_PCT**2, THROTTLE_FULL_PCT**k1,
                     1.0, 1.0, 1.0, 1.0, 1.0])


def theta_to_scaled(theta_table: np.ndarray, k1: float) -> np.ndarray:
    """Table I units (throttle in %) -> adaptation scaling (throttle as a fraction)."""
    return np.asarray(theta_table, dtype=float) * theta_scale(k1)


def theta_from_scaled(theta_scaled: np.ndarray, k1: float) -> np.ndarray:
    """Adaptation scaling -> Table I units (throttle in %)."""
    return np.asarray(theta_scaled, dtype=float) / theta_scale(k1)


def model_kernel_params(aero_scale_per_m: float, k1: float, k2: float) -> np.ndarray:
    """Kernel parameter array ``[rho S / (2 m), k1, k2]`` for :mod:`vtoladapt.forces`."""
    return np.array([aero_scale_per_m, k1, k2], dtype=float)


def scaled_theta(vehicle: Vehicle) -> np.ndarray:
    """The vehicle's published theta (Table I means) in the adaptation scaling."""
    return vehicle.theta_scaled.copy()  # a writable copy: the vehicle's own array is read-only


def _v3(v_i_B) -> np.ndarray:
    v = np.asarray(v_i_B, dtype=float)
    if v.shape != (3,):
        raise ValueError(f"v_i_B must have shape (3,), got {v.shape}")
    return v


def body_force(v_i_B, throttle_x_pct: float, throttle_z_pct: float, vehicle: Vehicle,
               theta_scaled: np.ndarray | None = None) -> np.ndarray:
    """Estimated body force ``f_b-hat = f_T-hat + f_A-hat`` (m/s^2, body FRD) (eq:fThat + eq:fAhat).

    Parameters
    ----------
    v_i_B : array (3,)
        Incident velocity (vehicle relative to air) in body axes, m/s.
    throttle_x_pct, throttle_z_pct : float
        Pusher and lift-rotor throttle, percent.
    vehicle : Vehicle
        Supplies the coefficients (Table I means) unless ``theta_scaled`` is given.
    theta_scaled : array (8,), optional
        Coefficients in the adaptation scaling, e.g. an adapted theta-hat.
    """
    theta = vehicle.theta_scaled if theta_scaled is None else np.asarray(theta_scaled, float)
    out = np.empty(3)
    forces.body_force(_v3(v_i_B), throttle_x_pct / THROTTLE_FULL_PCT,
                      throttle_z_pct / THROTTLE_FULL_PCT, theta, vehicle.model_kernel, out)
    return out


def regressor(v_i_B, throttle_x_pct: float, throttle_z_pct: float, vehicle: Vehicle) -> np.ndarray:
    """The regressor ``Phi`` (3x8) with ``Phi @ scaled_theta(vehicle) == body_force(...)``.

    Columns are ``CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1`` in the adaptation scaling.
    """
    Phi = np.empty((3, forces.N_THETA))
    forces.regressor(_v3(v_i_B), throttle_x_pct / THROTTLE_FULL_PCT,
                     throttle_z_pct / THROTTLE_FULL_PCT, vehicle.model_kernel, Phi)
    return Phi


def body_force_jacobian(v_i_B, throttle_x_pct: float, throttle_z_pct: float, vehicle: Vehicle,
                        theta_scaled: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(d f_b / d v_i_B [3x3, 1/s], d f_b / d(throttle_x_pct, throttle_z_pct) [3x2, m/s^2 per %])``.

    At the vehicle's published coefficients, or at ``theta_scaled`` (e.g. an adapted theta-hat).
    """
    theta = vehicle.theta_scaled if theta_scaled is None else np.asarray(theta_scaled, float)
    J_v = np.empty((3, 3))
    J_u = np.empty((3, 2))
    forces.body_force_jacobian(_v3(v_i_B), throttle_x_pct / THROTTLE_FULL_PCT,
                               throttle_z_pct / THROTTLE_FULL_PCT, theta,
                               vehicle.model_kernel, J_v, J_u)
    return J_v, J_u / THROTTLE_FULL_PCT


def airflow_angles(v_i_B) -> tuple[float, float, float]:
    """``(V [m/s], alpha [rad], beta [rad])`` of an incident velocity (eq:alphabeta)."""
    return forces.airflow_angles(_v3(v_i_B))


__all__ = ["PARAMETER_NAMES", "THROTTLE_FULL_PCT", "airflow_angles", "body_force",
           "body_force_jacobian", "model_kernel_params", "regressor", "scaled_theta",
           "theta_from_scaled", "theta_scale", "theta_to_scaled"]
