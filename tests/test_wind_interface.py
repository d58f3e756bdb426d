"""The wind-model interface of :mod:`vtoladapt.wind`, held by the package's model and by a model
written here the way a user would write one (a wind shear that depends on the position).

The contract (see the package docstring): validated settings with a ``to_kernel()`` whose array
layout is a ``BlockLayout``; ``initial_state(params)``; a compiled
``step(params, state, t, dt, p_W, rng, out_v_wind_W)`` that writes NED m/s, advances its state in
place and draws a fixed number of standard normals per call.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pytest
from numba import njit

from vtoladapt import wind
from vtoladapt.config import ConfigError, build, setting
from vtoladapt.layout import BlockLayout, Field

# --- a user's wind model -------------------------------------------------------------------------

SHEAR_PARAMS = BlockLayout("shear wind parameters", [
    Field("SPEED", 1, "m/s", "wind speed at the reference height"),
    Field("DIR", 2, "-", "unit (N, E) vector the wind blows toward"),
    Field("SHEAR", 1, "1/s", "increase of the speed per metre of height"),
    Field("GUST_STD", 1, "m/s", "white gusting per axis"),
])
_SPEED, _DIR, _SHEAR, _GUST_STD = SHEAR_PARAMS.offsets("SPEED", "DIR", "SHEAR", "GUST_STD")
SHEAR_STATE = BlockLayout("shear wind state", [Field("STEPS", 1, "-", "steps taken")])
(_STEPS,) = SHEAR_STATE.offsets("STEPS")
SHEAR_STATE_SIZE = SHEAR_STATE.size  # kernels see plain ints, bound at import
SHEAR_DRAWS_PER_STEP = 3


@dataclass(frozen=True)
class ShearWindConfig:
    """A horizontal wind growing linearly with height, with white gusting."""

    speed_mps: float = setting("m/s", "wind speed at the reference height (p_D = 0)", default=5.0, ge=0.0)
    bearing_deg: float = setting("deg", "where the wind comes from (0: north)", default=0.0,
                                 ge=-360.0, le=360.0)
    shear_per_s: float = setting("1/s", "speed gained per metre of height", default=0.2)
    gust_std_mps: float = setting("m/s", "white gusting per axis", default=0.0, ge=0.0)

    def to_kernel(self) -> np.ndarray:
        """Parameter array (layout ``SHEAR_PARAMS``)."""
        b = math.radians(self.bearing_deg)
        return SHEAR_PARAMS.pack(SPEED=self.speed_mps, DIR=(-math.cos(b), -math.sin(b)),
                                 SHEAR=self.shear_per_s, GUST_STD=self.gust_std_mps)


@njit
def shear_initial_state(params):
    return np.zeros(SHEAR_STATE_SIZE)


@njit
def shear_step(params, state, t, dt, p_W, rng, out_v_wind_W):
    n0 = rng.standard_normal()
    n1 = rng.standard_normal()
    n2 = rng.standard_normal()
    height_m = -p_W[2]  # NED: up is -D
    speed = params[_SPEED] + params[_SHEAR] * height_m
    s = params[_GUST_STD]
    out_v_wind_W[0] = speed * params[_DIR] + s * n0
    out_v_wind_W[1] = speed * params[_DIR + 1] + s * n1
    out_v_wind_W[2] = s * n2
    state[_STEPS] += 1.0


# --- the contract, for any model ------------------------------------------------------------------

@dataclasses.dataclass
class WindModel:
    name: str
    settings: type
    table: dict
    initial_state: object
    step: object
    draws_first: int
    draws_per_step: int


MODELS = [
    WindModel("vtoladapt.wind", wind.WindConfig,
              {"fan_array": {"profile": "comparison"},
               "turbulence": {"enabled": True, "mean_wind_fraction": [0.1, 0.1, 0.05]},
               "gusts": [{"shape": "step", "start_s": 0.1, "duration_s": 0.2, "amplitude_mps": [0, 2, 0]}]},
              wind.wind_initial_state, wind.wind_step, wind.WIND_DRAWS_FIRST_STEP, wind.WIND_DRAWS_PER_STEP),
    WindModel("user shear", ShearWindConfig, {"speed_mps": 4.0, "shear_per_s": 0.3, "gust_std_mps": 0.5},
              shear_initial_state, shear_step, SHEAR_DRAWS_PER_STEP, SHEAR_DRAWS_PER_STEP),
]


def _params(model: WindModel) -> np.ndarray:
    return build(model.settings, model.table, source="<test>", section="wind").to_kernel()


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_settings_are_declared_with_unit_and_meaning(model):
    for f in dataclasses.fields(model.settings):
        assert f.metadata.get("unit") and f.metadata.get("doc"), f.name
    with pytest.raises(ConfigError, match="unknown key"):
        build(model.settings, {"no_such_setting": 1.0}, source="<test>", section="wind")


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_fixed_draws_per_step_and_reproducible(model):
    params = _params(model)
    n = 200
    rng = np.random.default_rng(11)
    a = wind.run_wind_model(model.step, params, model.initial_state(params), n, 0.004, rng,
                            p_W=(0.0, 0.0, -2.0))
    # the generator has moved by exactly the declared number of draws
    ref = np.random.default_rng(11)
    ref.standard_normal(model.draws_first + (n - 1) * model.draws_per_step)
    assert rng.standard_normal() == ref.standard_normal()
    b = wind.run_wind_model(model.step, params, model.initial_state(params), n, 0.004,
                            np.random.default_rng(11), p_W=(0.0, 0.0, -2.0))
    assert a.shape == (n, 3) and np.all(np.isfinite(a))
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_state_is_advanced_in_place_so_a_run_can_be_continued(model):
    params = _params(model)
    whole = wind.run_wind_model(model.step, params, model.initial_state(params), 100, 0.004,
                                np.random.default_rng(3))
    state = model.initial_state(params)
    rng = np.random.default_rng(3)
    first = wind.run_wind_model(model.step, params, state, 60, 0.004, rng)
    rest = wind.run_wind_model(model.step, params, state, 40, 0.004, rng, t0_s=60 * 0.004)
    np.testing.assert_array_equal(np.vstack([first, rest]), whole)


def test_user_model_sees_the_position():
    cfg = ShearWindConfig(speed_mps=4.0, bearing_deg=90.0, shear_per_s=0.3)
    params = cfg.to_kernel()
    for height_m in (0.0, 2.0, 10.0):
        v = wind.run_wind_model(shear_step, params, shear_initial_state(params), 5, 0.01,
                                np.random.default_rng(0), p_W=(1.0, 2.0, -height_m))
        # from the east, blowing west: (0, -(V0 + k h), 0)
        np.testing.assert_allclose(v, np.tile([0.0, -(4.0 + 0.3 * height_m), 0.0], (5, 1)), atol=1e-12)


def test_package_model_is_what_wind_series_runs():
    cfg = wind.WindConfig.from_mapping(MODELS[0].table)
    t, v = wind.wind_series(cfg, 50, 0.01, np.random.default_rng(4))
    params = cfg.to_kernel()
    direct = wind.run_wind_model(wind.wind_step, params, wind.wind_initial_state(params), 50, 0.01,
                                 np.random.default_rng(4))
    np.testing.assert_array_equal(v, direct)
    np.testing.assert_allclose(t, 0.01 * np.arange(50))


def test_layout_is_the_parts_blocks():
    # the composed parameter array is the parts' blocks, in the declared order, with nothing else
    sizes = [f.size for f in wind.WIND_PARAMS.fields]
    assert sizes == [wind.fan_array.FAN_PARAMS.size, 3, wind.dryden.TURBULENCE_PARAMS.size,
                     wind.gusts.GUSTS_PARAMS.size]
    assert wind.WIND_KERNEL_SIZE == sum(sizes) == wind.WindConfig().to_kernel().size
    cfg = wind.WindConfig.from_mapping({"constant_mps": [1.0, -2.0, 0.5]})
    np.testing.assert_array_equal(wind.WIND_PARAMS.view(cfg.to_kernel(), "CONST"), [1.0, -2.0, 0.5])
