"""Fits to real wind-tunnel data with the same Bayesian machinery as Table I.

Sources (the repository's ``data/`` folder or ``$VTOLADAPT_DATA_DIR``; see each folder's SOURCE.md)
----------------------------------------------------------------------------------------------------
* UIUC Propeller Data Site, volumes 1-3: J. B. Brandt, R. W. Deters, G. K. Ananda,
  O. D. Dantsker and M. S. Selig, *UIUC Propeller Database*, University of Illinois at
  Urbana-Champaign, m-selig.ae.illinois.edu/props/propDB.html (merged CSV mirror, folder
  ``uiuc-propdb/``). The paper's pusher is an APC 7x4; the database has no APC 7x4 (nor any 6x4),
  so we use the same size, the Master Airscrew GF 7x4 (``magf 7.0x4.0``, volume 1).
* TU Delft V3 kite, Open Jet Facility 2024, Re = 5e5 (Poland et al. 2025; github.com/awegroup/
  TUDELFT_V3_KITE, MIT licence), folder ``tudelft-v3-kite-windtunnel/``: C_L, C_D vs alpha.

What is fitted
--------------
* :func:`fit_uiuc_static_ct`: ``T = C_T rho n^2 D^4`` (eq:model_T) to the static (J = 0) sweep.
  The database gives C_T per RPM, not thrust; the thrust is rebuilt as ``C_T rho n^2 D^4``
  (n in rev/s, D in m, rho = 1.225 kg/m^3, which cancels) and regressed on ``rho n^2 D^4`` with a
  relative (load-cell) noise of unknown size. The check against the data's own C_T column tests
  the whole unit chain (RPM -> rev/s, inch -> m) and the fit.
* :func:`fit_uiuc_ct_of_j`: ``C_T(J) = c0 + c1 J + c2 J^2`` over the advance-ratio sweeps and the
  static points at the same speeds; :func:`pusher_thrust_ratio_model` gives the pusher's thrust
  ratio ``C_T(J) / C_T(0) = 1 + a1 J + a2 J^2`` (zero at ``J_zero``), for the plant.
* :func:`fit_tudelft_polar`: ``C_L = C_L0 + C_L1 alpha``, ``C_D = C_D0 + C_D1 alpha + C_D2 alpha^2``
  (eq:model_cl, eq:model_cd) on the linear range of the lift curve, chosen from the data
  (:func:`linear_lift_range`).
"""
from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .sampler import MarginalProblem, SamplerSettings, autocorr_time, find_map, sample_marginal, split_rhat
from .data import FitDataError

INCH_M = 0.0254
RHO_UIUC_KGPM3 = 1.225
DEFAULT_PROP = "magf 7.0x4.0"
UIUC_CITATION = ("J.B. Brandt, R.W. Deters, G.K. Ananda, O.D. Dantsker and M.S. Selig, UIUC Propeller "
                 "Database, Vols 1-3, University of Illinois at Urbana-Champaign, "
                 "m-selig.ae.illinois.edu/props/propDB.html")
TUDELFT_CITATION = ("TU Delft V3 kite wind-tunnel data (Open Jet Facility, 2024, Re 5e5), Poland et al. "
                    "2025, github.com/awegroup/TUDELFT_V3_KITE, MIT licence")
TUDELFT_ALPHA_FILE = "WindTunnel_Re5e5_alpha_sweep_beta_0_Poland2025.csv"


def default_data_dir() -> Path:
    """The data folder: ``$VTOLADAPT_DATA_DIR`` if set, else the repository's vendored ``data/``.

    The repository ships the small subsets the fits need (the UIUC 7x4 rows, the TU Delft polars),
    each with its SOURCE.md; point ``VTOLADAPT_DATA_DIR`` at a folder with the full data sets (for
    example every propeller of ``uiuc-propdb/volume*_exp.csv``) to fit anything else.
    """
    env = os.environ.get("VTOLADAPT_DATA_DIR")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[3] / "data"


