"""Measure each deviation of the code from the paper against the paper's own choice (README, "Deviations").

Every case flies the paper's comparison (or its convergence experiment) over the reproduction's
evaluation variants twice, with the shipped setting and with the paper's (or with the addition
switched off), and reports the paired difference, alternative minus shipped, of each metric
(Hodges-Lehmann estimate, 95 % signed-rank interval: :mod:`vtoladapt.experiments.pairs`) and, for
the convergence experiment, each claim's fraction of variants. Also two numbers the README states:
the desired angle of attack flown at 9 m/s (the comparison's 70 % plateau) and INDI's still-air
position error with and without the accelerometer bias.

    .venv/bin/python docs/measure_deviations.py [N]      # N variants (default 30), ~15 min on 2 cores

Writes docs/deviations.json (the README's table is written from it by hand, numbers rounded).
"""
from __future__ import annotations

import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from vtoladapt.control.registry import controller_ids
from vtoladapt.experiments.distribution import (
    PAIRED_METRICS, convergence_distribution, fly_variants, per_variant_values, variant_seeds,
    wind_condition_scenario,
)
from vtoladapt.experiments.metrics import fan_throttle_series, wind_phase_masks
from vtoladapt.experiments.pairs import paired_difference
from vtoladapt.sim.driver import simulate
from vtoladapt.sim.scenario import SCENARIO_DIR, load_scenario

OUT = Path(__file__).with_name("deviations.json")
METRICS = ("vel_err_rms_mps", "vel_err_rms_plateau_mps", "vel_err_rms_fan_off_mps", "overshoot_after_fan_off_mps",
           "pred_err_p95_g", "mixer_saturated_fraction")


def _nan(v):
    return [np.nan if x is None else x for x in v]


def comparison_case(comp, n, cid, **changes):
    """One law over the variants with the shipped settings and with ``changes`` (shared keys, or
    ``law=dict`` for its own table): the paired differences, alternative - shipped."""
    law = changes.pop("law", {})
    shipped = replace(comp.controller, kind=cid)
    alt = replace(shipped, **changes, **({cid: replace(getattr(shipped, cid), **law)} if law else {}))
    base = replace(comp, experiment=replace(comp.experiment, controllers=(cid,)))
    a = per_variant_values(fly_variants(base, n, controllers={cid: shipped}))[cid]
    b = per_variant_values(fly_variants(base, n, controllers={cid: alt}))[cid]
    out = {}
    for m in METRICS + tuple(k for k in PAIRED_METRICS if k not in METRICS):
        if m in a and m in b:
            r = paired_difference(_nan(b[m]), _nan(a[m]))
            r["shipped_median"] = float(np.nanmedian(_nan(a[m])))
            r["alternative_median"] = float(np.nanmedian(_nan(b[m])))
            out[m] = r
    return out


def convergence_case(conv, n, composite_changes=None, bounds=None):
    """The convergence experiment's claims and spread ratios over ``n`` variants."""
    sc = conv
    if composite_changes:
        sc = replace(conv, controller=replace(conv.controller,
                                              composite=replace(conv.controller.composite, **composite_changes)))
    if bounds is not None:
        import vtoladapt.control.step as step

        saved = step.theta_bounds
        step.theta_bounds = bounds
        try:
            d = convergence_distribution(sc, n)
        finally:
            step.theta_bounds = saved
    else:
        d = convergence_distribution(sc, n)
    return {"claims": {k: {"fraction": c["fraction"], "successes": c["successes"], "n": c["n"],
                           "ci95": c["ci95"], "value": c["value"]} for k, c in d["claims"].items()},
            "param_std_ratio": d["param_std_ratio"]}


def unsigned_bounds(theta_0, theta_std, bound_fraction, bound_sigmas, signs=None):
    """The bounds before issue #25: no cut at the signs physics gives (C_S could reach -0.5 theta_0)."""
    from vtoladapt.control.step import theta_bound_half_widths

    th0 = np.asarray(theta_0, dtype=float)
    half = theta_bound_half_widths(th0, theta_std, bound_fraction, bound_sigmas)
    return th0 - half, th0 + half


