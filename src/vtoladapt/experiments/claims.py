"""The paper's claims as measurable statements, each with its value, threshold and verdict."""
from __future__ import annotations

import math
from typing import Optional

from ..control.registry import COMPOSITE_IDS, PAPER_ADAPTIVE_IDS, PAPER_BASELINE_IDS

CLAIM_UNITS: dict[str, str] = {
    "pd_large_errors_at_high_wind": "ratio",
    "pid_overshoots_when_fan_stops": "ratio",
    "adaptive_track_best": "ratio",
    "composite_prediction_error_below_0p05g": "g",
    "theta_spread_shrinks": "ratio",
    "predicted_force_spread_shrinks": "ratio",
}
"""Unit of each claim's value and threshold, as the reports print it."""


def check_claims(comparison: Optional[dict], convergence: Optional[dict]) -> dict:
    """The claims the given experiments can test: name -> ``{holds, value, threshold, statement}``."""
    claims = {}
    if comparison is not None:
        c = comparison["controllers"]
        if "pd" in c and "composite" in c:
            v = c["pd"]["vel_err_rms_high_wind_mps"] / c["composite"]["vel_err_rms_high_wind_mps"]
            claims["pd_large_errors_at_high_wind"] = _claim(
                v, 3.0, v >= 3.0, "PD's velocity error at fan >= 60 % is at least 3x C. Adapt's")
        adaptive = [k for k in PAPER_ADAPTIVE_IDS if k in c]  # the paper's claims are about I-III
        if "pid" in c and adaptive and "overshoot_after_fan_off_mps" in c["pid"]:
            worst = max(c[k]["overshoot_after_fan_off_mps"] for k in adaptive)
            v = c["pid"]["overshoot_after_fan_off_mps"] / worst
            claims["pid_overshoots_when_fan_stops"] = _claim(
                v, 1.0, v > 1.0, "PID's peak velocity error after the fan stops exceeds every "
                                 "adaptive controller's (ratio to the worst adaptive)")
        baselines = [k for k in PAPER_BASELINE_IDS if k in c]
        if adaptive and baselines:
            v = max(c[k]["vel_err_rms_mps"] for k in adaptive) / min(c[k]["vel_err_rms_mps"] for k in baselines)
            claims["adaptive_track_best"] = _claim(
                v, 1.0, v < 1.0, "every adaptive controller's RMS velocity error is below PID's and "
                                 "PD's (worst adaptive / best baseline)")
        comp = [k for k in COMPOSITE_IDS if k in c]
        if comp:
            v = max(c[k]["pred_err_p95_g"] for k in comp)
            claims["composite_prediction_error_below_0p05g"] = _claim(
                v, 0.05, v < 0.05, "95th percentile of the composite controllers' prediction error "
                                   "norm is below 0.05 g")
    if convergence is not None:
        ratios = [r for r in convergence["param_std_ratio"].values() if math.isfinite(r)]
        v = max(ratios)
        claims["theta_spread_shrinks"] = _claim(
            v, 1.0, v < 1.0, "the spread of theta-hat across runs at the end is below that at the "
                             "start for every parameter (largest ratio)")
        v = convergence["predicted_force_std_ratio"]
        claims["predicted_force_spread_shrinks"] = _claim(
            v, 1.0, v < 1.0, "the force the runs' theta-hat predict at the final operating point "
                             "agrees across runs better at the end than at the start (std ratio)")
    return claims


def _claim(value: float, threshold: float, holds: bool, statement: str) -> dict:
    return {"holds": bool(holds), "value": float(value), "threshold": float(threshold),
            "statement": statement}
