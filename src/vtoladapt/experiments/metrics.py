"""The experiments' numbers: each run's metrics (:func:`vtoladapt.sim.run_metrics.run_metrics`) per
controller, and the spread of theta-hat across the random-start runs."""
from __future__ import annotations

import math

import numpy as np

from ..sim.run_metrics import run_metrics
from ..sim.results import SimulationResult
from ..sim.scenario import Scenario
from ..vehicle import PARAMETER_NAMES
from ..bases.paper import SCALED_UNITS as THETA_SCALED_UNITS  # noqa: F401  (the paper's basis's; re-exported)


def fan_throttle_series(scenario: Scenario, t: np.ndarray) -> np.ndarray:
    """The fan array's throttle (%) from the scenario's schedule at each time ``t`` (s)."""
    from ..wind import fan_throttle_pct

    params = scenario.wind.to_kernel()
    return np.array([fan_throttle_pct(params, ti) for ti in t])


def fan_speed_series(scenario: Scenario, t: np.ndarray) -> np.ndarray:
    """The fan array's mean wind speed (m/s) at each time ``t`` (s)."""
    from ..wind import fan_mean_wind_speed

    params = scenario.wind.to_kernel()
    return np.array([fan_mean_wind_speed(params, ti) for ti in t])


# --- the wind's phases --------------------------------------------------------------------------
WIND_PHASES: dict[str, str] = {"rising": "rising wind", "plateau": "wind plateau", "fan_off": "fan-off transient"}
"""The phases of a fan schedule a comparison's metrics are also given in (:func:`wind_phase_masks`)."""

PHASE_METRIC_INFO: dict[str, tuple[str, str]] = {
    **{f"vel_err_rms_{k}_mps": (f"RMS velocity error, {label}", "m/s") for k, label in WIND_PHASES.items()},
    **{f"pred_err_p95_{k}_g": (f"95th-percentile prediction error, {label}", "g") for k, label in WIND_PHASES.items()},
}
"""Label and unit of each per-phase metric (the keys :func:`phase_metrics` adds), as
:data:`vtoladapt.sim.run_metrics.METRIC_INFO` has them for the run's other metrics."""


def wind_phase_masks(t: np.ndarray, fan_pct: np.ndarray) -> dict[str, np.ndarray]:
    """Masks of the log rows in each phase of the fan schedule (:data:`WIND_PHASES`).

    ``fan_pct`` is the commanded throttle at each row (the schedule, no spin-up lag). *rising*: from
    the fan's first start to the start of its last constant level before it stops; *plateau*: that
    last level; *fan-off transient*: the :data:`vtoladapt.sim.run_metrics.OVERSHOOT_WINDOW_S` after it stops
    (the window of ``overshoot_after_fan_off_mps``). A schedule without a stop, or with one level
    only, has empty masks where a phase does not exist. In the paper's comparison: 5-30 s (30 %
    to 60 %), 30-40 s (70 %), 40-45 s.
    """
    from ..sim.run_metrics import OVERSHOOT_WINDOW_S, fan_events

    empty = np.zeros(t.shape, dtype=bool)
    _, t_off = fan_events(t, fan_pct)
    on = fan_pct > 0.5
    if t_off is None or not on.any():
        return {k: empty for k in WIND_PHASES}
    t_on = float(t[np.argmax(on)])
    before = (t >= t_on) & (t < t_off)
    idx = np.flatnonzero(before)
    changes = idx[1:][np.abs(np.diff(fan_pct[idx])) > 1e-9]
    t_plateau = float(t[changes[-1]]) if changes.size else t_on
    return {"rising": before & (t < t_plateau), "plateau": before & (t >= t_plateau),
            "fan_off": (t >= t_off) & (t <= t_off + OVERSHOOT_WINDOW_S)}


