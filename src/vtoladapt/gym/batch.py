"""Kernel state of a batch of episodes in one array per chunk, and the compiled calls that step them.

:class:`RunBatch` is shared by the single environment (a batch of one) and the vector
environment, so both step through the same compiled :func:`~vtoladapt.gym.batch_kernel.step_batch` and
an environment of a batch is, draw for draw, the single environment with the same seed.

Each :class:`_Chunk` (a contiguous range of environments) owns one 2-D array whose rows are its
environments' whole kernel state (the blocks of :data:`~vtoladapt.gym.batch_kernel.ROW_BLOCKS`) and its own
copy of the shared tables: Numba counts references to an array's buffer atomically whenever the
kernel takes a slice of it, so two threads slicing one allocation would bounce that counter's
cache line between the cores at every slice. The actions, operations, tick counters and outputs
are one array each for the whole batch, each chunk stepping through its rows (views): a step
copies the actions in once and the outputs out once, whatever the number of chunks.

Threads: ``workers - 1`` persistent threads (:class:`_Workers`) and the calling thread step the
chunks, each its own share first, then whatever another has not started (:class:`_Claims`), so a
thread that the operating system delays (a busy machine) leaves most of its share to the others
instead of holding the whole step up. A hand-off is a bare lock, not a ``concurrent.futures``
future.
"""
from __future__ import annotations

import math
import threading
import weakref
from typing import Optional

import numpy as np
from numba import typed

from ..control.blocks import P_TAU_MAX, P_U_MAX
from ..control.trajectory import trajectory_from_reference
from ..layout import CMD_SIZE, MEAS_SIZE, PLANT_INPUT_SIZE, REF_P_W, TRUTH_SIZE, X_P_W, X_SIZE, BlockLayout, Field
from ..sensors import mocap
from ..sim.driver import PreparedRun, chunk_ticks, prepare
from ..sim.loop import diagnostics_columns
from ..sim.loop import TICK_WORK_SIZE
from ..sim.scenario import Scenario
from .batch_kernel import (B_FAULT_S, B_SENS_S, BOUNDS, MODE_DIRECT, MODE_RESIDUAL, OP_BEGIN, OP_SKIP, OP_STEP,
                           ROW_BLOCKS, SET_PREFETCH_END, SET_PREFETCH_RESUME, SET_PREFETCH_STOP, SETTINGS,
                           SHARED_BLOCKS, step_batch)
from .settings import HoldEnvConfig
from .spaces import ACTION_SIZE, OBS_SIZE

CHUNKS_PER_WORKER = 4
"""Chunks per thread: enough that a thread delayed by the machine's other work leaves a few for the
others, few enough that the per-chunk call (about 3 us, unboxing its arguments) stays small."""
MIN_CHUNK_ENVS = 16
"""No fewer environments per chunk (except when there are fewer than ``workers`` x this)."""

_PER_RUN = ("PLANT_PARAMS", "CONTROLLER_STATE", "WIND_PARAMS", "WIND_STATE", "SENSOR_PARAMS", "SENSOR_STATE",
            "FAULT_STATE")
"""The row's blocks loaded from a :class:`~vtoladapt.sim.driver.PreparedRun` (its attribute of that name,
lower case); the shared table's come from it too."""


def _sized(fields, sizes: dict) -> list[Field]:
    return [Field(f.name, sizes[f.name], f.unit, f.doc) for f in fields]


def row_layouts(template: PreparedRun) -> tuple[BlockLayout, BlockLayout]:
    """The layouts of an environment's row (:data:`~vtoladapt.gym.batch_kernel.ROW_BLOCKS`) and of a
    shared table row (:data:`~vtoladapt.gym.batch_kernel.SHARED_BLOCKS`), sized for ``template``'s scenario."""
    sizes = {"X": X_SIZE, "TRUTH": TRUTH_SIZE, "MEAS": MEAS_SIZE, "CMD": CMD_SIZE, "BASE": CMD_SIZE,
             "DIAG": len(diagnostics_columns(template.controller_params)), "MOTOR": PLANT_INPUT_SIZE, "WORK": TICK_WORK_SIZE,
             "WIND_DRAWS": template.wind_parts.draws_size, "SENSOR_DRAWS": template.sensor_parts.draws_size}
    sizes.update({name: getattr(template, name.lower()).size for name in _PER_RUN})
    shared = {f.name: _shared_value(template, f.name).size for f in SHARED_BLOCKS}
    return (BlockLayout("environment row", _sized(ROW_BLOCKS, sizes)),
            BlockLayout("shared table row", _sized(SHARED_BLOCKS, shared)))


