"""The Gymnasium environment vtoladapt/Hold-v0: API conformance, seeding, the vector version,
the residual mode against the simulator, reward and termination, randomisation, bad input."""
from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import vtoladapt.gym as vgym
from conftest import examples
from vtoladapt.config import ConfigError
from vtoladapt.gym import HoldEnv, HoldVectorEnv
from vtoladapt.gym.settings import RANDOMIZED_COEFFICIENTS, episode_scenario, make_config
from vtoladapt.gym.spaces import (ACTION_FIELDS, OBS_CMD, OBS_P_ERR, OBS_Q, OBS_SIZE, OBS_V,
                                  OBS_V_I, OBS_V_I_VALID, OBSERVATION_FIELDS, markdown_table)
from vtoladapt.sim.scenario import load_scenario
from vtoladapt.sim.driver import CHUNK_S, simulate


def short_hold(duration_s: float) -> dict:
    """The shipped gym_hold scenario as a mapping, shortened (the wind's times scaled with it)."""
    import tomllib

    from vtoladapt.sim.scenario import SCENARIO_DIR

    data = tomllib.loads((SCENARIO_DIR / "gym_hold.toml").read_text())
    scale = duration_s / data["duration_s"]
    data["duration_s"] = duration_s
    data["wind"]["fan_array"]["schedule"] = [[t * scale, u] for t, u in data["wind"]["fan_array"]["schedule"]]
    data["wind"]["fan_array"]["spin_up_time_constant_s"] *= scale
    return data


def test_registered_and_made_through_gymnasium():
    env = gym.make(vgym.ENV_ID, scenario=short_hold(0.1))
    assert isinstance(env.unwrapped, HoldEnv)
    venv = gym.make_vec(vgym.ENV_ID, num_envs=2, scenario=short_hold(0.1), workers=1)
    assert isinstance(venv, HoldVectorEnv) and venv.num_envs == 2
    env.close()
    venv.close()


# direct mode's check (18 s) runs with `make test-slow`; residual mode's covers the same env code
# path in the default suite (CI's 10-minute budget)
@pytest.mark.parametrize("residual", [pytest.param(False, marks=pytest.mark.slow), True])
def test_env_checker_passes(residual):
    env = HoldEnv(residual=residual)
    check_env(env, skip_render_check=True)
    env.close()


def test_spaces_documented_and_observations_inside():
    env = HoldEnv(scenario=short_hold(0.2))
    assert env.observation_space.dtype == np.float32 and env.observation_space.shape == (OBS_SIZE,)
    assert env.action_space.dtype == np.float32 and env.action_space.shape == (5,)
    assert np.all(env.action_space.low == -1.0) and np.all(env.action_space.high == 1.0)
    assert sum(f.size for f in OBSERVATION_FIELDS) == OBS_SIZE
    assert (OBS_P_ERR, OBS_V, OBS_Q, OBS_V_I, OBS_V_I_VALID, OBS_CMD) == (0, 3, 6, 13, 16, 17)
    assert all(f.unit for f in OBSERVATION_FIELDS + ACTION_FIELDS)
    assert markdown_table(OBSERVATION_FIELDS).count("\n") == len(OBSERVATION_FIELDS) + 1
    obs, _ = env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(50):
        assert env.observation_space.contains(obs)
        q = obs[OBS_Q:OBS_Q + 4].astype(float)
        assert abs(np.linalg.norm(q) - 1.0) < 1e-3  # an attitude quaternion, not clipped garbage
        obs, *_ = env.step(rng.uniform(-0.05, 0.05, 5).astype(np.float32))


def test_same_seed_same_episode_and_other_seed_differs():
    def episode(seed):
        env = HoldEnv(scenario=short_hold(0.2), residual=True)
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(1)
        out = [obs]
        for _ in range(40):
            out.append(env.step(rng.uniform(-1, 1, 5))[0])
        return np.array(out), env.episode_scenario

    a, sc_a = episode(7)
    b, sc_b = episode(7)
    c, sc_c = episode(8)
    assert np.array_equal(a, b) and sc_a == sc_b
    assert not np.array_equal(a, c) and sc_a.seed != sc_c.seed


