"""Incremental nonlinear dynamic inversion (INDI) of the force loop, on the measured acceleration.

The law
-------
The virtual control is the composite law's desired acceleration, with the same shared gain and
reference feed-forward (the paper's "equivalent gains"): ``nu = v_r' - K_v v~`` (NED, m/s^2).
INDI asks for the *increment* of specific force that changes the measured acceleration into
``nu``::

    f_r = f_0f + (nu - a_f),        a_f = R a_mf + g_vec,        f_0f = R [W theta]

with ``a_mf`` the accelerometer (specific force, body) through the front end's first-order
filter ``[.]_f`` (``lowpass_cutoff_hz``), ``g_vec = (0, 0, g)`` NED, and ``f_0f`` the specific
force the actuators were producing, passed through *the same* filter: ``[W theta]`` is the
force model (regressor ``Phi`` with theta-hat = theta_0, this law never adapts it) evaluated at
the throttles the allocation actually commanded, passed through the vehicle's nominal motor lag
(the front end's ``regressor_motor_lag``) and then through ``[.]_f`` -- the front end's filtered
regressor ``W``. Since ``W theta - a_mf`` is the prediction error ``e`` of eq:prediction_error,
the law is ``f_r = (nu - g_vec) + R e``: the nominal model-based command of the composite law
(eq:f_ctrl with theta_0) plus the rotated mismatch between the force the model says the
actuators produced and the force the accelerometer felt. That mismatch is the whole of the
unmodelled force (wrong coefficients, drag, gusts), measured rather than modelled, so a constant
disturbance is rejected with no integrator and no adaptation (the sensor-based view of INDI).

Sources
-------
* E. J. J. Smeur, Q. P. Chu, G. C. H. E. de Croon, "Adaptive incremental nonlinear dynamic
  inversion for attitude control of micro air vehicles", J. Guidance, Control, and Dynamics
  39(3), 2016: INDI as a sensor-based law using only the control effectiveness, and the
  synchronisation of the actuator state with the measured derivative by filtering both with the
  same filter (and the actuator state estimated through an actuator model).
* E. J. J. Smeur, G. C. H. E. de Croon, Q. P. Chu, "Cascaded incremental nonlinear dynamic
  inversion for MAV disturbance rejection", Control Engineering Practice 73, 2018: the outer-loop
  (acceleration) INDI used here -- filtered accelerometer, the thrust vector estimated from the
  measured attitude and the actuator model through the same filter, the increment turned into a
  thrust and attitude command.
* E. J. J. Smeur, M. Bronz, G. C. H. E. de Croon, "Incremental control and guidance of hybrid
  aircraft applied to a tailsitter unmanned air vehicle", J. Guidance, Control, and Dynamics
  43(2), 2020: the same acceleration INDI across hover, transition and wing-borne flight of a
  hybrid aircraft, wing forces included in the increment. PX4 and Paparazzi ship INDI loops of
  this kind; here the increment feeds the shared desired attitude and allocation, which invert
  the full force model (lift, drag, thrust) as the "control effectiveness".

Why the same filter on ``f_0`` (synchronisation)
------------------------------------------------
``a_mf`` is the true specific force delayed by the filter (a 16 ms time constant at 10 Hz). An
unfiltered ``f_0`` would be compared with a measurement that has not yet seen it: after every
change of command ``f_0 - R a_mf`` would report the filter's lag as an unmodelled force, which
is fed straight back into the command -- an oscillating, lag-driven loop rather than a
disturbance estimate. Filtered alike (same cutoff, same start, same frame: body, rotated by the
current ``R`` together), the two differ only by the force model's error; with the plant equal to
the model the increment is zero at every instant, not only at rest -- once the front end's
motor-lag estimate, which starts from the first command, has caught up with the motors' true
state (a start-up transient of ~0.3 s when the motors start elsewhere).

Fault handling, start-up and saturation
---------------------------------------
* **Start-up and sensor faults.** The increment is used only while the front end's
  ``accel_ok`` holds: the filters have their first sample, the accelerometer is valid, and has
  been for ``adaptation_holdoff_s`` so that the filter has flushed a stale or frozen value. The
  probe is not needed (Smeur's INDI uses only the accelerometer and the actuator state): while it
  is out, ``W theta`` is the model's force at the fallback incident flow and the increment carries
  that error too, as it carries any other. (Gated on the adaptive laws' ``may_adapt``, which also
  needs the probe, INDI flew its nominal command whenever the probe was out: issue #34.) While it
  does not hold, the last increment is kept and fades toward zero with ``fault_fade_s`` -- a one-tick
  dropout keeps the disturbance estimate, a long outage flies the nominal model-based command
  ``nu - g_vec``. When it holds again (and at start-up, from zero) the increment blends toward
  ``R e`` with a weight rising linearly from 0 to 1 over ``reentry_blend_s``; after that it is
  exactly ``R e``. A non-finite ``e`` counts as invalid: the command is never NaN.
* **Saturation.** ``f_0`` is the force of the *commanded, clipped* throttles (what the allocation
  achieved), not the force command: an unachievable command never enters the increment, and the
  law holds no memory of past commands, so there is nothing to wind up.
* **A wrong but plausible accelerometer** cannot steer the aircraft by more than
  ``increment_limit_mps2``: ``|R e|`` is limited to it.

Gains and why
-------------
No gain of its own beyond the fault handling: the filter is the shared accelerometer filter
``lowpass_cutoff_hz`` (10 Hz, the paper's; INDI needs the same filter on ``f_0`` and ``a_m``,
and the front end already applies it to both), and ``K_v``, ``Lambda_p`` are the shared
equivalent gains. Time-scale separation is checked: ``2 pi lowpass_cutoff_hz`` must be at least
3 x the largest ``K_v``, so that the increment settles faster than the velocity loop it serves
(62.8 against 12 /s with the defaults). With the plant's force effectiveness ``k`` times the
model's, the increment's error shrinks by ``|1 - k|`` per filter time constant: it converges for
``0 < k < 2`` (INDI's known tolerance of effectiveness errors). ``increment_limit_mps2 = 5``: the
largest model error the law trusts the accelerometer for, half a g (a 30 % thrust-coefficient
error in hover is 0.43 g); ``fault_fade_s = 1`` keeps the estimate through dropouts of a few
ticks yet forgets it within seconds; ``reentry_blend_s = 0.1`` spreads the step of re-entry over
the attitude loop's 0.2 s time constant instead of one tick.

Diagnostics: ``indi_increment_*`` hold the increment actually applied (m/s^2 NED), the term that
plays the integral's part in this law (its ``DIAG``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ...config import ConfigError, Validated, setting
from ...layout import BlockLayout, Field
from .. import filters
from ...frames import rows_times
from ..blocks import D_LAW, P_K_V, P_LAW, S_LAW, T_ACCEL_OK, T_DT, T_E, T_NEW_DT, T_V_R_DOT, T_V_TILDE, law_offsets
from ..tracking import force_command, limit_norm
from . import LawContext, finish, law_update, tick3, tick_R

TIME_SCALE_SEPARATION = 3.0
"""``2 pi lowpass_cutoff_hz`` must be at least this multiple of the largest ``K_v``."""


@dataclass(frozen=True)
class IndiSettings(Validated):
    """The INDI law's own settings (the ``[controller.indi]`` table): its fault handling."""

    increment_limit_mps2: float = setting(
        "m/s^2", "limit on |R (W theta - a_m)|, the increment added to the nominal command",
        default=5.0, gt=0.0)
    fault_fade_s: float = setting(
        "s", "while the accelerometer is invalid the last increment fades toward zero "
        "with this time constant", default=1.0, gt=0.0)
    reentry_blend_s: float = setting(
        "s", "at start-up and when the sensors are valid again the increment blends in over this time "
        "(0: at once)", default=0.1, ge=0.0)


