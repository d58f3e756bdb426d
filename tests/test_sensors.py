"""Sensor models: ideal truth, noise statistics, biases, latency, probe lag and dropout, seeds.

Independent references: the configured standard deviations (per-sample sigma = density *
sqrt(rate)), the first-order step response ``1 - exp(-t / tau)``, a shifted copy of the truth for
the latency, the binomial law for dropouts, and gravity for the accelerometer.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, strategies as st
from scipy.spatial.transform import Rotation

from vtoladapt import layout, sensors
from vtoladapt.config import ConfigError, read_toml
from vtoladapt.frames import GRAVITY_MPS2, quat_from_euler, quat_to_rotmat
from vtoladapt.sensors import (
    AttitudeConfig,
    ImuConfig,
    MocapConfig,
    ProbeConfig,
    SensorsConfig,
    run_sensor_model,
    specific_force_B,
)
from vtoladapt.sensors import imu

DT = 0.004


class _Suite:
    """A configuration's channels and a run's state of them (what a simulation holds)."""

    def __init__(self, cfg: SensorsConfig, rng):
        self.parts = cfg.assemble()
        self.params = self.parts.params
        self.state = self.parts.initial_state(rng)

    def run(self, dt, X, F, VI, rng):
        return run_sensor_model(self.parts, self.state, dt, X, F, VI, rng)

    def imu_biases(self):
        return imu.biases(self.parts.block(self.state, "imu", of="state"))


def _truth(n: int, seed: int = 0):
    """A smoothly moving, rotating vehicle: state rows, specific force and incident velocity."""
    t = np.arange(n) * DT
    X = np.zeros((n, layout.X_SIZE))
    X[:, layout.X_P_W] = 2.0 * np.sin(0.7 * t)
    X[:, layout.X_P_W + 1] = 0.3 * t
    X[:, layout.X_P_W + 2] = -1.5 + 0.1 * np.cos(1.3 * t)
    X[:, layout.X_V_W] = 1.4 * np.cos(0.7 * t)
    X[:, layout.X_V_W + 1] = 0.3
    X[:, layout.X_V_W + 2] = -0.13 * np.sin(1.3 * t)
    for k in range(n):
        X[k, layout.X_Q_WB:layout.X_Q_WB + 4] = quat_from_euler(0.2 * t[k], 0.1 * np.sin(t[k]), 0.05)
    X[:, layout.X_OMEGA_B] = 0.1 * np.cos(t)
    X[:, layout.X_OMEGA_B + 1] = -0.2
    X[:, layout.X_OMEGA_B + 2] = 0.3 * np.sin(2 * t)
    X[:, layout.X_MOTOR:] = 0.5
    F = np.column_stack([0.5 * np.sin(t), 0.1 * np.cos(t), -GRAVITY_MPS2 + 0.2 * np.sin(3 * t)])
    VI = np.column_stack([5.0 + np.sin(0.5 * t), 0.2 * np.cos(t), 0.4 + 0.1 * np.sin(t)])
    return t, X, F, VI


def _simulate(cfg: SensorsConfig, X, F, VI, seed: int = 1, dt: float = DT):
    rng = np.random.default_rng(seed)
    suite = _Suite(cfg, rng)
    return suite.run(dt, np.ascontiguousarray(X), np.ascontiguousarray(F), np.ascontiguousarray(VI), rng), suite


def _quiet(**overrides) -> SensorsConfig:
    """Non-ideal sensors with every noise, bias and latency set to zero, then ``overrides``."""
    base = dict(
        imu=ImuConfig(gyro_noise_density_dps_rtHz=0.0, accel_noise_density_ug_rtHz=0.0,
                      gyro_bias_std_dps=0.0, accel_bias_std_mps2=0.0),
        mocap=MocapConfig(position_noise_std_m=0.0, velocity_noise_std_mps=0.0, latency_s=0.0),
        attitude=AttitudeConfig(noise_std_deg=0.0),
        probe=ProbeConfig(noise_std_mps=0.0, time_constant_s=0.0))
    base.update(overrides)
    return SensorsConfig(**base)


# --------------------------------------------------------------------------------------------------
# ideal sensors and the accelerometer convention
# --------------------------------------------------------------------------------------------------

def test_ideal_sensors_reproduce_the_truth_exactly():
    _, X, F, VI = _truth(500)
    meas, _ = _simulate(SensorsConfig.all_ideal(), X, F, VI)
    assert np.array_equal(meas[:, layout.MEAS_P_W:layout.MEAS_P_W + 3], X[:, layout.X_P_W:layout.X_P_W + 3])
    assert np.array_equal(meas[:, layout.MEAS_V_W:layout.MEAS_V_W + 3], X[:, layout.X_V_W:layout.X_V_W + 3])
    assert np.array_equal(meas[:, layout.MEAS_Q_WB:layout.MEAS_Q_WB + 4],
                          X[:, layout.X_Q_WB:layout.X_Q_WB + 4])
    assert np.array_equal(meas[:, layout.MEAS_OMEGA_B:layout.MEAS_OMEGA_B + 3],
                          X[:, layout.X_OMEGA_B:layout.X_OMEGA_B + 3])
    assert np.array_equal(meas[:, layout.MEAS_ACCEL_B:layout.MEAS_ACCEL_B + 3], F)
    assert np.array_equal(meas[:, layout.MEAS_V_I_B:layout.MEAS_V_I_B + 3], VI)
    assert np.all(meas[:, layout.MEAS_V_I_VALID] == 1.0)


def test_ideal_probe_is_valid_even_in_still_air():
    _, X, F, VI = _truth(10)
    meas, _ = _simulate(SensorsConfig.all_ideal(), X, F, np.zeros_like(VI))
    assert np.all(meas[:, layout.MEAS_V_I_VALID] == 1.0)
    assert np.all(meas[:, layout.MEAS_V_I_B:layout.MEAS_V_I_B + 3] == 0.0)


def test_specific_force_convention():
    level = quat_to_rotmat(np.array([1.0, 0.0, 0.0, 0.0]))
    np.testing.assert_allclose(specific_force_B(np.zeros(3), level), [0.0, 0.0, -9.80665], atol=0)
    np.testing.assert_allclose(specific_force_B(np.array([0.0, 0.0, GRAVITY_MPS2]), level), 0.0,
                               atol=1e-15)  # free fall reads zero
    pitch = math.radians(30.0)
    R = quat_to_rotmat(quat_from_euler(0.0, pitch, 0.0))
    g = GRAVITY_MPS2
    np.testing.assert_allclose(specific_force_B(np.zeros(3), R),
                               [g * math.sin(pitch), 0.0, -g * math.cos(pitch)], atol=1e-12)


def test_accelerometer_at_rest_level_reads_minus_g_plus_its_bias():
    n = 20000
    X = np.zeros((n, layout.X_SIZE))
    X[:, layout.X_Q_WB] = 1.0
    F = np.tile(specific_force_B(np.zeros(3), np.eye(3)), (n, 1))
    meas, state = _simulate(SensorsConfig(), X, F, np.zeros((n, 3)))
    acc = meas[:, layout.MEAS_ACCEL_B:layout.MEAS_ACCEL_B + 3]
    bias = state.imu_biases()[1]
    sigma = 175e-6 * GRAVITY_MPS2 / math.sqrt(DT)
    # mean within 5 standard errors of -g + bias
    np.testing.assert_allclose(acc.mean(axis=0), np.array([0.0, 0.0, -GRAVITY_MPS2]) + bias,
                               atol=5 * sigma / math.sqrt(n))


# --------------------------------------------------------------------------------------------------
# noise statistics and biases
# --------------------------------------------------------------------------------------------------

def test_noise_standard_deviations_match_the_configuration():
    n = 20000
    _, X, F, VI = _truth(n)
    cfg = SensorsConfig(
        imu=ImuConfig(gyro_bias_std_dps=0.0, accel_bias_std_mps2=0.0),
        mocap=MocapConfig(latency_s=0.0, position_noise_std_m=0.001, velocity_noise_std_mps=0.03),
        attitude=AttitudeConfig(noise_std_deg=0.5),
        probe=ProbeConfig(time_constant_s=0.0, noise_std_mps=0.1))
    meas, _ = _simulate(cfg, X, F, VI)
    # one sample of sigma has relative standard error 1 / sqrt(2 n) = 0.5 %; allow 3 %
    rtol = 0.03
    gyro = meas[:, layout.MEAS_OMEGA_B:layout.MEAS_OMEGA_B + 3] - X[:, layout.X_OMEGA_B:layout.X_OMEGA_B + 3]
    np.testing.assert_allclose(gyro.std(axis=0), math.radians(0.007) * math.sqrt(250.0), rtol=rtol)
    acc = meas[:, layout.MEAS_ACCEL_B:layout.MEAS_ACCEL_B + 3] - F
    np.testing.assert_allclose(acc.std(axis=0), 175e-6 * GRAVITY_MPS2 * math.sqrt(250.0), rtol=rtol)
    pos = meas[:, layout.MEAS_P_W:layout.MEAS_P_W + 3] - X[:, layout.X_P_W:layout.X_P_W + 3]
    np.testing.assert_allclose(pos.std(axis=0), 0.001, rtol=rtol)
    vel = meas[:, layout.MEAS_V_W:layout.MEAS_V_W + 3] - X[:, layout.X_V_W:layout.X_V_W + 3]
    np.testing.assert_allclose(vel.std(axis=0), 0.03, rtol=rtol)
    probe = meas[:, layout.MEAS_V_I_B:layout.MEAS_V_I_B + 3] - VI
    np.testing.assert_allclose(probe.std(axis=0), 0.1, rtol=rtol)
    # attitude: the error rotation q_true^-1 q_meas as a rotation vector in body axes
    q_t = X[:, layout.X_Q_WB:layout.X_Q_WB + 4][:, [1, 2, 3, 0]]
    q_m = meas[:, layout.MEAS_Q_WB:layout.MEAS_Q_WB + 4][:, [1, 2, 3, 0]]
    err = (Rotation.from_quat(q_t).inv() * Rotation.from_quat(q_m)).as_rotvec()
    np.testing.assert_allclose(err.std(axis=0), math.radians(0.5), rtol=rtol)
    np.testing.assert_allclose(err.mean(axis=0), 0.0, atol=5 * math.radians(0.5) / math.sqrt(n))
    np.testing.assert_allclose(np.linalg.norm(meas[:, layout.MEAS_Q_WB:layout.MEAS_Q_WB + 4], axis=1),
                               1.0, atol=1e-14)


def test_biases_are_constant_over_a_run_and_drawn_with_the_configured_std():
    n = 5000
    _, X, F, VI = _truth(n)
    cfg = SensorsConfig(imu=ImuConfig(gyro_bias_std_dps=0.3, accel_bias_std_mps2=0.08))
    rng = np.random.default_rng(4)
    suite = _Suite(cfg, rng)
    b0 = np.concatenate(suite.imu_biases())
    out = suite.run(DT, X, F, VI, rng)
    # no random walk configured: the biases do not change
    assert np.array_equal(np.concatenate(suite.imu_biases()), b0)
    gyro_err = (out[:, layout.MEAS_OMEGA_B:layout.MEAS_OMEGA_B + 3]
                - X[:, layout.X_OMEGA_B:layout.X_OMEGA_B + 3])
    sg = math.radians(0.007) * math.sqrt(250.0)
    np.testing.assert_allclose(gyro_err.mean(axis=0), b0[:3], atol=5 * sg / math.sqrt(n))
    # the biases across many runs have the configured spread (3000 draws: 1.3 % s.e.; allow 7 %)
    draws = np.array([np.concatenate(_Suite(cfg, np.random.default_rng(s)).imu_biases()) for s in range(3000)])
    np.testing.assert_allclose(draws[:, :3].std(axis=0), math.radians(0.3), rtol=0.07)
    np.testing.assert_allclose(draws[:, 3:].std(axis=0), 0.08, rtol=0.07)


def test_bias_random_walk_grows_with_the_square_root_of_time():
    n, runs, q = 250, 400, 0.02   # 1 s per run, accel bias walk 0.02 m/s^2/sqrt(s)
    cfg = _quiet(imu=ImuConfig(gyro_noise_density_dps_rtHz=0.0, accel_noise_density_ug_rtHz=0.0,
                               gyro_bias_std_dps=0.0, accel_bias_std_mps2=0.0,
                               accel_bias_random_walk_mps2_rts=q))
    _, X, F, VI = _truth(n)
    finals = np.array([_simulate(cfg, X, F, VI, seed=s)[1].imu_biases()[1] for s in range(runs)])
    # std after 1 s is q; s.e. of a std from 1200 values is ~2 %; allow 10 %
    assert finals.std() == pytest.approx(q * math.sqrt(n * DT), rel=0.10)


def test_outputs_saturate_at_the_full_scale_range():
    _, X, F, VI = _truth(5)
    X[:, layout.X_OMEGA_B] = math.radians(3000.0)
    F[:, 0] = 400.0
    meas, _ = _simulate(_quiet(), X, F, VI)
    assert np.all(meas[:, layout.MEAS_OMEGA_B] == pytest.approx(math.radians(2000.0)))
    assert np.all(meas[:, layout.MEAS_ACCEL_B] == pytest.approx(16.0 * GRAVITY_MPS2))


# --------------------------------------------------------------------------------------------------
# latency and lags
# --------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("latency_s, ticks", [(0.0, 0), (0.004, 1), (0.012, 3), (0.02, 5),
                                              (0.0119, 3), (0.1, 25)])
def test_mocap_latency_delays_by_whole_ticks(latency_s, ticks):
    assert sensors.latency_ticks(latency_s, DT) == ticks
    n = 400
    _, X, F, VI = _truth(n)
    meas, _ = _simulate(_quiet(mocap=MocapConfig(position_noise_std_m=0.0,
                                                 velocity_noise_std_mps=0.0,
                                                 latency_s=latency_s)), X, F, VI)
    p_true = X[:, layout.X_P_W:layout.X_P_W + 3]
    v_true = X[:, layout.X_V_W:layout.X_V_W + 3]
    p_meas = meas[:, layout.MEAS_P_W:layout.MEAS_P_W + 3]
    v_meas = meas[:, layout.MEAS_V_W:layout.MEAS_V_W + 3]
    shifted = np.concatenate([np.repeat(p_true[:1], ticks, axis=0), p_true[:n - ticks]])
    assert np.array_equal(p_meas, shifted)
    shifted_v = np.concatenate([np.repeat(v_true[:1], ticks, axis=0), v_true[:n - ticks]])
    assert np.array_equal(v_meas, shifted_v)


def test_latency_beyond_the_ring_buffer_raises():
    _, X, F, VI = _truth(3)
    with pytest.raises(ValueError, match="ring buffer"):
        _simulate(_quiet(mocap=MocapConfig(latency_s=0.2)), X, F, VI, dt=0.001)


def test_probe_lag_is_the_exact_first_order_step_response():
    tau = 0.003
    n, k0 = 40, 5
    _, X, F, _ = _truth(n)
    VI = np.zeros((n, 3))
    VI[k0:] = [8.0, -1.0, 0.5]
    cfg = _quiet(probe=ProbeConfig(noise_std_mps=0.0, time_constant_s=tau, min_airspeed_mps=0.0))
    meas, _ = _simulate(cfg, X, F, VI)
    v = meas[:, layout.MEAS_V_I_B:layout.MEAS_V_I_B + 3]
    assert np.all(v[:k0] == 0.0)
    j = np.arange(n - k0)
    # input held at its tick value over the preceding tick: y(t_k0 + j dt) = 1 - exp(-(j+1) dt / tau)
    expected = 1.0 - np.exp(-(j + 1) * DT / tau)
    np.testing.assert_allclose(v[k0:] / np.array([8.0, -1.0, 0.5]), expected[:, None] * np.ones(3),
                               rtol=1e-12)


def test_differentiated_mocap_velocity():
    n = 2000
    _, X, F, VI = _truth(n)
    # no noise, no filter: the backward difference of the true positions
    cfg = _quiet(mocap=MocapConfig(position_noise_std_m=0.0, velocity_from="differentiate",
                                   velocity_lowpass_hz=0.0, latency_s=0.0))
    meas, _ = _simulate(cfg, X, F, VI)
    p = X[:, layout.X_P_W:layout.X_P_W + 3]
    np.testing.assert_allclose(meas[1:, layout.MEAS_V_W:layout.MEAS_V_W + 3], np.diff(p, axis=0) / DT,
                               rtol=1e-9, atol=1e-9)
    # white position noise differenced: sigma_v = sqrt(2) sigma_p / dt (allow 4 %)
    cfg = _quiet(mocap=MocapConfig(position_noise_std_m=0.0005, velocity_from="differentiate",
                                   velocity_lowpass_hz=0.0, latency_s=0.0))
    meas, _ = _simulate(cfg, X, F, VI)
    err = meas[1:, layout.MEAS_V_W:layout.MEAS_V_W + 3] - np.diff(p, axis=0) / DT
    np.testing.assert_allclose(err.std(axis=0), math.sqrt(2.0) * 0.0005 / DT, rtol=0.04)
    # with the 20 Hz low-pass the noise drops (first-order filter on white-ish noise)
    cfg = _quiet(mocap=MocapConfig(position_noise_std_m=0.0005, velocity_from="differentiate",
                                   velocity_lowpass_hz=20.0, latency_s=0.0))
    meas, _ = _simulate(cfg, X, F, VI)
    err_f = meas[100:, layout.MEAS_V_W:layout.MEAS_V_W + 3] - X[100:, layout.X_V_W:layout.X_V_W + 3]
    assert np.all(err_f.std(axis=0) < 0.5 * err.std(axis=0))


# --------------------------------------------------------------------------------------------------
# probe validity
# --------------------------------------------------------------------------------------------------

def test_dropout_rate_matches_the_probability():
    n, p = 20000, 0.2
    _, X, F, VI = _truth(n)
    meas, _ = _simulate(SensorsConfig(probe=ProbeConfig(dropout_probability=p)), X, F, VI)
    invalid = meas[:, layout.MEAS_V_I_VALID] == 0.0
    se = math.sqrt(p * (1 - p) / n)
    assert abs(invalid.mean() - p) < 5 * se
    v = meas[:, layout.MEAS_V_I_B:layout.MEAS_V_I_B + 3]
    assert np.all(np.isnan(v[invalid])) and np.all(np.isfinite(v[~invalid]))
    assert set(np.unique(meas[:, layout.MEAS_V_I_VALID])) == {0.0, 1.0}
    # every other channel stays finite through dropouts
    others = np.delete(meas, np.s_[layout.MEAS_V_I_B:layout.MEAS_V_I_B + 3], axis=1)
    assert np.all(np.isfinite(others))


def test_minimum_airspeed_flags_readings_invalid_but_keeps_them():
    n = 200
    _, X, F, _ = _truth(n)
    VI = np.zeros((n, 3))
    VI[:, 0] = np.linspace(0.0, 2.0, n)
    cfg = _quiet(probe=ProbeConfig(noise_std_mps=0.0, time_constant_s=0.0, min_airspeed_mps=1.0))
    meas, _ = _simulate(cfg, X, F, VI)
    valid = meas[:, layout.MEAS_V_I_VALID]
    np.testing.assert_array_equal(valid, (VI[:, 0] >= 1.0).astype(float))
    np.testing.assert_array_equal(meas[:, layout.MEAS_V_I_B], VI[:, 0])


# --------------------------------------------------------------------------------------------------
# seeds and draw order
# --------------------------------------------------------------------------------------------------

def test_same_seed_identical_different_seed_different():
    _, X, F, VI = _truth(300)
    cfg = SensorsConfig(probe=ProbeConfig(dropout_probability=0.1))
    a, _ = _simulate(cfg, X, F, VI, seed=3)
    b, _ = _simulate(cfg, X, F, VI, seed=3)
    c, _ = _simulate(cfg, X, F, VI, seed=4)
    assert np.array_equal(a, b, equal_nan=True)
    assert not np.allclose(a, c, equal_nan=True)


@given(st.booleans(), st.booleans(), st.booleans(), st.booleans())
def test_making_one_sensor_ideal_leaves_the_others_noise_unchanged(imu, mocap, att, probe):
    _, X, F, VI = _truth(50)
    noisy, _ = _simulate(SensorsConfig(), X, F, VI, seed=9)
    cfg = SensorsConfig(imu=ImuConfig(ideal=imu), mocap=MocapConfig(ideal=mocap),
                        attitude=AttitudeConfig(ideal=att), probe=ProbeConfig(ideal=probe))
    mixed, _ = _simulate(cfg, X, F, VI, seed=9)
    blocks = {"imu": (imu, slice(layout.MEAS_OMEGA_B, layout.MEAS_ACCEL_B + 3)),
              "mocap": (mocap, slice(layout.MEAS_P_W, layout.MEAS_V_W + 3)),
              "att": (att, slice(layout.MEAS_Q_WB, layout.MEAS_Q_WB + 4)),
              "probe": (probe, slice(layout.MEAS_V_I_B, layout.MEAS_V_I_VALID + 1))}
    for name, (ideal, cols) in blocks.items():
        if not ideal:
            assert np.array_equal(mixed[:, cols], noisy[:, cols]), name


def test_fixed_number_of_draws_per_step():
    _, X, F, VI = _truth(20)
    for cfg in (SensorsConfig(), SensorsConfig.all_ideal()):
        rng = np.random.default_rng(2)
        _Suite(cfg, rng).run(DT, X, F, VI, rng)
        ref = np.random.default_rng(2)
        ref.standard_normal(sensors.SENSOR_DRAWS_INITIAL)
        for _ in range(20):
            for channel in (sensors.imu, sensors.mocap, sensors.attitude, sensors.airflow_probe):
                ref.standard_normal(channel.NORMALS_PER_STEP)
                for _ in range(channel.UNIFORMS_PER_STEP):
                    ref.random()
        assert rng.random() == ref.random()


# --------------------------------------------------------------------------------------------------
# configuration
# --------------------------------------------------------------------------------------------------

def test_sensors_table_loads_from_toml(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("""
[sensors.imu]
gyro_noise_density_dps_rtHz = 0.01
accel_bias_std_mps2 = 0.0
[sensors.mocap]
latency_s = 0.02
velocity_from = "differentiate"
[sensors.attitude]
ideal = true
[sensors.probe]
model = "ideal_noise"
dropout_probability = 0.01
""")
    cfg = SensorsConfig.from_mapping(read_toml(path)["sensors"], source=str(path))
    assert cfg.imu.gyro_noise_density_dps_rtHz == 0.01 and cfg.attitude.ideal
    assert cfg.mocap.velocity_from == "differentiate" and cfg.probe.dropout_probability == 0.01
    assert cfg.imu.gyro_bias_std_dps == 0.1   # defaults fill the rest
    assert "ideal_noise" in cfg.probe.describe()
    parts = cfg.assemble()
    assert parts.ids == ("imu", "mocap", "attitude", "probe")
    # the suite's parameters are its channels' blocks, nothing else (the ideal_noise probe has no calibration)
    assert [f.size for f in parts.params_layout.fields] == [
        sensors.imu.PARAMS.size, sensors.mocap.PARAMS.size, sensors.attitude.PARAMS.size,
        sensors.airflow_probe.PARAMS.size]
    assert cfg.to_kernel().size == parts.params_layout.size


@pytest.mark.parametrize("data, fragment", [
    ({"probe": {"calibration": "magic"}}, r"\[sensors.probe\] calibration = 'magic'"),
    ({"probe": {"sdp33": {"noise_std_Pa": -1.0}}}, r"noise_std_Pa = -1.0"),
    ({"probe": {"model": "magic"}}, r"model = 'magic'"),
    ({"imu": {"gyro_noise": 1.0}}, r"\[sensors.imu\] gyro_noise.*unknown key"),
    ({"mocap": {"latency_s": -0.01}}, r"latency_s = -0.01: out of range"),
    ({"probe": {"dropout_probability": 1.5}}, r"dropout_probability = 1.5: out of range"),
    ({"mocap": {"velocity_from": "kalman"}}, r"velocity_from = 'kalman'"),
    ({"barometer": {}}, r"\[sensors\] barometer.*unknown key"),
])
def test_invalid_sensor_tables_raise_config_error(data, fragment):
    with pytest.raises(ConfigError, match=fragment):
        SensorsConfig.from_mapping(data, source="s.toml")



README_EXAMPLE = """
[wind]
constant_mps = [0.0, 0.0, 0.0]

