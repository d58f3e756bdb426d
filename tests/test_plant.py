"""The plant against closed forms, conservation laws and scipy's integrator."""
from conftest import REPO_DATA_DIR, examples
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import vtoladapt
from vtoladapt import layout
from vtoladapt.sim import plant
from vtoladapt.config import ConfigError
from vtoladapt.frames import GRAVITY_MPS2, quat_from_euler, quat_to_rotmat


@pytest.fixture(scope="module")
def veh():
    return vtoladapt.load_vehicle("caltech_vtol")


def kernel(veh, **overrides):
    return plant.plant_config_from_mapping(overrides, "test").to_kernel(veh)


def vacuum(p):
    """Plant parameters with no air and no rotor torques: a free rigid body."""
    p = p.copy()
    p[plant.P_RHO] = 0.0
    p[plant.P_KM] = 0.0
    p[plant.P_KM_PUSHER] = 0.0
    return p


def integrate(x, motor, wind, p, h, n):
    f = np.empty(3)
    u = plant.plant_input(motor)
    for _ in range(n):
        plant.rk4_step(x, u, wind, p, h, f)
    return x


def test_free_fall_matches_closed_form(veh):
    p = vacuum(kernel(veh))
    v0 = np.array([3.0, -1.0, -2.0])
    x = layout.pack_state([1.0, 2.0, -50.0], v0, quat_from_euler(0.3, 0.2, -0.1), [0, 0, 0], np.zeros(5))
    T = 3.0
    integrate(x, np.zeros(5), np.zeros(3), p, 1e-3, 3000)
    g = np.array([0, 0, GRAVITY_MPS2])
    np.testing.assert_allclose(x[0:3], [1.0, 2.0, -50.0] + v0 * T + 0.5 * g * T**2, atol=1e-9)
    np.testing.assert_allclose(x[3:6], v0 + g * T, atol=1e-10)


def test_torque_free_rotation_conserves_energy_and_momentum(veh):
    """60 s of tumbling: kinetic energy and world-frame angular momentum conserved to 1e-8 relative."""
    p = vacuum(kernel(veh, motor_lag=True))
    J = p[plant.P_J:plant.P_J + 9].reshape(3, 3)
    omega0 = np.array([1.5, -0.7, 2.0])  # rad/s about all three axes: a genuinely tumbling body
    x = layout.pack_state([0, 0, 0], [0, 0, 0], quat_from_euler(0.1, 0.2, 0.3), omega0, np.zeros(5))

    def invariants(x):
        w = x[10:13]
        R = quat_to_rotmat(x[6:10])
        return 0.5 * w @ J @ w, R @ (J @ w)

    E0, L0 = invariants(x)
    integrate(x, np.zeros(5), np.zeros(3), p, 1e-3, 60_000)
    E1, L1 = invariants(x)
    assert abs(E1 - E0) / E0 < 1e-8
    np.testing.assert_allclose(L1, L0, rtol=0, atol=1e-8 * np.linalg.norm(L0))
    assert abs(np.linalg.norm(x[6:10]) - 1.0) < 1e-12


def test_rk4_is_fourth_order_against_solve_ivp(veh):
    """Error vs a tight DOP853 reference falls ~16x per halving of the step."""
    p = kernel(veh)
    motor = np.array([0.62, 0.55, 0.60, 0.57, 0.35])
    wind = np.array([-6.0, 1.0, 0.0])
    x0 = layout.pack_state([0, 0, -5], [1.0, 0.0, 0.0], quat_from_euler(0.1, 0.15, 0.05),
                           [0.2, -0.3, 0.1], [0.5, 0.5, 0.5, 0.5, 0.2])
    T = 0.5
    ref = plant.integrate_reference(x0, motor, wind, p, T)
    errors = []
    for h in (0.01, 0.005, 0.0025):
        x = integrate(x0.copy(), motor, wind, p, h, int(round(T / h)))
        errors.append(np.linalg.norm((x - ref)[:6]))
    ratios = [errors[i] / errors[i + 1] for i in range(2)]
    for r in ratios:
        assert 12.0 < r < 20.0, (errors, ratios)


def test_trimmed_hover_stays_put(veh):
    pc = plant.plant_config_from_mapping({}, "test")
    p = pc.to_kernel(veh)
    motor = plant.hover_trim_motor(veh, pc)
    x = layout.pack_state([0, 0, -2.0], [0, 0, 0], [1, 0, 0, 0], [0, 0, 0], motor)
    integrate(x, motor, np.zeros(3), p, 1e-3, 10_000)
    np.testing.assert_allclose(x[0:3], [0, 0, -2.0], atol=1e-9)
    np.testing.assert_allclose(x[10:13], 0.0, atol=1e-12)


