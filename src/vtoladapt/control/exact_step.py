"""The constant-P law's step solved exactly over the tick (:mod:`.adaptation`, composite_pconst).

``theta' = P_0 (c - A theta)`` with ``A = w W^T W`` and everything held over the tick has the
solution ``theta_k+1 = theta_k + dt phi(dt P_0 A) P_0 tau_k``, ``phi(X) = X^-1 (I - e^-X)``. Its
gain is formed through the 3 x 3 ``B = W P_0 W^T`` (push-through identity), inverted:

    K^-1 = Gamma_0 + W^T Q diag(w dt psi(x) / phi(x)) Q^T W,   B = Q diag(b) Q^T,  x = w dt b,

``psi(x) = (1 - phi(x)) / x``: Woodbury's inverse of ``K = P_0 - P_0 W^T Q diag(w dt psi(x)) Q^T
W P_0``. Pure functions of flat arrays and offsets, no allocation (compiled into the tick).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..layout import BlockLayout, Field

EXACT_WORK = BlockLayout("constant-P exact step scratch", [
    Field("B", 9, "-", "B = W P0 W^T (3 x 3), then its eigenvalues on the diagonal"),
    Field("Q", 9, "-", "its eigenvectors (columns, row-major)"),
    Field("S", 9, "-", "S = Q diag(m) Q^T"),
])
"""The fixed part of :func:`constant_gain_inverse`'s scratch; ``W^T S`` (n x 3) follows it."""
EX_B, EX_Q, EX_S = EXACT_WORK.offsets("B", "Q", "S")
EX_WS = EXACT_WORK.size
"""Where ``W^T S`` starts in the scratch."""


@njit(cache=True, error_model="numpy")
def symmetric_eigen3(A, a, Q, q) -> None:
    """Eigen-decomposition of the symmetric 3 x 3 matrix at ``A[a:]`` by cyclic Jacobi rotations.

    ``A`` is overwritten: its diagonal becomes the eigenvalues (off-diagonal ~0); ``Q[q:]`` gets
    the eigenvectors as columns (row-major, orthonormal), ``A_in = Q diag Q^T``. Each rotation
    zeroes one off-diagonal entry exactly (Numerical Recipes' form); sweeps stop once the
    off-diagonal part is below 1e-30 of the diagonal's square (a few sweeps: quadratic convergence).
    """
    for i in range(3):
        for j in range(3):
            Q[q + 3 * i + j] = 1.0 if i == j else 0.0
    for _ in range(32):
        off = A[a + 1] ** 2 + A[a + 2] ** 2 + A[a + 5] ** 2
        dg = A[a] ** 2 + A[a + 4] ** 2 + A[a + 8] ** 2
        if not off > 1e-30 * dg:
            return
        for pr in range(3):
            ip = 0 if pr < 2 else 1
            ir = pr + 1 if pr < 2 else 2
            apr = A[a + 3 * ip + ir]
            if apr == 0.0:
                continue
            app = A[a + 4 * ip]
            arr = A[a + 4 * ir]
            h = (arr - app) / (2.0 * apr)
            if abs(h) > 1e150:
                t = 0.5 / h
            else:
                t = 1.0 / (abs(h) + np.sqrt(h * h + 1.0))
                if h < 0.0:
                    t = -t
            c = 1.0 / np.sqrt(t * t + 1.0)
            sn = t * c
            k = 3 - ip - ir
            akp = A[a + 3 * k + ip]
            akr = A[a + 3 * k + ir]
            A[a + 3 * k + ip] = c * akp - sn * akr
            A[a + 3 * ip + k] = A[a + 3 * k + ip]
            A[a + 3 * k + ir] = sn * akp + c * akr
            A[a + 3 * ir + k] = A[a + 3 * k + ir]
            A[a + 4 * ip] = app - t * apr
            A[a + 4 * ir] = arr + t * apr
            A[a + 3 * ip + ir] = 0.0
            A[a + 3 * ir + ip] = 0.0
            for m in range(3):
                qp = Q[q + 3 * m + ip]
                qr = Q[q + 3 * m + ir]
                Q[q + 3 * m + ip] = c * qp - sn * qr
                Q[q + 3 * m + ir] = sn * qp + c * qr


@njit(cache=True)
def phi_psi(x: float) -> tuple:
    """``(phi(x), psi(x))`` for ``x >= 0``: ``phi = (1 - e^-x)/x``, ``psi = (1 - phi)/x = (x - 1 + e^-x)/x^2``.

    Their series below ``x = 0.01`` (truncation below 3e-17), so neither cancels.
    """
    if x < 0.01:
        psi = 0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0 - x * (1.0 / 120.0 - x * (1.0 / 720.0 - x / 5040.0))))
        return 1.0 - x * psi, psi
    em = np.expm1(-x)
    return -em / x, (x + em) / (x * x)


@njit(cache=True, error_model="numpy")
def constant_gain_inverse(x, wf, prior, p0, g0, g, scratch, w_dt, n) -> None:
    """``G = K^-1 = Gamma_0 + W^T Q diag(w_dt psi/phi) Q^T W`` of the constant-P step (module notes).

    ``W`` (3 x n) at ``x[wf:]``, ``P_0`` and ``Gamma_0`` (n x n) at ``prior[p0:]``, ``prior[g0:]``;
    ``G`` written at ``x[g:]`` (n x n, exactly symmetric); ``x[scratch:]`` holds :data:`EXACT_WORK`
    then ``W^T S`` (n x 3): ``EXACT_WORK.size + 3 n`` floats; ``w_dt`` is the prediction-error weight
    times ``dt``.
    """
    b = scratch + EX_B
    qv = scratch + EX_Q
    sm = scratch + EX_S
    ws = scratch + EX_WS
    for r in range(3):
        for c in range(r, 3):
            t = 0.0
            for i in range(n):
                u = 0.0
                for j in range(n):
                    u += prior[p0 + n * i + j] * x[wf + n * c + j]
                t += x[wf + n * r + i] * u
            x[b + 3 * r + c] = t
            x[b + 3 * c + r] = t
    symmetric_eigen3(x, b, x, qv)
    m0 = 0.0
    m1 = 0.0
    m2 = 0.0
    for r in range(3):
        ph, ps = phi_psi(w_dt * max(x[b + 4 * r], 0.0))
        m = w_dt * ps / ph
        if r == 0:
            m0 = m
        elif r == 1:
            m1 = m
        else:
            m2 = m
    for r in range(3):
        for c in range(r, 3):
            t = (x[qv + 3 * r] * m0 * x[qv + 3 * c] + x[qv + 3 * r + 1] * m1 * x[qv + 3 * c + 1]
                 + x[qv + 3 * r + 2] * m2 * x[qv + 3 * c + 2])
            x[sm + 3 * r + c] = t
            x[sm + 3 * c + r] = t
    for i in range(n):
        for c in range(3):
            x[ws + 3 * i + c] = (x[wf + i] * x[sm + c] + x[wf + n + i] * x[sm + 3 + c]
                                 + x[wf + 2 * n + i] * x[sm + 6 + c])
    for i in range(n):
        for j in range(i, n):
            v = prior[g0 + n * i + j] + (x[ws + 3 * i] * x[wf + j] + x[ws + 3 * i + 1] * x[wf + n + j]
                                         + x[ws + 3 * i + 2] * x[wf + 2 * n + j])
            x[g + n * i + j] = v
            x[g + n * j + i] = v


__all__ = ["EXACT_WORK", "constant_gain_inverse", "phi_psi", "symmetric_eigen3"]