def _shared_value(run: PreparedRun, name: str) -> np.ndarray:
    """Shared block ``name`` of a run (the fault schedule flattened, row after row)."""
    return run.fault_schedule.ravel() if name == "FAULT_SCHEDULE" else getattr(run, name.lower())


def _tables(template: PreparedRun) -> list[tuple[str, np.ndarray]]:
    """The function tables of :data:`~vtoladapt.gym.batch_kernel.TABLES`, in order."""
    return [("WIND_TABLE", template.wind_parts.table), ("SENSOR_TABLE", template.sensor_parts.table),
            ("CONTROLLER_FNS", template.controller_fns)]


def block_offsets(template: PreparedRun) -> np.ndarray:
    """The kernel's ``off`` array (laid out as :data:`~vtoladapt.gym.batch_kernel.BOUNDS`): where each
    block of a row starts and the row's width, the same for the shared table, then the rows of the
    function tables."""
    row, shared = row_layouts(template)
    tables = BlockLayout("function tables", [Field(name, t.shape[0], "rows", name) for name, t in _tables(template)])
    off = np.zeros(BOUNDS.size, dtype=np.int64)
    for lay, end in ((row, "ROW_END"), (shared, "SHARED_END"), (tables, "TABLES_END")):
        for f in lay.fields:
            off[BOUNDS.offset(f.name)] = lay.offset(f.name)
        off[BOUNDS.offset(end)] = lay.size
    return off


def prefetch_range(template: PreparedRun, off: np.ndarray) -> tuple[int, int, int]:
    """``(end, resume, stop)``: the columns of the next row a step prefetches, ``[0, end)`` and
    ``[resume, stop)``: everything before the fault state but the motion-capture ring, of which a step
    touches two entries (the fault state, mostly its own latency ring, is touched only under faults)."""
    stop = int(off[B_FAULT_S])
    sensors = template.sensor_parts
    if "mocap" not in sensors.ids:
        return stop, stop, stop
    ring = int(off[B_SENS_S]) + sensors.state_layout.offset("MOCAP") + mocap.STATE.offset("RING")
    return ring, ring + mocap.STATE.field("RING").size, stop


