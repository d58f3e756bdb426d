"""The envelope targets: what each campaign run is judged on, and their fractions over the draws.

A campaign file (:mod:`vtoladapt.campaign.runner`, ``[campaign]``) flies every draw of its conditions
with each of its controllers on the same seed. :func:`envelope_run_metrics` reduces one run's
log to the numbers the targets need; :func:`envelope_summary` judges the targets per draw and
reports each as the fraction of draws where it holds with its 95 % Wilson interval, overall, per
true-airspeed bin and per condition group (a choice such as the vehicle, or a band of a drawn
value such as the fan bearing sector), so the hard part of the envelope is not averaged away.

The targets (issue #11, "Must show"):

``pred_err_every_bin``
    The composite controller's 95th-percentile prediction error is below
    :data:`~vtoladapt.sim.run_metrics.PRED_ERR_BOUND_G` in every true-airspeed bin of ``pred_err_p95_g_by_airspeed``
    (bins with no sample are skipped). A diverged run fails.
``alpha_protect_brief`` / ``alpha_stall_brief``
    The true angle of attack goes past the vehicle's protected angle
    (``[envelope] stall_angle_deg - stall_margin_deg``, what the controller believes is safe) /
    past the plant's own stall angle (``[plant] stall_angle_deg``) only in brief transients:
    every excursion shorter than :data:`ALPHA_EXCURSION_MAX_S` and all of them together less
    than :data:`ALPHA_TIME_FRACTION_MAX` of the time the wing flies. alpha counts only where the
    true airspeed is at least the vehicle's ``hover_blend_airspeed_mps[0]`` (below it the wing
    carries a few percent of the weight and alpha = atan2(v_iz, v_ix) is the direction of a
    breeze, not a wing state); ``|alpha|`` is used (the plant's stall blend is even in alpha), so flow
    from behind (``|alpha|`` near 180 deg) and from the side counts as past stall, as the plant treats it.
``finite_logs``
    No NaN or infinity in any controller's log of the draw.
``beats_pid_pd``
    Every adaptive controller of the registry flown in the draw (``adaptive = True``: composite,
    composite_pconst, tracking_only, l1) has a lower RMS velocity error ``||v - v_r||`` (the
    paper's tracking metric, eq:wr, from the true state, whole run) than both PID and PD. Each
    controller's own fraction is reported too (nominal and INDI included).

Beside the targets, every run's log is scored by the prediction yardstick (:mod:`.yardstick`, issue
#34): the prediction error on probe-valid samples one tick and ``horizon_s`` ahead, the no-model hold
at both, the blind time, and the constant-weights ceiling of the basis fitted on this run's own log
(:mod:`vtoladapt.experiments.ceiling`, true and measured inputs); per controller the summary reports the
fraction of draws where each passes in every airspeed bin (:data:`YARDSTICK_KEYS`).

Per airspeed bin the prediction-error target is judged on that bin, the tracking target on the
RMS velocity error of the samples in that bin (bins with less than :data:`MIN_BIN_TIME_S` of
flight in any of the compared runs are skipped), the alpha target on the samples in that bin.
"""
from __future__ import annotations

import math
from typing import Iterable, Optional, Sequence

import numpy as np

from ..control.registry import adaptive_ids, composite_ids, paper_baseline_ids
from ..sim.run_metrics import AIRSPEED_BINS_MPS, PRED_ERR_BOUND_G, airspeed_bin_labels, run_metrics
from ..stats import fraction_holding, median_iqr

ALPHA_EXCURSION_MAX_S = 0.5
"""Longest allowed excursion of ``|alpha|`` past the protected (or stall) angle (s)."""
ALPHA_TIME_FRACTION_MAX = 0.01
"""Most of the wing-borne time ``|alpha|`` may spend past the protected (or stall) angle (fraction)."""
MIN_BIN_TIME_S = 1.0
"""Least flight time in an airspeed bin for a per-bin RMS velocity error (s)."""
TARGET_FRACTION = 0.95
"""Each target should hold in at least this fraction of the draws."""
YARDSTICK_KEYS = ("pred_valid_pass", "pred_horizon_pass", "hold_pass", "hold_horizon_pass", "ceiling_pass",
                  "ceiling_measured_pass")