def phase_metrics(result: SimulationResult, fan_pct: np.ndarray) -> dict:
    """RMS velocity error and 95th-percentile prediction error in each wind phase (:data:`PHASE_METRIC_INFO`);
    NaN for an empty phase. The prediction error is that of the law's theta-hat (theta_0 for a law
    that does not adapt it), skipping the first :data:`vtoladapt.sim.run_metrics.PRED_ERR_SKIP_S` as the
    run's own."""
    from ..frames import GRAVITY_MPS2
    from ..sim.run_metrics import PRED_ERR_SKIP_S

    t = result.time_s
    v = np.linalg.norm(result.velocity_error_W, axis=1)
    e = None
    if "pred_err_x_mps2" in result:
        e = np.linalg.norm(result.columns_like(("pred_err_x_mps2", "pred_err_y_mps2", "pred_err_z_mps2")),
                           axis=1) / GRAVITY_MPS2
    out = {}
    for k, mask in wind_phase_masks(t, fan_pct).items():
        out[f"vel_err_rms_{k}_mps"] = float(np.sqrt(np.mean(v[mask] ** 2))) if mask.any() else float("nan")
        sel = mask & (t >= PRED_ERR_SKIP_S)
        out[f"pred_err_p95_{k}_g"] = (float(np.percentile(e[sel], 95)) if e is not None and sel.any()
                                      else float("nan"))
    return out


def law_run_metrics(result: SimulationResult, fan_pct: np.ndarray) -> dict:
    """A comparison run's metrics: :func:`vtoladapt.sim.run_metrics.run_metrics` and :func:`phase_metrics`.

    Every law has a force model, theta-hat (theta_0 held for the laws that do not adapt it), so its
    prediction error is reported too: the nominal theta_0's is what adaptation is measured against.
    """
    return {**run_metrics(result, fan_pct), **phase_metrics(result, fan_pct)}


def comparison_metrics(scenario: Scenario, results: dict[str, SimulationResult]) -> dict:
    """Each controller's run metrics (:func:`law_run_metrics`)."""
    out = {}
    fan = None
    for cid, res in results.items():
        if fan is None or len(fan) != len(res.time_s):
            fan = fan_throttle_series(scenario, res.time_s)
        out[cid] = law_run_metrics(res, fan)
    return {"scenario": scenario.name, "controllers": out}


def _basis(scenario: Scenario):
    """The force-model basis the scenario's controller adapts."""
    from ..bases import describe_basis

    return describe_basis(scenario.load_vehicle(), scenario.controller.basis)


def convergence_metrics(scenario: Scenario, results: list[SimulationResult]) -> dict:
    """Spread of theta-hat across runs at the end over at the start, per parameter (of the controller's basis)."""
    names = results[0].theta_names
    theta = np.stack([r.theta_hat for r in results])  # runs x T x n
    std_start = theta[:, 0, :].std(axis=0, ddof=1)
    std_end = theta[:, -1, :].std(axis=0, ddof=1)
    ratio = {name: float(std_end[i] / std_start[i]) if std_start[i] > 0 else float("nan")
             for i, name in enumerate(names)}
    fan = fan_throttle_series(scenario, results[0].time_s)
    per_run = [run_metrics(r, fan) for r in results]
    force_start, force_end = _predicted_force_spread(scenario, results, theta)
    theta_0 = _basis(scenario).theta_scaled
    truth = results[0].metadata["theta_true_scaled"]
    return {
        # what the data identify: the force each run's theta-hat predicts at the final operating
        # point (collinear parameters may wander; their combination should not)
        "predicted_force_std_start_mps2": force_start,
        "predicted_force_std_end_mps2": force_end,
        "predicted_force_std_ratio": force_end / force_start if force_start > 0 else float("nan"),
        "scenario": scenario.name, "runs": len(results),
        "param_std_ratio": ratio,
        "theta_hat_final_mean_scaled": dict(zip(names, theta[:, -1, :].mean(axis=0).tolist())),
        "theta_hat_final_std_scaled": dict(zip(names, std_end.tolist())),
        # the plant's truth in the basis (none where the basis has no plant truth)
        "theta_true_scaled": dict(zip(names, truth)) if len(truth) == len(names) else None,
        "vel_err_rms_mps_per_run": [m["vel_err_rms_mps"] for m in per_run],
        "pred_err_p95_g_per_run": [m.get("pred_err_p95_g", float("nan")) for m in per_run],
        # which directions of theta each run's data determine (eigen-spectrum of its information)
        "identifiability_per_run": [run_identifiability(r, theta_0) for r in results],
    }


