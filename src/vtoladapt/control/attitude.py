"""Desired attitude: the wing solution (eq:fbar_solve, eq:alphad, eq:Rd) blended with hover.

The wing solution (paper, "Desired Attitude Determination")
------------------------------------------------------------
With the body-frame force command ``f_rb = R^T f_r`` and the measured incident velocity ``v_i``,
the incident-wind axes are ``x_i = v_i/|v_i|``, ``y_i = v_i x f_rb / |v_i x f_rb|``,
``z_i = x_i x y_i``; the wing supplies the force along ``-z_i`` by the angle of attack ``alpha_d``
of eq:alphad, and ``R_d = R R_i R_alpha`` (eq:Rd). ``R R_i`` depends only on world quantities
(its columns are ``R x_i``, ``R y_i``, ``R z_i``, and ``R v_i`` is the air-relative velocity in NED),
so it is computed in the world frame: the result does not depend on how the current attitude
``R`` is parametrised. ``R_alpha`` is the rotation about ``y_i`` by ``+alpha_d``, so that in the
desired frame ``v_i = V (cos alpha_d, 0, sin alpha_d)``: angle of attack ``alpha_d``, sideslip 0.

By construction ``-f_rb . z_i = |f_rb x x_i| >= 0``: the lift demanded is the part of the force
command normal to the airflow, and the wing is rolled so its lift points that way (upright
whenever the command has an upward component normal to the flow, i.e. whenever the commanded
acceleration is below 1 g).

eq:alphad with the model's per-unit-mass lift ``L = (rho S / 2m) V^2 (C_L0 + C_L1 alpha)``:
``L_0 = (rho S/2m) V^2 C_L0``, ``L_1 = (rho S/2m) V^2 C_L1`` (the paper's L_0, L_1 divided by the
mass, as f_b is). alpha_d is saturated on both sides: ``alpha_max`` above ``L_max = L_0 + L_1
alpha_max`` (the paper) and ``alpha_min`` below ``L_min = L_0 + L_1 alpha_min`` (the paper is
silent; the force the wing cannot supply is left to the thrusters, eq:f_proj, and reported as the
allocation residual).

Where the wing solution is undefined
------------------------------------
* **v_i parallel to f_rb** (or f_r = 0): with ``n = |x_i x f_r|`` (the force normal to the flow)
  below ``eta = 1e-3 m/s^2``, ``y_i = normalise(x_i x f_r + (eta - n) y_fb)``, where ``y_fb`` is the
  previous ``y_i`` (projected normal to ``x_i``), else the upright right-wing axis ``e_D x x_i``,
  else the reference heading's right axis. This is continuous in the inputs, is exactly the
  paper's ``y_i`` whenever ``n >= eta``, and never divides by zero.
* **Low airspeed.** Below ``V_lo`` the desired attitude is the multirotor solution: body ``-z``
  along ``f_r`` (tilt limited, with at least ``min_lift`` upward so that f_r = 0 or a downward
  command still gives an upright attitude), heading from the reference yaw. Between ``V_lo`` and
  ``V_hi`` (``vehicle.envelope.hover_blend_airspeed_mps``) the two solutions are slerped with the
  weight ``w = s^2 (3 - 2 s)``, ``s = (V - V_lo)/(V_hi - V_lo)``: C1 in V, no jump at either
  end. The multirotor solution's heading is the *commanded heading* below (not the reference
  yaw itself), and the wing weight is also multiplied by the heading alignment weight, so the two
  solutions slerped are never far apart in heading (never the 180 deg case).

Heading: weathervane into the wind, the reference yaw in hover
--------------------------------------------------------------
Why the side wind was bad (issue #11, from the logs of ``array_bearing_deg = 90``): the airflow
probe cannot measure a flow from the side or from behind; its calibration reports "invalid" and
a zero vector, exactly what it reports in still air (from behind, the centre port reads below
static pressure, q_inf < 0, which the calibration refuses). The front end took that for
still air (:mod:`.frontend`), so the controller flew the whole run as a multirotor facing north
with 85 deg of sideslip it did not know about: no wing, no turn into the wind, and every
adaptive law adapted on a regressor without the wind (the side force is in no column of Phi at
``v_i = 0``), hence worse than PID. Now:

* **Unseen flow** (:mod:`.frontend`): an invalid probe reading is taken as still air only while
  the body-horizontal prediction error is small (``unseen_flow_accel_mps2``): the model has no
  horizontal force in still air, the accelerometer feels the wind's.
* The **commanded heading** ``psi_c`` (state, :func:`heading_step`) approaches a target with a
  first-order lag (``heading_time_constant_s``), at most at ``heading_rate_max_degps``:
  the direction of the air-relative velocity ``atan2(v_i,E, v_i,N)`` (nose into the wind) while
  the horizontal airspeed is above the weathervane airspeed (``weathervane_airspeed_mps``, with
  hysteresis); while the probe cannot see the flow (unseen flow), the direction opposite to the
  unexplained horizontal force (``R e``, the model's force minus the measured: the drag points
  downwind) -- as PX4's weathervane turns into the direction it leans -- until the flow enters
  the probe's cone; otherwise the reference yaw (its own change passed through unfiltered, so a
  yaw ramp in hover is tracked without lag). ``psi_c`` is continuous in time whatever the target
  does; a target ~180 deg away keeps the direction of the turn under way.
* The multirotor solution holds the position at heading ``psi_c``: a multirotor holds station
  facing any way, so it carries the aircraft while the heading turns.
* The wing solution's weight is ``w(V) a(psi_c, v_i)``, ``a`` = :func:`heading_alignment_weight`:
  full once ``psi_c`` is within ``wing_heading_tolerance_deg[0]`` of the flow, none beyond
  ``[1]``. The wing is flown only once the nose points into the wind, and the slerp only ever
  joins solutions within ~30 deg of heading, so ``q_d`` is continuous in every input (wind
  direction, airspeed, heading) and never meets the 180 deg ambiguity.

Why weathervane rather than fly the wing sideways or hold the reference heading: eq:Rd flies
sideslip 0, so the wing needs the flow in the body x-z plane; held at the reference heading in
a side wind the aircraft gives up the wing's lift, flies large sideslip where neither the model
nor the probe works. In hover (below the weathervane airspeed) the reference yaw is honoured.

Lift-rotor reserve (not in the paper)
-------------------------------------
The aircraft has no control surfaces: every body moment comes from the lift rotors' differential
thrust, and rotors cannot push. eq:alphad gives the wing all the lift it can supply, so once the
wing alone can carry the weight (Caltech above ~9.5 m/s, PX4 above ~7.5 m/s at alpha_max) the
allocation's collective goes to 0 and any pitch or roll moment saturates the mixer, which then
drops yaw and lifts the collective on its own (envelope campaign, a fan step to 12.9 m/s: the mixer
saturated 47 % of the run, the sideslip that follows and the collective the mixer added were the
prediction error above 8 m/s). So eq:alphad is solved for the required lift minus
``lift_rotor_reserve_mps2``: the wing flies a lower alpha_d and the allocation (eq:f_proj, which
computes the wing's force at the measured flow) gives that much to the lift rotors, whose
collective then keeps moment authority. Where the wing at alpha_max lifts less than the required
lift minus the reserve (the Caltech aircraft below ~7.5 m/s with the default 5 m/s^2) alpha_d is
alpha_max either way and nothing changes. Measured (8 seeds per condition, composite law): with a
fan step to 12.9 m/s the mixer saturated 47 % of the run without the reserve, 22 % with 2.5 m/s^2,
3 % with 5 m/s^2, and the runs with every airspeed bin's p95 prediction error below 0.05 g went
from 0/8 to 1/8 and 6/8; on the PX4 airframe 0/8, 2/8, 7/8; on the paper's steps (to 9 m/s)
unchanged (8/8).

Flow-angle protection (the measured alpha kept below alpha_max)
---------------------------------------------------------------
eq:alphad limits the *desired* angle of attack. In the logs of the shipped comparison the
measured alpha sat at alpha_d = alpha_max = 12 deg on average, and turbulence and the attitude
loop's pitch error (the mixer saturates at 9 m/s) swung it by +-3 deg around that, so the true
alpha was above 12 deg half the flying time and reached 17-19 deg. The probe measures the
flown alpha, so the limit is closed around it here, in the reference shaping (before the
attitude loop and the allocation): the *guarded* alpha -- the measured alpha low-passed at
``alpha_protect_filter_hz`` (:func:`measured_angle_of_attack`) plus ``alpha_protect_sigmas``
standard deviations of its fluctuation about that (estimated over
``alpha_protect_spread_time_constant_s`` while the wing flies) -- minus ``alpha_max`` is
integrated (``alpha_protect_gain_per_s``, weighted by the wing weight, clipped at 0:
anti-windup) into a trim that lowers the alpha_d limit (:func:`alpha_protection_step`; the same
below ``alpha_min``). In steady turbulence the mean alpha settles ``n sigma`` below alpha_max;
what the wing no longer lifts, the allocation (eq:f_proj) gives to the lift rotors, since it
computes the aerodynamic force at the measured flow. Why here and not in the attitude loop or
the allocation: only the desired attitude sets alpha; an alpha term in the attitude loop would
fight R_d and change eq:m_ctrl, and the allocation cannot change alpha. The target is
``alpha_max`` (the vehicle file's ``[envelope] alpha_max_deg``, at most its believed stall minus
margin); gusts faster than the filter are what the margin is for. The controller never reads
the plant's stall angle.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..frames import rotmat_rows_to_quat


Y_REGULARISATION_MPS2 = 1e-3
"""eta of the y_i regularisation (m/s^2): below this normal force y_i leans on its fallback."""
V_WING_MIN_MPS = 1e-6
"""Below this airspeed ``x_i = v_i/|v_i|`` is not formed at all (the blend weight is 0 there anyway)."""


@njit(cache=True)
def hover_blend_weight(V: float, V_lo: float, V_hi: float) -> float:
    """Weight of the wing solution: 0 for ``V <= V_lo``, 1 for ``V >= V_hi``, smoothstep (C1) between."""
    if not V > V_lo:
        return 0.0
    if V >= V_hi:
        return 1.0
    s = (V - V_lo) / (V_hi - V_lo)
    return s * s * (3.0 - 2.0 * s)


@njit(cache=True)
def multirotor_attitude(f_r_W, yaw_rad, tilt_max_rad, min_lift_mps2) -> tuple:
    """Multirotor desired attitude ``R_d``: body ``-z`` along ``f_r``, heading from ``yaw_rad``.

    The upward part of ``f_r`` is at least ``min_lift_mps2`` and the tilt at most ``tilt_max_rad``
    (both continuous clamps), so the thrust axis is always well defined and upright. Returns
    ``R_d`` as three row 3-tuples.
    """
    up = max(-f_r_W[2], min_lift_mps2)
    hx = f_r_W[0]
    hy = f_r_W[1]
    h = np.sqrt(hx * hx + hy * hy)
    h_max = up * np.tan(tilt_max_rad)
    if h > h_max:
        s = h_max / h
        hx *= s
        hy *= s
    n = np.sqrt(hx * hx + hy * hy + up * up)
    b3x, b3y, b3z = -hx / n, -hy / n, up / n
    cy, sy = np.cos(yaw_rad), np.sin(yaw_rad)
    # b2 = b3 x x_c, x_c = (cos yaw, sin yaw, 0); |b3 x x_c| >= b3z >= cos(tilt_max) > 0
    b2x = -b3z * sy
    b2y = b3z * cy
    b2z = b3x * sy - b3y * cy
    m = np.sqrt(b2x * b2x + b2y * b2y + b2z * b2z)
    b2x /= m
    b2y /= m
    b2z /= m
    return ((b2y * b3z - b2z * b3y, b2x, b3x),
            (b2z * b3x - b2x * b3z, b2y, b3y),
            (b2x * b3y - b2y * b3x, b2z, b3z))


@njit(cache=True)
def _unit_normal_to(x, c0, c1, c2) -> tuple:
    """``(u, n)``: the part of ``c`` normal to unit ``x``, normalised if ``n`` (its norm) is > 0."""
    d = c0 * x[0] + c1 * x[1] + c2 * x[2]
    u0 = c0 - d * x[0]
    u1 = c1 - d * x[1]
    u2 = c2 - d * x[2]
    n = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    if n > 0.0:
        return (u0 / n, u1 / n, u2 / n), n
    return (u0, u1, u2), n


@njit(cache=True)
def incident_frame_W(x_i_W, f_r_W, y_prev_W, have_y_prev, yaw_rad) -> tuple:
    """World-frame incident-wind axes, the columns of ``R R_i`` (eq:Rd): ``(x_i, y_i, z_i)`` 3-tuples.

    ``x_i_W`` is the unit air-relative velocity in NED. ``y_i`` follows the paper
    (``v_i x f_rb`` normalised) with the regularisation of the module notes.
    """
    y_fb = (0.0, 0.0, 0.0)
    n = 0.0
    if have_y_prev:
        y_fb, n = _unit_normal_to(x_i_W, y_prev_W[0], y_prev_W[1], y_prev_W[2])
    if not n > 1e-3:
        # e_D x x_i: the right wing of an upright aircraft flying along x_i
        y_fb, n = _unit_normal_to(x_i_W, -x_i_W[1], x_i_W[0], 0.0)
    if not n > 1e-3:
        y_fb, n = _unit_normal_to(x_i_W, -np.sin(yaw_rad), np.cos(yaw_rad), 0.0)
    # x_i x f_r (= R (v_i x f_rb) / V); |x_i x f_r| is the force normal to the flow
    yx = x_i_W[1] * f_r_W[2] - x_i_W[2] * f_r_W[1]
    yy = x_i_W[2] * f_r_W[0] - x_i_W[0] * f_r_W[2]
    yz = x_i_W[0] * f_r_W[1] - x_i_W[1] * f_r_W[0]
    n_raw = np.sqrt(yx * yx + yy * yy + yz * yz)
    if n_raw < Y_REGULARISATION_MPS2:
        k = Y_REGULARISATION_MPS2 - n_raw
        yx += k * y_fb[0]
        yy += k * y_fb[1]
        yz += k * y_fb[2]
    m = np.sqrt(yx * yx + yy * yy + yz * yz)
    if m > 1e-12:
        yx /= m
        yy /= m
        yz /= m
    else:
        yx, yy, yz = y_fb[0], y_fb[1], y_fb[2]
    x_i = (x_i_W[0], x_i_W[1], x_i_W[2])
    z_i = (x_i_W[1] * yz - x_i_W[2] * yy, x_i_W[2] * yx - x_i_W[0] * yz, x_i_W[0] * yy - x_i_W[1] * yx)
    return x_i, (yx, yy, yz), z_i


@njit(cache=True)
def desired_angle_of_attack(lift_required_mps2, V, CL0, CL1, aero_scale_per_m, alpha_min_rad,
                            alpha_max_rad) -> float:
    """Desired angle of attack from the lift model (eq:alphad), saturated to ``[alpha_min, alpha_max]``.

    ``lift_required_mps2 = -f_rb . z_i`` (per unit mass); ``L_0 = (rho S/2m) V^2 C_L0`` and
    ``L_1 = (rho S/2m) V^2 C_L1`` are per unit mass like f_b.
    """
    q = aero_scale_per_m * V * V
    L0 = q * CL0
    L1 = q * CL1
    if not L1 > 1e-12:
        return alpha_max_rad if lift_required_mps2 > L0 else alpha_min_rad
    if lift_required_mps2 >= L0 + L1 * alpha_max_rad:
        return alpha_max_rad
    if lift_required_mps2 <= L0 + L1 * alpha_min_rad:
        return alpha_min_rad
    return (lift_required_mps2 - L0) / L1


@njit(cache=True)
def wing_attitude(v_i_W, f_r_W, CL0, CL1, aero_scale_per_m, alpha_min_rad, alpha_max_rad,
                  y_prev_W, have_y_prev, yaw_rad, lift_reserve_mps2=0.0) -> tuple:
    """Wing desired attitude ``R_d = R R_i R_alpha`` (eq:Rd, eq:alphad).

    Parameters
    ----------
    v_i_W : (3,) air-relative velocity ``R v_i`` in NED (m/s), ``|v_i_W| > 0``.
    f_r_W : (3,) force command per unit mass (m/s^2, NED).
    CL0, CL1 : lift coefficients (the current theta-hat).
    aero_scale_per_m : ``rho S / (2 m)`` (1/m).
    alpha_min_rad, alpha_max_rad : saturation of alpha_d.
    y_prev_W, have_y_prev : previous ``y_i`` (NED) for the degenerate case.
    yaw_rad : reference heading, last fallback for ``y_i``.
    lift_reserve_mps2 : lift (per unit mass) left to the lift rotors: eq:alphad is solved for
        ``lift - lift_reserve`` (module notes, "Lift-rotor reserve"); 0: the paper's eq:alphad.

    Returns
    -------
    (R_d, alpha_d_rad, lift_required_mps2)
        ``R_d`` as three row 3-tuples.
    """
    V = np.sqrt(v_i_W[0] ** 2 + v_i_W[1] ** 2 + v_i_W[2] ** 2)
    x = (v_i_W[0] / V, v_i_W[1] / V, v_i_W[2] / V)
    x_i, y_i, z_i = incident_frame_W(x, f_r_W, y_prev_W, have_y_prev, yaw_rad)
    lift = -(f_r_W[0] * z_i[0] + f_r_W[1] * z_i[1] + f_r_W[2] * z_i[2])
    alpha_d = desired_angle_of_attack(lift - lift_reserve_mps2, V, CL0, CL1, aero_scale_per_m, alpha_min_rad,
                                      alpha_max_rad)
    ca, sa = np.cos(alpha_d), np.sin(alpha_d)
    # R_alpha = R_y(alpha_d): columns (ca, 0, -sa), (0, 1, 0), (sa, 0, ca)
    R_d = ((ca * x_i[0] - sa * z_i[0], y_i[0], sa * x_i[0] + ca * z_i[0]),
           (ca * x_i[1] - sa * z_i[1], y_i[1], sa * x_i[1] + ca * z_i[1]),
           (ca * x_i[2] - sa * z_i[2], y_i[2], sa * x_i[2] + ca * z_i[2]))
    return R_d, alpha_d, lift


@njit(cache=True)
def quat_slerp(qa, qb, w) -> tuple:
    """Spherical interpolation from unit ``qa`` (w = 0) to ``qb`` (w = 1), the short way (4-tuple)."""
    d = qa[0] * qb[0] + qa[1] * qb[1] + qa[2] * qb[2] + qa[3] * qb[3]
    sgn = 1.0
    if d < 0.0:
        d = -d
        sgn = -1.0
    if d > 0.9995:
        # nearly equal: normalised lerp is exact to 1e-7 and avoids 0/0
        ka = 1.0 - w
        kb = sgn * w
    else:
        th = np.arccos(min(d, 1.0))
        s = np.sin(th)
        ka = np.sin((1.0 - w) * th) / s
        kb = sgn * np.sin(w * th) / s
    o0 = ka * qa[0] + kb * qb[0]
    o1 = ka * qa[1] + kb * qb[1]
    o2 = ka * qa[2] + kb * qb[2]
    o3 = ka * qa[3] + kb * qb[3]
    n = np.sqrt(o0 * o0 + o1 * o1 + o2 * o2 + o3 * o3)
    o0, o1, o2, o3 = o0 / n, o1 / n, o2 / n, o3 / n
    if o0 < 0.0:
        return (-o0, -o1, -o2, -o3)
    return (o0, o1, o2, o3)


@njit(cache=True)
def desired_attitude(f_r_W, v_i_W, yaw_rad, CL0, CL1, aero_scale_per_m, alpha_min_rad, alpha_max_rad,
                     V_lo, V_hi, tilt_max_rad, min_lift_mps2, y_prev_W, have_y_prev, cos_align_full=-2.0,
                     cos_align_zero=-3.0, lift_reserve_mps2=0.0) -> tuple:
    """Desired attitude ``q_d`` (scalar first) blending the multirotor and the wing solutions.

    See the module notes. ``yaw_rad`` is the commanded heading (the multirotor solution's
    heading, :func:`heading_step`); the wing weight is the airspeed blend times
    :func:`heading_alignment_weight` with ``cos_align_full``, ``cos_align_zero`` (the defaults,
    below -1, make the alignment weight 1 whatever the heading); ``lift_reserve_mps2``: see
    :func:`wing_attitude`.

    Returns
    -------
    (q_d, y_i_W, alpha_d_rad, blend_weight, wing_formed)
        ``q_d`` (4-tuple); the wing solution's ``y_i`` (NED 3-tuple, to be passed back as
        ``y_prev_W`` next tick; zeros if not formed); ``alpha_d`` of the wing solution (0 if not
        formed); the wing weight in [0, 1]; and whether the wing solution was formed
        (``V > 1e-6 m/s``).
    """
    V = np.sqrt(v_i_W[0] ** 2 + v_i_W[1] ** 2 + v_i_W[2] ** 2)
    return desired_attitude_aligned(f_r_W, v_i_W, V, yaw_rad, CL0, CL1, aero_scale_per_m, alpha_min_rad,
                                    alpha_max_rad, V_lo, V_hi, tilt_max_rad, min_lift_mps2, y_prev_W, have_y_prev,
                                    heading_alignment_weight(v_i_W, yaw_rad, cos_align_full, cos_align_zero),
                                    lift_reserve_mps2)


@njit(cache=True)
def desired_attitude_aligned(f_r_W, v_i_W, V, yaw_rad, CL0, CL1, aero_scale_per_m, alpha_min_rad, alpha_max_rad,
                             V_lo, V_hi, tilt_max_rad, min_lift_mps2, y_prev_W, have_y_prev, alignment,
                             lift_reserve_mps2) -> tuple:
    """:func:`desired_attitude` with ``V = |v_i_W|`` and the :func:`heading_alignment_weight` at
    ``yaw_rad`` (``alignment``, read only where the airspeed blend is nonzero) already evaluated: the
    controller's back end needs them for the flow-angle protection too."""
    w = hover_blend_weight(V, V_lo, V_hi)
    if w > 0.0:
        w *= alignment
    alpha_d = 0.0
    formed = V > V_WING_MIN_MPS
    q_w = (1.0, 0.0, 0.0, 0.0)
    y_i = (0.0, 0.0, 0.0)
    if formed:
        R_w, alpha_d, _ = wing_attitude(v_i_W, f_r_W, CL0, CL1, aero_scale_per_m, alpha_min_rad,
                                        alpha_max_rad, y_prev_W, have_y_prev, yaw_rad, lift_reserve_mps2)
        y_i = (R_w[0][1], R_w[1][1], R_w[2][1])
        q_w = rotmat_rows_to_quat(R_w)
    if w >= 1.0:
        return q_w, y_i, alpha_d, w, formed
    q_mc = rotmat_rows_to_quat(multirotor_attitude(f_r_W, yaw_rad, tilt_max_rad, min_lift_mps2))
    if w <= 0.0:
        return q_mc, y_i, alpha_d, w, formed
    return quat_slerp(q_mc, q_w, w), y_i, alpha_d, w, formed


