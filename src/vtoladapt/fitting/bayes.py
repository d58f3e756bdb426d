"""Bayesian regression of the force model by MCMC (the paper's Model Fitting section, Table I).

The model
---------
Every observation is one axis of one balance reading, per unit flight mass (m/s^2):

    y = X(phi) beta + e,   e ~ N(0, diag(sigma(phi)^2)),

with ``beta`` the coefficients that enter linearly (for Table I the adaptation-scaled
``theta = [CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1]``, eq:fThat + eq:fAhat through the control
regressor :func:`vtoladapt.forces.regressor_rows`) and ``phi`` the few parameters that do not
(``k1, k2`` of eq:model_Fs and the noise level). With a Gaussian prior ``beta ~ N(m0, S0)`` the
posterior of ``beta`` given ``phi`` is Gaussian in closed form and ``beta`` integrates out of the
likelihood analytically (the marginal likelihood below), so the MCMC (emcee's affine-invariant
ensemble with the differential-evolution move) runs over ``phi`` only: 2-4 dimensions instead of 12.
Joint samples of ``beta`` are then drawn exactly from ``N(mu(phi), A(phi)^-1)`` at each kept
sample of ``phi``.

    A(phi)  = S0^-1 + X^T W X,        W = diag(sigma^-2)
    b(phi)  = S0^-1 m0 + X^T W y,     mu = A^-1 b
    log p(y | phi) = -n/2 log(2 pi) - sum log sigma - 1/2 log|S0| - 1/2 log|A|
                     - 1/2 (y^T W y + m0^T S0^-1 m0 - b^T mu)

Convergence
-----------
Split R-hat (Gelman et al., BDA3 sec. 11.4) with each walker's chain split in half, and the
integrated autocorrelation time tau from :func:`emcee.autocorr.integrated_time`; the effective
sample size is ``(steps x walkers) / tau``. The sampler runs in chunks until every sampled
parameter has R-hat < ``rhat_max`` (1.01) and the chain is longer than ``tau_multiple`` (50)
autocorrelation times, or a step limit is reached (then ``converged`` is False).
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Callable

import emcee
import numpy as np
from numba import njit
from scipy import optimize

from .. import forces
from ..models import THROTTLE_FULL_PCT, theta_scale
from ..vehicle import PARAMETER_NAMES, Vehicle
from .data import FitDataError, ForceBalanceData
from .tunnel import regressor_for_rows

LOG_2PI = math.log(2.0 * math.pi)


# ----------------------------------------------------------------------------------------------
# Closed-form Bayesian linear regression (known noise)
# ----------------------------------------------------------------------------------------------
def closed_form_posterior(X: np.ndarray, y: np.ndarray, sigma: np.ndarray | float,
                          prior_mean: np.ndarray, prior_cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Posterior mean and covariance of ``beta`` for ``y = X beta + e``, ``e ~ N(0, diag(sigma^2))``.

    The textbook result with prior ``N(prior_mean, prior_cov)``:
    ``cov = (S0^-1 + X^T W X)^-1``, ``mean = cov (S0^-1 m0 + X^T W y)``.
    """
    X = np.atleast_2d(np.asarray(X, float))
    y = np.asarray(y, float)
    w = np.broadcast_to(1.0 / np.asarray(sigma, float) ** 2, y.shape)
    S0_inv = np.linalg.inv(np.asarray(prior_cov, float))
    A = S0_inv + X.T @ (X * w[:, None])
    cov = np.linalg.inv(A)
    cov = 0.5 * (cov + cov.T)
    mean = cov @ (S0_inv @ np.asarray(prior_mean, float) + X.T @ (w * y))
    return mean, cov