Settings = IndiSettings
"""The law interface's name for the settings class."""

TUNABLE = (("controller.lowpass_cutoff_hz", 2.0, 40.0, True), ("increment_limit_mps2", 1.0, 30.0, True))
"""The gains ``vtoladapt tune`` searches (:mod:`vtoladapt.experiments.tuning`): (setting, low, high, log scale).
INDI's gain is the shared filter ``[controller] lowpass_cutoff_hz`` (its rule: at least 3 max K_v / 2 pi)."""


PARAMS = BlockLayout("indi parameters", [
    Field("INC_LIMIT", 1, "m/s^2", "limit on the increment's norm"),
    Field("FADE_S", 1, "s", "fade of the held increment while the sensors are invalid"),
    Field("BLEND_S", 1, "s", "blend-in time of the increment (0: at once)"),
])
STATE = BlockLayout("indi state", [
    Field("INCREMENT", 3, "m/s^2", "increment added to the nominal command, NED"),
    Field("WEIGHT", 1, "-", "blend-in weight of the increment, 0..1"),
    Field("FADE", 1, "-", "decay factor of the held increment for the current dt"),
    Field("BLEND_STEP", 1, "-", "rise of the blend-in weight per tick for the current dt"),
])
DIAG = BlockLayout("indi diagnostics", [
    Field("INCREMENT", 3, "m/s^2", "the increment added to the nominal command, NED",
          columns=("indi_increment_N_mps2", "indi_increment_E_mps2", "indi_increment_D_mps2")),
])
P_INC_LIMIT, P_FADE_S, P_BLEND_S = law_offsets(PARAMS, P_LAW, "INC_LIMIT", "FADE_S", "BLEND_S")
S_INCREMENT, S_WEIGHT, S_FADE, S_BLEND_STEP = law_offsets(STATE, S_LAW, "INCREMENT", "WEIGHT", "FADE",
                                                          "BLEND_STEP")
