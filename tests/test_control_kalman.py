"""The composite law's Kalman form (vtoladapt.control.kalman) against independent references.

The compiled step is checked against a textbook discrete Kalman filter written here in numpy (predict with the
Ornstein-Uhlenbeck transition, update with the 3 x 3 innovation covariance, the tracking term added after), and,
with no process noise and no regularisation, against batch weighted least squares with the prior solved by
numpy's least squares; P is held symmetric positive definite over a long noisy flight of random regressors.
The prior's derivation is checked against the noise algebra it states and against the learned file's spreads.
"""
from __future__ import annotations

import numpy as np
import pytest

from vtoladapt.control import adaptation as ad
from vtoladapt.control import kalman

DT = 0.004
_IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def _arrays(n, theta, theta0, P, q, R, lower=-1e9, upper=1e9):
    at, x, prior = ad.standalone_arrays(n, covariance=True)
    mem, pri = ad.memory_layout(n), ad.prior_layout(n)
    mem.view(x, "THETA")[:] = theta
    mem.view(x, "GAMMA")[:] = np.asarray(P).ravel()
    prior[:] = pri.pack(THETA0=theta0, THETA_INIT=theta0, LOWER=lower, UPPER=upper, P0=np.asarray(P).ravel(),
                        GAMMA0=np.linalg.inv(P).ravel(), Q=q, R_MEAS=R)
    return at, x, prior, mem


def _tick(at, x, prior, mem, W, a_m, Phi, v_tilde, lam, w_track=1.0, w_pred=1.0, R_WB=_IDENTITY):
    mem.view(x, "W")[:] = np.asarray(W).ravel()
    mem.view(x, "A_M")[:] = a_m
    decay2, q_factor = ad.forgetting_weights(2.0 * lam, DT)
    return kalman.kalman_step(at, 0, x, prior, np.asarray(Phi, dtype=float).ravel(), 0, R_WB,
                              np.asarray(v_tilde, dtype=float), DT, decay2, q_factor, w_track, w_pred)


def _textbook(theta, P, theta0, q, R, W, y, Phi, v_tilde, lam, R_WB=np.eye(3)):
    """One tick of the discrete Kalman filter of the module notes, in plain numpy (the reference)."""
    a = np.exp(-lam * DT)
    F = a * np.eye(len(theta))
    Qd = np.diag(q) * (1.0 - a * a) / (2.0 * lam)
    theta_p = theta0 + F @ (theta - theta0)
    P_p = F @ P @ F.T + Qd
    Rd = np.diag(R) / DT
    S = W @ P_p @ W.T + Rd
    K = P_p @ W.T @ np.linalg.inv(S)
    theta_u = theta_p + K @ (y - W @ theta_p)
    P_u = (np.eye(len(theta)) - K @ W) @ P_p
    theta_u = theta_u + DT * P_u @ Phi.T @ np.linalg.inv(np.diag(R)) @ R_WB.T @ v_tilde
    return theta_u, P_u


