"""Composite adaptation of the force model (eq:prediction_error, eq:th_adapt, eq:P_adapt).

All quantities are in the adaptation scaling of :mod:`vtoladapt.models` (throttle as a fraction;
``f_b = Phi theta`` in m/s^2). The kernels here are pure functions of arrays; the controller
kernel (:mod:`.kernel`) owns the state.

Filters (eq:prediction_error)
-----------------------------
``[.]_f`` is a first-order low-pass at ``f_c`` (10 Hz in the paper), discretised exactly for an
input held over the tick: ``y <- y + (1 - exp(-2 pi f_c dt)) (x - y)``. The same filter acts on
the accelerometer's specific force (body axes, what ``f_b`` predicts) and on the regressor, so
``e = W theta-hat - a_m`` compares like with like.

The covariance (eq:P_adapt), in information form
------------------------------------------------
The paper's ``P' = -P W^T W P + lambda P`` is ``(P^-1)' = W^T W - lambda P^-1``: with ``lambda > 0``
the information decays in every direction the regressor does not excite, so P grows without
bound there (covariance wind-up; hover excites almost only C_Tz). We propagate the information
matrix ``Gamma = P^-1`` with forgetting *toward the prior*:

    Gamma' = W^T W - lambda (Gamma - Gamma_0),     Gamma_0 = P_0^-1,

which is the paper's law wherever the data dominate the prior (``P << P_0``), and relaxes
unexcited directions to ``P_0`` instead of infinity. Discretised exactly for ``W`` held over the
tick (``a = exp(-lambda dt)``, ``b = (1 - a)/lambda``, ``b = dt`` at ``lambda = 0``):

    Gamma_k+1 = a Gamma_k + (1 - a) Gamma_0 + b W^T W.

This is a convex combination of SPD matrices plus a PSD one, so ``Gamma_k+1 >= Gamma_0`` is SPD by
construction (``P <= P_0``, i.e. bounded, for any input), and it is kept exactly symmetric
(upper triangle computed, mirrored). As a last guard against absurd regressors,
``trace(Gamma - Gamma_0)`` is capped (``information_trace_max``) by scaling the data part, which
keeps it PSD and bounds ``P`` below. P itself is never propagated: it is ``Gamma^-1`` from a
Cholesky factorisation (``P = L^-T L^-1``, SPD by construction).

Lyapunov argument. With ``V = ... + theta~^T Gamma theta~ / 2`` the extra term ``lambda Gamma_0``
contributes ``+lambda theta~^T Gamma_0 theta~ / 2``; together with the paper's ``-lambda Gamma``
the forgetting part of ``V'`` is ``-lambda theta~^T (Gamma - Gamma_0) theta~ / 2 <= 0`` (since
``Gamma >= Gamma_0``). It is no longer strictly negative in unexcited directions, so the decay to
the error ball there comes from the sigma term ``-sigma |theta~|^2 / 2`` (the proof's
``(lambda c_P + sigma)/2`` becomes ``sigma/2`` plus a non-negative forgetting contribution).

The parameter update (eq:th_adapt), discretised
-----------------------------------------------
``theta' = P tau``, ``tau = Phi^T R^T v~ - W^T e - sigma (theta-hat - theta_0)``. An explicit
Euler step with a constant P is unstable once ``dt * eig(P W^T W) > 2`` (at 20 m/s with Table
III's P0 it is). The step is therefore implicit in the terms linear in theta-hat:

    theta_k+1 = theta_k + dt K tau_k,
    K = Gamma_k+1^-1 = P_k+1                  (composite: Gamma_k+1 already holds b W^T W)
      = (Gamma_0 + dt W^T W)^-1               (composite_pconst)
      = P_0                                   (tracking_only: no W term)

(``Gamma_k+1`` before the trace cap), i.e. backward Euler in the prediction-error term. It is
stable for any W and dt, equals the continuous law to first order in dt, has the same stationary
points (``tau = 0``), and for the composite law is the exact recursive-least-squares update. The
sigma term stays explicit (stable while ``dt sigma lambda_max(P0) < 2``, checked when the
parameters are built), so that the composite law's gain is exactly P.

Bounds by projection
--------------------
theta-hat stays in the box ``[lower, upper]``. The step direction ``d = K tau`` is projected in
the K-metric onto the tangent cone of the box: minimise ``(d - K tau)^T K^-1 (d - K tau)`` subject to
``d_i <= 0`` at an upper bound and ``d_i >= 0`` at a lower bound. The solution is
``d = K tau - K[:, A] K[A, A]^-1 (K tau)[A]`` for the active set A, found by a primal-dual
active-set iteration (start from every bound ``K tau`` points out of; then drop a bound whose
multiplier has the wrong sign, or add the most outward-pointing bound, until neither exists):
bounds whose law points inward are released, so theta-hat
never sticks. The projection never increases ``theta~^T K^-1 d`` for any truth inside the box,
which is what the Lyapunov argument needs. A component that reaches its bound within the step is
clipped to it (the continuous trajectory would hit the bound mid-step and then slide).
"""
from __future__ import annotations