def _folder(data_dir, name: str) -> Path:
    base = Path(data_dir) if data_dir is not None else default_data_dir()
    d = base / name
    if not d.is_dir():
        raise FitDataError(f"{d}: data folder not found; pass data_dir (--data-dir) or set "
                           "VTOLADAPT_DATA_DIR to the folder that holds it")
    return d


# ----------------------------------------------------------------------------------------------
# UIUC propeller data
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PropellerData:
    """All rows of one propeller: ``J``, ``rpm``, ``CT``, ``CP`` (N,), diameter in m."""

    name: str
    family: str
    blades: int
    diameter_m: float
    pitch_in: float
    J: np.ndarray
    rpm: np.ndarray
    CT: np.ndarray
    CP: np.ndarray
    source: str

    @property
    def static(self) -> np.ndarray:
        """Mask of the static points (advance ratio J = 0)."""
        return self.J == 0.0


def read_uiuc_propeller(prop_name: str = DEFAULT_PROP, data_dir=None) -> PropellerData:
    """Rows of ``prop_name`` (the ``BladeName`` column, e.g. ``"magf 7.0x4.0"``) from volumes 1-3."""
    folder = _folder(data_dir, "uiuc-propdb")
    J, N, CT, CP = [], [], [], []
    meta = None
    for vol in sorted(folder.glob("*_exp.csv")):
        with vol.open(newline="", encoding="utf-8") as fh:
            for k, row in enumerate(csv.DictReader(fh), start=2):
                if row["BladeName"].strip() != prop_name:
                    continue
                try:
                    J.append(float(row["J"]))
                    N.append(float(row["N"]))
                    CT.append(float(row["CT"]))
                    CP.append(float(row["CP"]))
                    if meta is None:
                        meta = (row["Family"], int(row["B"]), float(row["D"]), float(row["P"]), vol.name)
                except (KeyError, ValueError) as exc:
                    raise FitDataError(f"{vol}: line {k}: bad value ({exc})") from None
    if meta is None:
        raise FitDataError(f"{folder}: no propeller named {prop_name!r} (BladeName column), "
                           "e.g. 'magf 7.0x4.0'; the repository ships only that one: set "
                           "VTOLADAPT_DATA_DIR to a folder with the full uiuc-propdb/volume*_exp.csv")
    fam, B, D_in, P_in, src = meta
    return PropellerData(name=prop_name, family=fam, blades=B, diameter_m=D_in * INCH_M, pitch_in=P_in,
                         J=np.array(J), rpm=np.array(N), CT=np.array(CT), CP=np.array(CP),
                         source=str(folder / src))


def _one_noise_problem(X, y, reading, coef_names, prior_sd, noise_name, noise_bounds,
                       extra_var=None, prior_text=None) -> MarginalProblem:
    """A linear model with one sampled noise parameter: ``sigma = 10^phi * reading`` (relative,
    when ``reading`` is the size of each observation) or, with ``reading = 1``, absolute;
    ``extra_var`` (n,) adds a known variance."""
    X = np.asarray(X, float)
    y = np.asarray(y, float)
    reading = np.broadcast_to(np.asarray(reading, float), y.shape)
    ev = np.zeros_like(y) if extra_var is None else np.asarray(extra_var, float)

    def design_and_sigma(phi):
        s = 10.0 ** phi[:, 0]
        sigma = np.sqrt((s[:, None] * reading[None, :]) ** 2 + ev[None, :])
        return np.broadcast_to(X, (phi.shape[0],) + X.shape), sigma

    lo, hi = noise_bounds
    return MarginalProblem(
        y=y, coef_names=tuple(coef_names), prior_mean=np.zeros(len(coef_names)),
        prior_sd=np.asarray(prior_sd, float), param_names=(noise_name,),
        param_bounds=np.array([[lo, hi]]), design_and_sigma=design_and_sigma,
        starts=np.linspace(lo, hi, 12)[1:-1, None], prior_text=prior_text or {})


