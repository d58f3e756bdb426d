"""The controller's force model at every flow angle (issue #11 item 2), against independent checks.

References and tolerances
-------------------------
* ``paper_force``: the paper's polars and thrust model (eq:model_Txz, eq:model_FS, eq:model_cl,
  eq:model_cd, eq:fThat, eq:fAhat / m) written out with ``math``: inside the attached-flow range
  (``|alpha| <= stall_angle_deg``, ``|beta| <= 30 deg``) the model must equal it, rel 1e-12 of the
  largest term.
* ``documented_wing_force``: the continuation as the module notes of :mod:`vtoladapt.forces` state
  it (smoothstep blend over 8 deg into a plate with ``C_N = (C_L1 / pi) sin alpha`` plus ``C_D0``;
  ``(v_ix^2 + v_iz^2) / cos^2 30 deg`` for V^2 past 30 deg of sideslip), with ``math.sin``/``math.cos`` of alpha rather than the
  kernels' ratios of components: rel 1e-12 of the dynamic pressure times the largest coefficient.
* ``Phi theta == f_b-hat`` at random theta and any v_i: ``|Phi theta - f| <= 1e-12 |Phi| |theta|``.
* Continuity: ``|f(v + dv) - f(v)| <= L(V) |dv|`` for ``|dv| = 1e-7 (1 + V)`` with the bound derived
  from the model's form (see :func:`wing_lipschitz_bound`): ``L = (s V_max / c2) [2 C + (C + D)]``,
  ``s = rho S / (2 m)``, ``c2 = cos^2 30 deg``, ``C`` a bound on |C_L| + |C_D| and ``D`` on
  their alpha-slopes over the whole circle. The old model's jumps (12 m/s^2 across alpha = +-pi at
  3 m/s, 160 m/s^2 across the spanwise direction at 10 m/s) exceed it by a factor of 1e6 or more
  (checked, so that the test can fail).
* Rotor side force near axial flow: ``|F_S| <= C_S u^k1 V^(1-k1) (pi/2)(pi^2/4 + ...)`` -> 0 with the
  in-plane speed h (bound from eq:model_Fs with ``pi/2 - |alpha_disk| <= (pi/2) h / V``).
* Backward flow, alpha = pi: the wing gives exactly ``s V^2 C_D0`` along ``-v_i`` and nothing else
  (a plate edge-on to the flow); past the blend the wing force never does positive work on the
  airflow (``f . v_i <= 0``), and at alpha = 90 deg the normal-force coefficient ``C_L1 / pi`` lies
  within a factor 2 of Viterna and Corrigan's flat-plate ``C_Dmax = 1.11 + 0.018 AR``.
* Jacobian against central finite differences (step 1e-5 m/s) in the blend, past stall, in backward
  flow and past 30 deg of sideslip: max error <= 1e-5 max|J| + 1e-7.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from conftest import examples
from vtoladapt import forces, load_vehicle, models
from vtoladapt.fitting import tunnel

VEHICLES = {name: load_vehicle(name) for name in ("caltech_vtol", "px4_standard_vtol")}
CALTECH = VEHICLES["caltech_vtol"]
COS2_LIN = math.cos(math.radians(30.0)) ** 2
BLEND_RAD = math.radians(8.0)

vehicle_name = st.sampled_from(sorted(VEHICLES))
theta_factors = st.lists(st.floats(-2.0, 2.0), min_size=8, max_size=8)
unit = st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)).filter(
    lambda d: 1e-3 < math.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2))


def on_sphere(radius: float, d) -> np.ndarray:
    """The point at ``radius`` in the direction ``d`` (any nonzero 3-vector)."""
    d = np.asarray(d, float)
    return radius * d / np.linalg.norm(d)


def from_angles(V: float, alpha_rad: float, beta_rad: float = 0.0) -> np.ndarray:
    """``v_i = V [cos a cos b, sin b, sin a cos b]`` (eq:alphabeta)."""
    return V * np.array([math.cos(alpha_rad) * math.cos(beta_rad), math.sin(beta_rad),
                         math.sin(alpha_rad) * math.cos(beta_rad)])


def paper_force(v, ux, uz, theta_s, k1, k2, s):
    """f_b-hat from the paper's formulas (kernel scaling: throttle fractions, theta scaled)."""
    ctx, ctz, cs, cd0, cd1, cd2, cl0, cl1 = theta_s
    vx, vy, vz = v
    V = math.sqrt(vx * vx + vy * vy + vz * vz)
    h = math.hypot(vx, vy)
    a_disk = math.atan2(vz, h)
    G = uz**k1 * V ** (2 - k1) * ((math.pi / 2) ** 2 - a_disk**2) * (a_disk + k2) if uz > 0 and V > 0 else 0.0
    bb = math.atan2(vy, vx)
    a = math.atan2(vz, vx)
    CL = cl0 + cl1 * a
    CD = cd0 + cd1 * a + cd2 * a * a
    q = s * V * V
    return np.array([ctx * ux * ux - cs * G * math.cos(bb) + q * (CL * math.sin(a) - CD * math.cos(a)),
                     -cs * G * math.sin(bb),
                     -ctz * uz * uz + q * (-CL * math.cos(a) - CD * math.sin(a))])


