"""Composite adaptation (eq:prediction_error, eq:th_adapt, eq:P_adapt), projection and Lyapunov function.

The adaptation kernel is driven directly with synthetic regressors and a known truth,
``a_m = W theta``, so the limits are known in closed form.
"""
from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from scipy.integrate import solve_ivp
from scipy.optimize import minimize

from vtoladapt import forces
from vtoladapt.control import adaptation as ad
from vtoladapt.control.kernel import default_theta_bounds

DT = 0.004
N = 8


def _excitation(vehicle, n):
    """``n`` regressors over a rich, periodic set of operating points (all 8 columns excited)."""
    t = np.arange(n) / n * 2 * np.pi
    out = np.empty((n, 3, N))
    for k in range(n):
        V = 6.0 + 4.0 * np.sin(t[k])
        alpha = 0.2 * np.sin(3 * t[k] + 0.3)
        beta = 0.3 * np.sin(2 * t[k] + 1.0)
        v_i = V * np.array([np.cos(alpha) * np.cos(beta), np.sin(beta), np.sin(alpha) * np.cos(beta)])
        u_x = 0.4 + 0.3 * np.sin(5 * t[k])
        u_z = 0.5 + 0.3 * np.sin(7 * t[k] + 0.5)
        forces.regressor(v_i, u_x, u_z, vehicle.model_kernel, out[k])
    return out


@njit(cache=True)
def _drive(mode, theta, Gamma, Ws, theta_true, a_bias, n_steps, theta0, Gamma0, P0, lower, upper, lam, sigma,
           trace_max, theta_hist):
    """Run ``n_steps`` ticks cycling through ``Ws`` with ``a_m = W theta_true + a_bias`` and v~ = 0."""
    e = np.empty(3)
    P_diag = np.empty(N)
    mats = np.empty((3, N, N))
    a_m = np.empty(3)
    R = np.eye(3)
    v_t = np.zeros(3)
    n_p = Ws.shape[0]
    worst = 0
    for k in range(n_steps):
        W = Ws[k % n_p]
        for i in range(3):
            a_m[i] = a_bias[i]
            for j in range(N):
                a_m[i] += W[i, j] * theta_true[j]
        r = ad.adaptation_step(mode, theta, Gamma, W, a_m, W, R, v_t, 0.004, theta0, Gamma0, P0, lower, upper,
                               lam, sigma, trace_max, e, P_diag, mats)
        worst = min(worst, r)
        if k >= n_steps - theta_hist.shape[0]:
            theta_hist[k - (n_steps - theta_hist.shape[0])] = theta
    return worst


def _prior(vehicle):
    th0 = vehicle.theta_scaled.copy()
    P0 = np.diag(vehicle.adaptation.P0_diag)
    lo, hi = default_theta_bounds(vehicle, th0)
    return th0, P0, np.linalg.inv(P0), lo, hi


def _spd_checks(Gamma, P0):
    assert np.array_equal(Gamma, Gamma.T)                       # exactly symmetric
    P = np.linalg.inv(Gamma)
    assert np.linalg.eigvalsh(Gamma).min() > 0.0                # P^-1, hence P, positive definite
    # P <= P0 in the Loewner order (forgetting is toward the prior)
    assert np.linalg.eigvalsh(P0 - P).min() > -1e-9 * np.abs(P0).max()
    return P


def test_persistent_excitation_converges_to_the_truth(caltech):
    th0, P0, G0, lo, hi = _prior(caltech)
    theta_true = th0 * (1 + np.array([0.1, -0.05, 0.3, 0.2, -0.3, 0.15, -0.2, 0.1]))
    assert np.all((lo < theta_true) & (theta_true < hi))
    Ws = _excitation(caltech, 400)
    Ebar = np.einsum("kij,kil->jl", Ws, Ws) / len(Ws)
    # persistently exciting; but the aerodynamic columns are nearly collinear, and with Table III's
    # P0 the slowest direction converges at min eig(P0^1/2 E P0^1/2) = 0.04 /s. A 50x larger P0
    # makes that 2 /s, so a 2-minute run shows the limit (the law, not the prior, is under test).
    P0 = 50.0 * P0
    G0 = np.linalg.inv(P0)
    S = np.sqrt(P0)
    assert np.linalg.eigvalsh(S @ Ebar @ S).min() > 1.0
    theta = th0.copy()
    Gamma = G0.copy()
    hist = np.empty((400, N))
    _drive(ad.ADAPT_COMPOSITE, theta, Gamma, Ws, theta_true, np.zeros(3), 120 * 250, th0, G0, P0, lo, hi,
           0.5, 0.0, 1e6, hist)
    np.testing.assert_allclose(theta, theta_true, rtol=1e-8)
    e = np.array([W @ theta - W @ theta_true for W in Ws])
    assert np.abs(e).max() < 1e-8                               # prediction error -> 0 (m/s^2)
    _spd_checks(Gamma, P0)