def _summ(x: np.ndarray) -> dict:
    x = np.asarray(x, float)
    flat = x.ravel()
    sd = float(np.std(flat, ddof=1))
    ess = x.shape[0] * x.shape[1] / float(autocorr_time(x)[0]) if x.ndim == 2 else float(flat.size)
    return {"mean": float(flat.mean()), "std": sd,
            "ci95": [float(np.quantile(flat, 0.025)), float(np.quantile(flat, 0.975))],
            "mcse": sd / math.sqrt(ess), "ess": ess,
            "rhat": float(split_rhat(x)[0]) if x.ndim == 2 else None}


def fit_uiuc_static_ct(prop_name: str = DEFAULT_PROP, data_dir=None,
                       rng: np.random.Generator | None = None,
                       settings: SamplerSettings | None = None) -> dict:
    """Bayesian fit of the static thrust coefficient of eq:model_T to the UIUC static sweep.

    Returns
    -------
    dict
        ``CT`` (mean, std, ci95, mcse, ess, rhat), ``noise_rel`` (relative thrust noise),
        ``column`` (mean, min, max, n of the data's own C_T column at J = 0), ``rel_diff``
        (fit minus column mean, relative), the RPM range, the RPM trend of C_T (per 1000 rpm,
        least squares) and the sources.
    """
    rng = rng or np.random.default_rng(0)
    prop = read_uiuc_propeller(prop_name, data_dir)
    st = prop.static
    if np.count_nonzero(st) < 3:
        raise FitDataError(f"{prop.source}: {prop_name!r} has fewer than 3 static (J = 0) rows")
    n_rps = prop.rpm[st] / 60.0
    x = RHO_UIUC_KGPM3 * n_rps**2 * prop.diameter_m**4           # T / C_T, N
    T = prop.CT[st] * x                                           # rebuilt thrust, N
    ct_ref = float(np.median(prop.CT[st]))
    problem = _one_noise_problem(
        x[:, None], T, ct_ref * x, ("CT",), [1.0], "log10_noise_rel", (-5.0, 0.0),
        prior_text={"CT": "Gaussian, mean 0, sd 1", "noise_rel": "log-uniform on (1e-5, 1)",
                    "likelihood": "T_i ~ N(C_T x_i, (noise_rel * median(C_T column) * x_i)^2), "
                                  "x_i = rho n_i^2 D^4"})
    fit = sample_marginal(problem, rng, settings)
    ct = _summ(fit.coef_draws[:, :, 0])
    col = prop.CT[st]
    slope = np.polyfit(prop.rpm[st] / 1000.0, col, 1)[0]
    return {
        "prop": prop_name, "family": prop.family, "blades": prop.blades,
        "diameter_m": prop.diameter_m, "pitch_in": prop.pitch_in,
        "n_static_rows": int(st.sum()),
        "rpm_range": [float(prop.rpm[st].min()), float(prop.rpm[st].max())],
        "CT": ct,
        "noise_rel": _summ(10.0 ** fit.phi_draws[:, :, 0]),
        "column": {"mean": float(col.mean()), "min": float(col.min()), "max": float(col.max()),
                   "std": float(col.std(ddof=1)), "n": int(col.size)},
        "rel_diff_to_column_mean": (ct["mean"] - float(col.mean())) / float(col.mean()),
        "CT_trend_per_1000rpm": float(slope),
        "converged": bool(fit.converged), "priors": problem.prior_text,
        "source": prop.source, "citation": UIUC_CITATION,
        "note": "UIUC gives C_T per RPM, not thrust: thrust is rebuilt as C_T rho n^2 D^4 "
                "(rho = 1.225 kg/m^3 cancels) and regressed on rho n^2 D^4",
    }


