"""Compiled force-model kernels: the paper's force model, one function per equation.

Everything here takes plain float64 arrays (or tuples) and scalars (see :mod:`vtoladapt.models` for the
user-facing API that takes a :class:`~vtoladapt.vehicle.Vehicle` and throttle in percent).

Kernel conventions
------------------
* ``v_i_B``: incident velocity (vehicle relative to the air) in body FRD axes, m/s (eq:vi).
* ``u_x``, ``u_z``: pusher and lift-rotor throttle as fractions in ``[0, 1]``.
* ``theta``: the adapted parameters ``[CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1]`` in the
  *adaptation scaling* (throttle as a fraction, see :func:`vtoladapt.scaling.theta_to_scaled`),
  so ``CTz`` is the full-throttle lift acceleration in m/s^2.
* ``model``: float64 array ``[aero_scale_per_m, k1, k2]`` where ``aero_scale_per_m = rho S / (2 m)``.
* All forces are per unit mass (m/s^2), body FRD. The force kernels return them as tuples
  (``regressor``: three rows of 8) and also write them into an ``out`` array when one is given:
  tuples pass between compiled functions for free, arrays cost reference counting.

Where the paper is silent or slips (see SPEC.md)
------------------------------------------------
* alpha is the four-quadrant ``atan2(v_iz, v_ix)``; it equals the paper's ``arctan(v_iz / v_ix)``
  whenever ``v_ix > 0``, and keeps lift and drag pointing the right way in backward flow.
* The rotor side force acts in the rotor plane (body x-y) against the in-plane incident flow, so
  its direction is ``beta_bar = atan2(v_iy, v_ix)``, not the paper's ``arctan(v_iy / v_iz)``.
* The side-force basis G uses the rotor-disk angle of attack ``atan2(v_iz, hypot(v_ix, v_iy))``,
  which equals alpha at zero sideslip in forward flight, stays in ``[-pi/2, pi/2]`` where the
  paper's polynomial is defined, and makes G the same for every in-plane flow direction, as a
  rotor is axisymmetric.
* eq:fAhat is divided by mass (through ``aero_scale_per_m``) so that f_A is in m/s^2 like f_b.
"""
from __future__ import annotations

import numpy as np
from numba import njit

N_THETA = 8
I_CTX, I_CTZ, I_CS, I_CD0, I_CD1, I_CD2, I_CL0, I_CL1 = range(8)
M_AERO_SCALE, M_K1, M_K2 = range(3)
HALF_PI_SQ = (0.5 * np.pi) ** 2


@njit(cache=True)
def incident_velocity(v_W: np.ndarray, v_wind_W: np.ndarray, R_WB: np.ndarray) -> np.ndarray:
    """Incident velocity in body axes, ``v_i = R^T (v - v_w)`` (eq:vi)."""
    d0 = v_W[0] - v_wind_W[0]
    d1 = v_W[1] - v_wind_W[1]
    d2 = v_W[2] - v_wind_W[2]
    out = np.empty(3)
    for j in range(3):
        out[j] = R_WB[0, j] * d0 + R_WB[1, j] * d1 + R_WB[2, j] * d2
    return out


@njit(cache=True)
def airflow_angles(v_i_B: np.ndarray) -> tuple:
    """Airspeed ``V``, angle of attack ``alpha`` and sideslip ``beta`` (rad) (eq:alphabeta).

    Returns ``(0, 0, 0)`` at ``V = 0`` rather than NaN.
    """
    vx, vy, vz = v_i_B[0], v_i_B[1], v_i_B[2]
    V = np.sqrt(vx * vx + vy * vy + vz * vz)
    alpha = np.arctan2(vz, vx)
    beta = np.arcsin(min(1.0, max(-1.0, vy / V))) if V > 0.0 else 0.0
    return V, alpha, beta


@njit(cache=True)
def rotor_flow_angles(v_i_B: np.ndarray) -> tuple:
    """Rotor-disk angle of attack and the in-plane flow direction ``(cos beta_bar, sin beta_bar)``.

    ``beta_bar = atan2(v_iy, v_ix)`` replaces eq:fThat's ``arctan(v_iy / v_iz)`` (see module notes).
    With no in-plane flow the direction is taken as +x; G vanishes there, so it does not matter.
    """
    vx, vy, vz = v_i_B[0], v_i_B[1], v_i_B[2]
    h = np.sqrt(vx * vx + vy * vy)
    alpha_disk = np.arctan2(vz, h)
    if h > 0.0:
        return alpha_disk, vx / h, vy / h
    return alpha_disk, 1.0, 0.0


@njit(cache=True)
def thrust(u: float, CT: float) -> float:
    """Thrust per unit mass ``T = C_T u^2`` (eq:model_Txz, eq:model_T with n linear in u)."""
    return CT * u * u