def test_sigma_modification_converges_to_the_biased_point_of_the_law(caltech):
    """With sigma > 0 the limit solves (E[W^T W] + sigma I) theta = E[W^T W] theta_true + sigma theta_0."""
    th0, P0, G0, lo, hi = _prior(caltech)
    lo, hi = th0 - 10 * np.abs(th0) - 1, th0 + 10 * np.abs(th0) + 1     # bounds out of the way
    theta_true = th0 * (1 + np.array([0.2, -0.1, 0.5, 0.3, -0.4, 0.2, -0.3, 0.2]))
    # a short period (10 ticks) so that P hardly varies within it: the discrete law's limit is then
    # the stationary point averaged over the excitation
    Ws = _excitation(caltech, 10)
    Ebar = np.einsum("kij,kil->jl", Ws, Ws) / len(Ws)
    assert np.linalg.matrix_rank(Ebar) == N
    P0 = 50.0 * P0                       # fast enough to reach the limit (see the test above)
    G0 = np.linalg.inv(P0)
    sigma = 0.02
    closed_form = np.linalg.solve(Ebar + sigma * np.eye(N), Ebar @ theta_true + sigma * th0)
    bias = np.abs(closed_form - theta_true)
    assert np.all(bias > 1e-3 * np.abs(theta_true))             # the bias is real, so the test can fail
    theta = th0.copy()
    Gamma = G0.copy()
    hist = np.empty((10 * 100, N))
    _drive(ad.ADAPT_COMPOSITE, theta, Gamma, Ws, theta_true, np.zeros(3), 400 * 250, th0, G0, P0, lo, hi, 0.5,
           sigma, 1e6, hist)
    mean = hist.mean(axis=0)
    assert np.all(np.abs(mean - closed_form) <= 0.01 * bias)
    assert np.all(np.abs(mean - theta_true) >= 0.9 * bias)     # distinguishably not the truth


@pytest.mark.parametrize("mode", [ad.ADAPT_COMPOSITE, ad.ADAPT_PCONST])
def test_sigma_limit_is_exact_for_a_constant_regressor(caltech, mode):
    """For a constant W both composite variants stop at (W^T W + sigma I)^-1 (W^T W theta + sigma theta_0),

    whatever their gain (the discretisation keeps the stationary points of the law exactly).
    """
    th0, P0, G0, lo, hi = _prior(caltech)
    P0 = 50.0 * P0                       # sigma alone moves unexcited directions at sigma * P0
    G0 = np.linalg.inv(P0)
    lo, hi = th0 - 10 * np.abs(th0) - 1, th0 + 10 * np.abs(th0) + 1
    W = np.empty((3, N))
    forces.regressor(np.array([8.0, 0.3, 1.2]), 0.35, 0.5, caltech.model_kernel, W)
    theta_true = th0 * (1 + np.array([0.2, -0.1, 0.5, 0.3, -0.4, 0.2, -0.3, 0.2]))
    sigma = 0.02
    A = W.T @ W
    closed_form = np.linalg.solve(A + sigma * np.eye(N), A @ theta_true + sigma * th0)
    theta = th0.copy()
    hist = np.empty((1, N))
    _drive(mode, theta, G0.copy(), W[None], theta_true, np.zeros(3), 400 * 250, th0, G0, P0, lo, hi, 0.5, sigma,
           1e6, hist)
    np.testing.assert_allclose(theta, closed_form, rtol=1e-8, atol=1e-12)
    assert np.abs(closed_form - theta_true).max() > 1e-3        # sigma's bias is visible


