"""Thruster force allocation at the current attitude (eq:f_proj).

``M f_T-hat = M (R^T f_r - f_A-hat)`` with ``M = diag(1, 0, 1)``: the lift rotors and the pusher
act along body z and x only; the body-y force is the attitude's job (eq:fbar_solve).
Substituting eq:fThat:

* z row: ``-C_Tz u_z^2 = (f_rb - f_A)_z``, solved first (lift has priority: it keeps the
  aircraft in the air), ``u_z = sqrt(max(0, -(f_rb - f_A)_z) / C_Tz)``;
* x row: ``C_Tx u_x^2 - C_S G(alpha, V, u_z) cos(beta_bar) = (f_rb - f_A)_x`` with the rotor side
  force at the ``u_z`` just found (:func:`vtoladapt.forces.side_force_basis`,
  :func:`vtoladapt.forces.rotor_flow_angles`; ``beta_bar = atan2(v_iy, v_ix)``, see forces.py).

Both throttles are clipped to ``[0, u_max]`` (``u_max = throttle_max_pct / 100``). The residual
``f_rb - f_b-hat(v_i, u_x, u_z)`` (body, m/s^2) is reported: zero in x and z inside the
achievable set, the unachievable part outside it. Each row's residual is the smallest its
throttle can give (the map ``u -> C_T u^2`` is monotone on ``[0, u_max]``). When the pusher row
saturates, the lift throttle still moves the x force through the rotor side force, so ``u_z`` is
then refined by a few Gauss-Newton steps on ``|M (f_rb - f_b-hat)|^2``: the reported residual is
the smallest over both throttles (checked against a brute-force search in the tests). The shift
is small (a few 1e-3 m/s^2 of lift) because ``d F_S / d u_z`` is ~1/60 of ``d T_z / d u_z``.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .. import forces

SAT_NONE = 0.0
SAT_LOW = -1.0
SAT_HIGH = 1.0
SAT_TOL_MPS2 = 1e-6
"""A row asking for less than this of the impossible sign is not flagged (round-off in hover)."""


@njit(cache=True)
def _refine_lift_throttle(bx, bz, cs_cb, ctz, G0, u0, k1, u_max) -> float:
    """Gauss-Newton on ``|r|^2``, ``r_x = bx + cs_cb G(u)``, ``r_z = bz + ctz u^2``, ``G = G0 (u/u0)^k1``."""
    if not u0 > 0.0:
        return u0
    c = G0 / u0 ** k1
    u = u0
    for _ in range(6):
        G = c * u ** k1
        rx = bx + cs_cb * G
        rz = bz + ctz * u * u
        jx = cs_cb * k1 * G / u
        jz = 2.0 * ctz * u
        den = jx * jx + jz * jz
        if not den > 0.0:
            break
        u_new = min(max(u - (jx * rx + jz * rz) / den, 1e-6 * u_max), u_max)
        if abs(u_new - u) < 1e-12:
            u = u_new
            break
        u = u_new
    return u


@njit(cache=True)
def allocate_thrusters(f_rb_B, v_i_B, theta, model, u_max) -> tuple:
    """Throttles ``[u_x, u_z]`` (fractions) realising ``f_rb`` at the current attitude (eq:f_proj).

    Parameters
    ----------
    f_rb_B : (3,) force command in body axes ``R^T f_r`` (m/s^2).
    v_i_B : (3,) incident velocity, body (m/s).
    theta : (8,) model parameters (adaptation scaling).
    model : (3,) ``[rho S/(2m), k1, k2]``.
    u_max : float, throttle limit (fraction).

    Returns
    -------
    (u_x, u_z, residual_B, sat_x, sat_z)
        The throttles; ``f_rb - f_b-hat(v_i, u_x, u_z)`` (m/s^2, body, 3-tuple); and per throttle
        -1 if it is at 0 because the row asks for the opposite sign (by more than
        ``SAT_TOL_MPS2``), +1 if clipped at ``u_max``, 0 otherwise.
    """
    return allocate_thrusters_at(f_rb_B, forces.incident_flow(v_i_B, model), theta, model, u_max)


@njit(cache=True)
def allocate_thrusters_at(f_rb_B, flow, theta, model, u_max) -> tuple:
    """:func:`allocate_thrusters` with the incident flow already evaluated (``flow`` =
    :func:`vtoladapt.forces.incident_flow` of ``v_i_B``): the controller's tick evaluates it once for
    the regressor and the allocation."""
    fa = forces.aero_force_at(flow, theta)
    ctx = max(theta[forces.I_CTX], 1e-9)
    ctz = max(theta[forces.I_CTZ], 1e-9)
    u2_max = u_max * u_max
    # z row: -CTz u_z^2 = target_z
    tz = f_rb_B[2] - fa[2]
    u2 = -tz / ctz
    sat_z = SAT_NONE
    if not u2 > 0.0:
        u2 = 0.0
        if tz > SAT_TOL_MPS2:
            sat_z = SAT_LOW
    elif u2 > u2_max:
        u2 = u2_max
        sat_z = SAT_HIGH
    u_z = np.sqrt(u2)
    # x row: CTx u_x^2 - CS G cos(beta_bar) = target_x
    V = flow[forces.F_V]
    alpha_disk, cb, sb = flow[forces.F_ALPHA_DISK], flow[forces.F_COS_BETA_BAR], flow[forces.F_SIN_BETA_BAR]
    G = forces.side_force_basis(alpha_disk, V, u_z, model[forces.M_K1], model[forces.M_K2])
    side_x = -theta[forces.I_CS] * G * cb
    tx = f_rb_B[0] - fa[0] - side_x
    u2 = tx / ctx
    sat_x = SAT_NONE
    if not u2 > 0.0:
        u2 = 0.0
        if tx < -SAT_TOL_MPS2:
            sat_x = SAT_LOW
    elif u2 > u2_max:
        u2 = u2_max
        sat_x = SAT_HIGH
    u_x = np.sqrt(u2)
    if sat_x != SAT_NONE and G > 0.0:
        # x is saturated: trade lift against rotor drag, minimising |r_x|^2 + |r_z|^2 over u_z
        u_z = _refine_lift_throttle(f_rb_B[0] - fa[0] - ctx * u2, f_rb_B[2] - fa[2], theta[forces.I_CS] * cb,
                                    ctz, G, u_z, model[forces.M_K1], u_max)
        G = forces.side_force_basis(alpha_disk, V, u_z, model[forces.M_K1], model[forces.M_K2])
    # f_T-hat at (u_x, u_z) from the flow angles and G above (thruster_force would evaluate them again)
    ft = forces.thruster_force_at(u_x, u_z, theta, G, cb, sb)
    residual_B = (f_rb_B[0] - fa[0] - ft[0], f_rb_B[1] - fa[1] - ft[1], f_rb_B[2] - fa[2] - ft[2])
    return u_x, u_z, residual_B, sat_x, sat_z


__all__ = ["SAT_HIGH", "SAT_LOW", "SAT_NONE", "allocate_thrusters", "allocate_thrusters_at"]