"""Per run, 1/0 (NaN: not judged): the yardstick's one-tick and horizon predictions on probe-valid samples,
the hold baseline at both, the ceiling on the run's own log with true and with measured inputs, each
p95 < :data:`~vtoladapt.sim.run_metrics.PRED_ERR_BOUND_G` in every airspeed bin; beside them ``blind_fraction`` and each one's
worst-bin p95 (``<key>_worst_g``, the ``_pass`` replaced)."""
HEADLINE_CONTROLLER = "composite"
"""The controller the prediction-error and alpha targets are judged on (others in the per-controller table)."""

TARGETS: dict[str, str] = {
    "pred_err_every_bin": f"composite p95 prediction error < {PRED_ERR_BOUND_G:g} g in every airspeed bin",
    "alpha_protect_brief": (f"composite: true |α| past the vehicle's protected angle only briefly "
                            f"(each excursion < {ALPHA_EXCURSION_MAX_S:g} s, in total < "
                            f"{100 * ALPHA_TIME_FRACTION_MAX:g} % of the wing-borne time)"),
    "alpha_stall_brief": (f"composite: true |α| past the plant's stall angle only briefly "
                          f"(each excursion < {ALPHA_EXCURSION_MAX_S:g} s, in total < "
                          f"{100 * ALPHA_TIME_FRACTION_MAX:g} % of the wing-borne time)"),
    "finite_logs": "no non-finite value in any controller's log",
    "beats_pid_pd": "every adaptive controller has a lower RMS ‖ṽ‖ than PID and PD",
}
"""Target name -> statement (as the README and figure print it)."""


def _bin_key(metric: str, label: str) -> str:
    return f"{metric}{label}"


# --- one run -------------------------------------------------------------------------------------
def schedule_throttle_pct(scenario, t_s: np.ndarray) -> np.ndarray:
    """The fan schedule's throttle (%) at times ``t_s``, interpolated at once over its breakpoints
    (:func:`vtoladapt.experiments.metrics.fan_throttle_series` evaluates the compiled schedule
    sample by sample, which costs a third of a short run; the two differ only at the instant of
    a step)."""
    pts = scenario.wind.fan_array.linear_breakpoints()
    if not pts:
        return np.zeros_like(t_s, dtype=float)
    bp = np.array(pts, dtype=float)
    return np.interp(t_s, bp[:, 0], bp[:, 1])


def alpha_excursions(alpha_abs_rad: np.ndarray, counted: np.ndarray, threshold_rad: float,
                     dt_s: float) -> tuple[float, float]:
    """``(time fraction, longest excursion in s)`` of ``|alpha| > threshold`` among the
    ``counted`` samples (an excursion is a run of consecutive counted samples past the
    threshold; a sample not counted ends it). No counted sample: ``(0, 0)``."""
    n_counted = int(counted.sum())
    if n_counted == 0:
        return 0.0, 0.0
    past = counted & (alpha_abs_rad > threshold_rad)
    if not past.any():
        return 0.0, 0.0
    edges = np.diff(np.concatenate(([0], past.astype(np.int8), [0])))
    starts = np.nonzero(edges == 1)[0]
    ends = np.nonzero(edges == -1)[0]
    return float(past.sum() / n_counted), float((ends - starts).max() * dt_s)