def test_covariance_bounded_spd_and_no_windup_under_a_constant_regressor(caltech):
    """Ten minutes of hover: only C_Tz is excited; P stays SPD, <= P0, and returns to P0 elsewhere."""
    th0, P0, G0, lo, hi = _prior(caltech)
    W = np.empty((3, N))
    forces.regressor(np.zeros(3), 0.0, 0.58, caltech.model_kernel, W)
    theta = th0.copy()
    Gamma = G0.copy()
    hist = np.empty((1, N))
    lam = 0.5
    # a_m 5 m/s^2 more upward than the model says: C_Tz-hat is pushed onto its upper bound
    _drive(ad.ADAPT_COMPOSITE, theta, Gamma, W[None], th0, np.array([0.3, -0.2, -5.0]), 600 * 250, th0, G0, P0,
           lo, hi, lam, 1e-4, 1e6, hist)
    P = _spd_checks(Gamma, P0)
    excited = np.zeros(N, bool)
    excited[forces.I_CTZ] = True
    np.testing.assert_allclose(np.diag(P)[~excited], np.diag(P0)[~excited], rtol=1e-9)
    # steady state of Gamma' = W^T W - lambda (Gamma - Gamma_0) along C_Tz
    expected = 1.0 / (G0[1, 1] + W[2, 1] ** 2 / lam)
    assert P[1, 1] == pytest.approx(expected, rel=1e-6)
    assert theta[forces.I_CTZ] == hi[forces.I_CTZ]
    # unexcited parameters stay at theta_0 (sigma holds them; nothing drives them)
    np.testing.assert_allclose(theta[~excited], th0[~excited], rtol=1e-12)
    # with a reachable bias the limit is the least-squares point along C_Tz (sigma-biased)
    theta = th0.copy()
    Gamma = G0.copy()
    _drive(ad.ADAPT_COMPOSITE, theta, Gamma, W[None], th0, np.array([0.0, 0.0, -2.0]), 120 * 250, th0, G0, P0,
           lo, hi, lam, 1e-4, 1e6, hist)
    w2 = W[2, 1] ** 2
    target = th0[1] - 2.0 / W[2, 1]
    assert theta[1] == pytest.approx((w2 * target + 1e-4 * th0[1]) / (w2 + 1e-4), rel=1e-6)


def test_huge_regressor_keeps_p_spd_bounded_and_theta_in_bounds(caltech, rng):
    th0, P0, G0, lo, hi = _prior(caltech)
    Ws = 1e8 * rng.normal(size=(7, 3, N))
    theta = th0.copy()
    Gamma = G0.copy()
    hist = np.empty((1, N))
    _drive(ad.ADAPT_COMPOSITE, theta, Gamma, Ws, th0 * 3.0, np.array([1e3, 0.0, -1e3]), 5000, th0, G0, P0, lo,
           hi, 0.5, 1e-4, 1e6, hist)
    assert np.all(np.isfinite(Gamma)) and np.all(np.isfinite(theta))
    _spd_checks(Gamma, P0)
    assert np.trace(Gamma - G0) <= 1e6 * (1 + 1e-12)
    assert np.all((lo <= theta) & (theta <= hi))
    for mode in (ad.ADAPT_PCONST, ad.ADAPT_TRACKING):
        theta = th0.copy()
        _drive(mode, theta, G0.copy(), Ws, th0 * 3.0, np.zeros(3), 2000, th0, G0, P0, lo, hi, 0.5, 1e-4, 1e6, hist)
        assert np.all(np.isfinite(theta)) and np.all((lo <= theta) & (theta <= hi))


def _random_spd(rng, n=N):
    A = rng.normal(size=(n, n))
    return A @ A.T + 0.1 * np.eye(n)


def test_projection_matches_a_qp_solver_and_never_helps_the_wrong_way(rng):
    lo, hi = -np.ones(N), np.ones(N)
    for trial in range(60):
        K = _random_spd(rng)
        theta = rng.uniform(-0.9, 0.9, N)
        at = rng.choice(N, size=rng.integers(1, N + 1), replace=False)
        theta[at] = np.where(rng.random(at.size) < 0.5, lo[at], hi[at])
        d0 = rng.normal(size=N)
        d = np.empty(N)
        n_act = ad.project_direction(K, d0, theta, lo, hi, d)
        assert n_act >= 0
        Kinv = np.linalg.inv(K)
        cons = []
        for i in range(N):
            if theta[i] >= hi[i]:
                cons.append({"type": "ineq", "fun": lambda x, i=i: -x[i]})
            elif theta[i] <= lo[i]:
                cons.append({"type": "ineq", "fun": lambda x, i=i: x[i]})
        sol = minimize(lambda x: (x - d0) @ Kinv @ (x - d0), d0, jac=lambda x: 2 * Kinv @ (x - d0),
                       constraints=cons, method="SLSQP", options={"ftol": 1e-14, "maxiter": 500})
        assert sol.success
        np.testing.assert_allclose(d, sol.x, atol=1e-6)
        # feasibility: no component leaves the box
        assert np.all(d[theta >= hi] <= 1e-12) and np.all(d[theta <= lo] >= -1e-12)
        # for every truth in the box, projection does not increase theta~^T K^-1 d (Lyapunov)
        for _ in range(5):
            theta_true = rng.uniform(lo, hi)
            assert (theta - theta_true) @ Kinv @ (d - d0) <= 1e-9


