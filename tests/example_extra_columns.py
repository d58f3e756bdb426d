"""A test basis: the paper's eight columns and two extra columns whose force the test chooses by theta.

``Fy0`` (m/s^2): a constant body-y force ``(0, 1, 0)`` -- a stand-in for a learned block that
explains a horizontal force away (issue #34, defect 2). ``CTx_extra`` (m/s^2): ``(u_x^2, 0, 0)``, the
pusher column's own shape -- a stand-in for a learned block whose force grows with the pusher
throttle (defect 3: the network's ``|dF_x/du_x|`` reached 0.66-0.85 of the thrust slope).
Both priors are 0 with a wide spread, so a test sets their weight through ``theta_init``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vtoladapt.bases import IN_U, BasisInfo, BasisSpec, paper, regressor_kernel
from vtoladapt.config import Validated

EXTRA = ("Fy0", "CTx_extra")
N = paper.N_THETA + len(EXTRA)


@dataclass(frozen=True)
class Settings(Validated):
    """No settings of its own."""


def describe(vehicle, settings: Settings) -> BasisSpec:
    """The paper's basis for ``vehicle`` with the two columns appended (prior 0, std 100)."""
    p = paper.describe(vehicle, paper.Settings())
    k = len(EXTRA)
    return BasisSpec(
        id="paper_extra_test", names=p.names + EXTRA, units=p.units + ("m/s^2",) * k,
        scaled_units=p.scaled_units + ("m/s^2",) * k, scale=np.append(p.scale, np.ones(k)),
        theta_table=np.append(p.theta_table, np.zeros(k)), std_table=np.append(p.std_table, np.full(k, 100.0)),
        P0_diag=np.append(p.P0_diag, np.ones(k)), bound_fraction=np.append(p.bound_fraction, np.ones(k)),
        bound_sigmas=p.bound_sigmas, sign=np.append(p.sign, np.zeros(k)), wing=np.append(p.wing, [False] * k),
        block=p.block, regressor=regressor, physics=p.physics, source=p.source)


def parameter_names(block) -> tuple[str, ...]:
    """The paper's eight, then the two test columns."""
    return paper.parameter_names(block) + EXTRA


@regressor_kernel
def regressor(block, x, phi, work):
    """The paper's columns, then ``(0, 1, 0)`` and ``(u_x^2, 0, 0)``."""
    paper.paper_columns(block, x, phi, N)
    u_x = x[IN_U]
    phi[N - 2] = 0.0
    phi[2 * N - 2] = 1.0
    phi[3 * N - 2] = 0.0
    phi[N - 1] = u_x * u_x
    phi[2 * N - 1] = 0.0
    phi[3 * N - 1] = 0.0


INFO = BasisInfo("paper_extra_test", "Paper + two test columns (10)", __name__,
                 "the paper's eight columns, a constant side force and a second pusher column (tests only)")
