"""The constant-weights ceiling of a basis on one log: the best any estimator of that basis can do.

:func:`ceiling_fit`: the best *constant* weights for the whole run, by least squares on the aircraft's
true specific force with the true incident flow, the throttles the rotors actually had (the lift
collective as the RMS of the four rotors: the same total thrust) and the true attitude and rates,
judged as the envelope campaign judges the controller (p95 < 0.05 g in every true-airspeed bin, after
the first 2 s). No sensor, no adaptation lag: what the basis allows at best.

:func:`measured_ceiling_fit`: the same with what the controller has instead of the truth: the inputs it
formed (the flow it used, probe or fallback; the throttle commands through the nominal motor lag; the
measured attitude, rates and velocity) and the accelerometer, both through the controller's low-pass,
so that the residual is the prediction error the controller's constant-weights best would log. The gap
between the two ceilings is what sensing costs; the gap between this one and the closed loop is what
the estimator (adaptation, its lag and its tracking term) costs.

:func:`bases_metrics`: the ``bases`` entry of ``vtoladapt reproduce``'s metrics.json, a live ceiling per
basis on the comparison experiment's composite log beside the committed envelope comparison per basis
(``docs/basis_comparison.json``, which :mod:`vtoladapt.learn.evaluate` regenerates: far longer than
``make reproduce``'s budget); the report's section is :func:`vtoladapt.experiments.report.bases_section`.

The envelope campaign, the reproduction and the learning of a basis all judge a basis this way; it
lives with the experiments, below the learning (which runs campaigns of them).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..frames import GRAVITY_MPS2
from ..sim.run_metrics import PRED_ERR_BOUND_G, PRED_ERR_SKIP_S, pred_err_p95_by_airspeed

COMPARISON_FILE = Path(__file__).resolve().parents[3] / "docs" / "basis_comparison.json"
BASES = ("paper", "extended", "learned")


def true_inputs(result, vehicle) -> tuple[np.ndarray, np.ndarray]:
    """Basis input rows from the log's *true* state (flow, rotor throttles, attitude, rates) and the true force."""
    from ..bases import input_rows

    v_i = result.columns_like(("v_i_x_mps", "v_i_y_mps", "v_i_z_mps"))
    lift = result.columns_like(tuple(f"motor{i}_frac" for i in range(1, 5)))
    u_z = np.sqrt(np.mean(lift * lift, axis=1))
    x = input_rows(v_i, result["pusher_frac"], u_z, vehicle.model_kernel,
                   q_WB=result.columns_like(("q_w", "q_x", "q_y", "q_z")),
                   omega_B=result.columns_like(("omega_x_radps", "omega_y_radps", "omega_z_radps")),
                   v_W=result.columns_like(("v_N_mps", "v_E_mps", "v_D_mps")))
    return x, result.columns_like(("f_B_x_mps2", "f_B_y_mps2", "f_B_z_mps2"))


def ceiling_fit(result, vehicle, spec) -> dict:
    """The constant-weights ceiling of ``spec`` on one log: p95 error (g) per airspeed bin and whether all pass."""
    from ..bases import evaluate

    x, f = true_inputs(result, vehicle)
    t = result.time_s
    late = (t >= t[0] + PRED_ERR_SKIP_S) & np.all(np.isfinite(x), axis=1) & np.all(np.isfinite(f), axis=1)
    return _judge(evaluate(spec, x[late]), f[late], result["airspeed_mps"][late], spec.n)


def measured_ceiling_fit(result, vehicle, spec, cutoff_hz: float = 10.0) -> dict:
    """:func:`ceiling_fit` with the controller's inputs and accelerometer, both low-passed at ``cutoff_hz`` as the
    controller filters them (the paper's 10 Hz)."""
    from ..bases import evaluate
    from ..bases.log_samples import flight_from_result

    flight = flight_from_result(result, vehicle, skip_s=0.0, stride=1)
    if len(flight.f) != len(result.time_s):    # a non-finite sample: the filter would smear it; judge nothing
        return {"p95_g": {}, "pass": False, "rms_g": float("nan")}
    t = result.time_s
    dt = float(np.median(np.diff(t)))
    c = 1.0 - np.exp(-2.0 * np.pi * cutoff_hz * dt)

    Phi = evaluate(spec, flight.x)
    late = t >= t[0] + PRED_ERR_SKIP_S
    return _judge(lowpass(Phi, c)[late], lowpass(flight.f, c)[late], result["airspeed_mps"][late], spec.n)


def lowpass(a: np.ndarray, c: float) -> np.ndarray:
    """The controller's first-order filter along axis 0, ``y_k = y_k-1 + c (x_k - y_k-1)``, started at the first
    sample (:func:`vtoladapt.control.filters.lowpass`, vectorised)."""
    from scipy.signal import lfilter

    return lfilter([c], [1.0, c - 1.0], a - a[0], axis=0) + a[0]


def _judge(Phi: np.ndarray, f: np.ndarray, airspeed: np.ndarray, n: int) -> dict:
    """Least-squares constant weights of ``Phi`` (N, 3, n) for ``f`` (N, 3); the residual judged per airspeed bin."""
    A = Phi.reshape(-1, n)
    y = f.reshape(-1)
    theta, *_ = np.linalg.lstsq(A, y, rcond=None)
    e = np.linalg.norm((y - A @ theta).reshape(-1, 3), axis=1) / GRAVITY_MPS2
    bins = pred_err_p95_by_airspeed(e, airspeed)
    ok = all(v < PRED_ERR_BOUND_G for v in bins.values() if v is not None)
    return {"p95_g": bins, "pass": ok, "rms_g": float(np.sqrt(np.mean(e * e)))}


def bases_metrics(comparison_dir: Path, scenario) -> dict:
    """The ``bases`` entry of metrics.json: the ceiling per basis on the comparison's composite log and
    the committed envelope comparison (if the file is there)."""
    from ..bases import describe_basis
    from ..sim.results import SimulationResult

    out: dict = {"ceiling": {}}
    log = Path(comparison_dir) / "runs" / f"{scenario.name}_composite.parquet"
    if log.is_file():
        res = SimulationResult.from_parquet(log)
        veh = scenario.load_vehicle()
        for b in BASES:
            fit = ceiling_fit(res, veh, describe_basis(veh, b))
            out["ceiling"][b] = fit
    if COMPARISON_FILE.is_file():
        out["envelope"] = json.loads(COMPARISON_FILE.read_text())
    return out