@njit(cache=True)
def marginal_kernel(XtWX, XtWy, yWy, sum_log_sigma, n_obs, m0, S0_inv_diag, logdet_S0,
                    lml, mu, L) -> None:
    """Log marginal likelihood, conditional mean and chol(A) for W parameter values, in place.

    ``A = S0^-1 + X^T W X = L L^T``, ``b = S0^-1 m0 + X^T W y``, ``L z = b``, ``L^T mu = z``,
    ``log p(y) = -n/2 log 2 pi - sum log sigma - 1/2 log|S0| - log|L| - 1/2 (y^T W y
    + m0^T S0^-1 m0 - |z|^2)``. A walker whose A is not positive definite gets ``-inf``.
    """
    Wn, p = XtWy.shape
    z = np.empty(p)
    b = np.empty(p)
    m0Sm0 = 0.0
    for a in range(p):
        m0Sm0 += S0_inv_diag[a] * m0[a] * m0[a]
    for w in range(Wn):
        ok = np.isfinite(yWy[w]) and np.isfinite(sum_log_sigma[w])
        # Cholesky of A, lower triangle of L[w]
        for i in range(p):
            for j in range(p):
                L[w, i, j] = 0.0
        for j in range(p):
            if not ok:
                break
            d = XtWX[w, j, j] + S0_inv_diag[j]
            for k in range(j):
                d -= L[w, j, k] * L[w, j, k]
            if not (d > 0.0) or not np.isfinite(d):
                ok = False
                break
            ljj = np.sqrt(d)
            L[w, j, j] = ljj
            for i in range(j + 1, p):
                v = XtWX[w, i, j]
                for k in range(j):
                    v -= L[w, i, k] * L[w, j, k]
                L[w, i, j] = v / ljj
        if not ok:
            lml[w] = -np.inf
            for a in range(p):
                mu[w, a] = np.nan
            continue
        for a in range(p):
            b[a] = XtWy[w, a] + S0_inv_diag[a] * m0[a]
        zz = 0.0
        logdet_L = 0.0
        for i in range(p):
            v = b[i]
            for k in range(i):
                v -= L[w, i, k] * z[k]
            z[i] = v / L[w, i, i]
            zz += z[i] * z[i]
            logdet_L += np.log(L[w, i, i])
        for i in range(p - 1, -1, -1):
            v = z[i]
            for k in range(i + 1, p):
                v -= L[w, k, i] * mu[w, k]
            mu[w, i] = v / L[w, i, i]
        lml[w] = (-0.5 * n_obs * np.log(2.0 * np.pi) - sum_log_sigma[w] - 0.5 * logdet_S0
                  - logdet_L - 0.5 * (yWy[w] + m0Sm0 - zz))


def _marginal_from_stats(XtWX: np.ndarray, XtWy: np.ndarray, yWy: np.ndarray,
                         sum_log_sigma: np.ndarray, n_obs: int, m0: np.ndarray,
                         S0_inv_diag: np.ndarray, logdet_S0: float, need_L: bool = False):
    """Log marginal likelihood (W,), conditional mean (W, p) and, if asked, chol(A) (W, p, p)."""
    Wn, p = XtWy.shape
    lml = np.empty(Wn)
    mu = np.empty((Wn, p))
    L = np.empty((Wn, p, p))
    marginal_kernel(np.ascontiguousarray(XtWX, dtype=float), np.ascontiguousarray(XtWy, dtype=float),
                    np.ascontiguousarray(yWy, dtype=float),
                    np.ascontiguousarray(sum_log_sigma, dtype=float), float(n_obs),
                    np.ascontiguousarray(m0, dtype=float), np.ascontiguousarray(S0_inv_diag, dtype=float),
                    float(logdet_S0), lml, mu, L)
    return lml, mu, (L if need_L else None)


def stats_from_design(design_and_sigma, y: np.ndarray):
    """A sufficient-statistics function (see :class:`MarginalProblem`) from a dense design."""
    y = np.asarray(y, float)

    def stats(phi):
        X, sigma = design_and_sigma(phi)
        w = 1.0 / sigma**2
        XwT = np.swapaxes(X * w[:, :, None], 1, 2)
        return XwT @ X, XwT @ y, (w * y * y).sum(axis=1), np.log(sigma).sum(axis=1)

    return stats


