"""The probe linearity figure (the paper's Fig. flow_sensor_linearity)."""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

_STYLE = {"single_k": ("o", "tab:orange", "single k (eq:aoa)"),
          "calibrated": ("x", "tab:blue", "calibrated (spline)")}


def plot_linearity(results: Mapping, path: str | Path, title: str = "") -> Path:
    """Estimated against true angle of attack and sideslip, one marker per model, 1:1 line.

    Top row: the paper's linearity plot; bottom row: the errors (estimated minus true), which
    are too small to see on the top row for a good calibration.

    Parameters
    ----------
    results : mapping of str to CalibrationMetrics
        Model name to its evaluation (:func:`~vtoladapt.probe.calibration.evaluate_calibration`).
    path : str or pathlib.Path
        PNG file to write.
    title : str
        Figure title (e.g. the data file and the points).

    Returns
    -------
    pathlib.Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    fig, axes = plt.subplots(2, 2, figsize=(10.0, 8.0), constrained_layout=True,
                             gridspec_kw={"height_ratios": [2.2, 1.0]})
    for col, key, label in ((0, "alpha", r"angle of attack $\alpha$"),
                            (1, "beta", r"sideslip $\beta$")):
        ax = axes[0, col]
        ax_err = axes[1, col]
        lo, hi = np.inf, -np.inf
        for name, m in results.items():
            true = getattr(m, f"{key}_true_deg")
            est = getattr(m, f"{key}_est_deg")
            marker, color, text = _STYLE.get(name, ("s", None, name))
            rms = getattr(m, f"{key}_rms_deg")
            style = dict(color=color, ms=4, ls="none",
                         mfc="none" if marker == "o" else None)
            ax.plot(true, est, marker, label=f"{text}: RMS {rms:.3f} deg (n={m.n_used})",
                    **style)
            ax_err.plot(true, est - true, marker, label=text, **style)
            finite = np.isfinite(est)
            if np.any(finite):
                lo = min(lo, np.min(true[finite]), np.min(est[finite]))
                hi = max(hi, np.max(true[finite]), np.max(est[finite]))
        if not np.isfinite(lo):
            lo, hi = -1.0, 1.0
        pad = 0.05 * (hi - lo if hi > lo else 1.0)
        ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], "k-", lw=0.8, label="1:1")
        ax.set_xlim(lo - pad, hi + pad)
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_aspect("equal")
        ax.set_xlabel(f"true {label} (deg)")
        ax.set_ylabel(f"estimated {label} (deg)")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left", fontsize=8)
        ax_err.axhline(0.0, color="k", lw=0.8)
        ax_err.set_xlim(lo - pad, hi + pad)
        ax_err.set_xlabel(f"true {label} (deg)")
        ax_err.set_ylabel(f"error in {label} (deg)")
        ax_err.grid(True, alpha=0.3)
        ax_err.legend(loc="best", fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
