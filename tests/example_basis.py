"""An example force-model basis from outside the package: the paper's eight columns plus a side force C_Y(beta).

This module is what README "Adding a force-model basis" shows: one module meeting the basis interface
(:mod:`vtoladapt.bases`), registered by ``vtoladapt.components.register("basis", INFO)``. The ninth
column is the fuselage and tail's side force, ``f_y = (rho S / 2 m) V^2 beta C_Y`` per unit mass (the
form of the simulated aircraft's, :mod:`vtoladapt.sim.plant`), with ``beta = asin(v_iy / V)``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vtoladapt.bases import IN_V_I_B, BasisInfo, BasisSpec, paper, regressor_kernel
from vtoladapt.config import Validated, setting
from vtoladapt.layout import BlockLayout, Field

N = paper.N_THETA + 1

BLOCK = BlockLayout("paper_cy constants", [
    Field("PAPER", paper.BLOCK.size, "-", "the paper's constants (k1, k2)"),
    Field("AERO_SCALE", 1, "1/m", "rho S / (2 m)"),
])
(B_AERO_SCALE,) = BLOCK.offsets("AERO_SCALE")


@dataclass(frozen=True)
class Settings(Validated):
    """The prior of C_Y (the vehicle file's ``[basis_settings.paper_cy]``)."""

    config_section = "basis_settings.paper_cy"

    CY_mean: float = setting("1/rad", "prior mean of the side-force slope C_Y", default=0.0, ge=-10.0, le=10.0)
    CY_std: float = setting("1/rad", "prior standard deviation of C_Y", default=0.5, gt=0.0, le=10.0)
    CY_P0: float = setting("adaptation units", "initial adaptation gain of C_Y", default=1.0, gt=0.0, le=1e6)


def describe(vehicle, settings: Settings) -> BasisSpec:
    """The paper's basis for ``vehicle`` with the C_Y column appended."""
    p = paper.describe(vehicle, paper.Settings())
    return BasisSpec(
        id="paper_cy", names=p.names + ("CY",), units=p.units + ("1/rad",),
        scaled_units=p.scaled_units + ("1/rad",), scale=np.append(p.scale, 1.0),
        theta_table=np.append(p.theta_table, settings.CY_mean), std_table=np.append(p.std_table, settings.CY_std),
        P0_diag=np.append(p.P0_diag, settings.CY_P0), bound_fraction=np.append(p.bound_fraction, 1.0),
        bound_sigmas=p.bound_sigmas, sign=np.append(p.sign, -1.0),   # a side force opposes the sideslip
        wing=np.append(p.wing, False), block=BLOCK.pack(PAPER=p.block, AERO_SCALE=vehicle.aero_scale_per_m),
        regressor=regressor, physics=p.physics + " Side force (rho S / 2m) V^2 beta C_Y along body y.",
        source=p.source + "; C_Y: [basis_settings.paper_cy]")


def parameter_names(block) -> tuple[str, ...]:
    """The paper's eight, then CY."""
    return paper.parameter_names(block) + ("CY",)


@regressor_kernel
def regressor(block, x, phi, work):
    """The paper's columns, then ``(0, (rho S / 2m) V^2 beta, 0)``."""
    paper.paper_columns(block, x, phi, N)
    vx, vy, vz = x[IN_V_I_B], x[IN_V_I_B + 1], x[IN_V_I_B + 2]
    V2 = vx * vx + vy * vy + vz * vz
    beta = np.arcsin(min(1.0, max(-1.0, vy / np.sqrt(V2)))) if V2 > 0.0 else 0.0
    phi[N - 1] = 0.0
    phi[2 * N - 1] = block[B_AERO_SCALE] * V2 * beta
    phi[3 * N - 1] = 0.0


INFO = BasisInfo("paper_cy", "Paper + C_Y (9)", __name__,
                 "the paper's eight columns and a side force C_Y(beta) (an example from outside the package)")
