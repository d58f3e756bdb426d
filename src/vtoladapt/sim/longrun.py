"""Long runs: the closed loop in chunks, the log streamed to Parquet row groups, health figures measured.

A one-hour flight at 250 Hz is 900 000 log rows of 157 float64 columns (1.1 GB in memory), so
:func:`stream_to_parquet` never holds more than one row group: it advances the loop a chunk at a time
(:func:`vtoladapt.sim.driver.run_chunk`, the same kernel :func:`~vtoladapt.sim.driver.simulate`
calls) and appends each row group to the Parquet file. Every command that writes a simulation log
(``vtoladapt run``, ``reproduce``) writes it this way (:func:`stream_many` for several runs side by
side). :func:`stream_run` adds, after each row group, a measure of what a long run could wear out: the orthonormality of ``R_WB`` (from the plant's quaternion and
from the controller's attitude estimate), the symmetry and eigenvalues of the adaptation gain ``P``
(symmetric positive definite and bounded), theta-hat against its bounds, and the process's
resident memory (psutil).
"""
from __future__ import annotations

import json
import os
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

from ..frames import quats_to_rotmats
from ..layout import X_Q_WB
from .scenario import Scenario


@dataclass(frozen=True)
class LongRunReport:
    """Health figures of a streamed run (units in the names)."""

    simulated_s: float
    ticks: int
    row_groups: int
    diverged_at_s: float | None
    divergence_reason: str | None
    R_orthonormality_err_max: float
    """max over ticks of ``||R^T R - I||_F`` of the plant's R_WB (from its unit quaternion)."""
    P_symmetry_err_max: float
    """max over chunk ends of ``||P - P^T||_F / ||P||_F``."""
    P_eig_min: float
    P_eig_max: float
    theta_hat_outside_bounds_max: float
    """largest distance (adaptation units) of theta-hat outside its bounds; 0 if always inside."""
    rss_start_MB: float
    """after the first chunk (kernels loaded, chunk buffer and writer allocated)."""
    rss_end_MB: float
    rss_max_MB: float
    parquet_bytes: int

    def to_json(self) -> str:
        """The report as JSON."""
        return json.dumps(asdict(self), indent=2)


def _rss_MB() -> float:
    import psutil

    return psutil.Process(os.getpid()).memory_info().rss / 2**20


def rotation_orthonormality_error(q_WB: np.ndarray) -> np.ndarray:
    """``||R^T R - I||_F`` per row of a ``(T, 4)`` quaternion history (scalar first, unnormalised)."""
    R = quats_to_rotmats(q_WB)
    E = np.einsum("tji,tjk->tik", R, R) - np.eye(3)
    return np.sqrt(np.einsum("tij,tij->t", E, E))


ROW_GROUP_S = 60.0
"""Simulated seconds per Parquet row group of a streamed log (15 000 rows at 250 Hz, 19 MB in memory)."""


