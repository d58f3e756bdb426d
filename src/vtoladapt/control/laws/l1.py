"""L1 adaptive control (a baseline): the composite law's force command with theta-hat = theta_0, plus
an L1 adaptive term from a translational state predictor.

Sources
-------
* N. Hovakimyan and C. Cao, *L1 Adaptive Control Theory: Guaranteed Robustness with Fast
  Adaptation*, SIAM 2010: the state predictor with a Hurwitz ``A_s``, the piecewise-constant
  adaptation law at the sampling period ``T`` (``sigma-hat(iT) = -Phi(T)^-1 mu(iT)``,
  ``Phi(T) = A_s^-1 (e^{A_s T} - I)``, ``mu(iT) = e^{A_s T} x~(iT)``) and the low-pass filter
  ``C(s)`` on the adaptive term.
* Z. Wu, S. Cheng, K. A. Ackerman, A. Gahlawat, A. Lakshmanan, P. Zhao and N. Hovakimyan,
  "L1 Adaptive Augmentation for Geometric Tracking Control of Quadrotors", ICRA 2022, and
  Z. Wu et al., "L1Quad: L1 Adaptive Augmentation of Geometric Control for Agile Quadrotors with
  Performance Guarantees", arXiv:2302.07208 (2023): the same structure on a quadrotor, the
  predictor on the translational velocity only, the baseline's force command minus the filtered
  estimate.

The law (eq:f_ctrl augmented)
-----------------------------
Baseline: ``f_b = v_r' - K_v v~ - g`` (eq:f_ctrl, :func:`vtoladapt.control.tracking.force_command`)
with the shared ``K_v``, ``Lambda_p`` and feed-forward of the composite law, and theta-hat held at
its start (theta_0) for the allocation, so the comparison with the composite law differs only in
how the model error is compensated. Per axis of world NED (``A_s = -a_s I`` is diagonal, so
every matrix below is a scalar times I), once per tick of ``T = dt``:

* **Predictor** ``v-hat' = f_applied + g + sigma-hat + A_s (v-hat - v)``, propagated over the
  interval that just ended by its exact solution for constant inputs (:func:`predictor_step`):
  ``v-hat(T) = v + e^{-a_s T} (v-hat - v) + Phi(T) (f_applied + g + sigma-hat)`` with
  ``Phi(T) = (1 - e^{-a_s T}) / a_s``, ``v`` the measurement held over the interval.
* **Adaptation** (piecewise constant): ``sigma-hat = -Phi(T)^-1 e^{-a_s T} (v-hat - v)``
  (:func:`piecewise_constant_gains`), limited to ``|sigma-hat| <= accel_max_mps2``.
* **Filter** ``sigma_lpf = C(s) sigma-hat``, ``C(s) = omega_c / (s + omega_c)``, exactly
  discretised (``c = 1 - e^{-omega_c T}``), limited to ``|sigma_lpf| <= adaptive_term_max_mps2``.
* **Command** ``f_r = f_b - sigma_lpf``; ``-sigma_lpf`` is logged in ``l1_adaptive_term_*`` (its ``DIAG``).

``f_applied`` is the force the aircraft is believed to produce, not the previous command: the
model's specific force ``R Phi(v_i, u) theta-hat`` at the measured attitude and incident velocity
and the throttles the motors are estimated to deliver (the front end's nominal motor lag on the
commands, the regressor ``Phi`` every law gets), averaged over the interval (trapezoid of its
values at the two ticks; exact for a constant force). The command ``f_r`` would put into
``sigma-hat`` everything between command and force: the ``|f_r + g|`` limit, the allocation's
saturation, the attitude loop's 0.2 s lag and the motor lag. ``sigma-hat`` would then grow while
the allocation saturates (wind-up) and the filter would have to be slower than the attitude loop
to stay stable. With the model's force ``sigma-hat`` is what the model mispredicts (coefficient
errors, unmodelled aerodynamics, disturbances), the quantity the composite law learns as theta~.

Gain rule (``[controller.l1]``) and the numbers behind the defaults
---------------------------------------------------------------------
At ``dt`` = 4 ms, with the caltech_vtol's motor lags 30 ms (lift, ``1/tau`` = 33 rad/s) and 40 ms
(pusher, 25 rad/s), the attitude loop's ``Lambda_q / 2`` = 5 rad/s (roll and pitch, a 0.2 s time
constant) and the velocity loop's ``K_v`` = 1.8 /s (horizontal):

* ``cutoff_radps`` ``omega_c = Lambda_q,xy / 4`` = 2.5 rad/s: half the roll/pitch bandwidth,
  because the horizontal compensation is realised by tilting and content the attitude loop cannot
  follow only adds attitude activity; 10x below the pusher's ``1/tau`` and 13x below the lift
  rotors', so the actuators see a slowly varying term. ``omega_c T`` = 0.01: the discrete filter
  is the continuous ``C(s)``. The term settles in ``1/omega_c`` = 0.4 s, as fast as the velocity
  loop (0.55 s). The filter passes the velocity sensor's noise only differenced (the
  piecewise-constant estimate is close to ``dv/dt``): ~``omega_c`` times the noise, 0.05 m/s^2
  for the default 0.02 m/s mocap noise.
* ``predictor_pole_radps`` ``a_s = 4 omega_c`` = 10 rad/s: the predictor is faster than the
  filter it feeds (the L1 design's separation of estimation and compensation), and ``a_s T`` =
  0.04 stays small: for a constant uncertainty the piecewise-constant law settles at
  ``sigma-hat = e^{-a_s T} sigma`` (one tick of the predictor's error decays before it is
  measured), so 96 % is compensated and 4 % is left to ``K_v``. ``fill_params`` refuses
  ``a_s dt >= 0.5`` (less than 61 % compensated).
* ``adaptive_term_max_mps2`` = 5 m/s^2 (half a g): above a 30 % lift-thrust error in hover
  (2.9 m/s^2), the largest model error the tests inject, and below the shared 2 g limit on
  ``|f_r + g|``, so a wrong estimate cannot take the whole authority.
* ``fault_bleed_s`` = 2 s, the wind estimate's fade (``wind_estimate_fade_s``): a short sensor
  outage keeps the compensation, a long one returns to the baseline law.

Start-up, dt changes, faults
----------------------------
* The first tick seats the predictor at the measured velocity with ``sigma-hat = 0``.
* ``new_dt`` recomputes ``e^{-a_s T}``, ``Phi(T)^-1 e^{-a_s T}``, the filter gain and the bleed.
* The law uses no accelerometer and needs no probe (the fallback incident velocity only changes
  ``f_applied``, and ``sigma-hat`` absorbs its error), so it ignores ``may_adapt`` and never
  adapts theta-hat (``adapt_active`` is False). A velocity the front end holds because the
  measurement was not plausible (``FAULT_VELOCITY`` in the tick's ``FAULTS``, the front end's fault
  bits) freezes ``sigma-hat`` and bleeds it (``fault_bleed_s``); the filter keeps running, and the
  next good sample re-seats the predictor (one tick without an update), so that an outage is not
  read as one tick's acceleration.
* A velocity equal to the last tick's is not a fault: a sample-and-hold source (motion capture
  slower than the loop, a replayed log) repeats its samples. The predictor and the
  piecewise-constant law run on every tick against the held sample, so the estimate on a held
  tick says "no acceleration" and the next fresh sample's tick the rest; the estimate's mean is
  the source's slope and ``C(s)`` filters the ripple. (Until issue #25 a repeat counted as a
  fault: with 100 Hz motion capture in a 250 Hz loop the predictor was re-seated on 60 % of the
  ticks and the estimate never built up.)
* Anything non-finite in the law's memory (impossible for the sanitised inputs, but guarded)
  restarts it from the measured velocity with ``sigma-hat = 0`` and sets ``FAULT_ADAPTATION``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ...config import ConfigError, Validated, setting
from ...frames import GRAVITY_MPS2
from ...layout import BlockLayout, Field
from .. import filters
from ...frames import rows_times
from ..blocks import (
    A_N, A_PHI, A_THETA, D_LAW, FAULT_ADAPTATION, FAULT_VELOCITY, P_ACC_MAX, P_K_V, P_LAW, S_LAW, T_DT, T_FAULTS,
    T_NEW_DT, T_V_R_DOT, T_V_TILDE, T_V_W, law_offsets,
)
from ..tracking import force_command, limit_norm
from . import LawContext, finish, law_update, tick3, tick_R

A_S_DT_MAX = 0.5
"""Largest ``a_s dt`` accepted: the estimate keeps ``e^{-a_s dt}`` (61 %) of a constant uncertainty."""


@dataclass(frozen=True)
class L1Settings(Validated):
    """The L1 law's own gains (the ``[controller.l1]`` table); the rule behind the defaults is in the module notes."""

    cutoff_radps: float = setting("rad/s", "bandwidth omega_c of the low-pass C(s) = omega_c / (s + omega_c) "
                                  "on the adaptive term", default=2.5, gt=0.0, le=1000.0)
    predictor_pole_radps: float = setting("rad/s", "a_s of the state predictor's A_s = -a_s I (its error decays "
                                          "as e^{-a_s t})", default=10.0, gt=0.0)
    adaptive_term_max_mps2: float = setting("m/s^2", "limit on |sigma_lpf|, the filtered adaptive term "
                                            "subtracted from the force command", default=5.0, gt=0.0)
    fault_bleed_s: float = setting("s", "while the velocity is held by the front end the frozen estimate "
                                   "decays toward 0 with this time constant", default=2.0, gt=0.0)