import numpy as np
from numba import njit

N_THETA = 8

ADAPT_COMPOSITE = 0
ADAPT_PCONST = 1
ADAPT_TRACKING = 2
ADAPT_NONE = 3

PROJECTION_MAX_ITER = 32


# --- small dense linear algebra (8x8, no allocation beyond small work arrays) -----------------

@njit(cache=True)
def cholesky_lower(A, n, L) -> bool:
    """Cholesky factor ``L`` (lower) of the leading ``n x n`` block of SPD ``A``; False if not PD."""
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        d = np.sqrt(s)
        L[j, j] = d
        r = 1.0 / d
        for i in range(j + 1, n):
            t = A[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t * r
        for i in range(j):
            L[i, j] = 0.0
    return True


@njit(cache=True)
def cholesky_solve(L, n, b, x) -> None:
    """Solve ``L L^T x = b`` (leading ``n`` entries) given the Cholesky factor ``L``."""
    for i in range(n):
        t = b[i]
        for k in range(i):
            t -= L[i, k] * x[k]
        x[i] = t / L[i, i]
    for i in range(n - 1, -1, -1):
        t = x[i]
        for k in range(i + 1, n):
            t -= L[k, i] * x[k]
        x[i] = t / L[i, i]


@njit(cache=True)
def inverse_factor(A, M, L) -> bool:
    """``M = L^-1`` (lower triangular) for the Cholesky factor ``L`` of SPD ``A``, so ``A^-1 = M^T M``.

    ``L`` is an ``n x n`` work array. Returns False (``M`` untouched) if ``A`` is not PD.
    """
    n = A.shape[0]
    if not cholesky_lower(A, n, L):
        return False
    for i in range(n):
        M[i, i] = 1.0 / L[i, i]
    for j in range(n):
        for i in range(j + 1, n):
            t = 0.0
            for k in range(j, i):
                t -= L[i, k] * M[k, j]
            M[i, j] = t * M[i, i]
        for i in range(j):
            M[i, j] = 0.0
    return True


@njit(cache=True)
def gram_of_factor(M, out) -> None:
    """``out = M^T M`` for lower-triangular ``M`` (exactly symmetric, PD if ``M`` is invertible)."""
    n = M.shape[0]
    for i in range(n):
        for j in range(i, n):
            t = 0.0
            for k in range(j, n):
                t += M[k, i] * M[k, j]
            out[i, j] = t
            out[j, i] = t


@njit(cache=True)
def factor_diag(M, out) -> None:
    """``diag(M^T M)`` for lower-triangular ``M`` (the diagonal of ``A^-1``)."""
    n = M.shape[0]
    for i in range(n):
        t = 0.0
        for k in range(i, n):
            t += M[k, i] * M[k, i]
        out[i] = t


@njit(cache=True)
def factor_apply(M, x, out) -> None:
    """``out = M^T (M x)`` for lower-triangular ``M`` (``A^-1 x``)."""
    n = M.shape[0]
    y = np.empty(n)
    for i in range(n):
        t = 0.0
        for k in range(i + 1):
            t += M[i, k] * x[k]
        y[i] = t
    for i in range(n):
        t = 0.0
        for k in range(i, n):
            t += M[k, i] * y[k]
        out[i] = t


@njit(cache=True)
def spd_inverse(A, Ainv, L) -> bool:
    """Inverse of SPD ``A`` via Cholesky, ``A^-1 = L^-T L^-1``: symmetric and PD by construction.

    ``L`` is an ``n x n`` work array (overwritten). Returns False (``Ainv`` untouched) if ``A`` is
    not PD.
    """
    n = A.shape[0]
    M = np.empty((n, n))
    if not inverse_factor(A, M, L):
        return False
    gram_of_factor(M, Ainv)
    return True


# --- filters and the prediction error -----------------------------------------------------------

TINY = 1e-100
"""States decaying toward zero are set to zero below this magnitude: no physical quantity here is
that small, and subnormal floats (below 2.2e-308, reached after a few thousand ticks of exponential
decay) make every operation on them about a hundred times slower."""


@njit(cache=True)
def flush_tiny(x: float) -> float:
    """``x``, or 0 if ``|x| < TINY`` (keeps decaying states out of the subnormal range)."""
    return x if abs(x) >= TINY else 0.0


@njit(cache=True)
def lowpass_update(y, x, c) -> None:
    """``y <- y + c (x - y)`` element-wise for 1-D arrays, flushing tiny values to zero."""
    for i in range(y.shape[0]):
        y[i] = flush_tiny(y[i] + c * (x[i] - y[i]))


@njit(cache=True)
def lowpass_gain(cutoff_hz: float, dt: float) -> float:
    """Gain ``c = 1 - exp(-2 pi f_c dt)`` of the exactly discretised first-order low-pass."""
    return 1.0 - np.exp(-2.0 * np.pi * cutoff_hz * dt)


@njit(cache=True)
def prediction_error(W, theta, a_m, e) -> None:
    """Prediction error ``e = W theta-hat - a_m`` (eq:prediction_error), body axes, m/s^2."""
    for i in range(3):
        t = -a_m[i]
        for j in range(W.shape[1]):
            t += W[i, j] * theta[j]
        e[i] = t


@njit(cache=True)
def gram(W, G) -> None:
    """``G = W^T W`` (n x n), exactly symmetric."""
    n = W.shape[1]
    for i in range(n):
        for j in range(i, n):
            t = 0.0
            for r in range(W.shape[0]):
                t += W[r, i] * W[r, j]
            G[i, j] = t
            G[j, i] = t


@njit(cache=True)
def information_update(Gamma, Gamma0, WtW, lam, dt, out) -> None:
    """One exact step of ``Gamma' = W^T W - lambda (Gamma - Gamma_0)`` (eq:P_adapt, information form).

    ``out = a Gamma + (1 - a) Gamma_0 + b W^T W``, ``a = exp(-lambda dt)``, ``b = (1 - a)/lambda``
    (``b = dt`` at ``lambda = 0``). ``out`` may be ``Gamma``.
    """
    n = Gamma.shape[0]
    if lam > 0.0:
        a = np.exp(-lam * dt)
        b = -np.expm1(-lam * dt) / lam
    else:
        a = 1.0
        b = dt
    for i in range(n):
        for j in range(i, n):
            v = flush_tiny(a * Gamma[i, j] + (1.0 - a) * Gamma0[i, j] + b * WtW[i, j])
            out[i, j] = v
            out[j, i] = v


@njit(cache=True)
def cap_information(Gamma, Gamma0, trace_max) -> bool:
    """Scale the data part ``Gamma - Gamma_0`` so its trace is at most ``trace_max``; True if capped."""
    n = Gamma.shape[0]
    tr = 0.0
    for i in range(n):
        tr += Gamma[i, i] - Gamma0[i, i]
    if tr <= trace_max:
        return False
    s = trace_max / tr
    for i in range(n):
        for j in range(n):
            Gamma[i, j] = Gamma0[i, j] + s * (Gamma[i, j] - Gamma0[i, j])
    return True


# --- projection ----------------------------------------------------------------------------------

@njit(cache=True)
def project_direction(K, d0, theta, lower, upper, d) -> int:
    """Project the update direction ``d0 = K tau`` onto the box's tangent cone in the K-metric.

    Parameters
    ----------
    K : (n, n) SPD gain (the metric is ``K^-1``).
    d0 : (n,) unconstrained direction.
    theta, lower, upper : (n,) current estimate and its bounds.
    d : (n,) output direction.

    Returns
    -------
    int
        Number of active bounds (0 if none); -1 if the iteration limit was reached (``d`` is then
        the last iterate, and the caller's clip keeps theta-hat inside).
    """
    n = theta.shape[0]
    any_side = False
    for i in range(n):
        d[i] = d0[i]
        tol = 1e-12 * max(1.0, upper[i] - lower[i])
        if theta[i] >= upper[i] - tol or theta[i] <= lower[i] + tol:
            any_side = True
    if not any_side:
        return 0
    side = np.zeros(n)          # +1 at the upper bound, -1 at the lower bound, 0 inside
    for i in range(n):
        tol = 1e-12 * max(1.0, upper[i] - lower[i])
        if theta[i] >= upper[i] - tol:
            side[i] = 1.0
        elif theta[i] <= lower[i] + tol:
            side[i] = -1.0
    active = np.zeros(n, dtype=np.bool_)
    idx = np.empty(n, dtype=np.int64)
    KA = np.empty((n, n))
    LA = np.empty((n, n))
    rhs = np.empty(n)
    mu = np.empty(n)
    # start from every bound the unconstrained direction leaves (usually already the answer)
    for i in range(n):
        d[i] = d0[i]
        active[i] = side[i] * d0[i] > 0.0
    for _ in range(PROJECTION_MAX_ITER):
        m = 0
        for i in range(n):
            if active[i]:
                idx[m] = i
                m += 1
        for i in range(n):
            d[i] = d0[i]
        if m > 0:
            for a in range(m):
                rhs[a] = d0[idx[a]]
                for b in range(m):
                    KA[a, b] = K[idx[a], idx[b]]
            if not cholesky_lower(KA, m, LA):
                return -1
            cholesky_solve(LA, m, rhs, mu)
            for i in range(n):
                t = 0.0
                for a in range(m):
                    t += K[i, idx[a]] * mu[a]
                d[i] -= t
            for a in range(m):
                d[idx[a]] = 0.0
            # dual feasibility: the multiplier side * mu must be >= 0
            worst = -1
            worst_val = 0.0
            for a in range(m):
                v = side[idx[a]] * mu[a]
                if v < worst_val:
                    worst_val = v
                    worst = idx[a]
            if worst >= 0:
                active[worst] = False
                continue
        # primal feasibility: no inactive bound may point outward
        worst = -1
        worst_val = 0.0
        for i in range(n):
            if side[i] != 0.0 and not active[i]:
                v = side[i] * d[i]
                if v > worst_val:
                    worst_val = v
                    worst = i
        if worst >= 0:
            active[worst] = True
            continue
        return m
    return -1


# --- the adaptation step ----------------------------------------------------------------------

@njit(cache=True)
def _at_a_bound(theta, lower, upper) -> bool:
    for i in range(theta.shape[0]):
        tol = 1e-12 * max(1.0, upper[i] - lower[i])
        if theta[i] >= upper[i] - tol or theta[i] <= lower[i] + tol:
            return True
    return False


@njit(cache=True)
def adaptation_step(mode, theta, Gamma, W, a_m, Phi, R, v_tilde_W, dt, theta0, Gamma0, P0, lower, upper,
                    lam, sigma, trace_max, e, P_diag, mats) -> int:
    """One tick of eq:th_adapt and eq:P_adapt (see the module notes), in place.

    Parameters
    ----------
    mode : ADAPT_COMPOSITE, ADAPT_PCONST, ADAPT_TRACKING or ADAPT_NONE.
    theta : (8,) theta-hat, updated in place.
    Gamma : (8, 8) information matrix ``P^-1``, updated in place (composite only).
    W : (3, 8) filtered regressor ``[Phi]_f``.
    a_m : (3,) filtered specific force, body (m/s^2).
    Phi : (3, 8) unfiltered regressor at the current airflow and the last command.
    R : (3, 3) attitude ``R_WB``.
    v_tilde_W : (3,) velocity error ``v - v_r`` (m/s, NED).
    dt : float, tick (s).
    theta0, Gamma0, P0 : prior mean, prior information ``P0^-1`` and ``P0``.
    lower, upper : bounds of theta-hat.
    lam, sigma, trace_max : forgetting (1/s), sigma-modification, information-trace cap.
    e : (3,) output: prediction error before the update (eq:prediction_error).
    P_diag : (8,) output: diagonal of P after the update (of ``P0`` for the constant-P modes).
    mats : (3, 8, 8) work arrays.

    Returns
    -------
    int
        Number of active bounds, or -1 if the projection hit its iteration limit, or -2 if the
        gain could not be formed (the update is then skipped; cannot happen for finite inputs).
    """
    n = theta.shape[0]
    prediction_error(W, theta, a_m, e)
    if mode == ADAPT_NONE:
        return 0
    work = mats[0]
    M = mats[1]
    K = mats[2]
    # tau = Phi^T R^T v~ - W^T e - sigma (theta - theta0)
    rv0 = R[0, 0] * v_tilde_W[0] + R[1, 0] * v_tilde_W[1] + R[2, 0] * v_tilde_W[2]
    rv1 = R[0, 1] * v_tilde_W[0] + R[1, 1] * v_tilde_W[1] + R[2, 1] * v_tilde_W[2]
    rv2 = R[0, 2] * v_tilde_W[0] + R[1, 2] * v_tilde_W[1] + R[2, 2] * v_tilde_W[2]
    tau = np.empty(n)
    for k in range(n):
        t = Phi[0, k] * rv0 + Phi[1, k] * rv1 + Phi[2, k] * rv2 - sigma * (theta[k] - theta0[k])
        if mode != ADAPT_TRACKING:
            t -= W[0, k] * e[0] + W[1, k] * e[1] + W[2, k] * e[2]
        tau[k] = t
    d0 = np.empty(n)
    bounded = _at_a_bound(theta, lower, upper)
    if mode == ADAPT_TRACKING:
        # K = P0
        for i in range(n):
            P_diag[i] = P0[i, i]
            t = 0.0
            for j in range(n):
                K[i, j] = P0[i, j]
                t += P0[i, j] * tau[j]
            d0[i] = t
    else:
        gram(W, work)
        if mode == ADAPT_COMPOSITE:
            # Gamma_k+1 = a Gamma_k + (1 - a) Gamma_0 + b W^T W; K = Gamma_k+1^-1 (before the cap)
            information_update(Gamma, Gamma0, work, lam, dt, Gamma)
            G = Gamma
        else:
            # backward Euler in the prediction term: K = (P0^-1 + dt W^T W)^-1
            for i in range(n):
                P_diag[i] = P0[i, i]
                for j in range(n):
                    work[i, j] = Gamma0[i, j] + dt * work[i, j]
            G = work
        if not inverse_factor(G, M, K):
            if mode == ADAPT_COMPOSITE:
                for i in range(n):
                    for j in range(n):
                        Gamma[i, j] = Gamma0[i, j]
            return -2
        factor_apply(M, tau, d0)
        if mode == ADAPT_COMPOSITE:
            factor_diag(M, P_diag)
            if cap_information(Gamma, Gamma0, trace_max):
                if inverse_factor(Gamma, K, work):
                    factor_diag(K, P_diag)
        if bounded:
            gram_of_factor(M, K)
    d = np.empty(n)
    n_active = 0
    if bounded:
        n_active = project_direction(K, d0, theta, lower, upper, d)
    else:
        for i in range(n):
            d[i] = d0[i]
    for i in range(n):
        x = flush_tiny(theta[i] + dt * d[i])
        if not np.isfinite(x):
            x = theta[i]
        theta[i] = min(max(x, lower[i]), upper[i])
    return n_active


@njit(cache=True)
def lyapunov_function(v_tilde, q0_tilde, theta_hat, P_inv, theta_true, gamma) -> float:
    """The proof's ``V = v~^T v~ / 2 + (2 - 2 q~_0)/gamma + theta~^T P^-1 theta~ / 2`` (Theorem).

    ``theta~ = theta-hat - theta``; ``theta_true`` comes from the simulator's plant (the controller
    never sees it); ``P_inv`` is the controller's information matrix (8 x 8).
    """
    V = 0.5 * (v_tilde[0] ** 2 + v_tilde[1] ** 2 + v_tilde[2] ** 2) + (2.0 - 2.0 * q0_tilde) / gamma
    n = theta_hat.shape[0]
    q = 0.0
    for i in range(n):
        di = theta_hat[i] - theta_true[i]
        for j in range(n):
            q += di * P_inv[i, j] * (theta_hat[j] - theta_true[j])
    return V + 0.5 * q


__all__ = ["ADAPT_COMPOSITE", "TINY", "factor_apply", "factor_diag", "flush_tiny", "gram_of_factor",
           "inverse_factor", "lowpass_update", "ADAPT_NONE", "ADAPT_PCONST", "ADAPT_TRACKING", "adaptation_step",
           "cap_information", "cholesky_lower", "cholesky_solve", "gram", "information_update",
           "lowpass_gain", "lyapunov_function", "prediction_error", "project_direction", "spd_inverse"]
