"""The controller's flat arrays: the shared blocks, the per-tick block, and where a law's and a basis's go.

Every controller's ``params``, ``state`` and ``diag`` arrays are a shared block of fixed size,
then the law's own block (so a law binds its offsets once, :func:`law_offsets` from :data:`P_LAW`,
:data:`S_LAW`, :data:`D_LAW`), then the blocks sized by the force-model basis (n parameters,
:mod:`vtoladapt.bases`)::

    params = [ SHARED_PARAMS | law.PARAMS | PRIOR(n)                          | basis constants ]
    state  = [ SHARED_STATE  | law.STATE  | ESTIMATE(n) | PHI | INFO_SUM | WORK(n) | basis scratch ]
    diag   = [ SHARED_DIAG   | law.DIAG   | THETA_HAT(n) | P_DIAG(n) ]

:func:`controller_layout` declares the whole of the three for one law and basis; where the blocks
sized by n are, the kernels read from the offsets table ``params[AT]`` (:data:`CONTROL_AT`), built
from those declarations. The shared blocks hold what every law needs: the shared gains of
``[controller]``, the sanitiser's last good values, the filters, the basis's input block
(:data:`vtoladapt.bases.INPUT`) and the per-tick block :data:`TICK`, through which the front end
(:mod:`.frontend`), the law and the back end (:mod:`.backend`) pass the tick's named quantities.
The model estimate theta-hat and ``P^-1`` (:func:`vtoladapt.control.adaptation.memory_layout`) is
read by the allocation for every law and updated only by adaptive laws.

Nothing here imports a law, the configuration or the step: laws import this module.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import forces
from .. import layout as L
from ..bases import INPUT
from ..layout import BlockLayout, Field
from . import adaptation as ad

# fault bits in diag['fault_flags']
FAULT_POSITION = 1
FAULT_VELOCITY = 2
FAULT_ATTITUDE = 4
FAULT_GYRO = 8
FAULT_ACCEL = 16
FAULT_PROBE = 32
FAULT_REFERENCE = 64
FAULT_COMMAND = 128
FAULT_ADAPTATION = 256
FAULT_DT = 512

# --- where the blocks sized by the basis are -----------------------------------------------------
CONTROL_AT = BlockLayout("controller offsets", [
    Field("ADAPTATION", ad.AT.size, "-", "the adaptation's offsets table (vtoladapt.control.adaptation.AT): n, "
          "its memory and scratch in state, its prior in params"),
    Field("PHI", 1, "-", "state: the unfiltered regressor Phi (3 x n, row-major) of this tick"),
    Field("INFO_SUM", 1, "-", "state: the un-forgotten information sum (n x n)"),
    Field("BASIS", 1, "-", "params: the basis's constants"),
    Field("BASIS_SIZE", 1, "-", "their number"),
    Field("BASIS_WORK", 1, "-", "state: the basis's scratch"),
    Field("BASIS_WORK_SIZE", 1, "-", "its size"),
    Field("D_THETA_HAT", 1, "-", "diag: theta-hat (n)"),
    Field("D_P_DIAG", 1, "-", "diag: diag(P) (n)"),
    Field("STATE_SIZE", 1, "-", "the state array's length"),
    Field("DIAG_SIZE", 1, "-", "the diag array's length"),
])
"""The offsets of the blocks sized by the basis, stored in ``params`` (never in ``state``, which a
caller may overwrite with a snapshot): built by :func:`controller_layout` from the declarations."""

# --- shared parameters ---------------------------------------------------------------------------
SHARED_PARAMS = BlockLayout("controller parameters (shared)", [
    Field("LAW_KEY", 1, "-", "the law's key (CRC-32 of its id, registry.law_key): which law's update runs"),
    Field("BASIS_KEY", 1, "-", "the force-model basis's key (CRC-32 of its id, vtoladapt.bases.basis_key)"),
    Field("AT", CONTROL_AT.size, "-", "where the blocks sized by the basis are (CONTROL_AT layout)"),
    Field("K_V", 3, "1/s", "velocity-error gain K_v (eq:f_ctrl), NED"),
    Field("LAMBDA_P", 3, "1/s", "position-error gain Lambda_p (eq:wr), NED"),
    Field("LAMBDA_Q", 3, "1/s", "attitude-error gain Lambda_q (eq:wr), FRD"),
    Field("K_OMEGA", 3, "N m s", "rate-error gain K_omega (eq:m_ctrl), FRD"),
    Field("J", 9, "kg m^2", "the controller's inertia, row-major"),
    Field("MODEL", forces.N_MODEL, "-", "the vehicle's force-model constants (vehicle.model_kernel)"),
    Field("LOWPASS_HZ", 1, "Hz", "filter [.]_f of the accelerometer and Phi"),
    Field("GAMMA_LYAP", 1, "-", "weight of the attitude term of the Lyapunov function"),
    Field("HOLDOFF_S", 1, "s", "adaptation resumes this long after the sensors are valid again"),
    Field("ALPHA_MIN", 1, "rad", "smallest desired angle of attack"),
    Field("ALPHA_MAX", 1, "rad", "largest desired angle of attack"),
    Field("V_LO", 1, "m/s", "hover-blend airspeed, start"),
    Field("V_HI", 1, "m/s", "hover-blend airspeed, end"),
    Field("TILT_MAX", 1, "rad", "tilt limit of the multirotor attitude"),
    Field("MIN_LIFT", 1, "m/s^2", "least upward force the multirotor attitude assumes"),
    Field("ACC_MAX", 1, "m/s^2", "limit on |f_r + g|"),
    Field("VCORR_MAX", 1, "m/s", "limit on |Lambda_p p~|"),
    Field("VERR_MAX", 1, "m/s", "limit on |v~|"),
    Field("WD_ON", 1, "-", "1: omega_d feed-forward on"),
    Field("WD_HZ", 1, "Hz", "omega_d low-pass cutoff"),
    Field("WD_MAX", 1, "rad/s", "limit on |omega_d|"),
    Field("WD_DOT_MAX", 1, "rad/s^2", "limit on |omega_d-dot|"),
    Field("TAU_MAX", 3, "N m", "limit on each body moment command"),
    Field("U_MAX", 1, "-", "throttle limit, fraction"),
    Field("VPROBE_MAX", 1, "m/s", "probe readings faster than this are invalid"),
    Field("WIND_TAU", 1, "s", "time constant of the wind estimate"),
    Field("WIND_FADE", 1, "s", "fade of the wind estimate while the probe is out"),
    Field("DT_NOMINAL", 1, "s", "nominal tick, replaces an invalid dt"),
    Field("MOTOR_LAG_ON", 1, "-", "1: the regressor's throttles pass through the nominal motor lag"),
    Field("MOTOR_TAU", 2, "s", "nominal motor time constants: pusher, lift"),
    Field("WV_AIRSPEED", 2, "m/s", "weathervane: off below the first horizontal airspeed, on above the second"),
    Field("HEADING_TAU", 1, "s", "time constant of the commanded heading"),
    Field("HEADING_RATE", 1, "rad/s", "rate limit of the commanded heading"),
    Field("ALIGN_COS", 2, "-", "cosines of the heading tolerances: wing weight full, zero"),
    Field("AP_GAIN", 1, "1/s", "flow-angle protection: integral gain on the measured alpha's excess"),
    Field("AP_TAU", 1, "s", "flow-angle protection: time constant of the measured-alpha filter"),
    Field("AP_TRIM_MAX", 1, "rad", "flow-angle protection: largest shift of an alpha_d limit"),
    Field("AP_SIGMAS", 1, "-", "flow-angle protection: guarded alpha = filtered alpha + this many spreads"),
    Field("AP_SPREAD_TAU", 1, "s", "flow-angle protection: time constant of the alpha spread estimate"),
    Field("UNSEEN_ACCEL", 2, "m/s^2", "body-horizontal prediction error: unseen flow off below, on above"),
    Field("LIFT_RESERVE", 1, "m/s^2", "lift the wing leaves to the lift rotors (their collective keeps moment authority)"),
    Field("FLOW_EST_ON", 1, "-", "1: estimate the airflow the probe cannot see from the unexplained force (0: off)"),
    Field("FLOW_EST_TAU", 1, "s", "time constant of that estimate's entry into the wind estimate"),
])
(P_LAW_KEY, P_BASIS_KEY, P_AT, P_K_V, P_LAMBDA_P, P_LAMBDA_Q, P_K_OMEGA, P_J, P_MODEL, P_LOWPASS_HZ, P_GAMMA_LYAP,
 P_HOLDOFF_S, P_ALPHA_MIN, P_ALPHA_MAX, P_V_LO, P_V_HI, P_TILT_MAX, P_MIN_LIFT, P_ACC_MAX, P_VCORR_MAX,
 P_VERR_MAX, P_WD_ON, P_WD_HZ, P_WD_MAX, P_WD_DOT_MAX, P_TAU_MAX, P_U_MAX, P_VPROBE_MAX, P_WIND_TAU,
 P_WIND_FADE, P_DT_NOMINAL, P_MOTOR_LAG_ON, P_MOTOR_TAU, P_WV_AIRSPEED, P_HEADING_TAU, P_HEADING_RATE, P_ALIGN_COS,
 P_AP_GAIN, P_AP_TAU, P_AP_TRIM_MAX, P_AP_SIGMAS, P_AP_SPREAD_TAU, P_UNSEEN_ACCEL,
 P_LIFT_RESERVE, P_FLOW_EST_ON, P_FLOW_EST_TAU) = SHARED_PARAMS.offsets(*(f.name for f in SHARED_PARAMS.fields))
(A_N, A_COVARIANCE, A_THETA, A_GAMMA, A_W, A_A_M, A_THETA0, A_THETA_INIT, A_LOWER, A_UPPER, A_GAMMA0, A_P0, A_WK_WTW,
 A_WK_M, A_WK_L) = (SHARED_PARAMS.offset("AT") + CONTROL_AT.offset("ADAPTATION") + o for o in ad.AT.offsets(
    "N", "COVARIANCE", "THETA", "GAMMA", "W", "A_M", "THETA0", "THETA_INIT", "LOWER", "UPPER", "GAMMA0", "P0", "WTW",
    "M", "L"))
"""Where, in ``params``, the adaptation's offsets table says n and where its blocks are (read them with ``int``)."""
(A_PHI, A_INFO_SUM, A_BASIS, A_BASIS_SIZE, A_BASIS_WORK, A_BASIS_WORK_SIZE, A_D_THETA_HAT, A_D_P_DIAG,
 A_STATE_SIZE, A_DIAG_SIZE) = SHARED_PARAMS.nested("AT", CONTROL_AT, "PHI", "INFO_SUM", "BASIS", "BASIS_SIZE",
                                                   "BASIS_WORK", "BASIS_WORK_SIZE", "D_THETA_HAT", "D_P_DIAG",
                                                   "STATE_SIZE", "DIAG_SIZE")
