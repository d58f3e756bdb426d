"""Outputs of the fitting commands: the posterior file, Table I in Markdown, figures, and the
validation study (z-scores against the truth, 1/sqrt(N) shrinkage) and real-data reports."""
from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Callable

import numpy as np

from ..vehicle import PARAMETER_NAMES, Vehicle
from . import figures
from .bayes import SamplerSettings, Table1Fit, fit_table1
from .posterior import POSTERIOR_NAMES, posterior_dict_from_fit, write_posterior
from .rhat import SAMPLED_TO_QUANTITY, largest_rhat, rhat_by_quantity  # noqa: F401 (re-exported)
from .tunnel import make_design, run_virtual_tunnel

THRUSTER_ROWS = ("CTx", "CTz", "CS", "k1", "k2")
AERO_ROWS = ("CL0", "CL1", "CD0", "CD1", "CD2")
TEX = {"CTx": "C_Tx", "CTz": "C_Tz", "CS": "C_S", "k1": "k_1", "k2": "k_2", "CL0": "C_L0",
       "CL1": "C_L1", "CD0": "C_D0", "CD1": "C_D1", "CD2": "C_D2"}


def _pm(e: dict) -> str:
    return f"{e['mean']:.4g} ± {e['std']:.3g}"


def table1_markdown(post: dict, vehicle: Vehicle | None = None) -> str:
    """Table I of the paper, filled with a posterior (dict as in ``posterior.json``).

    With ``vehicle``, a column gives that vehicle file's values (for ``caltech_vtol``: the
    paper's Table I) for comparison.
    """
    p = post["parameters"]
    d = post.get("diagnostics", {})
    data = post.get("data", {})
    ref = post.get("reference", {})
    lines = ["# Fitted force model (the paper's Table I)", ""]
    lines.append(f"Data: `{data.get('path')}`: {data.get('n_rows')} rows, {data.get('n_observations')} "
                 f"observations ({data.get('n_rows_wing_on')} rows with the wing, "
                 f"{data.get('n_rows_side_force')} rotor side-force rows).  ")
    lines.append(f"Reference: vehicle `{ref.get('vehicle')}`, flight mass {ref.get('mass_kg')} kg, wing "
                 f"area {ref.get('wing_area_m2')} m², air density {ref.get('air_density_kgpm3')} kg/m³.  ")
    lines.append("Units as in Table I: throttle u in percent, forces per unit flight mass (m/s²), "
                 "alpha in rad. Posterior mean ± standard deviation.")
    lines += ["", "| Thruster | mean ± std | Aero | mean ± std |", "|---|---|---|---|"]
    for t, a in zip(THRUSTER_ROWS, AERO_ROWS):
        lines.append(f"| {TEX[t]} | {_pm(p[t])} | {TEX[a]} | {_pm(p[a])} |")
    truth = post.get("truth_check")
    head = "| parameter | unit | mean | std | 95 % credible interval | split R-hat | ESS | tau (steps) |"
    sep = "|---|---|---|---|---|---|---|---|"
    if vehicle is not None:
        head += f" `{vehicle.name}` file (mean ± std) |"
        sep += "---|"
    if truth:
        head += " truth | z |"
        sep += "---|---|"
    lines += ["", "## Details", "", head, sep]
    rhat = d.get("rhat_split", {})
    rhat_name, rhat_value = largest_rhat(rhat)
    rhat_text = f"{rhat_value:.4f} ({rhat_name})"
    ess = d.get("ess", {})
    tau = d.get("autocorr_time_steps", {})
    fitted = tuple(post.get("basis_names", PARAMETER_NAMES)) + ("k1", "k2")
    for n in fitted:
        e = p[n]
        row = (f"| {TEX.get(n, n)} | {e.get('unit', '')} | {e['mean']:.6g} | {e['std']:.4g} | "
               f"[{e['ci95'][0]:.5g}, {e['ci95'][1]:.5g}] | {rhat.get(n, float('nan')):.4f} | "
               f"{ess.get(n, float('nan')):.0f} | {tau.get(n, float('nan')):.1f} |")
        if vehicle is not None:
            fm, fs = vehicle.force_model, vehicle.force_model_std
            row += (f" {getattr(fm, n):.4g} ± {getattr(fs, n):.3g} |" if n in POSTERIOR_NAMES
                    else " (the basis's prior) |")
        if truth:
            t = truth.get(n)
            row += (f" {t['truth']:.6g} | {t['z']:+.2f} |" if t and t.get("z") is not None else " | |")
        lines.append(row)
    nz = post.get("noise", {})
    if nz:
        lines += ["", "Balance noise estimate (per axis, std = sigma_abs + sigma_rel |reading|): "
                  f"sigma_abs = {_pm(nz['sigma_abs_N'])} N, sigma_rel = {_pm(nz['sigma_rel'])}."]
    if post.get("not_identified"):
        lines += ["", "**Not identified by these data (posterior = prior):**"]
        lines += [f"- {k}: {v}" for k, v in post["not_identified"].items()]
    if post.get("fixed"):
        lines += ["", "Held fixed: " + ", ".join(f"{k} = {v:g}" for k, v in post["fixed"].items())]
    if d:
        lines += ["", "## Convergence", "",
                  f"- converged: **{d.get('converged')}** ({d.get('criteria')})",
                  f"- chain: {d.get('chain_length_steps')} steps x {d.get('n_walkers')} walkers after "
                  f"{d.get('burn_in_steps')} burn-in steps; longest autocorrelation time of a sampled "
                  f"parameter: chain = {d.get('chain_over_max_tau', float('nan')):.0f} tau",
                  f"- largest split R-hat: {rhat_text}; smallest "
                  f"ESS: {min(ess.values()) if ess else float('nan'):.0f}",
                  f"- acceptance fraction {d.get('acceptance_fraction', float('nan')):.2f}; "
                  f"{d.get('log_prob_evaluations')} log-posterior evaluations; sampler wall time "
                  f"{d.get('wall_time_s', float('nan')):.1f} s",
                  f"- sampler: {d.get('sampler')}"]
    pr = post.get("priors", {})
    if pr:
        lines += ["", "## Priors", ""]
        for k, v in pr.items():
            if isinstance(v, dict):
                v = "; ".join(f"{kk}: {vv}" for kk, vv in v.items())
            lines.append(f"- {k}: {v}")
    return "\n".join(lines) + "\n"