Settings = L1Settings
"""The law interface's name for the settings class."""

TUNABLE = (("cutoff_radps", 0.5, 40.0, True), ("predictor_pole_radps", 0.5, 100.0, True))
"""The gains ``vtoladapt tune`` searches (:mod:`vtoladapt.experiments.tuning`): (setting, low, high, log scale);
a_s up to 100 rad/s keeps ``a_s dt`` = 0.4 < 0.5 at 250 Hz."""


PARAMS = BlockLayout("l1 parameters", [
    Field("A_S", 1, "1/s", "predictor pole a_s"),
    Field("OMEGA_C", 1, "rad/s", "bandwidth of C(s)"),
    Field("TERM_MAX", 1, "m/s^2", "limit on |sigma_lpf|"),
    Field("BLEED_S", 1, "s", "decay time of the frozen estimate during a velocity fault"),
])
STATE = BlockLayout("l1 state", [
    Field("V_HAT", 3, "m/s", "predicted velocity v-hat, NED"),
    Field("V_HOLD", 3, "m/s", "the measured velocity held over the current interval, NED"),
    Field("F_PREV", 3, "m/s^2", "model specific force at the last tick (start of the interval), NED"),
    Field("SIGMA_HAT", 3, "m/s^2", "piecewise-constant estimate sigma-hat, NED"),
    Field("SIGMA_LPF", 3, "m/s^2", "filtered adaptive term sigma_lpf, NED"),
    Field("RUNNING", 1, "-", "1 while the predictor runs; 0: the next fresh velocity seats it"),
    Field("GAINS", 4, "-", "for the current dt: the L1_GAINS layout"),
])
DIAG = BlockLayout("l1 diagnostics", [
    Field("ADAPTIVE_TERM", 3, "m/s^2", "-sigma_lpf, the adaptive term added to the force command, NED",
          columns=("l1_adaptive_term_N_mps2", "l1_adaptive_term_E_mps2", "l1_adaptive_term_D_mps2")),
])
P_A_S, P_OMEGA_C, P_TERM_MAX, P_BLEED_S = law_offsets(PARAMS, P_LAW, "A_S", "OMEGA_C", "TERM_MAX", "BLEED_S")
S_V_HAT, S_V_HOLD, S_F_PREV, S_SIGMA_HAT, S_SIGMA_LPF, S_RUNNING, S_GAINS_L1 = law_offsets(
    STATE, S_LAW, "V_HAT", "V_HOLD", "F_PREV", "SIGMA_HAT", "SIGMA_LPF", "RUNNING", "GAINS")