def test_zero_residual_is_the_simulators_run_bit_for_bit():
    """residual=True, action 0: the observations are the simulator's log of the same scenario."""
    duration = 1.0
    assert duration <= CHUNK_S
    env = HoldEnv(scenario=short_hold(duration), residual=True)  # plant and wind randomised too
    obs, info = env.reset(seed=11)
    n = env.max_steps
    observations, true_err = [obs], []
    for _ in range(n - 1):
        obs, _, terminated, truncated, info = env.step(np.zeros(5))
        assert not terminated and not truncated
        observations.append(obs)
        true_err.append(info["p_err_true_m"])
    log = simulate(env.episode_scenario)
    assert len(log) == n
    meas_p = log.columns_like(["meas_p_N_m", "meas_p_E_m", "meas_p_D_m"])
    ref_p = log.columns_like(["ref_p_N_m", "ref_p_E_m", "ref_p_D_m"])
    observations = np.array(observations)
    np.testing.assert_array_equal(observations[:, OBS_P_ERR:OBS_P_ERR + 3], (meas_p - ref_p).astype(np.float32))
    np.testing.assert_array_equal(observations[:, OBS_V_I:OBS_V_I + 3],
                                  log.columns_like(["meas_v_i_x_mps", "meas_v_i_y_mps",
                                                    "meas_v_i_z_mps"]).astype(np.float32))
    u_max = env._batch.u_max
    np.testing.assert_array_equal(observations[:, OBS_CMD + 1], (2.0 * log["cmd_u_z_frac"] / u_max - 1.0)
                                  .astype(np.float32))
    np.testing.assert_array_equal(np.array(true_err), log.position_W[1:] - ref_p[1:])


def test_vector_env_matches_single_envs_through_autoreset():
    """Each environment of the batch is the single environment with seed + i, across episodes."""
    n, steps, seed = 3, 130, 40
    scenario = short_hold(0.2)  # 50 steps: two autoresets in 130 steps
    venv = HoldVectorEnv(num_envs=n, workers=2, scenario=scenario, residual=True)
    singles = [HoldEnv(scenario=scenario, residual=True) for _ in range(n)]
    rng = np.random.default_rng(5)
    actions = rng.uniform(-1, 1, (steps, n, 5))
    v_obs, _ = venv.reset(seed=seed)
    s_obs = np.array([env.reset(seed=seed + i)[0] for i, env in enumerate(singles)])
    np.testing.assert_array_equal(v_obs, s_obs)
    done = np.zeros(n, dtype=bool)
    n_resets = 0
    for k in range(steps):
        v_obs, v_rew, v_term, v_trunc, _ = venv.step(actions[k])
        for i, env in enumerate(singles):
            if done[i]:  # NEXT_STEP autoreset: this step resets, reward 0, not done
                obs, _ = env.reset()
                rew, term, trunc = 0.0, False, False
                n_resets += 1
            else:
                obs, rew, term, trunc, _ = env.step(actions[k, i])
            np.testing.assert_array_equal(v_obs[i], obs)
            assert (v_rew[i], v_term[i], v_trunc[i]) == (rew, term, trunc)
            done[i] = term or trunc
    assert n_resets >= 2 * n
    assert [s.seed for s in venv.episode_scenarios] == [env.episode_scenario.seed for env in singles]
    v_obs, _ = venv.reset()  # unseeded: every environment continues its own generator
    np.testing.assert_array_equal(v_obs, np.array([env.reset()[0] for env in singles]))
    venv.close()