def documented_wing_force(v, theta_s, s, stall_rad):
    """The wing force as the module notes of vtoladapt.forces describe it, with math.sin/cos."""
    _, _, _, cd0, cd1, cd2, cl0, cl1 = theta_s
    vx, vy, vz = v
    V2 = vx * vx + vy * vy + vz * vz
    r2 = vx * vx + vz * vz
    if r2 == 0.0:
        return np.zeros(3)
    a = math.atan2(vz, vx)
    sa, ca = math.sin(a), math.cos(a)
    t = min(1.0, max(0.0, (abs(a) - stall_rad) / BLEND_RAD))
    sigma = t * t * (3 - 2 * t)
    CN = cl1 / math.pi * sa
    CL = (1 - sigma) * (cl0 + cl1 * a) + sigma * CN * ca
    CD = (1 - sigma) * (cd0 + cd1 * a + cd2 * a * a) + sigma * (cd0 + CN * sa)
    q = s * min(V2, r2 / COS2_LIN)
    return np.array([q * (CL * sa - CD * ca), 0.0, q * (-CL * ca - CD * sa)])


def coefficient_bounds(theta_s, stall_rad):
    """``(C, D)``: bounds on |C_L| + |C_D| and on |dC_L/da| + |dC_D/da| over the whole circle.

    The polar terms act only for |alpha| <= stall + blend (a_m), with weight <= 1 and weight slope
    <= 1.5 / blend; the plate terms are |C_L1| / pi times sines and cosines (slopes <= 2 |C_L1| / pi).
    """
    _, _, _, cd0, cd1, cd2, cl0, cl1 = np.abs(theta_s)
    a_m = stall_rad + BLEND_RAD
    polar = cl0 + cl1 * a_m + cd0 + cd1 * a_m + cd2 * a_m * a_m
    plate = cd0 + 2 * cl1 / math.pi
    C = polar + plate
    D = (cl1 + cd1 + 2 * cd2 * a_m) + 2 * 2 * cl1 / math.pi + 1.5 / BLEND_RAD * (polar + plate)
    return C, D


def wing_lipschitz_bound(V_max, theta_s, vehicle):
    """``L`` with ``|f_A(v) - f_A(w)| <= L |v - w|`` on the ball ``|v| <= V_max`` (module docstring).

    ``|J| <= |grad q| |F| + (q / r) |F'|`` with ``F = (C_L sa - C_D ca, -C_L ca - C_D sa)``:
    ``q = s min(V^2, r^2 / c2)``, so ``|grad q| <= 2 s V / c2`` and ``q / r <= s r / c2 <= s V / c2``.
    """
    C, D = coefficient_bounds(theta_s, math.radians(vehicle.envelope.stall_angle_deg))
    s = vehicle.aero_scale_per_m
    return s * V_max / COS2_LIN * (2 * C + (C + D))