# ----------------------------------------------------------------------------------------------
# The generic problem and sampler
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class MarginalProblem:
    """A linear-Gaussian model with a few nonlinear / noise parameters (see module docstring).

    Parameters
    ----------
    y : numpy.ndarray, shape (n,)
        Observations.
    coef_names : tuple of str
        Names of the linear coefficients ``beta`` (p).
    prior_mean, prior_sd : numpy.ndarray, shape (p,)
        Independent Gaussian prior on ``beta``.
    param_names : tuple of str
        Names of the sampled parameters ``phi`` (d, may be 0).
    param_bounds : numpy.ndarray, shape (d, 2)
        Uniform prior box of ``phi`` (open interval).
    design_and_sigma : callable
        ``phi (W, d) -> (X (W, n, p), sigma (W, n))``.
    stats : callable
        ``phi (W, d) -> (X^T W X (W, p, p), X^T W y (W, p), y^T W y (W,), sum log sigma (W,))``
        with ``W = diag(sigma^-2)``: what the likelihood needs (:func:`stats_from_design`
        builds it from ``design_and_sigma``; a problem may supply a faster one).
    starts : numpy.ndarray, shape (k, d)
        Starting points of the MAP search (the best is refined).
    prior_text : dict
        Human-readable description of the priors, written to the outputs.
    """

    y: np.ndarray
    coef_names: tuple[str, ...]
    prior_mean: np.ndarray
    prior_sd: np.ndarray
    param_names: tuple[str, ...]
    param_bounds: np.ndarray
    design_and_sigma: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
    starts: np.ndarray
    stats: Callable | None = None
    prior_text: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        if self.stats is None:
            object.__setattr__(self, "stats", stats_from_design(self.design_and_sigma, self.y))

    @property
    def n_obs(self) -> int:
        return int(self.y.shape[0])

    def in_bounds(self, phi: np.ndarray) -> np.ndarray:
        phi = np.atleast_2d(phi)
        lo, hi = self.param_bounds[:, 0], self.param_bounds[:, 1]
        return np.all((phi > lo) & (phi < hi), axis=1)

    def log_posterior(self, phi: np.ndarray, need_L: bool = False):
        """``log p(phi | y)`` up to a constant (W,), with the conditional means (and chol(A))."""
        phi = np.atleast_2d(np.asarray(phi, float))
        W = phi.shape[0]
        lp = np.full(W, -np.inf)
        mu = np.full((W, len(self.coef_names)), np.nan)
        L = np.full((W, len(self.coef_names), len(self.coef_names)), np.nan) if need_L else None
        inside = self.in_bounds(phi) if phi.shape[1] else np.ones(W, bool)
        if not np.any(inside):
            return lp, mu, L
        XtWX, XtWy, yWy, slog = self.stats(phi[inside])
        S0_inv_diag = 1.0 / self.prior_sd**2
        logdet_S0 = float(np.sum(np.log(self.prior_sd**2)))
        lml, mu_in, L_in = _marginal_from_stats(XtWX, XtWy, yWy, slog, self.n_obs, self.prior_mean,
                                                S0_inv_diag, logdet_S0, need_L)
        lp[inside] = lml
        mu[inside] = mu_in
        if need_L:
            L[inside] = L_in
        lp[~np.isfinite(lp)] = -np.inf
        return lp, mu, L


def split_rhat(chains: np.ndarray) -> np.ndarray:
    """Split R-hat (BDA3 sec. 11.4) of ``chains`` shaped (steps, chains[, k]) -> (k,).

    Each chain is split into halves; with ``n`` steps per half, ``W`` the mean within-half
    variance and ``B/n`` the variance of the half means, ``R = sqrt(((n-1)/n W + B/n) / W)``.
    """
    x = np.asarray(chains, float)
    if x.ndim == 2:
        x = x[:, :, None]
    n = x.shape[0] // 2
    if n < 2:
        return np.full(x.shape[2], np.nan)
    halves = np.concatenate([x[:n], x[x.shape[0] - n:]], axis=1)    # (n, 2C, k)
    means = halves.mean(axis=0)
    within = halves.var(axis=0, ddof=1).mean(axis=0)
    between_over_n = means.var(axis=0, ddof=1)
    var_plus = (n - 1) / n * within + between_over_n
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.sqrt(var_plus / within)
    r[within == 0] = 1.0
    return r