(D_ADAPTIVE_TERM,) = law_offsets(DIAG, D_LAW, "ADAPTIVE_TERM")
L1_GAINS = BlockLayout("l1 gains for the current dt", [
    Field("DECAY", 1, "-", "e^{-a_s dt}"),
    Field("ADAPT", 1, "1/s", "Phi^-1 e^{-a_s dt}"),
    Field("FILTER", 1, "-", "gain of C(s)"),
    Field("BLEED", 1, "-", "decay of the frozen estimate"),
])
G_DECAY, G_ADAPT, G_FILTER, G_BLEED = L1_GAINS.offsets("DECAY", "ADAPT", "FILTER", "BLEED")


def check_a_s_dt(settings: L1Settings, dt_s: float, source: str) -> None:
    """``ConfigError`` naming ``source`` unless ``a_s dt < A_S_DT_MAX`` at the controller's tick ``dt_s``."""
    x = settings.predictor_pole_radps * dt_s
    if not x < A_S_DT_MAX:
        prefix = f"{source}: " if source else ""
        raise ConfigError(
            f"{prefix}[controller.l1] predictor_pole_radps = {settings.predictor_pole_radps}: needs a_s * dt < "
            f"{A_S_DT_MAX} (the estimate keeps e^(-a_s dt) of the uncertainty), here {x:.3g} with dt = {dt_s:g} s "
            f"([controller] loop_rate_hz = {1.0 / dt_s:g}; in a scenario 1/dt_control_s); lower predictor_pole_radps "
            f"or run the controller faster")


