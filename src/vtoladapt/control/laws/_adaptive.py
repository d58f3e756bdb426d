"""What the three adaptive laws share: one tick of the adaptation of theta-hat and P, and its diagnostics.

Not a law (it is not in the registry): :mod:`.composite`, :mod:`.composite_pconst` and
:mod:`.tracking_only` call :func:`adaptive_estimate` with their adaptation mode
(:mod:`vtoladapt.control.adaptation`) and their own state offsets.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .. import adaptation as ad
from ..frontend import prediction_error
from ..layouts import (
    DIAG_P_DIAG, DIAG_PROJ_ACTIVE, FAULT_ADAPTATION, N_THETA, P_P0, P_PRIOR, P_V_LO,
    S_ESTIMATE, S_GAMMA, S_INFO_SUM, S_SAT_PREV, S_V_I_LAW, S_W_F,
)


@njit(cache=True)
def model_validity(params, state, alpha_trust_rad, alpha_stall_rad) -> float:
    """How far the linear-in-parameters force model is trusted this tick, in [0, 1] (not in the paper).

    The measured angle of attack ``alpha = atan2(v_iz, v_ix)`` (the controller's ``v_i``, body)
    against the controller's belief (the vehicle file's ``[envelope]``, never the plant's): 1 up to
    ``alpha_trust`` (``stall_angle_deg - stall_margin_deg``, the protected angle), 0 from the
    believed stall angle on, linear between.
    Backward flow (``|alpha|`` near pi) is beyond stall. The wing's force, and so the model's error,
    scale with ``V^2``: below the hover blend (``V_lo``) the weight returns to 1 as ``(V/V_lo)^2``.
    """
    vx = state[S_V_I_LAW]
    vz = state[S_V_I_LAW + 2]
    V2 = vx * vx + state[S_V_I_LAW + 1] * state[S_V_I_LAW + 1] + vz * vz
    a = abs(np.arctan2(vz, vx))
    a_lo = alpha_trust_rad
    if a <= a_lo:
        return 1.0
    w = 0.0 if a >= alpha_stall_rad else (alpha_stall_rad - a) / (alpha_stall_rad - a_lo)
    v_lo = params[P_V_LO]
    reach = min(1.0, V2 / (v_lo * v_lo)) if v_lo > 0.0 else 1.0
    return 1.0 - (1.0 - w) * reach


@njit(cache=True)
def saturated(state) -> bool:
    """True if the last allocation saturated a throttle (the commanded force was not delivered)."""
    return state[S_SAT_PREV] != 0.0 or state[S_SAT_PREV + 1] != 0.0


@njit(cache=True)
def accumulate_information(state, weight, dt) -> None:
    """``INFO_SUM += weight W^T W dt`` with the filtered regressor W: the un-forgotten information (identifiability).

    Upper triangle computed and mirrored (exactly symmetric); read after the run
    (:func:`vtoladapt.experiments.metrics.identifiability`), never decomposed in the loop.
    """
    n = N_THETA
    c = weight * dt
    for i in range(n):
        for j in range(i, n):
            t = 0.0
            for r in range(3):
                t += state[S_W_F + n * r + i] * state[S_W_F + n * r + j]
            v = state[S_INFO_SUM + n * i + j] + c * t
            state[S_INFO_SUM + n * i + j] = v
            state[S_INFO_SUM + n * j + i] = v


@njit(cache=True)
def add_information(state, g, weight, dt) -> None:
    """``INFO_SUM += weight G dt`` for ``G = W^T W`` already formed at ``state[g:]`` (8 x 8, symmetric).

    Bit for bit :func:`accumulate_information` (the same upper-triangle sums, mirrored): the
    composite step has just formed ``W^T W`` of this ``W`` in its scratch, so it is not formed twice.
    """
    n = N_THETA
    c = weight * dt
    for i in range(n):
        for j in range(i, n):
            v = state[S_INFO_SUM + n * i + j] + c * state[g + n * i + j]
            state[S_INFO_SUM + n * i + j] = v
            state[S_INFO_SUM + n * j + i] = v


@njit(cache=True, _nrt=False)
def adaptive_estimate(mode, params, state, diag, s_active, s_work, may_adapt, Phi, R, v_tilde, dt, forget_a,
                      forget_b, sigma, trace_max, w_track=1.0, w_pred=1.0, directional=False,
                      gain_scale=1.0, toward_prior=1.0) -> tuple:
    """Update theta-hat and P (eq:th_adapt, eq:P_adapt) if ``may_adapt``; write ``P_diag`` and ``projection_active_bounds``.

    ``s_active``: the law's state slot holding the last projection's active set; ``s_work``: its
    :data:`~vtoladapt.control.adaptation.WORK` block; ``w_track``, ``w_pred``, ``directional``,
    ``gain_scale``, ``toward_prior``: see :func:`vtoladapt.control.adaptation.weighted_adaptation_step` (the
    defaults are the paper's law). Returns ``(e, adapt_active, faults)``: the prediction error
    before the update (m/s^2 body), whether theta-hat was updated, ``FAULT_*`` bits.
    """
    faults = 0
    n_active = 0
    p_diag = s_work + ad.WK_P_DIAG
    if may_adapt:
        n_active, active_set, e = ad.weighted_adaptation_step(
            mode, state, S_ESTIMATE, s_work, params, P_PRIOR, Phi, R, v_tilde, dt, forget_a, forget_b, sigma,
            trace_max, int(state[s_active]), w_track, w_pred, directional, gain_scale, toward_prior)
        state[s_active] = active_set
        if mode == ad.ADAPT_COMPOSITE:
            # the composite step leaves W^T W of this tick's W in its scratch (the other modes overwrite
            # it or never form it)
            add_information(state, s_work + ad.WK_WTW, w_pred, dt)
        else:
            accumulate_information(state, w_pred, dt)
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