@njit(cache=True)
def side_force_basis(alpha_rad: float, V: float, u_z: float, k1: float, k2: float) -> float:
    """Rotor side-force basis ``G(alpha, V, u_z) = u_z^k1 V^(2-k1) ((pi/2)^2 - alpha^2)(alpha + k2)``.

    eq:model_Fs with the constants ``rho d^(2+k1)`` folded into C_S (eq:model_FS). A negative
    throttle is treated as zero (a rotor cannot spin at negative speed in this model).
    """
    if u_z <= 0.0 or V <= 0.0:
        return 0.0
    return u_z**k1 * V ** (2.0 - k1) * (HALF_PI_SQ - alpha_rad * alpha_rad) * (alpha_rad + k2)


@njit(cache=True)
def lift_coefficient(alpha_rad: float, CL0: float, CL1: float) -> float:
    """``C_L = C_L0 + C_L1 alpha`` (eq:model_cl)."""
    return CL0 + CL1 * alpha_rad


@njit(cache=True)
def drag_coefficient(alpha_rad: float, CD0: float, CD1: float, CD2: float) -> float:
    """``C_D = C_D0 + C_D1 alpha + C_D2 alpha^2`` (eq:model_cd)."""
    return CD0 + CD1 * alpha_rad + CD2 * alpha_rad * alpha_rad


@njit(cache=True)
def thruster_force(v_i_B, u_x, u_z, theta, model, out=None) -> tuple:
    """Estimated thruster force f_T-hat per unit mass (eq:fThat): ``(f_x, f_y, f_z)``, also into ``out`` if given."""
    V = np.sqrt(v_i_B[0] ** 2 + v_i_B[1] ** 2 + v_i_B[2] ** 2)
    alpha_disk, cb, sb = rotor_flow_angles(v_i_B)
    FS = theta[I_CS] * side_force_basis(alpha_disk, V, u_z, model[M_K1], model[M_K2])
    f = (thrust(u_x, theta[I_CTX]) - FS * cb, -FS * sb, -thrust(u_z, theta[I_CTZ]))
    if out is not None:
        out[0], out[1], out[2] = f
    return f


@njit(cache=True)
def aero_force(v_i_B, theta, model, out=None) -> tuple:
    """Estimated wing force f_A-hat per unit mass (eq:fAhat, divided by mass): ``(f_x, f_y, f_z)``.

    Also written into ``out`` if given. The side-force coefficient is the model's ``C_Y = 0``
    (the controller keeps beta = 0).
    """
    vx, vz = v_i_B[0], v_i_B[2]
    V2 = vx * vx + v_i_B[1] ** 2 + vz * vz
    r = np.sqrt(vx * vx + vz * vz)
    alpha = np.arctan2(vz, vx)
    # sin/cos of alpha from the components avoids a trig call and is exact at r > 0.
    sa, ca = (vz / r, vx / r) if r > 0.0 else (0.0, 1.0)
    CL = lift_coefficient(alpha, theta[I_CL0], theta[I_CL1])
    CD = drag_coefficient(alpha, theta[I_CD0], theta[I_CD1], theta[I_CD2])
    q = model[M_AERO_SCALE] * V2
    f = (q * (CL * sa - CD * ca), 0.0, q * (-CL * ca - CD * sa))
    if out is not None:
        out[0], out[1], out[2] = f
    return f


@njit(cache=True)
def body_force(v_i_B, u_x, u_z, theta, model, out=None) -> tuple:
    """Estimated body force ``f_b-hat = f_T-hat + f_A-hat`` per unit mass (eq:fb): ``(f_x, f_y, f_z)``.

    Also written into ``out`` if given.
    """
    fa = aero_force(v_i_B, theta, model)
    ft = thruster_force(v_i_B, u_x, u_z, theta, model)
    f = (ft[0] + fa[0], ft[1] + fa[1], ft[2] + fa[2])
    if out is not None:
        out[0], out[1], out[2] = f
    return f


@njit(cache=True)
def regressor(v_i_B, u_x, u_z, model, Phi=None) -> tuple:
    """The regressor ``Phi(v_i, u_x, u_z)`` (3x8) with ``f_b-hat = Phi theta``.

    Returns the three rows (x, y, z) as tuples of 8, and writes them into the (3, 8) array ``Phi``
    if given. Columns follow ``theta = [CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1]`` (the paper's
    order). This one function serves control, adaptation and fitting.
    """
    vx, vy, vz = v_i_B[0], v_i_B[1], v_i_B[2]
    V2 = vx * vx + vy * vy + vz * vz
    V = np.sqrt(V2)
    r = np.sqrt(vx * vx + vz * vz)
    alpha = np.arctan2(vz, vx)
    sa, ca = (vz / r, vx / r) if r > 0.0 else (0.0, 1.0)
    alpha_disk, cb, sb = rotor_flow_angles(v_i_B)
    G = side_force_basis(alpha_disk, V, u_z, model[M_K1], model[M_K2])
    q = model[M_AERO_SCALE] * V2
    a2 = alpha * alpha
    # drag acts along -x_i = -(cos a, 0, sin a) with C_D0, C_D1 alpha, C_D2 alpha^2;
    # lift along (sin a, 0, -cos a) with C_L0, C_L1 alpha
    rows = ((u_x * u_x, 0.0, -G * cb, -q * ca, -q * alpha * ca, -q * a2 * ca, q * sa, q * alpha * sa),
            (0.0, 0.0, -G * sb, 0.0, 0.0, 0.0, 0.0, 0.0),
            (0.0, -u_z * u_z, 0.0, -q * sa, -q * alpha * sa, -q * a2 * sa, -q * ca, -q * alpha * ca))
    if Phi is not None:
        for i in range(3):
            for j in range(N_THETA):
                Phi[i, j] = rows[i][j]
    return rows


