"""Composite adaptation (eq:prediction_error, eq:th_adapt, eq:P_adapt), projection and Lyapunov function.

The adaptation kernel is driven directly with synthetic regressors and a known truth,
``a_m = W theta``, so the limits are known in closed form.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm
from scipy.optimize import lsq_linear, minimize

from vtoladapt import forces
from vtoladapt.control import adaptation as ad
from vtoladapt.control import linalg
from vtoladapt.control import exact_step
from vtoladapt.control.step import default_theta_bounds

DT = 0.004
N = 8
MEM = ad.memory_layout(N)
PRI = ad.prior_layout(N)
_IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def _standalone(theta, theta0, lower, upper, P0, Gamma=None, W=None, a_m=None):
    """``(at, x, prior)`` of one adaptation of N parameters (:func:`vtoladapt.control.adaptation.standalone_arrays`)."""
    at, x, prior = ad.standalone_arrays(N)
    MEM.view(x, "THETA")[:] = theta
    MEM.view(x, "GAMMA")[:] = np.linalg.inv(P0).ravel() if Gamma is None else np.asarray(Gamma).ravel()
    if W is not None:
        MEM.view(x, "W")[:] = np.asarray(W).ravel()
    if a_m is not None:
        MEM.view(x, "A_M")[:] = a_m
    prior[:] = PRI.pack(THETA0=theta0, LOWER=lower, UPPER=upper, GAMMA0=np.linalg.inv(P0).ravel(), P0=P0.ravel())
    return at, x, prior


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


def _drive(mode, theta, Gamma, Ws, theta_true, a_bias, n_steps, theta0, Gamma0, P0, lower, upper, lam, sigma,
           trace_max, theta_hist):
    """Run ``n_steps`` ticks cycling through ``Ws`` with ``a_m = W theta_true + a_bias`` and v~ = 0."""
    # the adaptation's memory and scratch in one array, the prior in another (as in the controller)
    at, x, prior = _standalone(theta, theta0, lower, upper, P0, Gamma)
    return _drive_kernel(mode, at, x, prior, theta, Gamma, Ws, theta_true, a_bias, n_steps, lam, sigma, trace_max,
                         theta_hist)


def _drive_kernel(mode, at, x, prior, theta, Gamma, Ws, theta_true, a_bias, n_steps, lam, sigma, trace_max,
                  theta_hist):
    """The ticks from Python, each one call of the package's compiled :func:`adaptation_step` (its
    cached entry, shared with every other caller of that signature). A test kernel of its own would
    compile the whole specialised adaptation into it again (two minutes per worker from a fresh clone)."""
    th, gam, wf, am = int(at[ad.AT_THETA]), int(at[ad.AT_GAMMA]), int(at[ad.AT_W]), int(at[ad.AT_A_M])
    forget_a, forget_b = ad.forgetting_weights(lam, 0.004)
    n_p = Ws.shape[0]
    flat_W = np.ascontiguousarray(Ws.reshape(n_p, 3 * N))
    a_ms = Ws @ theta_true + a_bias                      # the measured acceleration of each regressor
    step, v_t, first_kept = ad.adaptation_step, (0.0, 0.0, 0.0), n_steps - theta_hist.shape[0]
    worst = active = 0
    for k in range(n_steps):
        p = k % n_p
        x[wf:wf + 3 * N] = flat_W[p]
        x[am:am + 3] = a_ms[p]
        r, active, _ = step(mode, at, 0, x, prior, flat_W[p], 0, _IDENTITY, v_t, 0.004, forget_a, forget_b, sigma,
                            trace_max, active)
        worst = min(worst, r)
        if k >= first_kept:
            theta_hist[k - first_kept] = x[th:th + N]
    theta[:] = x[th:th + N]
    Gamma[:] = x[gam:gam + N * N].reshape(N, N)
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


@pytest.mark.slow  # 16 s; in the default suite the closed-loop tests check that the composite law learns the model
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


def _project(K, d0, theta, lo, hi, active_start):
    """project_direction on arrays: the projected direction (n_active must not be -1)."""
    m = (N // 2) ** 2
    x = np.zeros(3 * N + 2 * m + 2 * N)                 # tau, d0, d, then the projection's scratch
    x[:N] = np.linalg.solve(K, d0)                      # tau, with d0 = K tau
    x[N:2 * N] = d0
    at_upper, at_lower = ad.bound_sides(theta, 0, lo, 0, hi, 0, N)
    s = 3 * N
    n_act, active = ad.project_direction(K.ravel(), 0, np.linalg.inv(K).ravel(), 0, x, 0, N, 2 * N, s, s + m,
                                         s + 2 * m, s + 2 * m + N, at_upper, at_lower, int(active_start), N)
    assert n_act >= 0 and n_act == bin(active).count("1")
    return x[2 * N:3 * N].copy()


def test_projection_matches_a_qp_solver_and_never_helps_the_wrong_way(rng):
    lo, hi = -np.ones(N), np.ones(N)
    for trial in range(60):
        K = _random_spd(rng)
        theta = rng.uniform(-0.9, 0.9, N)
        at = rng.choice(N, size=rng.integers(1, N + 1), replace=False)
        theta[at] = np.where(rng.random(at.size) < 0.5, lo[at], hi[at])
        d0 = rng.normal(size=N)
        d = _project(K, d0, theta, lo, hi, 0)
        # the answer does not depend on where the active-set iteration starts
        for start in rng.integers(0, 1 << N, size=4):
            np.testing.assert_allclose(_project(K, d0, theta, lo, hi, start), d, rtol=1e-9, atol=1e-12)
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
    WtW_gram = np.empty(N * N)
    ad.gram(W.ravel(), 0, WtW_gram, 0, N)
    np.testing.assert_allclose(WtW_gram.reshape(N, N), WtW, rtol=1e-14)
    lam, dt = 0.7, 0.05

    def step(lam):
        out = G.ravel().copy()
        ad.information_update(out, 0, G0.ravel(), 0, WtW_gram, 0, *ad.forgetting_weights(lam, dt), N)
        return out.reshape(N, N)

    sol = solve_ivp(lambda t, y: (WtW - lam * (y.reshape(N, N) - G0)).ravel(), (0, dt), G.ravel(),
                    rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(step(lam), sol.y[:, -1].reshape(N, N), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(step(0.0), G + dt * WtW, rtol=1e-14)      # lambda = 0: plain integration
    # the paper's pure forgetting (forgetting = "paper"): Gamma' = W^T W - lambda Gamma
    paper = G.ravel().copy()
    ad.information_update(paper, 0, G0.ravel(), 0, WtW_gram, 0, *ad.forgetting_weights(lam, dt), N, 0.0)
    sol = solve_ivp(lambda t, y: (WtW - lam * y.reshape(N, N)).ravel(), (0, dt), G.ravel(), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(paper.reshape(N, N), sol.y[:, -1].reshape(N, N), rtol=1e-9, atol=1e-12)


def test_lowpass_is_the_exact_first_order_step_response():
    fc, dt = 10.0, 0.004
    c = ad.lowpass_gain(fc, dt)
    y = 0.0
    for k in range(1, 51):
        y = ad.lowpass(y, 1.0, c)
        assert y == pytest.approx(1 - np.exp(-2 * np.pi * fc * k * dt), rel=1e-12)


def test_small_linear_algebra_against_numpy(rng):
    work = np.empty(2 * N * N)
    for _ in range(20):
        A = _random_spd(rng)
        out = np.empty(N * N)
        assert linalg.spd_inverse(A.ravel(), 0, out, 0, work, 0, N)
        out = out.reshape(N, N)
        np.testing.assert_allclose(out, np.linalg.inv(A), rtol=1e-10, atol=1e-12)
        assert np.array_equal(out, out.T)
        # matrices at offsets inside larger arrays
        store = np.zeros(5 + 2 * N * N)
        store[5:5 + N * N] = A.ravel()
        assert linalg.cholesky_lower(store, 5, work, 0, N)
        linalg.inverse_factor(work, 0, store, 5 + N * N, N)
        M = store[5 + N * N:].reshape(N, N)
        np.testing.assert_allclose(M, np.linalg.inv(np.linalg.cholesky(A)), rtol=1e-10, atol=1e-12)
        L = np.empty(N * N)
        assert linalg.cholesky_lower(A.ravel(), 0, L, 0, N)
        b = rng.normal(size=N)
        x = b.copy()
        linalg.cholesky_solve(L, 0, N, x, 0)
        np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-10, atol=1e-12)
        x = np.concatenate([[7.0], b])
        linalg.factor_apply(store, 5 + N * N, x, 1, N)
        np.testing.assert_allclose(x[1:], np.linalg.solve(A, b), rtol=1e-10, atol=1e-12)
        assert x[0] == 7.0
        dg = np.empty(N)
        linalg.factor_diag(store, 5 + N * N, dg, 0, N)
        np.testing.assert_allclose(dg, np.diag(np.linalg.inv(A)), rtol=1e-10)
    assert not linalg.spd_inverse(-np.eye(N).ravel(), 0, out.ravel(), 0, work, 0, N)


def test_lyapunov_function_matches_its_definition(rng):
    v = rng.normal(size=3)
    q0 = 0.9
    th, tt = rng.normal(size=N), rng.normal(size=N)
    Pinv = _random_spd(rng)
    gamma = 2.5
    expected = 0.5 * v @ v + (2 - 2 * q0) / gamma + 0.5 * (th - tt) @ Pinv @ (th - tt)
    assert ad.lyapunov_function(v, q0, th, Pinv, tt, gamma) == pytest.approx(expected, rel=1e-13)


# --- the tracking mode's gain k P0 under the projection (issue #25) --------------------------------

def _tracking_step(P0, theta, lo, hi, Phi, v_tilde, k, dt=DT):
    """One tick of the tracking mode (gain ``k P0``, sigma 0): ``(theta' = step / dt, bounds held)``."""
    at, x, prior = _standalone(theta, theta, lo, hi, P0)
    n_act, _, _ = ad.weighted_adaptation_step(ad.ADAPT_TRACKING, at, 0, x, prior, np.ravel(Phi).astype(float), 0,
                                              _IDENTITY, tuple(v_tilde), dt, 1.0, dt, 0.0, np.inf, 0, 1.0, 1.0,
                                              False, k)
    return (MEM.view(x, "THETA") - theta) / dt, n_act


def test_tracking_gain_scale_survives_the_projection_with_any_number_of_bounds_held(rng):
    """The tracking law's gain is ``k P0``: its projected step is ``k`` times P0's, whatever the bounds held.

    Reference: the projection of ``k P0 tau`` onto the box's tangent cone in the metric
    ``(k P0)^-1``, from SciPy's SLSQP. Before the fix the free step of a projection holding five
    or more bounds was P0's whatever ``k`` (ratio 1.0 instead of 0.1).
    """
    lo, hi = -np.ones(N), np.ones(N)
    held_counts = set()
    for trial in range(80):
        P0 = _random_spd(rng)
        Phi = rng.normal(size=(3, N))
        v_tilde = rng.normal(size=3)
        d_unit = P0 @ (Phi.T @ v_tilde)
        theta = rng.uniform(-0.5, 0.5, N)
        at = rng.choice(N, size=rng.integers(0, N + 1), replace=False)
        theta[at] = np.where(d_unit[at] > 0, hi[at], lo[at])           # parked where the law points out
        step_1, n1 = _tracking_step(P0, theta, lo, hi, Phi, v_tilde, 1.0)
        for k in (0.1, 0.37):
            step_k, nk = _tracking_step(P0, theta, lo, hi, Phi, v_tilde, k)
            assert nk == n1 >= 0
            np.testing.assert_allclose(step_k, k * step_1, rtol=1e-9, atol=1e-12 * np.abs(step_1).max())
        held_counts.add(n1)
        K = 0.1 * P0
        d0 = K @ (Phi.T @ v_tilde)
        C = np.linalg.cholesky(np.linalg.inv(K))            # metric K^-1 = C C^T: min |C^T (d - d0)|^2
        upper = np.where(theta >= hi, 0.0, np.inf)
        lower = np.where(theta <= lo, 0.0, -np.inf)
        sol = lsq_linear(C.T, C.T @ d0, bounds=(lower, upper), method="bvls", tol=1e-14)
        assert sol.success
        step_k, _ = _tracking_step(P0, theta, lo, hi, Phi, v_tilde, 0.1)
        np.testing.assert_allclose(step_k, sol.x, rtol=1e-7, atol=1e-9 * np.abs(d0).max())
    assert {0, 1, 2, 3, 4, 5, 6} <= held_counts                # both of the projection's systems exercised


# --- bounds that respect the signs physics gives (issue #25) ---------------------------------------

KNOWN_SIGNS = {"CTx": 1, "CTz": 1, "CS": 1, "CD0": 1, "CD1": 0, "CD2": 1, "CL0": 0, "CL1": 1}
"""From physics, not from the code: thrust is along the rotor axis (C_T > 0); the rotor's in-plane
force opposes the flow (C_S >= 0); drag at zero alpha and its quadratic growth are >= 0; the lift
slope is > 0; the linear drag term and the zero-alpha lift of a cambered or symmetric wing have
either sign."""


def test_theta_bounds_respect_the_signs_physics_gives(any_vehicle):
    """No bound lets a coefficient of known sign change it (before: C_S's lower bound was -0.5 theta_0,
    a rotor side force along the flow, with the caltech_vtol's bound_fraction 1.5)."""
    from vtoladapt.vehicle import PARAMETER_NAMES, parameter_signs

    assert dict(zip(PARAMETER_NAMES, parameter_signs())) == KNOWN_SIGNS
    th0 = any_vehicle.theta_scaled
    lo, hi = default_theta_bounds(any_vehicle, th0)
    for i, name in enumerate(PARAMETER_NAMES):
        if KNOWN_SIGNS[name] > 0:
            assert lo[i] >= 0.0, name
        assert lo[i] <= th0[i] <= hi[i]
    # the rule is general: with every bound at 5 |theta_0| each known-positive coefficient stops
    # at 0 and the others keep their symmetric room
    wide = any_vehicle.replace(adaptation=replace(any_vehicle.adaptation, bound_fraction=(5.0,) * N))
    lo, hi = default_theta_bounds(wide, th0)
    for i, name in enumerate(PARAMETER_NAMES):
        half = max(5.0 * abs(th0[i]), 3.0 * any_vehicle.theta_std_scaled[i])
        assert hi[i] == pytest.approx(th0[i] + half, rel=1e-12)
        expected_lo = 0.0 if KNOWN_SIGNS[name] > 0 else th0[i] - half
        assert lo[i] == pytest.approx(expected_lo, rel=1e-12, abs=0.0)


def test_posterior_bounds_respect_the_signs_physics_gives(caltech):
    """A fitted posterior's bounds follow the same rule (one place for it)."""
    from vtoladapt.fitting.posterior import Posterior, controller_prior

    theta = caltech.force_model.as_table_theta()
    std = caltech.force_model_std.as_table_theta() * 4.0       # a wide posterior: 3 std reach past zero
    post = Posterior(theta_table=theta, std_table=std, k1=caltech.force_model.k1, k2=caltech.force_model.k2,
                     k1_std=0.01, k2_std=0.05, ci95={}, covariance=None, diagnostics={}, reference={}, raw={},
                     source="test")
    lower = controller_prior(post, caltech).lower_bounds_scaled
    for i, name in enumerate(KNOWN_SIGNS):
        if KNOWN_SIGNS[name] > 0:
            assert lower[i] >= 0.0, name
    assert lower[4] < 0.0                                       # CD1 (either sign) may still cross zero


# --- the constant-P law holds P at P0 (issue #25) ---------------------------------------------------

def _pconst_steps(P0, theta, W, a_m, Phi, v_tilde, sigma, w_pred, dt, n):
    """``n`` ticks of the constant-P mode with everything held; theta-hat after them (bounds far away)."""
    at, x, prior = _standalone(theta, np.zeros(N), np.full(N, -1e9), np.full(N, 1e9), P0, W=W, a_m=a_m)
    for _ in range(n):
        ad.weighted_adaptation_step(ad.ADAPT_PCONST, at, 0, x, prior, np.ravel(Phi).astype(float), 0, _IDENTITY,
                                    tuple(v_tilde), dt, 1.0, dt, sigma, np.inf, 0, 1.0, w_pred, False, 1.0)
    return MEM.view(x, "THETA").copy()


def _pconst_exact(P0, theta, W, a_m, Phi, v_tilde, sigma, w_pred, dt):
    """The continuous law with P = P0 over one tick, inputs held, sigma's term frozen at its start:
    ``theta' = P0 (Phi^T v~ - w W^T (W theta - a_m) - sigma theta_k)``, from scipy's expm."""
    A = w_pred * W.T @ W
    c = Phi.T @ v_tilde + w_pred * W.T @ a_m - sigma * theta
    M = np.zeros((N + 1, N + 1))
    M[:N, :N] = -P0 @ A
    M[:N, N] = P0 @ c
    return (expm(M * dt) @ np.append(theta, 1.0))[:N]


def test_constant_p_step_is_the_exact_solution_of_the_law_with_p0(rng, caltech):
    """One tick of composite_pconst is the continuous law ``theta' = P0 tau`` solved exactly over the
    tick. Before, the backward-Euler step had the gain ``(P0^-1 + dt W^T W)^-1``: 183 instead of 200
    along C_Tz in hover, and its step 4 % short of the exact one there."""
    for trial in range(20):
        P0 = _random_spd(rng) * 10.0 ** rng.uniform(-1, 2)
        W = rng.normal(size=(3, N)) * 10.0 ** rng.uniform(-2, 1)
        theta = rng.normal(size=N)
        a_m, Phi, v_t = rng.normal(size=3), rng.normal(size=(3, N)), rng.normal(size=3)
        sigma, w_pred = rng.uniform(0, 1e-3), rng.uniform(0.2, 1.0)
        exact = _pconst_exact(P0, theta, W, a_m, Phi, v_t, sigma, w_pred, DT)
        got = _pconst_steps(P0, theta, W, a_m, Phi, v_t, sigma, w_pred, DT, 1)
        np.testing.assert_allclose(got - theta, exact - theta, rtol=1e-8, atol=1e-12 * np.abs(exact - theta).max())
    # hover: C_Tz alone is excited; P stays 200 along it, the tick's step is 200's exact one
    W = np.empty((3, N))
    forces.regressor(np.zeros(3), 0.0, 0.585, caltech.model_kernel, W)
    P0 = np.diag(caltech.adaptation.P0_diag)
    theta = caltech.theta_scaled.copy()
    a_m = W @ theta + np.array([0.0, 0.0, -0.5])       # 0.5 m/s^2 more lift than the model's
    zero = np.zeros((3, N))
    got = _pconst_steps(P0, theta, W, a_m, zero, np.zeros(3), 0.0, 1.0, DT, 1)
    exact = _pconst_exact(P0, theta, W, a_m, zero, np.zeros(3), 0.0, 1.0, DT)
    np.testing.assert_allclose(got, exact, rtol=1e-12, atol=1e-14)
    euler_gain = 1.0 / (1.0 / 200.0 + DT * W[2, 1] ** 2)
    assert euler_gain == pytest.approx(183.0, abs=0.5)               # the reviewer's number
    gain = (got[1] - theta[1]) / (DT * -W[2, 1] * 0.5)               # step / (dt tau_CTz), tau = -W^T e
    x = DT * 200.0 * W[2, 1] ** 2
    assert gain == pytest.approx(200.0 * -np.expm1(-x) / x, rel=1e-10)   # P0 phi(dt P0 W^T W): 191


def test_constant_p_law_does_not_depend_on_the_tick(rng, caltech):
    """With P = P0 and the inputs held, one second of the law is the same at 250 Hz and at 2 kHz
    (the exact step); the backward-Euler step's gain fell with dt P0 W^T W (1 % apart here)."""
    W = np.empty((3, N))
    forces.regressor(np.array([9.0, 0.0, 1.5]), 0.4, 0.4, caltech.model_kernel, W)
    P0 = np.diag(caltech.adaptation.P0_diag)
    theta = caltech.theta_scaled.copy()
    a_m = W @ (theta * 1.1)
    zero = np.zeros((3, N))
    slow = _pconst_steps(P0, theta, W, a_m, zero, np.zeros(3), 0.0, 1.0, 0.004, 25)
    fast = _pconst_steps(P0, theta, W, a_m, zero, np.zeros(3), 0.0, 1.0, 0.0005, 200)
    assert np.abs(slow - theta).max() > 1e-3
    np.testing.assert_allclose(slow, fast, rtol=1e-10, atol=1e-13)


def test_symmetric_eigen3_and_phi_psi_against_numpy(rng):
    for A in [np.diag([3.0, 1.0, 2.0]), np.zeros((3, 3)), np.ones((3, 3)), np.eye(3) * 5.0]\
            + [(lambda B: B @ B.T)(rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-8, 8)) for _ in range(30)]:
        a = A.ravel().copy()
        Q = np.empty(9)
        exact_step.symmetric_eigen3(a, 0, Q, 0)
        Q = Q.reshape(3, 3)
        lam = np.diag(a.reshape(3, 3))
        np.testing.assert_allclose(np.sort(lam), np.linalg.eigvalsh(A), rtol=1e-12, atol=1e-13 * np.abs(A).max())
        np.testing.assert_allclose(Q @ Q.T, np.eye(3), atol=1e-14)
        np.testing.assert_allclose(Q @ np.diag(lam) @ Q.T, A, rtol=1e-12, atol=1e-13 * np.abs(A).max())
    for x in np.concatenate([[0.0], np.logspace(-12, 3, 200)]):
        phi, psi = exact_step.phi_psi(x)
        ref_phi = 1.0 if x == 0 else float(-np.expm1(-x) / x)
        # psi = sum_k (-x)^k / (k+2)!, summed in extended precision where the closed form cancels
        if x < 2.0:
            xl = np.longdouble(x)
            ref_psi = float(sum((-xl) ** k / np.prod(np.arange(1, k + 3, dtype=np.longdouble)) for k in range(60)))
        else:
            ref_psi = (x + np.expm1(-x)) / x ** 2
        assert phi == pytest.approx(ref_phi, rel=1e-14)
        assert psi == pytest.approx(ref_psi, rel=1e-12)
