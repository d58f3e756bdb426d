"""Stacked kernel arrays of a batch of episodes, and the one call that steps them.

:class:`RunBatch` is shared by the single environment (a batch of one) and the vector
environment, so both step through the same compiled :func:`~vtoladapt.gym.kernel.step_batch` and
an environment of a batch is, draw for draw, the single environment with the same seed.
"""
from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from typing import Optional

import numpy as np
from numba import typed

from ..control.kernel import DIAG_SIZE, P_TAU_MAX, P_U_MAX
from ..control.trajectory import trajectory_from_reference
from ..layout import CMD_SIZE, MEAS_SIZE, N_MOTORS, X_SIZE
from ..plant import RK4_WORK_SIZE
from ..scenario import Scenario
from ..simulate import PreparedRun, prepare
from .config import HoldEnvConfig
from .kernel import MODE_DIRECT, MODE_RESIDUAL, OP_BEGIN, OP_SKIP, OP_STEP, step_batch
from .spaces import ACTION_SIZE, OBS_SIZE

_PER_RUN = ("plant_params", "mixer_params", "controller_params", "controller_state", "wind_params",
            "wind_state", "sensor_params", "sensor_state")


class RunBatch:
    """``n`` closed-loop runs of one base scenario, stacked row by row, stepped in ``workers`` threads.

    Row ``i`` holds run ``i``'s plant state, kernel parameters and states (from
    :func:`vtoladapt.simulate.prepare` of its episode's scenario), the scratch the two halves of a
    tick hand each other, its tick counter and its generator. Threads take contiguous chunks of
    rows; the compiled step releases the GIL.
    """

    def __init__(self, cfg: HoldEnvConfig, n: int, workers: int = 1):
        base: Scenario = cfg.scenario
        self.cfg = cfg
        self.n = n
        self.dt = base.dt_control_s
        self.n_sub = base.plant_substeps
        self.n_ticks = base.n_ticks
        self.mode = MODE_RESIDUAL if cfg.residual else MODE_DIRECT
        times = np.arange(self.n_ticks + 1) * self.dt
        self.ref_table = np.ascontiguousarray(trajectory_from_reference(base.reference).reference_table(times))
        template = prepare(base.replace(duration_s=base.dt_control_s))
        self.u_max = float(template.controller_params[P_U_MAX])
        self.tau_max = np.array(template.controller_params[P_TAU_MAX:P_TAU_MAX + 3], dtype=float)
        self.cos_tilt_max = math.cos(math.radians(cfg.max_tilt_deg))
        self.arrays = {name: np.zeros((n, getattr(template, name).size)) for name in _PER_RUN}
        self.X = np.zeros((n, X_SIZE))
        self.V_WIND = np.zeros((n, 3))
        self.F_B = np.zeros((n, 3))
        self.V_I = np.zeros((n, 3))
        self.MEAS = np.zeros((n, MEAS_SIZE))
        self.CMD = np.zeros((n, CMD_SIZE))
        self.BASE = np.zeros((n, CMD_SIZE))
        self.DIAG = np.zeros((n, DIAG_SIZE))
        self.MOTOR = np.zeros((n, N_MOTORS))
        self.WORK = np.zeros((n, RK4_WORK_SIZE))
        self.K = np.zeros(n, dtype=np.int64)
        self.op = np.zeros(n, dtype=np.int64)
        self.actions = np.zeros((n, ACTION_SIZE))
        self.obs = np.zeros((n, OBS_SIZE), dtype=np.float32)
        self.reward = np.zeros(n)
        self.terminated = np.zeros(n, dtype=np.bool_)
        self.truncated = np.zeros(n, dtype=np.bool_)
        self.scenarios: list[Optional[Scenario]] = [None] * n
        workers = max(1, min(int(workers), n))
        edges = np.linspace(0, n, workers + 1).round().astype(int)
        self.chunks = [(int(edges[c]), int(edges[c + 1])) for c in range(workers)]
        # Python keeps each generator alive; the typed lists hold their unboxed form
        self._generators = [template.rng] * n
        self._lists = []
        for lo, hi in self.chunks:
            lst = typed.List()
            for _ in range(lo, hi):
                lst.append(template.rng)
            self._lists.append(lst)
        self._pool = ThreadPoolExecutor(max_workers=workers - 1) if workers > 1 else None
        self._bind()

    def load(self, i: int, scenario: Scenario) -> PreparedRun:
        """Put a fresh run of ``scenario`` in row ``i``; the next :meth:`advance` senses its tick 0."""
        run = prepare(scenario)
        for name in _PER_RUN:
            value = getattr(run, name)
            row = self.arrays[name][i]
            if value.size != row.size:
                raise ValueError(f"episode scenario {scenario.name!r}: {name} has {value.size} entries, the "
                                 f"batch {row.size}; the randomisation must not change array sizes")
            row[:] = value
        self.X[i] = run.x0
        for a in (self.V_WIND, self.F_B, self.V_I, self.MEAS, self.CMD, self.BASE, self.DIAG, self.MOTOR,
                  self.WORK):
            a[i] = 0.0
        self.K[i] = 0
        self.scenarios[i] = scenario
        self._generators[i] = run.rng
        for c, (lo, hi) in enumerate(self.chunks):
            if lo <= i < hi:
                self._lists[c][i - lo] = run.rng
        self.op[i] = OP_BEGIN
        return run

    def set_actions(self, actions: np.ndarray, mask: Optional[np.ndarray] = None) -> None:
        """Step every row (or the rows of ``mask``) with ``actions`` at the next :meth:`advance`."""
        self.actions[:] = actions
        if mask is None:
            self.op[:] = OP_STEP
        else:
            self.op[mask] = OP_STEP

    def _bind(self) -> None:
        # The arrays are updated in place, so each chunk's argument tuple is built once: a call
        # then costs Numba's dispatch alone (about 40 arguments), not 40 attribute look-ups too.
        a = self.arrays
        shared = (self.op, self.actions, self.mode, self.cfg.residual_scale, self.u_max, self.tau_max,
                  self.cfg.max_position_error_m, self.cos_tilt_max, self.cfg.action_cost, self.ref_table,
                  self.dt, self.n_sub, self.n_ticks,
                  self.X, a["plant_params"], a["mixer_params"], a["controller_params"], a["controller_state"],
                  a["wind_params"], a["wind_state"], a["sensor_params"], a["sensor_state"],
                  self.V_WIND, self.F_B, self.V_I, self.MEAS, self.CMD, self.BASE, self.DIAG, self.MOTOR,
                  self.WORK, self.K, self.obs, self.reward, self.terminated, self.truncated)
        self._args = [(lo, hi, self._lists[c]) + shared for c, (lo, hi) in enumerate(self.chunks)]

    def _run_chunk(self, c: int) -> None:
        step_batch(*self._args[c])

    def advance(self) -> None:
        """Apply :attr:`op` to every row (other chunks in the pool, the first here), then clear it."""
        if self._pool is None:
            self._run_chunk(0)
        else:
            futures = [self._pool.submit(self._run_chunk, c) for c in range(1, len(self.chunks))]
            self._run_chunk(0)
            for f in futures:
                f.result()
        self.op[:] = OP_SKIP

    def close(self) -> None:
        """Stop the worker threads."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

