"""The vector version of ``vtoladapt/Hold-v0``: ``num_envs`` episodes advanced by one compiled call.

``gymnasium.make_vec("vtoladapt/Hold-v0", num_envs=N)`` builds :class:`HoldVectorEnv`. All runs
live in one :class:`~vtoladapt.gym.batch.RunBatch`; a step is one call of the compiled batch kernel
per thread (``workers`` threads, default one per core, each a contiguous chunk of environments,
the GIL released while they run).

Seeding: environment ``i`` has its own generator, seeded ``seed + i`` by ``reset(seed=seed)`` (or
``seed[i]`` from a list), so it is the single environment reset with that seed, draw for draw;
``reset()`` without a seed continues each environment's generator, as the single environment's does.
Autoreset follows Gymnasium 1.x's default ``AutoresetMode.NEXT_STEP``: an environment that
terminated or truncated is reset by the next ``step`` (its action ignored; observation of the new
episode, reward 0, not terminated, not truncated), drawing its new episode from its own generator.
"""
from __future__ import annotations

import os
from typing import Any, Optional, Sequence

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..config import ConfigError
from .batch import RunBatch
from .settings import ENV_ID, HoldEnvConfig, episode_scenario, make_config
from .env import as_actions, check_options, check_render_mode, check_seed
from .spaces import ACTION_SIZE, action_space, observation_space


def _copy_finite(src: np.ndarray, dst: np.ndarray) -> bool:
    """Copy ``src`` into the float64 ``dst`` (same shape), clipped to the action space [-1, 1];
    whether every value is finite."""
    np.copyto(dst, src, casting="unsafe")
    if not np.isfinite(dst).all():
        return False
    np.clip(dst, -1.0, 1.0, out=dst)
    return True


class HoldVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`~vtoladapt.gym.env.HoldEnv` in one batch (see the module docstring).

    Keyword arguments: ``num_envs``, ``workers`` (threads; default one per core) and those of
    :class:`~vtoladapt.gym.settings.HoldEnvConfig`. ``step`` returns an empty info dict (per-step
    dicts of arrays would cost more than the step); ``episode_scenarios`` lists each environment's
    current episode scenario.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, workers: Optional[int] = None, render_mode: Optional[str] = None,
                 **kwargs: Any):
        check_render_mode(render_mode)
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ConfigError(f"{ENV_ID}: num_envs = {num_envs!r}: must be an integer >= 1")
        if workers is None:
            workers = os.cpu_count() or 1
        if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
            raise ConfigError(f"{ENV_ID}: workers = {workers!r}: must be an integer >= 1 (threads)")
        self.render_mode = None
        self.config: HoldEnvConfig = make_config(kwargs)
        self.num_envs = int(num_envs)
        self.single_observation_space = observation_space()
        self.single_action_space = action_space()
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._batch = RunBatch(self.config, self.num_envs, workers=int(workers))
        self.dt_s: float = self._batch.dt
        self.max_steps: int = self._batch.n_ticks
        self._rngs: list[Optional[np.random.Generator]] = [None] * self.num_envs
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_)
        self._started = False

    @property
    def episode_scenarios(self):
        """Each environment's current episode scenario (replayable with ``simulate``)."""
        return list(self._batch.scenarios)

    def _seeds(self, seed) -> Sequence[Optional[int]]:
        if seed is None:
            return [None] * self.num_envs
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            return [check_seed(seed) + i for i in range(self.num_envs)]
        if isinstance(seed, (str, bytes)) or not hasattr(seed, "__iter__"):
            raise ConfigError(f"{ENV_ID}: reset seed = {seed!r}: must be None, a whole number >= 0 (environment "
                              "i gets seed + i) or one such number (or None) per environment")
        seeds = [check_seed(s, f"reset seed[{i}]") for i, s in enumerate(seed)]
        if len(seeds) != self.num_envs:
            raise ConfigError(f"{ENV_ID}: reset seed = {seed!r}: {len(seeds)} seeds for {self.num_envs} "
                              "environments; give one integer, one per environment, or None")
        return seeds

    def reset(self, *, seed=None, options: Optional[dict] = None):
        """Start a new episode in every environment (``seed + i`` seeds environment ``i``)."""
        check_options(options)
        for i, s in enumerate(self._seeds(seed)):
            if s is not None or self._rngs[i] is None:  # unseeded: continue the environment's stream
                self._rngs[i], _ = seeding.np_random(s)
            self._batch.load(i, episode_scenario(self.config, self.config.scenario, self._rngs[i]))
        self._batch.advance()
        self._autoreset[:] = False
        self._started = True
        return self._batch.outputs()[0], {}

    def step(self, actions):
        """One controller tick in every environment (autoreset on the step after an episode ends)."""
        if not self._started:
            raise RuntimeError(f"{ENV_ID}: step() before reset()")
        b = self._batch
        a = actions if isinstance(actions, np.ndarray) and actions.dtype.kind in "fiu" else as_actions(actions)
        # one cast-and-copy into the batch's float64 actions (the kernels read them there)
        if a is None or a.shape != b.actions.shape or not _copy_finite(a, b.actions):
            raise ValueError(f"{ENV_ID}: actions of shape {np.shape(actions)}: must be "
                             f"({self.num_envs}, {ACTION_SIZE}) finite numbers (values outside [-1, 1] are clipped to it)")
        resetting = self._autoreset
        if resetting.any():
            for i in np.flatnonzero(resetting):
                b.load(int(i), episode_scenario(self.config, self.config.scenario, self._rngs[i]))
            b.set_actions(~resetting)
        else:
            b.set_actions()
        b.advance()
        obs, reward, terminated, truncated = b.outputs()
        np.logical_or(terminated, truncated, out=self._autoreset)
        return obs, reward, terminated, truncated, {}

    def close_extras(self, **kwargs: Any) -> None:
        """Release the batch's arrays and worker threads (called by ``VectorEnv.close``)."""
        self._batch.close()