@njit(cache=True)
def smoothstep(x) -> float:
    """``s^2 (3 - 2 s)`` of ``s = clip(x, 0, 1)``: C1, 0 at and below 0, 1 at and above 1 (NaN: 0)."""
    if not x > 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    return x * x * (3.0 - 2.0 * x)


@njit(cache=True)
def heading_alignment_weight(v_i_W, heading_rad, cos_full, cos_zero) -> float:
    """How far the wing solution may take over at heading ``heading_rad``: 0 to 1, continuous.

    ``c = (cos psi, sin psi, 0) . v_i/|v_i|`` is the cosine of the angle between the commanded
    heading and the air-relative velocity (horizontal flow: the heading error; steep flow: less).
    The weight is ``smoothstep((c - cos_zero) / (cos_full - cos_zero))``: 1 when the heading is
    within the first tolerance of the flow, 0 beyond the second, so the wing solution (which
    faces the flow) is only ever slerped with a multirotor solution of nearly the same heading.
    ``cos_full <= cos_zero`` (or ``cos_full < -1``): 1 (no alignment required).
    """
    if not cos_full > cos_zero or cos_full < -1.0:
        return 1.0
    V = np.sqrt(v_i_W[0] ** 2 + v_i_W[1] ** 2 + v_i_W[2] ** 2)
    if not V > V_WING_MIN_MPS:
        return 0.0
    c = (np.cos(heading_rad) * v_i_W[0] + np.sin(heading_rad) * v_i_W[1]) / V
    return smoothstep((c - cos_zero) / (cos_full - cos_zero))