@njit(cache=True)
def regressor_rows(v_i_B_rows, u_x_rows, u_z_rows, model) -> np.ndarray:
    """The regressor for many operating points at once: ``(N, 3)``, ``(N,)``, ``(N,)`` -> ``(N, 3, 8)``."""
    n = v_i_B_rows.shape[0]
    out = np.empty((n, 3, N_THETA))
    for i in range(n):
        regressor(v_i_B_rows[i], u_x_rows[i], u_z_rows[i], model, out[i])
    return out


@njit(cache=True)
def body_force_jacobian(v_i_B, u_x, u_z, theta, model, J_v, J_u) -> None:
    """Analytic Jacobian of ``f_b-hat``: ``J_v = d f / d v_i_B`` (3x3), ``J_u = d f / d(u_x, u_z)`` (3x2).

    Exact where the model is smooth (``V > 0``, in-plane flow ``> 0``, ``u_z > 0``); it is checked
    against finite differences in the tests.
    """
    vx, vy, vz = v_i_B[0], v_i_B[1], v_i_B[2]
    V2 = vx * vx + vy * vy + vz * vz
    V = np.sqrt(V2)
    s = model[M_AERO_SCALE]
    k1, k2 = model[M_K1], model[M_K2]
    for i in range(3):
        for j in range(3):
            J_v[i, j] = 0.0
        J_u[i, 0] = 0.0
        J_u[i, 1] = 0.0
    # wing: f = s V^2 [CL sa - CD ca, 0, -CL ca - CD sa]
    r2 = vx * vx + vz * vz
    if r2 > 0.0:
        r = np.sqrt(r2)
        alpha = np.arctan2(vz, vx)
        sa, ca = vz / r, vx / r
        CL = lift_coefficient(alpha, theta[I_CL0], theta[I_CL1])
        CD = drag_coefficient(alpha, theta[I_CD0], theta[I_CD1], theta[I_CD2])
        dCL = theta[I_CL1]
        dCD = theta[I_CD1] + 2.0 * theta[I_CD2] * alpha
        dalpha = (-vz / r2, 0.0, vx / r2)
        fx = CL * sa - CD * ca
        fz = -CL * ca - CD * sa
        dfx = dCL * sa + CL * ca - dCD * ca + CD * sa
        dfz = -dCL * ca + CL * sa - dCD * sa - CD * ca
        v = (vx, vy, vz)
        for j in range(3):
            J_v[0, j] += s * (2.0 * v[j] * fx + V2 * dfx * dalpha[j])
            J_v[2, j] += s * (2.0 * v[j] * fz + V2 * dfz * dalpha[j])
    # thrust
    J_u[0, 0] = 2.0 * theta[I_CTX] * u_x
    J_u[2, 1] = -2.0 * theta[I_CTZ] * u_z
    # rotor side force: f = -CS G [cb, sb, 0]
    h2 = vx * vx + vy * vy
    if h2 > 0.0 and u_z > 0.0 and V > 0.0:
        h = np.sqrt(h2)
        ad = np.arctan2(vz, h)
        cb, sb = vx / h, vy / h
        P = (HALF_PI_SQ - ad * ad) * (ad + k2)
        dP = -2.0 * ad * (ad + k2) + (HALF_PI_SQ - ad * ad)
        uk = u_z**k1
        G = uk * V ** (2.0 - k1) * P
        # Written with the ratios cb, sb, vz/V (each <= 1) so no product like h * h2 can underflow
        # to zero (Numba raises ZeroDivisionError) at tiny but nonzero airspeed.
        sz = vz / V
        dad = (-sz * cb / V, -sz * sb / V, (h / V) / V)
        dV = (vx / V, vy / V, sz)
        dcb = (sb * sb / h, -cb * sb / h, 0.0)
        dsb = (-cb * sb / h, cb * cb / h, 0.0)
        CS = theta[I_CS]
        for j in range(3):
            dG = uk * ((2.0 - k1) * V ** (1.0 - k1) * dV[j] * P + V ** (2.0 - k1) * dP * dad[j])
            J_v[0, j] += -CS * (dG * cb + G * dcb[j])
            J_v[1, j] += -CS * (dG * sb + G * dsb[j])
        dG_du = k1 * u_z ** (k1 - 1.0) * V ** (2.0 - k1) * P
        J_u[0, 1] += -CS * dG_du * cb
        J_u[1, 1] += -CS * dG_du * sb
