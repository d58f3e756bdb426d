"""The force-model parameters' scaling for adaptation (the one place it is defined).

Table I gives the thrust and side-force coefficients with throttle ``u`` in percent
(``C_Tz u_z^2`` = 9.81 m/s^2 at u_z ~ 58 %). Inside the regressor and adaptation the throttle is a
fraction in [0, 1], so the adapted parameters are

    CTx_s = CTx * 100^2,  CTz_s = CTz * 100^2,  CS_s = CS * 100^k1,  aero coefficients unchanged.

``CTz_s`` (28.7 m/s^2 for the paper's aircraft) is then the full-throttle acceleration, and all
eight regressor columns are of order 1-10 in flight, which is the scaling in which Table III's P0
is well conditioned (see the experiments' report).

The box theta-hat is kept in (:func:`theta_bounds`) is in this scaling too; it is here, below the
controller, because both the controller and a fitted posterior's prior (:mod:`vtoladapt.bases.posterior`) apply it.
"""
from __future__ import annotations

import math

import numpy as np

from . import forces

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


def model_kernel_params(aero_scale_per_m: float, k1: float, k2: float, stall_angle_deg: float) -> np.ndarray:
    """Kernel constants of the force model for :mod:`vtoladapt.forces` (``forces.N_MODEL`` floats).

    ``[rho S / (2 m), k1, k2, -stall, +stall, 1 / blend width, 1 / cos^2(linear sideslip)]`` (angles in
    rad): the wing follows the paper's polars for ``|alpha| <= stall_angle_deg`` and a flat plate
    beyond (see the module notes of :mod:`vtoladapt.forces`).

    Raises
    ------
    ValueError
        If ``stall_angle_deg`` is not in ``(0, 90]``.
    """
    if not 0.0 < stall_angle_deg <= 90.0:
        raise ValueError(f"stall_angle_deg = {stall_angle_deg!r}: must be in (0, 90] deg")
    stall_rad = math.radians(stall_angle_deg)
    model = np.empty(forces.N_MODEL)
    model[forces.M_AERO_SCALE] = aero_scale_per_m
    model[forces.M_K1] = k1
    model[forces.M_K2] = k2
    model[forces.M_ALPHA_LO] = -stall_rad
    model[forces.M_ALPHA_HI] = stall_rad
    model[forces.M_INV_BLEND] = 1.0 / math.radians(forces.STALL_BLEND_WIDTH_DEG)
    model[forces.M_INV_COS2_SIDESLIP] = 1.0 / math.cos(math.radians(forces.SIDESLIP_LINEAR_DEG)) ** 2
    return model


def theta_bound_half_widths(theta_0, theta_std, bound_fraction, bound_sigmas: float) -> np.ndarray:
    """Half-widths of the theta-hat box: ``max(bound_fraction |theta_0|, bound_sigmas |std|)``.

    :func:`theta_bounds` applies them (and the signs physics gives). Never narrower than
    ``1e-13 |theta_0|`` (1e-13 where theta_0 = 0): well above rounding, far below any real bound,
    so a degenerate setting cannot give a zero-width box that freezes theta-hat.
    """
    th0 = np.asarray(theta_0, dtype=float)
    half = np.maximum(np.asarray(bound_fraction, dtype=float) * np.abs(th0),
                      bound_sigmas * np.abs(np.asarray(theta_std, dtype=float)))
    return np.maximum(half, 1e-13 * np.where(th0 != 0.0, np.abs(th0), 1.0))


def theta_bounds(theta_0, theta_std, bound_fraction, bound_sigmas: float, signs) -> tuple[np.ndarray, np.ndarray]:
    """Box bounds of theta-hat: ``theta_0 +- max(bound_fraction |theta_0|, bound_sigmas |std|)``
    (:func:`theta_bound_half_widths`), cut at zero where a coefficient's sign is known from physics
    (``signs``, the basis's :attr:`~vtoladapt.bases.BasisSpec.sign`; for the paper's columns
    :func:`vtoladapt.vehicle.parameter_signs`): a non-negative one's lower bound is at least 0, a
    non-positive one's upper bound at most 0.

    The one rule for the bounds, whether theta_0 comes from the vehicle file or a fitted posterior.
    (Without the cut the caltech_vtol's ``bound_fraction`` 1.5 on C_S let theta-hat reach
    ``-0.5 theta_0``: a rotor side force along the flow.)
    """
    th0 = np.asarray(theta_0, dtype=float)
    half = theta_bound_half_widths(th0, theta_std, bound_fraction, bound_sigmas)
    signs = np.asarray(signs)
    lower = np.where(signs > 0, np.maximum(th0 - half, 0.0), th0 - half)
    upper = np.where(signs < 0, np.minimum(th0 + half, 0.0), th0 + half)
    return lower, upper