HEADING_REVERSAL_RAD = np.radians(150.0)
"""A heading error larger than this keeps the direction of the turn already under way."""


@njit(cache=True)
def heading_step(heading_rad, turn_sign, target_rad, feedforward_rad, dt, time_constant_s,
                 rate_max_radps) -> tuple:
    """One tick of the commanded heading: first order toward ``target_rad``, rate limited.

    ``heading + feedforward`` (the reference yaw's own change, passed through unfiltered so that
    a yaw ramp is tracked without lag) moves toward the target by ``e dt/(tau + dt)``, at most
    ``rate_max dt``, with ``e`` the wrapped error. A target about 180 deg away (the wind from
    behind) would flip the turn's direction with every small change of the flow direction:
    beyond :data:`HEADING_REVERSAL_RAD` the turn already under way (``turn_sign``) is kept.
    The heading is continuous in time whatever the target does (it moves at most
    ``|feedforward| + rate_max dt`` per tick).

    Returns ``(heading_rad in [-pi, pi], turn_sign in {-1, 0, 1})``.
    """
    h = heading_rad + feedforward_rad
    e = target_rad - h
    e = np.arctan2(np.sin(e), np.cos(e))
    if abs(e) > HEADING_REVERSAL_RAD and turn_sign * e < 0.0:
        e += 2.0 * np.pi * turn_sign
    step = e * dt / (time_constant_s + dt)
    lim = rate_max_radps * dt
    step = min(max(step, -lim), lim)
    sign = 0.0
    if e > 0.0:
        sign = 1.0
    elif e < 0.0:
        sign = -1.0
    h += step
    return np.arctan2(np.sin(h), np.cos(h)), sign


