"""Small dense linear algebra for the adaptation: ``n x n`` matrices in flat storage, no allocation.

Every kernel takes a flat array and an offset for each matrix (``A[a:a + n * n]``, row-major), so
the adaptation's matrices live inside the controller's state and scratch arrays
(:mod:`vtoladapt.control.adaptation`). The kernels the adaptation step calls are inlined into it
(``inline="always"``): the step is compiled for each shipped basis's n as a constant
(:data:`vtoladapt.control.adaptation.SPECIALISED_N`), and only inlined code sees that constant and
runs loops of constant length (1.5 to 2 times as fast as loops of run-time length).

No ``fastmath``: every sum is formed in the textbook order, so the numbers do not depend on how a
kernel is scheduled. The speed comes from independent sums run side by side (two rows of the
Cholesky factor, two columns of its inverse) and from symmetric matrices written by rows, then
mirrored (contiguous stores); ``tests/test_adaptation_specialised.py`` holds each kernel to the
textbook loops bit for bit.

The kernels never divide by zero (Cholesky pivots are > 0 once checked), so they use NumPy's error
model: a division cannot raise, which leaves them no exception path and lets Numba drop their
reference counting (otherwise kept on every call).
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def cholesky_lower(A, a, L, l, n) -> bool:
    """Cholesky factor (lower) of the SPD ``n x n`` matrix at ``A[a:]`` into ``L[l:]``; False if not PD.

    :func:`cholesky_inline` compiled once, for the small systems of the projection and the directional
    forgetting and for any caller off the adaptation step's path (an inlined copy in each of them cost
    first-import compile time for nothing measurable).
    """
    return cholesky_inline(A, a, L, l, n)


@njit(cache=True, error_model="numpy", inline="always")
def cholesky_inline(A, a, L, l, n) -> bool:
    """:func:`cholesky_lower` inlined into the caller: the adaptation step, where a constant n makes its
    loops of constant length (a third faster at n = 17).

    Column by column; the entries of a column two rows at a time, each its own sum in the textbook
    order (``A[i, j] - L[i, 0] L[j, 0] - L[i, 1] L[j, 1] - ...``): two independent chains of additions
    that share the loads of row j run in about two thirds of the time of one, with the same numbers.
    """
    A = A[a:a + n * n]
    L = L[l:l + n * n]
    for j in range(n):
        s = A[n * j + j]
        for k in range(j):
            s -= L[n * j + k] * L[n * j + k]
        if not s > 0.0:
            return False
        d = np.sqrt(s)
        L[n * j + j] = d
        r = 1.0 / d
        i = j + 1
        while i + 1 < n:
            t0 = A[n * i + j]
            t1 = A[n * (i + 1) + j]
            for k in range(j):
                ljk = L[n * j + k]
                t0 -= L[n * i + k] * ljk
                t1 -= L[n * (i + 1) + k] * ljk
            L[n * i + j] = t0 * r
            L[n * (i + 1) + j] = t1 * r
            i += 2
        if i < n:
            t = A[n * i + j]
            for k in range(j):
                t -= L[n * i + k] * L[n * j + k]
            L[n * i + j] = t * r
        for i in range(j):
            L[n * i + j] = 0.0
    return True


@njit(cache=True, error_model="numpy")
def cholesky_solve(L, l, n, b, o) -> None:
    """Solve ``L L^T x = b`` in place (``b[o:o+n]`` becomes x) given the Cholesky factor at ``L[l:]``."""
    L = L[l:l + n * n]
    b = b[o:o + n]
    for i in range(n):
        t = b[i]
        for k in range(i):
            t -= L[n * i + k] * b[k]
        b[i] = t / L[n * i + i]
    for i in range(n - 1, -1, -1):
        t = b[i]
        for k in range(i + 1, n):
            t -= L[n * k + i] * b[k]
        b[i] = t / L[n * i + i]


@njit(cache=True, error_model="numpy")
def inverse_factor(L, l, M, m, n) -> None:
    """:func:`inverse_factor_inline` compiled once, for the callers off the adaptation step's main path."""
    inverse_factor_inline(L, l, M, m, n)


