"""What a replay writes: ``replay.parquet``, ``metrics.json``, ``fig_replay.png``, ``report.md``/``.html``.

Prediction errors are reported as the norm of the filtered 3-axis error ``|e|`` (eq:prediction_error)
in units of standard gravity, over the *used* samples (finite inputs, airborne), for theta-hat as it
adapts (each sample's error is taken *before* that sample's update: a one-step-ahead prediction)
and for the vehicle's published theta_0.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..frames import GRAVITY_MPS2
from ..outputs import write_json, write_parquet
from .estimator import ReplayResult
from .flightlog import ReplayError

METRICS_FORMAT = "vtoladapt.replay.metrics"
METRICS_VERSION = 1
AIRSPEED_BINS_MPS = ((0.0, 2.0), (2.0, 5.0), (5.0, 8.0), (8.0, 11.0), (11.0, math.inf))
"""Airspeed bins of the per-airspeed metrics (m/s, lower bound inclusive)."""
OUTPUT_FILES = ("replay.parquet", "metrics.json", "fig_replay.png", "report.md", "report.html")
AXES = ("x", "y", "z")


def _finite_or_none(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _error_stats(e: np.ndarray) -> dict:
    """RMS, 95th percentile and maximum of ``|e|`` (g) and per-axis RMS (g); None when there are no samples."""
    if e.shape[0] == 0:
        return {"rms_g": None, "p95_g": None, "max_g": None, "rms_axis_g": None}
    norm = np.linalg.norm(e, axis=1) / GRAVITY_MPS2
    return {"rms_g": float(np.sqrt(np.mean(norm ** 2))), "p95_g": float(np.percentile(norm, 95)),
            "max_g": float(norm.max()),
            "rms_axis_g": [float(v) for v in np.sqrt(np.mean((e / GRAVITY_MPS2) ** 2, axis=0))]}


def airspeed_mps(result: ReplayResult) -> np.ndarray:
    """``|v_i_B|`` (m/s) per sample."""
    return np.linalg.norm(result.log.v_i_B_mps, axis=1)


def compute_metrics(result: ReplayResult) -> dict:
    """The ``metrics.json`` document (see the module notes)."""
    log = result.log
    used = result.used
    V = airspeed_mps(result)
    bins = []
    for lo, hi in AIRSPEED_BINS_MPS:
        m = used & (V >= lo) & (V < hi)
        a = _error_stats(result.e_mps2[m])
        p = _error_stats(result.e_prior_mps2[m])
        bins.append({"airspeed_mps": [lo, None if math.isinf(hi) else hi], "samples": int(m.sum()),
                     "adapted_rms_g": a["rms_g"], "adapted_p95_g": a["p95_g"],
                     "prior_rms_g": p["rms_g"], "prior_p95_g": p["p95_g"]})
    names = result.names
    theta_final = result.basis.from_scaled(result.theta_hat[-1])
    theta_0 = result.basis.from_scaled(result.theta_0)
    return {
        "format": METRICS_FORMAT, "version": METRICS_VERSION,
        "log": {"source": log.source, "format": log.log_format, "duration_s": log.duration_s,
                "rate_hz": log.rate_hz, "samples": log.n, "samples_used": int(used.sum()),
                "used_s": float(used.sum() / log.rate_hz),
                "samples_landed": int(log.landed.sum()),
                "samples_airspeed_from_pitot": int(log.v_i_from_pitot.sum()),
                "airspeed_mps_range": [_finite_or_none(np.nanmin(V[used])) if used.any() else None,
                                       _finite_or_none(np.nanmax(V[used])) if used.any() else None],
                "topics": log.topics, "sources": log.sources},
        "lacks": [{"quantity": n.quantity, "lacks": n.lacks, "filled": n.filled} for n in log.notes],
        "vehicle": result.vehicle.name,
        "prediction_error": {"adapted": _error_stats(result.e_mps2[used]),
                             "prior": _error_stats(result.e_prior_mps2[used]),
                             "units": "g (9.80665 m/s^2), norm of the filtered 3-axis error "
                                      "W theta - a_m over the used samples"},
        "by_airspeed_bin": bins,
        "theta": {"units": "Table I (throttle in percent, forces per unit mass)", "basis": result.basis.id,
                  "names": list(names),
                  "theta_0": dict(zip(names, map(float, theta_0))),
                  "final": dict(zip(names, map(float, theta_final))),
                  "at_bound": [name for i, name in enumerate(names)
                               if result.theta_hat[-1, i] <= result.theta_lower[i] + 1e-9 * max(1.0, abs(result.theta_lower[i]))
                               or result.theta_hat[-1, i] >= result.theta_upper[i] - 1e-9 * max(1.0, abs(result.theta_upper[i]))]},
        "settings": {k: getattr(result.settings, k) for k in result.settings.__dataclass_fields__},
    }


def write_timeseries(result: ReplayResult, path: Path) -> None:
    """``replay.parquet``: one row per sample, units in the column names."""
    import pyarrow as pa

    log = result.log
    V = airspeed_mps(result)
    vx, vy, vz = log.v_i_B_mps.T
    with np.errstate(invalid="ignore", divide="ignore"):
        alpha = np.degrees(np.arctan2(vz, vx))
        beta = np.degrees(np.arcsin(np.clip(vy / V, -1.0, 1.0)))
    cols = {"t_s": log.t_s, "airspeed_mps": V, "airspeed_pitot_mps": log.airspeed_pitot_mps,
            "alpha_deg": alpha, "beta_deg": beta, "airspeed_from_pitot": log.v_i_from_pitot,
            "throttle_x_pct": log.throttle_x_pct, "throttle_z_pct": log.throttle_z_pct,
            "landed": log.landed, "used": result.used, "adapting": result.adapting}
    for i, a in enumerate(AXES):
        cols[f"v_i_{a}_B_mps"] = log.v_i_B_mps[:, i]
        cols[f"wind_{'ned'[i]}_W_mps"] = log.wind_W_mps[:, i]
        cols[f"f_meas_{a}_B_mps2"] = log.f_meas_B_mps2[:, i]
        cols[f"a_m_f_{a}_B_mps2"] = result.a_m_f_mps2[:, i]
        cols[f"f_pred_{a}_B_mps2"] = result.f_pred_mps2[:, i]
        cols[f"f_pred_prior_{a}_B_mps2"] = result.f_pred_prior_mps2[:, i]
        cols[f"e_{a}_mps2"] = result.e_mps2[:, i]
        cols[f"e_prior_{a}_mps2"] = result.e_prior_mps2[:, i]
    th = result.theta_hat_table
    for i, name in enumerate(result.names):
        cols[f"theta_{name}"] = th[:, i]
    table = pa.table(cols)
    table = table.replace_schema_metadata({
        "vtoladapt": json.dumps({"format": "vtoladapt.replay.timeseries", "version": 1,
                                 "theta_units": "Table I (throttle in percent)",
                                 "frames": "body FRD, world NED", "source": log.source})})
    write_parquet(table, path)


def write_outputs(result: ReplayResult, out: Path) -> dict:
    """Write every output file into ``out`` (atomically, through :mod:`vtoladapt.outputs`); return the metrics."""
    from .figures import plot_replay
    from .report import write_report

    out = Path(out)
    metrics = compute_metrics(result)
    write_timeseries(result, out / "replay.parquet")
    write_json(out / "metrics.json", metrics)
    plot_replay(result, out / "fig_replay.png")
    write_report(result, metrics, out)
    return metrics


__all__ = ["AIRSPEED_BINS_MPS", "METRICS_FORMAT", "OUTPUT_FILES", "compute_metrics",
           "write_outputs", "write_timeseries"]
