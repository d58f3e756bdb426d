"""``vtoladapt/Hold-v0``: hold position in the fan array's wind, one closed-loop run per episode.

Episode
    One scenario (default: the shipped ``gym_hold``; any scenario via ``scenario=``). ``reset``
    draws the episode's scenario from the environment's generator (:func:`~vtoladapt.gym.settings.episode_scenario`:
    plant coefficients from the vehicle's Table I posterior, fan throttle factor and array bearing,
    then the run's seed) and prepares it exactly as ``vtoladapt run`` would; ``episode_scenario``
    holds it, so any episode can be replayed with :func:`vtoladapt.sim.driver.simulate`.
Step
    One controller tick (the scenario's ``dt_control_s``, 4 ms): the action is the command of
    this tick (or a residual on the composite controller's), see :mod:`vtoladapt.gym.spaces`.
Reward
    ``r = 1 - min(|p - p_ref| / d_max, 1) - c_a |a|^2 / 5`` per step, with ``p`` the true position,
    ``d_max = max_position_error_m`` and ``c_a = action_cost``: 1 per step spent on the reference,
    0 at ``d_max``; surviving is worth more than terminating.
Termination and truncation
    Terminated when the true position leaves the box ``|p - p_ref|_i <= d_max`` (any NED axis),
    the tilt exceeds ``max_tilt_deg`` or the state is not finite; truncated after the scenario's
    ``duration_s``.

With ``residual=True`` and a zero action the run is the simulator's own: for episodes no longer
than :data:`vtoladapt.sim.driver.CHUNK_S` (where the simulator's tick times are ``k dt`` too) the
observations come from the same log, bit for bit (tested).
"""
from __future__ import annotations

from typing import Any, Optional

import gymnasium as gym
import numpy as np

from ..config import ConfigError
from ..sim.scenario import Scenario
from .batch import RunBatch
from .settings import ENV_ID, HoldEnvConfig, episode_scenario, make_config
from .batch_kernel import OP_SKIP, OP_STEP
from .spaces import ACTION_SIZE, action_space, observation_space


def check_render_mode(render_mode: Optional[str]) -> None:
    """This environment draws nothing: only ``render_mode=None`` is allowed."""
    if render_mode is not None:
        raise ConfigError(f"{ENV_ID}: render_mode = {render_mode!r}: this environment does not render; "
                          "allowed: None (plot the episode's log with `vtoladapt run` instead)")


def check_options(options: Optional[dict]) -> None:
    """``reset`` takes no options."""
    if options:
        raise ConfigError(f"{ENV_ID}: reset options = {options!r}: none are accepted (the episode is "
                          "set by the environment's keyword arguments)")


def check_seed(seed: Any, where: str = "reset seed") -> Optional[int]:
    """A reset seed: None or a whole number >= 0 (a bool, a float or a negative number is refused in
    one line, rather than by Gymnasium's or Python's own errors)."""
    if seed is None:
        return None
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"{ENV_ID}: {where} = {seed!r}: must be None or a whole number >= 0")
    return int(seed)


def as_actions(action: Any) -> Optional[np.ndarray]:
    """``action`` as a real array (not yet float64), or None if it is not numbers: a complex action
    (whose imaginary part a cast to float64 would silently drop), text or objects."""
    try:
        a = np.asarray(action)
    except (TypeError, ValueError):
        return None
    if a.dtype.kind in "fiu":
        return a
    if a.dtype.kind == "O":
        try:
            return np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            return None
    return None


class HoldEnv(gym.Env):
    """Hold position in the wind; see the module docstring. Keyword arguments: :class:`HoldEnvConfig`."""

    metadata = {"render_modes": []}

    def __init__(self, render_mode: Optional[str] = None, **kwargs: Any):
        check_render_mode(render_mode)
        self.render_mode = None
        self.config: HoldEnvConfig = make_config(kwargs)
        self.observation_space = observation_space()
        self.action_space = action_space()
        self._batch = RunBatch(self.config, 1, workers=1)
        self._chunk = self._batch.chunks[0]
        self.dt_s: float = self._batch.dt
        self.max_steps: int = self._batch.n_ticks
        self.episode_scenario: Optional[Scenario] = None
        self._over = True

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        """Start an episode: draw its scenario from ``np_random`` (seeded by ``seed``), sense tick 0."""
        super().reset(seed=check_seed(seed))
        check_options(options)
        self.episode_scenario = episode_scenario(self.config, self.config.scenario, self.np_random)
        self._batch.load(0, self.episode_scenario)
        self._batch.advance()
        self._over = False
        return self._batch.outputs()[0][0], self._info()

    def step(self, action):
        """Apply ``action`` over one controller tick; return the observation at the next tick."""
        if self._over:
            raise RuntimeError(f"{ENV_ID}: step() after the episode ended (or before reset()): call reset()")
        a = as_actions(action)
        if a is None or a.shape != (ACTION_SIZE,) or not np.isfinite(a).all():
            raise ValueError(f"{ENV_ID}: action {action!r}: must be {ACTION_SIZE} finite numbers "
                             "(values outside [-1, 1] are clipped to it)")
        c = self._chunk  # a batch of one: write its row and call the kernel directly
        np.clip(a, -1.0, 1.0, out=c.actions[0])
        c.op[0] = OP_STEP
        try:
            c.run()
        finally:
            c.op[0] = OP_SKIP
        terminated, truncated = bool(c.terminated[0]), bool(c.truncated[0])
        self._over = terminated or truncated
        return c.obs[0].copy(), float(c.reward[0]), terminated, truncated, self._info()

    def _info(self) -> dict:
        t_s, p_err = self._batch.position_error(0)
        return {"t_s": t_s, "p_err_true_m": p_err}

    def close(self) -> None:
        """Release the environment's compiled-run arrays and worker threads."""
        self._batch.close()
        super().close()