def autocorr_time(chains: np.ndarray) -> np.ndarray:
    """Integrated autocorrelation time (steps) of ``chains`` (steps, walkers[, k]) -> (k,).

    emcee's estimator (``integrated_time`` with ``c = 5``, ``tol = 0``: no error if the chain
    is short; compare the result with the chain length yourself).
    """
    x = np.asarray(chains, float)
    if x.ndim == 2:
        x = x[:, :, None]
    tau = np.empty(x.shape[2])
    for j in range(x.shape[2]):
        if np.ptp(x[:, :, j]) == 0.0:
            tau[j] = 1.0
        else:
            tau[j] = float(emcee.autocorr.integrated_time(x[:, :, j], tol=0, quiet=True)[0])
    return np.maximum(tau, 1.0)


@dataclass(frozen=True, eq=False)
class SamplerSettings:
    """MCMC settings (defaults give a converged Table I fit in about ten seconds)."""

    n_walkers: int = 16
    n_burn: int = 300
    min_steps: int = 1000
    max_steps: int = 20000
    chunk_steps: int = 500
    tau_multiple: float = 50.0
    rhat_max: float = 1.01
    max_draw_steps: int = 500
    time_limit_s: float | None = None

    @staticmethod
    def fast() -> "SamplerSettings":
        """Short settings for smoke tests (not converged by the criteria above)."""
        return SamplerSettings(n_walkers=12, n_burn=100, min_steps=200, max_steps=200,
                               chunk_steps=200, max_draw_steps=100)


@dataclass(frozen=True, eq=False)
class MarginalFit:
    """Output of :func:`sample_marginal`.

    ``chain`` (S, W, d) holds the sampled parameters after burn-in, ``coef_draws`` (S', W, p) the
    linear coefficients drawn from their conditional posterior at every ``thin``-th step,
    ``phi_draws`` (S', W, d) the sampled parameters at the same steps.
    """

    problem: MarginalProblem
    chain: np.ndarray
    log_prob: np.ndarray
    coef_draws: np.ndarray
    phi_draws: np.ndarray
    thin: int
    map_phi: np.ndarray
    acceptance_fraction: float
    tau_steps: np.ndarray
    rhat: np.ndarray
    converged: bool
    n_burn: int
    wall_time_s: float
    n_log_prob_evaluations: int

    @property
    def n_steps(self) -> int:
        return int(self.chain.shape[0])


def _moves():
    """emcee's differential-evolution move alone.

    Not ``DESnookerMove``: in emcee 3.1.6 its direction vector is ``delta / sqrt(|delta|)``
    instead of a unit vector, so the step grows with the distance to the reference walker,
    the proposal is not symmetric and the chain is biased (a 1-D k2 posterior came out 4 Monte
    Carlo errors low against quadrature, a 4-D gamma target 5-9 errors low).
    """
    return emcee.moves.DEMove()


def _numerical_hessian(f, x, h):
    d = x.size
    H = np.empty((d, d))
    f0 = f(x)
    for i in range(d):
        for j in range(i, d):
            if i == j:
                e = np.zeros(d)
                e[i] = h[i]
                H[i, i] = (f(x + e) - 2 * f0 + f(x - e)) / h[i] ** 2
            else:
                ei = np.zeros(d)
                ej = np.zeros(d)
                ei[i] = h[i]
                ej[j] = h[j]
                H[i, j] = H[j, i] = (f(x + ei + ej) - f(x + ei - ej) - f(x - ei + ej)
                                     + f(x - ei - ej)) / (4 * h[i] * h[j])
    return H


