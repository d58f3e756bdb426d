"""The paper's experiments: parameter convergence and the five-controller comparison.

``vtoladapt reproduce --out DIR`` runs both shipped scenarios (``paper_convergence``,
``paper_comparison``) and writes the figures, ``metrics.json`` and a report that checks the
paper's claims in simulation. ``vtoladapt run SCENARIO --out DIR`` does the same for one
scenario file, so a user can vary one thing and compare.

metrics.json schema
-------------------
``comparison.controllers.<id>``: ``vel_err_rms_mps``, ``vel_err_max_mps``,
``vel_err_rms_high_wind_mps`` (fan >= 60 %), ``overshoot_after_fan_off_mps`` (peak velocity error
in the 5 s after the fan stops), and for the composite controllers ``pred_err_rms_g`` and
``pred_err_p95_g`` (after the first 2 s), plus further diagnostics.
``convergence.param_std_ratio.<param>``: spread (std) of theta-hat across the runs at the end
divided by at the start. ``claims.<name>``: ``{"holds", "value", "threshold", "statement"}``.
"""
from __future__ import annotations

import base64
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Optional

import numpy as np

from .control.registry import ADAPTIVE_IDS, COMPOSITE_IDS, CONTROLLERS
from .frames import GRAVITY_MPS2
from .metrics import run_metrics
from .results import SimulationResult
from .scenario import SCENARIO_DIR, Scenario, load_scenario
from .vehicle import PARAMETER_NAMES

CONTROLLER_LABELS = {k: c.label for k, c in CONTROLLERS.items()}
CONTROLLER_COLORS = {k: c.colour for k, c in CONTROLLERS.items()}
PRED_ERR_COLUMNS = ("pred_err_x_mps2", "pred_err_y_mps2", "pred_err_z_mps2")
PLOT_FILTER_HZ = 1.0
"""Prediction errors are low-passed at this cutoff for the figures only (as the paper's are)."""


# --- progress ------------------------------------------------------------------------------------
class _Progress:
    """A tqdm bar over simulated seconds of all runs, or nothing when quiet."""

    def __init__(self, total_s: float, show: bool, desc: str):
        self.bar = None
        if show:
            from tqdm import tqdm

            self.bar = tqdm(total=round(total_s, 1), unit="sim s", desc=desc, file=sys.stderr,
                            bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} sim s "
                                       "[{elapsed}<{remaining}]")
        self.done = 0.0

    def callback(self):
        start = self.done

        def cb(sim_s, _total):
            if self.bar is not None:
                self.bar.update(round(start + sim_s - self.bar.n, 3))
        return cb

    def finish_run(self, duration_s: float):
        self.done += duration_s

    def set(self, desc: str):
        if self.bar is not None:
            self.bar.set_description(desc)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _note(msg: str, show: bool) -> None:
    if show:
        print(msg, file=sys.stderr, flush=True)


def _warm_up(scenario: Scenario, show: bool) -> None:
    """Compile (or load from the on-disk cache) the kernels, telling the user."""
    from .simulate import load_kernels

    t0 = time.perf_counter()
    _note("Loading compiled kernels (the first run on a machine compiles them: under a minute)...", show)
    load_kernels(replace(scenario, experiment=replace(scenario.experiment, kind="single")))
    _note(f"  kernels ready in {time.perf_counter() - t0:.1f} s", show)


# --- running ---------------------------------------------------------------------------------------
def fan_throttle_series(scenario: Scenario, t: np.ndarray) -> np.ndarray:
    from .wind import fan_throttle_pct

    params = scenario.wind.to_kernel()
    return np.array([fan_throttle_pct(params, ti) for ti in t])


def fan_speed_series(scenario: Scenario, t: np.ndarray) -> np.ndarray:
    from .wind import fan_mean_wind_speed

    params = scenario.wind.to_kernel()
    return np.array([fan_mean_wind_speed(params, ti) for ti in t])


def run_comparison(scenario: Scenario, progress: Optional[_Progress] = None) -> dict[str, SimulationResult]:
    """The same scenario flown by each controller of ``[experiment] controllers`` (runs in parallel)."""
    ids = scenario.experiment.controllers
    runs = [replace(scenario, controller=replace(scenario.controller, kind=cid)) for cid in ids]
    return dict(zip(ids, _run_all(runs, progress, f"comparison of {len(ids)} controllers")))