def _ct_of_j_rows(prop: PropellerData, static_margin: float = 0.05):
    dyn = ~prop.static
    if not np.any(dyn):
        raise FitDataError(f"{prop.source}: {prop.name!r} has no advance-ratio (J > 0) sweep")
    lo, hi = prop.rpm[dyn].min(), prop.rpm[dyn].max()
    st = prop.static & (prop.rpm >= (1 - static_margin) * lo) & (prop.rpm <= (1 + static_margin) * hi)
    use = dyn | st
    return use, (float(lo), float(hi))


def fit_uiuc_ct_of_j(prop_name: str = DEFAULT_PROP, data_dir=None,
                     rng: np.random.Generator | None = None,
                     settings: SamplerSettings | None = None) -> dict:
    """Bayesian fit of ``C_T(J) = c0 + c1 J + c2 J^2`` for one propeller (UIUC data).

    Fitted to all advance-ratio sweeps of the propeller together with its static (J = 0) points
    within 5 % of the sweeps' speed range, with an unknown constant noise (log-uniform on
    (1e-6, 1)) and Gaussian priors N(0, 1) on c0, c1, c2.

    Returns
    -------
    dict
        ``coefficients`` c0, c1, c2 (mean, std, ...), ``ratio_coefficients`` ``[1, a1, a2]``
        with ``a = c / c0`` (posterior-mean values at the MAP noise, deterministic),
        ``J_zero`` (where C_T = 0), ``fit_range_J`` [0, max J of the data], ``rpm_range`` of the
        sweeps, ``rms_residual``, ``n_rows``, the sources.
    """
    rng = rng or np.random.default_rng(0)
    prop = read_uiuc_propeller(prop_name, data_dir)
    use, rpm_range = _ct_of_j_rows(prop)
    J = prop.J[use]
    y = prop.CT[use]
    X = np.stack([np.ones_like(J), J, J * J], axis=1)
    problem = _one_noise_problem(
        X, y, 1.0, ("c0", "c1", "c2"), [1.0, 1.0, 1.0], "log10_noise", (-6.0, 0.0),
        prior_text={"c0, c1, c2": "Gaussian, mean 0, sd 1", "noise": "log-uniform on (1e-6, 1)",
                    "likelihood": "C_T,i ~ N(c0 + c1 J_i + c2 J_i^2, noise^2)"})
    x_map, _ = find_map(problem)
    _, mu, _ = problem.log_posterior(x_map[None, :])
    c_map = mu[0]
    fit = sample_marginal(problem, rng, settings)
    d = fit.coef_draws
    coefs = {n: _summ(d[:, :, k]) for k, n in enumerate(("c0", "c1", "c2"))}
    a = c_map / c_map[0]
    roots = np.roots([a[2], a[1], a[0]])
    real = sorted(r.real for r in roots if abs(r.imag) < 1e-12 and r.real > 0)
    J_zero = float(real[0]) if real else float("nan")
    resid = y - X @ c_map
    return {
        "prop": prop_name, "family": prop.family, "diameter_m": prop.diameter_m,
        "model": "C_T(J) = c0 + c1 J + c2 J^2",
        "coefficients": coefs,
        "coefficients_map": c_map.tolist(),
        "ratio_coefficients": a.tolist(),
        "ratio_model": "C_T(J) / C_T(0) = r0 + r1 J + r2 J^2 with r = ratio_coefficients (r0 = 1)",
        "J_zero": J_zero,
        "fit_range_J": [0.0, float(J.max())],
        "rpm_range": list(rpm_range),
        "sweep_rpms": sorted({float(r) for r in prop.rpm[~prop.static]}),
        "n_rows": int(use.sum()), "n_static_rows": int((use & prop.static).sum()),
        "rms_residual": float(np.sqrt(np.mean(resid**2))),
        "max_abs_residual": float(np.max(np.abs(resid))),
        "noise": _summ(10.0 ** fit.phi_draws[:, :, 0]),
        "converged": bool(fit.converged), "priors": problem.prior_text,
        "source": prop.source, "citation": UIUC_CITATION,
    }


