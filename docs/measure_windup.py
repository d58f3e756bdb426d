"""Measure covariance wind-up of the paper's pure forgetting against the shipped forgetting toward P0.

The paper's eq:P_adapt, ``(P^-1)' = W^T W - lambda P^-1`` (``[controller.composite] forgetting =
"paper"``), lets the information decay in every direction the regressor does not excite; the
shipped law forgets toward P0 (``forgetting = "prior"``). Both fly, on the same seeds, where
excitation is poor for a long time:

* ``hover``: a 600 s still-air hold (``scenarios/long_hour.toml`` with the fan off throughout);
* ``hour``: ``scenarios/long_hour.toml`` itself, one hour of hover with 12 fan cycles to 60 %
  (still air 60 s, ramp 30 s, hold 150 s, stop 30 s, still 30 s);

each with the scenario's realistic sensors and with an ideal airflow probe (the true incident
velocity, always valid: in still air it reads the aircraft's own few cm/s, so the aerodynamic
columns of the regressor are nearly zero; the realistic probe reads nothing below 1 m/s and the
controller's estimate of the incident velocity then carries velocity noise, which excites them a
little). Every 5 s of flight the controller's information matrix ``Gamma = P^-1`` is read:
``lambda_max(P) = 1 / lambda_min(Gamma)`` and ``trace(P)`` (inf once Gamma is numerically
singular); theta-hat and the tracking and prediction errors come from the log.

    .venv/bin/python docs/measure_windup.py [N]     # N seeds (default 10), about 6 min on 2 cores

Seeds: the first N evaluation variants of long_hour's seed (``SeedSequence([11, 0xD157])``), each
its own plant draw, turbulence and sensor noise. Paired differences (paper - prior) over the seeds:
Hodges-Lehmann estimate and 95 % signed-rank interval (:mod:`vtoladapt.experiments.pairs`).
Writes docs/windup.json (the README's numbers are rounded from it by hand).
"""
from __future__ import annotations

import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from vtoladapt.control.blocks import FAULT_ADAPTATION
from vtoladapt.control.step import state_P_inv
from vtoladapt.experiments.distribution import _pool_map, variant_seeds
from vtoladapt.experiments.pairs import paired_difference
from vtoladapt.sim.driver import controller_prior, prepare, run_chunk
from vtoladapt.sim.scenario import SCENARIO_DIR, load_scenario

OUT = Path(__file__).with_name("windup.json")
MODES = ("prior", "paper")
CHUNK_S = 5.0
HOVER_S = 600.0
CYCLE_S = 300.0          # long_hour: still 0-60 s, ramp 60-90, hold 90-240, stop 240-270, still 270-300
NAMES = ("CTx", "CTz", "CS", "CD0", "CD1", "CD2", "CL0", "CL1")
G0_MPS2 = 9.80665