def find_map(problem: MarginalProblem) -> tuple[np.ndarray, np.ndarray]:
    """Maximum a posteriori ``phi`` (L-BFGS-B from the best of ``problem.starts``) and an
    approximate posterior covariance from the numerical Hessian there."""
    d = len(problem.param_names)
    lo, hi = problem.param_bounds[:, 0], problem.param_bounds[:, 1]

    def neg(x):
        v = problem.log_posterior(x[None, :])[0][0]
        return -v if np.isfinite(v) else 1e300

    lp_starts = problem.log_posterior(problem.starts)[0]
    best = problem.starts[int(np.argmax(lp_starts))].astype(float)
    span = hi - lo
    # quasi-Newton in the unit box of the prior (finite-difference gradients); the chain's
    # burn-in absorbs what precision this lacks
    res = optimize.minimize(lambda u: neg(lo + span * u), (best - lo) / span, method="L-BFGS-B",
                            bounds=[(1e-9, 1.0 - 1e-9)] * d,
                            options={"ftol": 1e-13, "gtol": 1e-9, "maxiter": 1000, "eps": 1e-8})
    x = lo + span * res.x if res.fun <= neg(best) else best
    cov = None
    for rel in (1e-4, 1e-5, 1e-3):
        h = np.minimum(rel * span, 0.25 * np.minimum(x - lo, hi - x))
        if np.any(h <= 0):
            continue
        H = _numerical_hessian(neg, x, h)
        try:
            np.linalg.cholesky(H)
            cov = np.linalg.inv(H)
            break
        except np.linalg.LinAlgError:
            continue
    if cov is None:
        cov = np.diag((1e-3 * span) ** 2)
    return x, 0.5 * (cov + cov.T)


def _initial_walkers(problem, x_map, cov, n_walkers, rng):
    L = np.linalg.cholesky(cov)
    out = np.empty((n_walkers, x_map.size))
    k = 0
    tries = 0
    while k < n_walkers:
        cand = x_map + L @ rng.standard_normal(x_map.size)
        tries += 1
        if problem.in_bounds(cand)[0] or tries > 1000 * n_walkers:
            if not problem.in_bounds(cand)[0]:
                cand = np.clip(cand, problem.param_bounds[:, 0] + 1e-9, problem.param_bounds[:, 1] - 1e-9)
            out[k] = cand
            k += 1
    return out


