"""The wind-part interface (:mod:`vtoladapt.parts`, :mod:`vtoladapt.wind.registry`), held by the
package's four parts and by a part written outside the package the way a user would write one
(``tests/example_wind_part.py``, a wind shear that depends on the height), which is registered by a
call and flown through ``simulate`` and the Gymnasium environment without recompiling the loop.

The how-to "Adding a wind model" (docs/howto/wind-and-sensors.md) is that file and the calls below; the last tests hold the README to them.
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

import example_wind_part
from vtoladapt import components, wind
from vtoladapt.config import ConfigError, build
from vtoladapt.gym import HoldEnv
from vtoladapt.gym.spaces import OBS_P_ERR, OBS_V
from vtoladapt.layout import BlockLayout
from vtoladapt.parts import Assembly, PartInfo
from vtoladapt.sim.driver import simulate
from vtoladapt.sim.loop import run_closed_loop
from vtoladapt.sim.scenario import scenario_from_mapping
from vtoladapt.wind.registry import WIND_KIND, WIND_PARTS

SHEAR = {"speed_mps": 3.0, "bearing_deg": 90.0, "shear_per_s": 0.4}


@pytest.fixture(scope="module", autouse=True)
def shear_registered():
    """The user's part, registered by a call as the how-to says (and removed after these tests)."""
    components.register("wind", PartInfo("shear", "example_wind_part", "a wind shear"))
    yield
    WIND_PARTS.unregister("shear")


PART_TABLES = {
    "fan_array": {"fan_array": {"schedule": [[0, 20], [0.2, 60]], "spin_up_time_constant_s": 0.1}},
    "constant": {"constant_mps": [1.0, -2.0, 0.5]},
    "gusts": {"gusts": [{"shape": "one_minus_cosine", "start_s": 0.05, "duration_s": 0.3,
                         "amplitude_mps": [0.0, 2.0, 0.0]}]},
    "turbulence": {"constant_mps": [6.0, 0.0, 0.0],
                   "turbulence": {"enabled": True, "mean_wind_fraction": [0.1, 0.1, 0.05]}},
    "shear": {"shear": dict(SHEAR, gust_std_mps=0.5)},
}


def _alone(part_id: str, table: dict) -> tuple[Assembly, object]:
    """The part ``part_id`` as the only part of an assembly, its settings from ``table`` (a [wind] table)."""
    cfg = wind.WindConfig.from_mapping(table)
    module = WIND_PARTS.module(part_id)
    return Assembly(WIND_KIND, [module], [module.pack(cfg.settings_of(part_id), cfg)], [part_id]), module


@pytest.mark.parametrize("part_id", list(PART_TABLES))
def test_every_part_meets_the_interface(part_id):
    module = WIND_PARTS.module(part_id)
    WIND_KIND.check(module)  # the registry's own check: layouts, draws, pack, initial_state, the signature
    assert isinstance(module.PARAMS, BlockLayout) and isinstance(module.STATE, BlockLayout)
    if module.Settings is not None:
        for f in dataclasses.fields(module.Settings):
            assert f.metadata.get("unit") and f.metadata.get("doc"), f.name
        with pytest.raises(ConfigError, match="unknown key"):
            build(module.Settings, {"no_such_setting": 1.0}, source="<test>", section=f"wind.{part_id}")


@pytest.mark.parametrize("part_id", list(PART_TABLES))
def test_fixed_draws_per_step_reproducible_and_continuable(part_id):
    parts, module = _alone(part_id, PART_TABLES[part_id])
    n = 150
    rng = np.random.default_rng(11)
    state = parts.initial_state(rng)
    after_start = np.random.default_rng(11)
    _alone(part_id, PART_TABLES[part_id])[0].initial_state(after_start)
    whole = wind.run_wind_model(parts, state, n, 0.004, rng, p_W=(0.0, 0.0, -2.0))
    # the generator has moved by exactly the declared draws per step
    after_start.standard_normal(n * module.NORMALS_PER_STEP)
    after_start.random(n * module.UNIFORMS_PER_STEP)
    assert rng.standard_normal() == after_start.standard_normal()
    assert whole.shape == (n, 3) and np.all(np.isfinite(whole))
    # same seed, same wind; and a run continued from its state is the run in one piece
    rng = np.random.default_rng(11)
    state = parts.initial_state(rng)
    first = wind.run_wind_model(parts, state, 90, 0.004, rng, p_W=(0.0, 0.0, -2.0))
    rest = wind.run_wind_model(parts, state, 60, 0.004, rng, t0_s=90 * 0.004, p_W=(0.0, 0.0, -2.0))
    # equal but for the last bit of the tick times (90 dt + k dt against (90 + k) dt)
    np.testing.assert_allclose(np.vstack([first, rest]), whole, rtol=1e-13, atol=1e-13)


