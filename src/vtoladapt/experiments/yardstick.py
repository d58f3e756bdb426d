"""The prediction-error yardstick of one run: what the model predicts, scored where it can be judged (issue #34).

The run metrics' ``pred_err_*`` (:mod:`vtoladapt.sim.run_metrics`) score the one-tick prediction
error ``e_k = W_k theta-hat_{k-1} - a_m,k`` on every sample after the first 2 s. Three things make that
a poor judge of the model, and this module scores beside it, from the log after the run (nothing is
added to the controller's tick):

* **Probe-valid samples** (:func:`probe_valid_mask`). While the probe is not used ("blind") the
  regressor is built from a fallback airflow and adaptation is paused: the error then measures the
  fallback, not the model. Scored: the samples where the probe has been used for at least
  ``settle_s`` (:data:`PROBE_SETTLE_S`, 0.5 s: the 10 Hz filter's 16 ms and the adaptation's holdoff
  several times over) and after the first 2 s; ``blind_fraction`` (the share of the run's samples
  after 2 s with the probe not used) is reported beside it.
* **A horizon** (:func:`frozen_theta_error`). One tick ahead, an estimator that follows the
  accelerometer fast scores well whatever its model: the prediction at sample ``k`` is made with
  theta-hat frozen ``horizon_s`` earlier (:data:`HORIZON_S`, 0.5 s) and the regressor at ``k``:
  ``e^h_k = W_k theta-hat_{k-m} - a_m,k = e_k + W_k (theta-hat_{k-m} - theta-hat_{k-1})``, with ``m``
  the horizon in log rows (the log's ``theta_hat_*`` row ``j`` holds theta-hat after the update at
  tick ``j``; ``e_k`` used row ``k-1``'s). The logged ``e_k`` carries the exact regressor; ``W_k`` is
  needed only for the change of theta-hat, and is rebuilt from the logged inputs
  (:func:`filtered_regressor`: the flow the controller used, its throttle commands through the
  nominal motor lag, the measured attitude, rates and velocity, through the controller's filter).
* **A no-model baseline** (:func:`hold_error`): the filtered accelerometer held from one tick
  (``hold_one_tick``) or ``horizon_s`` (``hold_horizon``) earlier, as the prediction. A model that
  does not beat the hold at the same horizon has shown nothing.

What each can and cannot show: the one-tick error on probe-valid samples says how well the
estimator follows the measured force (a fast estimator with a poor model passes it; the hold
passes much of it); the horizon error says how well a fixed theta-hat carries over half a second of
changing flight, i.e. the model (the constant-weights ceiling is its best case); neither says
anything about the blind part of the run, which ``blind_fraction`` sizes. Each is judged as the
envelope campaign judges the prediction error: p95 per true-airspeed bin against
:data:`vtoladapt.sim.run_metrics.PRED_ERR_BOUND_G` in every bin with samples.
"""
from __future__ import annotations

import numpy as np

from ..frames import GRAVITY_MPS2
from ..sim.run_metrics import PRED_ERR_BOUND_G, PRED_ERR_SKIP_S, pred_err_p95_by_airspeed

PROBE_SETTLE_S = 0.5
"""A sample is scored once the probe has been used this long without a break (s)."""
HORIZON_S = 0.5
"""theta-hat is frozen this long before the predicted sample in the horizon metric (s)."""
PRED_ERR_COLUMNS = ("pred_err_x_mps2", "pred_err_y_mps2", "pred_err_z_mps2")
A_M_COLUMNS = ("a_m_x_mps2", "a_m_y_mps2", "a_m_z_mps2")
METRICS = ("one_tick", "horizon", "hold_one_tick", "hold_horizon")
"""The scored predictions, in table order: the law's one tick ahead and at the horizon, the hold at each."""


def probe_valid_mask(probe_used: np.ndarray, dt_s: float, settle_s: float = PROBE_SETTLE_S) -> np.ndarray:
    """True where the probe has been used (``probe_valid_used`` = 1) for at least ``settle_s`` without a break
    (the sample itself included: ``settle_s`` = 0 is the probe-used samples)."""
    used = np.asarray(probe_used) > 0.5
    run = np.zeros(len(used))
    c = 0.0
    for k, u in enumerate(used):           # the time since the last unused sample, sample by sample
        c = c + dt_s if u else 0.0
        run[k] = c
    return used & (run >= settle_s + dt_s - 1e-9)


def hold_error(a_m: np.ndarray, lag_rows: int) -> np.ndarray:
    """The hold's prediction error ``a_m,k-lag - a_m,k`` (N, 3); NaN for the first ``lag_rows`` rows."""
    out = np.full(a_m.shape, np.nan)
    if lag_rows < len(a_m):
        out[lag_rows:] = a_m[:len(a_m) - lag_rows] - a_m[lag_rows:]
    return out