@dataclass(frozen=True)
class ThrustRatioModel:
    """Pusher thrust ratio ``C_T(J) / C_T(0) = r0 + r1 J + r2 J^2`` (r0 = 1).

    Valid on ``0 <= J <= J_max_fit`` (the data's range); it reaches zero at ``J_zero``
    (windmilling beyond). Plain floats, so a plant can pass them to compiled code.
    """

    coefficients: tuple[float, float, float]
    J_zero: float
    J_max_fit: float
    prop: str
    source: str

    def ratio(self, J):
        """The thrust ratio at advance ratio ``J`` (array or float), no clipping."""
        r0, r1, r2 = self.coefficients
        J = np.asarray(J, float)
        return r0 + r1 * J + r2 * J * J


#: Stored result of ``fit_uiuc_ct_of_j("magf 7.0x4.0")`` (MAP-noise posterior means), so that a
#: plant works without the data folder; a test refits and compares.
MAGF_7X4_THRUST_RATIO = ThrustRatioModel(
    coefficients=(1.0, -0.8441911915616274, -1.1022687986955924),
    J_zero=0.6436422915730226, J_max_fit=0.781, prop=DEFAULT_PROP,
    source="UIUC propeller database vol. 1 (Brandt & Selig), magf 7.0x4.0, J sweeps at "
           "4014-6998 rpm and static points 3846-7203 rpm")


def pusher_thrust_ratio_model(prop_name: str = DEFAULT_PROP, data_dir=None,
                              refit: bool = False) -> ThrustRatioModel:
    """The pusher's thrust loss with advance ratio, ``C_T(J) / C_T(0)``, from UIUC data.

    By default the stored fit of the 7x4 (:data:`MAGF_7X4_THRUST_RATIO`); ``refit=True`` (or
    another ``prop_name``) fits :func:`fit_uiuc_ct_of_j` to the data now.
    """
    if prop_name == DEFAULT_PROP and not refit:
        return MAGF_7X4_THRUST_RATIO
    res = fit_uiuc_ct_of_j(prop_name, data_dir, settings=SamplerSettings.fast())
    return ThrustRatioModel(coefficients=tuple(float(c) for c in res["ratio_coefficients"]),
                            J_zero=res["J_zero"], J_max_fit=res["fit_range_J"][1], prop=prop_name,
                            source=f"{res['source']} ({UIUC_CITATION})")


# ----------------------------------------------------------------------------------------------
# TU Delft wing polar
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PolarData:
    """An alpha sweep: alpha (deg), CL, CD and their 95 % confidence half-widths, sorted by alpha."""

    alpha_deg: np.ndarray
    CL: np.ndarray
    CL_ci: np.ndarray
    CD: np.ndarray
    CD_ci: np.ndarray
    source: str


def read_tudelft_polar(data_dir=None) -> PolarData:
    """The TU Delft V3 kite alpha sweep at beta = 0."""
    path = _folder(data_dir, "tudelft-v3-kite-windtunnel") / TUDELFT_ALPHA_FILE
    cols = {k: [] for k in ("alpha", "CL", "CL_ci", "CD", "CD_ci")}
    with path.open(newline="", encoding="utf-8") as fh:
        for k, row in enumerate(csv.DictReader(fh), start=2):
            for c in cols:
                try:
                    v = float(row[c])
                except (KeyError, ValueError):
                    raise FitDataError(f"{path}: line {k}, column '{c}': value {row.get(c)!r} "
                                       "is not a number") from None
                cols[c].append(v)
    o = np.argsort(cols["alpha"])
    arr = {c: np.asarray(v)[o] for c, v in cols.items()}
    return PolarData(alpha_deg=arr["alpha"], CL=arr["CL"], CL_ci=arr["CL_ci"], CD=arr["CD"],
                     CD_ci=arr["CD_ci"], source=str(path))