class _Chunk:
    """Rows ``lo .. hi-1`` of a batch in arrays of their own, and the argument tuple of their kernel call."""

    def __init__(self, batch: "RunBatch", lo: int, hi: int, template: PreparedRun):
        m = hi - lo
        self.lo, self.hi = lo, hi
        self.row_layout, self.shared_layout = row_layouts(template)
        self.off = block_offsets(template)
        self.S = np.zeros((m, self.row_layout.size))
        # the shared blocks' distinct values, one table row each, counted by the rows using them
        self.P = np.zeros((m, self.shared_layout.size))
        self.pidx = np.zeros(m, dtype=np.int64)
        self._p_rows: dict[bytes, list[int]] = {}  # value -> [table row, rows using it]
        self._p_key: list[Optional[bytes]] = [None] * m
        self._p_free = list(range(m - 1, -1, -1))
        # views of the batch's arrays: written and read by the batch once per step for all chunks
        self.K = batch.K[lo:hi]
        self.op = batch.op[lo:hi]
        self.actions = batch.actions[lo:hi]
        self.obs = batch.obs[lo:hi]
        self.reward = batch.reward[lo:hi]
        self.terminated = batch.terminated[lo:hi]
        self.truncated = batch.truncated[lo:hi]
        # Python keeps each generator alive; the typed list holds their unboxed form, so a call
        # does not unbox them again (a tuple of generators costs tens of microseconds each)
        self.generators = [template.rng] * m
        self.rngs = typed.List()
        for _ in range(m):
            self.rngs.append(template.rng)
        self.settings = batch.settings.copy()
        (self.settings[SET_PREFETCH_END], self.settings[SET_PREFETCH_RESUME],
         self.settings[SET_PREFETCH_STOP]) = prefetch_range(template, self.off)
        # the function tables every environment of the batch calls through (the template's parts keep
        # the functions alive)
        self.template = template
        self.tables = np.ascontiguousarray(np.vstack([t for _, t in _tables(template)]), dtype=np.int64)
        # every array is updated in place, so the arguments are bound once
        self.args = (self.rngs, self.op, self.actions, self.settings, batch.tau_max.copy(), batch.ref_table.copy(),
                     self.S, self.off, self.P, self.pidx, self.K, self.obs, self.reward, self.terminated,
                     self.truncated, self.tables, np.empty(0))
        self._slices = {}
        for lay, shared in ((self.row_layout, False), (self.shared_layout, True)):
            for f in lay.fields:
                self._slices[f.name] = self._slices[f.name.lower()] = (shared, lay.slice(f.name))

    def block(self, j: int, name: str) -> np.ndarray:
        """Row ``j``'s block ``name`` (a view; a shared block's is the table row it uses); ``name`` is a
        block of :data:`~vtoladapt.gym.batch_kernel.ROW_BLOCKS` or ``SHARED_BLOCKS``, in either case."""
        shared, columns = self._slices[name] if name in self._slices else self._slices[name.upper()]
        return self.P[self.pidx[j], columns] if shared else self.S[j, columns]

    def _check_size(self, key: str, value: np.ndarray, name: str) -> None:
        lay = self.shared_layout if key in self.shared_layout else self.row_layout
        if value.size != lay.field(key).size:
            raise ValueError(f"episode scenario {name!r}: {key.lower()} has {value.size} entries, the batch "
                             f"{lay.field(key).size}; the randomisation must not change array sizes")

    def _share(self, j: int, shared: np.ndarray) -> None:
        """Point row ``j`` at the table row holding ``shared`` (stored there if no row holds it yet)."""
        old = self._p_key[j]
        if old is not None:
            entry = self._p_rows[old]
            entry[1] -= 1
            if entry[1] == 0:
                self._p_free.append(entry[0])
                del self._p_rows[old]
        key = shared.tobytes()
        entry = self._p_rows.get(key)
        if entry is None:
            # at most m values are in use and row j's old one was just released: a row is free
            entry = self._p_rows[key] = [self._p_free.pop(), 0]
            self.P[entry[0]] = shared
        entry[1] += 1
        self._p_key[j] = key
        self.pidx[j] = entry[0]

    def load(self, j: int, run: PreparedRun, name: str) -> None:
        if run.wind_parts.ids != self.template.wind_parts.ids or run.sensor_parts.ids != self.template.sensor_parts.ids:
            raise ValueError(f"episode scenario {name!r}: its wind parts or sensor channels differ from the base "
                             "scenario's; the randomisation must not change them")
        row = self.S[j]
        row[:] = 0.0
        shared = np.zeros(self.P.shape[1])
        for key in _PER_RUN:
            value = getattr(run, key.lower())
            self._check_size(key, value, name)
            row[self.row_layout.slice(key)] = value
        for f in SHARED_BLOCKS:
            value = _shared_value(run, f.name)
            self._check_size(f.name, value, name)
            shared[self.shared_layout.slice(f.name)] = value
        self._share(j, shared)
        self.block(j, "X")[:] = run.x0
        self.K[j] = 0
        self.generators[j] = run.rng
        self.rngs[j] = run.rng
        self.op[j] = OP_BEGIN

    def run(self) -> None:
        """Apply the pending operations of this chunk's rows (releases the GIL while it runs)."""
        step_batch(*self.args)


