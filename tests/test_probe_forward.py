"""Forward model of the probe: tip pressures against potential-flow closed forms; SDP33 sensor."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vtoladapt.probe import (
    ProbeError,
    ProbeTip,
    SDP33Sensor,
    probe_differential_pressures,
    sdp33_sensor_step,
    v_i_from_airspeed_angles,
)
from vtoladapt.probe.sensor import sensor_response


def _random_directions(rng, n, cone_max_deg=60.0):
    th = np.radians(cone_max_deg) * np.sqrt(rng.random(n))
    ph = rng.uniform(-np.pi, np.pi, n)
    return np.column_stack([np.cos(th), np.sin(th) * np.sin(ph), np.sin(th) * np.cos(ph)])


# ---------------------------------------------------------------------------------------------
# tip
# ---------------------------------------------------------------------------------------------

def test_sphere_potential_flow_stagnation_and_equator():
    """Cp = 1 at the stagnation point and 1 - 9/4 = -1.25 at 90 deg (sphere in potential flow)."""
    tip = ProbeTip(port_angle_deg=45.0)
    rho, V = 1.2, 10.0
    q = 0.5 * rho * V ** 2
    # flow straight on: centre port at stagnation
    p = tip.port_pressures([V, 0.0, 0.0], rho)
    assert p[0] == pytest.approx(q, rel=1e-14)
    # peripheral ports at 45 deg: Cp = 1 - 2.25 * 0.5
    assert p[1:5] == pytest.approx(np.full(4, q * (1 - 2.25 * 0.5)), rel=1e-14)
    # flow arriving from below (alpha = +90 deg): bottom port normal is 45 deg from the flow, the
    # centre port is at 90 deg (the sphere's equator, Cp = -1.25)
    p = tip.port_pressures([0.0, 0.0, V], rho)
    assert p[0] == pytest.approx(-1.25 * q, rel=1e-14)
    # a port whose normal is the flow direction sees the full dynamic pressure
    tip_n = ProbeTip(port_angle_deg=30.0)
    v = V * np.array([math.cos(math.radians(30)), 0.0, math.sin(math.radians(30))])
    assert tip_n.port_pressures(v, rho)[1] == pytest.approx(q, rel=1e-13)


@pytest.mark.parametrize("port_angle_deg,K,cps", [(45.0, 2.25, 0.0), (30.0, 2.25, 0.05),
                                                   (60.0, 1.8, -0.02)])
def test_differential_pressures_match_closed_forms(port_angle_deg, K, cps):
    """q_alpha = 2K sin(2d) q n_x n_z, q_beta = 2K sin(2d) q n_x n_y,
    q_inf = q (1 - K (1 - n_x^2) - C_ps) (the tip law's closed forms, for directions where every
    port is windward; leeward ports read the wake law)."""
    rng = np.random.default_rng(3)
    tip = ProbeTip(port_angle_deg=port_angle_deg, pressure_factor=K,
                   static_port_coefficient=cps)
    n = _random_directions(rng, 4000)
    c, s = math.cos(math.radians(port_angle_deg)), math.sin(math.radians(port_angle_deg))
    windward = (n[:, 0] >= 0) & (c * n[:, 0] - s * np.abs(n[:, 2]) >= 0) & (c * n[:, 0] - s * np.abs(n[:, 1]) >= 0)
    n = n[windward][:500]
    assert len(n) == 500
    V = rng.uniform(1.0, 30.0, 500)
    rho = rng.uniform(0.9, 1.3, 500)
    v = n * V[:, None]
    q_dyn = 0.5 * rho * V ** 2
    q = tip.differential_pressures(v, rho)
    g = 2 * K * math.sin(2 * math.radians(port_angle_deg))
    np.testing.assert_allclose(q[:, 1], g * q_dyn * n[:, 0] * n[:, 2], rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(q[:, 2], g * q_dyn * n[:, 0] * n[:, 1], rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(q[:, 0], q_dyn * (1 - K * (1 - n[:, 0] ** 2) - cps), rtol=1e-12,
                               atol=1e-10)
    assert tip.ideal_k() == pytest.approx(1.0 / g, rel=1e-15)


def test_signs_follow_eq_aoa_convention():
    """Positive alpha -> q_alpha > 0 (bottom port faces the air); positive beta -> q_beta > 0."""
    tip = ProbeTip()
    for a_deg, b_deg in [(5, 0), (-5, 0), (0, 4), (0, -4), (10, -7)]:
        v = v_i_from_airspeed_angles(12.0, math.radians(a_deg), math.radians(b_deg))
        q = tip.differential_pressures(v, 1.2)
        assert np.sign(q[1]) == np.sign(a_deg)
        assert np.sign(q[2]) == np.sign(b_deg)
        assert q[0] > 0


def test_zero_and_nonfinite_velocity():
    tip = ProbeTip().to_kernel()
    out = np.empty(3)
    probe_differential_pressures(np.zeros(3), 1.2, tip, out)
    assert np.array_equal(out, np.zeros(3))
    probe_differential_pressures(np.array([np.nan, 0.0, 0.0]), 1.2, tip, out)
    assert np.all(np.isnan(out))


def test_tip_rejects_bad_settings():
    with pytest.raises(ProbeError, match="port_angle_deg = 95"):
        ProbeTip(port_angle_deg=95.0)
    with pytest.raises(ProbeError, match="pressure_factor"):
        ProbeTip(pressure_factor=float("nan"))


# ---------------------------------------------------------------------------------------------
# sensor
# ---------------------------------------------------------------------------------------------

def test_lag_step_response_is_exact_first_order():
    """Noise, offset and quantisation off: y_k = Q (1 - exp(-k dt / tau)) to rounding."""
    tau, dt = 1.0e-3, 2.5e-4
    s = SDP33Sensor(noise_std_Pa=0.0, resolution_Pa=0.0, time_constant_s=tau)
    y = sensor_response(s, [100.0, -50.0, 20.0], 40, dt, np.random.default_rng(0),
                        state=np.zeros(3))
    t = dt * np.arange(1, 41)
    expected = np.outer(1 - np.exp(-t / tau), [100.0, -50.0, 20.0])
    np.testing.assert_allclose(y, expected, rtol=0, atol=1e-11)
    # the default sensor reaches 95 % of a step in 3 ms ("< 3 ms" response)
    d = SDP33Sensor()
    assert 1 - math.exp(-3e-3 / d.time_constant_s) >= 0.95


def test_noise_offset_statistics_and_quantisation():
    """Mean = q + offset (within 4 sigma/sqrt(N)); std = sqrt(sigma^2 + step^2/12) within 3 %."""
    offsets = (0.3, -0.2, 0.1)
    s = SDP33Sensor(noise_std_Pa=0.2, offset_Pa=offsets, resolution_Pa=0.05)
    q = np.array([100.0, 3.3, -7.1])
    N = 20000
    y = sensor_response(s, q, N, 0.004, np.random.default_rng(42))
    sd = math.sqrt(s.noise_variance_Pa2())
    np.testing.assert_array_less(np.abs(y.mean(axis=0) - (q + offsets)), 4 * sd / math.sqrt(N))
    np.testing.assert_allclose(y.std(axis=0), sd, rtol=0.03)
    k = y / 0.05
    assert np.max(np.abs(k - np.round(k))) < 1e-6


def test_saturation_and_nonfinite_input():
    s = SDP33Sensor(noise_std_Pa=0.0, time_constant_s=0.0)
    y = sensor_response(s, [5000.0, -5000.0, 10.0], 3, 0.004, np.random.default_rng(0))
    assert np.array_equal(y[-1], [1500.0, -1500.0, 10.0])
    state = np.array([1.0, 2.0, 3.0])
    out = np.empty(3)
    sdp33_sensor_step(np.array([np.nan, 2.0, np.inf]), state, s.to_kernel(), 0.004,
                      np.random.default_rng(0), out)
    assert np.isnan(out[0]) and np.isnan(out[2]) and out[1] == 2.0
    assert state[0] == 1.0 and state[2] == 3.0


def test_same_seed_same_output_bit_for_bit():
    s = SDP33Sensor.with_random_offsets(np.random.default_rng(5))
    a = sensor_response(s, [80.0, 4.0, -2.0], 500, 0.004, np.random.default_rng(11))
    b = sensor_response(s, [80.0, 4.0, -2.0], 500, 0.004, np.random.default_rng(11))
    c = sensor_response(s, [80.0, 4.0, -2.0], 500, 0.004, np.random.default_rng(12))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert s == SDP33Sensor.with_random_offsets(np.random.default_rng(5))


def test_sensor_rejects_bad_settings():
    with pytest.raises(ProbeError, match="noise_std_Pa = -0.1"):
        SDP33Sensor(noise_std_Pa=-0.1)
    with pytest.raises(ProbeError, match="offset_Pa"):
        SDP33Sensor(offset_Pa=(0.0, 0.0))


def test_settings_build_from_config_tables():
    """The dataclasses follow the project's config conventions (unknown keys rejected)."""
    from vtoladapt.config import ConfigError, build

    tip = build(ProbeTip, {"port_angle_deg": 40.0}, source="vehicle.toml", section="probe.tip")
    assert tip.port_angle_deg == 40.0
    with pytest.raises(ConfigError, match="unknown key"):
        build(SDP33Sensor, {"noise_Pa": 0.1}, source="vehicle.toml", section="probe.sensor")