def alpha_d_at_9mps(comp, n):
    """Median over the variants of the composite law's desired angle of attack on the 70 % plateau (deg)."""
    vals = []
    for s in variant_seeds(comp.seed, n):
        res = simulate(replace(comp, seed=s))
        mask = wind_phase_masks(res.time_s, fan_throttle_series(comp, res.time_s))["plateau"]
        vals.append(float(np.degrees(np.median(res["alpha_d_rad"][mask]))))
    return {"median_deg": float(np.median(vals)), "iqr_deg": [float(np.percentile(vals, 25)),
                                                             float(np.percentile(vals, 75))], "n": n}


def indi_still_air(comp, n):
    """INDI's mean position error holding in still air (the wind table's cell), with and without the
    accelerometer bias: median over the variants (m)."""
    out = {}
    base = wind_condition_scenario(replace(comp, controller=replace(comp.controller, kind="indi")), "still")
    for name, bias in (("default_bias", comp.sensors.imu.accel_bias_std_mps2), ("no_bias", 0.0)):
        sc = replace(base, sensors=replace(base.sensors, imu=replace(base.sensors.imu, accel_bias_std_mps2=bias)))
        errs = []
        for s in variant_seeds(comp.seed, n):
            res = simulate(replace(sc, seed=s))
            late = res.time_s >= 5.0
            errs.append(float(np.linalg.norm(res.position_error_W[late], axis=1).mean()))
        out[name] = {"accel_bias_std_mps2": bias, "pos_err_mean_m": float(np.median(errs))}
    return out


def main(n: int) -> None:
    comp = load_scenario(SCENARIO_DIR / "paper_comparison.toml")
    conv = load_scenario(SCENARIO_DIR / "paper_convergence.toml")
    t0 = time.perf_counter()
    out = {"variants": n, "seeds": variant_seeds(comp.seed, n), "cases": {}}
    cases = out["cases"]
    cases["forgetting_paper"] = {
        "comparison": comparison_case(comp, n, "composite", law={"forgetting": "paper"}),
        "convergence_shipped": convergence_case(conv, n),
        "convergence_paper": convergence_case(conv, n, {"forgetting": "paper"})}
    cases["tracking_gain_rule_paper"] = {"comparison": comparison_case(comp, n, "tracking_only",
                                                                       law={"gain_rule": "paper"})}
    cases["regressor_motor_lag_off"] = {"comparison": comparison_case(comp, n, "composite", regressor_motor_lag=False)}
    cases["lift_rotor_reserve_off"] = {"comparison": comparison_case(comp, n, "composite", lift_rotor_reserve_mps2=0.0)}
    cases["flow_angle_protection_off"] = {"comparison": comparison_case(comp, n, "composite",
                                                                        alpha_protect_gain_per_s=0.0)}
    cases["weathervane_off"] = {"comparison": comparison_case(comp, n, "composite",
                                                              weathervane_airspeed_mps=(60.0, 61.0))}
    cases["unsigned_bounds"] = {"convergence": convergence_case(conv, n, bounds=unsigned_bounds)}
    for cid in ("pid", "pd"):
        cases[f"{cid}_feedforward_a_d"] = {"comparison": comparison_case(comp, n, cid, law={"feedforward": "a_d"})}
    out["alpha_d_at_9mps"] = alpha_d_at_9mps(comp, n)
    out["indi_still_air"] = indi_still_air(comp, n)
    out["wall_s"] = time.perf_counter() - t0
    OUT.write_text(json.dumps(out, indent=1))
    print(f"wrote {OUT} in {out['wall_s']:.0f} s")


if __name__ == "__main__":
    assert "composite" in controller_ids()
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 30)