P_AD = SHARED_PARAMS.offset("AT") + CONTROL_AT.offset("ADAPTATION")
"""First slot of the adaptation's offsets table in ``params`` (the ``at, a`` of its kernels)."""
P_LAW = SHARED_PARAMS.size
"""First slot of the law's own parameter block."""

# --- the tick: named quantities passed between the front end, the law and the back end ------------
TICK = BlockLayout("controller tick", [
    Field("DT", 1, "s", "the tick used (an invalid dt is replaced: nominal, or 0.1 s)"),
    Field("NEW_DT", 1, "-", "1 if dt differs from the last tick's (recompute dt-dependent gains)"),
    Field("MAY_ADAPT", 1, "-", "1 if an adaptive law may update theta-hat now (filters started, probe and "
          "accelerometer valid for adaptation_holdoff_s)"),
    Field("ACCEL_OK", 1, "-", "1 if a law may use the filtered accelerometer now (filters started, accelerometer "
          "valid for adaptation_holdoff_s; the probe need not be)"),
    Field("PROBE_OK", 1, "-", "1 if the probe's reading is used this tick"),
    Field("FAULTS", 1, "-", "FAULT_* bits found by the front end"),
    Field("R_WB", 9, "-", "attitude R_WB, row-major (sanitised)"),
    Field("V_W", 3, "m/s", "velocity, NED (sanitised)"),
    Field("P_TILDE", 3, "m", "position error p - p_d, NED"),
    Field("V_R", 3, "m/s", "reference velocity v_r (eq:wr), NED"),
    Field("V_R_DOT", 3, "m/s^2", "its derivative v_r', NED"),
    Field("V_TILDE_RAW", 3, "m/s", "velocity error v - v_r, NED"),
    Field("V_TILDE", 3, "m/s", "the same, limited to velocity_error_max_mps"),
    Field("A_D", 3, "m/s^2", "desired acceleration, NED"),
    Field("YAW_D", 1, "rad", "desired heading"),
    Field("E", 3, "m/s^2", "prediction error W theta-hat - a_m before the law's update (eq:prediction_error), body"),
    Field("F_R", 3, "m/s^2", "the law's force command f_r, NED, gravity included"),
    Field("ADAPT_ACTIVE", 1, "-", "the law: 1 if theta-hat and P were updated this tick"),
    Field("LAW_FAULTS", 1, "-", "the law: its FAULT_* bits"),
])
"""One tick's named data: the front end writes up to ``E``, the law's ``update`` reads them and writes
``F_R``, ``ADAPT_ACTIVE`` and ``LAW_FAULTS``, the back end reads them all. The incident velocity, the
throttles and the flow quantities of the tick are in the basis's input block (``S_INPUT``)."""
(T_DT, T_NEW_DT, T_MAY_ADAPT, T_ACCEL_OK, T_PROBE_OK, T_FAULTS, T_R_WB, T_V_W, T_P_TILDE, T_V_R, T_V_R_DOT,
 T_V_TILDE_RAW, T_V_TILDE, T_A_D, T_YAW_D, T_E, T_F_R, T_ADAPT_ACTIVE, T_LAW_FAULTS) = TICK.offsets(*(f.name for f in TICK.fields))
