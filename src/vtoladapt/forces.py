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
* ``model``: float64 array (or tuple) of the :data:`N_MODEL` model constants, built by
  :func:`vtoladapt.scaling.model_kernel_params`: ``[aero_scale_per_m, k1, k2, alpha_lo_rad,
  alpha_hi_rad, inv_blend_width_per_rad, inv_cos2_sideslip_linear]`` with
  ``aero_scale_per_m = rho S / (2 m)``, ``[alpha_lo, alpha_hi]`` the attached-flow range and the
  last two the widths of the continuations below.
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
  rotor is axisymmetric. G vanishes with the in-plane flow (``pi/2 - |alpha_disk| ~ h / V``) and
  with V (``V^(2 - k1)``, ``k1 < 2``), so the side force is continuous everywhere.
* eq:fAhat is divided by mass (through ``aero_scale_per_m``) so that f_A is in m/s^2 like f_b.

The wing outside its attached-flow range
----------------------------------------
The paper's polars (eq:model_cl, eq:model_cd) are fitted to wind-tunnel data between about -10 and
15 deg (Table I); evaluated at any other alpha they extrapolate without bound (at alpha = pi,
backward flow, C_L = 10.6 and C_D = 16.5 for Table I, i.e. 12 m/s^2 at 3 m/s) and jump where
alpha wraps from +pi to -pi. The model used here:

* **Attached flow, exactly the paper.** For ``alpha_lo <= alpha <= alpha_hi`` the coefficients
  are the paper's polynomials, evaluated as before (bit for bit). The range is the vehicle's
  believed stall angle, symmetric: ``alpha_hi = -alpha_lo = [envelope] stall_angle_deg``. (The
  vehicle file states one stall angle; the desired angle of attack lies in ``[alpha_min,
  alpha_max]`` inside it, and Table I's data lie inside it.)
* **Separated flow, a flat plate.** Past stall a wing behaves like a flat plate: a force normal to
  the chord, ``C_N = C_N90 sin(alpha)`` (so ``C_L = C_N cos(alpha)``, ``C_D = C_N sin(alpha)``),
  plus the skin and body drag ``C_D0`` along the flow. This is the leading term of Viterna and
  Corrigan's post-stall model (NASA CP-2230, 1982), whose ``C_N90 = C_Dmax = 1.11 + 0.018 AR``
  is 1.20 for both shipped wings (aspect ratio 5.2 and 4.4); a 2-D plate has about 2, which the
  plant's stall model uses. The plate must be written with the eight adapted parameters
  (``Phi theta == f_b-hat``, no term without a parameter), so its size is tied to the lift slope:
  ``C_N90 = 2 C_L1 / (2 pi) = C_L1 / pi``, the 2-D plate scaled by the same finite-span factor that
  lowers the attached slope from the thin-airfoil ``2 pi`` to ``C_L1``. That gives ``C_N90`` =
  1.03 (caltech_vtol) and 1.51 (px4_standard_vtol). ``C_D2`` would be the other candidate (for a
  plate ``C_D = C_N sin(alpha) ~ C_N90 alpha^2``) but is 0 for px4_standard_vtol, whose drag
  polar is linear. ``C_L0``, ``C_D1`` and ``C_D2`` (camber and the attached polar's shape) have no
  part past stall.
* **Between them, a smooth blend.** With ``t`` the distance past the range edge over
  :data:`STALL_BLEND_WIDTH_DEG` (clipped to [0, 1]) and ``sigma = 3 t^2 - 2 t^3``:
  ``C = (1 - sigma) C_paper + sigma C_plate``. sigma has zero slope at both ends, so the force and
  its Jacobian are continuous; in backward flow sigma = 1 on both sides of alpha = +-pi, and the
  plate terms depend on alpha only through ``sin``/``cos``, so nothing jumps there. At alpha = pi the
  wing gives ``C_D0`` drag along ``-v_i`` and no lift.
* **Sideslip.** The paper's dynamic pressure ``V^2`` includes the spanwise flow, which with C_Y = 0
  makes the force jump when the flow turns through the spanwise direction (``v_ix = v_iz = 0``
  with ``v_iy != 0``: alpha is undefined there). The paper's ``V^2`` is kept for
  ``|beta| <= SIDESLIP_LINEAR_DEG`` (30 deg, far beyond any coordinated flight); beyond, it is
  the chordwise ``v_ix^2 + v_iz^2 = V^2 cos^2(beta)`` of the independence principle (an unswept
  wing feels only the flow across its span), divided by ``cos^2(30 deg)`` so that the two join:
  ``min(V^2, (v_ix^2 + v_iz^2) / cos^2(30 deg))``. It vanishes as the flow turns spanwise (a wing
  edge-on to the flow makes no lift, and C_Y = 0 as in the paper). The join is continuous with a
  kink at 30 deg (a C1 join would need a division per call in the hot path, which cost a third
  of the force model's time in the benchmark).

Every term stays a basis function times one of the eight parameters, so ``regressor`` gives
``Phi theta == f_b-hat`` everywhere, and the fitting pipeline and adaptation see the same model
as the controller. The sine and cosine of alpha come from the velocity components, so the
continuation adds no transcendental call (one ``atan2`` per evaluation, as before).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .layout import BlockLayout, Field

THETA = BlockLayout("the paper's force-model parameters theta (Table I, adaptation scaling)", [
    Field("CTX", 1, "-", "pusher thrust coefficient"),
    Field("CTZ", 1, "-", "lift-rotor thrust coefficient"),
    Field("CS", 1, "-", "lift-rotor side-force coefficient"),
    Field("CD0", 1, "-", "drag at zero angle of attack"),
    Field("CD1", 1, "-", "drag, linear in alpha"),
    Field("CD2", 1, "-", "drag, quadratic in alpha"),
    Field("CL0", 1, "-", "lift at zero angle of attack"),
    Field("CL1", 1, "-", "lift slope"),
])
"""theta of the paper's eight-term model; the order of :func:`regressor`'s columns."""
N_THETA = THETA.size
I_CTX, I_CTZ, I_CS, I_CD0, I_CD1, I_CD2, I_CL0, I_CL1 = THETA.offsets(*(f.name for f in THETA.fields))
MODEL = BlockLayout("force-model constants (Vehicle.model_kernel)", [
    Field("AERO_SCALE", 1, "1/m", "rho S / (2 m): the wing's dynamic pressure per unit mass and V^2"),
    Field("K1", 1, "-", "rotor side-force constant k1"),
    Field("K2", 1, "-", "rotor side-force constant k2"),
    Field("ALPHA_LO", 1, "rad", "minus the stall angle: below it the wing blends to the flat plate"),
    Field("ALPHA_HI", 1, "rad", "the stall angle: above it likewise"),
    Field("INV_BLEND", 1, "1/rad", "1 / the blend's width (STALL_BLEND_WIDTH_DEG)"),
    Field("INV_COS2_SIDESLIP", 1, "-", "1 / cos^2 of the sideslip up to which the pressure is the paper's"),
])
"""The ``model`` constants array (see the kernel conventions)."""
N_MODEL = MODEL.size
(M_AERO_SCALE, M_K1, M_K2, M_ALPHA_LO, M_ALPHA_HI, M_INV_BLEND,
 M_INV_COS2_SIDESLIP) = MODEL.offsets(*(f.name for f in MODEL.fields))
HALF_PI_SQ = (0.5 * np.pi) ** 2
INV_PI = 1.0 / np.pi
STALL_BLEND_WIDTH_DEG = 8.0
"""Width of the blend from the paper's polars to the flat plate past the attached-flow range (deg).

Thin low-Reynolds-number wings lose most of their lift within 5-10 deg past the lift peak."""
SIDESLIP_LINEAR_DEG = 30.0
"""Sideslip up to which the wing's dynamic pressure is the paper's ``rho V^2 / 2`` (deg)."""


@njit(cache=True)
def model_at(a, offset: int) -> tuple:
    """The :data:`N_MODEL` model constants stored in ``a`` from ``offset`` on, as a tuple.

    For compiled callers that keep the constants in a packed parameter array (the controller's
    ``params``): a tuple costs no reference counting, a slice would.
    """
    o = offset
    return (a[o], a[o + 1], a[o + 2], a[o + 3], a[o + 4], a[o + 5], a[o + 6])


@njit(cache=True)
def theta_at(a, offset: int) -> tuple:
    """The :data:`N_THETA` parameters stored in ``a`` from ``offset`` on, as a tuple (as :func:`model_at`)."""
    o = offset
    return (a[o], a[o + 1], a[o + 2], a[o + 3], a[o + 4], a[o + 5], a[o + 6], a[o + 7])


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
    """``C_L = C_L0 + C_L1 alpha`` (eq:model_cl), the attached-flow polar."""
    return CL0 + CL1 * alpha_rad


@njit(cache=True)
def drag_coefficient(alpha_rad: float, CD0: float, CD1: float, CD2: float) -> float:
    """``C_D = C_D0 + C_D1 alpha + C_D2 alpha^2`` (eq:model_cd), the attached-flow polar."""
    return CD0 + CD1 * alpha_rad + CD2 * alpha_rad * alpha_rad


@njit(cache=True)
def stall_weight(alpha_rad: float, lo: float, hi: float, inv_w: float) -> tuple:
    """Weight ``sigma`` of the flat plate past the attached-flow range, and ``d sigma / d alpha``.

    0 inside ``[lo, hi]`` (rad), ``3 t^2 - 2 t^3`` over the blend (``t`` the distance past the edge
    times ``inv_w``, 1 / blend width in 1/rad), 1 beyond (module notes). Scalars, not the model
    array: passing an array to a compiled function costs reference counting in the hot path.
    """
    # branch-free (selects, not jumps): this runs on every evaluation of the wing
    t = min(max(max((alpha_rad - hi) * inv_w, (lo - alpha_rad) * inv_w), 0.0), 1.0)
    dt_dalpha = inv_w if alpha_rad > hi else -inv_w
    return t * t * (3.0 - 2.0 * t), 6.0 * t * (1.0 - t) * dt_dalpha


@njit(cache=True)
def wing_pressure(V2: float, r2: float, s: float, kc: float) -> float:
    """The wing's dynamic pressure per unit mass, ``s = rho S / (2 m)`` times ``V^2`` (m/s^2 per unit C).

    ``V2`` is ``|v_i|^2``, ``r2`` its chordwise part ``v_ix^2 + v_iz^2``, ``kc`` is
    ``1 / cos^2(SIDESLIP_LINEAR_DEG)``: the paper's ``V^2`` up to ``|beta| = SIDESLIP_LINEAR_DEG``, then
    ``kc r2`` (module notes).
    """
    r2_scaled = r2 * kc
    if r2_scaled < V2:
        return s * r2_scaled
    return s * V2


@njit(cache=True)
def wing_coefficients(alpha_rad: float, sin_alpha: float, cos_alpha: float, theta, model) -> tuple:
    """Lift and drag coefficients ``(C_L, C_D)`` at any angle of attack.

    eq:model_cl and eq:model_cd inside the attached-flow range, blended into a flat plate of
    normal-force coefficient ``(C_L1 / pi) sin(alpha)`` plus ``C_D0`` past it (module notes).
    ``sin_alpha``, ``cos_alpha`` are passed in because callers have them from ``v_i`` already.
    """
    CL = lift_coefficient(alpha_rad, theta[I_CL0], theta[I_CL1])
    CD = drag_coefficient(alpha_rad, theta[I_CD0], theta[I_CD1], theta[I_CD2])
    sigma, _ = stall_weight(alpha_rad, model[M_ALPHA_LO], model[M_ALPHA_HI], model[M_INV_BLEND])
    if sigma > 0.0:
        CN = theta[I_CL1] * INV_PI * sin_alpha
        CL = (1.0 - sigma) * CL + sigma * CN * cos_alpha
        CD = (1.0 - sigma) * CD + sigma * (theta[I_CD0] + CN * sin_alpha)
    return CL, CD


@njit(cache=True)
def thruster_force_at(u_x, u_z, theta, G, cos_beta_bar, sin_beta_bar) -> tuple:
    """eq:fThat with the rotor flow already evaluated: ``G`` the side-force basis
    (:func:`side_force_basis`) and the in-plane flow direction ``(cos beta_bar, sin beta_bar)``
    (:func:`rotor_flow_angles`); :func:`thruster_force` evaluates them from ``v_i``."""
    FS = theta[I_CS] * G
    return (thrust(u_x, theta[I_CTX]) - FS * cos_beta_bar, -FS * sin_beta_bar, -thrust(u_z, theta[I_CTZ]))


@njit(cache=True)
def thruster_force(v_i_B, u_x, u_z, theta, model, out=None) -> tuple:
    """Estimated thruster force f_T-hat per unit mass (eq:fThat): ``(f_x, f_y, f_z)``, also into ``out`` if given."""
    V = np.sqrt(v_i_B[0] ** 2 + v_i_B[1] ** 2 + v_i_B[2] ** 2)
    alpha_disk, cb, sb = rotor_flow_angles(v_i_B)
    f = thruster_force_at(u_x, u_z, theta, side_force_basis(alpha_disk, V, u_z, model[M_K1], model[M_K2]), cb, sb)
    if out is not None:
        out[0], out[1], out[2] = f
    return f


FLOW = BlockLayout("the incident_flow tuple", [
    Field("V", 1, "m/s", "airspeed"),
    Field("ALPHA", 1, "rad", "angle of attack"),
    Field("SIN_ALPHA", 1, "-", "its sine"),
    Field("COS_ALPHA", 1, "-", "its cosine"),
    Field("Q", 1, "m/s^2", "the wing's dynamic pressure per unit mass (wing_pressure)"),
    Field("SIGMA", 1, "-", "the stall weight (stall_weight)"),
    Field("ALPHA_DISK", 1, "rad", "the rotor disk's angle of attack (rotor_flow_angles)"),
    Field("COS_BETA_BAR", 1, "-", "cosine of the rotor flow's azimuth"),
    Field("SIN_BETA_BAR", 1, "-", "its sine"),
])
"""The entries of the :func:`incident_flow` tuple."""
FLOW_SIZE = FLOW.size
(F_V, F_ALPHA, F_SIN_ALPHA, F_COS_ALPHA, F_Q, F_SIGMA, F_ALPHA_DISK, F_COS_BETA_BAR,
 F_SIN_BETA_BAR) = FLOW.offsets(*(f.name for f in FLOW.fields))


@njit(cache=True)
def incident_flow(v_i_B, model) -> tuple:
    """Everything the force model evaluates from the incident velocity alone, as a tuple (indices ``F_*``).

    ``(V, alpha, sin alpha, cos alpha, q, sigma, alpha_disk, cos beta_bar, sin beta_bar)``: airspeed
    (m/s), angle of attack (rad) with its sine and cosine, the wing's dynamic pressure per unit mass
    (:func:`wing_pressure`), the stall weight (:func:`stall_weight`) and the rotor flow
    (:func:`rotor_flow_angles`). The controller evaluates it once per tick and hands it to the
    regressor and the allocation (:func:`regressor_at`, :func:`aero_force_at`), which would otherwise
    each take the square roots and arctangents again.
    """
    vx, vy, vz = v_i_B[0], v_i_B[1], v_i_B[2]
    V2 = vx * vx + vy * vy + vz * vz   # summed in this order: bit for bit the paper's model
    r2 = vx * vx + vz * vz
    r = np.sqrt(r2)
    alpha = np.arctan2(vz, vx)
    # sin/cos of alpha from the components avoids a trig call and is exact at r > 0.
    sa, ca = (vz / r, vx / r) if r > 0.0 else (0.0, 1.0)
    alpha_disk, cb, sb = rotor_flow_angles(v_i_B)
    q = wing_pressure(V2, r2, model[M_AERO_SCALE], model[M_INV_COS2_SIDESLIP])
    sigma, _ = stall_weight(alpha, model[M_ALPHA_LO], model[M_ALPHA_HI], model[M_INV_BLEND])
    return (np.sqrt(V2), alpha, sa, ca, q, sigma, alpha_disk, cb, sb)


@njit(cache=True)
def aero_force_at(flow, theta) -> tuple:
    """:func:`aero_force` at an evaluated :func:`incident_flow`: ``(f_x, f_y, f_z)`` per unit mass."""
    alpha, sa, ca, q, sigma = flow[F_ALPHA], flow[F_SIN_ALPHA], flow[F_COS_ALPHA], flow[F_Q], flow[F_SIGMA]
    CL = lift_coefficient(alpha, theta[I_CL0], theta[I_CL1])
    CD = drag_coefficient(alpha, theta[I_CD0], theta[I_CD1], theta[I_CD2])
    # the polar weighted by w = 1 - sigma (C_D0 kept whole) and the plate's normal force along -z,
    # grouped as the regressor's columns are; with sigma = 0 every step is exact (1 * x, x + 0 * y,
    # x - 0), so inside the range this is the paper's model bit for bit
    w = 1.0 - sigma
    CL = w * CL
    CD = w * CD + sigma * theta[I_CD0]
    N = sigma * theta[I_CL1] * INV_PI * sa
    return (q * (CL * sa - CD * ca), 0.0, q * (-CL * ca - CD * sa) - q * N)


@njit(cache=True)
def aero_force(v_i_B, theta, model, out=None) -> tuple:
    """Estimated wing force f_A-hat per unit mass (eq:fAhat, divided by mass): ``(f_x, f_y, f_z)``.

    Also written into ``out`` if given. The side-force coefficient is the model's ``C_Y = 0``
    (the controller keeps beta = 0). Outside the attached-flow range and past 30 deg of sideslip
    the coefficients and the dynamic pressure continue as in the module notes.
    """
    f = aero_force_at(incident_flow(v_i_B, model), theta)
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
def regressor_at(flow, u_x, u_z, k1, k2) -> tuple:
    """:func:`regressor` at an evaluated :func:`incident_flow` (side-force constants ``k1``, ``k2``): three rows of 8."""
    alpha, sa, ca, q, sigma = flow[F_ALPHA], flow[F_SIN_ALPHA], flow[F_COS_ALPHA], flow[F_Q], flow[F_SIGMA]
    cb, sb = flow[F_COS_BETA_BAR], flow[F_SIN_BETA_BAR]
    G = side_force_basis(flow[F_ALPHA_DISK], flow[F_V], u_z, k1, k2)
    # drag acts along -x_i = -(cos a, 0, sin a) with C_D0, C_D1 alpha, C_D2 alpha^2;
    # lift along (sin a, 0, -cos a) with C_L0, C_L1 alpha; past stall the polar terms are weighted
    # by w = 1 - sigma (w = 1 exactly inside the range, so these are the paper's columns bit for bit)
    w = 1.0 - sigma
    qw = q * w
    b1 = w * alpha
    b2 = w * (alpha * alpha)
    # the plate's normal force (C_L1 / pi) sin(a) along body -z: lift cos a and drag sin a of it
    n_z = -q * sigma * INV_PI * sa
    return ((u_x * u_x, 0.0, -G * cb, -q * ca, -q * b1 * ca, -q * b2 * ca, qw * sa, q * b1 * sa),
            (0.0, 0.0, -G * sb, 0.0, 0.0, 0.0, 0.0, 0.0),
            (0.0, -u_z * u_z, 0.0, -q * sa, -q * b1 * sa, -q * b2 * sa, -qw * ca, -q * b1 * ca + n_z))


@njit(cache=True)
def regressor(v_i_B, u_x, u_z, model, Phi=None) -> tuple:
    """The regressor ``Phi(v_i, u_x, u_z)`` (3x8) with ``f_b-hat = Phi theta``.

    Returns the three rows (x, y, z) as tuples of 8, and writes them into the (3, 8) array ``Phi``
    if given. Columns follow ``theta = [CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1]`` (the paper's
    order). This one function serves control, adaptation and fitting. Past stall the polar's
    columns fade with ``1 - sigma`` and the C_L1 column gains the flat plate's normal force along
    body -z (module notes).
    """
    rows = regressor_at(incident_flow(v_i_B, model), u_x, u_z, model[M_K1], model[M_K2])
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

    Exact where the model is smooth (``V > 0``, in-plane flow ``> 0``, ``u_z > 0``, chordwise flow
    ``> 0``, ``|beta| != 30 deg``), including the stall continuation; it is checked against finite
    differences in the tests.
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
    # wing: f = q(v) [CL sa - CD ca, 0, -CL ca - CD sa], q = s V^2 phi(p), CL and CD functions of alpha
    r2 = vx * vx + vz * vz
    if r2 > 0.0:
        r = np.sqrt(r2)
        alpha = np.arctan2(vz, vx)
        sa, ca = vz / r, vx / r
        CL0, CL1 = theta[I_CL0], theta[I_CL1]
        CD0, CD1, CD2 = theta[I_CD0], theta[I_CD1], theta[I_CD2]
        CL = lift_coefficient(alpha, CL0, CL1)
        CD = drag_coefficient(alpha, CD0, CD1, CD2)
        dCL = CL1
        dCD = CD1 + 2.0 * CD2 * alpha
        sigma, dsigma = stall_weight(alpha, model[M_ALPHA_LO], model[M_ALPHA_HI], model[M_INV_BLEND])
        if sigma > 0.0:
            kN = CL1 * INV_PI
            CN = kN * sa
            CLp, CDp = CN * ca, CD0 + CN * sa
            dCLp, dCDp = kN * (ca * ca - sa * sa), 2.0 * kN * sa * ca
            dCL = (1.0 - sigma) * dCL + sigma * dCLp + dsigma * (CLp - CL)
            dCD = (1.0 - sigma) * dCD + sigma * dCDp + dsigma * (CDp - CD)
            CL = (1.0 - sigma) * CL + sigma * CLp
            CD = (1.0 - sigma) * CD + sigma * CDp
        fx = CL * sa - CD * ca
        fz = -CL * ca - CD * sa
        dfx = dCL * sa + CL * ca - dCD * ca + CD * sa
        dfz = -dCL * ca + CL * sa - dCD * sa - CD * ca
        # d q / d v and q / r^2 (which multiplies d alpha / d v = (-vz, 0, vx) / r^2), the latter
        # formed without dividing by a tiny r^2: it is at most s / cos^2(30 deg)
        kc = model[M_INV_COS2_SIDESLIP]
        if r2 * kc < V2:
            # q = s kc r^2 (past 30 deg of sideslip)
            q_r2 = s * kc
            dq = (2.0 * s * kc * vx, 0.0, 2.0 * s * kc * vz)
        else:
            q_r2 = s * (V2 / r2)
            dq = (2.0 * s * vx, 2.0 * s * vy, 2.0 * s * vz)
        dalpha_r2 = (-vz, 0.0, vx)
        for j in range(3):
            J_v[0, j] += dq[j] * fx + q_r2 * dfx * dalpha_r2[j]
            J_v[2, j] += dq[j] * fz + q_r2 * dfz * dalpha_r2[j]
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