def sample_marginal(problem: MarginalProblem, rng: np.random.Generator,
                    settings: SamplerSettings | None = None) -> MarginalFit:
    """Sample ``p(phi | y)`` with emcee and draw ``beta`` from ``p(beta | phi, y)``.

    With no sampled parameters (``d = 0``) the posterior is the closed form and the draws are
    independent (``settings.max_draw_steps x n_walkers`` of them).
    """
    settings = settings or SamplerSettings()
    t0 = time.perf_counter()
    d = len(problem.param_names)
    p = len(problem.coef_names)
    W = settings.n_walkers
    n_eval = 0
    if d == 0:
        lp, mu, L = problem.log_posterior(np.zeros((1, 0)), need_L=True)
        S = settings.max_draw_steps
        z = rng.standard_normal((S * W, p))
        dev = np.linalg.solve(np.broadcast_to(L[0].T, (S * W, p, p)), z[:, :, None])[:, :, 0]
        draws = (mu[0] + dev).reshape(S, W, p)
        chain = np.zeros((S, W, 0))
        return MarginalFit(problem, chain, np.full((S, W), lp[0]), draws, chain.copy(), 1,
                           np.zeros(0), 1.0, np.zeros(0), np.zeros(0), True, 0,
                           time.perf_counter() - t0, 1)

    x_map, cov = find_map(problem)
    p0 = _initial_walkers(problem, x_map, cov, W, rng)

    def log_prob(coords):
        nonlocal n_eval
        n_eval += coords.shape[0]
        return problem.log_posterior(coords)[0]

    moves = _moves()
    sampler = emcee.EnsembleSampler(W, d, log_prob, vectorize=True, moves=moves)
    state = emcee.State(p0, random_state=np.random.RandomState(
        int(rng.integers(2**32 - 1))).get_state())
    state = sampler.run_mcmc(state, settings.n_burn, progress=False, skip_initial_state_check=True)
    sampler.reset()
    converged = False
    steps = 0
    tau = np.full(d, np.inf)
    rhat = np.full(d, np.inf)
    while True:
        n_more = settings.chunk_steps if steps >= settings.min_steps else max(
            settings.chunk_steps, settings.min_steps - steps)
        n_more = min(n_more, settings.max_steps - steps)
        if n_more > 0:
            state = sampler.run_mcmc(state, n_more, progress=False, skip_initial_state_check=True)
            steps += n_more
        chain = sampler.get_chain()
        tau = autocorr_time(chain)
        rhat = split_rhat(chain)
        converged = bool(np.all(rhat < settings.rhat_max) and steps > settings.tau_multiple * tau.max())
        out_of_time = (settings.time_limit_s is not None
                       and time.perf_counter() - t0 > settings.time_limit_s)
        if (converged and steps >= settings.min_steps) or steps >= settings.max_steps or out_of_time:
            break
    chain = sampler.get_chain()
    log_prob_chain = sampler.get_log_prob()
    thin = max(1, int(math.ceil(chain.shape[0] / settings.max_draw_steps)))
    phi_draws = chain[::thin]
    S2 = phi_draws.shape[0]
    flat = phi_draws.reshape(S2 * W, d)
    coef = np.empty((S2 * W, p))
    for start in range(0, flat.shape[0], 2048):
        sl = slice(start, start + 2048)
        _, mu, L = problem.log_posterior(flat[sl], need_L=True)
        z = rng.standard_normal(mu.shape)
        coef[sl] = mu + np.linalg.solve(np.swapaxes(L, 1, 2), z[:, :, None])[:, :, 0]
    return MarginalFit(
        problem=problem, chain=chain, log_prob=log_prob_chain, coef_draws=coef.reshape(S2, W, p),
        phi_draws=phi_draws, thin=thin, map_phi=x_map,
        acceptance_fraction=float(np.mean(sampler.acceptance_fraction)), tau_steps=tau, rhat=rhat,
        converged=converged, n_burn=settings.n_burn, wall_time_s=time.perf_counter() - t0,
        n_log_prob_evaluations=n_eval)


# ----------------------------------------------------------------------------------------------
# Plain MCMC of a linear regression (all coefficients sampled): the check of the machinery
# ----------------------------------------------------------------------------------------------
def mcmc_linear_regression(X: np.ndarray, y: np.ndarray, sigma: np.ndarray | float,
                           prior_mean: np.ndarray, prior_cov: np.ndarray, rng: np.random.Generator,
                           n_walkers: int = 32, n_burn: int = 500, n_steps: int = 4000):
    """Sample ``p(beta | y)`` of a Gaussian linear regression with known noise directly with emcee.

    The same ensemble moves and diagnostics as :func:`sample_marginal`, here on every
    coefficient, so the result can be compared with :func:`closed_form_posterior`.

    Returns
    -------
    chain : numpy.ndarray, shape (n_steps, n_walkers, p)
    tau : numpy.ndarray, shape (p,)
        Integrated autocorrelation time (steps).
    rhat : numpy.ndarray, shape (p,)
    """
    X = np.atleast_2d(np.asarray(X, float))
    y = np.asarray(y, float)
    w = np.broadcast_to(1.0 / np.asarray(sigma, float) ** 2, y.shape)
    m0 = np.asarray(prior_mean, float)
    P0 = np.linalg.inv(np.asarray(prior_cov, float))
    p = X.shape[1]

    def log_prob(B):
        r = y[None, :] - B @ X.T
        dm = B - m0
        return -0.5 * np.sum(w * r * r, axis=1) - 0.5 * np.einsum("wi,ij,wj->w", dm, P0, dm)

    mean0, cov0 = closed_form_posterior(X, y, sigma, m0, prior_cov)
    # a deliberately over-dispersed start (3x the posterior spread), so burn-in is exercised
    p0 = mean0 + 3.0 * rng.standard_normal((n_walkers, p)) @ np.linalg.cholesky(cov0).T
    moves = _moves()
    sampler = emcee.EnsembleSampler(n_walkers, p, log_prob, vectorize=True, moves=moves)
    state = emcee.State(p0, random_state=np.random.RandomState(
        int(rng.integers(2**32 - 1))).get_state())
    state = sampler.run_mcmc(state, n_burn, progress=False)
    sampler.reset()
    sampler.run_mcmc(state, n_steps, progress=False)
    chain = sampler.get_chain()
    return chain, autocorr_time(chain), split_rhat(chain)


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

    ``base`` (n, 8) is the regressor without its C_S column; ``nz[i, :nnz[i]]`` lists the columns
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