def test_reward_and_termination_follow_the_true_position():
    """Direct mode, motors off: the aircraft falls; reward and termination recomputed from info."""
    d_max, cost = 0.3, 0.5
    env = HoldEnv(scenario=short_hold(2.0), max_position_error_m=d_max, action_cost=cost)
    env.reset(seed=2)
    action = np.array([-1.0, -1.0, 0.0, 0.0, 0.0])  # zero throttle, zero moment
    for k in range(env.max_steps):
        obs, reward, terminated, truncated, info = env.step(action)
        np.testing.assert_allclose(obs[OBS_CMD:OBS_CMD + 5], action, atol=1e-6)  # applied command
        err = info["p_err_true_m"]
        expected = 1.0 - min(np.linalg.norm(err) / d_max, 1.0) - cost * np.sum(action ** 2) / 5
        assert reward == pytest.approx(expected, abs=1e-12)
        assert terminated == bool(np.any(np.abs(err) > d_max))
        if terminated:
            break
    assert terminated and not truncated and err[2] > d_max  # fell (NED: down is +z)
    # free fall from rest with the rotors spinning down: about g t^2 / 2 after t seconds
    assert 0.5 * 9.81 * info["t_s"] ** 2 > d_max
    with pytest.raises(RuntimeError, match="reset"):
        env.step(action)


def test_truncation_after_the_scenario_duration():
    env = HoldEnv(scenario=short_hold(0.1), residual=True)
    env.reset(seed=0)
    flags = [env.step(np.zeros(5))[2:4] for _ in range(env.max_steps)]
    assert env.max_steps == 25
    assert flags[-1] == (False, True) and all(f == (False, False) for f in flags[:-1])


def test_randomisation_draws_from_the_stated_distributions():
    cfg = make_config({"coefficient_sigmas": 2.0, "fan_throttle_scale": (0.25, 0.75),
                       "array_bearing_deg": (-30.0, 10.0)})
    base = cfg.scenario
    vehicle = base.load_vehicle()
    rng = np.random.default_rng(123)
    draws = [episode_scenario(cfg, base, rng) for _ in range(400)]
    for name in ("CTz", "CL0", "CD1"):
        mean = getattr(vehicle.force_model, name)
        std = getattr(vehicle.force_model_std, name)
        z = np.array([(getattr(d.plant.coefficients, name) - mean) / (2.0 * std) for d in draws])
        assert abs(z.mean()) < 4 / math.sqrt(len(z)) and abs(z.std() - 1.0) < 0.12
    base_max = max(u for _, u in base.wind.fan_array.schedule)
    scale = np.array([max(u for _, u in d.wind.fan_array.schedule) / base_max for d in draws])
    assert scale.min() >= 0.25 and scale.max() <= 0.75 and abs(scale.mean() - 0.5) < 0.03
    bearing = np.array([d.wind.fan_array.array_bearing_deg for d in draws])
    assert bearing.min() >= -30 and bearing.max() <= 10 and abs(bearing.mean() + 10) < 1.5
    assert len({d.seed for d in draws}) == len(draws)
    fixed = make_config({"randomize": False})
    assert episode_scenario(fixed, fixed.scenario, rng).replace(seed=0) == fixed.scenario.replace(seed=0)
    assert set(RANDOMIZED_COEFFICIENTS) == {"CTx", "CTz", "CS", "k1", "k2", "CD0", "CD1", "CD2", "CL0", "CL1"}


@pytest.mark.parametrize("kwargs, words", [
    ({"residual_scal": 0.1}, ["residual_scal", "did you mean 'residual_scale'"]),
    ({"residual_scale": 2.0}, ["residual_scale", "2"]),
    ({"fan_throttle_scale": (0.9, 0.5)}, ["fan_throttle_scale", "lo <= hi"]),
    ({"scenario": "no_such_scenario"}, ["no_such_scenario", "shipped scenarios"]),
    ({"scenario": 3}, ["scenario = 3"]),
    ({"render_mode": "human"}, ["render_mode", "human"]),
    ({"max_position_error_m": -1.0}, ["max_position_error_m", "-1"]),
    ({"array_bearing_deg": (10.0,)}, ["array_bearing_deg"]),
])
def test_bad_keyword_arguments_give_one_line_errors(kwargs, words):
    with pytest.raises(ConfigError) as err:
        HoldEnv(**kwargs)
    message = str(err.value)
    assert "\n" not in message
    for w in words:
        assert w in message


