"""The posterior file (``posterior.json``) and how a controller starts from it.

A model-layer module: the simulator flies a scenario's ``[controller_prior] posterior`` through
:func:`apply_posterior` without reaching into the fitting, which writes these files
(:func:`vtoladapt.fitting.posterior.posterior_dict_from_fit`) and names everything here too.

File format (``format = "vtoladapt.posterior"``, ``format_version = 1``)
------------------------------------------------------------------------
A JSON object with

* ``basis`` (optional, default ``"paper"``): the force-model basis fitted (:mod:`vtoladapt.bases`)
  and ``basis_names`` (optional, default the paper's eight): its parameters, the paper's
  ``CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1`` first;
* ``parameters``: for each of the basis's names and ``k1, k2`` an object
  ``{"mean", "std", "ci95": [lo, hi], "mcse", "unit"}`` in Table I units (throttle in percent,
  forces per unit flight mass, alpha in rad);
* ``covariance``: ``{"names": [...], "matrix": [[...]]}``, the posterior covariance of those;
* ``noise``: the balance-noise estimate (``sigma_abs_N``, ``sigma_rel``), same layout;
* ``diagnostics``: split R-hat, effective sample size and autocorrelation time (steps) per
  parameter, chain length, walkers, burn-in, acceptance, ``converged`` and the criteria;
* ``priors``, ``data`` (file, sha256, rows, observations), ``reference`` (vehicle, flight mass,
  wing area, reference air density the coefficients refer to), and optionally ``truth_check``
  (z-scores against a virtual tunnel's true coefficients).

Only ``format``, ``format_version`` and ``parameters`` (the means and stds) are required by
:func:`load_posterior`; a hand-written file with just those works (the paper's basis).

From a posterior to the controller (:func:`controller_prior`)
-------------------------------------------------------------
* ``theta_0`` = the posterior means, converted to the adaptation scaling with the posterior's
  ``k1`` (:func:`vtoladapt.models.theta_to_scaled`; a basis's extra columns with its own scale);
* the theta-hat bounds are ``theta_0 -+ max(n_sigma * std, fraction * |theta_0|)`` per parameter,
  with ``std`` the posterior standard deviation (scaled the same way) and ``n_sigma``,
  ``fraction`` the vehicle's ``[adaptation] bound_sigmas`` (3) and ``bound_fraction``, cut at 0
  where physics gives the coefficient's sign: the same rule the vehicle file applies to Table I's
  std (:func:`vtoladapt.scaling.theta_bounds`), now with the fitted spread;
* ``P0`` = the basis's (the vehicle's ``[adaptation] P0_diag``, Table III, for the paper's) unless given.

A posterior flies only with the basis it was fitted in (:func:`apply_posterior` refuses another).

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
from ..vehicle import PARAMETER_NAMES, ForceModelCoefficients, ForceModelStd, Vehicle

POSTERIOR_FORMAT = "vtoladapt.posterior"
POSTERIOR_VERSION = 1
POSTERIOR_NAMES = PARAMETER_NAMES + ("k1", "k2")
"""The ten fitted quantities of the paper's basis, in the paper's order then k1, k2 (a basis with extra
columns has them after the paper's eight: :attr:`Posterior.fitted_names`)."""


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
    theta_table, std_table : numpy.ndarray, shape (p,)
        Means and standard deviations of the basis's coefficients (:attr:`names`; the paper's
        ``CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1`` first).
    k1, k2, k1_std, k2_std : float
    ci95 : dict
        name -> (lo, hi), 95 % credible interval.
    covariance : numpy.ndarray (p + 2, p + 2) or None
        Over :attr:`fitted_names`.
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
    basis: str = "paper"
    names: tuple[str, ...] = PARAMETER_NAMES

    @property
    def fitted_names(self) -> tuple[str, ...]:
        """The basis's names, then ``k1``, ``k2``."""
        return tuple(self.names) + ("k1", "k2")

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
    basis = d.get("basis", "paper")
    names = d.get("basis_names", list(PARAMETER_NAMES))
    if not (isinstance(basis, str) and basis.isidentifier()):
        raise PosteriorError(f"{source}: basis = {basis!r}: must be the id of a force-model basis")
    if (not isinstance(names, list) or not all(isinstance(n, str) and n.isidentifier() for n in names)
            or tuple(names[:len(PARAMETER_NAMES)]) != PARAMETER_NAMES or len(set(names)) != len(names)):
        raise PosteriorError(f"{source}: basis_names = {names!r:.80}: must list the basis's parameters, the "
                             f"paper's {', '.join(PARAMETER_NAMES)} first")
    fitted = tuple(names) + ("k1", "k2")
    for name in fitted:
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
            names_cov = list(c["names"])
            M = np.asarray(c["matrix"], dtype=float)
        except (KeyError, TypeError, ValueError):
            raise PosteriorError(f"{source}: covariance: must be {{'names': [...], 'matrix': [[...]]}}") from None
        if M.shape != (len(names_cov), len(names_cov)) or not np.all(np.isfinite(M)):
            raise PosteriorError(f"{source}: covariance.matrix: must be a finite "
                                 f"{len(names_cov)}x{len(names_cov)} matrix, got shape {M.shape}")
        if names_cov != list(fitted):
            idx = [names_cov.index(n) for n in fitted if n in names_cov]
            if len(idx) != len(fitted):
                raise PosteriorError(f"{source}: covariance.names: must list {list(fitted)}")
            M = M[np.ix_(idx, idx)]
        cov = M
    for key in ("diagnostics", "reference"):
        if d.get(key) is not None and not isinstance(d[key], dict):
            raise PosteriorError(f"{source}: {key} = {str(d[key])[:40]}: must be a JSON object")
    mean = np.array([params[n]["mean"] for n in names], float)
    std = np.array([params[n]["std"] for n in names], float)
    if not 0.0 < params["k1"]["mean"] < 2.0:
        raise PosteriorError(f"{source}: parameters.k1.mean = {params['k1']['mean']!r}: must be in (0, 2)")
    if not params["k2"]["mean"] > 0.5 * math.pi:
        raise PosteriorError(f"{source}: parameters.k2.mean = {params['k2']['mean']!r}: must be > pi/2")
    return Posterior(
        theta_table=mean, std_table=std, k1=float(params["k1"]["mean"]), k2=float(params["k2"]["mean"]),
        k1_std=float(params["k1"]["std"]), k2_std=float(params["k2"]["std"]),
        ci95={n: tuple(params[n]["ci95"]) if params[n].get("ci95") else None for n in fitted},
        covariance=cov, diagnostics=dict(d.get("diagnostics") or {}),
        reference=dict(d.get("reference") or {}), raw=d, source=source, basis=basis, names=tuple(names))


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