@dataclass(frozen=True, eq=False)
class Table1Data:
    """Force-balance data prepared for the Table I regression (everything per unit flight mass)."""

    data: ForceBalanceData
    mass_kg: float
    wing_area_m2: float
    rho_ref_kgpm3: float
    aero_scale_ref_per_m: float
    v_i_B: np.ndarray
    u_x: np.ndarray
    u_z: np.ndarray
    rho_ratio: np.ndarray
    Phi_base: np.ndarray        # (N, 3, 8), the C_S column is recomputed for each (k1, k2)
    side_rows: np.ndarray       # indices of rows where G can be nonzero
    y_B: np.ndarray             # (N, 3) m/s^2
    vehicle_name: str

    @property
    def n_rows(self) -> int:
        return self.data.n_rows

    def regressor(self, k1: float, k2: float) -> np.ndarray:
        """The full regressor (N, 3, 8) at ``(k1, k2)``, straight from :func:`forces.regressor_rows`."""
        return regressor_for_rows(self.v_i_B, self.u_x, self.u_z, self.data.wing_on,
                                  self.data.density(self.rho_ref_kgpm3), self.rho_ref_kgpm3,
                                  self.aero_scale_ref_per_m, k1, k2)


def prepare_table1_data(data: ForceBalanceData, vehicle: Vehicle, *,
                        mass_kg: float | None = None, wing_area_m2: float | None = None,
                        rho_ref_kgpm3: float | None = None) -> Table1Data:
    """Turn force-balance data into the per-unit-mass regression of eq:fThat + eq:fAhat.

    The flight mass is ``mass_kg``, else the file's ``mass_kg`` column, else the vehicle's mass;
    the wing area and the reference density (to which the coefficients refer) default to the
    vehicle's.
    """
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
    Phi = regressor_for_rows(v_i_B, u_x, u_z, data.wing_on, rho, rho_ref, scale, 1.0, 2.0)
    Phi[:, :, forces.I_CS] = 0.0
    side = np.nonzero((u_z > 0) & (data.airspeed_mps > 0)
                      & (np.hypot(v_i_B[:, 0], v_i_B[:, 1]) > 0))[0]
    return Table1Data(data=data, mass_kg=m, wing_area_m2=S, rho_ref_kgpm3=rho_ref,
                      aero_scale_ref_per_m=scale, v_i_B=v_i_B, u_x=u_x, u_z=u_z,
                      rho_ratio=rho / rho_ref, Phi_base=Phi, side_rows=side,
                      y_B=data.force_B_N / m, vehicle_name=vehicle.name)


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
    sd = dict(DEFAULT_PRIOR_SD_SCALED)
    sd.update(prior_sd_scaled or {})
    prior_sd = np.array([sd[n] for n in PARAMETER_NAMES], float)
    free = [k for k in TABLE1_PARAM_NAMES if k not in fixed]
    bounds_all = {"k1": K1_BOUNDS, "k2": K2_BOUNDS, "log10_sigma_abs_N": LOG10_SIGMA_ABS_BOUNDS,
                  "sigma_rel": SIGMA_REL_BOUNDS}
    bounds = np.array([bounds_all[k] for k in free], float).reshape(len(free), 2)
    n = td.n_rows
    y = td.y_B.reshape(3 * n)
    r = np.abs(td.y_B if reading_scale is None else np.asarray(reading_scale, float)).reshape(3 * n)
    inv_m = 1.0 / td.mass_kg
    base = td.Phi_base.reshape(3 * n, 8)
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
        X = np.broadcast_to(base, (Wn, 3 * n, 8)).copy()
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
    nz = np.zeros((3 * n, 8), np.int64)
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
        XtWX = np.empty((Wn, 8, 8))
        XtWy = np.empty((Wn, 8))
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
            "sd_scaled": {k: sd[k] for k in PARAMETER_NAMES},
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
    return MarginalProblem(y=y, coef_names=PARAMETER_NAMES, prior_mean=np.zeros(8),
                           prior_sd=prior_sd, param_names=tuple(free), param_bounds=bounds,
                           design_and_sigma=design_and_sigma, starts=starts, stats=stats,
                           prior_text=prior_text)


