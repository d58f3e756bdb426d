"""Measure the composite law's Kalman form and composite_indi against the paper's law, INDI and PID (issue #34).

Draws: the committed envelope campaign (``vtoladapt/scenarios/envelope.toml``, 200 draws, seed 1111), the same
draws, plants, winds and sensor noise as ``vtoladapt campaign``. The split: draws 150-155 were used to choose
the Kalman form's defaults (``measurement_noise_scale``, ``kalman_time_scale_s``); the evaluation is on draws
``0 .. --draws - 1`` (held out). Every law flies every draw on the same seed.

Laws: composite with the paper's estimator and with the Kalman form, composite_indi with each, all four on the
learned basis (both shipped vehicles have a trained file); INDI and PID (theta-hat = theta_0, the vehicle's
default basis). Per run: RMS ||v~|| (m/s, whole run, true state), the yardstick's worst-airspeed-bin p95
prediction error on probe-valid samples one tick ahead and 0.5 s ahead (theta-hat frozen), the constant-weights
ceiling fitted on the run's own log, and the pass flags (p95 < 0.05 g in every bin).

    PYTHONPATH=src python docs/measure_kalman.py --draws 40 --out docs/kalman_comparison.json

writes the per-draw values and the summary (medians, pass fractions with Wilson intervals, paired differences of
RMS ||v~|| against the paper's composite law and against INDI with 95 % intervals).
"""
from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path

import numpy as np

LAWS = {
    "composite_paper": {"kind": "composite", "basis": "learned"},
    "composite_kalman": {"kind": "composite", "basis": "learned", "composite": {"estimator": "kalman"}},
    "composite_indi_paper": {"kind": "composite_indi", "basis": "learned"},
    "composite_indi_kalman": {"kind": "composite_indi", "basis": "learned", "composite_indi": {"estimator": "kalman"}},
    "indi": {"kind": "indi"},
    "pid": {"kind": "pid"},
}
METRICS = ("vel_err_rms_mps", "pred_valid_worst_g", "pred_horizon_worst_g", "ceiling_worst_g", "pred_valid_pass",
           "pred_horizon_pass", "ceiling_pass", "blind_fraction", "diverged")
CAMPAIGN = Path(__file__).resolve().parents[1] / "src" / "vtoladapt" / "scenarios" / "envelope.toml"
TUNING_DRAWS = (150, 151, 152, 153, 154, 155)


def fly(draws: int) -> dict:
    from vtoladapt.campaign.runner import plan_campaign_file
    from vtoladapt.experiments.envelope import envelope_run_metrics
    from vtoladapt.sim.driver import simulate
    from vtoladapt.sim.scenario import scenario_from_mapping

    _, specs = plan_campaign_file(CAMPAIGN, runs=200)
    first = {}
    for s in specs:
        first.setdefault(s.index, s)
    rows = {law: [] for law in LAWS}
    for i in range(draws):
        assert i not in TUNING_DRAWS
        s = first[i]
        for law, ctl in LAWS.items():
            m = copy.deepcopy(s.mapping)
            m["controller"] = {**m.get("controller", {}), **ctl}
            sc = scenario_from_mapping(m, s.source, source_path=s.source)
            t0 = time.perf_counter()
            met = envelope_run_metrics(simulate(sc), sc)
            rows[law].append({"draw": i, "vehicle": s.drawn.get("choice.vehicle"),
                              **{k: _num(met.get(k)) for k in METRICS}})
            print(f"draw {i} {law}: rms {rows[law][-1]['vel_err_rms_mps']:.4f} m/s "
                  f"({time.perf_counter() - t0:.1f} s)", file=sys.stderr, flush=True)
    return rows


def _num(v):
    return None if v is None or not np.isfinite(float(v)) else float(v)


def summarize(rows: dict) -> dict:
    from vtoladapt.experiments.pairs import paired_difference
    from vtoladapt.stats import fraction_holding, median_iqr

    def col(law, key):
        return np.array([np.nan if r[key] is None else r[key] for r in rows[law]], dtype=float)

    out = {"draws": len(rows["pid"]), "split": f"evaluation: envelope draws 0-{len(rows['pid']) - 1}; the Kalman "
           f"form's defaults were chosen on draws {TUNING_DRAWS[0]}-{TUNING_DRAWS[-1]}", "laws": {}, "paired_rms": {}}
    for law in rows:
        entry = {}
        for key in ("vel_err_rms_mps", "pred_valid_worst_g", "pred_horizon_worst_g", "ceiling_worst_g",
                    "blind_fraction"):
            m = median_iqr(col(law, key).tolist())
            entry[key] = m.as_dict()
        for key in ("pred_valid_pass", "pred_horizon_pass", "ceiling_pass"):
            f = fraction_holding([None if not np.isfinite(v) else bool(v) for v in col(law, key)])
            entry[key] = f.as_dict()
        h, c = col(law, "pred_horizon_worst_g"), col(law, "ceiling_worst_g")
        ok = np.isfinite(h) & np.isfinite(c)
        within = [bool(x) for x in (h[ok] <= 1.1 * c[ok])]
        f = fraction_holding(within)
        entry["horizon_within_10pct_of_ceiling"] = f.as_dict()
        out["laws"][law] = entry
    for ref in ("composite_paper", "indi", "pid"):
        for law in rows:
            if law != ref:
                out["paired_rms"][f"{law} - {ref}"] = paired_difference(col(law, "vel_err_rms_mps"),
                                                                        col(ref, "vel_err_rms_mps"))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=40)
    ap.add_argument("--out", type=Path, default=Path("docs/kalman_comparison.json"))
    a = ap.parse_args()
    if not 5 <= a.draws <= 150:
        print(f"error: --draws {a.draws}: allowed 5 to 150 (draws 150-155 tuned the defaults)", file=sys.stderr)
        return 2
    rows = fly(a.draws)
    summary = summarize(rows)
    a.out.write_text(json.dumps({"summary": summary, "per_draw": rows}, indent=1) + "\n")
    for law, e in summary["laws"].items():
        print(f"{law:24s} RMS|v~| median {e['vel_err_rms_mps']['median']:.4f} m/s  "
              f"p95 pred (valid, worst bin) {e['pred_valid_worst_g']['median']:.4f} g  "
              f"horizon {e['pred_horizon_worst_g']['median']:.4f} g  ceiling {e['ceiling_worst_g']['median']:.4f} g  "
              f"pass valid {e['pred_valid_pass']['fraction']:.2f} horizon {e['pred_horizon_pass']['fraction']:.2f}  "
              f"horizon<=1.1 ceiling {e['horizon_within_10pct_of_ceiling']['fraction']:.2f}")
    for k, d in summary["paired_rms"].items():
        if d["estimate"] is not None:
            print(f"{k:40s} {d['estimate']:+.4f} m/s  95 % [{d['ci95'][0]:+.4f}, {d['ci95'][1]:+.4f}]  {d['verdict']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
