"""Issue #36's measurements: the paper's hold and its comparison claims on the native and the JSBSim engine.

    python docs/measure_jsbsim.py 30 docs/jsbsim_results.json

1. ``paper_comparison`` (50 s, its seed) flown once by each of its controllers on each engine: RMS and
   largest distance from the held point over the run;
2. the same comparison over ``n`` seeded variants on each engine (:func:`vtoladapt.experiments.distribution.
   fly_variants`, as ``make reproduce`` flies its comparison variants with the scenario's own controller
   settings): each claim as the fraction of variants where it holds with its 95 % Wilson interval, and each
   law's RMS position error (median, IQR).

Nothing is tuned to either engine: the scenario is flown as written with ``[plant] engine`` switched.
"""
from __future__ import annotations

import dataclasses
import json
import sys
import time

import numpy as np

from vtoladapt.experiments.distribution import fly_variants, summarize_claims, summarize_controllers
from vtoladapt.sim.driver import simulate
from vtoladapt.sim.scenario import load_scenario

ENGINES = ("native", "jsbsim")


def on(scenario, engine: str):
    return scenario.replace(plant=dataclasses.replace(scenario.plant, engine=engine))


def hold_once(base) -> dict:
    out = {}
    for cid in base.experiment.controllers:
        for engine in ENGINES:
            sc = on(base, engine).replace(controller=dataclasses.replace(base.controller, kind=cid))
            r = simulate(sc)
            held = np.array(base.reference.position_m)
            e = np.linalg.norm(r.columns_like(("p_N_m", "p_E_m", "p_D_m")) - held, axis=1)
            out[f"{cid}/{engine}"] = {"diverged_at_s": r.metadata["diverged_at_s"],
                                      "finite": bool(np.isfinite(r.data).all()),
                                      "rms_pos_err_m": float(np.sqrt(np.mean(e**2))), "max_pos_err_m": float(e.max())}
    return out


def variants(base, n: int) -> dict:
    out = {}
    for engine in ENGINES:
        t0 = time.perf_counter()
        vs = fly_variants(on(base, engine), n)
        ctrls = summarize_controllers(vs)
        out[engine] = {"wall_s": time.perf_counter() - t0, "claims": summarize_claims(vs),
                       "pos_err_rms_m": {c: m.get("pos_err_rms_m") for c, m in ctrls.items()}}
    return out


def main(argv: list[str]) -> None:
    n, path = int(argv[0]), argv[1]
    base = load_scenario("paper_comparison")
    result = {"scenario": base.name, "hold_once": hold_once(base), "variants": n, "engines": variants(base, n)}
    with open(path, "w", encoding="utf-8") as f:
        json.dump(result, f, indent=1, default=str)


if __name__ == "__main__":
    main(sys.argv[1:])
