"""A user's control law from a module outside the package (``tests/example_law.py``), registered by a call.

README "Adding a controller" is this recipe: the module meets the law interface, one
``vtoladapt.components.register("law", INFO)`` after import, and then configuration validation, the
scenario files, the experiments, ``simulate`` and the Gymnasium environment take it (no file of the
package names it). References: with the plant equal to the controller's model (unmodelled effects
off, ideal sensors) the law's eq:f_ctrl with gain ``1.2 K_v`` returns the aircraft to the setpoint,
so after 6 s the position error is below 2 cm; the environment's zero-residual run is the
simulator's log bit for bit (it calls the law through its address, the simulator through the
function object).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import example_law
from test_gym import short_hold
from vtoladapt import components, simulate
from vtoladapt.config import ConfigError
from vtoladapt.control.registry import CONTROLLERS, controller_ids
from vtoladapt.control.settings import ControllerConfig, controller_config_from_mapping
from vtoladapt.sim.scenario import ExperimentConfig, scenario_from_mapping

UNMODELLED_OFF = {"stall": False, "side_force": False, "pusher_advance_ratio_loss": False,
                  "rotor_reaction_torque": False, "aero_rate_damping": False}
IDEAL_SENSORS = {name: {"ideal": True} for name in ("imu", "mocap", "attitude", "probe")}


@pytest.fixture(scope="module")
def registered():
    """The example law registered (after the package was imported), removed again afterwards."""
    assert "example" not in CONTROLLERS
    components.register("law", example_law.INFO)
    yield example_law.INFO
    CONTROLLERS.unregister("example")


def test_the_registered_law_is_validated_like_a_shipped_one(registered):
    assert "example" in controller_ids() and CONTROLLERS["example"].law is example_law
    cfg = controller_config_from_mapping({"kind": "example", "example": {"gain_scale": 1.2}}, "user.toml")
    assert cfg.example.gain_scale == 1.2 and cfg.info.label == "Example (scaled K_v)"
    assert ControllerConfig(kind="example", example=example_law.ExampleSettings(gain_scale=2.0)).example.gain_scale == 2.0
    with pytest.raises(ConfigError, match=r"\[controller\] gain_scale = 1.2: moved to .*\[controller\.example\] gain_scale"):
        controller_config_from_mapping({"gain_scale": 1.2}, "user.toml")
    with pytest.raises(ConfigError, match=r"\[controller\.example\] gain_scale = 0.0: out of range"):
        controller_config_from_mapping({"kind": "example", "example": {"gain_scale": 0.0}}, "user.toml")
    assert "example" in ExperimentConfig().controllers                    # the default compares every law
    assert ExperimentConfig(kind="comparison", controllers=("composite", "example")).controllers[-1] == "example"


def test_the_command_line_lists_and_runs_the_registered_law(registered, capsys):
    from vtoladapt.cli import load_run_scenario, main

    assert main(["controllers"]) == 0
    assert any(line.split()[:1] == ["example"] and "a user's minimal law" in line
               for line in capsys.readouterr().out.splitlines())
    sc = load_run_scenario("gym_hold", duration_s=0.1, controller="example")
    assert sc.controller.kind == "example"


def _hover_scenario(kind: str, duration_s: float, **controller):
    return scenario_from_mapping({
        "name": "example-law", "vehicle": "caltech_vtol", "duration_s": duration_s, "seed": 2,
        "initial": {"position_m": [0.2, 0.0, -1.2]}, "reference": {"position_m": [0.0, 0.0, -1.5]},
        "plant": UNMODELLED_OFF, "sensors": IDEAL_SENSORS, "controller": {"kind": kind, **controller}},
        "tests/test_extension_law.py")


def test_the_registered_law_flies_in_simulate(registered):
    r = simulate(_hover_scenario("example", 6.0, example={"gain_scale": 1.2}))
    assert r.diverged_at_s is None
    err = np.linalg.norm(r.position_error_W[-1])
    assert err < 0.02, err
    # the law's own diagnostics column is logged, named as it declared it
    K_v_N = ControllerConfig().K_v[0]
    np.testing.assert_array_equal(r["example_K_v_N_per_s"], 1.2 * K_v_N)
    assert "integrator_N_mps2" not in r                                  # no other law's columns


def test_the_registered_law_flies_in_the_gym_as_in_simulate(registered):
    """residual=True, zero action: the environment's run is the simulator's, bit for bit."""
    from vtoladapt.gym import HoldEnv
    from vtoladapt.gym.spaces import OBS_CMD

    data = short_hold(0.4)
    data["controller"] = {"kind": "example", "example": {"gain_scale": 1.2}}
    env = HoldEnv(scenario=data, residual=True)
    obs, _ = env.reset(seed=3)
    observations = [obs]
    for _ in range(env.max_steps - 1):
        obs, _, terminated, truncated, _ = env.step(np.zeros(5))
        assert not terminated and not truncated
        observations.append(obs)
    log = simulate(env.episode_scenario)
    assert env.episode_scenario.controller.kind == "example"
    u_max = env._batch.u_max
    np.testing.assert_array_equal(np.array(observations)[:, OBS_CMD + 1],
                                  (2.0 * log["cmd_u_z_frac"] / u_max - 1.0).astype(np.float32))
    assert log["cmd_u_z_frac"].min() > 0.3                                # the law flew the aircraft


def test_a_law_that_misses_the_interface_is_refused_at_registration():
    bad = dataclasses.replace(example_law.INFO, id="broken", module="test_extension_law")
    with pytest.raises(TypeError, match="missing Settings, PARAMS, STATE, DIAG, fill_params, init_state, update"):
        components.register("law", bad)
    assert "broken" not in CONTROLLERS