def envelope_run_metrics(result, scenario) -> dict:
    """The numbers one run is judged on (every key always present; NaN where not applicable).

    ``result`` is a :class:`~vtoladapt.sim.results.SimulationResult` of ``scenario``. Keys: the run
    metrics (``vel_err_rms_mps``, ``pred_err_p95_g``, ...), per airspeed bin ``B``
    ``pred_err_p95_g[B]`` (composite controllers), ``vel_err_rms_mps[B]`` and
    ``alpha_over_protect_fraction[B]`` / ``alpha_over_protect_longest_s[B]``; the alpha
    excursions past the protected and the plant's stall angle; ``finite``, ``nonfinite_values``,
    ``diverged``, ``flown_s``.
    """
    vehicle = scenario.load_vehicle()
    labels = airspeed_bin_labels()
    nan = float("nan")
    data = result.data
    nonfinite = int(data.size - np.count_nonzero(np.isfinite(data)))
    row: dict = {
        "alpha_protect_deg": vehicle.envelope.stall_angle_deg - vehicle.envelope.stall_margin_deg,
        "alpha_stall_true_deg": scenario.plant.resolved(vehicle, scenario.seed).true_stall_angle_deg(vehicle),
        "wing_airspeed_min_mps": vehicle.envelope.hover_blend_airspeed_mps[0],
        "finite": float(nonfinite == 0), "nonfinite_values": float(nonfinite),
        "diverged": float(result.diverged),
        "flown_s": float(len(result) * scenario.dt_control_s),
        "wall_time_s": float(result.metadata["wall_time_s"]),
    }
    scalar_keys = ("vel_err_rms_mps", "vel_err_max_mps", "pos_err_rms_m", "pred_err_p95_g",
                   "mixer_saturated_fraction", "lift_attitude_unmet_fraction", "airspeed_max_mps")
    for k in scalar_keys:
        row[k] = nan
    for lab in labels:
        for m in ("pred_err_p95_g", "vel_err_rms_mps", "alpha_over_protect_fraction",
                  "alpha_over_protect_longest_s"):
            row[_bin_key(m, lab)] = nan
    for k in ("alpha_abs_max_deg", "alpha_over_protect_fraction", "alpha_over_protect_longest_s",
              "alpha_over_stall_fraction", "alpha_over_stall_longest_s"):
        row[k] = nan
    if len(result) < 2:
        return row
    composite = scenario.controller.kind in composite_ids()
    # a log with NaN in it still gets the metrics of its finite part (nan-aware below)
    with np.errstate(invalid="ignore"):
        metrics = run_metrics(result, schedule_throttle_pct(scenario, result.time_s))
    for k in scalar_keys:
        if k in metrics and (composite or not k.startswith("pred_err")):
            row[k] = float(metrics[k])
    if composite:
        for lab, v in metrics.get("pred_err_p95_g_by_airspeed", {}).items():
            row[_bin_key("pred_err_p95_g", lab)] = nan if v is None else float(v)

    row.update(yardstick_columns(result, scenario, vehicle))

    dt = scenario.dt_control_s
    airspeed = result["airspeed_mps"]
    alpha_abs = np.abs(result["alpha_rad"])
    winged = np.isfinite(airspeed) & (airspeed >= row["wing_airspeed_min_mps"]) & np.isfinite(alpha_abs)
    protect = math.radians(row["alpha_protect_deg"])
    stall = math.radians(row["alpha_stall_true_deg"])
    row["alpha_abs_max_deg"] = float(np.degrees(alpha_abs[winged].max())) if winged.any() else 0.0
    row["alpha_over_protect_fraction"], row["alpha_over_protect_longest_s"] = \
        alpha_excursions(alpha_abs, winged, protect, dt)
    row["alpha_over_stall_fraction"], row["alpha_over_stall_longest_s"] = \
        alpha_excursions(alpha_abs, winged, stall, dt)

    v_err = np.linalg.norm(result.velocity_error_W, axis=1)
    edges = AIRSPEED_BINS_MPS
    for i, lab in enumerate(labels):
        sel = (airspeed >= edges[i]) & (airspeed < edges[i + 1])
        if sel.sum() * dt >= MIN_BIN_TIME_S:
            row[_bin_key("vel_err_rms_mps", lab)] = float(np.sqrt(np.nanmean(np.square(v_err[sel]))))
        in_bin = winged & sel
        if in_bin.any():
            f, longest = alpha_excursions(alpha_abs, in_bin, protect, dt)
            row[_bin_key("alpha_over_protect_fraction", lab)] = f
            row[_bin_key("alpha_over_protect_longest_s", lab)] = longest
    return row


