"""The Gymnasium environment flies the simulator's own tick: a scenario's ``[[faults]]`` act in it (#27 item 2).

Before, the environment's tick had neither the fault schedule nor the envelope: with
``scenario="faults/pusher_saturated"`` (residual mode, zero actions) its worst position error stayed
0.048 m while ``simulate`` of the same episode went 190.5 m off, and four fault scenarios gave
bit-identical trajectories with and without their fault. The reference here is ``simulate`` of the
episode's own scenario (``vtoladapt run``): with a zero residual the environment must be that run,
bit for bit, inside the fault window and out, for the whole episode.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from vtoladapt.gym import HoldEnv
from vtoladapt.gym.spaces import OBS_P_ERR, OBS_V_I
from vtoladapt.sim.driver import simulate
from vtoladapt.sim.scenario import load_scenario

FAULT_SCENARIOS = ("faults/pusher_saturated", "faults/probe_stuck", "faults/imu_spike", "faults/lift_motor_loss")
"""An actuator fault that carries the aircraft far off, a sensor fault held over the window, a short
IMU burst and a partial motor loss."""


def _episode(scenario, n_steps=None):
    """A zero-residual episode of ``scenario`` (not randomised): observations and true position errors."""
    env = HoldEnv(scenario=scenario, residual=True, randomize=False, max_position_error_m=100.0,
                  max_tilt_deg=180.0)
    obs, info = env.reset(seed=5)
    observations, errors = [obs], [info["p_err_true_m"]]
    for _ in range((n_steps or env.max_steps) - 1):
        obs, _, terminated, truncated, info = env.step(np.zeros(5))
        observations.append(obs)
        errors.append(info["p_err_true_m"])
        if terminated or truncated:
            break
    env.close()
    return np.array(observations), np.array(errors), env.episode_scenario


@pytest.mark.parametrize("name", FAULT_SCENARIOS)
def test_a_fault_scenario_in_the_gym_is_its_simulated_run_window_for_window(name):
    sc = load_scenario(name)
    fault = sc.faults[0]
    sc = sc.replace(duration_s=min(sc.duration_s, fault.end_s + 2.0))
    observations, errors, episode = _episode(sc)
    log = simulate(episode)
    t = log.time_s
    n = min(len(observations), len(t))
    ref_p = log.columns_like(["ref_p_N_m", "ref_p_E_m", "ref_p_D_m"])
    meas_p = log.columns_like(["meas_p_N_m", "meas_p_E_m", "meas_p_D_m"])
    meas_vi = log.columns_like(["meas_v_i_x_mps", "meas_v_i_y_mps", "meas_v_i_z_mps"])
    window = (t[:n] >= fault.start_s) & (t[:n] < fault.end_s)
    assert window.sum() >= 10 and np.all(log["faults_active"][:n][window] == 1.0)
    # the observations are the run's measurements: before, inside and after the fault window
    for part in (t[:n] < fault.start_s, window, t[:n] >= fault.end_s):
        np.testing.assert_array_equal(observations[:n][part, OBS_P_ERR:OBS_P_ERR + 3],
                                      np.nan_to_num((meas_p - ref_p)[:n][part]).astype(np.float32).clip(-10, 10))
        np.testing.assert_array_equal(observations[:n][part, OBS_V_I:OBS_V_I + 3],
                                      np.nan_to_num(meas_vi[:n][part]).astype(np.float32).clip(-50, 50))
    # and the true position is the run's, tick for tick
    np.testing.assert_array_equal(errors[1:n], (log.position_W - ref_p)[1:n])


@pytest.mark.parametrize("name", FAULT_SCENARIOS)
def test_the_gym_trajectory_changes_with_the_fault(name):
    sc = load_scenario(name)
    fault = sc.faults[0]
    sc = sc.replace(duration_s=fault.end_s + 2.0)
    with_fault = _episode(sc)[1]
    without = _episode(sc.replace(faults=()))[1]
    steps = int(round(fault.start_s / sc.dt_control_s))
    n = min(len(with_fault), len(without))  # the pusher's episode ends early: carried out of the box
    # identical up to the fault (same seed, same draws), different from it on
    np.testing.assert_array_equal(with_fault[:steps], without[:steps])
    assert np.abs(with_fault[steps:n] - without[steps:n]).max() > 1e-3


def test_pusher_stuck_at_full_throttle_carries_the_gym_aircraft_away_as_it_does_the_run():
    """The reported case: with the pusher at full throttle for 4 s the aircraft is carried far off (the
    run: 190.5 m), not held within 5 cm as the environment's old tick, which had no faults, held it."""
    sc = load_scenario("faults/pusher_saturated")
    errors = _episode(sc, n_steps=int(round(16.0 / sc.dt_control_s)))[1]
    assert np.linalg.norm(errors, axis=1).max() > 50.0


def test_the_scenarios_envelope_ends_the_episode_where_it_ends_the_run():
    """The envelope monitor acts in the environment too: the episode terminates at the tick the run
    stops as diverged (here 5 m from the reference, the pusher stuck at full throttle)."""
    sc = load_scenario("faults/pusher_saturated")
    sc = sc.replace(duration_s=16.0, envelope=dataclasses.replace(sc.envelope, max_position_error_m=5.0))
    errors, episode = _episode(sc)[1:]
    log = simulate(episode)
    assert log.diverged and "max_position_error_m" in log.divergence_reason
    # the run stops before the tick whose state is outside; the episode's last step reached that state
    assert len(errors) == len(log) + 1
    assert np.linalg.norm(errors[-1]) > 5.0 >= np.linalg.norm(errors[-2])