def run_convergence(scenario: Scenario, progress: Optional[_Progress] = None) -> list[SimulationResult]:
    """``[experiment] runs`` runs from random initial theta-hat, seeds spawned from the scenario seed."""
    seeds = np.random.SeedSequence(scenario.seed).generate_state(scenario.experiment.runs)
    prior = replace(scenario.controller_prior, initial_theta="random")
    runs = [replace(scenario, seed=int(seed), controller_prior=prior) for seed in seeds]
    return _run_all(runs, progress, f"convergence: {len(runs)} runs")


def _run_all(runs: list[Scenario], progress: Optional[_Progress], desc: str) -> list[SimulationResult]:
    """Every run side by side, one thread per core (bit-identical to running them one by one)."""
    from .simulate import simulate_many

    if progress is not None:
        progress.set(desc)
    results = simulate_many(runs, progress=progress.callback() if progress else None)
    if progress is not None:
        progress.finish_run(sum(sc.duration_s for sc in runs))
    return results


# --- metrics -----------------------------------------------------------------------------------------
def comparison_metrics(scenario: Scenario, results: dict[str, SimulationResult]) -> dict:
    out = {}
    for cid, res in results.items():
        m = run_metrics(res, fan_throttle_series(scenario, res.time_s))
        if cid not in COMPOSITE_IDS:
            m.pop("pred_err_rms_g", None)
            m.pop("pred_err_p95_g", None)
        out[cid] = m
    return {"scenario": scenario.name, "controllers": out}


def convergence_metrics(scenario: Scenario, results: list[SimulationResult]) -> dict:
    """Spread of theta-hat across runs at the end over at the start, per parameter."""
    theta = np.stack([r.theta_hat for r in results])  # runs x T x 8
    std_start = theta[:, 0, :].std(axis=0, ddof=1)
    std_end = theta[:, -1, :].std(axis=0, ddof=1)
    ratio = {name: float(std_end[i] / std_start[i]) if std_start[i] > 0 else float("nan")
             for i, name in enumerate(PARAMETER_NAMES)}
    per_run = [run_metrics(r, fan_throttle_series(scenario, r.time_s)) for r in results]
    force_start, force_end = _predicted_force_spread(scenario, results, theta)
    return {
        # what the data identify: the force each run's theta-hat predicts at the final operating
        # point (collinear parameters may wander; their combination should not)
        "predicted_force_std_start_mps2": force_start,
        "predicted_force_std_end_mps2": force_end,
        "predicted_force_std_ratio": force_end / force_start if force_start > 0 else float("nan"),
        "scenario": scenario.name, "runs": len(results),
        "param_std_ratio": ratio,
        "theta_hat_final_mean_scaled": dict(zip(PARAMETER_NAMES, theta[:, -1, :].mean(axis=0).tolist())),
        "theta_hat_final_std_scaled": dict(zip(PARAMETER_NAMES, std_end.tolist())),
        "theta_true_scaled": dict(zip(PARAMETER_NAMES, results[0].metadata["theta_true_scaled"])),
        "vel_err_rms_mps_per_run": [m["vel_err_rms_mps"] for m in per_run],
        "pred_err_p95_g_per_run": [m.get("pred_err_p95_g", float("nan")) for m in per_run],
    }


def _predicted_force_spread(scenario: Scenario, results: list[SimulationResult], theta: np.ndarray):
    """Norm of the across-run std of ``Phi(v_i, u) theta-hat`` at the runs' mean final operating
    point, with theta-hat at the start and at the end (m/s^2)."""
    from .models import regressor

    vehicle = scenario.load_vehicle()
    last = np.array([r.data[-1] for r in results])
    idx = {n: i for i, n in enumerate(results[0].columns)}
    v_i = last[:, [idx["ctrl_v_i_x_mps"], idx["ctrl_v_i_y_mps"], idx["ctrl_v_i_z_mps"]]].mean(axis=0)
    u_x = 100.0 * last[:, idx["cmd_u_x_frac"]].mean()
    u_z = 100.0 * last[:, idx["cmd_u_z_frac"]].mean()
    Phi = regressor(v_i, u_x, u_z, vehicle)
    f_start = theta[:, 0, :] @ Phi.T
    f_end = theta[:, -1, :] @ Phi.T
    return (float(np.linalg.norm(f_start.std(axis=0, ddof=1))),
            float(np.linalg.norm(f_end.std(axis=0, ddof=1))))


