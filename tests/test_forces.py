"""The force model (vtoladapt.forces kernels, vtoladapt.models wrappers) against independent checks.

References and tolerances
-------------------------
* ``reference_force``: the paper's formulas (eq:model_Txz, eq:model_FS, eq:model_cl, eq:model_cd,
  eq:fThat, eq:fAhat / m) written out here with the ``math`` module, in Table I units (throttle in
  percent), with the choices documented in forces.py (four-quadrant alpha, rotor side force against
  the in-plane flow, G at the rotor-disk angle of attack), inside the wing's attached-flow range
  (the continuation beyond it is tested in test_force_model_envelope.py). rel 1e-12.
* Hand-computed operating points (hover; 9 m/s at alpha = 5 deg) from Table I with rho = 1.225,
  S = 0.223, m = 1.70, every intermediate number in plain arithmetic. rel 1e-12.
* ``Phi theta == f_b`` at random inputs and random theta: |Phi theta - f| <= 1e-12 * (|Phi| |theta|),
  i.e. relative to the size of the terms summed (f itself may cancel to zero).
* Jacobian against central finite differences (step 1e-4 m/s, 1e-4 %) at smooth points
  (V >= 1 m/s, in-plane flow >= 0.5 m/s, u_z >= 5 %, away from alpha = +-pi): max error
  <= 1e-6 * max|J| + 1e-8.
* (V, alpha, beta) from v_i = V [cos a cos b, sin b, sin a cos b]: 1e-10 rad, rel 1e-13 on V.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from conftest import examples
from vtoladapt import forces, load_vehicle, models
from vtoladapt.frames import GRAVITY_MPS2, quat_from_euler, quat_to_rotmat

VEHICLES = {name: load_vehicle(name) for name in ("caltech_vtol", "px4_standard_vtol")}
CALTECH = VEHICLES["caltech_vtol"]

# Table I and Table II, typed in from the paper; rho is ISA sea level (the paper does not say)
CTX, CTZ, CS, K1, K2 = 3.02e-3, 2.87e-3, 2.31e-5, 1.425, 3.126
CD0, CD1, CD2, CL0, CL1 = 0.1551, 0.1782, 1.6000, 0.3705, 3.2502
RHO, S_REF, MASS = 1.225, 0.223, 1.70

vel = st.floats(-30.0, 30.0, allow_nan=False)
tiny_or_any = st.one_of(st.just(0.0), st.floats(-1e-150, 1e-150), vel)
throttle_pct = st.floats(0.0, 100.0)
vehicle_name = st.sampled_from(sorted(VEHICLES))
theta_factors = st.lists(st.floats(-2.0, 2.0), min_size=8, max_size=8)


def reference_force(v, ux_pct, uz_pct, theta_table, k1, k2, rho_S_over_2m):
    """f_b-hat (m/s^2, body FRD) from the paper's formulas with scalar math, Table I units."""
    ctx, ctz, cs, cd0, cd1, cd2, cl0, cl1 = theta_table
    vx, vy, vz = v
    V = math.sqrt(vx * vx + vy * vy + vz * vz)
    # thrust, eq:model_Txz
    Tx, Tz = ctx * ux_pct**2, ctz * uz_pct**2
    # rotor side force, eq:model_FS, opposing the in-plane flow (direction beta_bar)
    h = math.hypot(vx, vy)
    a_disk = math.atan2(vz, h)
    G = uz_pct**k1 * V ** (2 - k1) * ((math.pi / 2) ** 2 - a_disk**2) * (a_disk + k2) if uz_pct > 0 and V > 0 else 0.0
    beta_bar = math.atan2(vy, vx)
    FS = cs * G
    # wing, eq:model_cl, eq:model_cd, eq:fAhat divided by mass
    a = math.atan2(vz, vx)
    CL = cl0 + cl1 * a
    CD = cd0 + cd1 * a + cd2 * a * a
    q = rho_S_over_2m * V * V
    return np.array([Tx - FS * math.cos(beta_bar) + q * (CL * math.sin(a) - CD * math.cos(a)),
                     -FS * math.sin(beta_bar),
                     -Tz + q * (-CL * math.cos(a) - CD * math.sin(a))])


