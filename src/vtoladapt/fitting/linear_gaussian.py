"""Closed-form Bayesian linear regression with known noise, and its marginal likelihood.

The building block of the Bayesian fitting (:mod:`vtoladapt.fitting.bayes`): with the noise level
and the nonlinear parameters fixed, the coefficients that enter linearly have a Gaussian
posterior in closed form and integrate out of the likelihood analytically.

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
sample of ``phi``::

    A(phi)  = S0^-1 + X^T W X,        W = diag(sigma^-2)
    b(phi)  = S0^-1 m0 + X^T W y,     mu = A^-1 b
    log p(y | phi) = -n/2 log(2 pi) - sum log sigma - 1/2 log|S0| - 1/2 log|A|
                     - 1/2 (y^T W y + m0^T S0^-1 m0 - b^T mu)
"""
from __future__ import annotations

import numpy as np
from numba import njit


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
    """A sufficient-statistics function (see :class:`~vtoladapt.fitting.sampler.MarginalProblem`) from a dense design."""
    y = np.asarray(y, float)

    def stats(phi):
        X, sigma = design_and_sigma(phi)
        w = 1.0 / sigma**2
        XwT = np.swapaxes(X * w[:, :, None], 1, 2)
        return XwT @ X, XwT @ y, (w * y * y).sum(axis=1), np.log(sigma).sum(axis=1)

    return stats