TICK_SIZE = TICK.size

# --- shared state --------------------------------------------------------------------------------
# The filter and lag gains depend only on dt and the parameters: they are computed when dt changes
# (every tick of the Python API, whose dt jitters by rounding; once per run in the simulator).
GAINS = BlockLayout("shared filter gains", [
    Field("LOWPASS", 1, "-", "gain of [.]_f"),
    Field("WIND", 1, "-", "gain of the wind estimate's low-pass"),
    Field("FADE", 1, "-", "decay factor of the wind estimate while the probe is out"),
    Field("MOTOR_X", 1, "-", "decay factor of the pusher's nominal lag"),
    Field("MOTOR_Z", 1, "-", "decay factor of the lift rotors' nominal lag"),
    Field("OMEGA_D", 1, "-", "gain of the omega_d low-passes"),
    Field("FLOW_EST", 1, "-", "gain of the unseen-flow airflow estimate's entry into the wind estimate"),
])
GAIN_LOWPASS, GAIN_WIND, GAIN_FADE, GAIN_MOTOR_X, GAIN_MOTOR_Z, GAIN_OMEGA_D, GAIN_FLOW_EST = GAINS.offsets(
    *(f.name for f in GAINS.fields))

SHARED_STATE = BlockLayout("controller state (shared)", [
    Field("TICK", TICK.size, "-", "this tick's named quantities (TICK layout): front end -> law -> back end"),
    Field("INPUT", INPUT.size, "-", "the basis's input this tick (vtoladapt.bases.INPUT)"),
    Field("FILT_INIT", 1, "-", "1 once the filters have their first sample"),
    Field("V_PREV", 3, "m/s", "last tick's velocity, NED"),
    Field("U_PREV", 2, "-", "throttles commanded for the current interval"),
    Field("TAU_PREV", 3, "N m", "last moment command, FRD"),
    Field("Q_D_PREV", 4, "-", "last desired attitude"),
    Field("WD_X1", 3, "rad/s", "omega_d filter, first stage"),
    Field("WD_X2", 3, "rad/s", "omega_d filter, second stage (omega_d)"),
    Field("HAVE_QD", 1, "-", "1 once a desired attitude exists"),
    Field("Y_I_PREV", 3, "-", "last desired body y axis"),
    Field("HAVE_Y_I", 1, "-", "1 once Y_I_PREV holds one"),
    Field("WIND_EST", 3, "m/s", "wind estimate, NED"),
    Field("HAVE_WIND", 1, "-", "1 once the wind estimate has a sample"),
    Field("VALID_TIME", 1, "s", "time the probe and accelerometer have been valid"),
    Field("ACCEL_VALID_TIME", 1, "s", "time the accelerometer has been valid (the probe or not)"),
    Field("P_LAST", 3, "m", "last good position, NED"),
    Field("V_LAST", 3, "m/s", "last good velocity, NED"),
    Field("Q_LAST", 4, "-", "last good attitude"),
    Field("OMEGA_LAST", 3, "rad/s", "last good body rate"),
    Field("HAVE_MEAS", 1, "-", "1 after the first tick"),
    Field("REF_LAST", L.REF_SIZE, "-", "last good reference (REF_* layout)"),
    Field("HAVE_REF", 1, "-", "1 once a reference was seen"),
    Field("SAT_PREV", 2, "-", "last allocation's saturation flags"),
    Field("RES_PREV_W", 3, "m/s^2", "last allocation's residual, NED"),
    Field("TIME", 1, "s", "controller time"),
    Field("STEPS", 1, "-", "ticks so far"),
    Field("U_EST", 2, "-", "throttles the motors are estimated to deliver (nominal lag)"),
    Field("GAINS_DT", 1, "s", "the dt the gains were computed for; 0: not yet"),
    Field("GAINS", GAINS.size, "-", "the filter gains (GAINS layout)"),
    Field("HEADING", 1, "rad", "commanded heading (multirotor solution, wing alignment)"),
    Field("TURN_SIGN", 1, "-", "direction of the heading turn under way: -1, 0, +1"),
    Field("WV_ON", 1, "-", "1 while the heading weathervanes into the flow"),
    Field("YAW_REF_PREV", 1, "rad", "last tick's reference yaw (its change is fed forward)"),
    Field("HAVE_HEADING", 1, "-", "1 once HEADING holds one"),
    Field("ALPHA_F", 1, "rad", "filtered measured angle of attack"),
    Field("ALPHA_TRIM", 2, "rad", "flow-angle protection trims: upper (>= 0), lower (<= 0)"),
    Field("ALPHA_VAR", 1, "rad^2", "variance of the measured alpha about its filtered value"),
    Field("UNSEEN_FLOW", 1, "-", "1 while the prediction error shows airflow the probe does not report"),
    Field("FLOW_EST_ON", 1, "-", "1 while the wind estimate follows the airflow estimated from the force (airflow_estimate)"),
    Field("FLOW_EST_W", 2, "m/s", "last accepted airflow estimate's horizontal wind, N and E (its warm start)"),
])
(S_TICK, S_INPUT, S_FILT_INIT, S_V_PREV, S_U_PREV, S_TAU_PREV, S_Q_D_PREV, S_WD_X1, S_WD_X2, S_HAVE_QD, S_Y_I_PREV,
 S_HAVE_Y_I, S_WIND_EST, S_HAVE_WIND, S_VALID_TIME, S_ACCEL_VALID_TIME, S_P_LAST, S_V_LAST, S_Q_LAST, S_OMEGA_LAST,
 S_HAVE_MEAS,
 S_REF_LAST, S_HAVE_REF, S_SAT_PREV, S_RES_PREV_W, S_TIME, S_STEPS, S_U_EST, S_GAINS_DT,
 S_GAINS, S_HEADING, S_TURN_SIGN, S_WV_ON, S_YAW_REF_PREV, S_HAVE_HEADING, S_ALPHA_F,
 S_ALPHA_TRIM, S_ALPHA_VAR, S_UNSEEN_FLOW, S_FLOW_EST_ON, S_FLOW_EST_W) = SHARED_STATE.offsets(*(f.name for f in SHARED_STATE.fields))