def wing(v, vehicle, theta_s=None):
    """The kernel's wing force (no thrust: throttles 0, so G = 0)."""
    theta = vehicle.theta_scaled if theta_s is None else theta_s
    out = np.empty(3)
    forces.aero_force(np.asarray(v, float), theta, vehicle.model_kernel, out)
    return out


# --- the defects, by number --------------------------------------------------------------
def test_backward_flow_at_3mps_is_cd0_drag_not_12mps2():
    """Issue #11: body_force([-3, 0, 0], 0, 50 %) gave +12 m/s^2 forward (alpha = pi in the polars)."""
    f = models.body_force([-3.0, 0.0, 0.0], 0.0, 50.0, CALTECH)
    fm = CALTECH.force_model
    s = CALTECH.aero_scale_per_m
    # rotor side force against the flow (eq:model_FS at alpha_disk = 0, beta_bar = pi) and C_D0 drag
    side = fm.CS * 50.0**fm.k1 * 3.0 ** (2 - fm.k1) * (math.pi / 2) ** 2 * fm.k2
    np.testing.assert_allclose(f, [s * 9.0 * fm.CD0 + side, 0.0, -fm.CTz * 50.0**2], rtol=1e-12)
    assert f[0] < 0.25


def test_backward_flow_is_continuous_across_alpha_pi():
    """Issue #11: +-0.3 m/s of v_iz in backward flow flipped f_z by about 12 m/s^2."""
    up = models.body_force([-3.0, 0.0, 0.3], 0.0, 50.0, CALTECH)
    down = models.body_force([-3.0, 0.0, -0.3], 0.0, 50.0, CALTECH)
    # what remains is odd in v_iz: the plate's normal force and C_D0 drag along -v_i,
    # 2 s V^2 sin(alpha) (C_L1 / pi + C_D0) with sin(alpha) = 0.3 / V
    s, V2 = CALTECH.aero_scale_per_m, 9.09
    fm = CALTECH.force_model
    plate = 2 * s * V2 * (0.3 / math.sqrt(V2)) * (fm.CL1 / math.pi + fm.CD0)
    assert abs(up[2] - down[2]) == pytest.approx(plate, rel=1e-12)
    assert np.linalg.norm(up - down) < 0.2
    eps = models.body_force([-3.0, 0.0, 1e-9], 0.0, 50.0, CALTECH) - \
        models.body_force([-3.0, 0.0, -1e-9], 0.0, 50.0, CALTECH)
    assert np.linalg.norm(eps) < 1e-8


# --- exactly the paper inside the attached-flow range --------------------------------------------
@settings(max_examples=examples(150), deadline=None)
@given(vehicle_name, st.floats(0.0, 30.0), st.floats(-1.0, 1.0), st.floats(-30.0, 30.0),
       st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.lists(st.floats(0.2, 2.0), min_size=8, max_size=8))
def test_inside_the_range_the_model_is_the_papers(name, V, alpha_frac, beta_deg, ux, uz, factors):
    veh = VEHICLES[name]
    stall = math.radians(veh.envelope.stall_angle_deg)
    v = from_angles(V, alpha_frac * stall, math.radians(beta_deg) * (1 - 1e-12))
    theta = veh.theta_scaled * np.asarray(factors)
    expected = paper_force(v, ux, uz, theta, veh.force_model.k1, veh.force_model.k2, veh.aero_scale_per_m)
    f = models.body_force(v, 100 * ux, 100 * uz, veh, theta_scaled=theta)
    Phi = models.regressor(v, 100 * ux, 100 * uz, veh)
    size = 1.0 + np.abs(Phi) @ np.abs(theta)
    np.testing.assert_allclose(f, expected, rtol=0, atol=1e-12 * size.max())
    # the regressor's wing columns are the paper's basis functions, column by column
    a = math.atan2(v[2], v[0])
    q = veh.aero_scale_per_m * V * V
    sa, ca = math.sin(a), math.cos(a)
    paper_cols = np.array([[-q * ca, -q * a * ca, -q * a * a * ca, q * sa, q * a * sa],
                           [0.0] * 5,
                           [-q * sa, -q * a * sa, -q * a * a * sa, -q * ca, -q * a * ca]])
    np.testing.assert_allclose(Phi[:, forces.I_CD0:], paper_cols, rtol=0, atol=1e-12 * (1 + q * 10))