def _worst_key(key: str) -> str:
    return key[:-len("_pass")] + "_worst_g"


def yardstick_columns(result, scenario, vehicle) -> dict:
    """The run's :data:`YARDSTICK_KEYS`, their worst-bin p95 and ``blind_fraction`` (NaN where not judged)."""
    from ..bases import describe_basis
    from .ceiling import ceiling_fit, measured_ceiling_fit
    from .yardstick import prediction_yardstick, worst_bin

    nan = float("nan")
    out = {"blind_fraction": nan, **{k: nan for k in YARDSTICK_KEYS}, **{_worst_key(k): nan for k in YARDSTICK_KEYS}}
    if not all(c in result for c in ("probe_valid_used", "pred_err_x_mps2", "a_m_x_mps2")):
        return out
    spec = describe_basis(vehicle, scenario.controller.basis)
    cutoff = scenario.controller.lowpass_cutoff_hz
    with np.errstate(invalid="ignore"):
        y = prediction_yardstick(result, vehicle, spec, cutoff)
        ceilings = {"ceiling_pass": ceiling_fit(result, vehicle, spec),
                    "ceiling_measured_pass": measured_ceiling_fit(result, vehicle, spec, cutoff)}
    out["blind_fraction"] = nan if y["blind_fraction"] is None else y["blind_fraction"]
    for key, name in (("pred_valid_pass", "one_tick"), ("pred_horizon_pass", "horizon"),
                      ("hold_pass", "hold_one_tick"), ("hold_horizon_pass", "hold_horizon")):
        judged = y.get(name)
        if judged and judged["pass"] is not None:
            out[key] = float(judged["pass"])
            w = worst_bin(judged)
            out[_worst_key(key)] = nan if w is None else float(w)
    for key, c in ceilings.items():
        vals = [v for v in c["p95_g"].values() if v is not None]
        if vals:
            out[key] = float(c["pass"])
            out[_worst_key(key)] = float(max(vals))
    return out


# --- judging the targets over draws --------------------------------------------------------------
def _finite(x) -> bool:
    return x is not None and isinstance(x, (int, float)) and math.isfinite(x)


def _brief(fraction, longest_s) -> Optional[bool]:
    if not (_finite(fraction) and _finite(longest_s)):
        return None
    return bool(fraction < ALPHA_TIME_FRACTION_MAX and longest_s < ALPHA_EXCURSION_MAX_S)


def _pred_every_bin(run: dict) -> Optional[bool]:
    if run["diverged"] > 0:
        return False
    values = [run[_bin_key("pred_err_p95_g", lab)] for lab in airspeed_bin_labels()]
    values = [v for v in values if _finite(v)]
    return all(v < PRED_ERR_BOUND_G for v in values) if values else None


def _alpha_brief(run: dict, which: str, bin_label: str = "") -> Optional[bool]:
    if run["diverged"] > 0 and not bin_label:
        return False
    return _brief(run[f"alpha_over_{which}_fraction{bin_label}"],
                  run[f"alpha_over_{which}_longest_s{bin_label}"])


def _beats(runs: dict, cid: str, metric: str = "vel_err_rms_mps") -> Optional[bool]:
    """``cid`` has a lower ``metric`` than every baseline (None: a value missing)."""
    if cid not in runs or any(b not in runs for b in paper_baseline_ids()):
        return None
    mine = runs[cid][metric]
    if metric != "vel_err_rms_mps":  # within an airspeed bin: judged where all have a value
        others = [runs[b][metric] for b in paper_baseline_ids()]
        if not (_finite(mine) and all(_finite(o) for o in others)):
            return None
        return bool(all(mine < o for o in others))
    if runs[cid]["diverged"] > 0 or not _finite(mine):
        return False
    # a baseline that diverged (its RMS covers only the time before) or went non-finite is beaten
    return bool(all(runs[b]["diverged"] > 0 or not _finite(runs[b][metric]) or mine < runs[b][metric]
                    for b in paper_baseline_ids()))