S_LAW = SHARED_STATE.size
"""First slot of the law's own state block."""

# --- diagnostics ---------------------------------------------------------------------------------
_XYZ_NED = ("N", "E", "D")
_XYZ_B = ("x", "y", "z")


def _cols(stem: str, axes, unit: str) -> tuple[str, ...]:
    return tuple(f"{stem}_{a}_{unit}" if unit else f"{stem}_{a}" for a in axes)


SHARED_DIAG = BlockLayout("controller diagnostics (shared)", [
    Field("P_TILDE", 3, "m", "position error p - p_d", _cols("p_tilde", _XYZ_NED, "m")),
    Field("V_TILDE", 3, "m/s", "velocity error v - v_r (before its limit)", _cols("v_tilde", _XYZ_NED, "mps")),
    Field("V_R", 3, "m/s", "reference velocity v_r (eq:wr)", _cols("v_r", _XYZ_NED, "mps")),
    Field("Q_TILDE", 4, "-", "attitude error quaternion", ("q_tilde_0", "q_tilde_x", "q_tilde_y", "q_tilde_z")),
    Field("F_R", 3, "m/s^2", "force command f_r", _cols("f_r", _XYZ_NED, "mps2")),
    Field("Q_D", 4, "-", "desired attitude", ("q_d_w", "q_d_x", "q_d_y", "q_d_z")),
    Field("OMEGA_D", 3, "rad/s", "desired frame's rate (feed-forward)", _cols("omega_d", _XYZ_B, "radps")),
    Field("OMEGA_R", 3, "rad/s", "reference rate (eq:wr)", _cols("omega_r", _XYZ_B, "radps")),
    Field("ALPHA_D", 1, "rad", "desired angle of attack", ("alpha_d_rad",)),
    Field("AIRSPEED", 1, "m/s", "airspeed the controller used", ("ctrl_airspeed_mps",)),
    Field("BLEND", 1, "-", "weight of the wing attitude", ("blend_weight_wing",)),
    Field("V_I_USED", 3, "m/s", "incident velocity used, body", _cols("ctrl_v_i", _XYZ_B, "mps")),
    Field("WIND_EST", 3, "m/s", "wind estimate, NED", _cols("wind_est", _XYZ_NED, "mps")),
    Field("PRED_ERR", 3, "m/s^2", "prediction error W theta-hat - a_m (eq:prediction_error), body",
          _cols("pred_err", _XYZ_B, "mps2")),
    Field("A_M", 3, "m/s^2", "filtered specific force, body", _cols("a_m", _XYZ_B, "mps2")),
    Field("W_THETA", 3, "m/s^2", "predicted specific force, body", _cols("W_theta", _XYZ_B, "mps2")),
    Field("ALLOC_RES", 3, "m/s^2", "allocation residual, body", _cols("alloc_residual", _XYZ_B, "mps2")),
    Field("SAT_X", 1, "-", "pusher saturation: -1 at 0, +1 at the limit, 0", ("sat_u_x",)),
    Field("SAT_Z", 1, "-", "lift saturation: -1 at 0, +1 at the limit, 0", ("sat_u_z",)),
    Field("PROBE_VALID", 1, "-", "1 if the probe reading was used", ("probe_valid_used",)),
    Field("ADAPT_ACTIVE", 1, "-", "1 if theta-hat and P were updated this tick", ("adaptation_active",)),
    Field("LYAP_V", 1, "m^2/s^2", "velocity term of the Lyapunov function", ("lyap_velocity_term_m2ps2",)),
    Field("LYAP_Q", 1, "-", "attitude term of the Lyapunov function", ("lyap_attitude_term",)),
    Field("FAULTS", 1, "-", "sum of the FAULT_* bits", ("fault_flags",)),
    Field("HEADING", 1, "rad", "commanded heading", ("heading_cmd_rad",)),
    Field("WV_ON", 1, "-", "1 while weathervaning into the flow", ("weathervane_on",)),
    Field("ALPHA_MEAS", 1, "rad", "filtered measured angle of attack", ("alpha_meas_filt_rad",)),
    Field("ALPHA_LIMITS", 2, "rad", "alpha_d limits flown after the flow-angle protection",
          ("alpha_min_flown_rad", "alpha_max_flown_rad")),
    Field("ALPHA_SPREAD", 1, "rad", "standard deviation of the measured alpha about its filtered value",
          ("alpha_meas_spread_rad",)),
    Field("UNSEEN_FLOW", 1, "-", "1 while the prediction error shows airflow the probe does not report",
          ("unseen_flow",)),
    Field("FLOW_EST_ON", 1, "-", "1 while the wind estimate follows the airflow estimated from the unexplained force",
          ("unseen_flow_estimate",)),
])
(DIAG_P_TILDE, DIAG_V_TILDE, DIAG_V_R, DIAG_Q_TILDE, DIAG_F_R, DIAG_Q_D, DIAG_OMEGA_D, DIAG_OMEGA_R, DIAG_ALPHA_D,
 DIAG_AIRSPEED, DIAG_BLEND, DIAG_V_I_USED, DIAG_WIND_EST, DIAG_PRED_ERR, DIAG_A_M, DIAG_W_THETA, DIAG_ALLOC_RES,
 DIAG_SAT_X, DIAG_SAT_Z, DIAG_PROBE_VALID, DIAG_ADAPT_ACTIVE, DIAG_LYAP_V, DIAG_LYAP_Q, DIAG_FAULTS, DIAG_HEADING,
 DIAG_WV_ON, DIAG_ALPHA_MEAS, DIAG_ALPHA_LIMITS, DIAG_ALPHA_SPREAD, DIAG_UNSEEN_FLOW,
 DIAG_FLOW_EST_ON) = SHARED_DIAG.offsets(*(f.name for f in SHARED_DIAG.fields))
