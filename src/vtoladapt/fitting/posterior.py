"""Writing a fit as a posterior file; the file's format and reading it are :mod:`vtoladapt.bases.posterior`.

The format, the reader and the controller's prior from a posterior are a model-layer module (the
simulator applies a scenario's posterior, and the simulator is below the fitting); their names are
imported here too, so ``vtoladapt.fitting.posterior.load_posterior`` and the like keep working.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..bases.posterior import (POSTERIOR_FORMAT, POSTERIOR_NAMES, POSTERIOR_VERSION, ControllerPrior,  # noqa: F401
                               Posterior, PosteriorError, apply_posterior, basis_of, controller_prior,
                               load_posterior, parameter_units, posterior_from_dict, vehicle_with_posterior,
                               write_posterior)


def file_sha256(path: str | Path) -> str:
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def posterior_dict_from_fit(fit, *, data_path: str | Path | None = None,
                            truth_theta_table: np.ndarray | None = None,
                            truth_k: tuple[float, float] | None = None,
                            settings=None) -> dict:
    """The posterior file's content for a :class:`vtoladapt.fitting.bayes.Table1Fit`.

    ``truth_theta_table`` (the paper's 8, or the basis's p) and ``truth_k`` = (k1, k2), when given (a
    virtual tunnel's truth), add ``truth_check`` with the z-score ``(mean - truth) / std`` of each parameter.
    """
    from .._version import __version__

    s = fit.summary()
    units = parameter_units()
    td = fit.table1_data
    m = fit.marginal

    def entry(name, unit):
        e = s[name]
        return {"mean": e["mean"], "std": e["std"], "ci95": e["ci95"], "mcse": e["mcse"], "unit": unit}

    spec = td.basis
    theta_names = fit.theta_names
    units.update(dict(zip(spec.names, spec.units)) if spec is not None else {})
    fitted = tuple(theta_names) + ("k1", "k2")
    params = {n: entry(n, units[n]) for n in fitted}
    noise = {"sigma_abs_N": entry("sigma_abs_N", "N"), "sigma_rel": entry("sigma_rel", "-")}
    idx = [fit.names.index(n) for n in fitted]
    flat = fit.draws.reshape(-1, fit.draws.shape[2])[:, idx]
    cov = np.cov(flat, rowvar=False)
    chain_tau = dict(zip(m.problem.param_names, (float(t) for t in m.tau_steps)))
    diag_names = fitted + ("sigma_abs_N", "sigma_rel")
    tau = {n: s[n]["tau_steps"] for n in diag_names}
    sampled_tau_max = max(chain_tau.values()) if chain_tau else 1.0
    rhat_all = {n: s[n]["rhat"] for n in diag_names}
    settings_d = ({k: getattr(settings, k) for k in ("n_walkers", "n_burn", "min_steps", "max_steps",
                                                     "chunk_steps", "tau_multiple", "rhat_max")}
                  if settings is not None else {})
    diagnostics = {
        "converged": bool(m.converged and max(rhat_all.values()) < (settings.rhat_max if settings else 1.01)),
        "criteria": "split R-hat < 1.01 for every quantity and chain length > 50 integrated "
                    "autocorrelation times of every sampled parameter",
        "rhat_split": rhat_all,
        "ess": {n: s[n]["ess"] for n in diag_names},
        "autocorr_time_steps": tau,
        "sampled_parameters": list(m.problem.param_names),
        "sampled_autocorr_time_steps": chain_tau,
        "sampled_rhat_split": dict(zip(m.problem.param_names, (float(r) for r in m.rhat))),
        "chain_length_steps": m.n_steps,
        "chain_over_max_tau": m.n_steps / sampled_tau_max,
        "n_walkers": int(m.chain.shape[1]),
        "burn_in_steps": m.n_burn,
        "thin_for_draws": m.thin,
        "n_draws": int(fit.draws.shape[0] * fit.draws.shape[1]),
        "acceptance_fraction": m.acceptance_fraction,
        "log_prob_evaluations": m.n_log_prob_evaluations,
        "wall_time_s": m.wall_time_s,
        "map_sampled_parameters": dict(zip(m.problem.param_names, (float(v) for v in m.map_phi))),
        "sampler": "emcee EnsembleSampler with DEMove; linear "
                   "coefficients marginalised analytically and drawn from their conditional Gaussian",
        "settings": settings_d,
    }
    d = {
        "format": POSTERIOR_FORMAT, "format_version": POSTERIOR_VERSION,
        "software": f"vtoladapt {__version__}",
        "units_note": "Table I units: throttle u in percent, forces per unit flight mass (m/s^2), "
                      "alpha in rad; coefficients refer to reference.air_density_kgpm3",
        "parameters": params,
        "covariance": {"names": list(fitted), "matrix": cov.tolist()},
        "noise": noise,
        "diagnostics": diagnostics,
        "priors": m.problem.prior_text,
        "fixed": {k: float(v) for k, v in fit.fixed.items()},
        "not_identified": dict(fit.not_identified),
        "data": {
            "path": None if data_path is None else str(data_path),
            "sha256": None if data_path is None else file_sha256(data_path),
            "n_rows": td.n_rows, "n_observations": 3 * td.n_rows,
            "n_rows_wing_on": int(np.sum(td.data.wing_on)),
            "n_rows_side_force": int(td.side_rows.size),
        },
        "reference": {"vehicle": td.vehicle_name, "mass_kg": td.mass_kg,
                      "wing_area_m2": td.wing_area_m2, "air_density_kgpm3": td.rho_ref_kgpm3},
    }
    if spec is not None and spec.id != "paper":
        d = {**{k: d[k] for k in ("format", "format_version", "software")}, "basis": spec.id,
             "basis_names": list(spec.names), **{k: v for k, v in d.items() if k not in ("format", "format_version",
                                                                                          "software")}}
    if truth_theta_table is not None:
        truth_names = theta_names if len(truth_theta_table) == len(theta_names) else PARAMETER_NAMES
        truth = dict(zip(truth_names, np.asarray(truth_theta_table, float)))
        if truth_k is not None:
            truth["k1"], truth["k2"] = truth_k
        d["truth_check"] = {n: {"truth": float(t), "z": (params[n]["mean"] - t) / params[n]["std"]
                                if params[n]["std"] > 0 else None}
                            for n, t in truth.items()}
    return d


__all__ = ["ControllerPrior", "POSTERIOR_FORMAT", "POSTERIOR_NAMES", "POSTERIOR_VERSION", "Posterior",
           "PosteriorError", "apply_posterior", "basis_of", "controller_prior", "load_posterior",
           "parameter_units", "posterior_dict_from_fit", "posterior_from_dict", "vehicle_with_posterior", "write_posterior"]
