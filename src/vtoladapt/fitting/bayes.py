"""Bayesian regression of the force model by MCMC: the paper's Model Fitting section, Table I.

Every observation is one axis of one balance reading, per unit flight mass (m/s^2):
``y = X(phi) beta + e``, with ``beta`` the adaptation-scaled theta of the controller's force-model
basis (:mod:`vtoladapt.bases`; the paper's ``[CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1]``, eq:fThat +
eq:fAhat through the control regressor :func:`vtoladapt.forces.regressor_rows`, then any extra
columns of the basis) and ``phi`` the few parameters that do not enter linearly (``k1, k2`` of
eq:model_Fs and the noise level). A basis's extra columns are evaluated once, by its compiled
regressor at the rows' flow and throttles (with the vehicle's ``k1``, ``k2``: an extra column's
shape is not fitted), zero with the wing off where the basis marks them the wing's, and scaled
with the density like every column. This module builds that problem
(:func:`prepare_table1_data`, :func:`table1_problem`) and fits it (:func:`fit_table1`) with the
generic machinery:

* :mod:`vtoladapt.fitting.linear_gaussian`: the closed-form posterior and marginal likelihood of
  the linear part;
* :mod:`vtoladapt.fitting.sampler`: :class:`MarginalProblem`, :func:`sample_marginal` and the
  convergence diagnostics (split R-hat, autocorrelation time).

Their public names are importable from here too.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import forces
from ..bases import N_PHYSICS, BasisSpec, describe_basis, evaluate, input_rows
from ..models import THROTTLE_FULL_PCT, model_kernel_params, theta_scale
from ..vehicle import PARAMETER_NAMES, Vehicle
from .data import FitDataError, ForceBalanceData
from .linear_gaussian import closed_form_posterior, marginal_kernel, stats_from_design
from .sampler import (MarginalFit, MarginalProblem, SamplerSettings, autocorr_time, find_map,
                      mcmc_linear_regression, sample_marginal, split_rhat)
from .tunnel import regressor_for_rows

__all__ = ["MarginalFit", "MarginalProblem", "SamplerSettings", "Table1Data", "Table1Fit",
           "autocorr_time", "closed_form_posterior", "find_map", "fit_table1", "identifiability",
           "marginal_kernel", "mcmc_linear_regression", "prepare_table1_data", "sample_marginal",
           "side_force_columns", "split_rhat", "stats_from_design", "table1_problem",
           "table1_stats_kernel"]


# ----------------------------------------------------------------------------------------------
# The Table I problem
# ----------------------------------------------------------------------------------------------
@njit(cache=True)
def side_force_columns(v_i_B_rows, u_z_rows, ratio_rows, k1s, k2s, out) -> None:
    """Rotor side-force regressor entries ``(-G cos beta_bar, -G sin beta_bar) * ratio`` into
    ``out`` (W, N, 2) for W values of ``(k1, k2)``: the C_S column of
    :func:`vtoladapt.forces.regressor` (x and y rows), from the same kernels
    (:func:`~vtoladapt.forces.rotor_flow_angles`, :func:`~vtoladapt.forces.side_force_basis`).
    """
    n = v_i_B_rows.shape[0]
    for i in range(n):
        v = v_i_B_rows[i]
        V = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        alpha_disk, cb, sb = forces.rotor_flow_angles(v)
        for w in range(k1s.shape[0]):
            G = forces.side_force_basis(alpha_disk, V, u_z_rows[i], k1s[w], k2s[w]) * ratio_rows[i]
            out[w, i, 0] = -G * cb
            out[w, i, 1] = -G * sb


@njit(cache=True)
def table1_stats_kernel(base, nz, nnz, cs_pos, cs_vals, y, r, inv_m, s_abs, s_rel,
                        XtWX, XtWy, yWy, slog) -> None:
    """Weighted sufficient statistics of the Table I regression for W noise/(k1, k2) values.

    ``base`` (n, p) is the regressor without its C_S column; ``nz[i, :nnz[i]]`` lists the columns
    of observation i that can be nonzero (C_S included for side-force observations, whose values
    are ``cs_vals[w, cs_pos[i]]``). Noise: ``sigma = s_abs inv_m + s_rel r``. Exploits the
    sparsity of the regressor (a wing row has 5 nonzero columns, a rotor row 1 per axis).
    """
    W = s_abs.shape[0]
    n = y.shape[0]
    p = base.shape[1]
    x = np.empty(p)
    for w in range(W):
        for a in range(p):
            XtWy[w, a] = 0.0
            for c in range(p):
                XtWX[w, a, c] = 0.0
        yy = 0.0
        sl = 0.0
        for i in range(n):
            s = s_abs[w] * inv_m + s_rel[w] * r[i]
            wi = 1.0 / (s * s)
            sl += np.log(s)
            yy += wi * y[i] * y[i]
            k = nnz[i]
            for q in range(k):
                c = nz[i, q]
                if cs_pos[i] >= 0 and c == forces.I_CS:
                    x[q] = cs_vals[w, cs_pos[i]]
                else:
                    x[q] = base[i, c]
            for q in range(k):
                ca = nz[i, q]
                wx = wi * x[q]
                XtWy[w, ca] += wx * y[i]
                for t in range(q, k):
                    XtWX[w, ca, nz[i, t]] += wx * x[t]
        for a in range(p):
            for c in range(a + 1, p):
                v = XtWX[w, a, c] + XtWX[w, c, a]
                XtWX[w, a, c] = v
                XtWX[w, c, a] = v
        yWy[w] = yy
        slog[w] = sl


K1_BOUNDS = (0.0, 2.0)
K2_BOUNDS = (0.5 * math.pi, 10.0)
LOG10_SIGMA_ABS_BOUNDS = (-6.0, 1.0)
SIGMA_REL_BOUNDS = (0.0, 0.5)
TABLE1_PARAM_NAMES = ("k1", "k2", "log10_sigma_abs_N", "sigma_rel")

#: Prior standard deviation of each coefficient, adaptation scaling (throttle as a fraction).
#: Zero-mean and two orders of magnitude wider than any plausible value: the data decide.
DEFAULT_PRIOR_SD_SCALED = {"CTx": 1000.0, "CTz": 1000.0, "CS": 100.0, "CD0": 100.0, "CD1": 100.0,
                           "CD2": 100.0, "CL0": 100.0, "CL1": 100.0}
EXTRA_PRIOR_SD_SCALED = 100.0
"""Prior standard deviation of a basis's extra column (adaptation scaling), zero-mean, unless
``prior_sd_scaled`` names it: as wide as the aerodynamic coefficients'."""


