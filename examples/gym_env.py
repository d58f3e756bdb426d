"""The Gymnasium environment: one short episode of ``vtoladapt/Hold-v0`` in residual mode (the action
is a residual on the composite controller's command) with a random policy, then a batch of
environments stepped in one compiled call.

    python examples/gym_env.py

Prints the episode's return and length. The episode is the shipped ``gym_hold`` scenario cut to
2 s (500 steps); pass any scenario to ``gym.make`` the same way.
"""
from __future__ import annotations

import gymnasium as gym
import numpy as np

import vtoladapt
import vtoladapt.gym  # noqa: F401  registers vtoladapt/Hold-v0


def main() -> float:
    scenario = vtoladapt.load_scenario("gym_hold")
    from dataclasses import replace
    env = gym.make("vtoladapt/Hold-v0", scenario=replace(scenario, duration_s=2.0), residual=True)
    policy_rng = np.random.default_rng(1)                 # the policy's own seeded generator
    obs, info = env.reset(seed=0)
    episode_return, steps, terminated, truncated = 0.0, 0, False, False
    while not (terminated or truncated):
        action = (0.05 * policy_rng.standard_normal(env.action_space.shape)).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        episode_return += float(reward)
        steps += 1
    env.close()
    print(f"episode: {steps} steps, {info['t_s']:.2f} s, return {episode_return:.2f}, terminated {terminated}")

    envs = gym.make_vec("vtoladapt/Hold-v0", num_envs=8, scenario=replace(scenario, duration_s=2.0), residual=True)
    obs, _ = envs.reset(seed=0)                            # environment i is seeded 0 + i
    obs, rewards, terminated, truncated, _ = envs.step(np.zeros((8, *env.action_space.shape), np.float32))
    envs.close()
    print("batch of 8: first rewards", np.round(rewards, 3))
    return episode_return


if __name__ == "__main__":
    main()