def test_the_desired_angle_of_attack_range_lies_inside():
    """control/attitude.py inverts C_L0 + C_L1 alpha on [alpha_min, alpha_max]: the model agrees there."""
    for veh in VEHICLES.values():
        a_max = math.radians(veh.envelope.alpha_max_deg)
        for a in np.linspace(-a_max, a_max, 41):
            CL, CD = models.wing_coefficients(a, veh)
            fm = veh.force_model
            assert CL == pytest.approx(fm.CL0 + fm.CL1 * a, rel=1e-14, abs=1e-15)
            assert CD == pytest.approx(fm.CD0 + fm.CD1 * a + fm.CD2 * a * a, rel=1e-14, abs=1e-15)


def test_tunnel_design_wing_rows_lie_inside_the_range():
    """The virtual tunnel's wing sweep (the paper's Model Fitting) stays in the attached range, so
    fits of it are unchanged by the continuation."""
    pts = tunnel.design_points(tunnel.make_design())
    wing_alpha = pts["alpha_deg"][pts["wing_on"] & (pts["airspeed_mps"] > 0)]
    for veh in VEHICLES.values():
        assert np.all(np.abs(wing_alpha) <= veh.envelope.stall_angle_deg)
        assert np.all(np.abs(pts["beta_deg"][pts["wing_on"]]) <= 30.0)


# --- the documented continuation ------------------------------------------------------------------
@settings(max_examples=examples(200), deadline=None)
@given(vehicle_name, st.floats(0.0, 30.0), unit, st.lists(st.floats(0.2, 2.0), min_size=8, max_size=8))
def test_wing_matches_the_documented_continuation(name, radius, d, factors):
    veh = VEHICLES[name]
    v = on_sphere(radius, d)
    theta = veh.theta_scaled * np.asarray(factors)
    expected = documented_wing_force(v, theta, veh.aero_scale_per_m, math.radians(veh.envelope.stall_angle_deg))
    C, _ = coefficient_bounds(theta, math.radians(veh.envelope.stall_angle_deg))
    np.testing.assert_allclose(wing(v, veh, theta), expected, rtol=0,
                               atol=1e-12 * veh.aero_scale_per_m * radius**2 * C + 1e-300)


@settings(max_examples=examples(200), deadline=None)
@given(vehicle_name, st.one_of(st.just(0.0), st.floats(1e-150, 1e-3), st.floats(0.0, 30.0)), unit,
       st.floats(0.0, 1.0), st.floats(0.0, 1.0), theta_factors)
def test_regressor_times_theta_is_the_force_everywhere(name, radius, d, ux, uz, factors):
    veh = VEHICLES[name]
    v = on_sphere(radius, d)
    theta = veh.theta_scaled * np.asarray(factors)
    out = np.empty(3)
    forces.body_force(v, ux, uz, theta, veh.model_kernel, out)
    Phi = np.empty((3, forces.N_THETA))
    forces.regressor(v, ux, uz, veh.model_kernel, Phi)
    J_v, J_u = np.empty((3, 3)), np.empty((3, 2))
    forces.body_force_jacobian(v, ux, uz, theta, veh.model_kernel, J_v, J_u)
    assert np.all(np.isfinite(out)) and np.all(np.isfinite(Phi)) and np.all(np.isfinite(J_v))
    assert np.all(np.abs(Phi @ theta - out) <= 1e-12 * (np.abs(Phi) @ np.abs(theta)) + 1e-300)


