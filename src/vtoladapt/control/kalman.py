"""The composite law's Kalman form (``[controller.composite] estimator = "kalman"``, not the paper's law).

Neural-Fly (O'Connell et al. 2022, Science Robotics, Eqs. 7-9) adapts the weights of a learned basis with a
Kalman-Bucy filter plus a tracking term:

    theta' = -lambda (theta - theta_0) - P W^T R^-1 (W theta - a_m) + P Phi^T R^-1 R_WB^T v~
    P'     = -2 lambda P + Q - P W^T R^-1 W P

(the paper regularises toward zero; here toward the prior theta_0, which is the same filter for the weights'
deviation from theta_0). ``R`` is the measurement noise (the filtered accelerometer's), ``Q`` the process noise
of each weight, ``lambda`` the regularisation. The tracking term is weighted by ``R^-1`` like the prediction
term: with ``P`` a covariance, the Lyapunov function ``v~^T R^-1 v~ / 2 + theta~^T P^-1 theta~ / 2`` has the
cross term ``v~^T R^-1 Phi theta~``, which this term cancels (unweighted, the tracking term's size against the
prediction term depended on the units of R).

Discretisation (exact for W, a_m and v~ held over the tick). The model behind the equations is an
Ornstein-Uhlenbeck process for every weight around theta_0 (rate lambda, driving density Q) observed through
``a_m = W theta + noise``. One tick of it is a textbook discrete Kalman filter:

    predict:  theta- = theta_0 + a (theta - theta_0),     P- = a^2 P + Q (1 - a^2) / (2 lambda)   (a = e^-lambda dt;
              Q dt at lambda = 0)
    update:   S = W P- W^T + R / dt (3 x 3),  B = P- W^T (n x 3)
              theta+ = theta- + B S^-1 (a_m - W theta-),     P+ = P- - B S^-1 B^T

(``R / dt``: the covariance per tick of white noise of density ``R``), then the tracking term
``theta += dt P+ Phi^T R^-1 R_WB^T v~`` and the box bounds by clipping (the paper's law projects in the
P^-1 metric; the Kalman form holds P, not P^-1, and clips). The update costs ``O(3 n^2)``: one 3 x 3
Cholesky factorisation, no n x n one. ``P+`` is formed as ``P- - C^T C`` with ``C = L^-1 B^T``
(``S = L L^T``), upper triangle mirrored, so it stays exactly symmetric; it is positive definite in
exact arithmetic (``P+ >= (P-^-1 + W^T (R/dt)^-1 W)^-1 > 0``) and the tests hold it so over long flights.

Where R, Q and P0 come from (:func:`kalman_prior`)
--------------------------------------------------
**R** (per body axis, (m/s^2)^2 s): from the accelerometer noise density the controller believes
(``accel_noise_density_ug_rtHz``, the data sheet's, never the plant's setting) and the low-pass filter
``[.]_f``: white noise of density ``rho`` sampled every ``dt`` has variance ``rho^2 / dt``; the filter
(gain ``c``) leaves ``rho^2 / dt * c / (2 - c)`` with correlation ``(1 - c)^k`` at lag k, so the filtered
samples are not independent; the noise density they carry at low frequency (what a weight sees) is that
variance times ``dt (1 + (1 - c)) / c``, i.e. ``rho^2`` again (the filter's DC gain is 1). Both factors are
computed in :func:`measurement_noise_density` from the settings. ``measurement_noise_scale`` multiplies it
(an unmodelled force the controller believes in; a tuning gain).

**P0 and Q of a learned weight**: the training solved one weight vector per flight; the spread of those
(the basis file's ``theta_std``, times ``net_std_scale``) is how far a new flight's weight lies from the
mean: ``P0 = spread^2``, and ``Q = 2 lambda spread^2``, so that without data P relaxes to ``P0`` (the
Ornstein-Uhlenbeck stationary variance ``Q / (2 lambda)``) instead of growing without bound.

**P0 and Q of a physics weight**: scaled so that every column adapts on the same time scale
``kalman_time_scale_s`` (tau). For one weight excited steadily with ``e = |W_i|^2`` the filter's stationary
covariance is ``P = sqrt(Q R / e)`` (at small lambda) and its rate ``P e / R = sqrt(Q e / R)``; ``Q = R / (tau^2 e)``
makes the rate ``1 / tau`` whatever the column's size. ``e`` is the column's *reference excitation*
(:func:`reference_excitation`: the mean of ``|Phi_i|^2`` over a stated grid of airflows and throttles, at the
vehicle's believed model); ``P0 = Q / (2 lambda)``, the same stationary variance rule as above. (The paper's
Table III P0 gives rates spanning nine orders of magnitude, from 600 /s for C_S to 1e-6 /s for dCN90.)

Not done while the front end pauses adaptation (no probe, invalid sensors): the estimate and P are held, as
for the paper's law.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..frames import GRAVITY_MPS2, rows_transpose_times
from .adaptation import (AT_DWT, AT_GAMMA, AT_LOWER, AT_N, AT_P_DIAG, AT_Q, AT_R_MEAS, AT_S, AT_S_FACTOR, AT_SWD,
                         AT_TAU, AT_THETA, AT_THETA0, AT_UPPER, AT_W, AT_A_M, N_SLOT_0, N_SLOT_1, N_SLOT_2)
from .filters import flush_tiny

MICRO_G_MPS2 = 1e-6 * GRAVITY_MPS2
"""One micro-g in m/s^2 (the accelerometer density's data-sheet unit)."""

REFERENCE_AIRSPEEDS_FRACTION = (0.0, 0.5, 1.0, 1.5)
"""The reference grid's airspeeds, as fractions of the vehicle's upper hover-blend airspeed V_hi
(hover, half way into the blend, its end, cruise beyond it)."""
REFERENCE_ALPHAS_DEG = (0.0, 10.0, 45.0)
"""The reference grid's angles of attack (attached flow, near stall, deep stall: the dCN90 column's range)."""
REFERENCE_THROTTLES = (0.3, 0.6)
"""The reference grid's throttles, the same for the pusher and the lift rotors (fractions)."""
EXCITATION_FLOOR = 1e-6
"""A column's reference excitation is at least this fraction of the largest one's (a column zero on the whole
grid would otherwise get an infinite Q)."""


def measurement_noise_density(accel_noise_density_ug_rtHz: float, lowpass_cutoff_hz: float, dt_s: float
                              ) -> tuple[float, float, float]:
    """``(R, variance_f, correlation)``: the low-frequency noise density ``R`` ((m/s^2)^2 s) of the filtered
    accelerometer, the filtered samples' variance ((m/s^2)^2) and the factor that turns it into a density
    (s; the sum of their autocorrelation over all lags times dt). See the module notes: ``R = rho^2``."""
    rho = accel_noise_density_ug_rtHz * MICRO_G_MPS2
    c = 1.0 - np.exp(-2.0 * np.pi * lowpass_cutoff_hz * dt_s)
    variance_f = rho * rho / dt_s * c / (2.0 - c)
    correlation = dt_s * (2.0 - c) / c
    return variance_f * correlation, variance_f, correlation


def reference_excitation(spec, vehicle) -> np.ndarray:
    """``e_i``: the mean over the reference grid of ``|Phi_i|^2`` (sum over the three body axes), (n,).

    The grid: airspeeds :data:`REFERENCE_AIRSPEEDS_FRACTION` x V_hi, angles of attack :data:`REFERENCE_ALPHAS_DEG`
    (flow in the body x-z plane), throttles :data:`REFERENCE_THROTTLES`, evaluated by the basis's own regressor
    with the controller's vehicle model (never the plant). Floored at :data:`EXCITATION_FLOOR` of the largest.
    """
    from ..bases import evaluate, input_rows

    v_hi = float(vehicle.envelope.hover_blend_airspeed_mps[1])
    rows = []
    for f in REFERENCE_AIRSPEEDS_FRACTION:
        for a in np.radians(REFERENCE_ALPHAS_DEG):
            for u in REFERENCE_THROTTLES:
                V = f * v_hi
                rows.append((V * np.cos(a), 0.0, V * np.sin(a), u))
    rows = np.array(rows)
    x = input_rows(rows[:, :3], rows[:, 3], rows[:, 3], vehicle.model_kernel)
    phi = evaluate(spec, x)
    e = np.mean(np.sum(phi * phi, axis=1), axis=0)
    return np.maximum(e, EXCITATION_FLOOR * max(float(np.max(e)), 1e-300))


def kalman_prior(spec, vehicle, settings, lowpass_cutoff_hz: float, dt_s: float) -> dict:
    """``{"P0", "Q", "R", "excitation", "R_accel"}`` of the Kalman form for ``spec`` (module notes).

    ``settings``: the composite law's (``regularisation_lambda``, ``kalman_time_scale_s``,
    ``accel_noise_density_ug_rtHz``, ``measurement_noise_scale``, ``process_noise_scale``); learned columns are
    the basis's ``trained_spread`` ones. ``P0`` is (n, n) diagonal, ``Q`` (n,), ``R`` (3,).
    """
    lam = settings.regularisation_lambda
    R_accel, _, _ = measurement_noise_density(settings.accel_noise_density_ug_rtHz, lowpass_cutoff_hz, dt_s)
    R = settings.measurement_noise_scale * R_accel
    e = reference_excitation(spec, vehicle)
    tau = settings.kalman_time_scale_s
    Q = R / (tau * tau * e)
    P0 = Q / (2.0 * lam)
    learned = np.asarray(spec.trained_spread, dtype=bool)
    if learned.any():
        spread2 = np.asarray(spec.std_scaled, dtype=float)[learned] ** 2
        P0[learned] = spread2
        Q[learned] = 2.0 * lam * spread2
    Q = settings.process_noise_scale * Q
    P0 = settings.process_noise_scale * P0
    return {"P0": np.diag(P0), "Q": Q, "R": np.full(3, R), "excitation": e, "R_accel": R_accel}


@njit(cache=True, error_model="numpy", _nrt=False)
def kalman_step(at, a, x, prior, Phi, phi, R_WB, v_tilde_W, dt, decay2, q_factor, w_track, w_pred) -> int:
    """One tick of the Kalman form (module notes), in place; returns 0, or -2 if ``S`` was not positive
    definite (the update is then skipped: cannot happen for finite inputs and R > 0).

    ``at, a``: the adaptation's offsets table (:data:`.adaptation.AT`, the GAMMA slot holding P); ``x`` the
    memory and scratch, ``prior`` the prior with ``Q`` and ``R_MEAS``; ``Phi`` (3 x n at ``Phi[phi:]``) the
    unfiltered regressor; ``R_WB`` the attitude; ``v_tilde_W`` (m/s, NED); ``decay2, q_factor``:
    :func:`.adaptation.forgetting_weights` of ``2 lambda`` (``a^2`` and ``(1 - a^2) / (2 lambda)``);
    ``w_track``, ``w_pred`` in [0, 1]: the tracking term's and the measurement's weights (the measurement
    noise is ``R / w_pred``; 0 skips the update). On return the scratch's ``P_DIAG`` holds diag(P).
    """
    n = int(at[a + AT_N])
    if n == N_SLOT_0:
        return _kalman(at, a, x, prior, Phi, phi, R_WB, v_tilde_W, dt, decay2, q_factor, w_track, w_pred, N_SLOT_0)
    if n == N_SLOT_1:
        return _kalman(at, a, x, prior, Phi, phi, R_WB, v_tilde_W, dt, decay2, q_factor, w_track, w_pred, N_SLOT_1)
    if n == N_SLOT_2:
        return _kalman(at, a, x, prior, Phi, phi, R_WB, v_tilde_W, dt, decay2, q_factor, w_track, w_pred, N_SLOT_2)
    return _kalman(at, a, x, prior, Phi, phi, R_WB, v_tilde_W, dt, decay2, q_factor, w_track, w_pred, n)


@njit(cache=True, error_model="numpy", inline="always")
def _kalman(at, a, x, prior, Phi, phi, R_WB, v_tilde_W, dt, decay2, q_factor, w_track, w_pred, n) -> int:
    """The body of :func:`kalman_step` for ``n`` parameters (inlined: a constant n, loops of constant length)."""
    th = int(at[a + AT_THETA])
    P = int(at[a + AT_GAMMA])
    wf = int(at[a + AT_W])
    am = int(at[a + AT_A_M])
    th0 = int(at[a + AT_THETA0])
    q = int(at[a + AT_Q])
    rm = int(at[a + AT_R_MEAS])
    B = int(at[a + AT_DWT])
    C = int(at[a + AT_SWD])
    sm = int(at[a + AT_S])
    sf = int(at[a + AT_S_FACTOR])
    g = int(at[a + AT_TAU])
    pd = int(at[a + AT_P_DIAG])
    lower = int(at[a + AT_LOWER])
    upper = int(at[a + AT_UPPER])
    decay = np.sqrt(decay2)
    # predict: the weights relax toward theta_0, P by a^2 plus the process noise over the tick
    for i in range(n):
        x[th + i] = prior[th0 + i] + decay * (x[th + i] - prior[th0 + i])
        for j in range(i, n):
            x[P + n * i + j] = decay2 * x[P + n * i + j]
        x[P + n * i + i] += q_factor * prior[q + i]
    status = 0
    if w_pred > 0.0:
        # B = P- W^T (n x 3), from the upper triangle of P-
        for i in range(n):
            b0 = 0.0
            b1 = 0.0
            b2 = 0.0
            for j in range(n):
                pij = x[P + n * i + j] if j >= i else x[P + n * j + i]
                b0 += pij * x[wf + j]
                b1 += pij * x[wf + n + j]
                b2 += pij * x[wf + 2 * n + j]
            x[B + 3 * i] = b0
            x[B + 3 * i + 1] = b1
            x[B + 3 * i + 2] = b2
        # S = W B + R / (w_pred dt), and the innovation nu = a_m - W theta-
        nu0 = x[am]
        nu1 = x[am + 1]
        nu2 = x[am + 2]
        for j in range(n):
            nu0 -= x[wf + j] * x[th + j]
            nu1 -= x[wf + n + j] * x[th + j]
            nu2 -= x[wf + 2 * n + j] * x[th + j]
        for r in range(3):
            for c in range(r, 3):
                t = 0.0
                for j in range(n):
                    t += x[wf + n * r + j] * x[B + 3 * j + c]
                x[sm + 3 * r + c] = t
                x[sm + 3 * c + r] = t
            x[sm + 4 * r] += prior[rm + r] / (w_pred * dt)
        # Cholesky of the 3 x 3 S = L L^T (L at sf, row-major lower)
        s00 = x[sm]
        if not s00 > 0.0:
            status = -2
        else:
            l00 = np.sqrt(s00)
            l10 = x[sm + 3] / l00
            l20 = x[sm + 6] / l00
            s11 = x[sm + 4] - l10 * l10
            if not s11 > 0.0:
                status = -2
            else:
                l11 = np.sqrt(s11)
                l21 = (x[sm + 7] - l20 * l10) / l11
                s22 = x[sm + 8] - l20 * l20 - l21 * l21
                if not s22 > 0.0:
                    status = -2
                else:
                    l22 = np.sqrt(s22)
                    x[sf] = l00
                    x[sf + 3] = l10
                    x[sf + 4] = l11
                    x[sf + 6] = l20
                    x[sf + 7] = l21
                    x[sf + 8] = l22
                    # z = L^-1 nu
                    z0 = nu0 / l00
                    z1 = (nu1 - l10 * z0) / l11
                    z2 = (nu2 - l20 * z0 - l21 * z1) / l22
                    # C = L^-1 B^T, stored n x 3 (row i: the column i of C)
                    for i in range(n):
                        c0 = x[B + 3 * i] / l00
                        c1 = (x[B + 3 * i + 1] - l10 * c0) / l11
                        c2 = (x[B + 3 * i + 2] - l20 * c0 - l21 * c1) / l22
                        x[C + 3 * i] = c0
                        x[C + 3 * i + 1] = c1
                        x[C + 3 * i + 2] = c2
                        # theta+ = theta- + B S^-1 nu = theta- + C^T z
                        x[th + i] += c0 * z0 + c1 * z1 + c2 * z2
                    # P+ = P- - C^T C (upper triangle)
                    for i in range(n):
                        c0 = x[C + 3 * i]
                        c1 = x[C + 3 * i + 1]
                        c2 = x[C + 3 * i + 2]
                        for j in range(i, n):
                            x[P + n * i + j] = flush_tiny(x[P + n * i + j] - (c0 * x[C + 3 * j] + c1 * x[C + 3 * j + 1]
                                                                          + c2 * x[C + 3 * j + 2]))
    # mirror P's upper triangle (exactly symmetric)
    for i in range(n):
        for j in range(i + 1, n):
            x[P + n * j + i] = x[P + n * i + j]
    # the tracking term: theta += dt P+ Phi^T R^-1 R_WB^T v~ (body axes)
    if w_track > 0.0:
        rv0, rv1, rv2 = rows_transpose_times(R_WB, v_tilde_W)
        rv0 *= w_track / prior[rm]
        rv1 *= w_track / prior[rm + 1]
        rv2 *= w_track / prior[rm + 2]
        for k in range(n):
            x[g + k] = Phi[phi + k] * rv0 + Phi[phi + n + k] * rv1 + Phi[phi + 2 * n + k] * rv2
        for i in range(n):
            t = 0.0
            for j in range(n):
                t += x[P + n * i + j] * x[g + j]
            x[th + i] += dt * t
    for i in range(n):
        v = x[th + i]
        if not np.isfinite(v):
            v = prior[th0 + i]
        x[th + i] = min(max(v, prior[lower + i]), prior[upper + i])
        x[pd + i] = x[P + n * i + i]
    return status


__all__ = ["EXCITATION_FLOOR", "REFERENCE_ALPHAS_DEG", "REFERENCE_AIRSPEEDS_FRACTION", "REFERENCE_THROTTLES",
           "kalman_prior", "kalman_step", "measurement_noise_density", "reference_excitation"]