def fly(scenario, every_s: float = CHUNK_S) -> dict:
    """Fly ``scenario`` in chunks of ``every_s``; per tick |v~| and |e|/g, per chunk end P's size and theta-hat."""
    run = prepare(scenario)
    _, theta0, _, lower, upper, _ = controller_prior(scenario, run.vehicle)
    col = {c: i for i, c in enumerate(run.log_layout.columns)}  # this run's law and basis
    vt_cols = [col[f"v_tilde_{a}_mps"] for a in "NED"]
    pe_cols = [col[f"pred_err_{a}_mps2"] for a in "xyz"]
    th_cols = [col[f"theta_hat_{n}"] for n in NAMES]
    x = run.x0.copy()
    n, ch = scenario.n_ticks, int(round(every_s / scenario.dt_control_s))
    log = np.empty((ch, run.log_layout.size))
    t, vt, pe, faults = [], [], [], []
    t_chunk, p_max, p_trace, theta = [], [], [], []
    for k0 in range(0, n, ch):
        done, reason = run_chunk(run, x, k0, min(n, k0 + ch), log[:min(n, k0 + ch) - k0])
        rows = log[:done]
        t.append(rows[:, 0].copy())
        vt.append(np.linalg.norm(rows[:, vt_cols], axis=1))
        pe.append(np.linalg.norm(rows[:, pe_cols], axis=1) / G0_MPS2)
        faults.append((rows[:, col["fault_flags"]].astype(np.int64) & FAULT_ADAPTATION) != 0)
        gamma = state_P_inv(run.controller_params, run.controller_state)
        eig = np.linalg.eigvalsh(0.5 * (gamma + gamma.T))
        t_chunk.append((k0 + done) * scenario.dt_control_s)
        p_max.append(float(1.0 / eig[0]) if eig[0] > 0.0 else float("inf"))
        p_trace.append(float(np.sum(1.0 / eig)) if eig[0] > 0.0 else float("inf"))
        theta.append(rows[-1, th_cols].copy() if done else np.full(len(NAMES), np.nan))
        if reason != 0:
            break
    return {"t": np.concatenate(t), "vt": np.concatenate(vt), "pe": np.concatenate(pe),
            "faults": np.concatenate(faults), "t_chunk": np.array(t_chunk), "p_max": np.array(p_max),
            "p_trace": np.array(p_trace), "theta": np.array(theta), "lower": lower, "upper": upper,
            "theta0": theta0, "diverged": bool(reason != 0)}


def rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else float("nan")


def theta_summary(r: dict, after_s: float, until_s: float | None = None) -> dict:
    """Per parameter: the share of the bound box theta-hat swept, and the share of chunk ends at a bound."""
    m = r["t_chunk"] >= after_s
    if until_s is not None:
        m &= r["t_chunk"] < until_s
    th = r["theta"][m]
    width = r["upper"] - r["lower"]
    at_bound = (np.isclose(th, r["lower"], rtol=0, atol=1e-9 * width)
                | np.isclose(th, r["upper"], rtol=0, atol=1e-9 * width))
    return {n: {"swept_fraction_of_box": float((th[:, i].max() - th[:, i].min()) / width[i]),
                "at_bound_fraction": float(at_bound[:, i].mean()),
                "min": float(th[:, i].min()), "max": float(th[:, i].max()),
                "lower": float(r["lower"][i]), "upper": float(r["upper"][i]), "theta0": float(r["theta0"][i])}
            for i, n in enumerate(NAMES)}


def hover_metrics(r: dict) -> dict:
    late = r["t"] >= 60.0
    ctz = r["theta"][:, NAMES.index("CTz")]
    ref = ctz[np.searchsorted(r["t_chunk"], 60.0)]
    at = {f"{s:g}": float(r["p_max"][min(np.searchsorted(r["t_chunk"], s - 1e-6), len(r["p_max"]) - 1)])
          for s in (10.0, 30.0, 60.0, 120.0, 300.0, HOVER_S)}
    return {"vel_err_rms_mps": rms(r["vt"][late]), "pred_err_p95_g": float(np.percentile(r["pe"][late], 95)),
            "P_eig_max": float(np.max(r["p_max"])), "P_trace_max": float(np.max(r["p_trace"])),
            "P_eig_max_at_s": at, "CTz_drift_max": float(np.max(np.abs(ctz[r["t_chunk"] >= 60.0] - ref))),
            "adaptation_fault_ticks": int(r["faults"].sum()), "diverged": r["diverged"],
            "theta": theta_summary(r, 60.0)}