@njit(cache=True, error_model="numpy", inline="always")
def inverse_factor_inline(L, l, M, m, n) -> None:
    """``M = L^-1`` (lower triangular) for a Cholesky factor ``L`` of ``A``, so ``A^-1 = M^T M``.

    ``n x n``, ``L`` at ``L[l:]`` (from :func:`cholesky_lower`), ``M`` into ``M[m:]``. Forward
    substitution column by column, ``M[i, j] = -(L[i, j] M[j, j] + ... + L[i, i-1] M[i-1, j]) M[i, i]``,
    two columns at a time: their sums share the loads of row i of L and run as two independent
    chains (about 1.6 times as fast at n = 17), each in the order of one column alone (same numbers).
    """
    L = L[l:l + n * n]
    M = M[m:m + n * n]
    for i in range(n):
        M[n * i + i] = 1.0 / L[n * i + i]
    j = 0
    while j + 1 < n:
        # columns j and j + 1; column j's sum has one term more (k = j) before the shared ones
        M[n * (j + 1) + j] = (0.0 - L[n * (j + 1) + j] * M[n * j + j]) * M[n * (j + 1) + j + 1]
        for i in range(j + 2, n):
            t0 = 0.0 - L[n * i + j] * M[n * j + j]
            t1 = 0.0
            for k in range(j + 1, i):
                lik = L[n * i + k]
                t0 -= lik * M[n * k + j]
                t1 -= lik * M[n * k + j + 1]
            M[n * i + j] = t0 * M[n * i + i]
            M[n * i + j + 1] = t1 * M[n * i + i]
        for i in range(j):
            M[n * i + j] = 0.0
            M[n * i + j + 1] = 0.0
        M[n * j + j + 1] = 0.0
        j += 2
    if j < n:
        # the last column of an odd n (only its diagonal: no row below it)
        for i in range(j):
            M[n * i + j] = 0.0


@njit(cache=True, error_model="numpy", inline="always")
def gram_of_factor(M, m, out, o, n) -> None:
    """``out = M^T M`` for lower-triangular ``M`` (exactly symmetric, PD if ``M`` is invertible), ``n x n``."""
    M = M[m:m + n * n]
    out = out[o:o + n * n]
    for i in range(n):
        for j in range(i, n):
            t = 0.0
            for k in range(j, n):
                t += M[n * k + i] * M[n * k + j]
            out[n * i + j] = t
            out[n * j + i] = t


@njit(cache=True, error_model="numpy", inline="always")
def factor_diag(M, m, out, o, n) -> None:
    """``diag(M^T M)`` for lower-triangular ``M`` (the diagonal of ``A^-1``) into ``out[o:o+n]``."""
    M = M[m:m + n * n]
    out = out[o:o + n]
    for i in range(n):
        t = 0.0
        for k in range(i, n):
            t += M[n * k + i] * M[n * k + i]
        out[i] = t


@njit(cache=True, error_model="numpy", inline="always")
def factor_apply(M, m, x, o, n) -> None:
    """``x <- M^T (M x)`` in place (``x[o:o+n]``) for lower-triangular ``M``: ``A^-1 x``."""
    M = M[m:m + n * n]
    x = x[o:o + n]
    # y = M x from the last row up (row i reads x_0..x_i, which are not overwritten yet)
    for i in range(n - 1, -1, -1):
        t = 0.0
        for k in range(i + 1):
            t += M[n * i + k] * x[k]
        x[i] = t
    # M^T y from the first row down (row i reads y_i..y_n-1)
    for i in range(n):
        t = 0.0
        for k in range(i, n):
            t += M[n * k + i] * x[k]
        x[i] = t


@njit(cache=True, error_model="numpy", inline="always")
def mirror_upper(A, a, n) -> None:
    """Copy the upper triangle of the ``n x n`` matrix at ``A[a:]`` onto its lower one (exactly symmetric).

    The kernels that form a symmetric matrix write its upper triangle row by row, contiguous stores
    the compiler vectorises, and mirror it here: writing both halves in the same loop made every
    second store strided and the loop scalar (1.7 times as long at n = 17)."""
    A = A[a:a + n * n]
    for i in range(n):
        for j in range(i + 1, n):
            A[n * j + i] = A[n * i + j]


@njit(cache=True, error_model="numpy")
def spd_inverse(A, a, Ainv, ai, work, w, n) -> bool:
    """Inverse of SPD ``A`` via Cholesky, ``A^-1 = L^-T L^-1``: symmetric and PD by construction.

    ``n x n`` matrices at ``A[a:]`` and into ``Ainv[ai:]``; ``work[w:]`` holds two of them
    (overwritten). Returns False (``Ainv`` untouched) if ``A`` is not PD.
    """
    L = w + n * n
    if not cholesky_lower(A, a, work, L, n):
        return False
    inverse_factor(work, L, work, w, n)
    gram_of_factor(work, w, Ainv, ai, n)
    return True