def test_a_flow_from_behind_reads_the_wake_not_a_headwind():
    """Straight from behind every port sits in the separated wake: the centre port reads the base
    pressure CP_WAKE q (not a stagnation q), the pairs read nothing, and the q_inf the probe's
    calibration needs is negative, so the reading is refused as a real probe's would be."""
    from vtoladapt.probe.tip import CP_WAKE, ProbeTip, probe_differential_pressures

    tip = ProbeTip()
    rho, V = 1.2, 8.0
    q = np.empty(3)
    probe_differential_pressures(np.array([-V, 0.0, 0.0]), rho, tip.to_kernel(), q)
    np.testing.assert_allclose(q, [CP_WAKE * 0.5 * rho * V * V, 0.0, 0.0], atol=1e-12)
    probe_differential_pressures(np.array([V, 0.0, 0.0]), rho, tip.to_kernel(), q)
    assert q[0] == pytest.approx(0.5 * rho * V * V)  # head-on: the full dynamic pressure


@pytest.mark.parametrize("K", [1.0, 2.25, 3.0])
def test_port_pressure_is_continuous_at_ninety_degrees_and_potential_flow_windward(K):
    """Cp(theta) is continuous across 90 deg, equals 1 - K sin^2 on the windward side and reaches
    CP_WAKE at 180 deg."""
    from vtoladapt.probe.tip import CP_WAKE, port_pressure_coefficient

    eps = 1e-9
    assert port_pressure_coefficient(eps, K) == pytest.approx(port_pressure_coefficient(-eps, K), abs=1e-8)
    for theta in np.radians([0.0, 20.0, 45.0, 65.0, 89.0]):
        assert port_pressure_coefficient(np.cos(theta), K) == pytest.approx(1.0 - K * np.sin(theta) ** 2)
    assert port_pressure_coefficient(-1.0, K) == pytest.approx(CP_WAKE)
    thetas = np.radians(np.linspace(0.0, 180.0, 3601))
    cp = np.array([port_pressure_coefficient(np.cos(t), K) for t in thetas])
    assert np.max(np.abs(np.diff(cp))) < 4 * K * np.radians(0.05)  # no jump anywhere
