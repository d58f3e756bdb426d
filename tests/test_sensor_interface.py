"""The sensor interface of :mod:`vtoladapt.sensors`, held by the package's sensors and by a sensor
suite written here the way a user would write one (a GNSS-class receiver instead of motion
capture: position quantised and noisy, velocity noisy, everything else perfect).

The contract (see the module docstring): validated settings with a ``to_kernel()`` whose layout
is a ``BlockLayout``; ``initial_state(params, rng)``; a compiled
``step(params, state, t, dt, x_true, specific_force_B, v_i_B_true, rng, meas_out)`` that writes
every slot of the measurement (:data:`vtoladapt.layout.MEASUREMENT`), advances its state in
place and draws a fixed number of random numbers per call.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numba import njit

from vtoladapt import layout, sensors
from vtoladapt.config import ConfigError, build, setting
from vtoladapt.frames import quat_from_euler
from vtoladapt.layout import BlockLayout, Field

# --- a user's sensor suite ------------------------------------------------------------------------

GNSS_PARAMS = BlockLayout("GNSS suite parameters", [
    Field("POS_STD", 1, "m", "position noise per axis"),
    Field("POS_QUANTUM", 1, "m", "position resolution"),
    Field("VEL_STD", 1, "m/s", "velocity noise per axis"),
])
_POS_STD, _POS_QUANTUM, _VEL_STD = GNSS_PARAMS.offsets("POS_STD", "POS_QUANTUM", "VEL_STD")
GNSS_DRAWS_PER_STEP = 6


@dataclasses.dataclass(frozen=True)
class GnssSuiteConfig:
    """A GNSS receiver for position and velocity; perfect IMU, attitude and airflow probe."""

    position_noise_std_m: float = setting("m", "position noise per axis", default=0.5, ge=0.0)
    position_quantum_m: float = setting("m", "position resolution", default=0.01, gt=0.0)
    velocity_noise_std_mps: float = setting("m/s", "velocity noise per axis", default=0.05, ge=0.0)

    def to_kernel(self) -> np.ndarray:
        """Parameter array (layout ``GNSS_PARAMS``)."""
        return GNSS_PARAMS.pack(POS_STD=self.position_noise_std_m, POS_QUANTUM=self.position_quantum_m,
                                VEL_STD=self.velocity_noise_std_mps)


@njit
def gnss_initial_state(params, rng):
    return np.zeros(1)


@njit
def gnss_step(params, state, t, dt, x_true, specific_force_B, v_i_B_true, rng, meas_out):
    q = params[_POS_QUANTUM]
    for j in range(3):
        p = x_true[layout.X_P_W + j] + params[_POS_STD] * rng.standard_normal()
        meas_out[layout.MEAS_P_W + j] = q * np.round(p / q)
    for j in range(3):
        meas_out[layout.MEAS_V_W + j] = x_true[layout.X_V_W + j] + params[_VEL_STD] * rng.standard_normal()
    for j in range(4):
        meas_out[layout.MEAS_Q_WB + j] = x_true[layout.X_Q_WB + j]
    for j in range(3):
        meas_out[layout.MEAS_OMEGA_B + j] = x_true[layout.X_OMEGA_B + j]
        meas_out[layout.MEAS_ACCEL_B + j] = specific_force_B[j]
        meas_out[layout.MEAS_V_I_B + j] = v_i_B_true[j]
    meas_out[layout.MEAS_V_I_VALID] = 1.0


# --- the contract, for any sensor suite ----------------------------------------------------------

@dataclasses.dataclass
class SensorModel:
    name: str
    settings: type
    table: dict
    initial_state: object
    step: object
    normals_initial: int
    normals_per_step: int
    uniforms_per_step: int


MODELS = [
    SensorModel("vtoladapt.sensors", sensors.SensorsConfig,
                {"probe": {"dropout_probability": 0.1}, "mocap": {"velocity_from": "differentiate"}},
                sensors.sensors_initial_state, sensors.sensors_step, sensors.SENSOR_DRAWS_INITIAL,
                sensors.SENSOR_NORMALS_PER_STEP, sensors.SENSOR_UNIFORMS_PER_STEP),
    SensorModel("user GNSS", GnssSuiteConfig, {"position_noise_std_m": 0.3},
                gnss_initial_state, gnss_step, 0, GNSS_DRAWS_PER_STEP, 0),
]

N = 120
DT = 0.004


def _truth(n=N):
    t = DT * np.arange(n)
    X = np.array([layout.pack_state([np.sin(s), 2.0 * s, -1.0], [np.cos(s), 2.0, 0.0],
                                    quat_from_euler(0.3 * s, 0.05, -0.02), [0.1, -0.2, 0.3], [0.5] * 5)
                  for s in t])
    F = np.tile([0.2, -0.1, -9.8], (n, 1))
    VI = np.tile([8.0, 0.3, 0.6], (n, 1))
    return X, F, VI


def _params(model):
    return build(model.settings, model.table, source="<test>", section="sensors").to_kernel()


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_settings_are_declared_with_unit_and_meaning(model):
    for f in dataclasses.fields(model.settings):
        assert f.metadata.get("unit") and f.metadata.get("doc"), f.name
    with pytest.raises(ConfigError, match="unknown key"):
        build(model.settings, {"no_such_setting": 1.0}, source="<test>", section="sensors")


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_writes_every_slot_with_fixed_draws(model):
    params = _params(model)
    X, F, VI = _truth()
    rng = np.random.default_rng(5)
    state = model.initial_state(params, rng)
    meas = sensors.run_sensor_model(model.step, params, state, DT, X, F, VI, rng)
    ref = np.random.default_rng(5)
    ref.standard_normal(model.normals_initial)
    for _ in range(N):
        ref.standard_normal(model.normals_per_step)
        ref.random(model.uniforms_per_step)
    assert rng.standard_normal() == ref.standard_normal()
    assert meas.shape == (N, layout.MEAS_SIZE)
    # every slot written: finite, except the probe's values on a flagged dropout
    valid = meas[:, layout.MEAS_V_I_VALID]
    assert set(np.unique(valid)) <= {0.0, 1.0}
    probe = layout.MEASUREMENT.slice("V_I_B")
    others = np.delete(meas, np.arange(probe.start, probe.stop), axis=1)
    assert np.all(np.isfinite(others))
    assert np.all(np.isfinite(meas[valid == 1.0, probe]))
    q = meas[:, layout.MEASUREMENT.slice("Q_WB")]
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_reproducible_and_continuable(model):
    params = _params(model)
    X, F, VI = _truth()
    rng = np.random.default_rng(8)
    whole = sensors.run_sensor_model(model.step, params, model.initial_state(params, rng), DT, X, F, VI, rng)
    rng = np.random.default_rng(8)
    state = model.initial_state(params, rng)
    first = sensors.run_sensor_model(model.step, params, state, DT, X[:70], F[:70], VI[:70], rng)
    rest = sensors.run_sensor_model(model.step, params, state, DT, X[70:], F[70:], VI[70:], rng, t0_s=70 * DT)
    np.testing.assert_array_equal(np.vstack([first, rest]), whole)


def test_user_suite_quantises_and_passes_the_rest_through():
    cfg = GnssSuiteConfig(position_noise_std_m=0.0, position_quantum_m=0.25, velocity_noise_std_mps=0.0)
    params = cfg.to_kernel()
    X, F, VI = _truth()
    rng = np.random.default_rng(0)
    meas = sensors.run_sensor_model(gnss_step, params, gnss_initial_state(params, rng), DT, X, F, VI, rng)
    p_true = X[:, layout.STATE.slice("P_W")]
    p_meas = meas[:, layout.MEASUREMENT.slice("P_W")]
    np.testing.assert_allclose(p_meas, 0.25 * np.round(p_true / 0.25))
    assert np.max(np.abs(p_meas - p_true)) <= 0.125 + 1e-12
    np.testing.assert_array_equal(meas[:, layout.MEASUREMENT.slice("ACCEL_B")], F)
    np.testing.assert_array_equal(meas[:, layout.MEASUREMENT.slice("V_I_B")], VI)
