"""The posterior file (``posterior.json``) and how a controller starts from it.

File format (``format = "vtoladapt.posterior"``, ``format_version = 1``)
-----------------------------------------------------------------------
A JSON object with

* ``parameters``: for each of ``CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1, k1, k2`` an object
  ``{"mean", "std", "ci95": [lo, hi], "mcse", "unit"}`` in Table I units (throttle in percent,
  forces per unit flight mass, alpha in rad);
* ``covariance``: ``{"names": [...], "matrix": [[...]]}``, the posterior covariance of those ten;
* ``noise``: the balance-noise estimate (``sigma_abs_N``, ``sigma_rel``), same layout;
* ``diagnostics``: split R-hat, effective sample size and autocorrelation time (steps) per
  parameter, chain length, walkers, burn-in, acceptance, ``converged`` and the criteria;
* ``priors``, ``data`` (file, sha256, rows, observations), ``reference`` (vehicle, flight mass,
  wing area, reference air density the coefficients refer to), and optionally ``truth_check``
  (z-scores against a virtual tunnel's true coefficients).

Only ``format``, ``format_version`` and ``parameters`` (the ten means and stds) are required by
:func:`load_posterior`; a hand-written file with just those works.

From a posterior to the controller (:func:`controller_prior`)
-------------------------------------------------------------
* ``theta_0`` = the posterior means, converted to the adaptation scaling with the posterior's
  ``k1`` (:func:`vtoladapt.models.theta_to_scaled`);
* the theta-hat bounds are ``theta_0 -+ max(n_sigma * std, fraction * |theta_0|)`` per parameter,
  with ``std`` the posterior standard deviation (scaled the same way) and ``n_sigma``,
  ``fraction`` the vehicle's ``[adaptation] bound_sigmas`` (3) and ``bound_fraction``, cut at 0
  where physics gives the coefficient's sign: the same rule the vehicle file applies to Table I's
  std (:func:`vtoladapt.control.step.theta_bounds`), now with the fitted spread;
* ``P0`` = the vehicle's ``[adaptation] P0_diag`` (Table III) unless given.

Fly with a posterior by using both :func:`vehicle_with_posterior` (the controller's force model
then has the fitted k1, k2, which the C_S column of the regressor depends on) and
:func:`controller_prior`; :func:`apply_posterior` does both.
"""
from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..config import ConfigError, build
from ..models import theta_to_scaled
from ..vehicle import PARAMETER_NAMES, ForceModelCoefficients, ForceModelStd, Vehicle

POSTERIOR_FORMAT = "vtoladapt.posterior"
POSTERIOR_VERSION = 1
POSTERIOR_NAMES = PARAMETER_NAMES + ("k1", "k2")
"""The ten fitted quantities, in the paper's order then k1, k2."""


class PosteriorError(ConfigError):
    """A posterior file is invalid; the message names the file, the key and the value."""


def parameter_units() -> dict[str, str]:
    """Unit of each Table I quantity (from the vehicle file's declarations)."""
    return {f.name: f.metadata["unit"] for f in dataclasses.fields(ForceModelCoefficients)}