ALPHA_EXCESS_MAX_RAD = np.radians(10.0)
"""The measured excess over an alpha limit integrated per tick is clipped to this (probe outliers,
backward flow)."""


@njit(cache=True)
def measured_angle_of_attack(v_i_B) -> float:
    """``atan2(v_iz, max(v_ix, 0))`` (rad): the probe's alpha, held within +-90 deg in backward flow."""
    return np.arctan2(v_i_B[2], max(v_i_B[0], 0.0))


@njit(cache=True)
def alpha_protection_step(trim_hi, trim_lo, alpha_meas_rad, alpha_min_rad, alpha_max_rad, weight, gain_per_s,
                          dt, trim_max_rad, spread_rad=0.0) -> tuple:
    """One tick of the flow-angle protection: the trims that move the alpha_d limits (rad).

    ``trim_hi >= 0`` integrates the excess of the measured (filtered) alpha plus ``spread_rad``
    (its upper envelope: n standard deviations of the measured fluctuation) over ``alpha_max``,
    ``trim_lo <= 0`` the excess of the alpha minus ``spread_rad`` below ``alpha_min``, each at
    ``gain_per_s`` times the wing weight
    (the protection acts through alpha_d, which only the wing solution flies) and each clipped to
    ``[0, trim_max]`` (anti-windup: back to 0 once the measured alpha is inside). Off the wing
    (weight < 1) they also leak toward 0 at ``(1 - weight) gain``, so a trim learned in one wind
    does not outlive it. The limits flown are ``alpha_max - trim_hi`` and ``alpha_min - trim_lo``.
    """
    e_hi = min(max(alpha_meas_rad + spread_rad - alpha_max_rad, -ALPHA_EXCESS_MAX_RAD), ALPHA_EXCESS_MAX_RAD)
    e_lo = min(max(alpha_meas_rad - spread_rad - alpha_min_rad, -ALPHA_EXCESS_MAX_RAD), ALPHA_EXCESS_MAX_RAD)
    k = gain_per_s * dt
    trim_hi += k * (weight * e_hi - (1.0 - weight) * trim_hi)
    trim_lo += k * (weight * e_lo - (1.0 - weight) * trim_lo)
    return min(max(trim_hi, 0.0), trim_max_rad), min(max(trim_lo, -trim_max_rad), 0.0)


