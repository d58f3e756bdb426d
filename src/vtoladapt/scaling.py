"""The force-model parameters' scaling for adaptation (the one place it is defined).

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
