"""The paper's force model as a user-facing API (throttle in percent, a :class:`Vehicle`).

>>> import numpy as np, vtoladapt
>>> from vtoladapt import models
>>> veh = vtoladapt.load_vehicle("caltech_vtol")
>>> f_b = models.body_force(np.array([9.0, 0.0, 0.787]), 20.0, 58.0, veh)   # m/s^2, body FRD
>>> Phi = models.regressor(np.array([9.0, 0.0, 0.787]), 20.0, 58.0, veh)    # 3 x 8
>>> bool(np.allclose(Phi @ models.scaled_theta(veh), f_b))
True

The parameter scaling for adaptation (throttle as a fraction) is defined in
:mod:`vtoladapt.scaling`; its functions are importable from here too.
"""
from __future__ import annotations

import math

import numpy as np

from . import forces
from .scaling import THROTTLE_FULL_PCT, model_kernel_params, theta_from_scaled, theta_scale, theta_to_scaled
from .vehicle import PARAMETER_NAMES, Vehicle


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


def wing_coefficients(alpha_rad: float, vehicle: Vehicle,
                      theta_scaled: np.ndarray | None = None) -> tuple[float, float]:
    """``(C_L, C_D)`` of the controller's wing model at angle of attack ``alpha_rad`` (rad, any value).

    The paper's polars (eq:model_cl, eq:model_cd) for ``|alpha| <= [envelope] stall_angle_deg``,
    a flat plate past it (see :mod:`vtoladapt.forces`); ``alpha_rad`` is wrapped to ``(-pi, pi]``.
    At the vehicle's published coefficients, or at ``theta_scaled``.
    """
    theta = vehicle.theta_scaled if theta_scaled is None else np.asarray(theta_scaled, float)
    sa, ca = math.sin(alpha_rad), math.cos(alpha_rad)
    return forces.wing_coefficients(math.atan2(sa, ca), sa, ca, theta, vehicle.model_kernel)


def airflow_angles(v_i_B) -> tuple[float, float, float]:
    """``(V [m/s], alpha [rad], beta [rad])`` of an incident velocity (eq:alphabeta)."""
    return forces.airflow_angles(_v3(v_i_B))


__all__ = ["PARAMETER_NAMES", "THROTTLE_FULL_PCT", "airflow_angles", "body_force",
           "body_force_jacobian", "model_kernel_params", "regressor", "scaled_theta",
           "theta_from_scaled", "theta_scale", "theta_to_scaled", "wing_coefficients"]