def test_heavier_plant_needs_more_throttle(veh):
    light = plant.plant_config_from_mapping({}, "t")
    heavy = plant.plant_config_from_mapping({"mass_kg": 2.0}, "t")
    u_l = plant.hover_trim_motor(veh, light)[0]
    u_h = plant.hover_trim_motor(veh, heavy)[0]
    assert u_h / u_l == pytest.approx(np.sqrt(2.0 / 1.7), rel=1e-12)


def test_incident_flow_is_minus_wind_at_rest(veh):
    from vtoladapt.forces import incident_velocity

    wind = np.array([-9.0, 2.0, 0.5])
    for q in (np.array([1.0, 0, 0, 0]), quat_from_euler(0.7, -0.2, 0.4)):
        R = quat_to_rotmat(q)
        v_i = incident_velocity(np.zeros(3), wind, R)
        np.testing.assert_allclose(R @ v_i, -wind, atol=1e-12)


def test_stall_blend_and_flat_plate(veh):
    p = kernel(veh)
    CL_lin = 0.3705 + 3.2502 * np.radians(5)
    a = np.radians(5)
    CL, _ = plant.true_aero_coefficients(a, np.sin(a), np.cos(a), p)
    assert CL == pytest.approx(CL_lin, rel=1e-3)  # attached flow: linear polar
    a = np.radians(90)
    CL90, CD90 = plant.true_aero_coefficients(a, np.sin(a), np.cos(a), p)
    assert abs(CL90) < 1e-6 and CD90 == pytest.approx(0.1551 + 2.0, rel=1e-6)  # flat plate broadside
    p_off = kernel(veh, stall=False)
    a = np.radians(40)
    CL_off, _ = plant.true_aero_coefficients(a, np.sin(a), np.cos(a), p_off)
    assert CL_off == pytest.approx(0.3705 + 3.2502 * np.radians(40), rel=1e-12)


def test_px4_attached_drag_is_gazebos_magnitude():
    """PX4's Gazebo LiftDrag plugin: cd = |cda (a0 + alpha)|; its polar C_D0 + C_D1 alpha crosses 0 at -3.4 deg."""
    px4 = vtoladapt.load_vehicle("px4_standard_vtol")
    p = kernel(px4, stall=False)
    cda, a0 = 0.64171, 0.05984  # the Gazebo parameters the vehicle file quotes
    for a_deg in (-12.0, -5.0, -3.0, 0.0, 8.0):
        a = np.radians(a_deg)
        _, CD = plant.true_aero_coefficients(a, np.sin(a), np.cos(a), p)
        assert CD == pytest.approx(abs(cda * (a0 + a)), rel=1e-4)


@settings(max_examples=examples(300), deadline=None)
@given(alpha=st.floats(-np.pi, np.pi), name=st.sampled_from(("caltech_vtol", "px4_standard_vtol")))
def test_true_drag_never_negative(alpha, name):
    """Drag never pushes the aircraft forward, attached, blended or past stall."""
    p = kernel(vtoladapt.load_vehicle(name))
    _, CD = plant.true_aero_coefficients(alpha, np.sin(alpha), np.cos(alpha), p)
    assert CD >= 0.0


@settings(max_examples=examples(300), deadline=None)
@given(alpha=st.floats(-4.0, 4.0), M=st.floats(0.5, 1000.0), alpha_stall_deg=st.floats(1.0, 59.0))
def test_stall_blend_is_beard_mclain_sigmoid(alpha, M, alpha_stall_deg):
    """The one-exp form equals Beard & McLain's two-exp sigmoid, and stays in [0, 1] for any sharpness."""
    a0 = np.radians(alpha_stall_deg)
    a = min(max(alpha, -np.pi), np.pi)
    with np.errstate(over="ignore"):
        e1 = np.exp(min(-M * (a - a0), 700.0))
        e2 = np.exp(min(M * (a + a0), 700.0))
        reference = (1.0 + e1 + e2) / ((1.0 + e1) * (1.0 + e2))
    s = plant.stall_blend(alpha, M, np.exp(min(M * a0, 700.0)))
    assert 0.0 <= s <= 1.0
    if M * (abs(a) + a0) < 650.0:  # the reference itself is exact only without its clamps
        assert s == pytest.approx(reference, rel=1e-12, abs=1e-15)