def test_bad_actions_and_vector_arguments():
    env = HoldEnv(scenario=short_hold(0.1))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(np.zeros(4))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full(5, np.nan))
    with pytest.raises(ConfigError, match="num_envs"):
        HoldVectorEnv(num_envs=0, scenario=short_hold(0.1))
    venv = HoldVectorEnv(num_envs=2, workers=1, scenario=short_hold(0.1))
    with pytest.raises(ConfigError, match="seeds for 2"):
        venv.reset(seed=[1, 2, 3])
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"\(2, 5\)"):
        venv.step(np.zeros((3, 5)))
    venv.close()


def test_actions_outside_the_space_are_clipped_to_it():
    """An action beyond [-1, 1] steps exactly as its clipped value (command and reward), single and vector."""
    big = np.array([5.0, -3.0, 1.5, -1.0001, 0.25])
    for residual in (False, True):
        envs = [HoldEnv(scenario=short_hold(0.1), residual=residual, action_cost=0.3) for _ in range(2)]
        out = [env.reset(seed=3) and env.step(a) for env, a in zip(envs, (big, np.clip(big, -1.0, 1.0)))]
        np.testing.assert_array_equal(out[0][0], out[1][0])
        assert out[0][1] == out[1][1]
        venvs = [HoldVectorEnv(num_envs=2, workers=1, residual=residual, scenario=short_hold(0.1),
                               action_cost=0.3) for _ in range(2)]
        vout = [v.reset(seed=3) and v.step(np.stack([a, -a])) for v, a in zip(venvs, (big, np.clip(big, -1.0, 1.0)))]
        np.testing.assert_array_equal(vout[0][0], vout[1][0])
        np.testing.assert_array_equal(vout[0][1], vout[1][1])
        for v in venvs:
            v.close()


def test_shipped_scenario_is_the_default_and_runs_as_written():
    sc = load_scenario("gym_hold")
    assert HoldEnv().config.scenario == sc
    assert sc.n_ticks == 5000 and sc.controller.kind == "composite"


_RESIDUAL_ENV = {}


@settings(max_examples=examples(25))
@given(actions=hnp.arrays(np.float64, (12, 5), elements=st.floats(-1.0, 1.0)), seed=st.integers(0, 2**31))
def test_residual_command_and_reward_bounds_hold_for_any_action(actions, seed):
    """Residual mode: the applied command is the controller's plus the scaled residual, clipped;
    observations stay in the space and the reward in [-c_a, 1], whatever the actions."""
    if "env" not in _RESIDUAL_ENV:
        _RESIDUAL_ENV["env"] = HoldEnv(scenario=short_hold(0.2), residual=True, residual_scale=0.5,
                                       action_cost=0.3)
    env = _RESIDUAL_ENV["env"]
    obs, _ = env.reset(seed=seed)
    b = env._batch
    applied = b.chunks[0].block(0, "cmd")  # the command of the tick just stepped (a view)
    for a in actions:
        u_ctrl = (obs[OBS_CMD:OBS_CMD + 2].astype(float) + 1.0) / 2.0 * b.u_max
        tau_ctrl = obs[OBS_CMD + 2:OBS_CMD + 5].astype(float) * b.tau_max
        obs, reward, terminated, truncated, _ = env.step(a)
        expected_u = np.clip(u_ctrl + a[:2] * 0.5 * b.u_max, 0.0, b.u_max)
        expected_tau = np.clip(tau_ctrl + a[2:] * 0.5 * b.tau_max, -b.tau_max, b.tau_max)
        np.testing.assert_allclose(applied[:2], expected_u, atol=1e-6 * b.u_max)
        np.testing.assert_allclose(applied[2:], expected_tau, atol=1e-6 * b.tau_max.max())
        assert env.observation_space.contains(obs)
        assert -0.3 - 1e-12 <= reward <= 1.0
        if terminated or truncated:
            break