@dataclass(frozen=True, eq=False)
class Table1Fit:
    """A Table I fit: draws in Table I units, diagnostics, and what it was fitted to."""

    table1_data: Table1Data
    marginal: MarginalFit
    names: tuple[str, ...]          # the 8 theta names, k1, k2, sigma_abs_N, sigma_rel
    draws: np.ndarray               # (S', W, 12), Table I units (throttle in percent)
    fixed: dict
    not_identified: dict
    reading_scale: np.ndarray

    def column(self, name: str) -> np.ndarray:
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
    def theta_table_mean(self) -> np.ndarray:
        return self.draws[:, :, :8].reshape(-1, 8).mean(axis=0)

    def prediction_B(self, theta_table: np.ndarray | None = None, k1: float | None = None,
                     k2: float | None = None) -> np.ndarray:
        """Model force per unit mass (N, 3) at given (default: posterior-mean) coefficients."""
        s = self.summary()
        k1 = s["k1"]["mean"] if k1 is None else k1
        k2 = s["k2"]["mean"] if k2 is None else k2
        th = self.theta_table_mean if theta_table is None else np.asarray(theta_table, float)
        return self.table1_data.regressor(k1, k2) @ (th * theta_scale(k1))


def fit_table1(data: ForceBalanceData, vehicle: Vehicle, rng: np.random.Generator, *,
               settings: SamplerSettings | None = None, fixed: dict[str, float] | None = None,
               prior_sd_scaled: dict[str, float] | None = None, mass_kg: float | None = None,
               wing_area_m2: float | None = None, rho_ref_kgpm3: float | None = None,
               reading_scale: np.ndarray | None = None) -> Table1Fit:
    """Fit Table I (CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1, k1, k2) to force-balance data.

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
    """
    td = prepare_table1_data(data, vehicle, mass_kg=mass_kg, wing_area_m2=wing_area_m2,
                             rho_ref_kgpm3=rho_ref_kgpm3)
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
    scale = np.stack([np.full_like(k1, THROTTLE_FULL_PCT**2), np.full_like(k1, THROTTLE_FULL_PCT**2),
                      THROTTLE_FULL_PCT**k1] + [np.ones_like(k1)] * 5, axis=-1)
    theta_table = mfit.coef_draws / scale
    draws = np.concatenate([theta_table, k1[..., None], k2[..., None],
                            (10.0 ** phi_col("log10_sigma_abs_N"))[..., None],
                            phi_col("sigma_rel")[..., None]], axis=-1)
    names = PARAMETER_NAMES + ("k1", "k2", "sigma_abs_N", "sigma_rel")
    return Table1Fit(table1_data=td, marginal=mfit, names=names, draws=draws, fixed=fixed_all,
                     not_identified=identifiability(td), reading_scale=np.asarray(reading_scale))


__all__ = ["DEFAULT_PRIOR_SD_SCALED", "MarginalFit", "MarginalProblem", "SamplerSettings",
           "Table1Data", "Table1Fit", "autocorr_time", "closed_form_posterior", "find_map",
           "fit_table1", "identifiability", "mcmc_linear_regression", "prepare_table1_data",
           "sample_marginal", "side_force_columns", "split_rhat", "table1_problem"]
