"""The sensor-channel interface (:mod:`vtoladapt.parts`, :mod:`vtoladapt.sensors.registry`), held by the
package's four channels and by a channel written outside the package the way a user would write one
(``tests/example_sensor.py``, a GNSS receiver in place of the motion capture), which is registered by a
call and flown through ``simulate`` and the Gymnasium environment without recompiling the loop.

The how-to "Adding a sensor" (docs/howto/wind-and-sensors.md) is that file and the calls below; the last test holds the README to them.
"""
from __future__ import annotations

import dataclasses
import re
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from doc_pages import section as _section
from numba import njit

import example_sensor
from vtoladapt import components, layout, sensors
from vtoladapt.config import ConfigError, build
from vtoladapt.frames import quat_from_euler
from vtoladapt.gym import HoldEnv
from vtoladapt.gym.spaces import OBS_P_ERR, OBS_SIZE
from vtoladapt.parts import Assembly, PartInfo
from vtoladapt.sim.driver import simulate
from vtoladapt.sim.loop import run_closed_loop
from vtoladapt.sim.scenario import scenario_from_mapping
from vtoladapt.sensors.registry import SENSOR_CHANNELS, SENSOR_KIND

GNSS = {"position_noise_std_m": 0.0, "position_quantum_m": 0.25, "velocity_noise_std_mps": 0.0, "rate_hz": 50.0}


@pytest.fixture(scope="module", autouse=True)
def gnss_registered():
    """The user's channel, registered by a call as the how-to says (and removed after these tests)."""
    components.register("sensor", PartInfo("gnss", "example_sensor", "a GNSS receiver"))
    yield
    SENSOR_CHANNELS.unregister("gnss")


CHANNEL_TABLES = {
    "imu": {"imu": {"gyro_bias_random_walk_dps_rts": 0.1}},
    "mocap": {"mocap": {"velocity_from": "differentiate"}},
    "attitude": {},
    "probe": {"probe": {"dropout_probability": 0.1}},
    "gnss": {"channels": ["imu", "gnss", "attitude", "probe"], "gnss": {"position_noise_std_m": 0.3}},
}
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


def _alone(channel: str, table: dict) -> tuple[Assembly, object]:
    """Channel ``channel`` as the only channel of an assembly, its settings from ``table`` ([sensors])."""
    cfg = sensors.SensorsConfig.from_mapping(table)
    module = SENSOR_CHANNELS.module(channel)
    ctx = sensors.SensorContext()
    return Assembly(SENSOR_KIND, [module], [module.pack(cfg.settings_of(channel), ctx)], [channel]), module


@pytest.mark.parametrize("channel", list(CHANNEL_TABLES))
def test_every_channel_meets_the_interface(channel):
    module = SENSOR_CHANNELS.module(channel)
    SENSOR_KIND.check(module)  # the registry's own check: layouts, draws, pack, initial_state, WRITES, signature
    assert set(module.WRITES) <= {f.name for f in layout.MEASUREMENT.fields}
    for f in dataclasses.fields(module.Settings):
        assert f.metadata.get("unit") and f.metadata.get("doc"), f.name
    with pytest.raises(ConfigError, match="unknown key"):
        build(module.Settings, {"no_such_setting": 1.0}, source="<test>", section=f"sensors.{channel}")


