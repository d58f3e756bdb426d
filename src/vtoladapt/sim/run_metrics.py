"""Metrics of one run, as the paper judges its controllers (velocity tracking, prediction error)."""
from __future__ import annotations

import numpy as np

from ..frames import GRAVITY_MPS2
from .results import SimulationResult

PRED_ERR_BOUND_G = 0.05
"""The paper's prediction-error bound (g), judged as the 95th percentile in every airspeed bin (the envelope
campaign's target, the constant-weights ceiling and the prediction yardstick all judge against it)."""
PRED_ERR_SKIP_S = 2.0
"""Prediction-error statistics skip the first seconds, while the filters and theta-hat settle."""
OVERSHOOT_WINDOW_S = 5.0
HIGH_WIND_THROTTLE_PCT = 60.0
AIRSPEED_BINS_MPS = (0.0, 2.0, 5.0, 8.0, 11.0, float("inf"))
"""Edges of the airspeed bins ``pred_err_p95_g_by_airspeed`` is reported in (m/s, true airspeed)."""


def airspeed_bin_labels() -> tuple[str, ...]:
    """``"[0,2)"``, ..., ``"[11,inf)"``: the keys of ``pred_err_p95_g_by_airspeed``."""
    e = AIRSPEED_BINS_MPS
    return tuple(f"[{e[i]:g},{e[i + 1]:g})" for i in range(len(e) - 1))

METRIC_INFO: dict[str, tuple[str, str]] = {
    "vel_err_rms_mps": ("RMS velocity error", "m/s"),
    "vel_err_max_mps": ("peak velocity error", "m/s"),
    "vel_err_rms_high_wind_mps": (f"RMS velocity error at fan ≥ {HIGH_WIND_THROTTLE_PCT:g} %", "m/s"),
    "overshoot_after_fan_off_mps": (f"peak velocity error in the {OVERSHOOT_WINDOW_S:g} s after the fan stops",
                                    "m/s"),
    "pos_err_rms_m": ("RMS position error", "m"),
    "pos_err_max_m": ("peak position error", "m"),
    "pred_err_rms_g": (f"RMS prediction error (after {PRED_ERR_SKIP_S:g} s)", "g"),
    "pred_err_p95_g": (f"95th-percentile prediction error (after {PRED_ERR_SKIP_S:g} s)", "g"),
    "pred_err_p95_g_by_airspeed": ("95th-percentile prediction error per true-airspeed bin (m/s)", "g"),
    "mixer_saturated_fraction": ("share of time the allocator could not meet the asked lift and moment", "%"),
    "lift_attitude_unmet_fraction": ("share of time even lift, roll and pitch could not all be met (not only yaw)",
                                     "%"),
    "airspeed_max_mps": ("peak airspeed", "m/s"),
    "fan_off_time_s": ("time the fan stops", "s"),
    "wall_time_s": ("wall time of the run", "s"),
}
"""Every metric key -> (label in words, unit as printed): the one map tables and figures use.

Keys ending in ``_fraction`` are stored as fractions in ``metrics.json`` and shown in percent
(:func:`metric_display_value`)."""


def metric_label(key: str, with_unit: bool = True) -> str:
    """``"RMS velocity error [m/s]"`` for ``"vel_err_rms_mps"``; ``KeyError`` for an unknown key."""
    try:
        label, unit = METRIC_INFO[key]
    except KeyError:
        raise KeyError(f"metric {key!r} has no entry in METRIC_INFO; add its label and unit") from None
    return f"{label} [{unit}]" if with_unit else label


def metric_display_value(key: str, value: float) -> float:
    """The value in the unit :data:`METRIC_INFO` prints (fractions as percent)."""
    return 100.0 * value if key.endswith("_fraction") else value


def fan_events(t: np.ndarray, fan_pct: np.ndarray) -> tuple[np.ndarray, float | None]:
    """Mask of high-wind samples (fan >= 60 %) and the time the fan last switched off (or None)."""
    high = fan_pct >= HIGH_WIND_THROTTLE_PCT - 1e-9
    off = None
    on = fan_pct > 0.5
    drops = np.nonzero(on[:-1] & ~on[1:])[0]
    if drops.size:
        off = float(t[drops[-1] + 1])
    return high, off


def run_metrics(result: SimulationResult, fan_pct: np.ndarray) -> dict:
    """Velocity-tracking, prediction-error and saturation metrics of one run.

    Velocity error is the paper's ``v~ = v - v_r`` (eq:wr), from the true state.
    ``pred_err_p95_g_by_airspeed`` maps each bin of :data:`AIRSPEED_BINS_MPS` (true airspeed) to
    the 95th percentile of the prediction-error norm there (None where the run has no sample).

    No Lyapunov metric: the Theorem promises exponential convergence to an error ball whose size
    (``lambda ||theta - theta_0||^2 / (2c)``) depends on a rate ``c`` the paper does not give, and
    inside the ball V need not decrease, so the share of ticks with ``dV < 0`` (about 0.5 for every
    controller under sensor noise) tested nothing. The log keeps ``lyapunov_V``.

    ``fan_pct`` is the fan-array throttle at each log row (from the scenario's wind schedule).
    """
    t = result.time_s
    v_err = np.linalg.norm(result.velocity_error_W, axis=1)
    p_err = np.linalg.norm(result.position_error_W, axis=1)
    high, t_off = fan_events(t, fan_pct)
    out: dict[str, float] = {
        "vel_err_rms_mps": _rms(v_err),
        "vel_err_max_mps": float(v_err.max()),
        "pos_err_rms_m": _rms(p_err),
        "pos_err_max_m": float(p_err.max()),
        "vel_err_rms_high_wind_mps": _rms(v_err[high]) if high.any() else float("nan"),
        "mixer_saturated_fraction": float(result["mixer_saturated"].mean()),
    }
    if "alloc_unmet_lift_attitude" in result:
        out["lift_attitude_unmet_fraction"] = float(result["alloc_unmet_lift_attitude"].mean())
    if t_off is not None:
        window = (t >= t_off) & (t <= t_off + OVERSHOOT_WINDOW_S)
        out["overshoot_after_fan_off_mps"] = float(v_err[window].max())
        out["fan_off_time_s"] = t_off
    if "pred_err_x_mps2" in result:
        e = np.linalg.norm(result.columns_like(("pred_err_x_mps2", "pred_err_y_mps2", "pred_err_z_mps2")),
                           axis=1) / GRAVITY_MPS2
        late = t >= PRED_ERR_SKIP_S
        out["pred_err_rms_g"] = _rms(e[late])
        out["pred_err_p95_g"] = float(np.percentile(e[late], 95)) if late.any() else float("nan")
        out["pred_err_p95_g_by_airspeed"] = pred_err_p95_by_airspeed(e[late], result["airspeed_mps"][late])
    out["airspeed_max_mps"] = float(result["airspeed_mps"].max())
    return out


def pred_err_p95_by_airspeed(pred_err_g: np.ndarray, airspeed_mps: np.ndarray) -> dict:
    """95th percentile of ``pred_err_g`` within each airspeed bin (:func:`airspeed_bin_labels`),
    None for an empty bin."""
    out = {}
    e = AIRSPEED_BINS_MPS
    for i, label in enumerate(airspeed_bin_labels()):
        sel = (airspeed_mps >= e[i]) & (airspeed_mps < e[i + 1])
        out[label] = float(np.percentile(pred_err_g[sel], 95)) if sel.any() else None
    return out


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else float("nan")
