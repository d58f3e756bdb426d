"""The paper's force-model basis: thrust, rotor side force, lift and drag polars (eight parameters).

``theta = [CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1]`` in the adaptation scaling (throttle as a
fraction, :mod:`vtoladapt.scaling`); the columns are :func:`vtoladapt.forces.regressor_at` (eq:fThat
+ eq:fAhat, with the stall and sideslip continuations of :mod:`vtoladapt.forces`), evaluated on the
flow the controller's front end has already formed (``INPUT.FLOW``): bit for bit the paper's model.
The prior is the vehicle file's: ``[force_model]`` and ``[force_model_std]`` (Table I),
``[adaptation] P0_diag`` (Table III) and the bounds rule ``bound_fraction``, ``bound_sigmas``.
The constants the regressor reads are the side-force exponents ``k1``, ``k2`` (eq:model_Fs).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Mapping

import numpy as np
from numba import njit

from .. import forces
from ..config import Validated
from ..layout import BlockLayout, Field
from ..scaling import theta_scale
from ..vehicle import PARAMETER_NAMES, ForceModelCoefficients
from . import IN_FLOW, IN_U, BasisSpec, physics_signs, regressor_kernel

N_THETA = forces.N_THETA
BLOCK = BlockLayout("paper basis constants", [
    Field("K1", 1, "-", "side-force exponent on rotor speed (eq:model_Fs)"),
    Field("K2", 1, "rad", "side-force asymmetry offset (eq:model_Fs)"),
])
"""The constants the regressor reads (a basis with extra columns starts its block with these)."""
BLOCK_K1, BLOCK_K2 = BLOCK.offsets("K1", "K2")
WING_COLUMNS = np.array([False, False, False, True, True, True, True, True])
"""Drag and lift are the wing's; thrust and the rotor side force are not."""
SCALED_UNITS: dict[str, str] = {
    "CTx": "m/s²", "CTz": "m/s²", "CS": "m^(k1−1) s^(−k1)", "CD0": "-", "CD1": "1/rad",
    "CD2": "1/rad²", "CL0": "-", "CL1": "1/rad"}
"""Unit of each parameter in the adaptation scaling (throttle u as a fraction in [0, 1], forces per unit
mass), the scaling the controller adapts and the logs hold. CS multiplies ``u^k1 V^(2-k1)``
(eq:model_Fs), so its unit, (m/s^2) / (m/s)^(2-k1), depends on k1."""

PHYSICS = ("Thrust T = CT u^2 of the pusher (x) and the lift rotors (z); rotor side force CS G(alpha, V, u_z) "
           "against the in-plane flow; wing lift CL0 + CL1 alpha and drag CD0 + CD1 alpha + CD2 alpha^2 "
           "(eq:fThat, eq:fAhat), blended into a flat plate past the believed stall angle; C_Y = 0.")


@dataclass(frozen=True)
class PaperSettings(Validated):
    """The paper's basis has no settings of its own (its prior is the vehicle file's Table I and III)."""


Settings = PaperSettings


def units() -> tuple[str, ...]:
    """Table-I units of the eight parameters (the vehicle file's ``[force_model]`` units)."""
    meta = {f.name: f.metadata["unit"] for f in dataclasses.fields(ForceModelCoefficients)}
    return tuple(meta[n] for n in PARAMETER_NAMES)


def describe(vehicle, settings: PaperSettings) -> BasisSpec:
    """The basis for ``vehicle``: Table I (mean and std), Table III (P0) and the vehicle's bounds rule."""
    fm = vehicle.force_model
    return BasisSpec(
        id="paper", names=PARAMETER_NAMES, units=units(), scaled_units=tuple(SCALED_UNITS[n] for n in PARAMETER_NAMES),
        scale=theta_scale(fm.k1),
        theta_table=fm.as_table_theta(), std_table=vehicle.force_model_std.as_table_theta(),
        P0_diag=np.array(vehicle.adaptation.P0_diag), bound_fraction=np.array(vehicle.adaptation.bound_fraction),
        bound_sigmas=vehicle.adaptation.bound_sigmas, sign=physics_signs(), wing=WING_COLUMNS,
        block=BLOCK.pack(K1=fm.k1, K2=fm.k2), regressor=regressor, physics=PHYSICS,
        source=f"Table I of {vehicle.name}")


def parameter_names(block) -> tuple[str, ...]:
    """The eight names, whatever the constants."""
    return PARAMETER_NAMES


def truth(coefficients: Mapping[str, float], spec: BasisSpec) -> np.ndarray:
    """The plant's eight coefficients in the adaptation scaling (with the plant's own ``k1``)."""
    table = np.array([coefficients[n] for n in PARAMETER_NAMES], dtype=float)
    return table * theta_scale(coefficients["k1"])


@njit(cache=True, inline="always")
def paper_columns(block, x, phi, n) -> None:
    """Write the paper's eight columns (:func:`vtoladapt.forces.regressor_at` on the input's flow and
    throttles, ``k1``, ``k2`` at ``block[0:2]``) as the first eight of each row of ``phi`` (3 x n,
    row-major): the physics part of every basis, which a basis with extra columns calls first."""
    f = IN_FLOW
    flow = (x[f], x[f + 1], x[f + 2], x[f + 3], x[f + 4], x[f + 5], x[f + 6], x[f + 7], x[f + 8])
    rows = forces.regressor_at(flow, x[IN_U], x[IN_U + 1], block[BLOCK_K1], block[BLOCK_K2])
    for r in range(3):
        row = rows[r]
        for k in range(N_THETA):
            phi[n * r + k] = row[k]


@regressor_kernel
def regressor(block, x, phi, work):
    """The paper's regressor (:func:`paper_columns`), 3 x 8."""
    paper_columns(block, x, phi, N_THETA)