def test_the_parts_add_up_to_the_composed_wind():
    # turbulence with fixed intensities and convection speed is independent of the mean wind, and it is
    # the package's only part that draws: alone it is what it is in the sum
    table = {**PART_TABLES["fan_array"], **PART_TABLES["constant"], **PART_TABLES["gusts"],
             "turbulence": {"enabled": True, "sigma_mps": [1.0, 0.5, 0.3], "convection_speed_mps": 5.0}}
    _, total = wind.wind_series(wind.WindConfig.from_mapping(table), 100, 0.004, np.random.default_rng(4))
    pieces = {}
    for part_id in ("fan_array", "constant", "gusts", "turbulence"):
        parts = _alone(part_id, table)[0]
        rng = np.random.default_rng(4)
        pieces[part_id] = wind.run_wind_model(parts, parts.initial_state(rng), 100, 0.004, rng)
    np.testing.assert_allclose(total, pieces["fan_array"] + pieces["constant"] + pieces["gusts"]
                               + pieces["turbulence"], rtol=0, atol=1e-12)
    # a user's part adds to them (turbulence off here: the user's draws would interleave with it)
    table["turbulence"] = {"enabled": False}
    _, total = wind.wind_series(wind.WindConfig.from_mapping({**table, "shear": SHEAR}), 100, 0.004,
                                np.random.default_rng(4))
    parts = _alone("shear", {"shear": SHEAR})[0]
    shear = wind.run_wind_model(parts, parts.initial_state(None), 100, 0.004, np.random.default_rng(0))
    np.testing.assert_allclose(total, pieces["fan_array"] + pieces["constant"] + pieces["gusts"] + shear,
                               rtol=0, atol=1e-12)


def test_user_part_sees_the_position():
    cfg = wind.WindConfig.from_mapping({"shear": SHEAR})
    parts = _alone("shear", {"shear": SHEAR})[0]
    assert cfg.part_ids() == ("fan_array", "constant", "gusts", "turbulence", "shear")
    for height_m in (0.0, 2.0, 10.0):
        v = wind.run_wind_model(parts, parts.initial_state(None), 5, 0.01, np.random.default_rng(0),
                                p_W=(1.0, 2.0, -height_m))
        # from the east, blowing west: (0, -(V0 + k h), 0)
        np.testing.assert_allclose(v, np.tile([0.0, -(3.0 + 0.4 * height_m), 0.0], (5, 1)), atol=1e-12)


def test_a_module_without_the_kinds_signature_is_refused(monkeypatch):
    bad = types.ModuleType("vtoladapt_test_bad_wind")
    for name in ("Settings", "PARAMS", "STATE", "NORMALS_PER_STEP", "UNIFORMS_PER_STEP", "pack", "initial_state"):
        setattr(bad, name, getattr(example_wind_part, name))
    bad.step = njit(example_wind_part.step.__wrapped__)  # compiled for whatever it is called with: no C kernel
    monkeypatch.setitem(sys.modules, bad.__name__, bad)
    with pytest.raises(TypeError, match="WIND_STEP_SIGNATURE"):
        components.register("wind", PartInfo("bad", bad.__name__))
    assert "bad" not in WIND_PARTS
    with pytest.raises(ConfigError, match=r"\[wind\] bad.*unknown key"):
        wind.WindConfig.from_mapping({"bad": {}}, source="s.toml")


# --- flown ---------------------------------------------------------------------------------------