@dataclass(frozen=True, eq=False)
class Posterior:
    """A fitted force model: posterior means and spreads in Table I units.

    Attributes
    ----------
    theta_table, std_table : numpy.ndarray, shape (8,)
        Means and standard deviations of ``CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1``.
    k1, k2, k1_std, k2_std : float
    ci95 : dict
        name -> (lo, hi), 95 % credible interval.
    covariance : numpy.ndarray (10, 10) or None
        Over :data:`POSTERIOR_NAMES`.
    diagnostics, reference, raw : dict
        As in the file (``raw`` is the whole parsed file).
    source : str
    """

    theta_table: np.ndarray
    std_table: np.ndarray
    k1: float
    k2: float
    k1_std: float
    k2_std: float
    ci95: dict
    covariance: np.ndarray | None
    diagnostics: dict
    reference: dict
    raw: dict
    source: str = "<posterior>"

    def mean(self, name: str) -> float:
        """Posterior mean of parameter ``name`` (Table I units)."""
        return float(self.raw["parameters"][name]["mean"])

    def std(self, name: str) -> float:
        """Posterior standard deviation of parameter ``name`` (Table I units)."""
        return float(self.raw["parameters"][name]["std"])


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def posterior_from_dict(d: dict, source: str = "<posterior>") -> Posterior:
    """Validate a parsed posterior file and build a :class:`Posterior`."""
    if not isinstance(d, dict):
        raise PosteriorError(f"{source}: must be a JSON object")
    if d.get("format") != POSTERIOR_FORMAT:
        raise PosteriorError(f"{source}: format = {d.get('format')!r}: expected {POSTERIOR_FORMAT!r}")
    ver = d.get("format_version")
    if not isinstance(ver, int) or isinstance(ver, bool) or not 1 <= ver <= POSTERIOR_VERSION:
        raise PosteriorError(f"{source}: format_version = {ver!r}: this vtoladapt reads version "
                             f"1..{POSTERIOR_VERSION}")
    params = d.get("parameters")
    if not isinstance(params, dict):
        raise PosteriorError(f"{source}: missing 'parameters' object")
    for name in POSTERIOR_NAMES:
        entry = params.get(name)
        if not isinstance(entry, dict):
            raise PosteriorError(f"{source}: parameters.{name}: missing (need mean and std)")
        for key in ("mean", "std"):
            v = entry.get(key)
            if not _finite(v):
                raise PosteriorError(f"{source}: parameters.{name}.{key} = {v!r}: must be a finite number")
        if entry["std"] < 0:
            raise PosteriorError(f"{source}: parameters.{name}.std = {entry['std']!r}: must be >= 0")
        ci = entry.get("ci95")
        if ci is not None and not (isinstance(ci, list) and len(ci) == 2 and all(_finite(c) for c in ci)):
            raise PosteriorError(f"{source}: parameters.{name}.ci95 = {ci!r}: must be [lo, hi]")
    cov = None
    c = d.get("covariance")
    if c is not None:
        try:
            names = list(c["names"])
            M = np.asarray(c["matrix"], dtype=float)
        except (KeyError, TypeError, ValueError):
            raise PosteriorError(f"{source}: covariance: must be {{'names': [...], 'matrix': [[...]]}}") from None
        if M.shape != (len(names), len(names)) or not np.all(np.isfinite(M)):
            raise PosteriorError(f"{source}: covariance.matrix: must be a finite "
                                 f"{len(names)}x{len(names)} matrix, got shape {M.shape}")
        if names != list(POSTERIOR_NAMES):
            idx = [names.index(n) for n in POSTERIOR_NAMES if n in names]
            if len(idx) != len(POSTERIOR_NAMES):
                raise PosteriorError(f"{source}: covariance.names: must list {list(POSTERIOR_NAMES)}")
            M = M[np.ix_(idx, idx)]
        cov = M
    for key in ("diagnostics", "reference"):
        if d.get(key) is not None and not isinstance(d[key], dict):
            raise PosteriorError(f"{source}: {key} = {str(d[key])[:40]}: must be a JSON object")
    mean = np.array([params[n]["mean"] for n in PARAMETER_NAMES], float)
    std = np.array([params[n]["std"] for n in PARAMETER_NAMES], float)
    if not 0.0 < params["k1"]["mean"] < 2.0:
        raise PosteriorError(f"{source}: parameters.k1.mean = {params['k1']['mean']!r}: must be in (0, 2)")
    if not params["k2"]["mean"] > 0.5 * math.pi:
        raise PosteriorError(f"{source}: parameters.k2.mean = {params['k2']['mean']!r}: must be > pi/2")
    return Posterior(
        theta_table=mean, std_table=std, k1=float(params["k1"]["mean"]), k2=float(params["k2"]["mean"]),
        k1_std=float(params["k1"]["std"]), k2_std=float(params["k2"]["std"]),
        ci95={n: tuple(params[n]["ci95"]) if params[n].get("ci95") else None for n in POSTERIOR_NAMES},
        covariance=cov, diagnostics=dict(d.get("diagnostics") or {}),
        reference=dict(d.get("reference") or {}), raw=d, source=source)


def load_posterior(path: str | Path) -> Posterior:
    """Read and validate ``posterior.json``.

    Raises
    ------
    PosteriorError
        If the file is missing, not JSON, of another format or version, or lacks a mean or std.
    """
    path = Path(path)
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise PosteriorError(f"{path}: file not found") from None
    except json.JSONDecodeError as exc:
        raise PosteriorError(f"{path}: not valid JSON: {exc}") from None
    return posterior_from_dict(d, str(path))