def stream_to_parquet(scenario: Scenario, out: str | Path, progress=None, row_group_s: float = ROW_GROUP_S,
                      on_chunk: Optional[Callable] = None):
    """Run ``scenario`` writing its log to ``out`` (Parquet, one row group per ``row_group_s``); return
    the result backed by the file (:class:`vtoladapt.sim.results.LoggedResult`).

    Memory stays flat whatever the duration: one row group of the log is in memory at a time. The
    loop advances :data:`vtoladapt.sim.driver.CHUNK_S` at a time (:func:`vtoladapt.sim.driver.run_chunk`,
    the kernel :func:`~vtoladapt.sim.driver.simulate` calls, which also honours Ctrl-C there), so the
    file holds the same columns and values ``simulate`` returns, and its footer the run's metadata.
    ``progress(simulated_s, duration_s)`` is called after each chunk, ``on_chunk(run, x, rows)``
    (the prepared run, its state and the rows just written) after each row group. The file is written
    under a temporary name and renamed when the run ends (recorded in a claimed output folder's
    manifest): an interrupted run leaves no partial log. Stops at a divergence like ``simulate``.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    from ..outputs import atomic_path
    from .driver import chunk_ticks, prepare, run_chunk, run_metadata
    from .results import LoggedResult, log_metadata_entries

    from .limits import check_ticks

    check_ticks(scenario, scenario.source_path or f"scenario {scenario.name!r}", at_least=1)
    run = prepare(scenario)
    dt = scenario.dt_control_s
    n = scenario.n_ticks
    chunk = chunk_ticks(dt)
    # whole chunks per row group: the chunks start where simulate()'s do, so the log is its, bit for bit
    group = max(chunk, int(round(row_group_s / dt / chunk)) * chunk)
    x = run.x0.copy()
    columns = run.log_layout.columns  # this run's: its controller's diagnostics
    buffer = np.empty((min(group, n), run.log_layout.size))
    schema = pa.schema([(c, pa.float64()) for c in columns])
    out = Path(out)
    wall0 = time.perf_counter()
    n_done, reason, k1 = n, 0, 0
    with atomic_path(out) as tmp, pq.ParquetWriter(tmp, schema) as writer:
        for g0 in range(0, n, group):
            g1 = min(n, g0 + group)
            filled = 0
            for k0 in range(g0, g1, chunk):
                k1 = min(g1, k0 + chunk)
                done, reason = run_chunk(run, x, k0, k1, buffer[k0 - g0:k1 - g0])
                filled = k0 - g0 + done
                if reason != 0:
                    n_done = k0 + done
                    break
                if progress is not None:
                    progress(k1 * dt, scenario.duration_s)
            rows = buffer[:filled]
            if filled:
                writer.write_table(pa.Table.from_arrays([pa.array(rows[:, i]) for i in range(len(columns))],
                                                        schema=schema))
            if on_chunk is not None:
                on_chunk(run, x, rows)
            if reason != 0:
                break
        metadata = run_metadata(run, x, n_done, reason, k1 - 1, time.perf_counter() - wall0)
        writer.add_key_value_metadata({k.decode(): v.decode() for k, v in log_metadata_entries(metadata).items()})
    return LoggedResult(out, columns, metadata, n_done)


def stream_many(runs: Sequence[tuple[Scenario, Path]], workers: Optional[int] = None, progress=None) -> list:
    """:func:`stream_to_parquet` for each ``(scenario, path)`` on ``workers`` threads (default: one per
    core), results in the order given; each run owns its arrays and generator, so each log is the one
    a run alone writes. ``progress(simulated_s, total_s)`` is called with the sum over all runs."""
    from concurrent.futures import ThreadPoolExecutor

    runs = list(runs)
    workers = workers or os.cpu_count() or 1
    total_s = sum(sc.duration_s for sc, _ in runs)
    done_s = [0.0] * len(runs)
    lock = threading.Lock()

    def one(i: int):
        def report(sim_s: float, _duration_s: float) -> None:
            with lock:
                done_s[i] = sim_s
                progress(sum(done_s), total_s)
        sc, path = runs[i]
        return stream_to_parquet(sc, path, report if progress is not None else None)

    with ThreadPoolExecutor(max_workers=min(workers, max(1, len(runs)))) as pool:
        return list(pool.map(one, range(len(runs))))


def stream_run(scenario: Scenario, out: str | Path, chunk_s: float = 60.0) -> LongRunReport:
    """Run ``scenario`` streaming its log to ``out`` (:func:`stream_to_parquet`, one row group per
    ``chunk_s``) and measure, after each row group, what a long run could wear out."""
    from ..control.step import state_P_inv, state_theta_hat
    from .driver import controller_prior

    health = {"R_err": 0.0, "P_sym": 0.0, "theta_out": 0.0, "eig_min": np.inf, "eig_max": -np.inf,
              "rss_start": 0.0, "rss_max": 0.0, "groups": 0, "bounds": None}

    def measure(run, x, rows) -> None:
        if health["bounds"] is None:
            health["bounds"] = controller_prior(scenario, run.vehicle)[3:5]
        lower, upper = health["bounds"]
        if len(rows):
            health["groups"] += 1
            q = run.log_layout.view(rows, "STATE")[:, X_Q_WB:X_Q_WB + 4]
            health["R_err"] = max(health["R_err"], float(rotation_orthonormality_error(q).max()))
        P = np.linalg.inv(state_P_inv(run.controller_params, run.controller_state))
        health["P_sym"] = max(health["P_sym"], float(np.linalg.norm(P - P.T) / np.linalg.norm(P)))
        eig = np.linalg.eigvalsh(0.5 * (P + P.T))
        health["eig_min"] = min(health["eig_min"], float(eig[0]))
        health["eig_max"] = max(health["eig_max"], float(eig[-1]))
        th = state_theta_hat(run.controller_params, run.controller_state)
        health["theta_out"] = max(health["theta_out"], float(np.max(np.maximum(lower - th, 0.0))),
                                  float(np.max(np.maximum(th - upper, 0.0))))
        rss = _rss_MB()
        if health["groups"] <= 1:
            health["rss_start"] = rss
        health["rss_max"] = max(health["rss_max"], rss)

    result = stream_to_parquet(scenario, out, row_group_s=chunk_s, on_chunk=measure)
    return LongRunReport(
        simulated_s=len(result) * scenario.dt_control_s, ticks=len(result), row_groups=health["groups"],
        diverged_at_s=result.diverged_at_s, divergence_reason=result.divergence_reason,
        R_orthonormality_err_max=health["R_err"], P_symmetry_err_max=health["P_sym"],
        P_eig_min=health["eig_min"], P_eig_max=health["eig_max"], theta_hat_outside_bounds_max=health["theta_out"],
        rss_start_MB=health["rss_start"], rss_end_MB=_rss_MB(), rss_max_MB=health["rss_max"],
        parquet_bytes=Path(out).stat().st_size)


def main(argv: list[str] | None = None) -> int:
    """``python -m vtoladapt.sim.longrun SCENARIO OUT.parquet [CHUNK_S]``: stream a run, print its report."""
    import sys

    from .scenario import load_scenario

    args = sys.argv[1:] if argv is None else argv
    if len(args) not in (2, 3):
        print("usage: python -m vtoladapt.sim.longrun SCENARIO OUT.parquet [CHUNK_S]", file=sys.stderr)
        return 2
    report = stream_run(load_scenario(args[0]), args[1], float(args[2]) if len(args) == 3 else 60.0)
    print(report.to_json())
    return 1 if report.diverged_at_s is not None else 0


if __name__ == "__main__":
    raise SystemExit(main())