@dataclass(frozen=True, eq=False)
class Table1Data:
    """Force-balance data prepared for the Table I regression (everything per unit flight mass)."""

    data: ForceBalanceData
    mass_kg: float
    wing_area_m2: float
    rho_ref_kgpm3: float
    aero_scale_ref_per_m: float
    stall_angle_deg: float     # the wing's attached-flow range (forces module notes)
    v_i_B: np.ndarray
    u_x: np.ndarray
    u_z: np.ndarray
    rho_ratio: np.ndarray
    Phi_base: np.ndarray        # (N, 3, p), the C_S column is recomputed for each (k1, k2)
    side_rows: np.ndarray       # indices of rows where G can be nonzero
    y_B: np.ndarray             # (N, 3) m/s^2
    vehicle_name: str
    basis: BasisSpec | None = None   # the force-model basis fitted (None: the paper's)

    @property
    def n_rows(self) -> int:
        """Number of balance readings."""
        return self.data.n_rows

    @property
    def names(self) -> tuple[str, ...]:
        """The fitted coefficients' names (the basis's)."""
        return PARAMETER_NAMES if self.basis is None else self.basis.names

    def regressor(self, k1: float, k2: float) -> np.ndarray:
        """The full regressor (N, 3, p) at ``(k1, k2)``: :func:`forces.regressor_rows` for the paper's columns,
        then the basis's extra columns (which do not depend on k1, k2)."""
        Phi = regressor_for_rows(self.v_i_B, self.u_x, self.u_z, self.data.wing_on,
                                 self.data.density(self.rho_ref_kgpm3), self.rho_ref_kgpm3,
                                 self.aero_scale_ref_per_m, k1, k2, self.stall_angle_deg)
        if self.Phi_base.shape[2] > N_PHYSICS:
            Phi = np.concatenate([Phi, self.Phi_base[:, :, N_PHYSICS:]], axis=2)
        return Phi


