"""Figures of the fitting feature (matplotlib, Agg: no display needed).

Every function takes a result and a path, writes one PNG and returns the path.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from .. import forces

LABELS = {"CTx": r"$C_{Tx}$", "CTz": r"$C_{Tz}$", "CS": r"$C_S$", "CD0": r"$C_{D0}$",
          "CD1": r"$C_{D1}$", "CD2": r"$C_{D2}$", "CL0": r"$C_{L0}$", "CL1": r"$C_{L1}$",
          "k1": r"$k_1$", "k2": r"$k_2$", "sigma_abs_N": r"$\sigma_{abs}$ (N)",
          "sigma_rel": r"$\sigma_{rel}$", "log10_sigma_abs_N": r"$\log_{10}\sigma_{abs}$/N"}


CORNER_TICK_PT = 8.0
"""Tick-label size of the corner plot (pt): readable when the PNG is shown at its own size."""


def _save(fig: Figure, path) -> Path:
    """Write the PNG; its title (the figure's suptitle) also goes into the file's Title text chunk,
    so what the figure states (e.g. the R-hat) can be read back from the file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    title = fig._suptitle.get_text() if fig._suptitle is not None else ""
    fig.savefig(path, dpi=fig.dpi, metadata={"Title": title} if title else None)
    return path


def plot_corner(fit, path, truth: dict | None = None, max_points: int = 2000) -> Path:
    """:func:`corner_figure` written to ``path`` (PNG)."""
    return _save(corner_figure(fit, truth, max_points), path)


def corner_figure(fit, truth: dict | None = None, max_points: int = 2000) -> Figure:
    """Pairwise posterior of the fitted quantities (the basis's coefficients, the paper's ten Table I
    quantities first, then k1, k2): histograms on the diagonal, draws below.

    ``truth`` (name -> value), if given, is drawn as red lines (virtual-tunnel data).
    """
    names = [n for n in fit.names if n not in ("sigma_abs_N", "sigma_rel")]   # the coefficients, k1, k2
    idx = [fit.names.index(n) for n in names]
    flat = fit.draws.reshape(-1, fit.draws.shape[2])[:, idx]
    rng = np.random.default_rng(0)      # only to pick which draws to plot
    pick = flat if flat.shape[0] <= max_points else flat[rng.choice(flat.shape[0], max_points, replace=False)]
    k = len(names)
    fig = Figure(figsize=(1.35 * k, 1.35 * k), dpi=110)
    axes = fig.subplots(k, k)
    for i in range(k):
        for j in range(k):
            ax = axes[i, j]
            if j > i:
                ax.set_visible(False)
                continue
            if i == j:
                ax.hist(flat[:, i], bins=40, color="C0", histtype="stepfilled", alpha=0.6)
                if truth and names[i] in truth:
                    ax.axvline(truth[names[i]], color="C3", lw=1)
            else:
                ax.plot(pick[:, j], pick[:, i], ".", ms=1, color="C0", alpha=0.3)
                if truth and names[i] in truth and names[j] in truth:
                    ax.axvline(truth[names[j]], color="C3", lw=0.8)
                    ax.axhline(truth[names[i]], color="C3", lw=0.8)
            ax.xaxis.set_major_locator(MaxNLocator(3))
            ax.yaxis.set_major_locator(MaxNLocator(3))
            ax.tick_params(labelsize=CORNER_TICK_PT)
            for axis in (ax.xaxis, ax.yaxis):
                axis.get_offset_text().set_fontsize(CORNER_TICK_PT)
            try:
                ax.ticklabel_format(style="sci", scilimits=(-2, 3))
            except AttributeError:
                pass
            if i == j:
                ax.set_yticks([])
            if i == k - 1:
                ax.set_xlabel(LABELS[names[j]], fontsize=11)
                ax.tick_params(axis="x", labelrotation=45)
            else:
                ax.set_xticklabels([])
            if j == 0 and i > 0:
                ax.set_ylabel(LABELS[names[i]], fontsize=11)
            elif j > 0:
                ax.set_yticklabels([])
    title = ("Posterior of the force model, Table I units (throttle in %, forces per unit mass; "
             "units of each quantity in table1.md)")
    if truth:
        title += "; red: true values"
    fig.suptitle(title, fontsize=13)
    fig.subplots_adjust(left=0.07, right=0.99, bottom=0.07, top=0.96, wspace=0.12, hspace=0.12)
    return fig


def plot_trace(fit, path, diagnostics: dict | None = None) -> Path:
    """:func:`trace_figure` written to ``path`` (PNG)."""
    return _save(trace_figure(fit, diagnostics), path)


def trace_figure(fit, diagnostics: dict | None = None) -> Figure:
    """Chains of the sampled parameters and of the log posterior, every walker (after burn-in).

    The R-hat values shown are the ones ``posterior.json``, ``table1.md`` and the CLI report
    (``diagnostics["rhat_split"]``: split R-hat over the posterior draws, see
    :func:`vtoladapt.fitting.report.largest_rhat`); computed from ``fit`` when not given.
    """
    from .rhat import SAMPLED_TO_QUANTITY, largest_rhat, rhat_by_quantity

    rhat = rhat_by_quantity(fit) if diagnostics is None else diagnostics["rhat_split"]
    m = fit.marginal
    d = m.chain.shape[2]
    fig = Figure(figsize=(9, 1.7 * (d + 1)), dpi=90)
    axes = np.atleast_1d(fig.subplots(d + 1, 1, sharex=True))
    steps = np.arange(m.chain.shape[0])
    for i, name in enumerate(m.problem.param_names):
        axes[i].plot(steps, m.chain[:, :, i], lw=0.4, alpha=0.5)
        label = LABELS.get(name, name)
        axes[i].set_ylabel(label + (" [rad]" if name == "k2" else ""), fontsize=9)
        q = SAMPLED_TO_QUANTITY.get(name, name)
        r = f"split R-hat of {q} {rhat[q]:.4f}" if q in rhat else "split R-hat n/a"
        axes[i].set_title(f"{name}: {r}, tau {m.tau_steps[i]:.1f} steps", fontsize=8, loc="right")
    axes[d].plot(steps, m.log_prob, lw=0.4, alpha=0.5)
    axes[d].set_ylabel("log posterior", fontsize=9)
    axes[d].set_xlabel(f"step after {m.n_burn} burn-in steps ({m.chain.shape[1]} walkers)")
    q, r = largest_rhat(rhat)
    fig.suptitle(f"MCMC traces (emcee) of the sampled parameters; largest split R-hat {r:.4f} ({q})",
                 fontsize=10)
    fig.tight_layout()
    return fig


def side_force_points(fit) -> dict:
    """Measured non-dimensional rotor side force of every side-force row (Table I units).

    The part of each reading the posterior-mean model attributes to everything but C_S is
    subtracted; the rest, projected on the in-plane flow direction and divided by
    ``u_z^k1 V^(2-k1) rho/rho_ref`` (u_z in %), is ``F_S / (m u^k1 V^(2-k1))``, the per-unit-mass
    analogue of the paper's ``F_S / (rho n^k1 V^(2-k1) d^(2+k1))``.
    """
    td = fit.table1_data
    s = fit.summary()
    k1, k2 = s["k1"]["mean"], s["k2"]["mean"]
    th = fit.theta_table_mean.copy()
    th_no_cs = th.copy()
    th_no_cs[forces.I_CS] = 0.0
    rows = td.side_rows
    Phi = td.regressor(k1, k2)[rows]
    resid = td.y_B[rows] - Phi @ (th_no_cs * fit.scale(k1))
    v = td.v_i_B[rows]
    h = np.hypot(v[:, 0], v[:, 1])
    cb, sb = v[:, 0] / h, v[:, 1] / h
    alpha_disk = np.arctan2(v[:, 2], h)
    F_S = -(resid[:, 0] * cb + resid[:, 1] * sb)
    V = np.linalg.norm(v, axis=1)
    u_pct = td.data.throttle_z_pct[rows]
    norm = u_pct**k1 * V ** (2.0 - k1) * td.rho_ratio[rows]
    return {"alpha_rad": alpha_disk, "value": F_S / norm, "V": V, "u_pct": u_pct, "k1": k1, "k2": k2}


def plot_side_force(fit, path, truth: dict | None = None) -> Path:
    """The paper's Fig. rotor_Drag_Data: non-dimensional rotor side force vs alpha, with the fit.

    Fitted curve ``C_S ((pi/2)^2 - alpha^2)(alpha + k2)`` (eq:model_Fs) at the posterior mean and
    its 95 % band over the posterior draws.
    """
    fig = Figure(figsize=(7, 4.5), dpi=100)
    ax = fig.subplots()
    if fit.table1_data.side_rows.size == 0:
        ax.text(0.5, 0.5, "no side-force rows (lift rotors on, airspeed > 0) in the data",
                ha="center", va="center", transform=ax.transAxes)
        return _save(fig, path)
    pts = side_force_points(fit)
    sc = ax.scatter(np.degrees(pts["alpha_rad"]), pts["value"], c=pts["V"], s=8, cmap="viridis",
                    label="measured (model's other terms removed)")
    fig.colorbar(sc, ax=ax, label="airspeed V (m/s)")
    a = np.linspace(pts["alpha_rad"].min() - 0.05, pts["alpha_rad"].max() + 0.05, 200)
    cs = fit.column("CS").ravel()
    k2 = fit.column("k2").ravel()
    P = (0.25 * np.pi**2 - a**2)
    sub = np.arange(cs.size)[:: max(1, cs.size // 2000)]
    curves = cs[sub, None] * P[None, :] * (a[None, :] + k2[sub, None])
    lo, hi = np.quantile(curves, [0.025, 0.975], axis=0)
    s = fit.summary()
    mean_curve = s["CS"]["mean"] * P * (a + s["k2"]["mean"])
    ax.fill_between(np.degrees(a), lo, hi, color="C1", alpha=0.3, label="95 % posterior band")
    ax.plot(np.degrees(a), mean_curve, color="C1", lw=2,
            label=rf"fit: $C_S((\pi/2)^2-\alpha^2)(\alpha+k_2)$, $k_1$={s['k1']['mean']:.3f}, "
                  rf"$k_2$={s['k2']['mean']:.3f}")
    if truth and all(k in truth for k in ("CS", "k2")):
        ax.plot(np.degrees(a), truth["CS"] * P * (a + truth["k2"]), "k--", lw=1, label="truth")
    ax.set_xlabel(r"rotor angle of attack $\alpha$ (deg)")
    ax.set_ylabel(r"$F_S / (m\, u_z^{k_1} V^{2-k_1})$  (m/s$^2$ per %$^{k_1}$(m/s)$^{2-k_1}$)")
    ax.set_title("Non-dimensional rotor side force (eq:model_Fs), per unit mass, u in %")
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)


def plot_residuals(fit, path) -> Path:
    """Residual (measured minus posterior-mean model) of each axis against the reading, in N."""
    td = fit.table1_data
    pred = fit.prediction_B() * td.mass_kg
    meas = td.data.force_B_N
    fig = Figure(figsize=(10, 3.4), dpi=90)
    axes = fig.subplots(1, 3)
    wing = td.data.wing_on
    for j, (ax, name) in enumerate(zip(axes, ("x", "y", "z"))):
        ax.plot(meas[wing, j], meas[wing, j] - pred[wing, j], ".", ms=3, label="wing on")
        ax.plot(meas[~wing, j], meas[~wing, j] - pred[~wing, j], ".", ms=3, label="propulsion only")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xlabel(f"measured force {name} (N)")
        ax.set_ylabel(f"residual {name} (N)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle("Residuals of the posterior-mean model (body FRD)", fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def plot_sqrt_n(n_rows, stds: dict, path) -> Path:
    """Posterior standard deviation (relative to the smallest data set's) vs number of rows.

    ``stds``: name -> list of std at each ``n_rows``. The dashed line is the 1/sqrt(N) law.
    """
    n = np.asarray(n_rows, float)
    fig = Figure(figsize=(6.5, 4.5), dpi=100)
    ax = fig.subplots()
    for name, s in stds.items():
        s = np.asarray(s, float)
        ax.loglog(n, s / s[0], "o-", ms=4, lw=1, label=LABELS.get(name, name))
    ax.loglog(n, np.sqrt(n[0] / n), "k--", lw=2, label=r"$1/\sqrt{N}$")
    ax.set_xlabel("number of force-balance rows N")
    ax.set_ylabel("posterior std / std at smallest N [-]")
    ax.set_title("Posterior std vs number of rows (virtual tunnel)")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    return _save(fig, path)


def plot_uiuc(prop, static_res: dict, ctj_res: dict, path) -> Path:
    """UIUC 7x4: static C_T vs rpm with the fitted constant, and C_T(J) with the quadratic."""
    fig = Figure(figsize=(11, 4.2), dpi=100)
    ax1, ax2 = fig.subplots(1, 2)
    st = prop.static
    ax1.plot(prop.rpm[st], prop.CT[st], "o", label="UIUC static C_T column")
    ct = static_res["CT"]
    ax1.axhline(ct["mean"], color="C1", label=f"fitted C_T = {ct['mean']:.4f} ± {ct['std']:.4f}")
    ax1.axhspan(*ct["ci95"], color="C1", alpha=0.2, label="95 % credible interval")
    ax1.set_xlabel("rotor speed (rpm)")
    ax1.set_ylabel(r"$C_T = T / (\rho n^2 D^4)$")
    ax1.set_title(f"{prop.name}: static thrust (eq:model_T)", fontsize=9)
    ax1.legend(fontsize=7)
    ax1.grid(alpha=0.3)
    for r in sorted(set(prop.rpm[~st])):
        m = (~st) & (prop.rpm == r)
        ax2.plot(prop.J[m], prop.CT[m], ".", ms=5, label=f"{r:.0f} rpm")
    lo, hi = ctj_res["rpm_range"]
    m = st & (prop.rpm >= 0.95 * lo) & (prop.rpm <= 1.05 * hi)
    ax2.plot(prop.J[m], prop.CT[m], "k.", ms=5, label="static (J = 0)")
    J = np.linspace(0, ctj_res["fit_range_J"][1], 200)
    c = ctj_res["coefficients_map"]
    ax2.plot(J, c[0] + c[1] * J + c[2] * J * J, "C3", lw=2,
             label=f"fit {c[0]:.4f} {c[1]:+.4f} J {c[2]:+.4f} J²")
    ax2.axhline(0, color="k", lw=0.5)
    ax2.axvline(ctj_res["J_zero"], color="C3", ls=":", lw=1, label=f"J_zero = {ctj_res['J_zero']:.3f}")
    ax2.set_xlabel("advance ratio J = V / (n D)")
    ax2.set_ylabel(r"$C_T$")
    ax2.set_title(f"{prop.name}: thrust loss with advance ratio", fontsize=9)
    ax2.legend(fontsize=7)
    ax2.grid(alpha=0.3)
    fig.suptitle("UIUC propeller database (Brandt & Selig), Master Airscrew GF 7x4", fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def plot_tudelft(polar, res: dict, path) -> Path:
    """TU Delft V3 kite: C_L and C_D vs alpha, the fitted linear model and its range."""
    fig = Figure(figsize=(11, 4.2), dpi=100)
    ax1, ax2 = fig.subplots(1, 2)
    lo, hi = res["alpha_range_deg"]
    a = np.linspace(lo - 3, hi + 3, 200)
    ar = np.radians(a)
    c = {k: v["mean"] for k, v in res["coefficients"].items()}
    for ax, y, ci, model, name in (
            (ax1, polar.CL, polar.CL_ci, c["CL0"] + c["CL1"] * ar, "C_L"),
            (ax2, polar.CD, polar.CD_ci, c["CD0"] + c["CD1"] * ar + c["CD2"] * ar**2, "C_D")):
        ax.errorbar(polar.alpha_deg, y, yerr=ci, fmt="o", ms=4, capsize=2, label="wind tunnel (95 % CI)")
        ax.plot(a, model, "C3", lw=2, label="Bayesian fit (posterior mean)")
        ax.axvspan(lo, hi, color="C2", alpha=0.15, label=f"linear range {lo:.1f} to {hi:.1f} deg")
        ax.set_xlabel(r"angle of attack $\alpha$ (deg)")
        ax.set_ylabel(f"${name}$")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    ax1.set_title(f"C_L0 = {c['CL0']:.3f}, C_L1 = {c['CL1']:.2f} /rad", fontsize=9)
    ax2.set_title(f"C_D0 = {c['CD0']:.4f}, C_D1 = {c['CD1']:.3f} /rad, C_D2 = {c['CD2']:.2f} /rad²",
                  fontsize=9)
    fig.suptitle("TU Delft V3 kite, Open Jet Facility, Re 5e5 (Poland et al. 2025, MIT)", fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


__all__ = ["CORNER_TICK_PT", "corner_figure", "trace_figure", "plot_corner", "plot_residuals", "plot_side_force", "plot_sqrt_n", "plot_trace",
           "plot_tudelft", "plot_uiuc", "side_force_points"]