# --- continuity ----------------------------------------------------------------------------------
@settings(max_examples=examples(300), deadline=None)
@given(vehicle_name, st.floats(0.0, 30.0), unit, unit, st.sampled_from(["any", "alpha_pi", "edge", "spanwise"]),
       st.floats(-1.0, 1.0))
def test_wing_force_is_lipschitz_everywhere(name, radius, d, dd, where, x):
    """Continuity over all of v_i, with points steered onto alpha = +-pi, the range edges and the
    spanwise direction (where alpha is undefined) as well as anywhere."""
    veh = VEHICLES[name]
    stall = math.radians(veh.envelope.stall_angle_deg)
    if where == "alpha_pi":
        v = from_angles(radius, math.pi + 1e-7 * x, 0.5 * x)
    elif where == "edge":
        edge = stall if x > 0 else -stall - BLEND_RAD
        v = from_angles(radius, edge + 1e-7 * x + (BLEND_RAD if abs(x) > 0.5 else 0.0), 0.3 * x)
    elif where == "spanwise":
        v = radius * np.array([1e-8 * x, math.copysign(1.0, x), 1e-8 * d[0]])
    else:
        v = on_sphere(radius, d)
    step = 1e-7 * (1.0 + radius)
    w = v + on_sphere(step, dd)
    L = wing_lipschitz_bound(radius + step, veh.theta_scaled, veh)
    assert np.linalg.norm(wing(w, veh) - wing(v, veh)) <= L * step * (1 + 1e-9) + 1e-300


def test_the_bound_sees_the_papers_jumps():
    """The continuity test can fail: the paper's polars, evaluated at any alpha, break the bound by
    orders of magnitude across alpha = +-pi and across the spanwise direction."""
    theta, s = CALTECH.theta_scaled, CALTECH.aero_scale_per_m
    k1, k2 = CALTECH.force_model.k1, CALTECH.force_model.k2
    for v, w in (([-3.0, 0.0, 1e-9], [-3.0, 0.0, -1e-9]), ([1e-9, 10.0, 0.0], [-1e-9, 10.0, 0.0])):
        v, w = np.array(v), np.array(w)
        jump = np.linalg.norm(paper_force(v, 0.0, 0.0, theta, k1, k2, s) - paper_force(w, 0.0, 0.0, theta, k1, k2, s))
        L = wing_lipschitz_bound(np.linalg.norm(v), theta, CALTECH)
        assert jump > 1e6 * L * np.linalg.norm(v - w)
        assert np.linalg.norm(wing(v, CALTECH) - wing(w, CALTECH)) <= L * np.linalg.norm(v - w)


@settings(max_examples=examples(200), deadline=None)
@given(vehicle_name, st.floats(0.5, 30.0), st.floats(1e-9, 1e-2), st.floats(-math.pi, math.pi),
       st.booleans(), st.floats(0.01, 1.0))
def test_rotor_side_force_vanishes_with_the_in_plane_flow(name, V, h_frac, bb, up, uz):
    veh = VEHICLES[name]
    k1, k2 = veh.force_model.k1, veh.force_model.k2
    h = h_frac * V
    v = np.array([h * math.cos(bb), h * math.sin(bb), math.copysign(math.sqrt(V * V - h * h), 1.0 if up else -1.0)])
    f = forces.thruster_force(v, 0.0, uz, veh.theta_scaled, veh.model_kernel)
    # |G| <= u^k1 V^(2-k1) (pi/2 - |a|)(pi/2 + |a|)(|a| + k2) with pi/2 - |a| <= (pi/2) h / V
    bound = veh.theta_scaled[forces.I_CS] * uz**k1 * V ** (2 - k1) * (math.pi / 2) * (h / V) * math.pi * (math.pi / 2 + k2)
    assert math.hypot(f[0], f[1]) <= bound * (1 + 1e-9)