def judge_draw(runs: dict[str, dict]) -> dict:
    """Every target of one draw: ``runs`` maps controller id -> its row. Values are True, False
    or None (not judged: a controller the target needs was not flown, or no sample).

    Keys: the :data:`TARGETS`, ``<target>@<bin>`` per airspeed bin, and per controller
    ``alpha_protect_brief:<id>``, ``alpha_stall_brief:<id>``, ``finite_logs:<id>``,
    ``beats_pid_pd:<id>`` (not for the baselines themselves).
    """
    out: dict = {}
    head = runs.get(HEADLINE_CONTROLLER)
    labels = airspeed_bin_labels()
    out["pred_err_every_bin"] = _pred_every_bin(head) if head else None
    out["alpha_protect_brief"] = _alpha_brief(head, "protect") if head else None
    out["alpha_stall_brief"] = _alpha_brief(head, "stall") if head else None
    out["finite_logs"] = all(r["finite"] > 0 for r in runs.values()) if runs else None
    adaptive = [c for c in adaptive_ids() if c in runs]
    per = {c: _beats(runs, c) for c in adaptive}
    out["beats_pid_pd"] = (all(per.values()) if adaptive and None not in per.values() else None)
    for lab in labels:
        if head:
            v = head[_bin_key("pred_err_p95_g", lab)]
            out[f"pred_err_every_bin@{lab}"] = bool(v < PRED_ERR_BOUND_G) if _finite(v) else None
            out[f"alpha_protect_brief@{lab}"] = _alpha_brief(head, "protect", lab)
        per_bin = [_beats(runs, c, _bin_key("vel_err_rms_mps", lab)) for c in adaptive]
        out[f"beats_pid_pd@{lab}"] = all(per_bin) if per_bin and None not in per_bin else None
    for cid, run in runs.items():
        out[f"alpha_protect_brief:{cid}"] = _alpha_brief(run, "protect")
        out[f"alpha_stall_brief:{cid}"] = _alpha_brief(run, "stall")
        out[f"finite_logs:{cid}"] = bool(run["finite"] > 0)
        if cid not in paper_baseline_ids():
            out[f"beats_pid_pd:{cid}"] = _beats(runs, cid)
    return out


def _rows(columns: dict[str, Sequence]) -> list[dict]:
    n = len(columns["run"])
    return [{k: v[i] for k, v in columns.items()} for i in range(n)]


def _group_value(v) -> str:
    return str(v)