def prepare_table1_data(data: ForceBalanceData, vehicle: Vehicle, *,
                        mass_kg: float | None = None, wing_area_m2: float | None = None,
                        rho_ref_kgpm3: float | None = None, basis: BasisSpec | None = None) -> Table1Data:
    """Turn force-balance data into the per-unit-mass regression of the force model (eq:fThat + eq:fAhat,
    and any extra columns of the basis: ``basis``, default the vehicle's).

    The flight mass is ``mass_kg``, else the file's ``mass_kg`` column, else the vehicle's mass;
    the wing area and the reference density (to which the coefficients refer) default to the
    vehicle's.
    """
    spec = describe_basis(vehicle) if basis is None else basis
    m = float(mass_kg or data.mass_kg or vehicle.mass.mass_kg)
    S = float(wing_area_m2 or vehicle.geometry.wing_area_m2)
    rho_ref = float(rho_ref_kgpm3 or vehicle.envelope.air_density_kgpm3)
    for name, v in (("mass_kg", m), ("wing_area_m2", S), ("rho_ref_kgpm3", rho_ref)):
        if not (math.isfinite(v) and v > 0):
            raise FitDataError(f"{data.source}: {name} = {v!r}: must be > 0")
    scale = 0.5 * rho_ref * S / m
    v_i_B = np.ascontiguousarray(data.v_i_B)
    u_x = data.throttle_x_pct / THROTTLE_FULL_PCT
    u_z = data.throttle_z_pct / THROTTLE_FULL_PCT
    rho = data.density(rho_ref)
    stall = vehicle.envelope.stall_angle_deg
    Phi = regressor_for_rows(v_i_B, u_x, u_z, data.wing_on, rho, rho_ref, scale, 1.0, 2.0, stall)
    if spec.n > N_PHYSICS:
        # the basis's extra columns at the rows' flow (reference density) and throttles, the vehicle's k1, k2
        model = model_kernel_params(scale, vehicle.force_model.k1, vehicle.force_model.k2, stall)
        extra = evaluate(spec, input_rows(v_i_B, u_x, u_z, model))[:, :, N_PHYSICS:]
        wing = np.asarray(spec.wing[N_PHYSICS:])
        extra[np.ix_(~np.asarray(data.wing_on, bool), np.arange(3), np.flatnonzero(wing))] = 0.0
        extra *= (rho / rho_ref)[:, None, None]
        Phi = np.concatenate([Phi, extra], axis=2)
    Phi[:, :, forces.I_CS] = 0.0
    side = np.nonzero((u_z > 0) & (data.airspeed_mps > 0)
                      & (np.hypot(v_i_B[:, 0], v_i_B[:, 1]) > 0))[0]
    return Table1Data(data=data, mass_kg=m, wing_area_m2=S, rho_ref_kgpm3=rho_ref,
                      aero_scale_ref_per_m=scale, stall_angle_deg=stall, v_i_B=v_i_B, u_x=u_x, u_z=u_z,
                      rho_ratio=rho / rho_ref, Phi_base=Phi, side_rows=side,
                      y_B=data.force_B_N / m, vehicle_name=vehicle.name, basis=spec)


