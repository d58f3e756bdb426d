"""The extended physics basis: the paper's eight columns and five columns of physics the paper's model lacks.

The paper's model (:mod:`.paper`) has no side force of the airframe, ties the post-stall plate to
the lift slope (``C_N90 = C_L1 / pi``), stalls exactly where the vehicle file believes, and takes
the pusher's thrust as ``C_Tx u^2`` at any airspeed. A real aircraft (and the simulated one,
whose truth this module never reads) differs in each; each difference that is linear in one
coefficient becomes a column here, after the paper's eight (which stay bit for bit the paper's):

``CY`` (1/rad)
    Side force of fuselage and fin, ``f_y = (rho S / 2m) V^2 beta C_Y``, ``beta = asin(v_iy / V)``.
    Prior: the TU Delft V3 kite's wind-tunnel side-force slope (``data/tudelft-v3-kite-windtunnel``,
    ``C_S`` against beta over ``|beta| <= 12 deg``: 0.91/rad at alpha 7.4 deg, 0.53/rad at 12.5 deg)
    sets the prior's *width*, ``std = 0.7``/rad; its mean is 0 and its sign negative (an aircraft's
    side force opposes the sideslip; the kite's anhedral canopy is a side-force surface of the
    opposite sense, so its sign is not taken).
``dCN90`` (-)
    Normal-force coefficient of the post-stall plate beyond the paper model's ``C_L1 / pi``: the
    column is ``(0, 0, -q sigma sin(alpha))`` with the model's stall weight ``sigma``. Prior mean:
    Viterna and Corrigan's ``C_N90 = C_Dmax = 1.11 + 0.018 AR`` (NASA CP-2230) less ``C_L1 / pi``;
    std 1.0, wide enough to hold the thin flat plate's 2.0 (the wind-tunnel data stop at 24.5 deg,
    short of any post-stall plateau).
``dCL1_stall`` (1/rad)
    Lift slope gained or lost near the believed stall angle ``alpha_s`` where the real wing stalls
    earlier or later: the lift column ``q alpha (sin a, 0, -cos a)`` weighted by a bump
    ``sin^2(pi t)``, ``t = (|alpha| - alpha_s + stall_band_below_deg) / (stall_band_below_deg +
    8 deg)`` over ``[alpha_s - 6, alpha_s + 8] deg`` (the model's blend ends at ``alpha_s + 8``).
    Prior mean 0, std ``stall_std_fraction C_L1`` (an earlier stall loses most of the slope).
``CTJ1``, ``CTJ2`` (m/s^2)
    The pusher's thrust falls with the advance ratio ``J = v_ix / (n D)``: ``T/m = C_Tx u^2 +
    CTJ1 u^2 J + CTJ2 u^2 J^2`` with ``n = n_max u`` (rotor speed linear in throttle), ``J``
    clipped to ``[0, J_max]``. ``n_max D`` is the believed one: the static thrust coefficient
    ``pusher_static_CT`` with Table I's ``C_Tx`` and the vehicle's prop diameter. Prior means
    ``C_Tx a1``, ``C_Tx a2`` with ``a1, a2`` the UIUC propeller database's 7x4 ``C_T(J)/C_T(0)``
    fit (:func:`vtoladapt.fitting.pusher_thrust_ratio_model`; a test pins the numbers), std
    ``ctj_std_fraction`` of the mean.

The new columns' predicted force is what the controller's attitude and allocation take as a known
additive force (:mod:`vtoladapt.bases`); the Bayesian fit and the adaptation treat them like the
paper's (their own prior, P0, bounds and forgetting).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import forces
from ..config import Validated, setting
from ..layout import BlockLayout, Field
from . import IN_FLOW, IN_U, IN_V_I_B, BasisSpec, paper, regressor_kernel

EXTRA_NAMES = ("CY", "dCN90", "dCL1_stall", "CTJ1", "CTJ2")
N_EXTRA = len(EXTRA_NAMES)
N = paper.N_THETA + N_EXTRA

BLOCK = BlockLayout("extended basis constants", [
    Field("PAPER", paper.BLOCK.size, "-", "the paper's constants (k1, k2)"),
    Field("AERO_SCALE", 1, "1/m", "rho S / (2 m)"),
    Field("BUMP_LO", 1, "rad", "lower edge of the stall-onset bump"),
    Field("BUMP_INV_WIDTH", 1, "1/rad", "1 / width of the stall-onset bump"),
    Field("PUSH_ND", 1, "m/s", "believed n_max D of the pusher (advance ratio J = v_ix / (n_max D u))"),
    Field("J_MAX", 1, "-", "advance ratio beyond which the thrust-ratio fit is not extrapolated"),
])
"""The constants the regressor reads (a basis built on this one starts its block with these)."""
B_AERO_SCALE, B_BUMP_LO, B_BUMP_INV_WIDTH, B_PUSH_ND, B_J_MAX = BLOCK.offsets(
    "AERO_SCALE", "BUMP_LO", "BUMP_INV_WIDTH", "PUSH_ND", "J_MAX")

UIUC_7X4_STATIC_CT = 0.08188
"""UIUC magf 7x4 static thrust coefficient (:func:`vtoladapt.fitting.fit_uiuc_static_ct`)."""
UIUC_7X4_CT_RATIO = (-0.84419, -1.10227)
"""UIUC magf 7x4 ``C_T(J)/C_T(0) - 1 = a1 J + a2 J^2`` (:func:`vtoladapt.fitting.pusher_thrust_ratio_model`)."""
KITE_CY_SLOPE_ABS = (0.91, 0.53)
"""``abs(dC_S/dbeta)`` (1/rad) of the TU Delft V3 kite at alpha 7.4 and 12.5 deg, ``abs(beta) <= 12`` deg (tests pin them)."""
CORRIGAN_CN90 = (1.11, 0.018)
"""Viterna and Corrigan's ``C_Dmax = 1.11 + 0.018 AR`` (NASA CP-2230, 1982)."""
BLEND_WIDTH_RAD = math.radians(forces.STALL_BLEND_WIDTH_DEG)

