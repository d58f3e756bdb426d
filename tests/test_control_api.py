"""Python step API, controller configuration and position references."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from vtoladapt import layout as L
from vtoladapt.config import ConfigError
from vtoladapt.control import (
    Command,
    Controller,
    ControllerConfig,
    Hold,
    Measurement,
    MinJerkWaypoints,
    Reference,
    VelocityProfile,
    controller_arrays,
    controller_config_from_mapping,
    controller_functions,
    controller_step,
    load_controller_config,
    trajectory_from_reference,
)
from vtoladapt.control.step import controller_initial_state, controller_params, diagnostics_size
from vtoladapt.control.laws.composite import CompositeSettings
from vtoladapt.frames import GRAVITY_MPS2, quat_from_euler


def _meas_sequence(n, rng):
    """Plausible, varying measurements (hover in a gusty 5 m/s headwind)."""
    out = []
    for k in range(n):
        pitch = np.radians(8.0) + 0.02 * np.sin(0.1 * k)
        q = quat_from_euler(0.01 * np.sin(0.05 * k), pitch, 0.01 * np.cos(0.07 * k))
        v_i = (5.0 + 0.3 * rng.normal()) * np.array([np.cos(pitch), 0.02 * rng.normal(), np.sin(pitch)])
        out.append(Measurement.from_parts(
            p_W=(0.01 * k / n, 0.0, -1.5 + 0.02 * np.sin(0.03 * k)), v_W=0.05 * rng.normal(size=3), q_WB=q,
            omega_B=0.05 * rng.normal(size=3), accel_B=(-0.3, 0.0, -GRAVITY_MPS2) + 0.2 * rng.normal(size=3),
            v_i_B=v_i))
    return out


@pytest.mark.parametrize("kind", ["composite", "pid"])
def test_step_returns_exactly_what_the_kernel_returns(caltech, rng, kind):
    cfg = ControllerConfig(kind=kind)
    ctrl = Controller(caltech, cfg)
    params, state = controller_arrays(caltech, cfg)
    ref = Reference.hold((0.0, 0.0, -1.5))
    cmd = np.zeros(L.CMD_SIZE)
    diag = np.zeros(diagnostics_size(params))
    fns = controller_functions(params)          # the compiled entry as the simulator calls it
    for k, m in enumerate(_meas_sequence(100, rng)):
        out = ctrl.step(0.004 * k, m, ref)
        dt = 0.004 if k == 0 else 0.004 * k - 0.004 * (k - 1)      # what step() derives from t
        controller_step(fns, params, state, m.array, ref.array, dt, cmd, diag)
        assert isinstance(out, Command)
        assert np.array_equal(out.array, cmd)
        assert np.array_equal(ctrl.diagnostics_array, diag)
    assert np.array_equal(ctrl.state.array, state)


def test_get_state_set_state_reproduces_the_next_steps_bit_for_bit(caltech, rng):
    ctrl = Controller(caltech, ControllerConfig())
    ref = Reference.hold((0.0, 0.0, -1.5))
    seq = _meas_sequence(80, rng)
    for k in range(50):
        ctrl.step(0.004 * k, seq[k], ref)
    snap = ctrl.get_state()
    first = [ctrl.step(0.004 * k, seq[k], ref).array.copy() for k in range(50, 80)]
    theta_first = ctrl.state.theta_hat
    ctrl.set_state(snap)
    second = [ctrl.step(0.004 * k, seq[k], ref).array.copy() for k in range(50, 80)]
    for a, b in zip(first, second):
        assert np.array_equal(a, b)
    assert np.array_equal(theta_first, ctrl.state.theta_hat)
    # the snapshot is a copy: stepping did not change it
    ctrl.set_state(snap)
    assert np.array_equal(ctrl.step(0.2, seq[50], ref).array, first[0])


def test_reset_restores_the_initial_state(caltech, rng):
    cfg = ControllerConfig()
    ctrl = Controller(caltech, cfg)
    ref = Reference.hold((0.0, 0.0, -1.5))
    for k, m in enumerate(_meas_sequence(30, rng)):
        ctrl.step(0.004 * k, m, ref)
    assert not np.array_equal(ctrl.state.array, controller_initial_state(controller_params(cfg, caltech)))
    ctrl.reset()
    assert np.array_equal(ctrl.state.array, controller_initial_state(controller_params(cfg, caltech)))
    np.testing.assert_array_equal(ctrl.state.theta_hat, caltech.theta_scaled)
    np.testing.assert_allclose(ctrl.state.P, np.diag(caltech.adaptation.P0_diag), rtol=1e-12)
    np.testing.assert_array_equal(ctrl.state.integrator, 0.0)


def test_report_applied_is_what_the_next_step_adapts_on(caltech, rng):
    """The applied throttles replace the command in the adaptation's regressor: the thrust column
    of the filtered regressor follows the reported collective, so theta-hat moves differently."""
    ref = Reference.hold((0.0, 0.0, -1.5))
    seq = _meas_sequence(60, rng)
    a, b = Controller(caltech), Controller(caltech)
    for k in range(40):
        a.step(0.004 * k, seq[k], ref)
        b.step(0.004 * k, seq[k], ref)
    u = a.state.last_command_throttles
    b.report_applied(100.0 * u[0], 100.0 * u[1] - 5.0)          # the mixer took 5 % off the collective
    np.testing.assert_allclose(b.state.last_command_throttles, [u[0], u[1] - 0.05], rtol=1e-12)
    for k in range(40, 60):
        a.step(0.004 * k, seq[k], ref)
        b.step(0.004 * k, seq[k], ref)
    # the C_Tz column is -u_z^2 (lagged): a lower applied collective makes it smaller in magnitude
    assert abs(b.state.filtered_regressor[2, 1]) < abs(a.state.filtered_regressor[2, 1])
    assert not np.array_equal(a.state.theta_hat, b.state.theta_hat)
    # clipped to the throttle range; NaN refused in one line naming the argument
    b.report_applied(-10.0, 250.0)
    np.testing.assert_array_equal(b.state.last_command_throttles, [0.0, caltech.actuators.throttle_max_pct / 100])
    with pytest.raises(ValueError, match=r"report_applied: throttle_z_pct = nan: must be a finite number"):
        b.report_applied(10.0, float("nan"))
    with pytest.raises(ValueError, match=r"report_applied: throttle_x_pct = 'ten': must be a finite number"):
        b.report_applied("ten", 10.0)
    np.testing.assert_array_equal(b.state.last_command_throttles, [0.0, caltech.actuators.throttle_max_pct / 100])


def test_step_rejects_time_going_backwards(caltech):
    ctrl = Controller(caltech)
    m = Measurement.from_parts((0, 0, -1), (0, 0, 0), (1, 0, 0, 0), (0, 0, 0), (0, 0, -9.8), (0, 0, 0))
    ctrl.step(1.0, m, Reference.hold((0, 0, -1)))
    with pytest.raises(ValueError, match="must increase"):
        ctrl.step(1.0, m, Reference.hold((0, 0, -1)))


def test_records_have_named_views(caltech):
    m = Measurement.from_parts((1, 2, 3), (4, 5, 6), (1, 0, 0, 0), (7, 8, 9), (0, 0, -9.8), (10, 0, 1), False)
    assert m.array[L.MEAS_V_I_VALID] == 0.0 and not m.v_i_valid
    m.v_W = (0.5, 0.0, 0.0)
    assert m.array[L.MEAS_V_W] == 0.5
    np.testing.assert_array_equal(m.omega_B, (7, 8, 9))
    with pytest.raises(ValueError, match="p_W must have 3"):
        Measurement.from_parts((1, 2), (4, 5, 6), (1, 0, 0, 0), (7, 8, 9), (0, 0, 0), (0, 0, 0))
    with pytest.raises(ValueError, match="shape"):
        Reference(np.zeros(3))
    r = Reference.from_parts((1, 2, 3), yaw_rad=0.5)
    assert r.yaw_rad == 0.5 and r.as_dict()["ref_p_E_m"] == 2.0


def test_config_from_a_controller_table(tmp_path):
    path = tmp_path / "scenario.toml"
    path.write_text('[controller]\nkind = "pid"\nK_v = [2.0, 2.0, 4.5]\n\n[controller.composite]\n'
                    'forgetting_lambda = 0.2\n')
    cfg = load_controller_config(path)
    assert cfg.kind == "pid" and cfg.K_v == (2.0, 2.0, 4.5) and cfg.composite.forgetting_lambda == 0.2
    assert cfg.Lambda_p == ControllerConfig().Lambda_p
    with pytest.raises(ConfigError, match="did you mean 'forgetting_lambda'"):
        controller_config_from_mapping({"composite": {"forgeting_lambda": 0.1}}, source="s.toml")
    with pytest.raises(ConfigError, match="kind"):
        controller_config_from_mapping({"kind": "lqr"})
    with pytest.raises(ConfigError, match="K_v.*exactly 3"):
        controller_config_from_mapping({"K_v": [1.0, 2.0]})
    with pytest.raises(ConfigError, match="Lambda_q.*out of range"):
        controller_config_from_mapping({"Lambda_q": [1.0, -2.0, 3.0]})
    with pytest.raises(ConfigError, match="alpha_min_deg"):
        controller_config_from_mapping({"alpha_max_deg": 10.0, "alpha_min_deg": 12.0})


def test_params_conversion_accepts_a_posterior_and_rejects_bad_priors(caltech):
    cfg = ControllerConfig()
    A = np.random.default_rng(1).normal(size=(8, 8))
    P0 = A @ A.T * 0.01 + np.diag(caltech.adaptation.P0_diag)
    ctrl = Controller(caltech, cfg, theta_0=caltech.theta_scaled * 1.01, P0_diag=P0)
    np.testing.assert_allclose(ctrl.state.P, P0, rtol=1e-10)
    np.testing.assert_array_equal(ctrl.state.theta_hat, caltech.theta_scaled * 1.01)
    with pytest.raises(ValueError, match="P0_diag"):
        Controller(caltech, cfg, P0_diag=np.ones(7))
    with pytest.raises(ValueError, match="positive definite"):
        Controller(caltech, cfg, P0_diag=-np.eye(8))
    with pytest.raises(ValueError, match="theta_0"):
        Controller(caltech, cfg, theta_0=np.full(8, np.nan))
    with pytest.raises(ValueError, match="within the bounds"):
        Controller(caltech, cfg, theta_lower=caltech.theta_scaled * 1.1, theta_upper=caltech.theta_scaled * 1.2)
    with pytest.raises(ValueError, match="sigma"):
        Controller(caltech, ControllerConfig(composite=CompositeSettings(sigma=50.0)))
    # K_omega defaults to J times the rate bandwidth
    from vtoladapt.control.blocks import P_K_OMEGA
    p = controller_params(cfg, caltech)
    np.testing.assert_allclose(p[P_K_OMEGA:P_K_OMEGA + 3],
                               np.array(caltech.mass.inertia_kgm2) * np.array(cfg.rate_bandwidth_radps))


# --- references ---------------------------------------------------------------------------------

def _fd(table, t, col, n=3):
    """Central finite differences of columns ``col:col+n`` of a reference table."""
    return np.gradient(table[:, col:col + n], t, axis=0)


def test_hold_reference():
    tab = Hold((1.0, 2.0, -3.0), 0.7).reference_table(np.linspace(0, 10, 11))
    assert tab.shape == (11, L.REF_SIZE)
    np.testing.assert_array_equal(tab[:, L.REF_P_W:L.REF_P_W + 3], np.tile([1.0, 2.0, -3.0], (11, 1)))
    assert np.all(tab[:, L.REF_YAW] == 0.7) and np.all(tab[:, L.REF_V_W:L.REF_A_W + 3] == 0.0)


def test_min_jerk_waypoints_are_consistent_and_rest_to_rest():
    times = np.array([1.0, 4.0, 6.0])
    pts = np.array([[0.0, 0.0, -1.5], [3.0, -1.0, -2.0], [3.0, 2.0, -1.0]])
    ref = MinJerkWaypoints(times, pts, yaw_rad=[0.0, 3.0, -3.0])
    tab_k = ref.reference_table(times)
    np.testing.assert_allclose(tab_k[:, :3], pts, atol=1e-12)
    np.testing.assert_allclose(tab_k[:, 3:9], 0.0, atol=1e-12)       # v = a = 0 at every waypoint
    t = np.linspace(0.0, 7.0, 70001)
    tab = ref.reference_table(t)
    np.testing.assert_allclose(_fd(tab, t, L.REF_P_W)[1:-1], tab[1:-1, L.REF_V_W:L.REF_V_W + 3], atol=1e-6)
    # the jerk jumps at the waypoints, where the central difference is off by ~15 |dp| h / T^3
    np.testing.assert_allclose(_fd(tab, t, L.REF_V_W)[1:-1], tab[1:-1, L.REF_A_W:L.REF_A_W + 3], atol=1e-3)
    # heading 3.0 -> -3.0 turns the short way (through pi), 0.28 rad, not 6 rad
    yaw = np.unwrap(tab[(t >= 4) & (t <= 6), L.REF_YAW])
    assert abs(yaw[-1] - yaw[0]) == pytest.approx(2 * np.pi - 6.0, abs=1e-9)
    assert np.all(tab[t < 1.0, 0:3] == pts[0]) and np.allclose(tab[t > 6.0, 0:3], pts[-1])


def test_velocity_profile_position_is_the_integral_of_the_velocity():
    ref = VelocityProfile((0.0, 0.0, -1.5), [0.0, 2.0, 5.0], [[0, 0, 0], [2.0, 0, 0], [2.0, 1.0, -0.5]])
    t = np.linspace(-1.0, 8.0, 90001)
    tab = ref.reference_table(t)
    np.testing.assert_allclose(_fd(tab, t, L.REF_P_W)[1:-1], tab[1:-1, L.REF_V_W:L.REF_V_W + 3], atol=1e-6)
    np.testing.assert_allclose(_fd(tab, t, L.REF_V_W)[1:-1], tab[1:-1, L.REF_A_W:L.REF_A_W + 3], atol=1e-5)
    np.testing.assert_allclose(ref.reference(2.0)[3:6], [2.0, 0, 0], atol=1e-12)
    # 0-2 s: mean speed 1 m/s -> 2 m north
    np.testing.assert_allclose(ref.reference(2.0)[0:3], [2.0, 0.0, -1.5], atol=1e-12)


def test_reference_from_a_scenario_table():
    hold = trajectory_from_reference(SimpleNamespace(kind="hold", position_m=(1.0, 0.0, -2.0), yaw_deg=90.0,
                                                     waypoints=()))
    assert hold.reference(3.0)[L.REF_YAW] == pytest.approx(np.pi / 2)
    wp = trajectory_from_reference(SimpleNamespace(kind="waypoints", position_m=(0, 0, 0), yaw_deg=0.0,
                                                   waypoints=((0.0, 0, 0, -1), (5.0, 10, 0, -1))))
    np.testing.assert_allclose(wp.reference(5.0)[0:3], [10, 0, -1])
    with pytest.raises(ValueError, match="increase"):
        MinJerkWaypoints([0.0, 0.0], [[0, 0, 0], [1, 1, 1]])