class _Claims:
    """The chunks of one step, handed out one at a time to the threads that ask.

    Thread ``t`` first takes its own contiguous share of the chunks, in order, so on an idle
    machine each thread steps the same environments at every step (their rows stay in its
    core's caches when they fit); a thread that runs out takes the last chunk left in the
    largest remaining share, so a thread the machine delays holds the step up by one chunk at most.
    """

    def __init__(self, chunks: list[_Chunk], threads: int):
        self.chunks = chunks
        self.lock = threading.Lock()
        edges = np.linspace(0, len(chunks), threads + 1).round().astype(int)
        self.own = [(int(edges[t]), int(edges[t + 1])) for t in range(threads)]
        self.front = [hi for _, hi in self.own]  # nothing to claim until start()
        self.back = [hi for _, hi in self.own]
        self.error: Optional[BaseException] = None

    def start(self) -> None:
        self.front = [lo for lo, _ in self.own]
        self.back = [hi for _, hi in self.own]
        self.error = None

    def _claim(self, t: int) -> int:
        with self.lock:
            if self.front[t] < self.back[t]:
                self.front[t] += 1
                return self.front[t] - 1
            left = [b - f for f, b in zip(self.front, self.back)]
            u = max(range(len(left)), key=left.__getitem__)
            if left[u] <= 0:
                return -1
            self.back[u] -= 1
            return self.back[u]

    def run_until_empty(self, t: int) -> None:
        """Step chunks as thread ``t`` until none is left (an exception is kept for the caller to raise)."""
        while True:
            j = self._claim(t)
            if j < 0:
                return
            try:
                self.chunks[j].run()
            except BaseException as exc:  # re-raised by the thread that called RunBatch.advance
                with self.lock:
                    self.error = exc
                    self.back = list(self.front)
                return


def _work(claims: _Claims, t: int, go, done, stop: threading.Event) -> None:
    """Worker thread ``t``: whenever ``go`` is released, step chunks until none is left, then release ``done``."""
    while True:
        go.acquire()
        if stop.is_set():
            return
        claims.run_until_empty(t)
        done.release()


class _Workers:
    """``n`` persistent daemon threads that help the calling thread (thread 0) through a step's chunks.

    Each hand-off is a bare lock used as a binary semaphore (held = nothing to do; released by the
    other side), which waits in C with the GIL released (``threading.Semaphore`` and futures wait
    on a ``threading.Condition`` written in Python). The threads hold the chunks but not the
    batch, so a batch that is dropped without ``close`` is still collected; its finaliser stops
    them.
    """

    def __init__(self, claims: _Claims, n: int):
        self.claims = claims
        self.go = [threading.Lock() for _ in range(n)]
        self.done = [threading.Lock() for _ in range(n)]
        for lock in self.go + self.done:
            lock.acquire()
        self.stop = threading.Event()
        self.threads = [threading.Thread(target=_work, args=(claims, t + 1, self.go[t], self.done[t], self.stop),
                                         name=f"vtoladapt-gym-{t + 1}", daemon=True) for t in range(n)]
        for t in self.threads:
            t.start()

    def run(self) -> None:
        """Step every chunk: release the workers, work alongside them, wait for all of them."""
        self.claims.start()
        for go in self.go:
            go.release()
        try:
            self.claims.run_until_empty(0)
        finally:  # never return while a worker still steps: the next step would race it
            for done in self.done:
                done.acquire()

    def close(self) -> None:
        self.stop.set()
        for go in self.go:
            go.release()
        for t in self.threads:
            t.join()