def _predicted_force_spread(scenario: Scenario, results: list[SimulationResult], theta: np.ndarray):
    """Norm of the across-run std of ``Phi(v_i, u) theta-hat`` at the runs' mean final operating
    point, with theta-hat at the start and at the end (m/s^2); ``Phi`` the controller's basis's."""
    from ..bases import evaluate, input_rows
    from ..models import THROTTLE_FULL_PCT

    vehicle = scenario.load_vehicle()
    names = ("ctrl_v_i_x_mps", "ctrl_v_i_y_mps", "ctrl_v_i_z_mps", "cmd_u_x_frac", "cmd_u_z_frac")
    last = np.array([[r[n][-1] for n in names] for r in results])  # each run's last tick
    v_i = last[:, :3].mean(axis=0)
    u_x = 100.0 * last[:, 3].mean()
    u_z = 100.0 * last[:, 4].mean()
    x = input_rows(v_i, u_x / THROTTLE_FULL_PCT, u_z / THROTTLE_FULL_PCT, vehicle.model_kernel)
    Phi = evaluate(_basis(scenario), x)[0]
    f_start = theta[:, 0, :] @ Phi.T
    f_end = theta[:, -1, :] @ Phi.T
    return (float(np.linalg.norm(f_start.std(axis=0, ddof=1))),
            float(np.linalg.norm(f_end.std(axis=0, ddof=1))))


# --- identifiability: what the data of a run determine ----------------------------------------------
IDENTIFIABILITY_SENSITIVITY_MIN_MPS2 = 1.0
"""A direction of theta is *determined* by a run if its sensitivity (below) is at least this: a
10 % error of theta along it then changes the run's RMS predicted specific force by at least
0.1 m/s^2 (0.01 g, a fifth of the paper's 0.05 g prediction-error bound), which the data show."""

DOMINANT_COMPONENT_MIN = 0.3
"""A parameter is named in an eigenvector's description if its component's magnitude is at least this."""


