"""Command-line interface of the fitting feature.

::

    vtoladapt tunnel --vehicle NAME --out DATA.csv [--seed N] [--perturb] [--repeats R]
    vtoladapt fit DATA.csv --out DIR [--vehicle NAME] [--seed N] [--truth DATA.truth.json] [--fast]
    vtoladapt fit-realdata --out DIR [--data-dir PATH] [--seed N]
    vtoladapt fit-validate --out DIR [--vehicle NAME] [--seed N] [--seeds K] [--quick]

``tunnel`` writes a force-balance CSV (format: :mod:`vtoladapt.fitting.data`) and its side file
``DATA.truth.json`` (the true coefficients, noise model and design). ``fit`` writes
``posterior.json``, ``table1.md``, ``corner.png``, ``trace.png``, ``side_force.png`` and
``residuals.png`` into DIR. ``fit-realdata`` fits the UIUC 7x4 propeller and the TU Delft wing
(``realdata.json``, ``realdata.md``, ``uiuc_7x4.png``, ``tudelft_polar.png``). ``fit-validate``
measures the targets on virtual data (``validation.json``, ``validation.md``, ``sqrt_n.png``).

Every leaf parser sets ``handler`` (``handler(args) -> int``, the exit code: 0 success, 1 bad
input or data, 3 fit not converged with ``--require-converged``).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from ..config import ConfigError
from ..vehicle import load_vehicle


def register_cli(subparsers) -> dict[str, argparse.ArgumentParser]:
    """Add ``tunnel``, ``fit``, ``fit-realdata`` and ``fit-validate`` to ``subparsers``.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        From ``parser.add_subparsers()``.

    Returns
    -------
    dict
        Sub-command name -> its parser.
    """
    parsers = {}
    tun = subparsers.add_parser(
        "tunnel", help="virtual wind tunnel: force-balance sweeps of a simulated aircraft",
        description="Sweep the simulated aircraft (wing over the linear alpha range at 3-9 m/s, "
                    "static thrust steps, lift rotors at -45..45 deg for the rotor side force) and "
                    "write a force-balance CSV with balance noise (0.02 N + 1 %% of reading per axis "
                    "by default) and DATA.truth.json with the true coefficients.")
    tun.add_argument("--vehicle", default="caltech_vtol", help="vehicle name or .toml path "
                     "(default caltech_vtol)")
    tun.add_argument("--out", metavar="DATA.csv", type=Path, required=True, help="CSV file to write")
    tun.add_argument("--seed", type=int, default=0, help="seed of the numpy Generator (default 0)")
    tun.add_argument("--perturb", action="store_true",
                     help="draw the true coefficients from Table I's mean and std (default: the means)")
    tun.add_argument("--repeats", type=int, default=1, help="measure every point this many times")
    tun.add_argument("--noise-abs-N", dest="noise_abs_N", type=float, default=0.02,
                     help="absolute balance noise per axis, N (default 0.02)")
    tun.add_argument("--noise-rel", dest="noise_rel", type=float, default=0.01,
                     help="relative balance noise per axis (default 0.01 = 1 %% of reading)")
    tun.add_argument("--air-density", dest="air_density", type=float, default=None,
                     help="tunnel air density, kg/m^3 (default: the vehicle's reference density)")
    tun.set_defaults(handler=cmd_tunnel)
    parsers["tunnel"] = tun

    fit = subparsers.add_parser(
        "fit", help="Bayesian fit (MCMC) of the force model (Table I) to force-balance data",
        description="Fit CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1, k1, k2 to a force-balance CSV by "
                    "Bayesian regression (emcee over k1, k2 and the noise; the eight linear "
                    "coefficients marginalised analytically) and write posterior.json, table1.md "
                    "and figures into DIR.")
    fit.add_argument("data", metavar="DATA.csv", type=Path, help="force-balance CSV")
    fit.add_argument("--out", metavar="DIR", type=Path, required=True, help="output folder")
    fit.add_argument("--vehicle", default="caltech_vtol",
                     help="vehicle giving wing area, flight mass and reference density "
                          "(default caltech_vtol)")
    fit.add_argument("--seed", type=int, default=0, help="seed of the numpy Generator (default 0)")
    fit.add_argument("--truth", type=Path, default=None,
                     help="a tunnel side file (DATA.truth.json): adds z-scores against the truth")
    fit.add_argument("--mass-kg", dest="mass_kg", type=float, default=None,
                     help="flight mass the per-unit-mass model refers to (default: CSV column, else "
                          "the vehicle's)")
    fit.add_argument("--wing-area-m2", dest="wing_area_m2", type=float, default=None,
                     help="reference wing area (default: the vehicle's)")
    fit.add_argument("--rho-ref", dest="rho_ref", type=float, default=None,
                     help="air density the coefficients refer to, kg/m^3 (default: the vehicle's)")
    fit.add_argument("--walkers", type=int, default=None, help="emcee walkers (default 16)")
    fit.add_argument("--max-steps", dest="max_steps", type=int, default=None,
                     help="most MCMC steps after burn-in (default 20000)")
    fit.add_argument("--fast", action="store_true",
                     help="short chains for a smoke test (not converged by the criteria)")
    fit.add_argument("--no-figures", dest="figures", action="store_false", help="skip the PNGs")
    fit.add_argument("--require-converged", dest="require_converged", action="store_true",
                     help="exit with code 3 if the convergence criteria are not met")
    fit.set_defaults(handler=cmd_fit)
    parsers["fit"] = fit

    real = subparsers.add_parser(
        "fit-realdata", help="fit the UIUC 7x4 propeller and the TU Delft wing polar",
        description="Static C_T and C_T(J) of the UIUC Master Airscrew GF 7x4 (Brandt & Selig) and "
                    "CL0, CL1, CD0, CD1, CD2 of the TU Delft V3 kite wing (Poland et al. 2025) on "
                    "its linear range, with the same Bayesian machinery; writes realdata.json, "
                    "realdata.md and figures into DIR.")
    real.add_argument("--out", metavar="DIR", type=Path, required=True, help="output folder")
    real.add_argument("--data-dir", dest="data_dir", type=Path, default=None,
                      help="the data folder holding uiuc-propdb/ and "
                           "tudelft-v3-kite-windtunnel/ (default $VTOLADAPT_DATA_DIR, else the "
                           "repository's vendored data/)")
    real.add_argument("--prop", default=None, help="UIUC BladeName (default 'magf 7.0x4.0')")
    real.add_argument("--vehicle", default="caltech_vtol",
                      help="vehicle for the implied pusher speed at full throttle")
    real.add_argument("--seed", type=int, default=0)
    real.set_defaults(handler=cmd_fit_realdata)
    parsers["fit-realdata"] = real

    val = subparsers.add_parser(
        "fit-validate", help="measure the fit against known truths (z-scores, 1/sqrt(N), time)",
        description="Virtual-tunnel data from known coefficients: z-scores of a full fit for one "
                    "seed, calibration over several seeds, and the posterior std at N, 4N, 16N rows.")
    val.add_argument("--out", metavar="DIR", type=Path, required=True, help="output folder")
    val.add_argument("--vehicle", default="caltech_vtol")
    val.add_argument("--seed", type=int, default=0)
    val.add_argument("--seeds", type=int, default=10, help="seeds of the calibration study")
    val.add_argument("--quick", action="store_true",
                     help="3 seeds and N, 4N only, short chains (a smoke test)")
    val.add_argument("--quiet", action="store_true", help="no progress bar")
    val.set_defaults(handler=cmd_fit_validate)
    parsers["fit-validate"] = val
    return parsers


def _err(cmd: str, exc: Exception) -> int:
    print(f"vtoladapt {cmd}: error: {exc}", file=sys.stderr)
    return 1


def cmd_tunnel(args: argparse.Namespace) -> int:
    """Handler of ``vtoladapt tunnel``; returns the exit code."""
    from .tunnel import BalanceNoise, make_design, run_virtual_tunnel, write_tunnel_run

    try:
        veh = load_vehicle(args.vehicle)
        noise = BalanceNoise(sigma_abs_N=args.noise_abs_N, sigma_rel=args.noise_rel)
        if args.noise_abs_N < 0 or not 0 <= args.noise_rel < 1:
            raise ConfigError(f"--noise-abs-N = {args.noise_abs_N}, --noise-rel = {args.noise_rel}: "
                              "need noise-abs-N >= 0 and 0 <= noise-rel < 1")
        design = make_design(repeats=args.repeats)
        run = run_virtual_tunnel(veh, np.random.default_rng(args.seed), design=design, noise=noise,
                                 perturb=args.perturb, air_density_kgpm3=args.air_density,
                                 seed=args.seed)
        csv_path, side = write_tunnel_run(run, args.out)
    except (ConfigError, ValueError, OSError) as exc:
        return _err("tunnel", exc)
    print(f"{run.data.n_rows} rows from {veh.name} (truth: "
          f"{'perturbed draw' if args.perturb else 'Table I means'}, seed {args.seed})")
    print(f"wrote {csv_path}\nwrote {side}")
    return 0


def cmd_fit(args: argparse.Namespace) -> int:
    """Handler of ``vtoladapt fit``; returns the exit code."""
    from .bayes import SamplerSettings, fit_table1
    from .data import read_force_balance_csv
    from .tunnel import read_truth

    from .report import write_fit_outputs

    try:
        veh = load_vehicle(args.vehicle)
        data = read_force_balance_csv(args.data)
        truth_info = read_truth(args.truth) if args.truth is not None else None
        settings = SamplerSettings.fast() if args.fast else SamplerSettings()
        changes = {}
        if args.walkers is not None:
            if args.walkers < 4:
                raise ConfigError(f"--walkers = {args.walkers}: need at least 4")
            changes["n_walkers"] = args.walkers
        if args.max_steps is not None:
            if args.max_steps < 10:
                raise ConfigError(f"--max-steps = {args.max_steps}: need at least 10")
            changes["max_steps"] = args.max_steps
            changes["min_steps"] = min(settings.min_steps, args.max_steps)
        if changes:
            import dataclasses

            settings = dataclasses.replace(settings, **changes)
        t0 = time.perf_counter()
        fit = fit_table1(data, veh, np.random.default_rng(args.seed), settings=settings,
                         mass_kg=args.mass_kg, wing_area_m2=args.wing_area_m2,
                         rho_ref_kgpm3=args.rho_ref)
        elapsed = time.perf_counter() - t0
        paths = write_fit_outputs(fit, args.out, data_path=args.data, truth_info=truth_info,
                                  settings=settings, vehicle=veh, make_figures=args.figures)
    except (ConfigError, ValueError, OSError) as exc:
        return _err("fit", exc)
    import json

    from .report import largest_rhat

    post = json.loads(paths["posterior"].read_text())
    d = post["diagnostics"]
    rhat_name, rhat = largest_rhat(d["rhat_split"])
    print(f"fit of {data.n_rows} rows in {elapsed:.1f} s: converged {d['converged']} (largest split "
          f"R-hat {rhat:.4f} ({rhat_name}), chain = {d['chain_over_max_tau']:.0f} tau)")
    for n, e in post["parameters"].items():
        z = post.get("truth_check", {}).get(n, {}).get("z")
        print(f"  {n:4s} {e['mean']: .5g} +- {e['std']:.3g}" + (f"   z = {z:+.2f}" if z is not None else ""))
    for p in paths.values():
        print(f"wrote {p}")
    if args.require_converged and not d["converged"]:
        print("vtoladapt fit: the convergence criteria were not met", file=sys.stderr)
        return 3
    return 0


def cmd_fit_realdata(args: argparse.Namespace) -> int:
    """Handler of ``vtoladapt fit-realdata``; returns the exit code."""
    from .report import realdata_outputs

    try:
        veh = load_vehicle(args.vehicle)
        res = realdata_outputs(args.out, args.data_dir, args.seed, args.prop, veh)
    except (ConfigError, ValueError, OSError) as exc:
        return _err("fit-realdata", exc)
    s = res["uiuc_static_ct"]
    print(f"UIUC {s['prop']}: static C_T = {s['CT']['mean']:.5f} +- {s['CT']['std']:.5f} "
          f"(data column mean {s['column']['mean']:.5f})")
    r = res["uiuc_ct_of_j"]["ratio_coefficients"]
    print(f"pusher thrust ratio C_T(J)/C_T(0) = 1 {r[1]:+.4f} J {r[2]:+.4f} J^2")
    t = res["tudelft_polar"]
    print(f"TU Delft wing, alpha {t['alpha_range_deg'][0]:.1f}..{t['alpha_range_deg'][1]:.1f} deg: " +
          ", ".join(f"{n} = {e['mean']:.4g} +- {e['std']:.3g}" for n, e in t["coefficients"].items()))
    print(f"wrote {args.out / 'realdata.json'}, realdata.md, uiuc_7x4.png, tudelft_polar.png")
    return 0


def cmd_fit_validate(args: argparse.Namespace) -> int:
    """Handler of ``vtoladapt fit-validate``; returns the exit code."""
    from tqdm import tqdm

    from .bayes import SamplerSettings
    from .report import validation_fit_count, validation_report

    n_seeds, repeats = (3, (1, 4)) if args.quick else (args.seeds, (1, 4, 16))
    # a bar over the fits: a full validation takes minutes, and each fit is silent
    bar = tqdm(total=validation_fit_count(n_seeds, repeats), unit="fit", desc="fit-validate",
               file=sys.stderr, disable=args.quiet,
               bar_format="{desc}: {n_fmt}/{total_fmt} fits |{bar}| [{elapsed}<{remaining}] {postfix}")
    started = [False]

    def progress(what: str) -> None:
        if started[0]:
            bar.update(1)
        started[0] = True
        bar.set_postfix_str(what)

    try:
        veh = load_vehicle(args.vehicle)
        if args.quick:
            res = validation_report(args.out, veh, seed=args.seed, n_seeds=n_seeds, repeats=repeats,
                                    settings=SamplerSettings.fast(),
                                    sqrt_n_settings=SamplerSettings.fast(), progress=progress)
        else:
            res = validation_report(args.out, veh, seed=args.seed, n_seeds=n_seeds, progress=progress)
        bar.update(1)
    except (ConfigError, ValueError, OSError) as exc:
        return _err("fit-validate", exc)
    finally:
        bar.close()
    s = res["single_seed"]
    print(f"seed {s['seed']}: max |z| = {s['max_abs_z']:.2f}, fit {s['fit_time_s']:.1f} s, "
          f"converged {s['converged']}")
    print(f"{res['seeds']['n_z']} z-scores: {100 * res['seeds']['fraction_within_2sd']:.0f} % within 2 std")
    print(f"wrote {args.out / 'validation.md'}, validation.json, sqrt_n.png")
    return 0


__all__ = ["cmd_fit", "cmd_fit_realdata", "cmd_fit_validate", "cmd_tunnel", "register_cli"]