def hour_metrics(r: dict) -> dict:
    t = r["t"]
    phase = np.mod(t, CYCLE_S)
    fan = (phase >= 60.0) & (phase < 270.0)
    still = ~fan
    cycles = []
    for c in range(int(round(t[-1] / CYCLE_S + 0.5))):
        c0 = c * CYCLE_S
        ramp = (t >= c0 + 60.0) & (t < c0 + 120.0)
        off = (t >= c0 + 240.0) & (t < c0 + 300.0)
        cm = (r["t_chunk"] >= c0) & (r["t_chunk"] < c0 + CYCLE_S)
        if not ramp.any():
            break
        cycles.append({"peak_ramp_mps": float(r["vt"][ramp].max()), "peak_stop_mps": float(r["vt"][off].max()),
                       "P_eig_max": float(np.max(r["p_max"][cm]))})
    return {"vel_err_rms_mps": rms(r["vt"]), "vel_err_rms_fan_mps": rms(r["vt"][fan]),
            "vel_err_rms_still_mps": rms(r["vt"][still]),
            "peak_ramp_mps": float(np.median([c["peak_ramp_mps"] for c in cycles])),
            "peak_stop_mps": float(np.median([c["peak_stop_mps"] for c in cycles])),
            "pred_err_p95_fan_g": float(np.percentile(r["pe"][fan], 95)),
            "P_eig_max": float(np.max(r["p_max"])), "P_trace_max": float(np.max(r["p_trace"])),
            "P_eig_max_fan_end": float(np.median([r["p_max"][np.searchsorted(r["t_chunk"], c * CYCLE_S + 240.0 - 1e-6)]
                                                  for c in range(len(cycles))])),
            "adaptation_fault_ticks": int(r["faults"].sum()), "diverged": r["diverged"],
            "cycles": cycles, "theta_still": theta_summary(r, 0.0)}


def scenarios():
    hour = load_scenario(SCENARIO_DIR / "long_hour.toml")
    hover = replace(hour, name="long_hover", duration_s=HOVER_S,
                    wind=replace(hour.wind, fan_array=replace(hour.wind.fan_array,
                                                              schedule=((0.0, 0.0), (HOVER_S, 0.0)))))
    return {"hover": (hover, hover_metrics), "hour": (hour, hour_metrics)}


def with_case(scenario, mode: str, probe: str):
    sensors = scenario.sensors
    if probe == "ideal":
        sensors = replace(sensors, probe=replace(sensors.probe, ideal=True))
    c = scenario.controller
    return replace(scenario, sensors=sensors,
                   controller=replace(c, kind="composite", composite=replace(c.composite, forgetting=mode)))


PAIRED = ("vel_err_rms_mps", "vel_err_rms_fan_mps", "vel_err_rms_still_mps", "peak_ramp_mps", "peak_stop_mps",
          "pred_err_p95_g", "pred_err_p95_fan_g", "CTz_drift_max")


def main(n: int) -> None:
    t0 = time.perf_counter()
    out: dict = {"seeds_n": n, "chunk_s": CHUNK_S, "cases": {}}
    for name, (base, metrics) in scenarios().items():
        seeds = variant_seeds(base.seed, n)
        out["cases"][name] = case = {"scenario": base.name, "duration_s": base.duration_s, "seeds": seeds}
        for probe in ("realistic", "ideal"):
            per = {}
            for mode in MODES:
                sc = with_case(base, mode, probe)
                per[mode] = _pool_map(lambda s: metrics(fly(replace(sc, seed=s))), seeds)
                print(f"{name} {probe} {mode}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
            entry = {"runs": per, "median": {}, "paired_paper_minus_prior": {}}
            for mode in MODES:
                entry["median"][mode] = {k: float(np.median([r[k] for r in per[mode]]))
                                         for k, v in per[mode][0].items() if isinstance(v, (int, float))}
            for k in PAIRED:
                if k in per["prior"][0]:
                    entry["paired_paper_minus_prior"][k] = paired_difference(
                        [r[k] for r in per["paper"]], [r[k] for r in per["prior"]])
            case[probe] = entry
    out["wall_s"] = time.perf_counter() - t0
    OUT.write_text(json.dumps(out, default=float, separators=(",", ":")))
    print(f"wrote {OUT} in {out['wall_s']:.0f} s")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 10)
