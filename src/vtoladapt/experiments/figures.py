"""Figures of the experiments, a single run and a campaign (Matplotlib without pyplot).

Each ``plot_*`` function returns a :class:`matplotlib.figure.Figure` (so tests can read what is
drawn); each ``figure_*`` function draws the same and writes it to a PNG, returning the path.
Controllers keep their registry colour everywhere and get a line style of their own, so two
controllers with the same curve stay distinguishable (the first is drawn wide, the next dashed on
top).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Sequence

import numpy as np

from ..control.registry import CONTROLLERS, composite_ids, controller_ids
from ..frames import GRAVITY_MPS2
from ..sim.run_metrics import metric_label
from ..sim.results import SimulationResult
from ..sim.scenario import Scenario
from .metrics import fan_speed_series, fan_throttle_series
from .report import _save_figure


class _RegistryField(Mapping):
    """``{controller id: its registry entry's field}``, read from the registry at each look-up (a law
    registered after import has its label and colour)."""

    def __init__(self, field: str):
        self.field = field

    def __getitem__(self, key: str):
        try:
            info = CONTROLLERS[key]
        except KeyError:
            raise KeyError(key) from None
        return getattr(info, self.field)

    def __iter__(self):
        return iter(CONTROLLERS)

    def __len__(self) -> int:
        return len(CONTROLLERS)


CONTROLLER_LABELS: Mapping[str, str] = _RegistryField("label")
CONTROLLER_COLORS: Mapping[str, str] = _RegistryField("colour")
PRED_ERR_COLUMNS = ("pred_err_x_mps2", "pred_err_y_mps2", "pred_err_z_mps2")
MEAS_V_I_COLUMNS = ("meas_v_i_x_mps", "meas_v_i_y_mps", "meas_v_i_z_mps")
PLOT_FILTER_HZ = 1.0
"""Prediction errors are low-passed at this cutoff for the figures only (as the paper's are)."""

_LINESTYLES = ("-", (0, (5, 2)), (0, (6, 2, 1, 2)), (0, (2, 1)), (0, (1, 1)), (0, (8, 2, 1, 2, 1, 2)),
               (0, (3, 3)), (0, (4, 1, 1, 1, 1, 1)), (0, (10, 3)), (0, (1, 2, 4, 2)))
FIGURE_DPI = 130


def controller_style(controller_id: str) -> dict:
    """Matplotlib line properties of a controller: registry colour, its own dash pattern, and a
    width that shrinks down the registry so a later controller drawn over an earlier one on the
    same curve leaves the earlier one visible around it."""
    ids = controller_ids()
    i = ids.index(controller_id) if controller_id in ids else len(ids)
    return {"color": CONTROLLER_COLORS.get(controller_id, f"C{i % 10}"),
            "ls": _LINESTYLES[i % len(_LINESTYLES)], "lw": max(0.9, 2.2 - 0.2 * i),
            "label": CONTROLLER_LABELS.get(controller_id, controller_id), "zorder": 2 + i}


def measured_airspeed_mps(result: SimulationResult) -> np.ndarray:
    """Norm of the probe's incident velocity (m/s), NaN where the reading was invalid.

    An invalid reading (dropout, below the probe's minimum airspeed, outside its calibration) is
    not a measurement of zero airspeed: NaN makes Matplotlib leave a gap there.
    """
    v = np.linalg.norm(result.columns_like(MEAS_V_I_COLUMNS), axis=1)
    if "meas_v_i_valid" in result:
        v = np.where(result["meas_v_i_valid"] > 0.5, v, np.nan)
    return v


def _lowpass(x: np.ndarray, dt: float, cutoff_hz: float) -> np.ndarray:
    a = 1.0 - math.exp(-2.0 * math.pi * cutoff_hz * dt)
    y = np.empty_like(x)
    acc = x[0]
    for i in range(len(x)):
        acc = acc + a * (x[i] - acc)
        y[i] = acc
    return y


def _shade_fan(ax, t, fan_pct) -> None:
    k = _stride(len(t))
    on = fan_pct[::k] > 0.5
    if on.any():
        ax.fill_between(t[::k], 0, 1, where=on, transform=ax.get_xaxis_transform(), color="0.92", zorder=0,
                        lw=0)


MAX_PLOT_POINTS = 20_000
"""Most points a line of a figure gets. A one-hour log has 900 000 ticks, which matplotlib turned into
some 700 MB of copies and paths for a figure 1200 pixels wide; a longer series is drawn as the minimum
and maximum of each of MAX_PLOT_POINTS / 2 equal slices of it (:func:`_thin`), so every peak and dip
is still drawn, at a memory that does not grow with the run."""


def _stride(n: int) -> int:
    """The step that keeps at most :data:`MAX_PLOT_POINTS` of ``n`` samples (bands and shading)."""
    return max(1, -(-n // MAX_PLOT_POINTS))


def _thin(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(t, y)`` with at most :data:`MAX_PLOT_POINTS` samples: each slice's minimum and maximum, in
    time order (the envelope a plot of every sample shows)."""
    n = len(t)
    if n <= MAX_PLOT_POINTS:
        return t, y
    size = -(-n // (MAX_PLOT_POINTS // 2))
    rows = -(-n // size)
    y = np.asarray(y, dtype=float)
    padded = np.full(rows * size, np.nan)
    padded[:n] = y
    block = padded.reshape(rows, size)
    base = np.arange(rows) * size
    lo = base + np.argmin(np.where(np.isnan(block), np.inf, block), axis=1)
    hi = base + np.argmax(np.where(np.isnan(block), -np.inf, block), axis=1)
    idx = np.unique(np.concatenate((lo, hi, [0, n - 1])))
    idx = idx[idx < n]
    return t[idx], y[idx]


def _plot(ax, t, y, *args, **kwargs):
    """``ax.plot(t, y, ...)`` of the series thinned by :func:`_thin`."""
    return ax.plot(*_thin(np.asarray(t), np.asarray(y)), *args, **kwargs)


def new_figure(nrows: int, ncols: int, figsize: tuple, **kwargs):
    """A figure and its axes without pyplot: files only, and pyplot's import costs a second."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


# --- convergence -----------------------------------------------------------------------------------
def plot_parameter_convergence(scenario: Scenario, results: list[SimulationResult]):
    """theta-hat of every random-start run over time, 1-3 sigma bands across runs, fan wind."""
    from .metrics import _basis

    t = results[0].time_s
    names = results[0].theta_names
    units = dict(zip(names, _basis(scenario).scaled_units))
    theta = np.stack([r.theta_hat for r in results])
    truth = np.array(results[0].metadata["theta_true_scaled"])  # empty where the basis has no plant truth
    wind = fan_speed_series(scenario, t)
    rows = (len(names) + 1) // 2
    fig, axes = new_figure(rows, 2, figsize=(11, 2.5 * rows), sharex=True, squeeze=False)
    for i, name in enumerate(names):
        ax = axes[i // 2, i % 2]
        mean = theta[:, :, i].mean(axis=0)
        std = theta[:, :, i].std(axis=0, ddof=1)
        for n, alpha in ((3, 0.12), (2, 0.18), (1, 0.28)):
            k = _stride(len(t))
            ax.fill_between(t[::k], (mean - n * std)[::k], (mean + n * std)[::k], color="C0", alpha=alpha, lw=0,
                            label=f"{n}σ across runs" if i == 0 else None)
        for run in theta:
            _plot(ax, t, run[:, i], color="C0", lw=0.4, alpha=0.5)
        _plot(ax, t, mean, color="C0", lw=1.5, label="mean θ̂" if i == 0 else None)
        if truth.size == len(names):
            ax.axhline(truth[i], color="k", ls=":", lw=1, label="plant's linear part" if i == 0 else None)
        ax.set_ylabel(f"{name} [{units[name]}]")
        ax.grid(alpha=0.3)
        ax2 = ax.twinx()
        _plot(ax2, t, wind, color="0.5", lw=1.0, ls="--", label="fan wind" if i == 0 else None)
        ax2.set_ylabel("wind [m/s]", color="0.5")
        ax2.tick_params(axis="y", colors="0.5")
        if i == 0:
            h1, l1 = ax.get_legend_handles_labels()
            h2, l2 = ax2.get_legend_handles_labels()
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.suptitle(f"Convergence of θ̂ over {len(results)} runs from random initial θ̂ ({scenario.name})\n"
                 "adaptation scaling: throttle u ∈ [0, 1], forces per unit mass", y=0.995, fontsize=11)
    fig.legend(h1 + h2, l1 + l2, loc="upper center", bbox_to_anchor=(0.5, 0.955), ncol=6, frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 0.945))
    return fig


def figure_parameter_convergence(scenario: Scenario, results: list[SimulationResult], path: Path) -> Path:
    """:func:`plot_parameter_convergence` written to ``path`` (PNG)."""
    return _save_figure(plot_parameter_convergence(scenario, results), path, FIGURE_DPI)


# --- comparison ------------------------------------------------------------------------------------
def plot_tracking_comparison(scenario: Scenario, results: dict[str, SimulationResult]):
    """Measured airspeed, velocity-error norm of every controller, prediction-error norm of the
    composite ones (the paper's Fig. tracking_comparison)."""
    first = next(iter(results.values()))
    t = first.time_s
    dt = t[1] - t[0]
    fan = fan_throttle_series(scenario, t)
    fig, axes = new_figure(3, 1, figsize=(10, 8.5), sharex=True)
    ref_id = "composite" if "composite" in results else next(iter(results))
    airspeed = measured_airspeed_mps(results[ref_id])
    _plot(axes[0], t, airspeed, color="k", lw=1,
                 label=f"measured airspeed ({CONTROLLER_LABELS.get(ref_id, ref_id)} run; gaps: "
                       "reading invalid)")
    _plot(axes[0], t, fan_speed_series(scenario, t), color="0.5", ls="--", lw=1, label="fan mean wind")
    axes[0].set_ylabel("airspeed [m/s]")
    for cid, res in results.items():
        _plot(axes[1], t, np.linalg.norm(res.velocity_error_W, axis=1), **controller_style(cid))
    axes[1].set_ylabel("‖velocity error‖ [m/s]")
    for cid in composite_ids():
        if cid in results:
            e = np.linalg.norm(results[cid].columns_like(PRED_ERR_COLUMNS), axis=1) / GRAVITY_MPS2
            _plot(axes[2], t, _lowpass(e, dt, PLOT_FILTER_HZ), **controller_style(cid))
    axes[2].axhline(0.05, color="k", ls=":", lw=1, label="0.05 g")
    axes[2].set_ylabel(f"‖prediction error‖ [g]\n(low-passed {PLOT_FILTER_HZ:g} Hz)")
    axes[2].set_xlabel("time [s]")
    for ax in axes:
        _shade_fan(ax, t, fan)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", fontsize=8, ncol=3)
    axes[0].set_title(f"Controller comparison ({scenario.name}); grey: fan on")
    fig.tight_layout()
    return fig


def figure_tracking_comparison(scenario: Scenario, results: dict[str, SimulationResult], path: Path) -> Path:
    """:func:`plot_tracking_comparison` written to ``path`` (PNG)."""
    return _save_figure(plot_tracking_comparison(scenario, results), path, FIGURE_DPI)


def plot_tracking_axes(scenario: Scenario, results: dict[str, SimulationResult]):
    """Velocity error per NED axis and prediction error per body axis, every controller."""
    first = next(iter(results.values()))
    t = first.time_s
    dt = t[1] - t[0]
    fan = fan_throttle_series(scenario, t)
    fig, axes = new_figure(3, 2, figsize=(12, 8), sharex=True)
    for j, axis in enumerate("NED"):
        ax = axes[j, 0]
        for cid, res in results.items():
            _plot(ax, t, res.velocity_error_W[:, j], **controller_style(cid))
        ax.set_ylabel(f"velocity error {axis} [m/s]")
        ax = axes[j, 1]
        for cid in composite_ids():
            if cid in results:
                e = results[cid][PRED_ERR_COLUMNS[j]] / GRAVITY_MPS2
                _plot(ax, t, _lowpass(e, dt, PLOT_FILTER_HZ), **controller_style(cid))
        ax.set_ylabel(f"prediction error body {'xyz'[j]} [g]")
    for ax in axes.ravel():
        _shade_fan(ax, t, fan)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, ncol=2)
    if axes[0, 1].lines:
        axes[0, 1].legend(fontsize=8)
    axes[0, 0].set_title("velocity tracking error (NED, vehicle faces north)")
    axes[0, 1].set_title(f"prediction error (body FRD, low-passed {PLOT_FILTER_HZ:g} Hz)")
    axes[-1, 0].set_xlabel("time [s]")
    axes[-1, 1].set_xlabel("time [s]")
    fig.suptitle(f"{scenario.name}: per-axis errors; grey: fan on", fontsize=11)
    fig.tight_layout()
    return fig


def figure_tracking_axes(scenario: Scenario, results: dict[str, SimulationResult], path: Path) -> Path:
    """:func:`plot_tracking_axes` written to ``path`` (PNG)."""
    return _save_figure(plot_tracking_axes(scenario, results), path, FIGURE_DPI)


# --- single run --------------------------------------------------------------------------------------
def plot_single_run(scenario: Scenario, result: SimulationResult):
    """Airspeed, velocity error, theta-hat (relative to theta-hat(0)) and prediction error of one run."""
    t = result.time_s
    fan = fan_throttle_series(scenario, t)
    fig, axes = new_figure(4, 1, figsize=(10, 10), sharex=True)
    _plot(axes[0], t, result["airspeed_mps"], color="C0", lw=1.4, label="true airspeed")
    if all(c in result for c in MEAS_V_I_COLUMNS):
        _plot(axes[0], t, measured_airspeed_mps(result), color="k", lw=0.7,
                     label="measured airspeed (gaps: reading invalid)")
    _plot(axes[0], t, fan_speed_series(scenario, t), color="0.5", ls="--", lw=1, label="fan mean wind")
    axes[0].set_ylabel("airspeed [m/s]")
    v = result.velocity_error_W
    for j, axis in enumerate("NED"):
        _plot(axes[1], t, v[:, j], lw=0.9, label=axis)
    axes[1].set_ylabel("velocity error [m/s]")
    theta = result.theta_hat
    rel = theta / np.where(theta[0] != 0, theta[0], 1.0)
    for i, name in enumerate(result.theta_names):
        _plot(axes[2], t, rel[:, i], lw=0.9, ls=_LINESTYLES[i // 4 % len(_LINESTYLES)], label=name)
    axes[2].set_ylabel("θ̂ / θ̂(0) [-]")
    if all(c in result for c in PRED_ERR_COLUMNS):
        for j in range(3):
            _plot(axes[3], t, result[PRED_ERR_COLUMNS[j]] / GRAVITY_MPS2, lw=0.7, label="body " + "xyz"[j])
    else:
        axes[3].text(0.5, 0.5, "this controller makes no force prediction", ha="center",
                     va="center", transform=axes[3].transAxes)
    axes[3].set_ylabel("prediction error [g]")
    axes[3].set_xlabel("time [s]")
    for ax in axes:
        _shade_fan(ax, t, fan)
        ax.grid(alpha=0.3)
        if ax.lines:
            ax.legend(fontsize=8, ncol=4, loc="best")
    label = CONTROLLER_LABELS.get(scenario.controller.kind, scenario.controller.kind)
    axes[0].set_title(f"{scenario.name}: controller {label}; grey: fan on")
    fig.tight_layout()
    return fig


def figure_single_run(scenario: Scenario, result: SimulationResult, path: Path) -> Path:
    """:func:`plot_single_run` written to ``path`` (PNG)."""
    return _save_figure(plot_single_run(scenario, result), path, 120)


# --- campaign ------------------------------------------------------------------------------------------
CAMPAIGN_METRICS = ("vel_err_rms_mps", "pos_err_max_m")


def plot_campaign(rows: Sequence[dict], varied: Sequence[str] = (), units: dict | None = None):
    """Histograms of the campaign's main metrics (whole-number run counts) and, for each varied
    scenario key, those metrics against the drawn value (one point per run).

    ``rows``: one dict per run (the drawn values and the run's metrics); ``varied``: the scenario
    keys drawn per run; ``units``: key -> unit for the varied keys' axis labels.
    """
    from matplotlib.ticker import MaxNLocator

    units = units or {}
    nrows = 1 + len(varied)
    fig, axes = new_figure(nrows, len(CAMPAIGN_METRICS), figsize=(10, 3.6 * nrows), squeeze=False)
    for col, key in enumerate(CAMPAIGN_METRICS):
        vals = np.array([r[key] for r in rows], dtype=float)
        ax = axes[0, col]
        ax.hist(vals[np.isfinite(vals)], bins=max(5, min(30, len(rows) // 2)), color="C0", alpha=0.8)
        ax.set_xlabel(metric_label(key))
        ax.set_ylabel("runs [count]")
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(alpha=0.3)
        for r, vkey in enumerate(varied, start=1):
            ax = axes[r, col]
            x = np.array([row[vkey] for row in rows], dtype=float)
            ax.plot(x, vals, "o", ms=3, color="C0", alpha=0.7)
            unit = units.get(vkey)
            ax.set_xlabel(f"{vkey} [{unit}]" if unit else vkey)
            ax.set_ylabel(metric_label(key))
            ax.grid(alpha=0.3)
    fig.suptitle(f"Campaign of {len(rows)} runs"
                 + (f"; varied: {', '.join(varied)}" if varied else "; varied: the seed only"))
    fig.tight_layout()
    return fig


def figure_campaign(rows: Sequence[dict], path: Path, varied: Sequence[str] = (),
                    units: dict | None = None) -> Path:
    """:func:`plot_campaign` written to ``path`` (PNG)."""
    return _save_figure(plot_campaign(rows, varied, units), path, 120)