def random_theta_scaled(vehicle, factors):
    return vehicle.theta_scaled * np.asarray(factors)


# --- hand-computed operating points ----------------------------------------------------------

def test_hover_in_still_air():
    f = models.body_force(np.zeros(3), 0.0, 58.0, CALTECH)
    np.testing.assert_allclose(f, [0.0, 0.0, -CTZ * 58.0**2], rtol=1e-12, atol=0)
    assert f[2] == pytest.approx(-9.65468, rel=1e-12)


def test_hover_throttle_from_table_i_is_about_58_5_percent():
    """SPEC.md: 9.81 / 2.87e-3 = 3418 = 58.5^2, so Table I's throttle is in percent."""
    assert math.sqrt(9.81 / CTZ) == pytest.approx(58.5, abs=0.05)
    u_hover = math.sqrt(GRAVITY_MPS2 / CTZ)
    np.testing.assert_allclose(models.body_force(np.zeros(3), 0.0, u_hover, CALTECH),
                               [0.0, 0.0, -GRAVITY_MPS2], rtol=0, atol=1e-12)
    # and in the adaptation scaling CTz is the full-throttle acceleration, 28.7 m/s^2
    assert CALTECH.theta_scaled[1] == pytest.approx(28.7, rel=1e-15)


def test_forward_flight_9mps_alpha_5deg_by_hand():
    """9 m/s, alpha = 5 deg, beta = 0, u_x = 20 %, u_z = 58 %, all from Table I by hand."""
    V, a = 9.0, math.radians(5.0)
    v = np.array([V * math.cos(a), 0.0, V * math.sin(a)])
    q = 0.5 * RHO * V**2 * S_REF / MASS             # dynamic pressure x area / mass, m/s^2
    assert q == pytest.approx(6.5080, abs=1e-4)
    lift = q * (CL0 + CL1 * a)                      # eq:model_cl
    drag = q * (CD0 + CD1 * a + CD2 * a * a)        # eq:model_cd
    Tx, Tz = CTX * 20.0**2, CTZ * 58.0**2           # eq:model_Txz: 1.208, 9.65468
    G = 58.0**K1 * V ** (2 - K1) * ((math.pi / 2) ** 2 - a * a) * (a + K2)   # eq:model_Fs
    FS = CS * G                                     # eq:model_FS, against the flow (beta_bar = 0)
    assert (lift, drag, FS) == pytest.approx((4.2571, 1.1899, 0.2104), abs=1e-4)
    expected = [Tx - FS + lift * math.sin(a) - drag * math.cos(a),
                0.0,
                -Tz - lift * math.cos(a) - drag * math.sin(a)]
    f = models.body_force(v, 20.0, 58.0, CALTECH)
    np.testing.assert_allclose(f, expected, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(models.regressor(v, 20.0, 58.0, CALTECH) @ CALTECH.theta_scaled,
                               expected, rtol=1e-12, atol=1e-14)


def test_sideslip_rotor_force_opposes_in_plane_flow():
    """v_i = [9, 3, 0]: no alpha; the rotor side force points along -(9, 3)/|(9, 3)| in x-y
    (beta_bar = atan2(v_iy, v_ix), SPEC.md); the wing sees V^2 = 90 at alpha = 0."""
    v = np.array([9.0, 3.0, 0.0])
    V = math.sqrt(90.0)
    FS = CS * 58.0**K1 * V ** (2 - K1) * (math.pi / 2) ** 2 * K2
    q = 0.5 * RHO * 90.0 * S_REF / MASS
    expected = [CTX * 400.0 - FS * 9.0 / V - q * CD0, -FS * 3.0 / V, -CTZ * 58.0**2 - q * CL0]
    np.testing.assert_allclose(models.body_force(v, 20.0, 58.0, CALTECH), expected, rtol=1e-12)


def test_side_force_basis_shape():
    """eq:model_Fs: zero at alpha = +-90 deg; maximum where d/da[(pi^2/4 - a^2)(a + k2)] = 0,
    a* = (-2 k2 + sqrt(4 k2^2 + 3 pi^2)) / 6 (about 19.4 deg for Table I's k2), not at 0."""
    for a in (-math.pi / 2, math.pi / 2):
        assert abs(forces.side_force_basis(a, 9.0, 0.58, K1, K2)) < 1e-12
    assert forces.side_force_basis(0.1, 0.0, 0.58, K1, K2) == 0.0
    assert forces.side_force_basis(0.1, 9.0, 0.0, K1, K2) == 0.0
    grid = np.linspace(-math.pi / 2, math.pi / 2, 200001)
    values = [forces.side_force_basis(a, 9.0, 0.58, K1, K2) for a in grid[::10]]
    a_star = (-2 * K2 + math.sqrt(4 * K2**2 + 3 * math.pi**2)) / 6
    assert grid[::10][int(np.argmax(values))] == pytest.approx(a_star, abs=2e-4)
    assert math.degrees(a_star) == pytest.approx(19.4, abs=0.1)


# --- Phi theta == f_b and the reference formulas --------------------------------------------

@settings(max_examples=examples(500))
@given(vehicle_name, vel, vel, vel, throttle_pct, throttle_pct, theta_factors)
@example("caltech_vtol", 0.0, 0.0, 0.0, 0.0, 0.0, [1.0] * 8)
@example("px4_standard_vtol", 0.0, 12.0, 0.0, 50.0, 50.0, [1.0] * 8)
def test_regressor_times_theta_is_body_force(name, vx, vy, vz, ux, uz, factors):
    veh = VEHICLES[name]
    v = np.array([vx, vy, vz])
    theta = random_theta_scaled(veh, factors)
    f = models.body_force(v, ux, uz, veh, theta_scaled=theta)
    Phi = models.regressor(v, ux, uz, veh)
    scale = np.abs(Phi) @ np.abs(theta)
    assert np.all(np.abs(Phi @ theta - f) <= 1e-12 * scale + 1e-300)


@settings(max_examples=examples(300))
@given(vehicle_name, st.floats(0.5, 30.0), st.floats(-1.0, 1.0), st.floats(-30.0, 30.0), throttle_pct,
       throttle_pct, st.lists(st.floats(0.2, 2.0), min_size=8, max_size=8))
def test_body_force_matches_reference_formulas(name, V, alpha_frac, beta_deg, ux, uz, factors):
    """Inside the wing's attached-flow range (|alpha| <= stall angle, |beta| <= 30 deg); the model
    outside it is checked in test_force_model_envelope.py."""
    veh = VEHICLES[name]
    a, b = alpha_frac * math.radians(veh.envelope.stall_angle_deg), math.radians(beta_deg)
    v = V * np.array([math.cos(a) * math.cos(b), math.sin(b), math.sin(a) * math.cos(b)])
    theta_table = veh.force_model.as_table_theta() * np.asarray(factors)
    theta_s = models.theta_to_scaled(theta_table, veh.force_model.k1)
    expected = reference_force(v, ux, uz, theta_table, veh.force_model.k1, veh.force_model.k2,
                               veh.aero_scale_per_m)
    f = models.body_force(v, ux, uz, veh, theta_scaled=theta_s)
    # tolerance relative to the largest term (f may cancel): thrusts and dynamic pressure
    size = max(1.0, theta_s[0] * (ux / 100) ** 2, theta_s[1] * (uz / 100) ** 2,
               veh.aero_scale_per_m * v @ v * 10)
    np.testing.assert_allclose(f, expected, rtol=0, atol=1e-12 * size)


def test_default_theta_is_the_vehicles(any_vehicle):
    v = np.array([7.0, -1.0, 1.5])
    np.testing.assert_array_equal(models.body_force(v, 30.0, 50.0, any_vehicle),
                                  models.body_force(v, 30.0, 50.0, any_vehicle,
                                                    theta_scaled=models.scaled_theta(any_vehicle)))


def test_regressor_columns_act_where_the_paper_says():
    """Thrust x only in row 0, thrust z only in row 2, rotor side force only in the rotor plane,
    wing terms only in the x-z plane (C_Y = 0)."""
    Phi = models.regressor(np.array([8.0, 2.0, 1.0]), 30.0, 60.0, CALTECH)
    nz = Phi != 0.0
    np.testing.assert_array_equal(nz[:, 0], [True, False, False])
    np.testing.assert_array_equal(nz[:, 1], [False, False, True])
    np.testing.assert_array_equal(nz[:, 2], [True, True, False])
    np.testing.assert_array_equal(nz[1, 3:], False)
    assert Phi[0, 0] == pytest.approx(0.09) and Phi[2, 1] == pytest.approx(-0.36)


def test_regressor_rows_equals_rowwise_regressor(rng):
    v = rng.uniform(-20, 20, (50, 3))
    ux, uz = rng.uniform(0, 1, 50), rng.uniform(0, 1, 50)
    rows = forces.regressor_rows(v, ux, uz, CALTECH.model_kernel)
    Phi = np.empty((3, 8))
    for i in range(50):
        forces.regressor(v[i], ux[i], uz[i], CALTECH.model_kernel, Phi)
        np.testing.assert_array_equal(rows[i], Phi)


# --- Jacobian against finite differences -------------------------------------------------------

def _fd_jacobian(fun, v, ux, uz, hv=1e-4, hu=1e-4):
    """Five-point central differences, truncation O(h^4). The three-point stencil's error
    h^2 f'''(v)/6 reaches 5e-7 inside the 8 deg stall blend at 1.5 m/s airspeed (the smoothstep's
    third derivative is 12/w^3), above the 1e-6 relative bound, although the analytic Jacobian
    agrees with this stencil to 1e-12 there (caltech_vtol, v_i = [1.4375, 0, 0.625] m/s)."""
    def d5(g, h):
        return (-g(2 * h) + 8 * g(h) - 8 * g(-h) + g(-2 * h)) / (12 * h)

    J_v = np.empty((3, 3))
    for j in range(3):
        e = np.zeros(3)
        e[j] = 1.0
        J_v[:, j] = d5(lambda h: fun(v + h * e, ux, uz), hv)
    J_u = np.column_stack([d5(lambda h: fun(v, ux + h, uz), hu),
                           d5(lambda h: fun(v, ux, uz + h), hu)])
    return J_v, J_u


def _smooth_point(vx, vy, vz):
    return (math.sqrt(vx * vx + vy * vy + vz * vz) >= 1.0 and math.hypot(vx, vy) >= 0.5
            and math.hypot(vx, vz) >= 0.5 and (vx > 0.0 or abs(vz) >= 0.5))


@settings(max_examples=examples(300))
@given(vehicle_name, vel, vel, vel, st.floats(0.0, 100.0), st.floats(5.0, 100.0))
@example("caltech_vtol", 9.0, 0.0, 0.787, 20.0, 58.0)
def test_jacobian_matches_central_differences(name, vx, vy, vz, ux, uz):
    assume(_smooth_point(vx, vy, vz))
    veh = VEHICLES[name]
    v = np.array([vx, vy, vz])
    J_v, J_u = models.body_force_jacobian(v, ux, uz, veh)
    fd_v, fd_u = _fd_jacobian(lambda vv, a, b: models.body_force(vv, a, b, veh), v, ux, uz)
    assert np.abs(J_v - fd_v).max() <= 1e-6 * np.abs(J_v).max() + 1e-8
    assert np.abs(J_u - fd_u).max() <= 1e-6 * np.abs(J_u).max() + 1e-8


@given(vehicle_name, vel, vel, vel, st.floats(0.0, 1.0), st.floats(0.05, 1.0),
       st.lists(st.floats(0.2, 2.0), min_size=8, max_size=8))
@example("caltech_vtol", 1.4375, 0.0, 0.625, 0.0, 0.05, [1.0] * 8)  # inside the stall blend
def test_kernel_jacobian_with_random_theta(name, vx, vy, vz, ux, uz, factors):
    assume(_smooth_point(vx, vy, vz))
    veh = VEHICLES[name]
    theta = random_theta_scaled(veh, factors)
    model = veh.model_kernel

    def f(vv, a, b):
        out = np.empty(3)
        forces.body_force(vv, a, b, theta, model, out)
        return out

    v = np.array([vx, vy, vz])
    J_v, J_u = np.empty((3, 3)), np.empty((3, 2))
    forces.body_force_jacobian(v, ux, uz, theta, model, J_v, J_u)
    fd_v, fd_u = _fd_jacobian(f, v, ux, uz, hv=1e-4, hu=1e-6)
    assert np.abs(J_v - fd_v).max() <= 1e-6 * np.abs(J_v).max() + 1e-8
    assert np.abs(J_u - fd_u).max() <= 1e-6 * np.abs(J_u).max() + 1e-8


# --- airflow angles -----------------------------------------------------------------------------

@given(st.floats(1e-3, 50.0), st.floats(-math.pi + 1e-9, math.pi - 1e-9),
       st.floats(-math.pi / 2 + 0.01, math.pi / 2 - 0.01))
def test_airflow_angles_closed_form(V, a, b):
    v = V * np.array([math.cos(a) * math.cos(b), math.sin(b), math.sin(a) * math.cos(b)])
    V_out, a_out, b_out = models.airflow_angles(v)
    assert V_out == pytest.approx(V, rel=1e-13)
    assert abs(a_out - a) <= 1e-10 and abs(b_out - b) <= 1e-10


def test_airflow_angles_at_rest_and_pure_flows():
    assert models.airflow_angles(np.zeros(3)) == (0.0, 0.0, 0.0)
    assert models.airflow_angles(np.array([0.0, 0.0, 5.0])) == pytest.approx((5.0, math.pi / 2, 0.0))
    assert models.airflow_angles(np.array([0.0, 0.0, -5.0])) == pytest.approx((5.0, -math.pi / 2, 0.0))
    assert models.airflow_angles(np.array([0.0, 4.0, 0.0])) == pytest.approx((4.0, 0.0, math.pi / 2))


def test_incident_velocity_in_a_headwind_with_nose_up():
    """Facing north into a 9 m/s wind blowing south (v_w = [-9, 0, 0] NED), pitched 5 deg nose
    up, hovering: v_i = R^T (v - v_w) = 9 [cos 5, 0, sin 5] deg, so alpha = +5 deg (eq:vi)."""
    R_WB = quat_to_rotmat(quat_from_euler(0.0, math.radians(5.0), 0.0))
    v_i = forces.incident_velocity(np.zeros(3), np.array([-9.0, 0.0, 0.0]), R_WB)
    np.testing.assert_allclose(v_i, 9.0 * np.array([math.cos(math.radians(5)), 0.0,
                                                     math.sin(math.radians(5))]), atol=1e-12)
    _, alpha, beta = forces.airflow_angles(v_i)
    assert math.degrees(alpha) == pytest.approx(5.0, abs=1e-10) and beta == pytest.approx(0.0, abs=1e-12)


def test_incident_velocity_matches_numpy(rng):
    for _ in range(20):
        R = quat_to_rotmat(_unit(rng.normal(size=4)))
        v, w = rng.normal(size=3) * 10, rng.normal(size=3) * 5
        np.testing.assert_allclose(forces.incident_velocity(v, w, R), R.T @ (v - w), rtol=0, atol=1e-12)


def _unit(q):
    return q / np.linalg.norm(q)


# --- degenerate inputs and invariants ----------------------------------------------------------

SPECIAL_FLOWS = {
    "at rest": [0.0, 0.0, 0.0],
    "alpha +90 deg": [0.0, 0.0, 8.0],
    "alpha -90 deg": [0.0, 0.0, -8.0],
    "pure lateral": [0.0, 8.0, 0.0],
    "pure lateral, negative": [0.0, -8.0, 0.0],
    "backward": [-8.0, 0.0, 0.0],
    "tiny forward": [1e-110, 0.0, 0.0],
    "tiny lateral and vertical": [0.0, 1e-160, 1e-160],
}


@pytest.mark.parametrize("flow", list(SPECIAL_FLOWS), ids=list(SPECIAL_FLOWS))
@pytest.mark.parametrize("throttles", [(0.0, 0.0), (20.0, 58.0), (100.0, 100.0)])
def test_no_nan_or_inf_at_degenerate_flows(any_vehicle, flow, throttles):
    v = np.array(SPECIAL_FLOWS[flow])
    ux, uz = throttles
    f = models.body_force(v, ux, uz, any_vehicle)
    Phi = models.regressor(v, ux, uz, any_vehicle)
    J_v, J_u = models.body_force_jacobian(v, ux, uz, any_vehicle)
    for arr in (f, Phi, J_v, J_u, np.array(models.airflow_angles(v))):
        assert np.all(np.isfinite(arr)), (flow, throttles, arr)
    np.testing.assert_allclose(Phi @ any_vehicle.theta_scaled, f, rtol=1e-12, atol=1e-300)


def test_at_rest_only_thrust_remains(any_vehicle):
    f = models.body_force(np.zeros(3), 40.0, 70.0, any_vehicle)
    fm = any_vehicle.force_model
    np.testing.assert_allclose(f, [fm.CTx * 1600.0, 0.0, -fm.CTz * 4900.0], rtol=1e-12)


@settings(max_examples=examples(500))
@given(vehicle_name, tiny_or_any, tiny_or_any, tiny_or_any, throttle_pct, throttle_pct)
def test_finite_outputs_for_finite_inputs(name, vx, vy, vz, ux, uz):
    veh = VEHICLES[name]
    v = np.array([vx, vy, vz])
    outputs = [models.body_force(v, ux, uz, veh), models.regressor(v, ux, uz, veh),
               *models.body_force_jacobian(v, ux, uz, veh), np.array(models.airflow_angles(v))]
    for arr in outputs:
        assert np.all(np.isfinite(arr))


@given(vehicle_name, vel, vel, vel, throttle_pct, throttle_pct)
def test_lateral_mirror_symmetry(name, vx, vy, vz, ux, uz):
    """v_iy -> -v_iy mirrors the aircraft in its x-z plane: f_y and Phi's row 1 flip sign,
    x and z are unchanged (exactly: the model is built from even functions of v_iy)."""
    veh = VEHICLES[name]
    v, m = np.array([vx, vy, vz]), np.array([vx, -vy, vz])
    f, fm = models.body_force(v, ux, uz, veh), models.body_force(m, ux, uz, veh)
    P, Pm = models.regressor(v, ux, uz, veh), models.regressor(m, ux, uz, veh)
    np.testing.assert_array_equal(fm[[0, 2]], f[[0, 2]])
    np.testing.assert_array_equal(fm[1], -f[1])
    np.testing.assert_array_equal(Pm[[0, 2]], P[[0, 2]])
    np.testing.assert_array_equal(Pm[1], -P[1])


# --- parameter scaling ---------------------------------------------------------------------------

@given(st.lists(st.floats(-1e3, 1e3, allow_subnormal=False), min_size=8, max_size=8),
       st.floats(0.01, 1.99))
def test_scaling_round_trip(theta, k1):
    theta = np.array(theta)
    np.testing.assert_allclose(models.theta_from_scaled(models.theta_to_scaled(theta, k1), k1),
                               theta, rtol=1e-15, atol=1e-300)
    np.testing.assert_allclose(models.theta_to_scaled(models.theta_from_scaled(theta, k1), k1),
                               theta, rtol=1e-15, atol=1e-300)


@given(st.one_of(st.just(0.0), st.floats(1e-6, 100.0)), st.floats(0.01, 1.99))
def test_scaling_leaves_each_term_unchanged(u_pct, k1):
    """theta_table . u_pct^p == theta_scaled . (u_pct / 100)^p term by term (p = 2, 2, k1)."""
    table = np.array([CTX, CTZ, CS, 1, 1, 1, 1, 1])
    scaled = models.theta_to_scaled(table, k1)
    u = u_pct / 100.0
    assert scaled[0] * u**2 == pytest.approx(table[0] * u_pct**2, rel=1e-13, abs=1e-300)
    assert scaled[1] * u**2 == pytest.approx(table[1] * u_pct**2, rel=1e-13, abs=1e-300)
    assert scaled[2] * u**k1 == pytest.approx(table[2] * u_pct**k1, rel=1e-13, abs=1e-300)
    np.testing.assert_array_equal(scaled[3:], table[3:])


def test_wrappers_reject_wrong_shapes():
    with pytest.raises(ValueError, match=r"v_i_B must have shape \(3,\)"):
        models.body_force(np.zeros(2), 0.0, 0.0, CALTECH)
    with pytest.raises(ValueError, match="v_i_B"):
        models.regressor(np.zeros((3, 1)), 0.0, 0.0, CALTECH)
