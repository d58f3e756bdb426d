"""Issue #35's measurement: the envelope campaign's px4_standard_vtol draws flown with both allocators.

    python docs/measure_allocators.py N_DRAWS docs/allocator_summary.json [WORKERS]

Plans the committed envelope campaign (``scenarios/envelope.toml``: its seed 1111, its 200 draws, its
Latin hypercube) exactly as ``vtoladapt campaign`` does, keeps the first ``N_DRAWS`` draws whose vehicle is
``px4_standard_vtol`` (same seeds, plants, winds as the committed campaign's), and flies each with every
controller of the file twice: ``[allocation] method = "bounded_lsq"`` (the default) and ``"px4"`` with
``airmode = 1`` (PX4's ``MC_AIRMODE`` of the 1040 airframe). Both use the vehicle file's effectiveness
(``px4_ca``: PX4's belief); a third, ``bounded_lsq_truth``, believes the plant's own geometry
(``lift_rotors_surfaces``), to separate what the wrong belief costs. A fourth argument picks allocators
(comma-separated labels); results are added to an existing output of the same draws. Writes, per allocator: the allocator-saturated share of each run's time (median,
IQR and the order-statistic 95 % interval of the median, over every controller's runs and over the
composite's), the share where even lift, roll and pitch were unmet, every envelope target's fraction of draws
with its 95 % Wilson interval (``beats_pid_pd``: every adaptive law beats PID and PD), and each adaptive
law's own fraction of draws beating both.
"""
from __future__ import annotations

import copy
import json
import math
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.stats import binom

from vtoladapt.campaign.runner import plan_campaign_file, run_one
from vtoladapt.control.registry import adaptive_ids
from vtoladapt.experiments.envelope import envelope_summary
from vtoladapt.stats import fraction_holding

ROOT = Path(__file__).resolve().parents[1]
CAMPAIGN = ROOT / "scenarios" / "envelope.toml"
ALLOCATORS = {"bounded_lsq": {"method": "bounded_lsq"}, "px4": {"method": "px4", "airmode": 1},
              # the ablation: the allocator believes the plant's own geometry (belief = truth)
              "bounded_lsq_truth": {"method": "bounded_lsq", "effectiveness": "lift_rotors_surfaces"}}


def median_ci(values, confidence: float = 0.95) -> dict:
    """Median, IQR and the order-statistic interval holding the median with at least ``confidence``."""
    x = np.sort(np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float))
    n = x.size
    if n == 0:
        return {"median": None, "iqr": None, "ci95": None, "n": 0}
    lo = int(binom.ppf((1 - confidence) / 2, n, 0.5))
    hi = int(binom.isf((1 - confidence) / 2, n, 0.5))
    return {"median": float(np.median(x)), "iqr": [float(np.percentile(x, 25)), float(np.percentile(x, 75))],
            "ci95": [float(x[max(lo - 1, 0)]), float(x[min(hi, n - 1)])], "n": int(n)}


def beats_both(rows: list[dict]) -> dict:
    """Per adaptive law: the fraction of draws where its RMS velocity error is below PID's and PD's."""
    by_draw: dict = {}
    for r in rows:
        by_draw.setdefault(r["run"], {})[r["controller"]] = r["vel_err_rms_mps"]
    out = {}
    for cid in adaptive_ids():
        outcomes = []
        for d in sorted(by_draw):
            e = by_draw[d]
            if cid not in e or "pid" not in e or "pd" not in e:
                continue
            a = e[cid]
            outcomes.append(None if not all(math.isfinite(v) for v in (a, e["pid"], e["pd"]))
                            else bool(a < e["pid"] and a < e["pd"]))
        out[cid] = fraction_holding(outcomes).as_dict()
    return out


def main(n_draws: int, out_path: str, workers: int = 2, labels: tuple[str, ...] = tuple(ALLOCATORS)) -> None:
    _cf, specs = plan_campaign_file(CAMPAIGN)
    px4_draws = sorted({s.index for s in specs if s.drawn.get("choice.vehicle") == "px4_standard_vtol"})[:n_draws]
    chosen = [s for s in specs if s.index in set(px4_draws)]
    result: dict = {"campaign": str(CAMPAIGN.relative_to(ROOT)), "draws": px4_draws,
                    "controllers": sorted({s.controller for s in chosen}),
                    "allocators": {k: ALLOCATORS[k] for k in labels}}
    if Path(out_path).exists():  # add to an earlier measurement of the same draws
        earlier = json.loads(Path(out_path).read_text())
        if earlier.get("draws") == px4_draws:
            result = {**earlier, "allocators": {**earlier.get("allocators", {}), **result["allocators"]}}
    for label in labels:
        allocation = ALLOCATORS[label]
        runs = []
        for s in chosen:
            mapping = copy.deepcopy(s.mapping)
            mapping["allocation"] = {**mapping.get("allocation", {}), **allocation}
            runs.append(replace(s, mapping=mapping))
        wall0 = time.perf_counter()
        with ThreadPoolExecutor(max_workers=workers) as pool:
            rows = list(pool.map(run_one, runs))
        keys = list(dict.fromkeys(k for r in rows for k in r))
        summary = envelope_summary({k: [r.get(k) for r in rows] for k in keys})
        result[label] = {
            "saturated_fraction": median_ci(r["mixer_saturated_fraction"] for r in rows),
            "saturated_fraction_composite": median_ci(r["mixer_saturated_fraction"] for r in rows
                                                      if r["controller"] == "composite"),
            "lift_attitude_unmet_fraction": median_ci(r.get("lift_attitude_unmet_fraction") for r in rows),
            "targets": {k: {x: v[x] for x in ("fraction", "ci95", "n", "successes")}
                        for k, v in summary["targets"].items()},
            "beats_pid_and_pd": beats_both(rows),
            "wall_time_s": time.perf_counter() - wall0,
        }
        r = result[label]
        print(label, "saturated median", r["saturated_fraction"]["median"], r["saturated_fraction"]["ci95"],
              "beats_pid_pd", r["targets"]["beats_pid_pd"], flush=True)
    Path(out_path).write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main(int(sys.argv[1]), sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 2,
         tuple(sys.argv[4].split(",")) if len(sys.argv) > 4 else tuple(ALLOCATORS))
