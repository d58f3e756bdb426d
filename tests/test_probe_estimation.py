"""Estimation of v_i from the probe pressures: eq:aoa, recovery, noise propagation, NaN safety."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import examples
from vtoladapt.probe import (
    ProbeTip,
    SDP33Sensor,
    SingleKCalibration,
    aoa_incident_velocity,
    airspeed_angles_from_v_i,
    evaluate_calibration,
    fit_spline_calibration,
    incident_velocity_from_pressures,
    simulate_calibration_sweep,
    v_i_from_airspeed_angles,
)
from vtoladapt.probe.calibration import calibrate
from vtoladapt.probe.sensor import sensor_response

TIP = ProbeTip()


@pytest.fixture(scope="module")
def sim_models():
    """Both models fitted to a noise-free simulated sweep (cone angles up to 20 deg, 15 m/s)."""
    data = simulate_calibration_sweep(TIP, np.random.default_rng(0), V_mps=15.0, n_rings=12,
                                      n_test=300)
    return data, calibrate(data)


# ---------------------------------------------------------------------------------------------
# eq:aoa
# ---------------------------------------------------------------------------------------------

@settings(max_examples=examples(200), deadline=None)
@given(q_inf=st.floats(1e-3, 2000.0), qa=st.floats(-2000.0, 2000.0),
       qb=st.floats(-2000.0, 2000.0), rho=st.floats(0.3, 1.5), k=st.floats(0.01, 5.0))
def test_eq_aoa_magnitude_and_direction(q_inf, qa, qb, rho, k):
    """|v_i| = sqrt(2 q_inf / rho) and v_i is parallel to [q_inf, k q_beta, k q_alpha]."""
    out = np.empty(3)
    aoa_incident_velocity(q_inf, qa, qb, rho, k, out)
    assert np.linalg.norm(out) == pytest.approx(math.sqrt(2 * q_inf / rho), rel=1e-12)
    d = np.array([q_inf, k * qb, k * qa])
    assert np.linalg.norm(np.cross(out / np.linalg.norm(out), d / np.linalg.norm(d))) < 1e-12


def test_single_k_with_ideal_k_matches_the_analytic_tip_response():
    """Forward model + eq:aoa with k = 1/(2K sin 2d): tan(Theta_est) = cos(Th) sin(Th)/(1 - K
    sin^2 Th), roll angle preserved, |v| = V sqrt(1 - K sin^2 Th) (derived from the tip law)."""
    rng = np.random.default_rng(7)
    cal = SingleKCalibration(k=TIP.ideal_k(), q_inf_min_Pa=0.0, angle_limit_deg=90.0)
    th = np.radians(rng.uniform(0.0, 30.0, 400))
    ph = rng.uniform(-np.pi, np.pi, 400)
    n = np.column_stack([np.cos(th), np.sin(th) * np.sin(ph), np.sin(th) * np.cos(ph)])
    V = 14.0
    q = TIP.differential_pressures(V * n, 1.1)
    v, valid = cal.estimate(q, 1.1)
    assert np.all(valid)
    K = TIP.pressure_factor
    th_expected = np.arctan2(np.cos(th) * np.sin(th), 1 - K * np.sin(th) ** 2)
    th_est = np.arctan2(np.hypot(v[:, 1], v[:, 2]), v[:, 0])
    np.testing.assert_allclose(th_est, th_expected, atol=1e-12)
    big = th > 1e-3
    np.testing.assert_allclose(np.arctan2(v[big, 1], v[big, 2]), ph[big], atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), V * np.sqrt(1 - K * np.sin(th) ** 2),
                               rtol=1e-12)
    # so at small angles eq:aoa is exact to first order: error (K - 1) Theta^3
    small = th < math.radians(2.0)
    assert np.max(np.abs(th_est - th)[small]) < 1.3 * (K - 1) * math.radians(2.0) ** 3


# ---------------------------------------------------------------------------------------------
# forward then inverse, noise off
# ---------------------------------------------------------------------------------------------

def test_forward_then_inverse_recovers_flow_noise_off(sim_models):
    """Calibrated model on 300 random test points inside the 20 deg cone: flow angle RMS <=
    0.01 deg, max <= 0.03 deg, speed max <= 0.05 %, alpha/beta each within 0.03 deg."""
    data, models = sim_models
    m = evaluate_calibration(models["calibrated"], data, "test")
    assert m.n_valid == m.n_points == 300
    assert m.angle_rms_deg <= 0.01
    assert m.angle_max_deg <= 0.03
    assert m.speed_max_rel <= 5e-4
    assert np.max(np.abs(m.alpha_est_deg - m.alpha_true_deg)) <= 0.03
    assert np.max(np.abs(m.beta_est_deg - m.beta_true_deg)) <= 0.03
    # the fitted k is close to the analytic one, and single k is an order of magnitude worse
    s = evaluate_calibration(models["single_k"], data, "test")
    assert models["single_k"].k == pytest.approx(TIP.ideal_k(), rel=0.2)
    assert s.angle_rms_deg > 10 * m.angle_rms_deg


def test_recovery_at_other_airspeed_and_density(sim_models):
    """C_alpha, C_beta and C_q are non-dimensional: a calibration at 15 m/s, rho 1.225 holds at
    6 m/s, rho 1.0 (flow angle within 0.03 deg, speed within 0.05 %)."""
    _, models = sim_models
    rng = np.random.default_rng(8)
    th = np.radians(18.0) * np.sqrt(rng.random(200))
    ph = rng.uniform(-np.pi, np.pi, 200)
    v = 6.0 * np.column_stack([np.cos(th), np.sin(th) * np.sin(ph), np.sin(th) * np.cos(ph)])
    q = TIP.differential_pressures(v, 1.0)
    v_est, valid = models["calibrated"].estimate(q, 1.0)
    assert np.all(valid)
    cosang = np.sum(v_est * v, axis=1) / np.linalg.norm(v_est, axis=1) / 6.0
    assert np.degrees(np.max(np.arccos(np.clip(cosang, -1, 1)))) < 0.03
    np.testing.assert_allclose(np.linalg.norm(v_est, axis=1), 6.0, rtol=5e-4)


def test_kernel_grid_agrees_with_exact_spline(sim_models):
    """The kernel interpolates a grid of the spline: within 0.005 deg and 0.002 % of the exact
    spline everywhere in the calibrated disk."""
    _, models = sim_models
    cal = models["calibrated"]
    rng = np.random.default_rng(9)
    r = cal.c_scale * np.sqrt(rng.random(5000))
    ph = rng.uniform(-np.pi, np.pi, 5000)
    q = np.column_stack([np.full(5000, 100.0), 100 * r * np.cos(ph), 100 * r * np.sin(ph)])
    exact = cal.evaluate_exact(q)
    v, _ = cal.estimate(q, 1.2)
    V, a, b = airspeed_angles_from_v_i(v)
    assert np.degrees(np.max(np.abs(a - exact[:, 0]))) < 0.005
    assert np.degrees(np.max(np.abs(b - exact[:, 1]))) < 0.005
    np.testing.assert_allclose(V, np.sqrt(2 * 100.0 / (1.2 * exact[:, 2])), rtol=2e-5)


# ---------------------------------------------------------------------------------------------
# noise on: errors match the propagated sensor noise
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("model", ["single_k", "calibrated"])
def test_noise_on_errors_match_propagated_sensor_noise(sim_models, model):
    """4000 SDP33 readings at alpha 6 deg, beta -4 deg, 8 m/s: the standard deviations of the
    estimated alpha, beta and V equal J diag(s^2) J^T (J: Jacobian of the estimator, s^2 = sigma^2
    + step^2/12) within 8 % (the sampling error of a std from 4000 samples is 1.1 %), and the
    means equal the noise-free estimate within 5 standard errors."""
    _, models = sim_models
    cal = models[model].to_kernel()
    rho = 1.225
    v_true = v_i_from_airspeed_angles(8.0, math.radians(6.0), math.radians(-4.0))
    q_true = TIP.differential_pressures(v_true, rho)
    sensor = SDP33Sensor(noise_std_Pa=0.2, resolution_Pa=0.05)
    N = 4000
    readings = sensor_response(sensor, q_true, N, 0.004, np.random.default_rng(21))
    out = np.empty(3)

    def f(q):
        ok = incident_velocity_from_pressures(np.asarray(q, float), rho, cal, out)
        assert ok
        V, a, b = airspeed_angles_from_v_i(out)
        return np.array([a, b, V])

    est = np.array([f(r) for r in readings])
    y0 = f(q_true)
    J = np.empty((3, 3))
    h = 1e-3
    for j in range(3):
        dq = np.zeros(3)
        dq[j] = h
        J[:, j] = (f(q_true + dq) - f(q_true - dq)) / (2 * h)
    cov = J @ J.T * sensor.noise_variance_Pa2()
    sd_pred = np.sqrt(np.diag(cov))
    np.testing.assert_allclose(est.std(axis=0), sd_pred, rtol=0.08)
    np.testing.assert_array_less(np.abs(est.mean(axis=0) - y0), 5 * sd_pred / math.sqrt(N))


# ---------------------------------------------------------------------------------------------
# validity flag and NaN safety
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("q", [[0.0, 1.0, 1.0], [-5.0, 1.0, 1.0], [np.nan, 1.0, 1.0],
                               [100.0, np.nan, 0.0], [100.0, 0.0, np.inf], [1.0, 0.0, 0.0]])
@pytest.mark.parametrize("model", ["single_k", "calibrated"])
def test_bad_pressures_flagged_invalid_with_zero_vector(sim_models, q, model):
    """Zero, negative, NaN or infinite pressures, and q_inf below the 2 Pa limit: invalid, zeros."""
    _, models = sim_models
    out = np.full(3, 7.0)
    ok = incident_velocity_from_pressures(np.array(q, float), 1.2, models[model].to_kernel(), out)
    assert ok is False
    assert np.array_equal(out, np.zeros(3))


@pytest.mark.parametrize("model", ["single_k", "calibrated"])
def test_out_of_range_angle_is_flagged_but_finite(sim_models, model):
    _, models = sim_models
    v = v_i_from_airspeed_angles(15.0, math.radians(30.0), 0.0)  # calibrated up to 20 deg
    q = TIP.differential_pressures(v, 1.225)
    out = np.empty(3)
    assert not incident_velocity_from_pressures(q, 1.225, models[model].to_kernel(), out)
    assert np.all(np.isfinite(out)) and out[2] > 0
    v_ok = v_i_from_airspeed_angles(15.0, math.radians(10.0), 0.0)
    assert incident_velocity_from_pressures(TIP.differential_pressures(v_ok, 1.225), 1.225,
                                            models[model].to_kernel(), out)


def test_bad_density_and_malformed_calibration_arrays(sim_models):
    _, models = sim_models
    q = np.array([100.0, 5.0, -3.0])
    out = np.empty(3)
    k = models["single_k"].to_kernel()
    for rho in (0.0, -1.0, np.nan, np.inf):
        assert not incident_velocity_from_pressures(q, rho, k, out)
        assert np.array_equal(out, np.zeros(3))
    for cal in (np.zeros(0), np.array([9.0, 1.0, 1.0, 1.0]), np.array([1.0]),
                np.array([1.0, np.nan, 0.0, 1.0]), models["calibrated"].to_kernel()[:100],
                np.array([2.0] + [1.0] * 7), np.array([2.0, 0, 0, 1, 1, 1e300, 0, 1]),
                np.array([2.0, 0, 0, 1, 1, np.nan, 0, 1])):
        assert not incident_velocity_from_pressures(q, 1.2, cal, out)
        assert np.array_equal(out, np.zeros(3))


_any_float = st.floats(allow_nan=True, allow_infinity=True, width=64)
_pressure = st.one_of(_any_float, st.floats(-3000.0, 3000.0), st.sampled_from([0.0, -0.0, 1e-300,
                                                                               5e-324, 1e300]))


@settings(max_examples=examples(400), deadline=None)
@given(q=st.tuples(_pressure, _pressure, _pressure), rho=st.one_of(_any_float,
                                                                   st.floats(0.5, 1.5)))
def test_any_pressures_give_finite_output(sim_models, q, rho):
    """Invariant: for any float inputs the kernel returns a bool and a finite vector; an invalid
    reading is either the zero vector or a finite out-of-range estimate."""
    _, models = sim_models
    qa = np.array(q, dtype=float)
    for name in ("single_k", "calibrated"):
        out = np.full(3, np.nan)
        ok = incident_velocity_from_pressures(qa, rho, models[name].to_kernel(), out)
        assert isinstance(ok, bool)
        assert np.all(np.isfinite(out))
        if not (np.all(np.isfinite(qa)) and np.isfinite(rho) and rho > 0 and qa[0] > 0):
            assert not ok and np.array_equal(out, np.zeros(3))
        if ok:
            assert np.linalg.norm(out) > 0


def test_spline_fit_is_deterministic_and_smoothing_is_respected():
    data = simulate_calibration_sweep(TIP, np.random.default_rng(1), n_rings=6, n_test=10)
    a = fit_spline_calibration(data, smoothing=1e-4)
    b = fit_spline_calibration(data, smoothing=1e-4)
    assert a.smoothing == 1e-4
    assert np.array_equal(a.to_kernel(), b.to_kernel())


def test_calibrate_tip_for_the_simulator_is_deterministic_and_accurate_to_25_deg():
    """calibrate_tip: no randomness; within 0.05 deg and 0.05 % up to a 25 deg cone angle."""
    from vtoladapt.probe import calibrate_tip

    a = calibrate_tip(TIP)
    b = calibrate_tip(TIP)
    assert np.array_equal(a["calibrated"].to_kernel(), b["calibrated"].to_kernel())
    assert a["single_k"] == b["single_k"]
    data = simulate_calibration_sweep(TIP, np.random.default_rng(12), cone_max_deg=25.0,
                                      n_rings=2, n_test=300)
    m = evaluate_calibration(a["calibrated"], data, "test")
    assert m.n_valid == 300 and m.angle_max_deg < 0.05 and m.speed_max_rel < 5e-4


def test_loo_residuals_equal_explicit_refits():
    """Rippa's rule used to pick the smoothing equals refitting without each point (1e-8)."""
    from vtoladapt.probe.calibration import _tps_fit, tps_loo_residuals
    from vtoladapt.probe.estimation import tps_evaluate

    rng = np.random.default_rng(13)
    x = rng.uniform(-1, 1, (40, 2))
    y = np.column_stack([np.sin(2 * x[:, 0]) + x[:, 1] ** 2, x[:, 0] * x[:, 1],
                         rng.normal(size=40)])
    for s in (1e-6, 1e-2):
        loo = tps_loo_residuals(x, y, s)
        for i in (0, 17, 39):
            keep = np.arange(40) != i
            w, p = _tps_fit(x[keep], y[keep], s)
            pred = np.empty((1, 3))
            tps_evaluate(x[i:i + 1].copy(), x[keep].copy(), w, p, pred)
            np.testing.assert_allclose(loo[i], y[i] - pred[0], rtol=1e-8, atol=1e-10)