D_LAW = SHARED_DIAG.size
"""First slot of the law's own diagnostics block. The columns of a run's ``diag`` array are
:func:`diagnostics_columns` of its ``params``: these shared ones (units in the names; ``sat_u_*``: -1
throttle at 0, the row wanted the other sign, +1 at the limit, 0; ``fault_flags``: sum of the
``FAULT_*`` bits; ``lyap_*``: the tracking terms of the Lyapunov function, whose parameter term needs
the truth, :func:`vtoladapt.control.adaptation.lyapunov_function`), then the law's own (its ``DIAG``),
then ``theta_hat_<name>`` and ``P_diag_<name>`` per parameter of the basis."""


def law_offsets(layout: BlockLayout, base: int, *names: str) -> tuple[int, ...]:
    """Absolute offsets of a law's fields: ``base`` (:data:`P_LAW`, :data:`S_LAW` or :data:`D_LAW`) plus
    their place in ``layout``."""
    return tuple(base + o for o in layout.offsets(*names))


# --- one run's whole arrays ----------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class ControllerLayout:
    """The declared ``params``, ``state`` and ``diag`` arrays of one law and one basis of n parameters.

    ``params``, ``state``, ``diag``: the whole arrays (:class:`~vtoladapt.layout.BlockLayout`, one field
    per block); ``prior``, ``memory``, ``work``: the adaptation's blocks for n; ``at``: the offsets
    table :data:`CONTROL_AT` to store at ``params[AT]``.
    """

    n: int
    params: BlockLayout
    state: BlockLayout
    diag: BlockLayout
    prior: BlockLayout
    memory: BlockLayout
    work: BlockLayout
    at: np.ndarray