def truth_dict(truth_info: dict | None) -> dict | None:
    """name -> value of a tunnel side file's coefficients (None when it has none)."""
    if not truth_info or not truth_info.get("coefficients"):
        return None
    return {k: float(v) for k, v in truth_info["coefficients"].items()}


def write_fit_outputs(fit: Table1Fit, out_dir, *, data_path=None, truth_info: dict | None = None,
                      settings: SamplerSettings | None = None, vehicle: Vehicle | None = None,
                      make_figures: bool = True) -> dict[str, Path]:
    """Write posterior.json, table1.md and the figures of a Table I fit into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    truth = truth_dict(truth_info)
    post = posterior_dict_from_fit(
        fit, data_path=data_path,
        truth_theta_table=None if truth is None else np.array([truth[n] for n in PARAMETER_NAMES]),
        truth_k=None if truth is None else (truth["k1"], truth["k2"]), settings=settings)
    paths = {"posterior": write_posterior(out / "posterior.json", post)}
    md = out / "table1.md"
    md.write_text(table1_markdown(post, vehicle), encoding="utf-8")
    paths["table1"] = md
    if make_figures:
        paths["corner"] = figures.plot_corner(fit, out / "corner.png", truth)
        paths["trace"] = figures.plot_trace(fit, out / "trace.png", post["diagnostics"])
        paths["side_force"] = figures.plot_side_force(fit, out / "side_force.png", truth)
        paths["residuals"] = figures.plot_residuals(fit, out / "residuals.png")
    return paths


# ----------------------------------------------------------------------------------------------
# Validation study on virtual-tunnel data
# ----------------------------------------------------------------------------------------------
def zscores(fit: Table1Fit, truth_theta_table: np.ndarray, k1: float, k2: float) -> dict[str, float]:
    """(posterior mean - truth) / posterior std for the ten Table I quantities."""
    s = fit.summary()
    truth = dict(zip(PARAMETER_NAMES, truth_theta_table))
    truth.update(k1=k1, k2=k2)
    return {n: (s[n]["mean"] - truth[n]) / s[n]["std"] for n in POSTERIOR_NAMES}


def sqrt_n_study(vehicle: Vehicle, rng: np.random.Generator, repeats=(1, 4, 16),
                 settings: SamplerSettings | None = None, design_overrides: dict | None = None,
                 progress: Callable[[str], None] | None = None) -> dict:
    """Fit virtual-tunnel data with every point measured 1, 4, 16 times (N, 4N, 16N rows).

    Returns rows, the posterior std of each quantity at each N, and the successive std ratios
    (2 expected for a 4x larger data set).
    """
    stds = {n: [] for n in POSTERIOR_NAMES}
    n_rows, times, rhat_max = [], [], []
    for r in repeats:
        if progress is not None:
            progress(f"1/sqrt(N) study: every point measured {r} times")
        design = make_design(repeats=int(r), **(design_overrides or {}))
        run = run_virtual_tunnel(vehicle, rng, design=design)
        t0 = time.perf_counter()
        fit = fit_table1(run.data, vehicle, rng, settings=settings)
        times.append(time.perf_counter() - t0)
        s = fit.summary()
        n_rows.append(run.data.n_rows)
        rhat_max.append(max(s[n]["rhat"] for n in POSTERIOR_NAMES))
        for n in POSTERIOR_NAMES:
            stds[n].append(s[n]["std"])
    ratios = {n: [v[i] / v[i + 1] for i in range(len(v) - 1)] for n, v in stds.items()}
    return {"repeats": list(repeats), "n_rows": n_rows, "std": stds, "ratio": ratios,
            "fit_time_s": times, "rhat_max": rhat_max}


def zscore_study(vehicle: Vehicle, seeds, settings: SamplerSettings | None = None,
                 perturb: bool = True, progress: Callable[[str], None] | None = None) -> dict:
    """Tunnel + fit for several seeds (truth drawn from Table I's spread when ``perturb``);
    the z-scores of all ten quantities and the fraction within 1 and 2 standard deviations."""
    z_all = {}
    for seed in seeds:
        if progress is not None:
            progress(f"calibration study: seed {seed}")
        rng = np.random.default_rng(seed)
        run = run_virtual_tunnel(vehicle, rng, perturb=perturb, seed=seed)
        fit = fit_table1(run.data, vehicle, rng, settings=settings)
        t = run.truth
        z_all[int(seed)] = zscores(fit, t.as_table_theta(), t.k1, t.k2)
    z = np.array([[v[n] for n in POSTERIOR_NAMES] for v in z_all.values()])
    return {"seeds": [int(s) for s in seeds], "z": z_all,
            "fraction_within_1sd": float(np.mean(np.abs(z) < 1.0)),
            "fraction_within_2sd": float(np.mean(np.abs(z) < 2.0)),
            "n_z": int(z.size), "max_abs_z": float(np.max(np.abs(z)))}


def validation_fit_count(n_seeds: int, repeats) -> int:
    """How many fits :func:`validation_report` makes (for a progress bar)."""
    return 1 + int(n_seeds) + len(tuple(repeats))


def validation_report(out_dir, vehicle: Vehicle, *, seed: int = 0, n_seeds: int = 10,
                      repeats=(1, 4, 16), settings: SamplerSettings | None = None,
                      sqrt_n_settings: SamplerSettings | None = None,
                      progress: Callable[[str], None] | None = None) -> dict:
    """The targets of the fitting feature, measured: writes validation.json, validation.md and
    sqrt_n.png into ``out_dir`` and returns the numbers.

    1. One fixed seed: tunnel with Table I means as the truth, full fit, z-scores, fit time,
       convergence.
    2. ``n_seeds`` seeds with the truth drawn from Table I's spread: the fraction of |z| < 2.
    3. 1/sqrt(N): fits at N, 4N, 16N rows.

    ``progress``, if given, is called with a few words before each of the
    ``1 + n_seeds + len(repeats)`` fits (:func:`validation_fit_count`).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    settings = settings or SamplerSettings()
    rng = np.random.default_rng(seed)
    if progress is not None:
        progress(f"full fit, seed {seed}")
    run = run_virtual_tunnel(vehicle, rng, seed=seed)
    t0 = time.perf_counter()
    fit = fit_table1(run.data, vehicle, rng, settings=settings)
    fit_time = time.perf_counter() - t0
    s = fit.summary()
    t = run.truth
    z = zscores(fit, t.as_table_theta(), t.k1, t.k2)
    post = posterior_dict_from_fit(fit, settings=settings)
    single = {"seed": seed, "n_rows": run.data.n_rows, "fit_time_s": fit_time, "z": z,
              "max_abs_z": max(abs(v) for v in z.values()),
              "rhat_max": max(s[n]["rhat"] for n in s), "ess_min": min(s[n]["ess"] for n in s),
              "chain_over_max_tau": post["diagnostics"]["chain_over_max_tau"],
              "converged": post["diagnostics"]["converged"],
              "posterior": {n: {"mean": s[n]["mean"], "std": s[n]["std"]} for n in s}}
    zs = zscore_study(vehicle, range(seed + 1, seed + 1 + n_seeds), settings, progress=progress)
    sq = sqrt_n_study(vehicle, np.random.default_rng(seed + 1000), repeats,
                      sqrt_n_settings or SamplerSettings(n_burn=300, min_steps=1000, max_steps=1000),
                      progress=progress)
    figures.plot_sqrt_n(sq["n_rows"], sq["std"], out / "sqrt_n.png")
    result = {"single_seed": single, "seeds": zs, "sqrt_n": sq}
    (out / "validation.json").write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    lines = ["# Validation of the Table I fit on virtual-tunnel data", "",
             f"## One fixed seed ({seed}), truth = the `{vehicle.name}` Table I means", "",
             f"{single['n_rows']} rows; fit wall time {fit_time:.1f} s; converged: {single['converged']} "
             f"(largest split R-hat {single['rhat_max']:.4f}, smallest ESS {single['ess_min']:.0f}, "
             f"chain = {single['chain_over_max_tau']:.0f} autocorrelation times).", "",
             "| parameter | truth | posterior mean | posterior std | z |", "|---|---|---|---|---|"]
    truth = dict(zip(PARAMETER_NAMES, t.as_table_theta()))
    truth.update(k1=t.k1, k2=t.k2)
    for n in POSTERIOR_NAMES:
        lines.append(f"| {TEX[n]} | {truth[n]:.6g} | {s[n]['mean']:.6g} | {s[n]['std']:.4g} | {z[n]:+.2f} |")
    lines += ["", f"## {n_seeds} more seeds, truth drawn from Table I's spread", "",
              f"{zs['n_z']} z-scores: {100 * zs['fraction_within_1sd']:.0f} % within 1 std (68 % "
              f"expected), {100 * zs['fraction_within_2sd']:.0f} % within 2 std (95 % expected); "
              f"largest |z| = {zs['max_abs_z']:.2f}.", "",
              "## Posterior spread vs number of rows (1/sqrt(N))", "",
              "| parameter | " + " | ".join(f"std at N = {n}" for n in sq["n_rows"]) + " | "
              + " | ".join(f"ratio {sq['n_rows'][i]}->{sq['n_rows'][i + 1]}" for i in range(len(sq["n_rows"]) - 1))
              + " |", "|---|" + "---|" * (2 * len(sq["n_rows"]) - 1)]
    for n in POSTERIOR_NAMES:
        lines.append(f"| {TEX[n]} | " + " | ".join(f"{v:.4g}" for v in sq["std"][n]) + " | "
                     + " | ".join(f"{r:.3f}" for r in sq["ratio"][n]) + " |")
    allr = np.array([r for v in sq["ratio"].values() for r in v])
    lines += ["", f"Ratios for 4x more rows: {allr.min():.3f} to {allr.max():.3f} (2 expected); fit "
              "times " + ", ".join(f"{x:.1f} s" for x in sq["fit_time_s"]) + ". Figure: sqrt_n.png."]
    (out / "validation.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    return result


# ----------------------------------------------------------------------------------------------
# Real data
# ----------------------------------------------------------------------------------------------
def realdata_outputs(out_dir, data_dir=None, seed: int = 0, prop_name: str | None = None,
                     vehicle: Vehicle | None = None) -> dict:
    """UIUC 7x4 (static C_T, C_T(J)) and TU Delft wing fits: realdata.json, realdata.md, figures."""
    from . import realdata

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    prop_name = prop_name or realdata.DEFAULT_PROP
    rng = np.random.default_rng(seed)
    static = realdata.fit_uiuc_static_ct(prop_name, data_dir, rng)
    ctj = realdata.fit_uiuc_ct_of_j(prop_name, data_dir, rng)
    polar_fit = realdata.fit_tudelft_polar(data_dir, rng)
    prop = realdata.read_uiuc_propeller(prop_name, data_dir)
    figures.plot_uiuc(prop, static, ctj, out / "uiuc_7x4.png")
    figures.plot_tudelft(realdata.read_tudelft_polar(data_dir), polar_fit, out / "tudelft_polar.png")
    result = {"uiuc_static_ct": static, "uiuc_ct_of_j": ctj, "tudelft_polar": polar_fit}
    if vehicle is not None:
        # what Table I's CTx implies for the pusher's speed at full throttle, with the UIUC C_T
        D = vehicle.geometry.pusher_prop_diameter_m
        ct = static["CT"]["mean"]
        rho = vehicle.envelope.air_density_kgpm3
        T_full = vehicle.force_model.CTx * 100.0**2 * vehicle.mass.mass_kg
        n_full = math.sqrt(T_full / (ct * rho * D**4))
        result["implied_pusher_full_throttle"] = {
            "vehicle": vehicle.name, "thrust_N": T_full, "speed_rps": n_full, "speed_rpm": 60 * n_full,
            "note": "T(100 %) = CTx 100^2 m from Table I and T = C_T rho n^2 D^4 with the UIUC static C_T"}
    (out / "realdata.json").write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    c = ctj["coefficients_map"]
    r = ctj["ratio_coefficients"]
    pc = polar_fit["coefficients"]
    lines = ["# Fits to real wind-tunnel data", "",
             f"## UIUC propeller database: {prop_name} (the paper's APC 7x4 is not in the database)", "",
             f"Source: {static['citation']}; file `{static['source']}`.", "",
             f"- Static thrust T = C_T rho n² D⁴ (eq:model_T), {static['n_static_rows']} static rows, "
             f"{static['rpm_range'][0]:.0f}-{static['rpm_range'][1]:.0f} rpm: "
             f"**C_T = {static['CT']['mean']:.5f} ± {static['CT']['std']:.5f}** (95 % CI "
             f"[{static['CT']['ci95'][0]:.5f}, {static['CT']['ci95'][1]:.5f}]).",
             f"- The data's own C_T column at J = 0: mean {static['column']['mean']:.5f} (range "
             f"{static['column']['min']:.4f}-{static['column']['max']:.4f}); fit minus column mean: "
             f"{100 * static['rel_diff_to_column_mean']:+.3f} %.",
             f"- C_T rises with rpm ({static['CT_trend_per_1000rpm']:+.4f} per 1000 rpm, a Reynolds-number "
             f"effect the constant-C_T model of eq:model_T does not have); relative scatter about the "
             f"constant: {100 * static['noise_rel']['mean']:.1f} %.",
             f"- C_T(J) = {c[0]:.5f} {c[1]:+.5f} J {c[2]:+.5f} J² on J in [0, {ctj['fit_range_J'][1]:.3f}] "
             f"({ctj['n_rows']} rows: sweeps at {', '.join(f'{x:.0f}' for x in ctj['sweep_rpms'])} rpm and "
             f"{ctj['n_static_rows']} static rows), RMS residual {ctj['rms_residual']:.4f}.",
             f"- Pusher thrust ratio C_T(J)/C_T(0) = 1 {r[1]:+.4f} J {r[2]:+.4f} J², zero at "
             f"J = {ctj['J_zero']:.3f} (`pusher_thrust_ratio_model()`); at J = 0.5 it is "
             f"{1 + r[1] * 0.5 + r[2] * 0.25:.2f}."]
    if "implied_pusher_full_throttle" in result:
        ip = result["implied_pusher_full_throttle"]
        lines.append(f"- With Table I's CTx ({vehicle.name}), the pusher would give {ip['thrust_N']:.1f} N at "
                     f"100 % throttle, i.e. {ip['speed_rpm']:.0f} rpm with this C_T (for the advance "
                     "ratio J = V / (n D) of the plant's thrust loss).")
    lines += ["", "Figure: uiuc_7x4.png.", "",
              "## TU Delft V3 kite wing (Open Jet Facility, Re 5e5)", "",
              f"Source: {polar_fit['citation']}; file `{polar_fit['source']}`.", "",
              f"Linear range chosen from the data: alpha from {polar_fit['alpha_range_deg'][0]:.1f} to "
              f"{polar_fit['alpha_range_deg'][1]:.1f} deg ({polar_fit['n_points']} points). Rule: "
              f"{polar_fit['range_rule']}.", "",
              "| coefficient | unit | mean ± std | 95 % credible interval |", "|---|---|---|---|"]
    for n, e in pc.items():
        lines.append(f"| {n} | {polar_fit['units'][n]} | {_pm(e)} | [{e['ci95'][0]:.4g}, {e['ci95'][1]:.4g}] |")
    lines += ["", f"RMS residuals: C_L {polar_fit['rms_residual_CL']:.4f}, C_D "
              f"{polar_fit['rms_residual_CD']:.4f}; model-discrepancy sd C_L "
              f"{polar_fit['model_sd_CL']['mean']:.3f}, C_D {polar_fit['model_sd_CD']['mean']:.4f}. "
              f"Valid only inside the range (stall follows above it). Figure: tudelft_polar.png."]
    (out / "realdata.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    return result


__all__ = ["largest_rhat", "rhat_by_quantity", "validation_fit_count", "realdata_outputs", "sqrt_n_study", "table1_markdown", "truth_dict", "validation_report",
           "write_fit_outputs", "zscore_study", "zscores"]