def check_config(settings: L1Settings, config, source: str) -> None:
    """The rule the law's settings and the shared ones meet together: ``a_s dt < 0.5`` at ``loop_rate_hz``."""
    check_a_s_dt(settings, config.dt_nominal_s, source)


def fill_params(settings: L1Settings, ctx: LawContext) -> np.ndarray:
    """The law's parameter block; ``ConfigError`` if ``a_s dt`` leaves too little of the estimate."""
    check_a_s_dt(settings, ctx.dt_nominal_s, "")
    return PARAMS.pack(A_S=settings.predictor_pole_radps, OMEGA_C=settings.cutoff_radps,
                       TERM_MAX=settings.adaptive_term_max_mps2, BLEED_S=settings.fault_bleed_s)


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """Nothing beyond zeros: the first tick seats the predictor at the measured velocity (RUNNING = 0)."""


@njit(cache=True, inline="always")
def piecewise_constant_gains(a_s, dt) -> tuple:
    """``(e^{-a_s T}, Phi(T))`` for ``A_s = -a_s I`` and ``T = dt``; ``Phi(T) = A_s^-1 (e^{A_s T} - I)``.

    ``Phi(T) = (1 - e^{-a_s T}) / a_s`` is formed with ``expm1`` so it stays accurate for small
    ``a_s T``. The adaptation gain of Hovakimyan & Cao's piecewise-constant law is
    ``Phi(T)^-1 e^{-a_s T}`` (``sigma-hat = -`` that times ``v-hat - v``).
    """
    x = -a_s * dt
    return np.exp(x), -np.expm1(x) / a_s


@njit(cache=True, inline="always")
def predictor_step(v_hat, v_hold, c, decay, phi) -> float:
    """One axis of the predictor over one interval, exactly: ``x' = -a_s (x - v) + c`` with ``v``, ``c`` constant.

    ``x(T) = v + e^{-a_s T} (x(0) - v) + Phi(T) c``; ``c = f_applied + g + sigma-hat`` (m/s^2),
    ``decay = e^{-a_s T}``, ``phi = Phi(T)`` (s) from :func:`piecewise_constant_gains`.
    """
    return v_hold + decay * (v_hat - v_hold) + phi * c


@njit(cache=True, inline="always")
def update_gains(params, state, dt) -> None:
    """Store the dt-dependent gains (``GAINS`` field) for a tick of ``dt``."""
    decay, phi = piecewise_constant_gains(params[P_A_S], dt)
    state[S_GAINS_L1 + G_DECAY] = decay
    state[S_GAINS_L1 + G_ADAPT] = decay / phi
    state[S_GAINS_L1 + G_FILTER] = -np.expm1(-params[P_OMEGA_C] * dt)
    state[S_GAINS_L1 + G_BLEED] = np.exp(-dt / params[P_BLEED_S])


@njit(cache=True, inline="always")
def model_force_W(params, state, R) -> tuple:
    """``f_applied = R Phi theta-hat``: the model's specific force at this tick, m/s^2 NED (gravity excluded)."""
    n = int(params[A_N])
    th = int(params[A_THETA])
    phi = int(params[A_PHI])
    f_B0 = 0.0
    f_B1 = 0.0
    f_B2 = 0.0
    for k in range(n):
        t = state[th + k]
        f_B0 += state[phi + k] * t
        f_B1 += state[phi + n + k] * t
        f_B2 += state[phi + 2 * n + k] * t
    return rows_times(R, (f_B0, f_B1, f_B2))