PHYSICS_EXTRA = (" Side force (rho S / 2m) V^2 beta C_Y along body y; the post-stall plate's normal force beyond "
                 "C_L1/pi, dCN90 q sigma sin(a) along -z; lift slope dCL1_stall near the believed stall "
                 "(a sin^2 bump over [alpha_s - 6, alpha_s + 8] deg); the pusher's advance-ratio thrust loss "
                 "(CTJ1 J + CTJ2 J^2) u_x^2.")


@dataclass(frozen=True)
class Settings(Validated):
    """The priors of the extra columns (the vehicle file's ``[basis_settings.extended]``)."""

    config_section = "basis_settings.extended"

    CY_mean: float = setting("1/rad", "prior mean of the side-force slope C_Y", default=0.0, ge=-10.0, le=0.0)
    CY_std: float = setting("1/rad", "prior std of C_Y (the TU Delft kite's side-force slope, 0.53-0.91/rad)",
                            default=0.7, gt=0.0, le=10.0)
    CN90_mean: float = setting("-", "prior mean of the plate's C_N90 (0: Corrigan's 1.11 + 0.018 AR)",
                               default=0.0, ge=0.0, le=4.0)
    CN90_std: float = setting("-", "prior std of C_N90", default=1.0, gt=0.0, le=10.0)
    stall_band_below_deg: float = setting("deg", "the stall-onset bump starts this far below the believed "
                                          "stall angle", default=6.0, gt=0.0, le=20.0)
    stall_std_fraction: float = setting("-", "prior std of dCL1_stall as a fraction of C_L1", default=0.5,
                                        gt=0.0, le=5.0)
    pusher_static_CT: float = setting("-", "the pusher's static thrust coefficient (UIUC 7x4)",
                                      default=UIUC_7X4_STATIC_CT, gt=0.0, le=1.0)
    pusher_CT_a1: float = setting("-", "C_T(J)/C_T(0) - 1 = a1 J + a2 J^2: a1 (UIUC 7x4)",
                                  default=UIUC_7X4_CT_RATIO[0], ge=-10.0, le=10.0)
    pusher_CT_a2: float = setting("-", "a2 (UIUC 7x4)", default=UIUC_7X4_CT_RATIO[1], ge=-10.0, le=10.0)
    J_max: float = setting("-", "advance ratio where the fit stops (UIUC data to 0.78)", default=0.8, gt=0.0, le=2.0)
    ctj_std_fraction: float = setting("-", "prior std of CTJ1, CTJ2 as a fraction of their means", default=0.5,
                                      gt=0.0, le=10.0)
    P0_extra: tuple[float, ...] = setting("adaptation units", "initial adaptation gain of CY, dCN90, dCL1_stall, "
                                          "CTJ1, CTJ2", default=(1.0, 1.0, 1.0, 50.0, 50.0), length=N_EXTRA, gt=0.0)