def envelope_summary(columns: dict[str, Sequence], campaign: Optional[dict] = None) -> dict:
    """The campaign's summary from its table (``campaign.parquet`` as ``{column: values}``: one
    row per draw and controller, with ``run``, ``controller``, ``group.<name>`` columns and the
    columns of :func:`envelope_run_metrics`).

    Returns ``{campaign, thresholds, targets, by_airspeed, groups, controllers, diverged}``:
    every fraction as ``{fraction, ci95, n, successes}`` over the draws that judged it.
    """
    rows = _rows(columns)
    draws: dict[int, dict[str, dict]] = {}
    for r in rows:
        draws.setdefault(int(r["run"]), {})[str(r["controller"])] = r
    order = sorted(draws)
    judged = {d: judge_draw(draws[d]) for d in order}
    group_cols = [k for k in columns if k.startswith("group.")]
    groups_of = {d: {g[len("group."):]: _group_value(next(iter(draws[d].values()))[g]) for g in group_cols}
                 for d in order}
    controllers = list(dict.fromkeys(str(c) for c in columns["controller"]))

    def frac(name: str, subset: Iterable[int] = order) -> dict:
        return fraction_holding(judged[d].get(name) for d in subset).as_dict()

    targets = {name: {"statement": text, **frac(name)} for name, text in TARGETS.items()}
    labels = airspeed_bin_labels()
    by_airspeed = {lab: {name: frac(f"{name}@{lab}")
                         for name in ("pred_err_every_bin", "alpha_protect_brief", "beats_pid_pd")}
                   for lab in labels}
    groups: dict = {}
    for g in (c[len("group."):] for c in group_cols):
        values = list(dict.fromkeys(groups_of[d][g] for d in order))
        groups[g] = {v: {name: frac(name, [d for d in order if groups_of[d][g] == v]) for name in TARGETS}
                     for v in _ordered_groups(values)}
    per_controller: dict = {}
    for cid in controllers:
        own = [draws[d][cid] for d in order if cid in draws[d]]
        entry = {
            "alpha_protect_brief": frac(f"alpha_protect_brief:{cid}"),
            "alpha_stall_brief": frac(f"alpha_stall_brief:{cid}"),
            "finite_logs": frac(f"finite_logs:{cid}"),
            "diverged_runs": int(sum(r["diverged"] > 0 for r in own)),
            "vel_err_rms_mps": median_iqr(r["vel_err_rms_mps"] for r in own).as_dict(),
            "alpha_abs_max_deg": median_iqr(r["alpha_abs_max_deg"] for r in own).as_dict(),
            "mixer_saturated_fraction": median_iqr(r["mixer_saturated_fraction"] for r in own).as_dict(),
        }
        if cid not in paper_baseline_ids():
            entry["beats_pid_pd"] = frac(f"beats_pid_pd:{cid}")
        # the yardstick (issue #34), where the table has its columns (older campaigns have not)
        if own and "pred_valid_pass" in own[0]:
            entry["blind_fraction"] = median_iqr(r["blind_fraction"] for r in own).as_dict()
            for key in YARDSTICK_KEYS:
                entry[key] = fraction_holding(bool(r[key]) if _finite(r[key]) else None for r in own).as_dict()
                entry[_worst_key(key)] = median_iqr(r[_worst_key(key)] for r in own).as_dict()
        if cid in composite_ids():
            entry["pred_err_p95_g_worst_bin"] = median_iqr(
                max((r[_bin_key("pred_err_p95_g", lab)] for lab in labels
                     if _finite(r[_bin_key("pred_err_p95_g", lab)])), default=None) for r in own).as_dict()
        per_controller[cid] = entry
    wall = [r["wall_time_s"] for r in rows if _finite(r.get("wall_time_s"))]
    return {
        "campaign": dict(campaign or {}, draws=len(order), controllers=controllers,
                         simulated_s=float(sum(r["flown_s"] for r in rows)),
                         run_wall_time_s=float(sum(wall))),
        "thresholds": {"pred_err_bound_g": PRED_ERR_BOUND_G, "alpha_excursion_max_s": ALPHA_EXCURSION_MAX_S,
                       "alpha_time_fraction_max": ALPHA_TIME_FRACTION_MAX,
                       "min_bin_time_s": MIN_BIN_TIME_S, "target_fraction": TARGET_FRACTION,
                       "airspeed_bins_mps": list(AIRSPEED_BINS_MPS[:-1]) + ["inf"],
                       "adaptive": [c for c in adaptive_ids() if c in controllers],
                       "baselines": list(paper_baseline_ids())},
        "targets": targets,
        "by_airspeed": by_airspeed,
        "groups": groups,
        "controllers": per_controller,
    }


def _ordered_groups(values: list[str]) -> list[str]:
    """Band labels in numeric order (``[12,14) deg`` before ``[14,16) deg``), names as they came."""
    def key(v: str):
        try:
            return (0, float(v.lstrip("[(").split(",")[0]), v)
        except ValueError:
            return (1, 0.0, v)
    return sorted(values, key=key) if all(v.startswith("[") for v in values) else values