def identifiability(td: Table1Data) -> dict[str, str]:
    """Parameters the data cannot determine, with the reason (empty if all are identifiable)."""
    out = {}
    col_norm = np.abs(td.Phi_base).sum(axis=(0, 1))
    reasons = {"CTx": "no row with the pusher on (throttle_x_pct > 0)",
               "CTz": "no row with the lift rotors on (throttle_z_pct > 0)"}
    for name in ("CTx", "CTz", "CD0", "CD1", "CD2", "CL0", "CL1"):
        j = PARAMETER_NAMES.index(name)
        if col_norm[j] == 0.0:
            out[name] = reasons.get(name, "no row with the wing on and airspeed > 0")
    for j, name in enumerate(td.names[N_PHYSICS:], start=N_PHYSICS):
        if col_norm[j] == 0.0:
            out[name] = "no row gives the basis's column a value (its force is zero at every reading)"
    if td.side_rows.size == 0:
        why = "no row with the lift rotors on and airspeed > 0 (the rotor side-force sweep)"
        out.update({"CS": why, "k1": why, "k2": why})
    return out


def table1_problem(td: Table1Data, *, reading_scale: np.ndarray | None = None,
                   fixed: dict[str, float] | None = None,
                   prior_sd_scaled: dict[str, float] | None = None) -> MarginalProblem:
    """The Table I regression as a :class:`MarginalProblem`.

    Observations are the three body axes of each row, ``y = F / m`` (m/s^2). Coefficients are
    ``theta`` in the adaptation scaling. Sampled parameters: ``k1`` (uniform on (0, 2)), ``k2``
    (uniform on (pi/2, 10)), ``log10_sigma_abs_N`` (uniform on (-6, 1): log-uniform noise floor)
    and ``sigma_rel`` (uniform on (0, 0.5)). The noise of an observation is
    ``sigma = sigma_abs_N / m + sigma_rel * r`` (m/s^2), the balance's noise model, with ``r``
    the reading's size: ``reading_scale`` (N, 3) in m/s^2 if given (the fit passes a first-pass
    model prediction, so the weights do not depend on the noise of the reading itself), else the
    measured ``|y|``.

    Parameters listed in ``fixed`` (by the names above) are held at the given value.
    """
    fixed = dict(fixed or {})
    unknown = [k for k in fixed if k not in TABLE1_PARAM_NAMES]
    if unknown:
        raise ValueError(f"fixed: unknown parameter {unknown[0]!r}; allowed: {TABLE1_PARAM_NAMES}")
    if td.side_rows.size == 0:
        fixed.setdefault("k1", 1.0)
        fixed.setdefault("k2", 2.0)
    names = td.names
    p = len(names)
    sd = dict(DEFAULT_PRIOR_SD_SCALED)
    sd.update({n: EXTRA_PRIOR_SD_SCALED for n in names[N_PHYSICS:]})
    unknown_sd = [k for k in (prior_sd_scaled or {}) if k not in names]
    if unknown_sd:
        raise ValueError(f"prior_sd_scaled: unknown coefficient {unknown_sd[0]!r}; allowed: {', '.join(names)}")
    sd.update(prior_sd_scaled or {})
    prior_sd = np.array([sd[n] for n in names], float)
    free = [k for k in TABLE1_PARAM_NAMES if k not in fixed]
    bounds_all = {"k1": K1_BOUNDS, "k2": K2_BOUNDS, "log10_sigma_abs_N": LOG10_SIGMA_ABS_BOUNDS,
                  "sigma_rel": SIGMA_REL_BOUNDS}
    bounds = np.array([bounds_all[k] for k in free], float).reshape(len(free), 2)
    n = td.n_rows
    y = td.y_B.reshape(3 * n)
    r = np.abs(td.y_B if reading_scale is None else np.asarray(reading_scale, float)).reshape(3 * n)
    inv_m = 1.0 / td.mass_kg
    base = td.Phi_base.reshape(3 * n, p)
    side = td.side_rows
    v_side = np.ascontiguousarray(td.v_i_B[side])
    uz_side = np.ascontiguousarray(td.u_z[side])
    ratio_side = np.ascontiguousarray(td.rho_ratio[side])
    ix, iy = 3 * side, 3 * side + 1
    pos = {k: i for i, k in enumerate(free)}

    def value(phi, name):
        return phi[:, pos[name]] if name in pos else np.full(phi.shape[0], fixed[name])

    def design_and_sigma(phi):
        Wn = phi.shape[0]
        X = np.broadcast_to(base, (Wn, 3 * n, p)).copy()
        if side.size:
            cols = np.empty((Wn, side.size, 2))
            side_force_columns(v_side, uz_side, ratio_side,
                               np.ascontiguousarray(value(phi, "k1")),
                               np.ascontiguousarray(value(phi, "k2")), cols)
            X[:, ix, forces.I_CS] = cols[:, :, 0]
            X[:, iy, forces.I_CS] = cols[:, :, 1]
        s_abs = 10.0 ** value(phi, "log10_sigma_abs_N")
        s_rel = value(phi, "sigma_rel")
        sigma = s_abs[:, None] * inv_m + s_rel[:, None] * r[None, :]
        return X, sigma

    # Sparsity pattern: the columns of each observation that can be nonzero (sorted, so the
    # kernel fills one triangle consistently). The C_S entry of the x (y) observation of side
    # row j is cs_vals[w, 2 j] (cs_vals[w, 2 j + 1]).
    cs_pos = np.full(3 * n, -1, np.int64)
    cs_pos[ix] = 2 * np.arange(side.size)
    cs_pos[iy] = 2 * np.arange(side.size) + 1
    nzmask = base != 0.0
    nzmask[cs_pos >= 0, forces.I_CS] = True
    nnz = nzmask.sum(axis=1).astype(np.int64)
    nz = np.zeros((3 * n, p), np.int64)
    for i in np.nonzero(nnz)[0]:
        cols_i = np.nonzero(nzmask[i])[0]
        nz[i, :cols_i.size] = cols_i
    base_c = np.ascontiguousarray(base)

    def stats(phi):
        Wn = phi.shape[0]
        cols = np.zeros((Wn, side.size, 2))
        if side.size:
            side_force_columns(v_side, uz_side, ratio_side,
                               np.ascontiguousarray(value(phi, "k1")),
                               np.ascontiguousarray(value(phi, "k2")), cols)
        XtWX = np.empty((Wn, p, p))
        XtWy = np.empty((Wn, p))
        yWy = np.empty(Wn)
        slog = np.empty(Wn)
        table1_stats_kernel(base_c, nz, nnz, cs_pos, cols.reshape(Wn, 2 * side.size), y, r, inv_m,
                            np.ascontiguousarray(10.0 ** value(phi, "log10_sigma_abs_N")),
                            np.ascontiguousarray(value(phi, "sigma_rel"), dtype=float),
                            XtWX, XtWy, yWy, slog)
        return XtWX, XtWy, yWy, slog

    grids = {"k1": np.array([0.6, 1.0, 1.4, 1.8]), "k2": np.array([2.0, 3.0, 5.0, 8.0]),
             "log10_sigma_abs_N": np.array([-2.0]), "sigma_rel": np.array([0.01])}
    mesh = np.meshgrid(*[grids[k] for k in free], indexing="ij") if free else []
    starts = (np.stack([m.ravel() for m in mesh], axis=1) if free else np.zeros((1, 0)))
    prior_text = {
        "coefficients": {
            "distribution": "independent Gaussian, mean 0, on the adaptation-scaled coefficients "
                            "(throttle as a fraction; see vtoladapt.models.theta_to_scaled)",
            "sd_scaled": {k: sd[k] for k in names},
        },
        "k1": "uniform on (0, 2)" if "k1" in pos else f"fixed at {fixed['k1']}",
        "k2": "uniform on (pi/2, 10) rad" if "k2" in pos else f"fixed at {fixed['k2']}",
        "sigma_abs_N": ("log-uniform on (1e-6, 10) N" if "log10_sigma_abs_N" in pos
                        else f"fixed at {10 ** fixed['log10_sigma_abs_N']:g} N"),
        "sigma_rel": ("uniform on (0, 0.5)" if "sigma_rel" in pos
                      else f"fixed at {fixed['sigma_rel']:g}"),
        "likelihood": "each axis of each reading independent Gaussian, std = sigma_abs_N / mass "
                      "+ sigma_rel * |first-pass model prediction| (m/s^2)",
    }
    return MarginalProblem(y=y, coef_names=names, prior_mean=np.zeros(p),
                           prior_sd=prior_sd, param_names=tuple(free), param_bounds=bounds,
                           design_and_sigma=design_and_sigma, starts=starts, stats=stats,
                           prior_text=prior_text)