@njit(cache=True)
def desired_frame_rate(q_prev, q_now, dt) -> tuple:
    """Mean rate of the desired frame over a tick, in the desired frame: ``log(R_prev^T R_now) / dt`` (3-tuple)."""
    # q_e = q_prev^* q_now
    a0, a1, a2, a3 = q_prev[0], -q_prev[1], -q_prev[2], -q_prev[3]
    b0, b1, b2, b3 = q_now[0], q_now[1], q_now[2], q_now[3]
    e0 = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
    e1 = a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2
    e2 = a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1
    e3 = a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0
    if e0 < 0.0:
        e0, e1, e2, e3 = -e0, -e1, -e2, -e3
    s = np.sqrt(e1 * e1 + e2 * e2 + e3 * e3)
    if s < 1e-12:
        k = 2.0 / dt
    else:
        k = 2.0 * np.arctan2(s, e0) / s / dt
    return (k * e1, k * e2, k * e3)


__all__ = ["alpha_protection_step", "desired_angle_of_attack", "desired_attitude", "desired_attitude_aligned",
           "desired_frame_rate", "heading_alignment_weight", "heading_step", "hover_blend_weight", "incident_frame_W",
           "measured_angle_of_attack", "multirotor_attitude", "quat_slerp", "smoothstep", "wing_attitude"]