@settings(max_examples=examples(200), deadline=None)
@given(vehicle_name, st.floats(0.0, 1e-2), unit, st.floats(0.0, 1.0), st.floats(0.0, 1.0))
@example("px4_standard_vtol", 2.9021757228920926e-14, (1.0, 0.0, 0.0), 1.0, 1.0)
def test_force_tends_to_thrust_as_airspeed_vanishes(name, radius, d, ux, uz):
    veh = VEHICLES[name]
    fm = veh.force_model
    v = on_sphere(radius, d)
    f = forces.body_force(v, ux, uz, veh.theta_scaled, veh.model_kernel)
    thrust = np.array([veh.theta_scaled[0] * ux * ux, 0.0, -veh.theta_scaled[1] * uz * uz])
    C, _ = coefficient_bounds(veh.theta_scaled, math.radians(veh.envelope.stall_angle_deg))
    side = veh.theta_scaled[forces.I_CS] * uz**fm.k1 * radius ** (2 - fm.k1) * (math.pi / 2) ** 2 * (math.pi / 2 + fm.k2)
    # componentwise: a 2-norm of numbers near 1e-160 loses its digits to underflow in the squares;
    # the force adds the aerodynamic terms to the thrust, so it is exact only to the thrust's last bits
    # (thorough search: 20.944 + 3e-15 of aero force rounded one ulp, 3.6e-15, away)
    rounding = 4 * np.finfo(float).eps * np.abs(thrust).max()
    assert np.abs(np.asarray(f) - thrust).max() <= veh.aero_scale_per_m * radius**2 * C + side + rounding + 1e-300


# --- physically sane past stall --------------------------------------------------------------------
@settings(max_examples=examples(150), deadline=None)
@given(vehicle_name, st.floats(0.1, 30.0), st.floats(-1.0, 1.0), st.floats(-89.0, 89.0))
def test_past_stall_the_wing_only_resists_the_flow(name, V, x, beta_deg):
    """With sigma = 1 the force is C_D0 drag along -v_i plus a plate normal force that does no
    positive work (f . v_i <= 0), and the drag part equals s V^2 phi C_D0 along the chordwise flow."""
    veh = VEHICLES[name]
    a_past = math.radians(veh.envelope.stall_angle_deg) + BLEND_RAD
    a = math.copysign(a_past + (math.pi - a_past) * abs(x), x)
    v = from_angles(V, a, math.radians(beta_deg))
    f = wing(v, veh)
    assert f @ v <= 1e-12 * np.linalg.norm(f) * V
    assert f[1] == 0.0


def test_backward_flow_is_cd0_drag_along_minus_v():
    for veh in VEHICLES.values():
        for V in (1.0, 3.0, 12.0):
            f = wing([-V, 0.0, 0.0], veh)
            np.testing.assert_allclose(f, [veh.aero_scale_per_m * V * V * veh.force_model.CD0, 0.0, 0.0],
                                       rtol=1e-14)


def test_vertical_flow_is_a_flat_plate():
    """alpha = 90 deg (vertical descent): normal force C_N = C_L1 / pi + C_D0 along -z, within a
    factor 2 of Viterna and Corrigan's C_Dmax = 1.11 + 0.018 AR; lift (along x) zero."""
    for veh in VEHICLES.values():
        V = 6.0
        f = wing([0.0, 0.0, V], veh)
        s = veh.aero_scale_per_m
        fm = veh.force_model
        np.testing.assert_allclose(f, [0.0, 0.0, -s * V * V * (fm.CL1 / math.pi + fm.CD0)], rtol=1e-12, atol=1e-12)
        AR = veh.geometry.wingspan_m**2 / veh.geometry.wing_area_m2
        CDmax = 1.11 + 0.018 * AR
        assert 0.5 * CDmax <= fm.CL1 / math.pi <= 2.0 * CDmax
        CL, CD = models.wing_coefficients(math.pi / 2, veh)
        assert abs(CL) < 1e-12 and abs(CD - (fm.CL1 / math.pi + fm.CD0)) < 1e-12