@pytest.mark.parametrize("n", [8, 17, 5])
def test_step_equals_textbook_kalman_filter(n):
    """Predict, 3 x 3 innovation update and the R^-1-weighted tracking term equal the numpy filter on random data."""
    rng = np.random.default_rng(3 + n)
    A = rng.standard_normal((n, n))
    P = A @ A.T / n + 0.1 * np.eye(n)
    theta0 = rng.standard_normal(n)
    theta = theta0 + 0.3 * rng.standard_normal(n)
    q = rng.uniform(0.01, 1.0, n)
    R = rng.uniform(0.05, 0.5, 3)
    lam = 0.3
    at, x, prior, mem = _arrays(n, theta, theta0, P, q, R)
    th_ref, P_ref = theta.copy(), P.copy()
    angle = 0.4
    R_WB = np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.0]])
    rows = tuple(tuple(r) for r in R_WB)
    for _ in range(40):
        W = rng.standard_normal((3, n))
        Phi = W + 0.1 * rng.standard_normal((3, n))
        y = rng.standard_normal(3)
        v = 0.2 * rng.standard_normal(3)
        assert _tick(at, x, prior, mem, W, y, Phi, v, lam, R_WB=rows) == 0
        th_ref, P_ref = _textbook(th_ref, P_ref, theta0, q, R, W, y, Phi, v, lam, R_WB)
    np.testing.assert_allclose(mem.view(x, "THETA"), th_ref, rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(mem.view(x, "GAMMA").reshape(n, n), P_ref, rtol=1e-9, atol=1e-12)


def test_no_process_noise_equals_batch_weighted_least_squares_with_the_prior():
    """Q = 0, lambda -> 0 (no relaxation): after N ticks theta-hat and P are the batch weighted least-squares
    solution with the prior as N(theta_0, P0) (numpy lstsq on the whitened stacked system)."""
    rng = np.random.default_rng(11)
    n = 6
    P0 = np.diag(rng.uniform(0.5, 2.0, n))
    theta0 = rng.standard_normal(n)
    theta_true = theta0 + rng.standard_normal(n)
    R = np.array([0.2, 0.3, 0.4])
    at, x, prior, mem = _arrays(n, theta0, theta0, P0, np.zeros(n), R)
    W = rng.standard_normal((3, n))  # a constant regressor: only its row space is learned
    rows_A, rows_b = [], []
    L0 = np.linalg.cholesky(np.linalg.inv(P0))
    rows_A.append(L0.T)
    rows_b.append(L0.T @ theta0)
    sd = np.sqrt(R / DT)
    for _ in range(300):
        y = W @ theta_true + sd * rng.standard_normal(3)
        mem.view(x, "W")[:] = W.ravel()
        mem.view(x, "A_M")[:] = y
        assert kalman.kalman_step(at, 0, x, prior, np.zeros(3 * n), 0, _IDENTITY, np.zeros(3), DT, 1.0, DT, 0.0,
                                  1.0) == 0
        rows_A.append(W / sd[:, None])
        rows_b.append(y / sd)
    A = np.vstack(rows_A)
    b = np.concatenate(rows_b)
    theta_wls = np.linalg.lstsq(A, b, rcond=None)[0]
    P_wls = np.linalg.inv(A.T @ A)
    np.testing.assert_allclose(mem.view(x, "THETA"), theta_wls, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(mem.view(x, "GAMMA").reshape(n, n), P_wls, rtol=1e-6, atol=1e-12)


def test_covariance_stays_symmetric_positive_definite_over_a_long_flight():
    """100 000 ticks (400 s) of random, often rank-deficient regressors with a tiny R (the accelerometer's):
    P stays exactly symmetric, positive definite and bounded by the no-data stationary variance Q / (2 lambda)."""
    rng = np.random.default_rng(5)
    n = 17
    q = rng.uniform(1e-6, 1e-1, n)
    lam = 0.1
    P0 = np.diag(q / (2 * lam))
    R = np.full(3, 3e-6)
    theta0 = np.zeros(n)
    at, x, prior, mem = _arrays(n, theta0, theta0, P0, q, R)
    scale = np.exp(rng.uniform(-6, 2, n))
    for k in range(100_000):
        W = rng.standard_normal((3, n)) * scale
        if k % 3 == 0:
            W[:, rng.integers(0, n, 8)] = 0.0
        if k % 7 == 0:
            W[1:] = W[0]
        assert _tick(at, x, prior, mem, W, rng.standard_normal(3), W, np.zeros(3), lam, w_track=0.0) == 0
        if k % 5000 == 4999:
            P = mem.view(x, "GAMMA").reshape(n, n)
            assert np.array_equal(P, P.T)
            np.linalg.cholesky(P)
            assert np.all(np.diag(P) <= q / (2 * lam) * (1 + 1e-9))


def test_measurement_noise_density_is_the_accelerometer_density_squared():
    """The filtered samples' variance times their correlation sum is the raw density squared (the filter's DC
    gain is 1); the variance itself is the first-order filter's c/(2-c) of the per-sample variance."""
    rho_ug = 175.0
    R, var_f, corr = kalman.measurement_noise_density(rho_ug, 10.0, DT)
    rho = rho_ug * 9.80665e-6
    assert R == pytest.approx(rho ** 2, rel=1e-12)
    # independent: simulate the filter on white noise and measure the variance
    rng = np.random.default_rng(0)
    c = 1 - np.exp(-2 * np.pi * 10.0 * DT)
    xs = rng.standard_normal(400_000) * rho / np.sqrt(DT)
    y = np.empty_like(xs)
    acc = 0.0
    for i, v in enumerate(xs):
        acc += c * (v - acc)
        y[i] = acc
    assert np.var(y[1000:]) == pytest.approx(var_f, rel=0.02)
    assert corr == pytest.approx(DT * (2 - c) / c)


def test_prior_time_scale_and_learned_spreads():
    """Physics columns: Q e / R = 1/tau^2 (every column adapts at tau); learned columns: P0 = spread^2,
    Q = 2 lambda spread^2 (the basis file's per-flight spread)."""
    from vtoladapt.bases import describe_basis
    from vtoladapt.control.laws.composite import CompositeSettings
    from vtoladapt.vehicle import load_vehicle

    vehicle = load_vehicle("caltech_vtol")
    spec = describe_basis(vehicle, "learned")
    s = CompositeSettings(estimator="kalman", kalman_time_scale_s=0.5, regularisation_lambda=0.2)
    kp = kalman.kalman_prior(spec, vehicle, s, 10.0, DT)
    e, Q, R, P0 = kp["excitation"], kp["Q"], kp["R"][0], np.diag(kp["P0"])
    phys = ~spec.trained_spread
    assert phys.sum() == 13 and spec.trained_spread.sum() == spec.n - 13
    np.testing.assert_allclose((Q * e / R)[phys], 1 / 0.5 ** 2, rtol=1e-12)
    np.testing.assert_allclose(P0[phys], Q[phys] / (2 * 0.2), rtol=1e-12)
    spread = spec.std_scaled[spec.trained_spread]
    np.testing.assert_allclose(P0[~phys], spread ** 2, rtol=1e-12)
    np.testing.assert_allclose(Q[~phys], 2 * 0.2 * spread ** 2, rtol=1e-12)
