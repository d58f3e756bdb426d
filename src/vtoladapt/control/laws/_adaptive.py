"""What the three adaptive laws share: one tick of the adaptation of theta-hat and P, and its diagnostics.

Not a law (it is not in the registry): :mod:`.composite`, :mod:`.composite_pconst` and
:mod:`.tracking_only` call :func:`adaptive_estimate` with their adaptation mode
(:mod:`vtoladapt.control.adaptation`) and their own state offsets.
"""
from __future__ import annotations

from numba import njit

from .. import adaptation as ad
from ..frontend import prediction_error
from ..layouts import (
    DIAG_P_DIAG, DIAG_PROJ_ACTIVE, FAULT_ADAPTATION, N_THETA, P_P0, P_PRIOR, S_ESTIMATE, S_GAMMA,
)


@njit(cache=True)
def adaptive_estimate(mode, params, state, diag, s_active, s_work, may_adapt, Phi, R, v_tilde, dt, forget_a,
                      forget_b, sigma, trace_max) -> tuple:
    """Update theta-hat and P (eq:th_adapt, eq:P_adapt) if ``may_adapt``; write ``P_diag`` and ``projection_active_bounds``.

    ``s_active``: the law's state slot holding the last projection's active set; ``s_work``: its
    :data:`~vtoladapt.control.adaptation.WORK` block. Returns ``(e, adapt_active, faults)``: the
    prediction error before the update (m/s^2 body), whether theta-hat was updated, ``FAULT_*`` bits.
    """
    faults = 0
    n_active = 0
    p_diag = s_work + ad.WK_P_DIAG
    if may_adapt:
        n_active, active_set, e = ad.adaptation_step(
            mode, state, S_ESTIMATE, s_work, params, P_PRIOR, Phi, R, v_tilde, dt, forget_a, forget_b, sigma,
            trace_max, int(state[s_active]))
        state[s_active] = active_set
        if n_active < 0:
            faults |= FAULT_ADAPTATION
    else:
        e = prediction_error(state)
        if not (mode == ad.ADAPT_COMPOSITE
                and ad.cholesky_lower(state, S_GAMMA, state, s_work + ad.WK_L, N_THETA)):
            if mode == ad.ADAPT_COMPOSITE:
                faults |= FAULT_ADAPTATION
            for i in range(N_THETA):
                state[p_diag + i] = params[P_P0 + N_THETA * i + i]
        else:
            ad.inverse_factor(state, s_work + ad.WK_L, state, s_work + ad.WK_M)
            ad.factor_diag(state, s_work + ad.WK_M, state, p_diag)
    for i in range(N_THETA):
        diag[DIAG_P_DIAG + i] = state[p_diag + i]
    diag[DIAG_PROJ_ACTIVE] = n_active
    return e, may_adapt, faults
