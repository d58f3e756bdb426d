"""Gymnasium environment ``vtoladapt/Hold-v0`` on the simulator's compiled closed loop.

Importing this package registers the environment (single: :class:`HoldEnv`, vector:
:class:`HoldVectorEnv`)::

    import gymnasium as gym
    import vtoladapt.gym  # noqa: F401  (registers vtoladapt/Hold-v0)

    env = gym.make("vtoladapt/Hold-v0", residual=True)
    envs = gym.make_vec("vtoladapt/Hold-v0", num_envs=64)

``gym.make("vtoladapt.gym:vtoladapt/Hold-v0")`` imports it on the fly. The spaces are documented
in :mod:`vtoladapt.gym.spaces`, the episode, reward and termination in :mod:`vtoladapt.gym.env`,
the keyword arguments in :class:`vtoladapt.gym.settings.HoldEnvConfig`.
"""
from __future__ import annotations

from gymnasium.envs.registration import register, registry

from .settings import ENV_ID, HoldEnvConfig
from .env import HoldEnv
from .vector import HoldVectorEnv

if ENV_ID not in registry:
    register(id=ENV_ID, entry_point="vtoladapt.gym.env:HoldEnv",
             vector_entry_point="vtoladapt.gym.vector:HoldVectorEnv")

__all__ = ["ENV_ID", "HoldEnv", "HoldEnvConfig", "HoldVectorEnv"]