def _line(alpha, CL):
    X = np.stack([np.ones_like(alpha), alpha], axis=1)
    c, *_ = np.linalg.lstsq(X, CL, rcond=None)
    r = CL - X @ c
    return c, math.sqrt(float(r @ r) / max(alpha.size - 2, 1))


def linear_lift_range(alpha_deg: np.ndarray, CL: np.ndarray, level: float = 0.95) -> dict:
    """Where the lift curve is linear, chosen from the data.

    Rule: start from the 4 consecutive points with the steepest least-squares lift slope
    (attached flow). Repeatedly, fit a line to the current range and compute for the next point
    below and above it the standardised prediction error
    ``z = |CL - line(alpha)| / (s sqrt(1 + h))`` (``s`` the residual standard deviation, ``h``
    the point's leverage), which is Student-t with ``n - 2`` degrees of freedom if the point
    continues the line; this is the posterior predictive of a line with flat priors and unknown
    noise. Add the neighbour with the smaller ``z`` if it lies inside the ``level`` (95 %)
    predictive interval; stop when neither does: the lift curve has left the line (stall or
    negative stall).

    Returns
    -------
    dict
        ``i0, i1`` (inclusive indices), ``alpha_range_deg``, ``steps`` (each candidate's z and
        the t quantile it was compared with).
    """
    from scipy import stats

    a = np.asarray(alpha_deg, float)
    y = np.asarray(CL, float)
    if a.size < 4:
        raise FitDataError("linear_lift_range: need at least 4 points")
    slopes = [_line(a[i:i + 4], y[i:i + 4])[0][1] for i in range(a.size - 3)]
    i0 = int(np.argmax(slopes))
    i1 = i0 + 3
    steps = []
    while True:
        xa = a[i0:i1 + 1]
        c, s = _line(xa, y[i0:i1 + 1])
        s = max(s, 1e-300)
        n = xa.size
        sxx = float(np.sum((xa - xa.mean()) ** 2))
        t_q = float(stats.t.ppf(0.5 + 0.5 * level, n - 2))
        cands = []
        for k in (i0 - 1, i1 + 1):
            if 0 <= k < a.size:
                h = 1.0 / n + (a[k] - xa.mean()) ** 2 / sxx
                z = abs(y[k] - c[0] - c[1] * a[k]) / (s * math.sqrt(1.0 + h))
                cands.append((z, k))
        steps.append({"range_deg": [float(a[i0]), float(a[i1])], "t_quantile": t_q,
                      "candidates": [{"alpha_deg": float(a[k]), "z": float(z)} for z, k in cands]})
        ok = [(z, k) for z, k in cands if z <= t_q]
        if not ok:
            break
        _, k = min(ok)
        i0, i1 = min(i0, k), max(i1, k)
    return {"i0": i0, "i1": i1, "alpha_range_deg": [float(a[i0]), float(a[i1])], "level": level,
            "steps": steps}