def check_claims(comparison: Optional[dict], convergence: Optional[dict]) -> dict:
    """The paper's claims as measurable statements, each with its value, threshold and verdict."""
    claims = {}
    if comparison is not None:
        c = comparison["controllers"]
        if "pd" in c and "composite" in c:
            v = c["pd"]["vel_err_rms_high_wind_mps"] / c["composite"]["vel_err_rms_high_wind_mps"]
            claims["pd_large_errors_at_high_wind"] = _claim(
                v, 3.0, v >= 3.0, "PD's velocity error at fan >= 60 % is at least 3x C. Adapt's")
        adaptive = [k for k in ADAPTIVE_IDS if k in c]
        if "pid" in c and adaptive and "overshoot_after_fan_off_mps" in c["pid"]:
            worst = max(c[k]["overshoot_after_fan_off_mps"] for k in adaptive)
            v = c["pid"]["overshoot_after_fan_off_mps"] / worst
            claims["pid_overshoots_when_fan_stops"] = _claim(
                v, 1.0, v > 1.0, "PID's peak velocity error after the fan stops exceeds every "
                                 "adaptive controller's (ratio to the worst adaptive)")
        baselines = [k for k in ("pid", "pd") if k in c]
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


# --- figures ------------------------------------------------------------------------------------------
def _lowpass(x: np.ndarray, dt: float, cutoff_hz: float) -> np.ndarray:
    a = 1.0 - math.exp(-2.0 * math.pi * cutoff_hz * dt)
    y = np.empty_like(x)
    acc = x[0]
    for i in range(len(x)):
        acc = acc + a * (x[i] - acc)
        y[i] = acc
    return y


def _shade_fan(ax, t, fan_pct) -> None:
    on = fan_pct > 0.5
    if on.any():
        ax.fill_between(t, 0, 1, where=on, transform=ax.get_xaxis_transform(), color="0.92", zorder=0,
                        lw=0)