@dataclass(frozen=True, eq=False)
class Table1Fit:
    """A Table I fit: draws in Table I units, diagnostics, and what it was fitted to."""

    table1_data: Table1Data
    marginal: MarginalFit
    names: tuple[str, ...]          # the basis's theta names (the paper's 8 first), k1, k2, sigma_abs_N, sigma_rel
    draws: np.ndarray               # (S', W, p + 4), Table I units (throttle in percent)
    fixed: dict
    not_identified: dict
    reading_scale: np.ndarray

    def column(self, name: str) -> np.ndarray:
        """Draws of one parameter, shape (steps, walkers)."""
        return self.draws[:, :, self.names.index(name)]

    def summary(self) -> dict[str, dict]:
        """name -> mean, std, ci95, mcse, rhat, ess, tau_steps (Table I units)."""
        S2, W, _ = self.draws.shape
        rhat = split_rhat(self.draws)
        tau_draws = autocorr_time(self.draws)     # in thinned steps
        out = {}
        for j, name in enumerate(self.names):
            x = self.draws[:, :, j].ravel()
            ess = S2 * W / tau_draws[j]
            sd = float(np.std(x, ddof=1))
            out[name] = {
                "mean": float(np.mean(x)), "std": sd,
                "ci95": [float(np.quantile(x, 0.025)), float(np.quantile(x, 0.975))],
                "mcse": sd / math.sqrt(ess), "rhat": float(rhat[j]), "ess": float(ess),
                "tau_steps": float(tau_draws[j] * self.marginal.thin),
            }
        return out

    @property
    def theta_names(self) -> tuple[str, ...]:
        """The fitted coefficients' names (the basis's)."""
        return self.table1_data.names

    @property
    def theta_table_mean(self) -> np.ndarray:
        """Posterior mean of theta over all draws (the basis's p coefficients)."""
        p = len(self.theta_names)
        return self.draws[:, :, :p].reshape(-1, p).mean(axis=0)

    def scale(self, k1: float) -> np.ndarray:
        """Table-I units -> adaptation scaling of the p coefficients at ``k1``: the paper's columns' scale
        (:func:`vtoladapt.scaling.theta_scale`), then the basis's own for its extra columns."""
        spec = self.table1_data.basis
        extra = np.asarray(spec.scale[N_PHYSICS:]) if spec is not None else np.zeros(0)
        return np.concatenate([theta_scale(k1), extra])

    def prediction_B(self, theta_table: np.ndarray | None = None, k1: float | None = None,
                     k2: float | None = None) -> np.ndarray:
        """Model force per unit mass (N, 3) at given (default: posterior-mean) coefficients."""
        s = self.summary()
        k1 = s["k1"]["mean"] if k1 is None else k1
        k2 = s["k2"]["mean"] if k2 is None else k2
        th = self.theta_table_mean if theta_table is None else np.asarray(theta_table, float)
        return self.table1_data.regressor(k1, k2) @ (th * self.scale(k1))