def aspect_ratio(vehicle) -> float:
    """``b^2 / S`` of the vehicle's wing."""
    return vehicle.geometry.wingspan_m ** 2 / vehicle.geometry.wing_area_m2


def pusher_nd(vehicle, static_CT: float, CTx_scaled: float) -> float:
    """Believed ``n_max D`` (m/s): the rotor speed at which the static thrust ``CT rho n^2 D^4`` is
    ``C_Tx m`` (Table I), times the prop diameter."""
    D = vehicle.geometry.pusher_prop_diameter_m
    rho = vehicle.envelope.air_density_kgpm3
    n_max = math.sqrt(CTx_scaled * vehicle.mass.mass_kg / (static_CT * rho * D ** 4))
    return n_max * D


def extra_prior(vehicle, settings: Settings, p: BasisSpec) -> tuple[np.ndarray, np.ndarray]:
    """The five extra columns' prior mean and std (their units, scale 1)."""
    CL1 = vehicle.force_model.CL1
    cn90 = settings.CN90_mean or (CORRIGAN_CN90[0] + CORRIGAN_CN90[1] * aspect_ratio(vehicle))
    CTx_s = float(p.theta_scaled[forces.I_CTX])
    m1, m2 = CTx_s * settings.pusher_CT_a1, CTx_s * settings.pusher_CT_a2
    mean = np.array([settings.CY_mean, cn90 - CL1 / math.pi, 0.0, m1, m2])
    std = np.array([settings.CY_std, settings.CN90_std, settings.stall_std_fraction * CL1,
                    max(settings.ctj_std_fraction * abs(m1), 1e-6), max(settings.ctj_std_fraction * abs(m2), 1e-6)])
    return mean, std


def extended_block(vehicle, settings: Settings, p: BasisSpec) -> np.ndarray:
    """:data:`BLOCK` for ``vehicle``."""
    alpha_s = math.radians(vehicle.envelope.stall_angle_deg)
    lo = alpha_s - math.radians(settings.stall_band_below_deg)
    width = math.radians(settings.stall_band_below_deg) + BLEND_WIDTH_RAD
    nd = pusher_nd(vehicle, settings.pusher_static_CT, float(p.theta_scaled[forces.I_CTX]))
    return BLOCK.pack(PAPER=p.block, AERO_SCALE=vehicle.aero_scale_per_m, BUMP_LO=lo, BUMP_INV_WIDTH=1.0 / width,
                      PUSH_ND=nd, J_MAX=settings.J_max)