(D_INCREMENT,) = law_offsets(DIAG, D_LAW, "INCREMENT")


def check_config(settings: IndiSettings, config, source: str) -> None:
    """``ConfigError`` naming ``source`` if the shared filter is too slow for the velocity loop (module notes)."""
    bandwidth = 2.0 * np.pi * config.lowpass_cutoff_hz
    k_v_max = max(config.K_v)
    if bandwidth < TIME_SCALE_SEPARATION * k_v_max:
        prefix = f"{source}: " if source else ""
        raise ConfigError(
            f"{prefix}[controller] lowpass_cutoff_hz = {config.lowpass_cutoff_hz}: the indi law needs 2 pi "
            f"lowpass_cutoff_hz >= {TIME_SCALE_SEPARATION:g} x max(K_v) = {TIME_SCALE_SEPARATION * k_v_max:g} 1/s "
            f"([controller] K_v = {list(config.K_v)}; its increment must settle faster than the velocity loop); "
            f"raise lowpass_cutoff_hz or lower K_v")


def fill_params(settings: IndiSettings, ctx: LawContext) -> np.ndarray:
    """The law's parameter block; ``ConfigError`` if the shared filter is too slow for the velocity loop."""
    check_config(settings, ctx.config, "")
    return PARAMS.pack(INC_LIMIT=settings.increment_limit_mps2, FADE_S=settings.fault_fade_s,
                       BLEND_S=settings.reentry_blend_s)


def init_state(params: np.ndarray, state: np.ndarray) -> None:
    """No increment and weight 0: the first ticks fly the nominal command until the filters are valid."""


@njit(cache=True, inline="always")
def indi_increment(params, state, valid, R, e) -> tuple:
    """The increment (m/s^2 NED) of the module notes: blend toward ``R e`` if ``valid``, else hold and fade."""
    return increment_at(params, state, valid, R, e, P_INC_LIMIT, S_INCREMENT, S_WEIGHT, S_FADE, S_BLEND_STEP)


@njit(cache=True, inline="always")
def increment_at(params, state, valid, R, e, p_limit, s_increment, s_weight, s_fade, s_blend_step) -> tuple:
    """:func:`indi_increment` with the limit in ``params[p_limit]`` and the state's increment, weight, fade and
    blend step at the given slots (a law whose blocks put INDI's elsewhere, :mod:`.composite_indi`)."""
    ok = valid and np.isfinite(e[0]) and np.isfinite(e[1]) and np.isfinite(e[2])
    if ok:
        target, _ = limit_norm(rows_times(R, e), params[p_limit])
        w = min(1.0, state[s_weight] + state[s_blend_step])
        state[s_weight] = w
        for i in range(3):
            state[s_increment + i] = state[s_increment + i] + w * (target[i] - state[s_increment + i])
    else:
        state[s_weight] = 0.0
        fade = state[s_fade]
        for i in range(3):
            state[s_increment + i] = filters.flush_tiny(state[s_increment + i] * fade)
    return (state[s_increment], state[s_increment + 1], state[s_increment + 2])


@law_update
def update(params, state, tick, diag):
    """The INDI force command ``f_r = f_0f + nu - a_f`` (module notes); theta-hat is not adapted."""
    if tick[T_NEW_DT] > 0.0:
        dt = tick[T_DT]
        state[S_FADE] = np.exp(-dt / params[P_FADE_S])
        blend_s = params[P_BLEND_S]
        state[S_BLEND_STEP] = min(1.0, dt / blend_s) if blend_s > 0.0 else 1.0
    inc = indi_increment(params, state, tick[T_ACCEL_OK] > 0.0, tick_R(tick), tick3(tick, T_E))
    K_v = (params[P_K_V], params[P_K_V + 1], params[P_K_V + 2])
    nominal = force_command(tick3(tick, T_V_R_DOT), tick3(tick, T_V_TILDE), K_v)
    for i in range(3):
        diag[D_INCREMENT + i] = inc[i]
    finish(tick, (nominal[0] + inc[0], nominal[1] + inc[1], nominal[2] + inc[2]), False, 0)