def basis_of(posterior: Posterior, vehicle: Vehicle):
    """The :class:`vtoladapt.bases.BasisSpec` a posterior was fitted in, for ``vehicle``; a PosteriorError if
    the basis is unknown or its names differ from the file's."""
    from . import describe_basis

    try:
        spec = describe_basis(vehicle, posterior.basis)
    except ConfigError as exc:
        raise PosteriorError(f"{posterior.source}: {exc}") from None
    if spec.names != tuple(posterior.names):
        raise PosteriorError(f"{posterior.source}: basis_names = {list(posterior.names)}: the {spec.id} basis has "
                             f"{list(spec.names)}")
    return spec


def controller_prior(posterior: Posterior, vehicle: Vehicle, *, P0_diag=None,
                     bound_sigmas: float | None = None, bound_fraction=None) -> ControllerPrior:
    """theta_0, P0 and theta-hat bounds from a posterior (rule in the module docstring).

    Parameters
    ----------
    posterior : Posterior
    vehicle : Vehicle
        Supplies, through the posterior's basis, P0 (Table III for the paper's) and the bound rule's
        ``bound_sigmas``, ``bound_fraction`` and signs.
    P0_diag, bound_sigmas, bound_fraction : optional
        Override the basis's values (P0 in the adaptation scaling).

    Returns
    -------
    ControllerPrior
        ``(theta_0_scaled, P0_diag_scaled, lower_bounds_scaled, upper_bounds_scaled)``, each (p,).
    """
    from . import N_PHYSICS
    from ..scaling import theta_bounds, theta_scale  # the controller's own rule, one place

    spec = basis_of(posterior, vehicle)
    p = spec.n
    n_sigma = float(spec.bound_sigmas if bound_sigmas is None else bound_sigmas)
    frac = np.asarray(spec.bound_fraction if bound_fraction is None else bound_fraction, float)
    P0 = np.asarray(spec.P0_diag if P0_diag is None else P0_diag, float)
    for name, arr in (("bound_fraction", frac), ("P0_diag", P0)):
        if arr.shape != (p,) or not np.all(np.isfinite(arr)):
            raise PosteriorError(f"controller_prior: {name} must be {p} finite numbers (the {spec.id} basis's), "
                                 f"got {arr!r}")
    if np.any(P0 <= 0):
        raise PosteriorError(f"controller_prior: P0_diag = {P0.tolist()}: every entry must be > 0")
    if np.any(frac < 0) or not (math.isfinite(n_sigma) and n_sigma >= 0):
        raise PosteriorError("controller_prior: bound_fraction and bound_sigmas must be >= 0")
    # the paper's columns scale with the posterior's own k1; a basis's extra columns with the basis's scale
    scale = np.concatenate([theta_scale(posterior.k1), np.asarray(spec.scale[N_PHYSICS:])])
    theta0 = np.asarray(posterior.theta_table, dtype=float) * scale
    std = np.asarray(posterior.std_table, dtype=float) * scale

    lower, upper = theta_bounds(theta0, std, frac, n_sigma, spec.sign)
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


def apply_posterior(vehicle: Vehicle, path: str | Path, basis: str | None = None) -> tuple[Vehicle, ControllerPrior]:
    """Load ``path`` and return the vehicle with its force model and the controller prior.

    This is what a scenario's ``[controller_prior] posterior = "path/to/posterior.json"`` means.
    ``basis`` is the basis the controller flies (default: the vehicle's); a posterior of another
    basis is refused, naming both.
    """
    post = load_posterior(path)
    flies = basis or vehicle.basis
    if post.basis != flies:
        raise PosteriorError(f"{path}: basis = {post.basis!r}: the controller flies the {flies!r} basis (its "
                             f"[controller] basis, or the vehicle's); fit with that basis or fly {post.basis!r}")
    veh = vehicle_with_posterior(vehicle, post)
    return veh, controller_prior(post, veh)


__all__ = ["ControllerPrior", "POSTERIOR_FORMAT", "POSTERIOR_NAMES", "POSTERIOR_VERSION", "Posterior",
           "PosteriorError", "apply_posterior", "basis_of", "controller_prior", "load_posterior",
           "parameter_units", "posterior_from_dict", "vehicle_with_posterior", "write_posterior"]