def identifiability(information_sum: np.ndarray, theta_0: np.ndarray, adapt_time_s: float,
                    names: tuple[str, ...] = PARAMETER_NAMES) -> dict:
    """The eigen-spectrum of a run's un-forgotten information ``sum w W^T W dt`` and the directions it determines.

    The information is taken in *relative* coordinates, ``theta = diag(|theta_0|) (1 + delta)``, so
    that the n parameters (``names``, the basis's; the paper's eight by default), in different units, are
    comparable: ``A = D S D / T`` with
    ``D = diag(|theta_0|)`` (1 where theta_0 = 0) and ``T`` the time the law adapted. An eigenvalue
    ``mu`` of ``A`` says that a relative change ``delta`` along its eigenvector changes the predicted
    specific force by ``sqrt(mu) |delta|`` RMS over the run: the direction's *sensitivity*
    ``sqrt(mu)`` (m/s^2). Directions with a sensitivity of at least
    :data:`IDENTIFIABILITY_SENSITIVITY_MIN_MPS2` are *determined*; the others are left to the prior
    (and, with forgetting toward the prior or sigma, drift back to it).

    Returns a JSON-ready dict: ``sensitivity_mps2`` per direction (largest first), each
    eigenvector's components by parameter, its ``dominant`` parameters (signed components of
    magnitude >= :data:`DOMINANT_COMPONENT_MIN`), ``determined`` flags and their count, and the
    threshold used.

    Raises ValueError unless ``information_sum`` is a finite, symmetric (n, n) matrix (or its n^2
    entries), ``theta_0`` n finite numbers and ``adapt_time_s`` a finite time > 0 s (with no
    time adapted there is no information, and dividing by it would report every direction determined).
    """
    n = len(names)
    S = np.asarray(information_sum, dtype=float)
    if S.shape not in ((n, n), (n * n,)):
        raise ValueError(f"identifiability: information_sum has shape {S.shape}; allowed: ({n}, {n}) or ({n * n},)")
    S = S.reshape(n, n)
    if not np.all(np.isfinite(S)) or not np.allclose(S, S.T, rtol=1e-9, atol=0.0):
        raise ValueError("identifiability: information_sum must be finite and symmetric (a sum of W^T W dt)")
    th0 = np.asarray(theta_0, dtype=float)
    if th0.shape != (n,) or not np.all(np.isfinite(th0)):
        raise ValueError(f"identifiability: theta_0 must be {n} finite numbers, got shape {th0.shape}")
    T = float(adapt_time_s)
    if not (math.isfinite(T) and T > 0.0):
        raise ValueError(f"identifiability: adapt_time_s = {adapt_time_s!r}: must be a finite time > 0 s")
    return _spectrum(S, th0, T, names)


def _spectrum(S: np.ndarray, theta_0: np.ndarray, adapt_time_s: float, names: tuple[str, ...]) -> dict:
    """:func:`identifiability` without the checks (a run's own sum, possibly after no adapting at all)."""
    scale = np.where(np.asarray(theta_0) != 0.0, np.abs(theta_0), 1.0)
    A = scale[:, None] * S * scale[None, :] / max(adapt_time_s, 1e-12)
    mu, V = np.linalg.eigh(0.5 * (A + A.T))
    order = np.argsort(mu)[::-1]
    mu = np.clip(mu[order], 0.0, None)
    V = V[:, order]
    sens = np.sqrt(mu)
    directions = []
    for k in range(len(mu)):
        v = V[:, k] * (1.0 if V[np.argmax(np.abs(V[:, k])), k] > 0 else -1.0)  # largest component positive
        dom = sorted(((names[i], float(v[i])) for i in range(len(v)) if abs(v[i]) >= DOMINANT_COMPONENT_MIN),
                     key=lambda p: -abs(p[1]))
        directions.append({
            "sensitivity_mps2": float(sens[k]),
            "determined": bool(sens[k] >= IDENTIFIABILITY_SENSITIVITY_MIN_MPS2),
            "dominant": " ".join(f"{'+' if c > 0 else '-'}{abs(c):.2f} {n}" for n, c in dom),
            "components": dict(zip(names, (float(c) for c in v))),
        })
    return {
        "threshold_sensitivity_mps2": IDENTIFIABILITY_SENSITIVITY_MIN_MPS2,
        "adapt_time_s": float(adapt_time_s),
        "n_determined": int(sum(d["determined"] for d in directions)),
        "directions": directions,
    }


def run_identifiability(result: SimulationResult, theta_0: np.ndarray) -> dict | None:
    """:func:`identifiability` of one run from its metadata's ``information_sum`` (None if it has none)."""
    S = result.metadata.get("information_sum")
    if S is None or "adaptation_active" not in result:
        return None
    dt = float(result.metadata.get("dt_control_s", np.median(np.diff(result.time_s))))
    t_adapt = float(np.sum(result["adaptation_active"] > 0.5)) * dt
    # a run that never adapted has an all-zero sum: its spectrum (nothing determined) is still reported
    names = result.theta_names
    n = len(names)
    return _spectrum(np.asarray(S, dtype=float).reshape(n, n), theta_0, t_adapt, names)
