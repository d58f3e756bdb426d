"""Long runs: the closed loop in chunks, the log streamed to Parquet row groups, health figures measured.

A one-hour flight at 250 Hz is 900 000 log rows of ~200 float64 columns (1.4 GB in memory), so
:func:`stream_run` never holds more than one chunk: it advances the loop ``chunk_s`` at a time
(:func:`vtoladapt.sim.driver.run_chunk`, the same kernel :func:`~vtoladapt.sim.driver.simulate`
calls), appends each chunk to the Parquet file as one row group, and after each chunk measures
what a long run could wear out: the orthonormality of ``R_WB`` (from the plant's quaternion and
from the controller's attitude estimate), the symmetry and eigenvalues of the adaptation gain ``P``
(symmetric positive definite and bounded), theta-hat against its bounds, and the process's
resident memory (psutil).
"""
from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path

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


def stream_run(scenario: Scenario, out: str | Path, chunk_s: float = 60.0) -> LongRunReport:
    """Run ``scenario`` writing its log to ``out`` (Parquet, one row group per ``chunk_s``).

    Memory stays flat whatever the duration: one chunk of the log is in memory at a time. The
    file holds the same columns and values :func:`vtoladapt.sim.driver.simulate` returns (its
    schema carries the run's metadata once the run ends). Stops at a divergence like
    :func:`~vtoladapt.sim.driver.simulate`.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    from .loop import log_columns
    from ..control.step import diagnostics_columns, state_P_inv, state_theta_hat
    from .driver import controller_prior, prepare, run_chunk

    run = prepare(scenario)
    _, _, _, lower, upper, _ = controller_prior(scenario, run.vehicle)
    dt = scenario.dt_control_s
    n = scenario.n_ticks
    chunk = max(1, int(round(chunk_s / dt)))
    x = run.x0.copy()
    columns = log_columns(diagnostics_columns(run.controller_params))
    log = np.empty((chunk, len(columns)))
    schema = pa.schema([(c, pa.float64()) for c in columns])
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    R_err = P_sym = theta_out = 0.0
    eig_min, eig_max = np.inf, -np.inf
    rss_start = rss_max = 0.0
    groups = 0
    n_done, reason = n, 0
    with pq.ParquetWriter(out, schema) as writer:
        for k0 in range(0, n, chunk):
            k1 = min(n, k0 + chunk)
            done, reason = run_chunk(run, x, k0, k1, log[:k1 - k0])
            rows = log[:done]
            if done:
                writer.write_table(pa.Table.from_arrays([pa.array(rows[:, i]) for i in range(len(columns))],
                                                        schema=schema))
                groups += 1
                q = rows[:, 1 + X_Q_WB:1 + X_Q_WB + 4]
                R_err = max(R_err, float(rotation_orthonormality_error(q).max()))
            P = np.linalg.inv(state_P_inv(run.controller_params, run.controller_state))
            P_sym = max(P_sym, float(np.linalg.norm(P - P.T) / np.linalg.norm(P)))
            eig = np.linalg.eigvalsh(0.5 * (P + P.T))
            eig_min, eig_max = min(eig_min, float(eig[0])), max(eig_max, float(eig[-1]))
            th = state_theta_hat(run.controller_params, run.controller_state)
            theta_out = max(theta_out, float(np.max(np.maximum(lower - th, 0.0))),
                            float(np.max(np.maximum(th - upper, 0.0))))
            rss = _rss_MB()
            if groups <= 1:
                rss_start = rss
            rss_max = max(rss_max, rss)
            if reason != 0:
                n_done = k0 + done
                break
    diverged_at = n_done * dt if reason != 0 else None
    why = (scenario.envelope.describe_violation(reason, x, diverged_at, run.reference_table[min(n_done, k1 - 1)])
           if reason != 0 else None)
    return LongRunReport(
        simulated_s=n_done * dt, ticks=n_done, row_groups=groups, diverged_at_s=diverged_at,
        divergence_reason=why, R_orthonormality_err_max=R_err, P_symmetry_err_max=P_sym,
        P_eig_min=eig_min, P_eig_max=eig_max, theta_hat_outside_bounds_max=theta_out,
        rss_start_MB=rss_start, rss_end_MB=_rss_MB(), rss_max_MB=rss_max, parquet_bytes=out.stat().st_size)


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