class RunBatch:
    """``n`` closed-loop runs of one base scenario, stacked row by row, stepped in ``workers`` threads.

    Row ``i`` holds run ``i``'s plant state, kernel parameters and states (from
    :func:`vtoladapt.sim.driver.prepare` of its episode's scenario), the scratch the two halves of a
    tick hand each other, its tick counter and its generator. The rows are cut into contiguous
    chunks (:data:`CHUNKS_PER_WORKER` per thread, at least :data:`MIN_CHUNK_ENVS` rows each),
    which the threads claim as they come free; the compiled step releases the GIL.
    """

    def __init__(self, cfg: HoldEnvConfig, n: int, workers: int = 1):
        base: Scenario = cfg.scenario
        if base.plant.engine != "native":
            from ..config import ConfigError

            raise ConfigError(f"{base.source_path or base.name}: [plant] engine = {base.plant.engine!r}: the "
                              "Gymnasium environment steps the compiled native plant; allowed: 'native'")
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
        self.settings = SETTINGS.pack(MODE=self.mode, RESIDUAL_SCALE=cfg.residual_scale, U_MAX=self.u_max,
                                      MAX_ERR_M=cfg.max_position_error_m, COS_TILT_MAX=self.cos_tilt_max,
                                      ACTION_COST=cfg.action_cost, DT_S=self.dt, N_SUB=self.n_sub,
                                      N_TICKS=self.n_ticks, CHUNK_TICKS=chunk_ticks(self.dt))
        self.scenarios: list[Optional[Scenario]] = [None] * n
        self.K = np.zeros(n, dtype=np.int64)
        self.op = np.zeros(n, dtype=np.int64)
        self.actions = np.zeros((n, ACTION_SIZE))
        self.obs = np.zeros((n, OBS_SIZE), dtype=np.float32)
        self.reward = np.zeros(n)
        self.terminated = np.zeros(n, dtype=np.bool_)
        self.truncated = np.zeros(n, dtype=np.bool_)
        workers = max(1, min(int(workers), n))
        n_chunks = workers if workers == 1 else max(workers, min(workers * CHUNKS_PER_WORKER, n // MIN_CHUNK_ENVS))
        edges = np.linspace(0, n, n_chunks + 1).round().astype(int)
        self.chunks = [_Chunk(self, int(edges[c]), int(edges[c + 1]), template) for c in range(n_chunks)]
        self._chunk_of = np.repeat(np.arange(n_chunks), np.diff(edges))
        self._claims = _Claims(self.chunks, workers)
        self._workers = _Workers(self._claims, workers - 1) if workers > 1 else None
        if self._workers is not None:
            self._finalizer = weakref.finalize(self, self._workers.close)

    def load(self, i: int, scenario: Scenario) -> PreparedRun:
        """Put a fresh run of ``scenario`` in row ``i``; the next :meth:`advance` senses its tick 0."""
        run = prepare(scenario)
        chunk = self.chunks[self._chunk_of[i]]
        chunk.load(i - chunk.lo, run, scenario.name)
        self.scenarios[i] = scenario
        return run

    def set_actions(self, mask: Optional[np.ndarray] = None) -> None:
        """Step every row (or the rows of ``mask``) with :attr:`actions` at the next :meth:`advance`.

        The caller writes the ``(n, 5)`` actions into :attr:`actions` (float64) first.
        """
        if mask is None:
            self.op[:] = OP_STEP
        else:
            self.op[mask] = OP_STEP

    def advance(self) -> None:
        """Apply the pending operations to every row, then mark every row to skip."""
        try:
            if self._workers is None:
                for c in self.chunks:
                    c.run()
            else:
                self._workers.run()
                if self._claims.error is not None:
                    raise self._claims.error
        finally:
            self.op[:] = OP_SKIP

    def outputs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """New arrays ``(obs, reward, terminated, truncated)`` of every row, from the last :meth:`advance`."""
        return self.obs.copy(), self.reward.copy(), self.terminated.copy(), self.truncated.copy()

    def position_error(self, i: int) -> tuple[float, np.ndarray]:
        """``(t_s, p - p_ref)`` of row ``i``: its time and true position error, NED, m."""
        c = self.chunks[self._chunk_of[i]]
        j = i - c.lo
        k = int(c.K[j])
        return k * self.dt, c.block(j, "X")[X_P_W:X_P_W + 3] - self.ref_table[k, REF_P_W:REF_P_W + 3]

    def close(self) -> None:
        """Stop the worker threads."""
        if self._workers is not None:
            self._finalizer()  # runs _Workers.close once
            self._workers = None