def test_projection_releases_a_bound_when_the_law_points_inward(caltech):
    th0, P0, G0, lo, hi = _prior(caltech)
    Ws = _excitation(caltech, 50)
    for side, truth_factor in ((hi, 1.05), (lo, 0.95)):
        theta = th0.copy()
        theta[1] = side[1]                             # C_Tz parked on a bound...
        theta_true = th0.copy()
        theta_true[1] *= truth_factor                  # ...while the data say it is near theta_0
        hist = np.empty((10, N))
        _drive(ad.ADAPT_COMPOSITE, theta, G0.copy(), Ws, theta_true, np.zeros(3), 2500, th0, G0, P0, lo, hi, 0.5,
               0.0, 1e6, hist)
        assert lo[1] < theta[1] < hi[1]
        assert theta[1] == pytest.approx(theta_true[1], rel=1e-3)


def test_information_update_is_the_exact_solution_of_its_ode(rng):
    G0 = np.linalg.inv(np.diag([200.0, 200.0, 0.1, 1.0, 5.0, 20.0, 0.1, 0.1]))
    G = G0 + _random_spd(rng)
    W = rng.normal(size=(3, N))
    WtW = W.T @ W
    lam, dt = 0.7, 0.05
    out = np.empty((N, N))
    ad.information_update(G, G0, WtW, lam, dt, out)
    sol = solve_ivp(lambda t, y: (WtW - lam * (y.reshape(N, N) - G0)).ravel(), (0, dt), G.ravel(),
                    rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out, sol.y[:, -1].reshape(N, N), rtol=1e-9, atol=1e-12)
    ad.information_update(G, G0, WtW, 0.0, dt, out)           # lambda = 0: plain integration
    np.testing.assert_allclose(out, G + dt * WtW, rtol=1e-14)


def test_lowpass_is_the_exact_first_order_step_response():
    fc, dt = 10.0, 0.004
    c = ad.lowpass_gain(fc, dt)
    y = np.zeros(1)
    for k in range(1, 51):
        ad.lowpass_update(y, np.ones(1), c)
        assert y[0] == pytest.approx(1 - np.exp(-2 * np.pi * fc * k * dt), rel=1e-12)


def test_small_linear_algebra_against_numpy(rng):
    for _ in range(20):
        A = _random_spd(rng)
        out = np.empty((N, N))
        assert ad.spd_inverse(A, out, np.empty((N, N)))
        np.testing.assert_allclose(out, np.linalg.inv(A), rtol=1e-10, atol=1e-12)
        assert np.array_equal(out, out.T)
        M = np.empty((N, N))
        ad.inverse_factor(A, M, np.empty((N, N)))
        x = rng.normal(size=N)
        y = np.empty(N)
        ad.factor_apply(M, x, y)
        np.testing.assert_allclose(y, np.linalg.solve(A, x), rtol=1e-10, atol=1e-12)
        dg = np.empty(N)
        ad.factor_diag(M, dg)
        np.testing.assert_allclose(dg, np.diag(np.linalg.inv(A)), rtol=1e-10)
    assert not ad.spd_inverse(-np.eye(N), out, np.empty((N, N)))


def test_lyapunov_function_matches_its_definition(rng):
    v = rng.normal(size=3)
    q0 = 0.9
    th, tt = rng.normal(size=N), rng.normal(size=N)
    Pinv = _random_spd(rng)
    gamma = 2.5
    expected = 0.5 * v @ v + (2 - 2 * q0) / gamma + 0.5 * (th - tt) @ Pinv @ (th - tt)
    assert ad.lyapunov_function(v, q0, th, Pinv, tt, gamma) == pytest.approx(expected, rel=1e-13)
