"""``fig_replay.png``: airspeed, throttles, measured vs predicted specific force, error, theta-hat."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..frames import GRAVITY_MPS2
from ..outputs import save_figure
from .estimator import ReplayResult


def _shade(ax, t, mask, label=None) -> None:
    """Grey bands where ``mask`` is True (e.g. on the ground)."""
    if not mask.any():
        return
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(int), [0]))))
    for i, (a, b) in enumerate(zip(edges[::2], edges[1::2])):
        ax.axvspan(t[a], t[min(b, len(t) - 1)], color="0.85", lw=0, zorder=0, label=label if i == 0 else None)


def plot_replay(result: ReplayResult, path: Path) -> Path:
    """Seven stacked panels over time; NaN (invalid data) shows as gaps, ground contact as grey bands."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    log = result.log
    t = log.t_s
    fig, axes = plt.subplots(7, 1, figsize=(10, 16), sharex=True)
    fig.subplots_adjust(left=0.09, right=0.98, top=0.97, bottom=0.04, hspace=0.12)
    ax = axes[0]
    _shade(ax, t, log.landed, "on the ground (land detector)")
    ax.plot(t, np.linalg.norm(log.v_i_B_mps, axis=1), lw=1, label="|v_i| used by the model")
    ax.plot(t, log.airspeed_pitot_mps, lw=1, ls="--", label="pitot TAS (valid readings)")
    ax.set_ylabel("airspeed (m/s)")
    ax.legend(loc="upper right", fontsize=8)
    ax = axes[1]
    ax.plot(t, log.throttle_x_pct, lw=1, label="pusher u_x")
    ax.plot(t, log.throttle_z_pct, lw=1, label="lift collective u_z")
    ax.set_ylabel("throttle (%)")
    ax.legend(loc="upper right", fontsize=8)
    pred = result.a_m_f_mps2 + result.e_mps2
    pred0 = result.a_m_f_mps2 + result.e_prior_mps2
    for i, a in enumerate("xyz"):
        ax = axes[2 + i]
        _shade(ax, t, log.landed)
        ax.plot(t, result.a_m_f_mps2[:, i], color="k", lw=1, label="measured [a_m]_f")
        ax.plot(t, pred0[:, i], lw=1, ls="--", label="predicted, theta_0")
        ax.plot(t, pred[:, i], lw=1, label="predicted, theta-hat")
        ax.set_ylabel(f"f_{a} body (m/s²)")
        if i == 0:
            ax.legend(loc="upper right", fontsize=8)
    ax = axes[5]
    _shade(ax, t, log.landed)
    ax.plot(t, np.linalg.norm(result.e_prior_mps2, axis=1) / GRAVITY_MPS2, lw=1, ls="--", label="theta_0")
    ax.plot(t, np.linalg.norm(result.e_mps2, axis=1) / GRAVITY_MPS2, lw=1, label="theta-hat (adapting)")
    ax.set_ylabel("|prediction error| (g)")
    ax.legend(loc="upper right", fontsize=8)
    ax = axes[6]
    half = 0.5 * (result.theta_upper - result.theta_lower)
    rel = (result.theta_hat - result.theta_0) / half
    for k, name in enumerate(result.names):
        ax.plot(t, rel[:, k], lw=1, label=name)
    ax.axhline(1.0, color="0.5", lw=0.5, ls=":")
    ax.axhline(-1.0, color="0.5", lw=0.5, ls=":")
    ax.set_ylabel("(θ̂ − θ₀) / bound half-width (–)")
    ax.legend(loc="upper left", fontsize=7, ncol=4)
    axes[-1].set_xlabel(f"time since log sample {log.t0_us} us (s)")
    axes[0].set_title(f"replay of {Path(log.source).name} with vehicle {result.vehicle.name}", fontsize=10)
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return Path(path)


__all__ = ["plot_replay"]