# --- figure ----------------------------------------------------------------------------------
FIGURE_TARGETS = ("pred_err_every_bin", "alpha_protect_brief", "alpha_stall_brief", "finite_logs",
                  "beats_pid_pd")


def plot_envelope(summary: dict):
    """One panel per target: the fraction of draws where it holds [%] with its 95 % Wilson
    interval, overall, per airspeed bin (where judged) and per condition group; the 95 % target
    as a dashed line."""
    from .figures import new_figure

    labels: list[str] = ["all draws"]
    entries: dict[str, list] = {t: [summary["targets"][t]] for t in FIGURE_TARGETS}
    for lab, per in summary["by_airspeed"].items():
        labels.append(f"airspeed {lab} m/s")
        for t in FIGURE_TARGETS:
            entries[t].append(per.get(t))
    for g, values in summary["groups"].items():
        for v, per in values.items():
            labels.append(f"{g}: {v}")
            for t in FIGURE_TARGETS:
                entries[t].append(per.get(t))
    fig, axes = new_figure(len(FIGURE_TARGETS), 1, figsize=(11, 2.3 * len(FIGURE_TARGETS) + 2.5),
                           sharex=True)
    x = np.arange(len(labels))
    for ax, t in zip(axes, FIGURE_TARGETS):
        for xi, e in zip(x, entries[t]):
            if not e or e.get("fraction") is None:
                continue
            lo, hi = e["ci95"]
            f = e["fraction"]
            ok = lo >= TARGET_FRACTION
            ax.errorbar([xi], [100 * f], yerr=[[100 * (f - lo)], [100 * (hi - f)]], fmt="o",
                        color="C2" if ok else ("C1" if hi >= TARGET_FRACTION else "C3"), capsize=3, ms=4)
        ax.axhline(100 * TARGET_FRACTION, color="0.4", ls="--", lw=0.8)
        ax.set_ylim(-5, 105)
        ax.set_ylabel("draws holding [%]")
        ax.set_title(TARGETS[t], fontsize=9, loc="left")
        ax.grid(alpha=0.3)
    axes[-1].set_xticks(x)
    axes[-1].set_xticklabels(labels, rotation=60, ha="right", fontsize=8)
    n = summary["campaign"]["draws"]
    fig.suptitle(f"Envelope campaign: fraction of {n} draws where each target holds, 95 % Wilson "
                 f"intervals (green: interval above the {100 * TARGET_FRACTION:g} % target; "
                 f"red: below it)", fontsize=10)
    fig.tight_layout()
    return fig


def figure_envelope(summary: dict, path) -> None:
    """:func:`plot_envelope` written to ``path`` (PNG)."""
    from ..outputs import save_figure

    save_figure(plot_envelope(summary), path, dpi=110)


def resummarize(out_dir) -> dict:
    """Judge a finished campaign's ``campaign.parquet`` again (after a change of the targets'
    definitions): rewrite ``summary.json`` (keeping its ``campaign`` entry) and
    ``fig_campaign.png`` in ``out_dir``, with no run flown again."""
    import json
    from pathlib import Path

    import pyarrow.parquet as pq

    from ..outputs import write_json

    out = Path(out_dir)
    old = json.loads((out / "summary.json").read_text()).get("campaign", {})
    keep = {k: v for k, v in old.items() if k not in ("draws", "controllers", "simulated_s", "run_wall_time_s")}
    summary = envelope_summary(pq.read_table(out / "campaign.parquet").to_pydict(), keep)
    write_json(out / "summary.json", summary)
    figure_envelope(summary, out / "fig_campaign.png")
    return summary


if __name__ == "__main__":
    import sys

    if len(sys.argv) != 2:
        sys.exit("usage: python -m vtoladapt.experiments.envelope CAMPAIGN_DIR  (re-judges campaign.parquet)")
    resummarize(sys.argv[1])
