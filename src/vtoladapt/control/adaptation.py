"""Composite adaptation of the force model (eq:prediction_error, eq:th_adapt, eq:P_adapt).

All quantities are in the adaptation scaling of :mod:`vtoladapt.models` (throttle as a fraction;
``f_b = Phi theta`` in m/s^2). The kernels here are pure functions of arrays; the controller's
compiled step (:mod:`vtoladapt.control.step`) owns the state.

Filters (eq:prediction_error)
-----------------------------
``[.]_f`` is a first-order low-pass at ``f_c`` (10 Hz in the paper), discretised exactly for an
input held over the tick: ``y <- y + (1 - exp(-2 pi f_c dt)) (x - y)`` (:mod:`vtoladapt.control.filters`,
which the laws and the front end share). The same filter acts on
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
III's P0 it is). The step is therefore implicit in the terms linear in theta-hat::

    theta_k+1 = theta_k + dt K tau_k,
    K = Gamma_k+1^-1 = P_k+1                  (composite: Gamma_k+1 already holds b W^T W)
      = phi(dt P_0 W^T W) P_0                 (composite_pconst, phi(X) = X^-1 (I - e^-X))
      = P_0                                   (tracking_only: no W term)

(``Gamma_k+1`` before the trace cap). For the composite law this is backward Euler in the
prediction-error term, the exact recursive-least-squares update. For the constant-P law it is the
exact solution over the tick of ``theta' = P_0 tau`` with W, a_m and the tracking term held: P is
P_0, and the tick's ``K`` is what the continuous law does in ``dt`` (191 along C_Tz in hover with
Table III's 200, ``dt P_0 W^T W`` = 0.094). (Backward Euler there, ``K = (Gamma_0 + dt W^T W)^-1``,
had put 183 and made the law depend on the tick.) Both are stable for any W and dt, equal the
continuous law to first order in dt and have its stationary points (``tau = 0``). The sigma term
stays explicit (stable while ``dt sigma lambda_max(P0) < 2``, checked when the parameters are
built), so that the composite law's gain is exactly P.

The constant-P law's ``K`` is formed as its inverse through the 3 x 3 ``W P_0 W^T`` (:mod:`.exact_step`).

Extensions (not in the paper; off in :func:`adaptation_step`)
--------------------------------------------------------------
:func:`weighted_adaptation_step` adds weights on the tracking and prediction-error terms (a
law's model-validity measure), directional forgetting (:func:`directional_information_update`)
and a scalar on the tracking mode's gain (the tracking law's gain rule). With unit weights,
forgetting toward the prior and a unit scale it is the step above, bit for bit.

Bounds by projection
--------------------
theta-hat stays in the box ``[lower, upper]``. The step direction ``d = K tau`` is projected in
the K-metric onto the tangent cone of the box: minimise ``(d - K tau)^T K^-1 (d - K tau)`` subject to
``d_i <= 0`` at an upper bound and ``d_i >= 0`` at a lower bound. The solution is
``d = K tau - K[:, A] K[A, A]^-1 (K tau)[A]`` for the active set A, found by a primal-dual
active-set iteration (drop a bound whose multiplier has the wrong sign, or add the most
outward-pointing bound, until neither exists): bounds whose law points inward are released, so
theta-hat never sticks. It starts from the previous tick's active set (parked on a bound, the
answer is then found in one iteration; the answer does not depend on the start), or, when there
is none, from every bound ``K tau`` points out of. The projection never increases
``theta~^T K^-1 d`` for any truth inside the box, which is what the Lyapunov argument needs. A
component that reaches its bound within the step is clipped to it (the continuous trajectory
would hit the bound mid-step and then slide).

Compiled sizes
--------------
The step, the projection and the front end's loops over n are compiled for every shipped basis's n
with constant loop lengths (:data:`.sizes.SPECIALISED_N`: 8, 13 and 13 + h, derived from the bases and the
shipped network files, not typed) and once more for any n (a user's basis). The copies run the same
sums in the same order, so they give the same numbers bit for bit
(``tests/test_adaptation_specialised.py``); the constant lengths make the composite step at n = 17
about 1.6 times as fast. Each copy costs compile time on the first import.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..frames import rows_transpose_times
from ..layout import BlockLayout, Field
from .exact_step import EXACT_WORK, constant_gain_inverse
# lowpass and lowpass_gain were this module's before the filters had a module of their own: named here too
from .filters import TINY, flush_tiny, lowpass, lowpass_gain  # noqa: F401
from .linalg import (cholesky_inline, cholesky_lower, cholesky_solve, factor_apply, factor_diag, gram_of_factor,
                     inverse_factor, inverse_factor_inline, mirror_upper)
from .sizes import N_SLOT_0, N_SLOT_1, N_SLOT_2, N_SPECIALISED_SLOTS, SPECIALISED_N

ADAPT_COMPOSITE = 0
ADAPT_PCONST = 1
ADAPT_TRACKING = 2
ADAPT_NONE = 3
ADAPT_KALMAN = 4
"""The Kalman form (Neural-Fly's Eqs. 7-9, :mod:`.kalman`): the GAMMA slot holds the covariance P, not P^-1."""

PROJECTION_MAX_ITER = 32

# --- storage -------------------------------------------------------------------------------------
# Vectors and matrices live in flat float64 arrays (in the controller, its state and parameter
# vectors) and are addressed by an offset; an n x n matrix is row-major: entry (i, j) of the one
# at offset o of x is x[o + n i + j]. The kernels take the whole array and the offset, not a
# slice: every array view handed to a compiled function costs two atomic reference-count updates
# (and a 2-D view a reshape call), about 30 ns on the 2-core machine, more than the arithmetic of
# most of these small kernels. A kernel that calls no other slices its own views at entry: there
# Numba drops their reference counting.
#
# The number of parameters n is the force-model basis's (vtoladapt.bases), so the blocks below
# are declared per n and their offsets, derived from these declarations in Python, reach the
# kernels through an offsets table (:data:`AT`, built by :func:`offsets_table`).


def memory_layout(n: int) -> BlockLayout:
    """The adaptation's memory: theta-hat, the information matrix Gamma = P^-1, the filtered
    regressor W = [Phi]_f (3 x n) and the filtered specific force a_m (body, m/s^2)."""
    return BlockLayout("adaptation memory", [
        Field("THETA", n, "adaptation units", "theta-hat"),
        Field("GAMMA", n * n, "adaptation units", "information matrix P^-1, row-major"),
        Field("W", 3 * n, "m/s^2 per adaptation unit", "filtered regressor W = [Phi]_f, row-major"),
        Field("A_M", 3, "m/s^2", "filtered specific force a_m, body axes"),
    ])


def prior_layout(n: int) -> BlockLayout:
    """The prior: theta_0, the initial theta-hat, the bounds, Gamma_0 = P_0^-1 and P_0."""
    return BlockLayout("adaptation prior", [
        Field("THETA0", n, "adaptation units", "prior mean theta_0 (sigma-modification target)"),
        Field("THETA_INIT", n, "adaptation units", "theta-hat at the start"),
        Field("LOWER", n, "adaptation units", "lower bounds of theta-hat"),
        Field("UPPER", n, "adaptation units", "upper bounds of theta-hat"),
        Field("GAMMA0", n * n, "adaptation units", "P_0^-1, row-major"),
        Field("P0", n * n, "adaptation units", "initial gain P_0, row-major"),
        Field("Q", n, "adaptation units^2/s", "Kalman form: process-noise density per weight (zeros otherwise)"),
        Field("R_MEAS", 3, "(m/s^2)^2 s", "Kalman form: measurement-noise density per body axis (zeros otherwise)"),
    ])


def work_layout(n: int) -> BlockLayout:
    """One step's scratch (meaningless between ticks); P_DIAG is the step's output.

    The projection's system (``K[A, A]`` or ``K^-1[F, F]``, at most ``n//2`` square, see
    :func:`project_direction`) and its factor, right-hand side and multipliers; the directional
    forgetting's products (:func:`directional_information_update`).
    """
    m = (n // 2) ** 2
    return BlockLayout("adaptation scratch", [
        Field("WTW", n * n, "-", "W^T W (composite), or the constant-P gain's inverse"),
        Field("M", n * n, "-", "L^-1 for the Cholesky factor L of the gain's inverse"),
        Field("L", n * n, "-", "L"),
        Field("K", n * n, "-", "the gain K, formed only to project"),
        Field("TAU", n, "-", "tau of eq:th_adapt"),
        Field("D0", n, "-", "K tau"),
        Field("D", n, "-", "its projection"),
        Field("P_DIAG", n, "adaptation units", "diag(P) after the step"),
        Field("SYSTEM", m, "-", "projection: K[A, A] or K^-1[F, F]"),
        Field("FACTOR", m, "-", "projection: its Cholesky factor"),
        Field("RHS", n, "-", "projection: right-hand side, then the solution"),
        Field("MU", n, "-", "projection: multipliers of the active bounds"),
        Field("DWT", 3 * n, "-", "directional forgetting: D W^T (n x 3)"),
        Field("SWD", 3 * n, "-", "directional forgetting: (S^-1 W D)^T (n x 3)"),
        Field("S", 9, "-", "directional forgetting: S = W Gamma W^T (3 x 3)"),
        Field("S_FACTOR", 9, "-", "directional forgetting: S's Cholesky factor"),
        Field("EXACT", EXACT_WORK.size + 3 * n, "-", "the constant-P law's exact step (exact_step.EXACT_WORK, "
              "then W^T S, n x 3)"),
    ])


AT = BlockLayout("adaptation offsets", [
    Field("N", 1, "-", "number of parameters n (the basis's)"),
    Field("COVARIANCE", 1, "-", "1: the GAMMA slot holds the covariance P (the Kalman form), 0: P^-1"),
    *(Field(name, 1, "-", f"offset of the memory's {name} in the memory array")
      for name in ("THETA", "GAMMA", "W", "A_M")),
    *(Field(name, 1, "-", f"offset of the prior's {name} in the prior array")
      for name in ("THETA0", "THETA_INIT", "LOWER", "UPPER", "GAMMA0", "P0", "Q", "R_MEAS")),
    *(Field(name, 1, "-", f"offset of the scratch's {name} in the memory array")
      for name in ("WTW", "M", "L", "K", "TAU", "D0", "D", "P_DIAG", "SYSTEM", "FACTOR", "RHS", "MU",
                   "DWT", "SWD", "S", "S_FACTOR", "EXACT")),
])
"""Where the blocks sized by n are: one slot per offset (absolute, in the arrays the kernels get)."""
(AT_N, AT_COVARIANCE, AT_THETA, AT_GAMMA, AT_W, AT_A_M, AT_THETA0, AT_THETA_INIT, AT_LOWER, AT_UPPER, AT_GAMMA0,
 AT_P0, AT_Q, AT_R_MEAS, AT_WTW, AT_M, AT_L, AT_K, AT_TAU, AT_D0, AT_D, AT_P_DIAG, AT_SYSTEM, AT_FACTOR, AT_RHS,
 AT_MU, AT_DWT, AT_SWD, AT_S, AT_S_FACTOR, AT_EXACT) = AT.offsets(*(f.name for f in AT.fields))


def standalone_arrays(n: int, covariance: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(at, x, prior)`` for one adaptation of n parameters outside the controller (replay, tests): the
    offsets table, the memory followed by the scratch in ``x`` and the prior in ``prior`` (zeros; fill them
    through :func:`memory_layout` and :func:`prior_layout`, e.g. ``memory_layout(n).view(x, "THETA")``)."""
    memory, work, prior = memory_layout(n), work_layout(n), prior_layout(n)
    return (offsets_table(n, 0, 0, memory.size, covariance), np.zeros(memory.size + work.size),
            np.zeros(prior.size))


def offsets_table(n: int, memory_at: int, prior_at: int, work_at: int, covariance: bool = False) -> np.ndarray:
    """The :data:`AT` table of n parameters whose memory starts at ``memory_at`` and scratch at
    ``work_at`` (of the memory array) and prior at ``prior_at`` (of the prior array); ``covariance``:
    the GAMMA slot holds P (the Kalman form, :mod:`.kalman`), not P^-1."""
    mem, prior, work = memory_layout(n), prior_layout(n), work_layout(n)
    values = {"N": n, "COVARIANCE": float(covariance)}
    values.update({f.name: memory_at + mem.offset(f.name) for f in mem.fields})
    values.update({f.name: prior_at + prior.offset(f.name) for f in prior.fields})
    values.update({f.name: work_at + work.offset(f.name) for f in work.fields})
    return AT.pack(**values)


# --- small dense linear algebra: vtoladapt.control.linalg ----------------------------------------
# The small kernels the step calls are inlined into it (``inline="always"``): the step is compiled for
# each shipped basis's n as a constant (SPECIALISED_N), and only inlined code sees that constant and runs
# loops of constant length. The projection, too large to inline into every copy of the step, specialises
# itself the same way.


# --- the prediction error (its filters: vtoladapt.control.filters) -----------------------------

@njit(cache=True, error_model="numpy", inline="always")
def prediction_error(W, w, theta, t, a_m, m, n) -> tuple:
    """Prediction error ``e = W theta-hat - a_m`` (eq:prediction_error), body axes, m/s^2 (3-tuple).

    ``W`` (3 x n) at ``W[w:]``, theta-hat at ``theta[t:]``, ``a_m`` at ``a_m[m:]``.
    """
    W = W[w:w + 3 * n]
    theta = theta[t:t + n]
    e0 = -a_m[m]
    e1 = -a_m[m + 1]
    e2 = -a_m[m + 2]
    for j in range(n):
        e0 += W[j] * theta[j]
        e1 += W[n + j] * theta[j]
        e2 += W[2 * n + j] * theta[j]
    return e0, e1, e2


@njit(cache=True, error_model="numpy", inline="always")
def gram(W, w, G, g, n) -> None:
    """``G = W^T W`` (n x n, exactly symmetric) for the 3 x n ``W`` at ``W[w:]``."""
    W = W[w:w + 3 * n]
    G = G[g:g + n * n]
    # the upper triangle by rows (contiguous: vectorised), then mirrored; each sum 0 + row 0 + row 1 + row 2
    for i in range(n):
        w0, w1, w2 = W[i], W[n + i], W[2 * n + i]
        for j in range(i, n):
            G[n * i + j] = 0.0 + w0 * W[j] + w1 * W[n + j] + w2 * W[2 * n + j]
    mirror_upper(G, 0, n)


@njit(cache=True)
def forgetting_weights(lam: float, dt: float) -> tuple:
    """``(a, b)`` of the exact information step: ``a = exp(-lambda dt)``, ``b = (1 - a)/lambda`` (``dt`` at 0)."""
    if lam > 0.0:
        return np.exp(-lam * dt), -np.expm1(-lam * dt) / lam
    return 1.0, dt


@njit(cache=True, error_model="numpy", inline="always")
def information_update(Gamma, g, Gamma0, g0, WtW, h, a, b, n, toward_prior=1.0) -> None:
    """One exact step of ``Gamma' = W^T W - lambda (Gamma - Gamma_0)`` (eq:P_adapt, information form).

    ``Gamma <- a Gamma + (1 - a) Gamma_0 + b W^T W`` in place, with ``(a, b)`` from
    :func:`forgetting_weights` (n x n matrices at ``Gamma[g:]``, ``Gamma0[g0:]``, ``WtW[h:]``).
    ``toward_prior = 0``: the paper's pure forgetting ``Gamma' = W^T W - lambda Gamma`` (P winds up
    where W does not excite; measured against the shipped law in the README, "Deviations").
    """
    Gamma = Gamma[g:g + n * n]
    Gamma0 = Gamma0[g0:g0 + n * n]
    WtW = WtW[h:h + n * n]
    c = toward_prior * (1.0 - a)
    for i in range(n):
        for j in range(i, n):
            Gamma[n * i + j] = flush_tiny(a * Gamma[n * i + j] + c * Gamma0[n * i + j] + b * WtW[n * i + j])
    mirror_upper(Gamma, 0, n)


@njit(cache=True, error_model="numpy", inline="always")
def cap_information(Gamma, g, Gamma0, g0, trace_max, n) -> bool:
    """Scale the data part ``Gamma - Gamma_0`` so its trace is at most ``trace_max``; True if capped."""
    Gamma = Gamma[g:g + n * n]
    Gamma0 = Gamma0[g0:g0 + n * n]
    tr = 0.0
    for i in range(n):
        tr += Gamma[n * i + i] - Gamma0[n * i + i]
    if tr <= trace_max:
        return False
    s = trace_max / tr
    for i in range(n * n):
        Gamma[i] = Gamma0[i] + s * (Gamma[i] - Gamma0[i])
    return True


@njit(cache=True, error_model="numpy")
def directional_information_update(Gamma, g, Gamma0, g0, W, wf, WtW, h, a, b, x, dwt, swd, sm, sf, n) -> None:
    """One step of directional forgetting: ``Gamma' = W^T W - lambda M`` (information form, not in the paper).

    ``M = D W^T (W Gamma W^T)^-1 W D`` with ``D = Gamma - Gamma_0`` (the data part of the
    information): the information is forgotten only along the directions the current regressor
    ``W`` excites (Bittanti et al. 1990 and Cao & Schwartz 2000 forget along the current
    regressor; here in the information form, toward the prior). Directions ``W`` does not see
    keep their information, so theta-hat does not drift along them while others are excited.
    Since ``W Gamma W^T >= W D W^T``, ``0 <= M <= D``: ``Gamma_k+1 >= Gamma_0`` stays SPD, and the
    forgetting part of the Lyapunov derivative, ``-lambda theta~^T M theta~ / 2``, is <= 0.

    Discretised like :func:`information_update`: ``Gamma <- Gamma - (1 - a) M + b W^T W``, ``M``
    from the Gamma before the step. ``W`` (3 x n) at ``W[wf:]``, ``W^T W`` at ``WtW[h:]``; scratch
    in ``x`` (:func:`work_layout`): ``D W^T`` (n x 3) at ``dwt``, ``(S^-1 W D)^T`` at ``swd``,
    ``S = W Gamma W^T`` (3 x 3) at ``sm`` and its factor at ``sf``. ``S`` gets a ``1e-12``
    relative ridge so that a rank-deficient ``W`` (a zero row) forgets nothing along the missing row.
    """
    Gamma = Gamma[g:g + n * n]
    Gamma0 = Gamma0[g0:g0 + n * n]
    W = W[wf:wf + 3 * n]
    WtW = WtW[h:h + n * n]
    for i in range(n):
        for r in range(3):
            t = 0.0
            for j in range(n):
                t += (Gamma[n * i + j] - Gamma0[n * i + j]) * W[n * r + j]
            x[dwt + 3 * i + r] = t
    tr = 0.0
    for r in range(3):
        for c in range(r, 3):
            t = 0.0
            for i in range(n):
                gi = 0.0
                for j in range(n):
                    gi += Gamma[n * i + j] * W[n * c + j]
                t += W[n * r + i] * gi
            x[sm + 3 * r + c] = t
            x[sm + 3 * c + r] = t
        tr += x[sm + 4 * r]
    ridge = 1e-12 * tr + TINY
    for r in range(3):
        x[sm + 4 * r] += ridge
    ok = cholesky_lower(x, sm, x, sf, 3)
    for i in range(n):
        for r in range(3):
            x[swd + 3 * i + r] = x[dwt + 3 * i + r]
        if ok:
            cholesky_solve(x, sf, 3, x, swd + 3 * i)
    c = 1.0 - a
    for i in range(n):
        for j in range(i, n):
            m_ij = 0.0
            if ok:
                m_ij = (x[dwt + 3 * i] * x[swd + 3 * j] + x[dwt + 3 * i + 1] * x[swd + 3 * j + 1]
                        + x[dwt + 3 * i + 2] * x[swd + 3 * j + 2])
            v = flush_tiny(Gamma[n * i + j] - c * m_ij + b * WtW[n * i + j])
            Gamma[n * i + j] = v
            Gamma[n * j + i] = v


# --- projection ----------------------------------------------------------------------------------

@njit(cache=True, error_model="numpy", inline="always")
def bound_sides(theta, t, lower, lo, upper, up, n) -> tuple:
    """Which components of theta-hat (at ``theta[t:]``) sit on a bound: ``(at_upper, at_lower)`` bit masks.

    Bit ``i`` is set if component ``i`` is within ``1e-12 max(1, upper - lower)`` of that bound
    (bounds at ``lower[lo:]``, ``upper[up:]``).
    """
    theta = theta[t:t + n]
    lower = lower[lo:lo + n]
    upper = upper[up:up + n]
    at_upper = 0
    at_lower = 0
    for i in range(n):
        tol = 1e-12 * max(1.0, upper[i] - lower[i])
        if theta[i] >= upper[i] - tol:
            at_upper |= 1 << i
        elif theta[i] <= lower[i] + tol:
            at_lower |= 1 << i
    return at_upper, at_lower


@njit(cache=True)
def _side(at_upper, at_lower, i) -> float:
    """+1 at the upper bound, -1 at the lower bound, 0 inside."""
    if (at_upper >> i) & 1:
        return 1.0
    if (at_lower >> i) & 1:
        return -1.0
    return 0.0


@njit(cache=True, error_model="numpy", _nrt=False)
def project_direction(K, k, G, g, x, tau, d0, d, sa, sl, rhs, mu, at_upper, at_lower, active_start, n) -> tuple:
    """Project the update direction ``d0 = K tau`` onto the box's tangent cone in the K-metric.

    For an active set A (free set F) the projection holds ``d_A = 0`` and is either
    ``d = d0 - K[:, A] mu`` with ``mu = K[A, A]^-1 d0[A]``, or, the same by the Schur complement
    of ``G = K^-1``, ``d_F = G[F, F]^-1 tau[F]`` with ``mu = tau[A] - G[A, F] d_F`` (the
    multipliers). Each iteration solves the smaller of the two systems (at most n//2 square).

    Parameters
    ----------
    K, k : the n x n SPD gain at ``K[k:]`` (the metric is ``K^-1``).
    G, g : its inverse ``K^-1`` at ``G[g:]``.
    x : array holding ``tau`` (at ``x[tau:]``), ``d0 = K tau`` (at ``x[d0:]``), the output ``d``
        (at ``x[d:]``) and the scratch of :func:`work_layout`: the system at ``sa``, its factor at
        ``sl`` (``(n//2)^2`` each), the right-hand side at ``rhs`` and the multipliers at ``mu``.
    at_upper, at_lower : bit masks of the components at a bound (:func:`bound_sides`).
    active_start : bit mask of the bounds to start the active-set iteration from (the previous
        tick's answer); those not at a bound now are dropped, and if none is left the iteration
        starts from every bound ``d0`` leaves. The answer does not depend on the start (the
        problem is strictly convex), only the number of iterations does.

    Returns
    -------
    (n_active, active)
        Number of active bounds (0 if none), or -1 if the iteration limit was reached (``d`` is
        then the last iterate, and the caller's clip keeps theta-hat inside); and their bit mask.
    """
    # only the paper's n (the smallest shipped size) with constant loops: the projection runs on the ticks
    # a bound is held, and a copy per shipped size cost more first-import compile time than it saved
    if n == N_SLOT_0:
        return _project(K, k, G, g, x, tau, d0, d, sa, sl, rhs, mu, at_upper, at_lower, active_start, N_SLOT_0)
    return _project(K, k, G, g, x, tau, d0, d, sa, sl, rhs, mu, at_upper, at_lower, active_start, n)


@njit(cache=True, error_model="numpy", inline="always")
def _project(K, k, G, g, x, tau, d0, d, sa, sl, rhs, mu, at_upper, at_lower, active_start, n) -> tuple:
    """The body of :func:`project_direction` (inlined into it for the paper's n and for any n)."""
    for i in range(n):
        x[d + i] = x[d0 + i]
    if at_upper == 0 and at_lower == 0:
        return 0, 0
    # mu: the multipliers of the active bounds, in index order
    active = active_start & (at_upper | at_lower)
    if active == 0:
        # every bound the unconstrained direction leaves
        for i in range(n):
            if _side(at_upper, at_lower, i) * x[d0 + i] > 0.0:
                active |= 1 << i
    for _ in range(PROJECTION_MAX_ITER):
        m = 0
        for i in range(n):
            x[d + i] = x[d0 + i]
            if (active >> i) & 1:
                m += 1
        if m > 0:
            # the system on the held set (K[A, A]) or on the free set (G[F, F]), whichever is smaller
            on_free = m > n - m
            ms = n - m if on_free else m
            a = 0
            for i in range(n):
                if ((active >> i) & 1) != on_free:
                    x[rhs + a] = x[tau + i] if on_free else x[d0 + i]
                    b = 0
                    for j in range(n):
                        if ((active >> j) & 1) != on_free:
                            x[sa + ms * a + b] = G[g + n * i + j] if on_free else K[k + n * i + j]
                            b += 1
                    a += 1
            if not cholesky_lower(x, sa, x, sl, ms):
                return -1, active
            cholesky_solve(x, sl, ms, x, rhs)
            if on_free:
                # d_F = G[F, F]^-1 tau[F], d_A = 0; mu = tau[A] - G[A, F] d_F
                a = 0
                c = 0
                for i in range(n):
                    if (active >> i) & 1:
                        t = x[tau + i]
                        b = 0
                        for j in range(n):
                            if not (active >> j) & 1:
                                t -= G[g + n * i + j] * x[rhs + b]
                                b += 1
                        x[mu + c] = t
                        x[d + i] = 0.0
                        c += 1
                    else:
                        x[d + i] = x[rhs + a]
                        a += 1
            else:
                # mu = K[A, A]^-1 d0[A]; d = d0 - K[:, A] mu, d_A = 0
                for a in range(m):
                    x[mu + a] = x[rhs + a]
                for i in range(n):
                    t = 0.0
                    a = 0
                    for j in range(n):
                        if (active >> j) & 1:
                            t += K[k + n * i + j] * x[mu + a]
                            a += 1
                    x[d + i] -= t
                for i in range(n):
                    if (active >> i) & 1:
                        x[d + i] = 0.0
            # dual feasibility: the multiplier side * mu must be >= 0
            worst = -1
            worst_val = 0.0
            a = 0
            for i in range(n):
                if (active >> i) & 1:
                    v = _side(at_upper, at_lower, i) * x[mu + a]
                    if v < worst_val:
                        worst_val = v
                        worst = i
                    a += 1
            if worst >= 0:
                active &= ~(1 << worst)
                continue
        # primal feasibility: no inactive bound may point outward
        worst = -1
        worst_val = 0.0
        for i in range(n):
            if not (active >> i) & 1:
                v = _side(at_upper, at_lower, i) * x[d + i]
                if v > worst_val:
                    worst_val = v
                    worst = i
        if worst >= 0:
            active |= 1 << worst
            continue
        return m, active
    return -1, active


# --- the adaptation step ----------------------------------------------------------------------

@njit(cache=True, error_model="numpy")
def adaptation_step(mode, at, a, x, prior, Phi, phi, R, v_tilde_W, dt, forget_a, forget_b, sigma, trace_max,
                    active_set) -> tuple:
    """One tick of eq:th_adapt and eq:P_adapt, the paper's law: :func:`weighted_adaptation_step` with
    unit weights, forgetting toward the prior and the gain ``P0`` (tracking mode)."""
    return weighted_adaptation_step(mode, at, a, x, prior, Phi, phi, R, v_tilde_W, dt, forget_a, forget_b, sigma,
                                    trace_max, active_set, 1.0, 1.0, False, 1.0)


@njit(cache=True, error_model="numpy", _nrt=False)
def weighted_adaptation_step(mode, at, a, x, prior, Phi, phi, R, v_tilde_W, dt, forget_a, forget_b, sigma,
                             trace_max, active_set, w_track, w_pred, directional, gain_scale,
                             toward_prior=1.0) -> tuple:
    """One tick of eq:th_adapt and eq:P_adapt (see the module notes), in place.

    The paper's law is ``w_track = w_pred = gain_scale = 1``, ``directional = False``
    (:func:`adaptation_step`). The extensions (none in the paper, see the laws' modules):
    ``tau = w_track Phi^T R^T v~ - w_pred W^T e - sigma (theta-hat - theta_0)`` and the
    information increment ``w_pred W^T W`` (weights in [0, 1] saying how far the linear model is
    trusted this tick); ``directional``: the composite mode forgets only along the excited
    directions (:func:`directional_information_update`); ``gain_scale``: the tracking mode's
    gain is ``gain_scale P0``; ``toward_prior`` 0: the paper's pure forgetting (:func:`information_update`).

    Parameters
    ----------
    mode : ADAPT_COMPOSITE, ADAPT_PCONST, ADAPT_TRACKING or ADAPT_NONE.
    at, a : the offsets table (:data:`AT`, from :func:`offsets_table`) at ``at[a:]``: n and where
        the memory, the scratch (in ``x``) and the prior (in ``prior``) are.
    x : array holding the adaptation's memory (:func:`memory_layout`: theta-hat and Gamma = P^-1
        are updated, W = [Phi]_f and a_m read) and its scratch (:func:`work_layout`); on return
        the scratch's ``P_DIAG`` holds the diagonal of P after the update (of ``P0`` for the
        constant-P modes).
    prior : array holding the prior (:func:`prior_layout`: theta_0, bounds, Gamma_0, P_0).
    Phi, phi : the unfiltered regressor (3 x n, row-major) at ``Phi[phi:]``, at the current
        airflow and the throttles that produced the measured force.
    R : attitude ``R_WB`` (three rows of 3).
    v_tilde_W : (3,) velocity error ``v - v_r`` (m/s, NED).
    dt : float, tick (s).
    forget_a, forget_b : :func:`forgetting_weights` of the forgetting rate (1/s) and ``dt``.
    sigma, trace_max : sigma-modification, information-trace cap.
    w_track, w_pred, directional, gain_scale, toward_prior : the extensions above.
    active_set : bit mask of the bounds the previous step's projection held (0 if none): where
        this step's projection starts (:func:`project_direction`).

    Returns
    -------
    (n_active, active_set, e)
        Number of active bounds, or -1 if the projection hit its iteration limit, or -2 if the
        gain could not be formed (the update is then skipped; cannot happen for finite inputs);
        the bit mask of the active bounds; and the prediction error before the update
        (eq:prediction_error, 3-tuple).
    """
    n = int(at[a + AT_N])
    e = prediction_error(x, int(at[a + AT_W]), x, int(at[a + AT_THETA]), x, int(at[a + AT_A_M]), n)
    n_active, active = adaptation_step_with_error(mode, at, a, x, prior, Phi, phi, R, v_tilde_W, dt, forget_a,
                                                  forget_b, sigma, trace_max, active_set, w_track, w_pred,
                                                  directional, gain_scale, e, toward_prior)
    return n_active, active, e


@njit(cache=True, error_model="numpy", _nrt=False)
def adaptation_step_with_error(mode, at, a, x, prior, Phi, phi, R, v_tilde_W, dt, forget_a, forget_b, sigma,
                               trace_max, active_set, w_track, w_pred, directional, gain_scale, e,
                               toward_prior=1.0) -> tuple:
    """:func:`weighted_adaptation_step` given the prediction error ``e`` (eq:prediction_error, before the
    update: what the controller's front end has formed already); returns ``(n_active, active_set)``.

    Compiled for each shipped basis's n (:data:`SPECIALISED_N`, every loop of constant length) and for
    any n; they give the same numbers, the first in half to two thirds of the time.
    """
    n = int(at[a + AT_N])
    if n == N_SLOT_0:
        return _step(mode, at, a, x, prior, Phi, phi, R, v_tilde_W, dt, forget_a, forget_b, sigma, trace_max,
                     active_set, w_track, w_pred, directional, gain_scale, e, N_SLOT_0, toward_prior)
    if n == N_SLOT_1:
        return _step(mode, at, a, x, prior, Phi, phi, R, v_tilde_W, dt, forget_a, forget_b, sigma, trace_max,
                     active_set, w_track, w_pred, directional, gain_scale, e, N_SLOT_1, toward_prior)
    if n == N_SLOT_2:
        return _step(mode, at, a, x, prior, Phi, phi, R, v_tilde_W, dt, forget_a, forget_b, sigma, trace_max,
                     active_set, w_track, w_pred, directional, gain_scale, e, N_SLOT_2, toward_prior)
    return _step(mode, at, a, x, prior, Phi, phi, R, v_tilde_W, dt, forget_a, forget_b, sigma, trace_max,
                 active_set, w_track, w_pred, directional, gain_scale, e, n, toward_prior)


@njit(cache=True, error_model="numpy", inline="always")
def _step(mode, at, a, x, prior, Phi, phi, R, v_tilde_W, dt, forget_a, forget_b, sigma, trace_max, active_set,
          w_track, w_pred, directional, gain_scale, e, n, toward_prior) -> tuple:
    """The body of :func:`adaptation_step_with_error` for ``n`` parameters (inlined: a constant ``n`` makes
    every loop below of constant length)."""
    th = int(at[a + AT_THETA])
    gam = int(at[a + AT_GAMMA])
    wf = int(at[a + AT_W])
    if mode == ADAPT_NONE:
        return 0, 0
    tau = int(at[a + AT_TAU])
    d0 = int(at[a + AT_D0])
    p_diag = int(at[a + AT_P_DIAG])
    theta0 = int(at[a + AT_THETA0])
    lower = int(at[a + AT_LOWER])
    upper = int(at[a + AT_UPPER])
    gamma0 = int(at[a + AT_GAMMA0])
    p0 = int(at[a + AT_P0])
    # tau = Phi^T R^T v~ - W^T e - sigma (theta - theta0)
    rv0, rv1, rv2 = rows_transpose_times(R, v_tilde_W)
    for k in range(n):
        t = w_track * (Phi[phi + k] * rv0 + Phi[phi + n + k] * rv1 + Phi[phi + 2 * n + k] * rv2) \
            - sigma * (x[th + k] - prior[theta0 + k])
        if mode != ADAPT_TRACKING:
            t -= w_pred * (x[wf + k] * e[0] + x[wf + n + k] * e[1] + x[wf + 2 * n + k] * e[2])
        x[tau + k] = t
    at_upper, at_lower = bound_sides(x, th, prior, lower, prior, upper, n)
    bounded = at_upper != 0 or at_lower != 0
    n_active = 0
    active = 0
    d = int(at[a + AT_D])
    sa, sl, rhs, mu = int(at[a + AT_SYSTEM]), int(at[a + AT_FACTOR]), int(at[a + AT_RHS]), int(at[a + AT_MU])
    if mode == ADAPT_TRACKING:
        # K = gain_scale P0. The direction P0 tau is projected with P0 and its inverse, then scaled:
        # the projection of k P0 tau in the metric (k P0)^-1 is k times that of P0 tau in the metric
        # P0^-1. (Projecting k P0 tau with P0's matrices mixed the two: the free-set system
        # K^-1[F, F], solved when five or more bounds are held, gave P0's free step whatever k.)
        for i in range(n):
            x[p_diag + i] = gain_scale * prior[p0 + n * i + i]
            t = 0.0
            for j in range(n):
                t += prior[p0 + n * i + j] * x[tau + j]
            x[d0 + i] = t
        if bounded:
            n_active, active = project_direction(prior, p0, prior, gamma0, x, tau, d0, d, sa, sl, rhs, mu,
                                                 at_upper, at_lower, active_set, n)
        scaled = d if bounded else d0
        for i in range(n):
            x[scaled + i] *= gain_scale
    else:
        G = int(at[a + AT_WTW])
        gram(x, wf, x, G, n)
        if mode == ADAPT_COMPOSITE:
            # Gamma_k+1 = a Gamma_k + (1 - a) Gamma_0 + b W^T W; K = Gamma_k+1^-1 (before the cap)
            if directional:
                # forgetting tied to the excitation: a rejected tick (w_pred = 0) neither adds nor forgets
                directional_information_update(x, gam, prior, gamma0, x, wf, x, G, 1.0 - w_pred * (1.0 - forget_a),
                                               w_pred * forget_b, x, int(at[a + AT_DWT]), int(at[a + AT_SWD]),
                                               int(at[a + AT_S]), int(at[a + AT_S_FACTOR]), n)
            else:
                information_update(x, gam, prior, gamma0, x, G, forget_a, w_pred * forget_b, n, toward_prior)
            G = gam
        else:
            # P = P0, solved exactly over the tick: K = phi(dt P0 W^T W) P0, formed as its inverse
            for i in range(n):
                x[p_diag + i] = prior[p0 + n * i + i]
            constant_gain_inverse(x, wf, prior, p0, gamma0, G, int(at[a + AT_EXACT]), w_pred * dt, n)
        M = int(at[a + AT_M])
        L = int(at[a + AT_L])
        if not cholesky_inline(x, G, x, L, n):
            if mode == ADAPT_COMPOSITE:
                for i in range(n * n):
                    x[gam + i] = prior[gamma0 + i]
            return -2, active_set
        inverse_factor_inline(x, L, x, M, n)
        for i in range(n):
            x[d0 + i] = x[tau + i]
        factor_apply(x, M, x, d0, n)
        if bounded:
            # K = M^T M and K^-1 = G (Gamma before the cap below)
            K = int(at[a + AT_K])
            gram_of_factor(x, M, x, K, n)
            n_active, active = project_direction(x, K, x, G, x, tau, d0, d, sa, sl, rhs, mu, at_upper, at_lower,
                                                 active_set, n)
        if mode == ADAPT_COMPOSITE:
            factor_diag(x, M, x, p_diag, n)
            if cap_information(x, gam, prior, gamma0, trace_max, n):
                if cholesky_lower(x, gam, x, L, n):
                    inverse_factor(x, L, x, M, n)
                    factor_diag(x, M, x, p_diag, n)
    step = d if bounded else d0
    for i in range(n):
        lo = prior[lower + i]
        hi = prior[upper + i]
        v = flush_tiny(x[th + i] + dt * x[step + i])
        if not np.isfinite(v):
            v = x[th + i]
        x[th + i] = min(max(v, lo), hi)
    return n_active, active


@njit(cache=True)
def lyapunov_function(v_tilde, q0_tilde, theta_hat, P_inv, theta_true, gamma) -> float:
    """The proof's ``V = v~^T v~ / 2 + (2 - 2 q~_0)/gamma + theta~^T P^-1 theta~ / 2`` (Theorem).

    ``theta~ = theta-hat - theta``; ``theta_true`` comes from the simulator's plant (the controller
    never sees it); ``P_inv`` is the controller's information matrix (n x n). With an empty
    ``theta_true`` (a basis that has no plant truth, :func:`vtoladapt.bases.truth_of`) the parameter
    term is left out.
    """
    return lyapunov_at(v_tilde[0], v_tilde[1], v_tilde[2], q0_tilde, theta_hat, 0,
                       np.ascontiguousarray(P_inv).ravel(), 0, theta_true, gamma)


@njit(cache=True, _nrt=False)
def lyapunov_at(v0, v1, v2, q0_tilde, theta_buf, i_theta, P_inv_buf, i_P_inv, theta_true, gamma) -> float:
    """:func:`lyapunov_function` with ``theta-hat`` at ``theta_buf[i_theta:]`` and ``P^-1`` (n x n,
    row-major) at ``P_inv_buf[i_P_inv:]``: the simulator's log reads them from the controller state
    by offset every tick, without array views."""
    V = 0.5 * (v0 ** 2 + v1 ** 2 + v2 ** 2) + (2.0 - 2.0 * q0_tilde) / gamma
    n = theta_true.shape[0]
    q = 0.0
    for i in range(n):
        di = theta_buf[i_theta + i] - theta_true[i]
        for j in range(n):
            q += di * P_inv_buf[i_P_inv + n * i + j] * (theta_buf[i_theta + j] - theta_true[j])
    return V + 0.5 * q


__all__ = ["ADAPT_COMPOSITE", "ADAPT_KALMAN", "ADAPT_NONE", "ADAPT_PCONST", "ADAPT_TRACKING", "AT", "N_SLOT_0",
           "N_SLOT_1", "N_SLOT_2",
           "N_SPECIALISED_SLOTS", "SPECIALISED_N", "AT_A_M",
           "AT_COVARIANCE", "AT_Q", "AT_R_MEAS",
           "AT_D", "AT_D0", "AT_DWT", "AT_FACTOR", "AT_GAMMA", "AT_GAMMA0", "AT_K", "AT_L", "AT_LOWER", "AT_M",
           "AT_MU", "AT_N", "AT_P0", "AT_P_DIAG", "AT_RHS", "AT_S", "AT_SWD", "AT_SYSTEM", "AT_S_FACTOR", "AT_TAU",
           "AT_THETA", "AT_THETA0", "AT_THETA_INIT", "AT_UPPER", "AT_W", "AT_WTW", "adaptation_step",
           "adaptation_step_with_error", "bound_sides", "cap_information", "directional_information_update",
           "forgetting_weights", "gram", "information_update",
           "lyapunov_at", "lyapunov_function", "memory_layout", "offsets_table", "prediction_error",
           "prior_layout", "project_direction", "standalone_arrays", "weighted_adaptation_step", "work_layout"]