def controller_layout(n: int, law, names: tuple[str, ...], basis_size: int, basis_work_size: int) -> ControllerLayout:
    """The whole arrays of a controller with ``law`` (its module: ``PARAMS``, ``STATE``, ``DIAG``) and a basis
    of ``n`` parameters named ``names``, ``basis_size`` constants and ``basis_work_size`` floats of scratch."""
    prior, memory, work = ad.prior_layout(n), ad.memory_layout(n), ad.work_layout(n)
    params = BlockLayout("controller parameters", [
        Field("SHARED", SHARED_PARAMS.size, "-", "SHARED_PARAMS"),
        Field("LAW", law.PARAMS.size, "-", f"the law's ({law.PARAMS.title})"),
        Field("PRIOR", prior.size, "adaptation units", "the adaptation's prior"),
        Field("BASIS", basis_size, "-", "the basis's constants"),
    ])
    state = BlockLayout("controller state", [
        Field("SHARED", SHARED_STATE.size, "-", "SHARED_STATE"),
        Field("LAW", law.STATE.size, "-", f"the law's ({law.STATE.title})"),
        Field("ESTIMATE", memory.size, "adaptation units", "theta-hat, P^-1, filtered W and a_m"),
        Field("PHI", 3 * n, "m/s^2 per adaptation unit", "the unfiltered regressor of this tick, row-major"),
        Field("INFO_SUM", n * n, "s (m/s^2 per adaptation unit)^2",
              "un-forgotten information sum of w_pred W^T W dt over the adapting ticks (identifiability)"),
        Field("WORK", work.size, "-", "the adaptation's scratch (no meaning between ticks)"),
        Field("BASIS_WORK", basis_work_size, "-", "the basis's scratch"),
    ])
    diag = BlockLayout("controller diagnostics", [
        Field("SHARED", SHARED_DIAG.size, "-", "SHARED_DIAG", columns=SHARED_DIAG.columns),
        Field("LAW", law.DIAG.size, "-", f"the law's ({law.DIAG.title})", columns=law.DIAG.columns),
        Field("THETA_HAT", n, "adaptation units", "theta-hat", columns=tuple(f"theta_hat_{k}" for k in names)),
        Field("P_DIAG", n, "adaptation units", "diag(P) (written by an adaptive law; P0's otherwise)",
              columns=tuple(f"P_diag_{k}" for k in names)),
    ])
    if len(set(diag.columns)) != len(diag.columns):
        seen = set()
        dup = next(c for c in diag.columns if c in seen or seen.add(c))
        raise ValueError(f"diagnostics column {dup!r} is declared twice (the law's DIAG and the shared ones, or "
                         "the basis's names)")
    p0, s0 = params.offset("PRIOR"), state.offset("ESTIMATE")
    table = ad.offsets_table(n, s0, p0, state.offset("WORK"))
    at = CONTROL_AT.pack(ADAPTATION=table, PHI=state.offset("PHI"), INFO_SUM=state.offset("INFO_SUM"),
                         BASIS=params.offset("BASIS"), BASIS_SIZE=basis_size,
                         BASIS_WORK=state.offset("BASIS_WORK"), BASIS_WORK_SIZE=basis_work_size,
                         D_THETA_HAT=diag.offset("THETA_HAT"), D_P_DIAG=diag.offset("P_DIAG"),
                         STATE_SIZE=state.size, DIAG_SIZE=diag.size)
    return ControllerLayout(n=n, params=params, state=state, diag=diag, prior=prior, memory=memory, work=work, at=at)