@pytest.mark.parametrize("channel", list(CHANNEL_TABLES))
def test_writes_its_fields_only_with_fixed_draws_reproducible_and_continuable(channel):
    parts, module = _alone(channel, CHANNEL_TABLES[channel])
    X, F, VI = _truth()
    rng = np.random.default_rng(5)
    state = parts.initial_state(rng)
    after_start = np.random.default_rng(5)
    _alone(channel, CHANNEL_TABLES[channel])[0].initial_state(after_start)
    meas = sensors.run_sensor_model(parts, state, DT, X, F, VI, rng)
    for _ in range(N):
        after_start.standard_normal(module.NORMALS_PER_STEP)
        after_start.random(module.UNIFORMS_PER_STEP)
    assert rng.standard_normal() == after_start.standard_normal()
    # exactly its fields written (finite, but the probe's values on a flagged dropout), the others untouched
    mine = np.zeros(layout.MEAS_SIZE, dtype=bool)
    for name in module.WRITES:
        mine[layout.MEASUREMENT.slice(name)] = True
    assert np.all(np.isnan(meas[:, ~mine]))
    if channel == "probe":
        valid = meas[:, layout.MEAS_V_I_VALID]
        assert set(np.unique(valid)) <= {0.0, 1.0} and 0 < valid.sum() < N
        assert np.all(np.isfinite(meas[valid == 1.0][:, layout.MEASUREMENT.slice("V_I_B")]))
    else:
        assert np.all(np.isfinite(meas[:, mine]))
    rng = np.random.default_rng(5)
    state = parts.initial_state(rng)
    first = sensors.run_sensor_model(parts, state, DT, X[:70], F[:70], VI[:70], rng)
    rest = sensors.run_sensor_model(parts, state, DT, X[70:], F[70:], VI[70:], rng, t0_s=70 * DT)
    np.testing.assert_allclose(np.vstack([first, rest]), meas, rtol=1e-13, atol=1e-13, equal_nan=True)