def describe(vehicle, settings: Settings) -> BasisSpec:
    """The paper's basis for ``vehicle`` with the five extra columns appended."""
    p = paper.describe(vehicle, paper.Settings())
    mean, std = extra_prior(vehicle, settings, p)
    ones = np.ones(N_EXTRA)
    return BasisSpec(
        id="extended", names=p.names + EXTRA_NAMES, units=p.units + ("1/rad", "-", "1/rad", "m/s²", "m/s²"),
        scaled_units=p.scaled_units + ("1/rad", "-", "1/rad", "m/s²", "m/s²"), scale=np.append(p.scale, ones),
        theta_table=np.append(p.theta_table, mean), std_table=np.append(p.std_table, std),
        P0_diag=np.append(p.P0_diag, settings.P0_extra), bound_fraction=np.append(p.bound_fraction, ones),
        bound_sigmas=p.bound_sigmas,
        # a side force opposes the sideslip and the pusher loses thrust with J; the others either sign
        sign=np.append(p.sign, [-1.0, 0.0, 0.0, -1.0, 0.0]),
        wing=np.append(p.wing, [False, True, True, False, False]),
        block=extended_block(vehicle, settings, p), regressor=regressor, physics=paper.PHYSICS + PHYSICS_EXTRA,
        source=(p.source + "; CY: TU Delft V3 kite side-force slope (width); dCN90: Viterna-Corrigan C_Dmax; "
                "CTJ1, CTJ2: UIUC 7x4 C_T(J); [basis_settings.extended]"))


def parameter_names(block) -> tuple[str, ...]:
    """The paper's eight, then :data:`EXTRA_NAMES`."""
    return paper.parameter_names(block) + EXTRA_NAMES


@njit(cache=True, inline="always")
def extended_columns(block, x, phi, n) -> None:
    """Write the paper's eight columns and the five extra ones as columns 0-12 of each row of ``phi``
    (3 x n, row-major): the physics part of a basis built on this one."""
    paper.paper_columns(block, x, phi, n)
    vx, vy, vz = x[IN_V_I_B], x[IN_V_I_B + 1], x[IN_V_I_B + 2]
    V2 = vx * vx + vy * vy + vz * vz
    beta = np.arcsin(min(1.0, max(-1.0, vy / np.sqrt(V2)))) if V2 > 0.0 else 0.0
    f = IN_FLOW
    alpha = x[f + forces.F_ALPHA]
    sa = x[f + forces.F_SIN_ALPHA]
    ca = x[f + forces.F_COS_ALPHA]
    q = x[f + forces.F_Q]
    sigma = x[f + forces.F_SIGMA]
    k = paper.N_THETA
    # side force
    phi[k] = 0.0
    phi[n + k] = block[B_AERO_SCALE] * V2 * beta
    phi[2 * n + k] = 0.0
    # the plate's normal force beyond C_L1/pi, along body -z
    phi[k + 1] = 0.0
    phi[n + k + 1] = 0.0
    phi[2 * n + k + 1] = -q * sigma * sa
    # lift slope near the believed stall: a sin^2 bump in |alpha|
    t = (abs(alpha) - block[B_BUMP_LO]) * block[B_BUMP_INV_WIDTH]
    bump = np.sin(np.pi * t) ** 2 if 0.0 < t < 1.0 else 0.0
    phi[k + 2] = q * bump * alpha * sa
    phi[n + k + 2] = 0.0
    phi[2 * n + k + 2] = -q * bump * alpha * ca
    # the pusher's advance-ratio loss: u^2 J and u^2 J^2, J clipped to [0, J_max]
    u = x[IN_U]
    if u > 0.0:
        J = min(max(vx, 0.0) / (block[B_PUSH_ND] * u), block[B_J_MAX])
        phi[k + 3] = u * u * J
        phi[k + 4] = u * u * J * J
    else:
        phi[k + 3] = 0.0
        phi[k + 4] = 0.0
    for r in (1, 2):
        phi[r * n + k + 3] = 0.0
        phi[r * n + k + 4] = 0.0


@regressor_kernel
def regressor(block, x, phi, work):
    """The extended basis's regressor (:func:`extended_columns`), 3 x 13."""
    extended_columns(block, x, phi, N)