def test_vector_env_same_seed_same_run_whatever_the_thread_count(monkeypatch):
    """Chunking over threads changes no number: 1, 2 and 3 threads give bit-identical steps,
    through autoresets, and a rerun with the same seed repeats them."""
    import vtoladapt.gym.batch as gym_batch

    # one environment per chunk: several chunks per thread, so threads also take others' leftovers
    monkeypatch.setattr(gym_batch, "MIN_CHUNK_ENVS", 1)
    n, steps = 5, 60
    scenario = short_hold(0.1)  # 25 steps: two autoresets per environment
    actions = np.random.default_rng(7).uniform(-1, 1, (steps, n, 5))

    def trajectory(workers):
        venv = HoldVectorEnv(num_envs=n, workers=workers, scenario=scenario, residual=True)
        out = [venv.reset(seed=11)[0]]
        for a in actions:
            out.extend(venv.step(a)[:4])
        venv.close()
        return out

    reference = trajectory(1)
    for workers in (2, 3, 1):
        for got, want in zip(trajectory(workers), reference):
            np.testing.assert_array_equal(got, want)
    # the same seed differs from another seed (the comparison above can fail)
    venv = HoldVectorEnv(num_envs=n, workers=1, scenario=scenario, residual=True)
    assert not np.array_equal(venv.reset(seed=12)[0], reference[0])
    venv.close()


def test_tumbling_vehicle_gives_finite_observations_and_ends_the_episode():
    """Direct mode with random full-range commands and no position or tilt limit: the vehicle
    tumbles, yet every observation is finite and inside the space, every reward finite, and
    the NEXT_STEP autoreset starts a fresh episode (reward 0, not done) in the environments that ended."""
    n, steps = 4, 200
    venv = HoldVectorEnv(num_envs=n, workers=2, scenario=short_hold(0.6), residual=False,
                         max_position_error_m=100.0, max_tilt_deg=180.0)
    obs, _ = venv.reset(seed=3)
    actions = np.random.default_rng(3).uniform(-1, 1, (steps, n, 5))
    was_done = np.zeros(n, dtype=bool)
    n_done = 0
    for a in actions:
        obs, reward, terminated, truncated, info = venv.step(a)
        assert info == {}
        assert venv.observation_space.contains(obs)
        assert np.isfinite(reward).all()
        # an environment that ended last step was reset by this one
        assert (reward[was_done] == 0.0).all() and not (terminated | truncated)[was_done].any()
        was_done = terminated | truncated
        n_done += int(was_done.sum())
    assert n_done >= n  # every environment ended at least once (150 steps per episode)
    venv.close()


def test_equal_controller_parameters_are_stored_once_and_others_apart():
    """Rows whose controller and mixer parameters are equal share one row of the chunk's table; a
    row loaded with other parameters holds its own (those of its scenario) and gives it back when
    reloaded with the shared ones."""
    from vtoladapt.gym.batch import RunBatch
    from vtoladapt.sim.driver import prepare

    variant = short_hold(0.1)
    variant.setdefault("controller", {}).setdefault("composite", {})["forgetting_lambda"] = 0.37
    base = make_config({"scenario": short_hold(0.1)}).scenario
    other = make_config({"scenario": variant}).scenario
    assert not np.array_equal(prepare(base).controller_params, prepare(other).controller_params)
    batch = RunBatch(make_config({"scenario": base}), 3, workers=1)
    chunk = batch.chunks[0]
    for i, scenario in enumerate((base, base, other)):
        batch.load(i, scenario)
    assert chunk.pidx[0] == chunk.pidx[1] != chunk.pidx[2]
    for i, scenario in enumerate((base, base, other)):
        run = prepare(scenario)
        np.testing.assert_array_equal(chunk.block(i, "controller_params"), run.controller_params)
        np.testing.assert_array_equal(chunk.block(i, "mixer_params"), run.mixer_params)
    batch.load(2, base)
    assert len(set(chunk.pidx.tolist())) == 1 and len(chunk._p_rows) == 1
    batch.load(0, other)  # the freed table row is reused
    np.testing.assert_array_equal(chunk.block(0, "controller_params"), prepare(other).controller_params)
    np.testing.assert_array_equal(chunk.block(1, "controller_params"), prepare(base).controller_params)
    batch.close()