def test_lift_past_stall_is_far_below_the_polars_extrapolation():
    """At 30-90 deg the polar would give C_L up to 5.5 (Table I); the plate gives at most C_L1 / (2 pi)."""
    for veh in VEHICLES.values():
        fm = veh.force_model
        for deg in np.linspace(veh.envelope.stall_angle_deg + 8.0, 180.0, 60):
            CL, CD = models.wing_coefficients(math.radians(deg), veh)
            assert abs(CL) <= fm.CL1 / (2 * math.pi) + 1e-12
            assert fm.CD0 - 1e-12 <= CD <= fm.CD0 + fm.CL1 / math.pi + 1e-12


def test_spanwise_flow_gives_no_wing_force():
    """A wing edge-on to the flow (v_i along y) makes no force (C_Y = 0 as in the paper)."""
    for veh in VEHICLES.values():
        assert np.all(wing([0.0, 7.0, 0.0], veh) == 0.0)
        assert np.linalg.norm(wing([1e-6, 7.0, -1e-6], veh)) < 1e-9


# --- the Jacobian in the continuation ------------------------------------------------------------
def _fd(fun, v, h):
    J = np.empty((3, 3))
    for j in range(3):
        d = np.zeros(3)
        d[j] = h
        J[:, j] = (np.asarray(fun(v + d)) - np.asarray(fun(v - d))) / (2 * h)
    return J


@settings(max_examples=examples(150), deadline=None)
@given(vehicle_name, st.floats(1.0, 30.0), st.floats(0.0, 1.0), st.booleans(), st.floats(-85.0, 85.0),
       st.floats(0.0, 1.0), theta_factors)
def test_jacobian_matches_finite_differences_past_stall(name, V, x, neg, beta_deg, uz, factors):
    veh = VEHICLES[name]
    stall = math.radians(veh.envelope.stall_angle_deg)
    a = stall + (math.pi - stall) * x
    a = -a if neg else a
    # stay clear of the blend's ends and of the sideslip seam (C1 there, the second derivative jumps)
    for edge in (stall, stall + BLEND_RAD, math.pi):
        if abs(abs(a) - edge) < 1e-3:
            return
    if abs(abs(beta_deg) - 30.0) < 0.1:
        return
    v = from_angles(V, a, math.radians(beta_deg))
    if math.hypot(v[0], v[1]) < 0.2:
        return
    theta = veh.theta_scaled * np.asarray(factors)
    model = veh.model_kernel
    J_v, J_u = np.empty((3, 3)), np.empty((3, 2))
    forces.body_force_jacobian(v, 0.3, uz, theta, model, J_v, J_u)
    fd = _fd(lambda w: forces.body_force(w, 0.3, uz, theta, model), v, 1e-5)
    assert np.abs(J_v - fd).max() <= 1e-5 * np.abs(J_v).max() + 1e-7


def test_model_kernel_layout():
    """The model constants: the vehicle's stall angle and the documented widths, N_MODEL floats."""
    m = CALTECH.model_kernel
    assert m.shape == (forces.N_MODEL,) and m.dtype == np.float64
    assert m[forces.M_ALPHA_HI] == -m[forces.M_ALPHA_LO] == math.radians(16.0)
    assert m[forces.M_INV_BLEND] == 1.0 / math.radians(forces.STALL_BLEND_WIDTH_DEG)
    np.testing.assert_allclose(m[forces.M_INV_COS2_SIDESLIP], 4.0 / 3.0, rtol=1e-15)
    assert forces.model_at(np.arange(10.0), 2) == tuple(np.arange(2.0, 2.0 + forces.N_MODEL))