def test_the_user_channel_fixes_at_its_rate_and_quantises():
    parts = _alone("gnss", {"channels": ["imu", "gnss", "attitude", "probe"], "gnss": GNSS})[0]
    X, F, VI = _truth()
    meas = sensors.run_sensor_model(parts, parts.initial_state(None), DT, X, F, VI, np.random.default_rng(0))
    p_true = X[:, layout.STATE.slice("P_W")]
    p_meas = meas[:, layout.MEASUREMENT.slice("P_W")]
    # a fix every 5 ticks at 50 Hz, held in between: tick k reads the truth of tick 5 (k // 5), quantised
    held = p_true[5 * (np.arange(N) // 5)]
    np.testing.assert_allclose(p_meas, 0.25 * np.round(held / 0.25), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(meas[:, layout.MEASUREMENT.slice("V_W")], X[5 * (np.arange(N) // 5), 3:6])


def test_a_suite_writes_each_field_once():
    with pytest.raises(ConfigError, match="'mocap' and 'gnss' both write the measurement's P_W"):
        sensors.SensorsConfig.from_mapping({"channels": ["imu", "mocap", "gnss", "attitude", "probe"]}, source="s.toml")
    with pytest.raises(ConfigError, match="nothing writes the measurement's P_W, V_W"):
        sensors.SensorsConfig.from_mapping({"channels": ["imu", "attitude", "probe"]}, source="s.toml")
    with pytest.raises(ConfigError, match=r"\[sensors.gnss\]: the channel is not in \[sensors\] channels"):
        sensors.SensorsConfig.from_mapping({"gnss": {}}, source="s.toml")
    with pytest.raises(ConfigError, match="'sonar': not a registered sensor channel"):
        sensors.SensorsConfig.from_mapping({"channels": ["imu", "sonar"]}, source="s.toml")


def test_a_module_without_the_kinds_signature_is_refused(monkeypatch):
    bad = types.ModuleType("vtoladapt_test_bad_sensor")
    for name in ("Settings", "PARAMS", "STATE", "NORMALS_PER_STEP", "UNIFORMS_PER_STEP", "pack", "initial_state",
                 "WRITES"):
        setattr(bad, name, getattr(example_sensor, name))
    bad.step = njit(example_sensor.step.__wrapped__)  # compiled for whatever it is called with: no C kernel
    monkeypatch.setitem(sys.modules, bad.__name__, bad)
    with pytest.raises(TypeError, match="SENSOR_STEP_SIGNATURE"):
        components.register("sensor", PartInfo("bad", bad.__name__))
    del bad.WRITES
    bad.step = example_sensor.step
    with pytest.raises(TypeError, match="missing WRITES"):
        components.register("sensor", PartInfo("bad", bad.__name__))
    assert "bad" not in SENSOR_CHANNELS


# --- flown ---------------------------------------------------------------------------------------

def _hold(duration_s: float, sensors_table: dict) -> dict:
    return {"name": "gnss_hold", "vehicle": "caltech_vtol", "duration_s": duration_s, "seed": 4,
            "reference": {"kind": "hold", "position_m": [0.0, 0.0, -1.5]}, "sensors": sensors_table}


GNSS_SUITE = {"channels": ["imu", "gnss", "attitude", "probe"], "gnss": GNSS}


def test_a_registered_channel_is_flown_by_simulate_without_recompiling_the_loop():
    simulate(scenario_from_mapping(_hold(0.2, {}), "<warm-up>"))
    compiled = len(run_closed_loop.signatures)
    log = simulate(scenario_from_mapping(_hold(3.0, GNSS_SUITE), "<gnss>"))
    assert len(run_closed_loop.signatures) == compiled and not log.diverged
    p_meas = log.columns_like(["meas_p_N_m", "meas_p_E_m", "meas_p_D_m"])
    # what the controller saw is the receiver's: quarter-metre steps, held five ticks at 50 Hz
    np.testing.assert_allclose(p_meas / 0.25, np.round(p_meas / 0.25), rtol=0, atol=1e-9)
    held = log.position_W[5 * (np.arange(len(log)) // 5)]
    np.testing.assert_allclose(p_meas, 0.25 * np.round(held / 0.25), rtol=0, atol=1e-12)
    calm = simulate(scenario_from_mapping(_hold(3.0, {}), "<mocap>"))
    assert np.abs(log["cmd_u_z_frac"] - calm["cmd_u_z_frac"]).max() > 1e-3


def test_a_registered_channel_is_flown_by_the_gym_as_by_simulate():
    sc = scenario_from_mapping(_hold(1.0, GNSS_SUITE), "<gnss>")
    env = HoldEnv(scenario=sc, residual=True, randomize=False)
    obs = [env.reset(seed=3)[0]]
    for _ in range(env.max_steps - 1):
        obs.append(env.step(np.zeros(5))[0])
    env.close()
    log = simulate(env.episode_scenario)
    meas_p = log.columns_like(["meas_p_N_m", "meas_p_E_m", "meas_p_D_m"])
    ref_p = log.columns_like(["ref_p_N_m", "ref_p_E_m", "ref_p_D_m"])
    np.testing.assert_array_equal(np.array(obs)[:, OBS_P_ERR:OBS_P_ERR + 3], (meas_p - ref_p).astype(np.float32))
    # the observation is the receiver's quantised fix
    np.testing.assert_allclose(meas_p / 0.25, np.round(meas_p / 0.25), rtol=0, atol=1e-9)


# --- the how-to's recipe --------------------------------------------------------------------------

def test_readme_recipe_is_the_example_channel_and_runs(tmp_path, monkeypatch):
    section = _section("Adding a sensor")[1]
    blocks = re.findall(r"```(\w+)\n(.*?)```", section, re.S)
    module = [b for lang, b in blocks if lang == "python" and "def step(" in b]
    assert module and module[0] == Path(example_sensor.__file__).read_text()
    toml = [b for lang, b in blocks if lang == "toml"]
    usage = [b for lang, b in blocks if lang == "python" and "def step(" not in b]
    assert toml and usage
    (tmp_path / "gnss_hold.toml").write_text(toml[0])
    monkeypatch.chdir(tmp_path)
    SENSOR_CHANNELS.unregister("gnss")  # the recipe registers it itself
    try:
        namespace: dict = {"__name__": "readme"}
        exec(compile(usage[0], "docs/howto/wind-and-sensors.md", "exec"), namespace)
        result = namespace["result"]
        assert "gnss" in SENSOR_CHANNELS and not result.diverged
        assert namespace["obs"].shape == (OBS_SIZE,) and np.isfinite(namespace["obs"]).all()
    finally:
        if "gnss" not in SENSOR_CHANNELS:
            components.register("sensor", PartInfo("gnss", "example_sensor", "a GNSS receiver"))