def test_motor_lag_is_integrated_exactly(veh):
    """Motor outputs follow u(t) = c + (u0 - c) exp(-t / tau) to rounding, whatever the step."""
    p = kernel(veh)
    cmd = np.array([0.9, 0.1, 0.5, 0.7, 1.4])  # the pusher's 1.4 saturates to 1
    u0 = np.array([0.3, 0.6, 0.5, 0.2, 0.0])
    x = layout.pack_state([0, 0, -5], [0, 0, 0], [1, 0, 0, 0], [0, 0, 0], u0)
    integrate(x, cmd, np.zeros(3), p, 0.004, 25)  # 0.1 s in steps as long as the lift motors' lag
    tau = np.array([veh.actuators.lift_motor_time_constant_s] * 4 + [veh.actuators.pusher_motor_time_constant_s])
    c = np.clip(cmd, 0.0, 1.0)
    np.testing.assert_allclose(x[layout.X_MOTOR:layout.X_MOTOR + layout.N_MOTORS], c + (u0 - c) * np.exp(-0.1 / tau),
                               rtol=0, atol=1e-14)


def test_first_stage_reuse_is_exact(veh):
    """A tick that reuses the sensors' first-stage evaluation ends bit-identical to one that does not."""
    p = kernel(veh)
    x0 = layout.pack_state([0, 0, -5], [2.0, 0.5, -0.3], quat_from_euler(0.2, 0.1, -0.05),
                           [0.1, -0.2, 0.05], [0.55, 0.6, 0.58, 0.52, 0.3])
    motor = plant.plant_input([0.6, 0.55, 0.62, 0.57, 0.4, 0.1, -0.05, 0.2, 0.0])
    wind = np.array([-7.0, 0.5, 0.2])
    a, b = x0.copy(), x0.copy()
    work_a, work_b = np.zeros(plant.RK4_WORK_SIZE), np.zeros(plant.RK4_WORK_SIZE)
    f_B, v_i = np.empty(3), np.empty(3)
    plant.plant_first_stage(a, wind, p, f_B, v_i, work_a)
    plant.plant_advance(a, motor, wind, p, 0.001, 4, True, work_a)
    plant.plant_advance(b, motor, wind, p, 0.001, 4, False, work_b)
    assert np.array_equal(a, b)
    xdot = np.empty(layout.X_SIZE)
    f_ref = np.empty(3)
    plant.plant_derivative(x0, motor, wind, p, xdot, f_ref)
    np.testing.assert_array_equal(f_B, f_ref)
    np.testing.assert_allclose(quat_to_rotmat(x0[6:10]) @ v_i, -wind + x0[3:6], atol=1e-12)


def test_pusher_thrust_ratio_follows_uiuc_fit(veh):
    p = kernel(veh)
    D = veh.geometry.pusher_prop_diameter_m
    n = 100.0
    for J in (0.0, 0.3, 0.6):
        expected = 1 + plant.UIUC_7X4_CT_RATIO_COEFFS[0] * J + plant.UIUC_7X4_CT_RATIO_COEFFS[1] * J**2
        assert plant.pusher_thrust_ratio(J * n * D, n, p) == pytest.approx(expected, rel=1e-12)
    assert plant.pusher_thrust_ratio(50.0, 0.0, p) == 1.0
    assert plant.pusher_thrust_ratio(5.0, n, kernel(veh, pusher_advance_ratio_loss=False)) == 1.0


def test_uiuc_coefficients_match_the_data_fit():
    """The plant's default C_T(J) is the fitting module's fit of the UIUC 7x4 data, and C_T(0) its static mean."""
    from vtoladapt.fitting import fit_uiuc_static_ct, pusher_thrust_ratio_model

    model = pusher_thrust_ratio_model(data_dir=REPO_DATA_DIR)
    static = fit_uiuc_static_ct(data_dir=REPO_DATA_DIR)
    np.testing.assert_allclose(model.coefficients[1:], plant.UIUC_7X4_CT_RATIO_COEFFS, rtol=1e-4)
    ct0 = static["CT"]["mean"]
    assert ct0 == pytest.approx(plant.UIUC_7X4_STATIC_CT, rel=1e-3)


def test_plant_config_rejects_bad_values():
    with pytest.raises(ConfigError, match=r"stal_angle_deg.*did you mean 'stall_angle_deg'"):
        plant.plant_config_from_mapping({"stal_angle_deg": 15}, "scen.toml")
    with pytest.raises(ConfigError, match=r"scen.toml: \[plant\] mass_kg = -1.0"):
        plant.plant_config_from_mapping({"mass_kg": -1.0}, "scen.toml")
    with pytest.raises(ConfigError, match=r"coefficients\] CL1"):
        plant.plant_config_from_mapping({"coefficients": {"CL1": -2.0}}, "scen.toml")