def fit_table1(data: ForceBalanceData, vehicle: Vehicle, rng: np.random.Generator, *,
               settings: SamplerSettings | None = None, fixed: dict[str, float] | None = None,
               prior_sd_scaled: dict[str, float] | None = None, mass_kg: float | None = None,
               wing_area_m2: float | None = None, rho_ref_kgpm3: float | None = None,
               reading_scale: np.ndarray | None = None, basis: BasisSpec | None = None) -> Table1Fit:
    """Fit Table I (CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1, k1, k2), and a basis's extra columns, to
    force-balance data.

    Two passes: a MAP fit with the noise weights from the measured readings gives a model
    prediction, whose size then sets the relative part of the noise in the final MCMC (so that
    no weight depends on the noise of its own reading). Pass ``reading_scale`` to skip the first
    pass.

    Parameters
    ----------
    data : ForceBalanceData
    vehicle : Vehicle
        Wing area, flight mass and reference density unless given explicitly.
    rng : numpy.random.Generator
        The only source of randomness (walker starts, emcee's moves, conditional draws).
    settings : SamplerSettings, optional
    fixed : dict, optional
        Hold some of ``k1, k2, log10_sigma_abs_N, sigma_rel`` at given values.
    prior_sd_scaled : dict, optional
        Override prior standard deviations (adaptation scaling) by coefficient name.
    basis : BasisSpec, optional
        The force-model basis (default: the vehicle's, :func:`vtoladapt.bases.describe_basis`).
    """
    td = prepare_table1_data(data, vehicle, mass_kg=mass_kg, wing_area_m2=wing_area_m2,
                             rho_ref_kgpm3=rho_ref_kgpm3, basis=basis)
    if reading_scale is None:
        first = table1_problem(td, fixed=fixed, prior_sd_scaled=prior_sd_scaled)
        if first.param_names:
            x_map, _ = find_map(first)
        else:
            x_map = np.zeros(0)
        _, mu, _ = first.log_posterior(x_map[None, :])
        X, _ = first.design_and_sigma(x_map[None, :])
        reading_scale = np.abs(X[0] @ mu[0]).reshape(td.n_rows, 3)
    problem = table1_problem(td, reading_scale=reading_scale, fixed=fixed,
                             prior_sd_scaled=prior_sd_scaled)
    mfit = sample_marginal(problem, rng, settings)
    fixed_all = {k: v for k, v in (fixed or {}).items()}
    if td.side_rows.size == 0:
        fixed_all.setdefault("k1", 1.0)
        fixed_all.setdefault("k2", 2.0)
    S2, W, _ = mfit.coef_draws.shape

    def phi_col(name):
        if name in problem.param_names:
            return mfit.phi_draws[:, :, problem.param_names.index(name)]
        return np.full((S2, W), float(fixed_all[name]))

    k1 = phi_col("k1")
    k2 = phi_col("k2")
    extra = [np.full_like(k1, s) for s in td.basis.scale[N_PHYSICS:]]
    scale = np.stack([np.full_like(k1, THROTTLE_FULL_PCT**2), np.full_like(k1, THROTTLE_FULL_PCT**2),
                      THROTTLE_FULL_PCT**k1] + [np.ones_like(k1)] * 5 + extra, axis=-1)
    theta_table = mfit.coef_draws / scale
    draws = np.concatenate([theta_table, k1[..., None], k2[..., None],
                            (10.0 ** phi_col("log10_sigma_abs_N"))[..., None],
                            phi_col("sigma_rel")[..., None]], axis=-1)
    names = td.names + ("k1", "k2", "sigma_abs_N", "sigma_rel")
    return Table1Fit(table1_data=td, marginal=mfit, names=names, draws=draws, fixed=fixed_all,
                     not_identified=identifiability(td), reading_scale=np.asarray(reading_scale))


__all__ = ["DEFAULT_PRIOR_SD_SCALED", "MarginalFit", "MarginalProblem", "SamplerSettings",
           "Table1Data", "Table1Fit", "autocorr_time", "closed_form_posterior", "find_map",
           "fit_table1", "identifiability", "mcmc_linear_regression", "prepare_table1_data",
           "sample_marginal", "side_force_columns", "split_rhat", "table1_problem"]