@njit(cache=True, inline="always")
def l1_estimate(params, state, v_W, f_now, held) -> int:
    """Predictor, piecewise-constant adaptation and filter for one tick (module notes); returns ``FAULT_*`` bits.

    ``held``: the front end is holding the last good velocity (this tick's was not plausible).
    """
    decay = state[S_GAINS_L1 + G_DECAY]
    k_adapt = state[S_GAINS_L1 + G_ADAPT]
    phi = (1.0 - decay) / params[P_A_S]
    faults = 0
    if state[S_RUNNING] > 0.0 and not held:
        for i in range(3):
            c = 0.5 * (state[S_F_PREV + i] + f_now[i]) + state[S_SIGMA_HAT + i]
            if i == 2:
                c += GRAVITY_MPS2
            v_hat = predictor_step(state[S_V_HAT + i], state[S_V_HOLD + i], c, decay, phi)
            state[S_V_HAT + i] = v_hat
            state[S_SIGMA_HAT + i] = -k_adapt * (v_hat - v_W[i])
        s, _ = limit_norm((state[S_SIGMA_HAT], state[S_SIGMA_HAT + 1], state[S_SIGMA_HAT + 2]), params[P_ACC_MAX])
        state[S_SIGMA_HAT], state[S_SIGMA_HAT + 1], state[S_SIGMA_HAT + 2] = s
    elif held:
        # the front end is holding a faulty velocity: freeze the estimate, bleed it, re-seat later
        bleed = state[S_GAINS_L1 + G_BLEED]
        for i in range(3):
            state[S_SIGMA_HAT + i] = filters.flush_tiny(state[S_SIGMA_HAT + i] * bleed)
        state[S_RUNNING] = 0.0
    else:
        # start-up, or the first fresh sample after a fault: seat the predictor on the measurement
        for i in range(3):
            state[S_V_HAT + i] = v_W[i]
        state[S_RUNNING] = 1.0
    c_f = state[S_GAINS_L1 + G_FILTER]
    for i in range(3):
        state[S_V_HOLD + i] = v_W[i]
        state[S_F_PREV + i] = f_now[i]
        state[S_SIGMA_LPF + i] = filters.lowpass(state[S_SIGMA_LPF + i], state[S_SIGMA_HAT + i], c_f)
    s, _ = limit_norm((state[S_SIGMA_LPF], state[S_SIGMA_LPF + 1], state[S_SIGMA_LPF + 2]), params[P_TERM_MAX])
    state[S_SIGMA_LPF], state[S_SIGMA_LPF + 1], state[S_SIGMA_LPF + 2] = s
    ok = True
    for i in range(3):
        ok = (ok and np.isfinite(state[S_V_HAT + i]) and np.isfinite(state[S_SIGMA_LPF + i])
              and np.isfinite(state[S_SIGMA_HAT + i]) and np.isfinite(state[S_F_PREV + i]))
    if not ok:
        faults |= FAULT_ADAPTATION
        for i in range(3):
            state[S_V_HAT + i] = v_W[i]
            state[S_V_HOLD + i] = v_W[i]
            state[S_F_PREV + i] = f_now[i] if np.isfinite(f_now[i]) else 0.0
            state[S_SIGMA_HAT + i] = 0.0
            state[S_SIGMA_LPF + i] = 0.0
        state[S_RUNNING] = 1.0
    return faults


@law_update
def update(params, state, tick, diag):
    """The baseline force command (eq:f_ctrl) minus the filtered L1 estimate; see the law interface.

    theta-hat is never adapted; ``MAY_ADAPT`` is not used (module notes).
    """
    if tick[T_NEW_DT] > 0.0:
        update_gains(params, state, tick[T_DT])
    held = (int(tick[T_FAULTS]) & FAULT_VELOCITY) != 0
    faults = l1_estimate(params, state, tick3(tick, T_V_W), model_force_W(params, state, tick_R(tick)), held)
    K_v = (params[P_K_V], params[P_K_V + 1], params[P_K_V + 2])
    f_b = force_command(tick3(tick, T_V_R_DOT), tick3(tick, T_V_TILDE), K_v)
    s = (state[S_SIGMA_LPF], state[S_SIGMA_LPF + 1], state[S_SIGMA_LPF + 2])
    for i in range(3):
        diag[D_ADAPTIVE_TERM + i] = -s[i]
    finish(tick, (f_b[0] - s[0], f_b[1] - s[1], f_b[2] - s[2]), False, faults)