def write_posterior(path: str | Path, d: dict) -> Path:
    """Write a posterior dict (validated first, so an unreadable file is never written)."""
    posterior_from_dict(d, str(path))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(d, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    return path


class ControllerPrior(NamedTuple):
    """What the adaptive controller starts from (all in the adaptation scaling)."""

    theta_0_scaled: np.ndarray
    P0_diag_scaled: np.ndarray
    lower_bounds_scaled: np.ndarray
    upper_bounds_scaled: np.ndarray


def controller_prior(posterior: Posterior, vehicle: Vehicle, *, P0_diag=None,
                     bound_sigmas: float | None = None, bound_fraction=None) -> ControllerPrior:
    """theta_0, P0 and theta-hat bounds from a posterior (rule in the module docstring).

    Parameters
    ----------
    posterior : Posterior
    vehicle : Vehicle
        Supplies P0 (Table III) and the bound rule's ``bound_sigmas`` and ``bound_fraction``.
    P0_diag, bound_sigmas, bound_fraction : optional
        Override the vehicle's values (P0 in the adaptation scaling).

    Returns
    -------
    ControllerPrior
        ``(theta_0_scaled, P0_diag_scaled, lower_bounds_scaled, upper_bounds_scaled)``, each (8,).
    """
    ad = vehicle.adaptation
    n_sigma = float(ad.bound_sigmas if bound_sigmas is None else bound_sigmas)
    frac = np.asarray(ad.bound_fraction if bound_fraction is None else bound_fraction, float)
    P0 = np.asarray(ad.P0_diag if P0_diag is None else P0_diag, float)
    for name, arr in (("bound_fraction", frac), ("P0_diag", P0)):
        if arr.shape != (8,) or not np.all(np.isfinite(arr)):
            raise PosteriorError(f"controller_prior: {name} must be 8 finite numbers, got {arr!r}")
    if np.any(P0 <= 0):
        raise PosteriorError(f"controller_prior: P0_diag = {P0.tolist()}: every entry must be > 0")
    if np.any(frac < 0) or not (math.isfinite(n_sigma) and n_sigma >= 0):
        raise PosteriorError("controller_prior: bound_fraction and bound_sigmas must be >= 0")
    theta0 = theta_to_scaled(posterior.theta_table, posterior.k1)
    std = theta_to_scaled(posterior.std_table, posterior.k1)
    from ..control.step import theta_bounds  # the controller's own rule, one place
    from ..vehicle import parameter_signs

    lower, upper = theta_bounds(theta0, std, frac, n_sigma, parameter_signs())
    return ControllerPrior(theta0, P0.copy(), lower, upper)


def vehicle_with_posterior(vehicle: Vehicle, posterior: Posterior) -> Vehicle:
    """A copy of ``vehicle`` whose ``force_model`` / ``force_model_std`` are the posterior's.

    Raises
    ------
    PosteriorError
        If a posterior value violates the vehicle file's limits (e.g. a negative ``CD2`` or a
        zero std of a coefficient that was held fixed in the fit).
    """
    p = posterior.raw["parameters"]
    means = {n: float(p[n]["mean"]) for n in POSTERIOR_NAMES}
    stds = {n: float(p[n]["std"]) for n in POSTERIOR_NAMES}
    try:
        fm = build(ForceModelCoefficients, means, source=posterior.source, section="parameters (mean)")
        fs = build(ForceModelStd, stds, source=posterior.source, section="parameters (std)")
    except ConfigError as exc:
        raise PosteriorError(f"cannot fly with this posterior: {exc}") from None
    return vehicle.replace(force_model=fm, force_model_std=fs,
                           description=f"{vehicle.description} [force model: {posterior.source}]")


def apply_posterior(vehicle: Vehicle, path: str | Path) -> tuple[Vehicle, ControllerPrior]:
    """Load ``path`` and return the vehicle with its force model and the controller prior.

    This is what a scenario's ``[controller] posterior = "path/to/posterior.json"`` means.
    """
    post = load_posterior(path)
    veh = vehicle_with_posterior(vehicle, post)
    return veh, controller_prior(post, veh)


def file_sha256(path: str | Path) -> str:
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def posterior_dict_from_fit(fit, *, data_path: str | Path | None = None,
                            truth_theta_table: np.ndarray | None = None,
                            truth_k: tuple[float, float] | None = None,
                            settings=None) -> dict:
    """The posterior file's content for a :class:`vtoladapt.fitting.bayes.Table1Fit`.

    ``truth_theta_table`` (8,) and ``truth_k`` = (k1, k2), when given (a virtual tunnel's
    truth), add ``truth_check`` with the z-score ``(mean - truth) / std`` of each parameter.
    """
    from .. import __version__

    s = fit.summary()
    units = parameter_units()
    td = fit.table1_data
    m = fit.marginal

    def entry(name, unit):
        e = s[name]
        return {"mean": e["mean"], "std": e["std"], "ci95": e["ci95"], "mcse": e["mcse"], "unit": unit}

    params = {n: entry(n, units[n]) for n in POSTERIOR_NAMES}
    noise = {"sigma_abs_N": entry("sigma_abs_N", "N"), "sigma_rel": entry("sigma_rel", "-")}
    idx = [fit.names.index(n) for n in POSTERIOR_NAMES]
    flat = fit.draws.reshape(-1, fit.draws.shape[2])[:, idx]
    cov = np.cov(flat, rowvar=False)
    chain_tau = dict(zip(m.problem.param_names, (float(t) for t in m.tau_steps)))
    diag_names = POSTERIOR_NAMES + ("sigma_abs_N", "sigma_rel")
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
        "covariance": {"names": list(POSTERIOR_NAMES), "matrix": cov.tolist()},
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
    if truth_theta_table is not None:
        truth = dict(zip(PARAMETER_NAMES, np.asarray(truth_theta_table, float)))
        if truth_k is not None:
            truth["k1"], truth["k2"] = truth_k
        d["truth_check"] = {n: {"truth": float(t), "z": (params[n]["mean"] - t) / params[n]["std"]
                                if params[n]["std"] > 0 else None}
                            for n, t in truth.items()}
    return d


__all__ = ["ControllerPrior", "POSTERIOR_FORMAT", "POSTERIOR_NAMES", "POSTERIOR_VERSION", "Posterior",
           "PosteriorError", "apply_posterior", "controller_prior", "load_posterior",
           "parameter_units", "posterior_dict_from_fit", "posterior_from_dict", "vehicle_with_posterior", "write_posterior"]
