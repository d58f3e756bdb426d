"""What the three adaptive laws share: one tick of the adaptation of theta-hat and P, and its diagnostics.

Not a law (it is not in the registry): :mod:`.composite`, :mod:`.composite_pconst` and
:mod:`.tracking_only` call :func:`adaptive_estimate` with their adaptation mode
(:mod:`vtoladapt.control.adaptation`), their own state slot for the projection's active set and
their own diagnostics column for it (:data:`DIAG`, which each of them declares as its ``DIAG``).
The adaptation's scratch is the shared ``WORK`` block sized by the basis.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ...bases import IN_V_I_B
from ...layout import BlockLayout, Field
from .. import adaptation as ad
from .. import linalg
from ..blocks import (A_D_P_DIAG, A_GAMMA, A_INFO_SUM, A_N, A_P0, A_PHI, A_W, A_WK_L, A_WK_M, A_WK_WTW, FAULT_ADAPTATION,
                      P_AD, P_V_LO, S_INPUT, S_SAT_PREV, T_DT, T_E, T_MAY_ADAPT, T_V_TILDE)
from ..kalman import kalman_step
from . import tick3, tick_R

DIAG = BlockLayout("adaptive law diagnostics", [
    Field("PROJ_ACTIVE", 1, "-", "number of bounds the projection held this tick (-1: its iteration limit)",
          columns=("projection_active_bounds",)),
])
"""The diagnostics every adaptive law declares (its ``DIAG``)."""


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
    v = S_INPUT + IN_V_I_B
    vx = state[v]
    vz = state[v + 2]
    V2 = vx * vx + state[v + 1] * state[v + 1] + vz * vz
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
def accumulate_information(params, state, weight, dt, n) -> None:
    """``INFO_SUM += weight W^T W dt`` with the filtered regressor W: the un-forgotten information (identifiability).

    Upper triangle computed and mirrored (exactly symmetric); read after the run
    (:func:`vtoladapt.experiments.metrics.identifiability`), never decomposed in the loop.
    """
    w = int(params[A_W])
    s = int(params[A_INFO_SUM])
    c = weight * dt
    for i in range(n):
        w0, w1, w2 = state[w + i], state[w + n + i], state[w + 2 * n + i]
        for j in range(i, n):
            state[s + n * i + j] += c * (0.0 + w0 * state[w + j] + w1 * state[w + n + j] + w2 * state[w + 2 * n + j])
    linalg.mirror_upper(state, s, n)


@njit(cache=True)
def add_information(params, state, g, weight, dt, n) -> None:
    """``INFO_SUM += weight G dt`` for ``G = W^T W`` already formed at ``state[g:]`` (n x n, symmetric).

    Bit for bit :func:`accumulate_information` (the same upper-triangle sums, mirrored): the
    composite step has just formed ``W^T W`` of this ``W`` in its scratch, so it is not formed twice.
    """
    s = int(params[A_INFO_SUM])
    c = weight * dt
    for i in range(n):
        for j in range(i, n):
            state[s + n * i + j] += c * state[g + n * i + j]
    linalg.mirror_upper(state, s, n)


@njit(cache=True, _nrt=False)
def adaptive_estimate(mode, params, state, tick, diag, s_active, d_proj, forget_a, forget_b, sigma, trace_max,
                      w_track=1.0, w_pred=1.0, directional=False, gain_scale=1.0, toward_prior=1.0) -> tuple:
    """Update theta-hat and P (eq:th_adapt, eq:P_adapt) if the tick allows; write ``P_diag`` and the
    projection's active bounds (at ``diag[d_proj]``).

    ``s_active``: the law's state slot holding the last projection's active set; ``w_track``,
    ``w_pred``, ``directional``, ``gain_scale``, ``toward_prior``: see
    :func:`vtoladapt.control.adaptation.weighted_adaptation_step` (the defaults are the paper's law).
    Returns ``(adapt_active, faults)``: whether theta-hat was updated, ``FAULT_*`` bits. Compiled for the
    shipped bases' n with constant loop lengths too (:data:`vtoladapt.control.adaptation.SPECIALISED_N`).
    """
    n = int(params[A_N])
    if n == ad.N_SLOT_0:
        return _estimate(mode, params, state, tick, diag, s_active, d_proj, forget_a, forget_b, sigma, trace_max,
                         w_track, w_pred, directional, gain_scale, toward_prior, ad.N_SLOT_0)
    if n == ad.N_SLOT_1:
        return _estimate(mode, params, state, tick, diag, s_active, d_proj, forget_a, forget_b, sigma, trace_max,
                         w_track, w_pred, directional, gain_scale, toward_prior, ad.N_SLOT_1)
    if n == ad.N_SLOT_2:
        return _estimate(mode, params, state, tick, diag, s_active, d_proj, forget_a, forget_b, sigma, trace_max,
                         w_track, w_pred, directional, gain_scale, toward_prior, ad.N_SLOT_2)
    return _estimate(mode, params, state, tick, diag, s_active, d_proj, forget_a, forget_b, sigma, trace_max,
                     w_track, w_pred, directional, gain_scale, toward_prior, n)


@njit(cache=True, inline="always")
def _estimate(mode, params, state, tick, diag, s_active, d_proj, forget_a, forget_b, sigma, trace_max, w_track,
              w_pred, directional, gain_scale, toward_prior, n) -> tuple:
    """The body of :func:`adaptive_estimate` for ``n`` parameters (inlined, see there)."""
    faults = 0
    n_active = 0
    p_diag = int(params[P_AD + ad.AT_P_DIAG])
    may_adapt = tick[T_MAY_ADAPT] > 0.0
    dt = tick[T_DT]
    if may_adapt and mode == ad.ADAPT_KALMAN:
        # the Kalman form (forget_a, forget_b: a^2 and the process noise's factor over the tick)
        if kalman_step(params, P_AD, state, params, state, int(params[A_PHI]), tick_R(tick), tick3(tick, T_V_TILDE),
                       dt, forget_a, forget_b, w_track, w_pred) < 0:
            faults |= FAULT_ADAPTATION
        accumulate_information(params, state, w_pred, dt, n)
    elif may_adapt:
        n_active, active_set = ad.adaptation_step_with_error(
            mode, params, P_AD, state, params, state, int(params[A_PHI]), tick_R(tick), tick3(tick, T_V_TILDE),
            dt, forget_a, forget_b, sigma, trace_max, int(state[s_active]), w_track, w_pred, directional, gain_scale,
            tick3(tick, T_E), toward_prior)
        state[s_active] = active_set
        if mode == ad.ADAPT_COMPOSITE:
            # the composite step leaves W^T W of this tick's W in its scratch (the other modes overwrite
            # it or never form it)
            add_information(params, state, int(params[A_WK_WTW]), w_pred, dt, n)
        else:
            accumulate_information(params, state, w_pred, dt, n)
        if n_active < 0:
            faults |= FAULT_ADAPTATION
    elif mode == ad.ADAPT_KALMAN:
        # the GAMMA slot holds P itself
        gam = int(params[A_GAMMA])
        for i in range(n):
            state[p_diag + i] = state[gam + n * i + i]
    else:
        if not (mode == ad.ADAPT_COMPOSITE
                and linalg.cholesky_lower(state, int(params[A_GAMMA]), state, int(params[A_WK_L]), n)):
            if mode == ad.ADAPT_COMPOSITE:
                faults |= FAULT_ADAPTATION
            p0 = int(params[A_P0])
            for i in range(n):
                state[p_diag + i] = params[p0 + n * i + i]
        else:
            linalg.inverse_factor(state, int(params[A_WK_L]), state, int(params[A_WK_M]), n)
            linalg.factor_diag(state, int(params[A_WK_M]), state, p_diag, n)
    d = int(params[A_D_P_DIAG])
    for i in range(n):
        diag[d + i] = state[p_diag + i]
    diag[d_proj] = n_active
    return may_adapt, faults
