"""Issue #24's measurements from two envelope campaigns on the same draws: surfaces on and surfaces off.

    vtoladapt campaign scenarios/envelope.toml --out out/env_on
    (the same file with [campaign.set.allocation] surfaces = false) --out out/env_off
    python docs/measure_airframe.py out/env_on out/env_off docs/airframe_summary.json

Both campaigns draw the same aircraft and winds (the same campaign seed and variations; the physical
parameters of each run are drawn from its seed on their own stream), so every row of one has its twin
in the other. It writes, for each: every target's fraction of draws with its 95 % Wilson interval; the
allocator-saturated share of each run's time per vehicle and per fan-bearing band (median, IQR and a
distribution-free 95 % interval of the median from the binomial order statistics), over all
controllers' runs, and the share where even lift, roll and pitch were unmet (not only yaw); and, paired draw by draw, the share of draws where the surfaces lowered each
controller's RMS velocity error.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from scipy.stats import binom

from vtoladapt.stats import fraction_holding


def median_ci(values, confidence: float = 0.95) -> dict:
    """Median, IQR and the order-statistic interval ``[x_(j), x_(k)]`` that holds the median with at least
    ``confidence`` (``j``, ``k`` from the Binomial(n, 1/2) quantiles)."""
    x = np.sort(np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float))
    n = x.size
    if n == 0:
        return {"median": None, "iqr": None, "ci95": None, "n": 0}
    lo = int(binom.ppf((1 - confidence) / 2, n, 0.5))
    hi = int(binom.isf((1 - confidence) / 2, n, 0.5))
    return {"median": float(np.median(x)), "iqr": [float(np.percentile(x, 25)), float(np.percentile(x, 75))],
            "ci95": [float(x[max(lo - 1, 0)]), float(x[min(hi, n - 1)])], "n": int(n)}


def _table(folder: Path) -> dict:
    t = pq.read_table(folder / "campaign.parquet").to_pydict()
    return t


def saturation(t: dict) -> dict:
    out: dict = {}
    vehicles = sorted(set(t["choice.vehicle"]))
    for veh in vehicles:
        rows = [i for i, v in enumerate(t["choice.vehicle"]) if v == veh]
        entry = {"all": median_ci(t["mixer_saturated_fraction"][i] for i in rows)}
        for band in sorted(set(t["group.fan bearing"][i] for i in rows)):
            entry[band] = median_ci(t["mixer_saturated_fraction"][i] for i in rows if t["group.fan bearing"][i] == band)
        entry["composite"] = median_ci(t["mixer_saturated_fraction"][i] for i in rows if t["controller"][i] == "composite")
        if "lift_attitude_unmet_fraction" in t:  # the share where more than yaw was unmet
            entry["lift_attitude_unmet"] = median_ci(t["lift_attitude_unmet_fraction"][i] for i in rows)
        out[veh] = entry
    return out


def paired(on: dict, off: dict) -> dict:
    """Per controller: the share of draws where surfaces on gave a lower RMS velocity error than off."""
    key = lambda t, i: (t["run"][i], t["controller"][i])  # noqa: E731
    off_at = {key(off, i): i for i in range(len(off["run"]))}
    out = {}
    for cid in sorted(set(on["controller"])):
        outcomes = []
        for i in range(len(on["run"])):
            if on["controller"][i] != cid:
                continue
            j = off_at.get(key(on, i))
            if j is None:
                continue
            a, b = on["vel_err_rms_mps"][i], off["vel_err_rms_mps"][j]
            outcomes.append(None if not (math.isfinite(a) and math.isfinite(b)) else bool(a < b))
        out[cid] = fraction_holding(outcomes).as_dict()
    return out


def main(on_dir: str, off_dir: str, out_path: str) -> None:
    on_dir, off_dir = Path(on_dir), Path(off_dir)
    on, off = _table(on_dir), _table(off_dir)
    assert on["seed"] == off["seed"], "the two campaigns must fly the same draws"
    result = {"draws": len(set(on["run"])), "controllers": sorted(set(on["controller"]))}
    for label, folder, t in (("surfaces_on", on_dir, on), ("surfaces_off", off_dir, off)):
        summary = json.loads((folder / "summary.json").read_text())
        result[label] = {"targets": {k: {x: v[x] for x in ("fraction", "ci95", "n", "successes")}
                                     for k, v in summary["targets"].items()},
                         "saturated_fraction": saturation(t),
                         "vel_err_rms_mps": {c: median_ci(t["vel_err_rms_mps"][i] for i in range(len(t["run"]))
                                                          if t["controller"][i] == c)
                                             for c in result["controllers"]},
                         "wall_time_s": summary["campaign"]["wall_time_s"]}
    result["surfaces_lower_vel_err"] = paired(on, off)
    Path(out_path).write_text(json.dumps(result, indent=1))
    for label in ("surfaces_on", "surfaces_off"):
        r = result[label]
        print(label, {k: f"{v['successes']}/{v['n']} [{v['ci95'][0]:.2f}, {v['ci95'][1]:.2f}]"
                      for k, v in r["targets"].items()})
        for veh, e in r["saturated_fraction"].items():
            print("  saturated", veh, {b: f"{100 * v['median']:.1f} % [{100 * v['ci95'][0]:.1f}, {100 * v['ci95'][1]:.1f}]"
                                       for b, v in e.items() if v["median"] is not None})
    print("surfaces lower RMS |v~| (share of draws):",
          {c: f"{v['successes']}/{v['n']}" for c, v in result["surfaces_lower_vel_err"].items()})


if __name__ == "__main__":
    main(*sys.argv[1:4])