def frozen_theta_error(e: np.ndarray, W: np.ndarray, theta: np.ndarray, lag_rows: int) -> np.ndarray:
    """``e_k + W_k (theta_{k-lag} - theta_{k-1})`` (N, 3) from the logged one-tick error ``e`` (N, 3), the
    regressor ``W`` (N, 3, n) and the logged theta-hat rows ``theta`` (N, n); NaN for the first ``lag_rows``
    rows. ``lag_rows`` = 1 gives ``e`` itself."""
    if lag_rows < 1:
        raise ValueError(f"lag_rows = {lag_rows}: the horizon must be at least one tick")
    out = np.full(e.shape, np.nan)
    if lag_rows < len(e):
        d = theta[:len(e) - lag_rows] - theta[lag_rows - 1:len(e) - 1]     # theta_{k-lag} - theta_{k-1}
        out[lag_rows:] = e[lag_rows:] + np.einsum("kij,kj->ki", W[lag_rows:], d)
    return out


def filtered_regressor(result, vehicle, spec, cutoff_hz: float) -> np.ndarray | None:
    """``W = [Phi]_f`` (N, 3, n) rebuilt from the log's controller inputs
    (:func:`vtoladapt.bases.log_samples.flight_from_result`), through the controller's first-order filter at
    ``cutoff_hz``; None if a row is not finite (the filter would smear it)."""
    from ..bases import evaluate
    from .ceiling import lowpass
    from ..bases.log_samples import flight_from_result

    flight = flight_from_result(result, vehicle, skip_s=0.0, stride=1)
    if len(flight.x) != len(result.time_s):
        return None
    t = result.time_s
    c = 1.0 - np.exp(-2.0 * np.pi * cutoff_hz * float(np.median(np.diff(t))))
    return lowpass(evaluate(spec, flight.x), c)


def _judge(err_mps2: np.ndarray, airspeed: np.ndarray, scored: np.ndarray, bound_g: float) -> dict:
    """p95 (g) of ``|err|`` on the ``scored`` samples: overall, per airspeed bin, and whether every bin is below."""
    e = np.linalg.norm(err_mps2, axis=1) / GRAVITY_MPS2
    sel = scored & np.isfinite(e) & np.isfinite(airspeed)
    if not sel.any():
        return {"p95_g": None, "p95_g_by_airspeed": {}, "pass": None}
    bins = pred_err_p95_by_airspeed(e[sel], airspeed[sel])
    return {"p95_g": float(np.percentile(e[sel], 95)), "p95_g_by_airspeed": bins,
            "pass": all(v < bound_g for v in bins.values() if v is not None)}


def prediction_yardstick(result, vehicle, spec, cutoff_hz: float = 10.0, horizon_s: float = HORIZON_S,
                         settle_s: float = PROBE_SETTLE_S) -> dict:
    """The module notes' metrics of one run: ``blind_fraction``, ``scored_fraction`` and, for each of
    :data:`METRICS`, ``{p95_g, p95_g_by_airspeed, pass}`` on the probe-valid samples (``horizon`` None where the
    regressor cannot be rebuilt). ``spec`` is the basis the run flew (its ``theta_hat_*`` columns)."""
    t = result.time_s
    dt = float(np.median(np.diff(t)))
    lag = max(1, int(round(horizon_s / dt)))
    late = t >= t[0] + PRED_ERR_SKIP_S
    used = result["probe_valid_used"]
    scored = late & probe_valid_mask(used, dt, settle_s) & (np.arange(len(t)) >= lag)
    airspeed = result["airspeed_mps"]
    e = result.columns_like(PRED_ERR_COLUMNS)
    a_m = result.columns_like(A_M_COLUMNS)
    out = {"horizon_s": horizon_s, "settle_s": settle_s,
           "blind_fraction": float(np.mean(~(used[late] > 0.5))) if late.any() else None,
           "scored_fraction": float(np.mean(scored[late])) if late.any() else None,
           "one_tick": _judge(e, airspeed, scored, PRED_ERR_BOUND_G),
           "hold_one_tick": _judge(hold_error(a_m, 1), airspeed, scored, PRED_ERR_BOUND_G),
           "hold_horizon": _judge(hold_error(a_m, lag), airspeed, scored, PRED_ERR_BOUND_G)}
    theta = result.columns_like(tuple(f"theta_hat_{name}" for name in spec.names))
    if np.all(theta == theta[:1]):
        out["horizon"] = out["one_tick"]           # theta-hat never moves: frozen is the same prediction
    else:
        W = filtered_regressor(result, vehicle, spec, cutoff_hz)
        out["horizon"] = (None if W is None
                          else _judge(frozen_theta_error(e, W, theta, lag), airspeed, scored, PRED_ERR_BOUND_G))
    return out


def worst_bin(judged: dict | None) -> float | None:
    """The largest per-bin p95 (g) of one :func:`_judge` entry (None if nothing was scored)."""
    vals = [v for v in ((judged or {}).get("p95_g_by_airspeed") or {}).values() if v is not None]
    return max(vals) if vals else None


__all__ = ["HORIZON_S", "METRICS", "PROBE_SETTLE_S", "filtered_regressor", "frozen_theta_error", "hold_error",
           "prediction_yardstick", "probe_valid_mask", "worst_bin"]