def new_figure(nrows: int, ncols: int, figsize: tuple, **kwargs):
    """A figure and its axes without pyplot: files only, and pyplot's import costs a second."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def figure_parameter_convergence(scenario: Scenario, results: list[SimulationResult], path: Path) -> Path:
    t = results[0].time_s
    theta = np.stack([r.theta_hat for r in results])
    truth = np.array(results[0].metadata["theta_true_scaled"])
    wind = fan_speed_series(scenario, t)
    fig, axes = new_figure(4, 2, figsize=(11, 10), sharex=True)
    units = {"CTx": "m/s² (u∈[0,1])", "CTz": "m/s² (u∈[0,1])", "CS": "scaled", "CD0": "-",
             "CD1": "1/rad", "CD2": "1/rad²", "CL0": "-", "CL1": "1/rad"}
    for i, name in enumerate(PARAMETER_NAMES):
        ax = axes[i // 2, i % 2]
        mean = theta[:, :, i].mean(axis=0)
        std = theta[:, :, i].std(axis=0, ddof=1)
        for n, alpha in ((3, 0.12), (2, 0.18), (1, 0.28)):
            ax.fill_between(t, mean - n * std, mean + n * std, color="C0", alpha=alpha, lw=0,
                            label=f"{n}σ across runs" if i == 0 else None)
        for run in theta:
            ax.plot(t, run[:, i], color="C0", lw=0.4, alpha=0.5)
        ax.plot(t, mean, color="C0", lw=1.5, label="mean θ̂" if i == 0 else None)
        ax.axhline(truth[i], color="k", ls=":", lw=1, label="plant's linear part" if i == 0 else None)
        ax.set_ylabel(f"{name} [{units[name]}]")
        ax.grid(alpha=0.3)
        ax2 = ax.twinx()
        ax2.plot(t, wind, color="0.5", lw=1.0, ls="--", label="fan wind" if i == 0 else None)
        ax2.set_ylabel("wind [m/s]", color="0.5")
        ax2.tick_params(axis="y", colors="0.5")
        if i == 0:
            h1, l1 = ax.get_legend_handles_labels()
            h2, l2 = ax2.get_legend_handles_labels()
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.suptitle(f"Convergence of θ̂ over {len(results)} runs from random initial θ̂ "
                 f"({scenario.name}; adaptation scaling)", y=0.995)
    fig.legend(h1 + h2, l1 + l2, loc="upper center", bbox_to_anchor=(0.5, 0.97), ncol=6, frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 0.94))
    fig.savefig(path, dpi=130)
    return path


def figure_tracking_comparison(scenario: Scenario, results: dict[str, SimulationResult], path: Path) -> Path:
    first = next(iter(results.values()))
    t = first.time_s
    dt = t[1] - t[0]
    fan = fan_throttle_series(scenario, t)
    fig, axes = new_figure(3, 1, figsize=(10, 8.5), sharex=True)
    ref_id = "composite" if "composite" in results else next(iter(results))
    airspeed = np.linalg.norm(results[ref_id].columns_like(("meas_v_i_x_mps", "meas_v_i_y_mps",
                                                            "meas_v_i_z_mps")), axis=1)
    axes[0].plot(t, airspeed, color="k", lw=1, label=f"measured airspeed ({CONTROLLER_LABELS[ref_id]} run)")
    axes[0].plot(t, fan_speed_series(scenario, t), color="0.5", ls="--", lw=1, label="fan mean wind")
    axes[0].set_ylabel("airspeed [m/s]")
    for cid, res in results.items():
        axes[1].plot(t, np.linalg.norm(res.velocity_error_W, axis=1), color=CONTROLLER_COLORS[cid], lw=1,
                     label=CONTROLLER_LABELS[cid])
    axes[1].set_ylabel("‖velocity error‖ [m/s]")
    for cid in COMPOSITE_IDS:
        if cid in results:
            e = np.linalg.norm(results[cid].columns_like(PRED_ERR_COLUMNS), axis=1) / GRAVITY_MPS2
            axes[2].plot(t, _lowpass(e, dt, PLOT_FILTER_HZ), color=CONTROLLER_COLORS[cid], lw=1,
                         label=CONTROLLER_LABELS[cid])
    axes[2].axhline(0.05, color="k", ls=":", lw=1, label="0.05 g")
    axes[2].set_ylabel(f"‖prediction error‖ [g]\n(low-passed {PLOT_FILTER_HZ:g} Hz)")
    axes[2].set_xlabel("time [s]")
    for ax in axes:
        _shade_fan(ax, t, fan)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", fontsize=8, ncol=3)
    axes[0].set_title(f"Controller comparison ({scenario.name}); grey: fan on")
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    return path


def figure_tracking_axes(scenario: Scenario, results: dict[str, SimulationResult], path: Path) -> Path:
    first = next(iter(results.values()))
    t = first.time_s
    dt = t[1] - t[0]
    fan = fan_throttle_series(scenario, t)
    fig, axes = new_figure(3, 2, figsize=(12, 8), sharex=True)
    for j, axis in enumerate("NED"):
        ax = axes[j, 0]
        for cid, res in results.items():
            ax.plot(t, res.velocity_error_W[:, j], color=CONTROLLER_COLORS[cid], lw=0.9,
                    label=CONTROLLER_LABELS[cid])
        ax.set_ylabel(f"v error {axis} [m/s]")
        ax = axes[j, 1]
        for cid in COMPOSITE_IDS:
            if cid in results:
                e = results[cid][PRED_ERR_COLUMNS[j]] / GRAVITY_MPS2
                ax.plot(t, _lowpass(e, dt, PLOT_FILTER_HZ), color=CONTROLLER_COLORS[cid], lw=0.9,
                        label=CONTROLLER_LABELS[cid])
        ax.set_ylabel(f"pred. error body {'xyz'[j]} [g]")
    for ax in axes.ravel():
        _shade_fan(ax, t, fan)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, ncol=2)
    axes[0, 1].legend(fontsize=8)
    axes[0, 0].set_title("velocity tracking error (NED, vehicle faces north)")
    axes[0, 1].set_title(f"prediction error (body, low-passed {PLOT_FILTER_HZ:g} Hz)")
    axes[-1, 0].set_xlabel("time [s]")
    axes[-1, 1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    return path


def figure_single_run(scenario: Scenario, result: SimulationResult, path: Path) -> Path:
    """Airspeed, velocity error, theta-hat (relative to theta_0) and prediction error of one run."""
    t = result.time_s
    fig, axes = new_figure(4, 1, figsize=(10, 10), sharex=True)
    axes[0].plot(t, result["airspeed_mps"], label="true airspeed")
    axes[0].plot(t, fan_speed_series(scenario, t), "k--", lw=1, label="fan mean wind")
    axes[0].set_ylabel("airspeed [m/s]")
    v = result.velocity_error_W
    for j, axis in enumerate("NED"):
        axes[1].plot(t, v[:, j], lw=0.9, label=axis)
    axes[1].set_ylabel("velocity error [m/s]")
    theta = result.theta_hat
    rel = theta / np.where(theta[0] != 0, theta[0], 1.0)
    for i, name in enumerate(PARAMETER_NAMES):
        axes[2].plot(t, rel[:, i], lw=0.9, label=name)
    axes[2].set_ylabel("θ̂ / θ̂(0)")
    if all(c in result for c in PRED_ERR_COLUMNS):
        for j in range(3):
            axes[3].plot(t, result[PRED_ERR_COLUMNS[j]] / GRAVITY_MPS2, lw=0.7, label="body " + "xyz"[j])
    axes[3].set_ylabel("prediction error [g]")
    axes[3].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, ncol=4, loc="upper left")
    axes[0].set_title(f"{scenario.name}: controller {scenario.controller.kind}")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return path


# --- reports ----------------------------------------------------------------------------------------
def _fmt(x) -> str:
    if isinstance(x, float):
        return "n/a" if not math.isfinite(x) else f"{x:.4g}"
    return str(x)


def write_report(out: Path, metrics: dict, figures: list[Path], notes: list[str]) -> tuple[Path, Path]:
    """report.md and report.html (figures inline) from the metrics."""
    lines = ["# vtoladapt: reproduction of Shi et al., ICRA 2020, in simulation", ""]
    lines += notes + [""]
    if "comparison" in metrics:
        cols = ["vel_err_rms_mps", "vel_err_max_mps", "vel_err_rms_high_wind_mps",
                "overshoot_after_fan_off_mps", "pred_err_rms_g", "pred_err_p95_g", "mixer_saturated_fraction"]
        lines += ["## Controller comparison", "",
                  "| controller | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
        for cid, m in metrics["comparison"]["controllers"].items():
            lines.append(f"| {CONTROLLER_LABELS.get(cid, cid)} | " + " | ".join(_fmt(m.get(c, float('nan')))
                                                                               for c in cols) + " |")
        lines.append("")
    if "convergence" in metrics:
        conv = metrics["convergence"]
        lines += ["## Parameter convergence", "",
                  f"{conv['runs']} runs from random initial θ̂. The force the runs' θ̂ predict at the final "
                  f"operating point spreads {_fmt(conv['predicted_force_std_start_mps2'])} m/s² across runs "
                  f"at the start and {_fmt(conv['predicted_force_std_end_mps2'])} m/s² at the end "
                  f"(ratio {_fmt(conv['predicted_force_std_ratio'])}).", "",
                  "Spread of each parameter across runs at the end / at the start:",
                  "", "| parameter | std ratio | final mean (scaled) | plant's linear part (scaled) |",
                  "|---|---|---|---|"]
        for name in PARAMETER_NAMES:
            lines.append(f"| {name} | {_fmt(conv['param_std_ratio'][name])} | "
                         f"{_fmt(conv['theta_hat_final_mean_scaled'][name])} | "
                         f"{_fmt(conv['theta_true_scaled'][name])} |")
        lines.append("")
    if metrics.get("claims"):
        lines += ["## The paper's claims, checked in simulation", "",
                  "| claim | value | threshold | holds |", "|---|---|---|---|"]
        for name, c in metrics["claims"].items():
            lines.append(f"| {c['statement']} | {_fmt(c['value'])} | {_fmt(c['threshold'])} | "
                         f"{'yes' if c['holds'] else '**no**'} |")
        lines.append("")
    lines += ["## Figures", ""] + [f"![{p.stem}]({p.name})" for p in figures] + [""]
    md = out / "report.md"
    md.write_text("\n".join(lines))
    html = out / "report.html"
    html.write_text(_markdown_to_html(lines, out))
    return md, html


def _markdown_to_html(lines: list[str], out: Path) -> str:
    body = []
    in_table = False
    for line in lines:
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            if set("".join(cells)) <= set("-"):
                continue
            if not in_table:
                body.append("<table>")
                in_table = True
                body.append("<tr>" + "".join(f"<th>{c}</th>" for c in cells) + "</tr>")
            else:
                body.append("<tr>" + "".join(f"<td>{c.replace('**', '')}</td>" for c in cells) + "</tr>")
            continue
        if in_table:
            body.append("</table>")
            in_table = False
        if line.startswith("!["):
            name = line[line.index("(") + 1:-1]
            data = base64.b64encode((out / name).read_bytes()).decode()
            body.append(f'<p><img alt="{name}" style="max-width:100%" src="data:image/png;base64,{data}"></p>')
        elif line.startswith("## "):
            body.append(f"<h2>{line[3:]}</h2>")
        elif line.startswith("# "):
            body.append(f"<h1>{line[2:]}</h1>")
        elif line:
            body.append(f"<p>{line}</p>")
    if in_table:
        body.append("</table>")
    style = ("body{font-family:sans-serif;max-width:1100px;margin:auto}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:3px 8px;font-size:90%}")
    return f"<!doctype html><html><head><meta charset='utf-8'><style>{style}</style></head><body>" \
           + "\n".join(body) + "</body></html>"


def _scenario_notes(scenario: Scenario, result: SimulationResult) -> list[str]:
    meta = result.metadata
    return [f"Scenario `{scenario.name}` ({scenario.source_path}): {scenario.description}",
            f"Vehicle `{meta['vehicle']}`; controller model from {meta['controller_prior']}; "
            f"airflow probe: {meta['probe_model']}."]


def _write_json(path: Path, data: dict) -> None:
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(data, indent=2, allow_nan=True))
    tmp.replace(path)


def run_experiment(scenario: Scenario, out: Path, show_progress: bool = True, warm: bool = True) -> dict:
    """Run one scenario per its ``[experiment]`` kind; write logs, figures, metrics.json, report."""
    from .simulate import simulate

    out.mkdir(parents=True, exist_ok=True)
    if warm:
        _warm_up(scenario, show_progress)
    kind = scenario.experiment.kind
    n_runs = {"single": 1, "convergence": scenario.experiment.runs,
              "comparison": len(scenario.experiment.controllers)}[kind]
    progress = _Progress(n_runs * scenario.duration_s, show_progress, scenario.name)
    metrics: dict = {}
    figures: list[Path] = []
    try:
        if kind == "single":
            res = simulate(scenario, progress.callback())
            res.to_parquet(out / "log.parquet")
            metrics["run"] = run_metrics(res, fan_throttle_series(scenario, res.time_s))
            figures.append(figure_single_run(scenario, res, out / "fig_run.png"))
            notes = _scenario_notes(scenario, res)
        elif kind == "comparison":
            results = run_comparison(scenario, progress)
            for cid, res in results.items():
                res.to_parquet(out / "runs" / f"{scenario.name}_{cid}.parquet")
            metrics["comparison"] = comparison_metrics(scenario, results)
            figures.append(figure_tracking_comparison(scenario, results, out / "fig_tracking_comparison.png"))
            figures.append(figure_tracking_axes(scenario, results, out / "fig_tracking_axes.png"))
            notes = _scenario_notes(scenario, next(iter(results.values())))
        else:
            results = run_convergence(scenario, progress)
            for i, res in enumerate(results):
                res.to_parquet(out / "runs" / f"{scenario.name}_run{i + 1}.parquet")
            metrics["convergence"] = convergence_metrics(scenario, results)
            figures.append(figure_parameter_convergence(scenario, results,
                                                        out / "fig_parameter_convergence.png"))
            notes = _scenario_notes(scenario, results[0])
    finally:
        progress.close()
    metrics["claims"] = check_claims(metrics.get("comparison"), metrics.get("convergence"))
    _write_json(out / "metrics.json", metrics)
    write_report(out, metrics, figures, notes)
    return metrics


def run_scenario_file(path, out: Path, duration_s: Optional[float] = None, seed: Optional[int] = None,
                      controller: Optional[str] = None, show_progress: bool = True) -> dict:
    """``vtoladapt run``: load, apply command-line overrides (validated), run, write outputs."""
    from .config import ConfigError

    scenario = load_scenario(path)
    if duration_s is not None:
        if not duration_s > 0:
            raise ConfigError(f"--duration = {duration_s}: must be > 0 s")
        scenario = replace(scenario, duration_s=duration_s)
    if seed is not None:
        if seed < 0:
            raise ConfigError(f"--seed = {seed}: must be >= 0")
        scenario = replace(scenario, seed=seed)
    if controller is not None:
        if controller not in CONTROLLER_LABELS:
            raise ConfigError(f"--controller = {controller!r}: unknown; allowed: {', '.join(CONTROLLER_LABELS)}")
        scenario = replace(scenario, controller=replace(scenario.controller, kind=controller))
        if scenario.experiment.kind == "comparison":  # compare just this one
            scenario = replace(scenario, experiment=replace(scenario.experiment, controllers=(controller,)))
    metrics = run_experiment(scenario, Path(out), show_progress)
    _note(f"wrote {out}/metrics.json, report.md, report.html and figures", show_progress)
    return metrics


def reproduce(out: Path, duration_scale: float = 1.0, show_progress: bool = True) -> dict:
    """Both paper experiments, one combined metrics.json and report."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    conv = load_scenario(SCENARIO_DIR / "paper_convergence.toml")
    comp = load_scenario(SCENARIO_DIR / "paper_comparison.toml")
    if duration_scale != 1.0:
        if not 0 < duration_scale <= 10:
            raise ValueError(f"duration_scale = {duration_scale}: must be in (0, 10]")
        conv = _scaled(conv, duration_scale)
        comp = _scaled(comp, duration_scale)
    t0 = time.perf_counter()
    _warm_up(comp, show_progress)
    m_conv = run_experiment(conv, out / "convergence", show_progress, warm=False)
    m_comp = run_experiment(comp, out / "comparison", show_progress, warm=False)
    metrics = {"convergence": m_conv["convergence"], "comparison": m_comp["comparison"]}
    metrics["claims"] = check_claims(metrics["comparison"], metrics["convergence"])
    figures = []
    for sub, name in (("convergence", "fig_parameter_convergence.png"),
                      ("comparison", "fig_tracking_comparison.png"), ("comparison", "fig_tracking_axes.png")):
        (out / name).write_bytes((out / sub / name).read_bytes())
        figures.append(out / name)
    _write_json(out / "metrics.json", metrics)
    from .simulate import controller_prior

    notes = [f"Generated by `vtoladapt reproduce` in {time.perf_counter() - t0:.0f} s "
             f"(duration scale {duration_scale:g}).",
             f"Convergence: `{conv.source_path}`, {conv.experiment.runs} runs of {conv.duration_s:g} s. "
             f"Comparison: `{comp.source_path}`, {comp.duration_s:g} s per controller.",
             f"Controller model: {controller_prior(comp, comp.load_vehicle())[-1]}; airflow probe: {comp.sensors.probe.describe()}.",
             "Per-experiment logs (Parquet), figures and metrics are in `convergence/` and `comparison/`."]
    write_report(out, metrics, figures, notes)
    holds = sum(c["holds"] for c in metrics["claims"].values())
    _note(f"Reproduction done: {holds}/{len(metrics['claims'])} claims hold. "
          f"See {out / 'report.md'} (and report.html).", show_progress)
    for name, c in metrics["claims"].items():
        _note(f"  [{'holds' if c['holds'] else 'FAILS'}] {c['statement']}: {c['value']:.3g} "
              f"(threshold {c['threshold']:g})", show_progress)
    return metrics


def _scaled(scenario: Scenario, scale: float) -> Scenario:
    """The scenario with its duration and wind schedule times scaled (quick looks and tests)."""
    return replace(scenario, duration_s=scenario.duration_s * scale, wind=scenario.wind.time_scaled(scale))