def _hold(duration_s: float, **wind_table) -> dict:
    return {"name": "shear_hold", "vehicle": "caltech_vtol", "duration_s": duration_s, "seed": 2,
            "reference": {"kind": "hold", "position_m": [0.0, 0.0, -1.5]}, "wind": wind_table}


def test_a_registered_part_is_flown_by_simulate_without_recompiling_the_loop():
    simulate(scenario_from_mapping(_hold(0.2), "<warm-up>"))
    compiled = len(run_closed_loop.signatures)
    log = simulate(scenario_from_mapping(_hold(4.0, shear=SHEAR), "<shear>"))
    assert len(run_closed_loop.signatures) == compiled  # the same compiled loop flew the user's part
    height = -log.position_W[:, 2]
    wind_W = log.columns_like(["wind_N_mps", "wind_E_mps", "wind_D_mps"])
    # the logged wind is the shear at the logged height, tick by tick (no gusting configured)
    np.testing.assert_allclose(wind_W[:, 1], -(3.0 + 0.4 * height), rtol=0, atol=1e-12)
    np.testing.assert_allclose(wind_W[:, [0, 2]], 0.0, atol=1e-12)
    calm = simulate(scenario_from_mapping(_hold(4.0), "<calm>"))
    # the wind from the east pushes the aircraft west before the controller catches up
    assert log.position_W[:, 1].min() < calm.position_W[:, 1].min() - 1e-3


def test_a_registered_part_is_flown_by_the_gym_as_by_simulate():
    sc = scenario_from_mapping(_hold(1.0, shear=SHEAR), "<shear>")
    env = HoldEnv(scenario=sc, residual=True, randomize=False)
    obs = [env.reset(seed=3)[0]]
    for _ in range(env.max_steps - 1):
        obs.append(env.step(np.zeros(5))[0])
    env.close()
    log = simulate(env.episode_scenario)
    meas_p = log.columns_like(["meas_p_N_m", "meas_p_E_m", "meas_p_D_m"])
    ref_p = log.columns_like(["ref_p_N_m", "ref_p_E_m", "ref_p_D_m"])
    np.testing.assert_array_equal(np.array(obs)[:, OBS_P_ERR:OBS_P_ERR + 3], (meas_p - ref_p).astype(np.float32))
    calm = HoldEnv(scenario=scenario_from_mapping(_hold(1.0), "<calm>"), residual=True, randomize=False)
    calm_obs = [calm.reset(seed=3)[0]] + [calm.step(np.zeros(5))[0] for _ in range(calm.max_steps - 1)]
    calm.close()
    assert np.abs(np.array(obs)[:, OBS_V + 1] - np.array(calm_obs)[:, OBS_V + 1]).max() > 1e-3


# --- the how-to's recipe --------------------------------------------------------------------------

def test_readme_recipe_is_the_example_part_and_runs(tmp_path, monkeypatch):
    section = _section("Adding a wind model")[1]
    blocks = re.findall(r"```(\w+)\n(.*?)```", section, re.S)
    module = [b for lang, b in blocks if lang == "python" and "def step(" in b]
    assert module and module[0] == Path(example_wind_part.__file__).read_text()
    toml = [b for lang, b in blocks if lang == "toml"]
    usage = [b for lang, b in blocks if lang == "python" and "def step(" not in b]
    assert toml and usage
    (tmp_path / "shear_hold.toml").write_text(toml[0])
    monkeypatch.chdir(tmp_path)
    WIND_PARTS.unregister("shear")  # the recipe registers it itself
    try:
        namespace: dict = {"__name__": "readme"}
        exec(compile(usage[0], "docs/howto/wind-and-sensors.md", "exec"), namespace)
        result = namespace["result"]
        wind_E = result["wind_E_mps"]
        # from the east, 3 m/s + 0.4 /s x 1.5 m at the held height, gusting 0.2 m/s averaged over 1250 ticks
        assert "shear" in WIND_PARTS and not result.diverged and abs(wind_E.mean() + 3.6) < 0.05
    finally:
        if "shear" not in WIND_PARTS:
            components.register("wind", PartInfo("shear", "example_wind_part", "a wind shear"))