def fit_tudelft_polar(data_dir=None, rng: np.random.Generator | None = None,
                      settings: SamplerSettings | None = None, level: float = 0.95) -> dict:
    """Bayesian fit of eq:model_cl and eq:model_cd to the TU Delft wing on its linear range.

    Observations: C_L and C_D at each alpha of the range (alpha in rad in the model). Noise of
    each: the data's 95 % confidence half-width / 1.96, plus a model-discrepancy term of unknown
    size (one for C_L, one for C_D; log-uniform on (1e-5, 1)), added in quadrature. Gaussian
    priors N(0, 10^2) on CL0, CL1, CD0, CD1, CD2. Sampled: the two discrepancy terms (emcee);
    the five coefficients are marginalised and drawn as in the Table I fit.
    """
    rng = rng or np.random.default_rng(0)
    polar = read_tudelft_polar(data_dir)
    rr = linear_lift_range(polar.alpha_deg, polar.CL, level)
    sl = slice(rr["i0"], rr["i1"] + 1)
    a = np.radians(polar.alpha_deg[sl])
    n = a.size
    y = np.concatenate([polar.CL[sl], polar.CD[sl]])
    X = np.zeros((2 * n, 5))
    X[:n, 0] = 1.0
    X[:n, 1] = a
    X[n:, 2] = 1.0
    X[n:, 3] = a
    X[n:, 4] = a * a
    var_ci = np.concatenate([(polar.CL_ci[sl] / 1.96) ** 2, (polar.CD_ci[sl] / 1.96) ** 2])
    is_cl = np.arange(2 * n) < n

    def design_and_sigma(phi):
        sL = 10.0 ** phi[:, 0]
        sD = 10.0 ** phi[:, 1]
        s_model = np.where(is_cl[None, :], sL[:, None], sD[:, None])
        return np.broadcast_to(X, (phi.shape[0],) + X.shape), np.sqrt(var_ci[None, :] + s_model**2)

    g = np.linspace(-4.5, -0.5, 5)
    starts = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    names = ("CL0", "CL1", "CD0", "CD1", "CD2")
    problem = MarginalProblem(
        y=y, coef_names=names, prior_mean=np.zeros(5), prior_sd=np.full(5, 10.0),
        param_names=("log10_model_sd_CL", "log10_model_sd_CD"),
        param_bounds=np.array([[-5.0, 0.0], [-5.0, 0.0]]), design_and_sigma=design_and_sigma,
        starts=starts,
        prior_text={"coefficients": "independent Gaussian, mean 0, sd 10 (alpha in rad)",
                    "model_sd_CL, model_sd_CD": "log-uniform on (1e-5, 1)",
                    "likelihood": "C ~ N(model, (ci95/1.96)^2 + model_sd^2)"})
    fit = sample_marginal(problem, rng, settings)
    coefs = {nm: _summ(fit.coef_draws[:, :, k]) for k, nm in enumerate(names)}
    mean = np.array([coefs[nm]["mean"] for nm in names])
    pred = X @ mean
    return {
        "coefficients": coefs,
        "units": {"CL0": "-", "CL1": "1/rad", "CD0": "-", "CD1": "1/rad", "CD2": "1/rad^2"},
        "alpha_range_deg": rr["alpha_range_deg"],
        "range_rule": (f"start from the 4 consecutive points with the steepest lift slope; add the "
                       f"next point below or above while it lies inside the {100 * level:g} % "
                       "prediction interval (Student t, with leverage) of the range's "
                       "least-squares line"),
        "range_steps": rr["steps"],
        "alpha_used_deg": polar.alpha_deg[sl].tolist(),
        "n_points": int(n),
        "model_sd_CL": _summ(10.0 ** fit.phi_draws[:, :, 0]),
        "model_sd_CD": _summ(10.0 ** fit.phi_draws[:, :, 1]),
        "rms_residual_CL": float(np.sqrt(np.mean((polar.CL[sl] - pred[:n]) ** 2))),
        "rms_residual_CD": float(np.sqrt(np.mean((polar.CD[sl] - pred[n:]) ** 2))),
        "converged": bool(fit.converged), "rhat_max": float(np.max(fit.rhat)),
        "priors": problem.prior_text, "source": polar.source, "citation": TUDELFT_CITATION,
    }


__all__ = ["DEFAULT_PROP", "MAGF_7X4_THRUST_RATIO", "PolarData", "PropellerData", "ThrustRatioModel",
           "default_data_dir", "fit_tudelft_polar", "fit_uiuc_ct_of_j", "fit_uiuc_static_ct",
           "linear_lift_range", "pusher_thrust_ratio_model", "read_tudelft_polar",
           "read_uiuc_propeller"]