[wind.fan_array]
schedule = [[0, 0], [5, 0], [5, 30], [15, 30], [15, 40], [20, 40], [20, 50], [25, 50],
            [25, 60], [30, 60], [30, 70], [40, 70], [40, 0]]
spin_up_time_constant_s = 1.0

[wind.turbulence]
enabled = true
mean_wind_fraction = [0.05, 0.05, 0.03]
altitude_m = 1.5

[[wind.gusts]]
shape = "one_minus_cosine"
start_s = 22.0
duration_s = 2.0
amplitude_mps = [0.0, 2.0, 0.0]

[sensors.imu]
gyro_bias_std_dps = 0.1

[sensors.mocap]
latency_s = 0.012
velocity_from = "direct"

[sensors.attitude]
noise_std_deg = 0.2

[sensors.probe]
model = "ideal_noise"
noise_std_mps = 0.1
time_constant_s = 0.003
dropout_probability = 0.001
min_airspeed_mps = 1.0
"""


def test_readme_example_loads(tmp_path):
    from vtoladapt import wind

    path = tmp_path / "example.toml"
    path.write_text(README_EXAMPLE)
    data = read_toml(path)
    w = wind.WindConfig.from_mapping(data["wind"], source=str(path))
    s = SensorsConfig.from_mapping(data["sensors"], source=str(path))
    assert w.fan_array.linear_breakpoints() == wind.comparison_schedule()
    assert w.gusts[0].amplitude_mps == (0.0, 2.0, 0.0)
    assert s.probe.dropout_probability == 0.001
    w.to_kernel()
    s.to_kernel()
