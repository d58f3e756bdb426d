"""Controller settings: the frozen, validated ``[controller]`` table of a scenario and its law tables.

``[controller]`` holds the controller's ``kind`` (an id of :mod:`~vtoladapt.control.registry`), its force-model
``basis`` (an id of :mod:`vtoladapt.bases`; default the vehicle's) and the gains every law shares;
each law's own gains are in its table ``[controller.<id>]`` (the law module's ``Settings``, e.g.
``[controller.pid] K_I``, ``[controller.composite] forgetting_lambda``), read as
``config.<id>`` (``config.pid.K_I``) and given as ``ControllerConfig(pid=PIDSettings(...))``. The
law ids are looked up in the registry when a table is read or an attribute asked for, so a law
registered after import has its table like the package's own. A law gain
written in ``[controller]`` itself (where it was before the laws had their own tables) is refused
with a message naming the table it moved to; nothing is silently dropped or zeroed. Every gain
carries its unit (see :func:`vtoladapt.config.describe`). Defaults and why
----------------------------------------------------------------------------------------

The paper gives none of its gains; the defaults below are chosen for the 250 Hz loop, the
30-40 ms motor lag of the paper's aircraft and the PX4 multicopter defaults the baselines copy.
They are checked by ``tests/test_control_gains.py`` (discrete-time closed-loop eigenvalues of the
linearised attitude and velocity loops, with the motor lag and the one-tick hold).

* **Velocity and position loops (every law).** ``K_v = (1.8, 1.8, 4.0) 1/s`` and
  ``Lambda_p = (0.95, 0.95, 1.0) 1/s`` are PX4's ``MPC_XY_VEL_P_ACC``, ``MPC_Z_VEL_P_ACC``,
  ``MPC_XY_P``, ``MPC_Z_P`` defaults. They are the "equivalent gains" of the paper's comparison:
  the adaptive controllers' ``K_v`` and ``Lambda_p`` *are* the PID's velocity and position P
  gains. The horizontal velocity loop acts through the attitude loop, so its 0.55 s time
  constant stays 3x slower than the attitude loop's; the vertical loop acts directly on the lift
  rotors (one motor lag, 30 ms) and can be faster.
* **Law gains** (PID integral and derivative, forgetting factor, sigma): in each law's module
  (:mod:`.laws.pid`, :mod:`.laws.composite`, ...), with the reasons for their defaults.
* **Attitude loop.** ``Lambda_q = (10, 10, 6) 1/s``: with ``omega = omega_r``, eq:wr gives
  ``q_v' = -Lambda_q q_v / 2``, a 0.2 s roll/pitch time constant (PX4's ``MC_ROLL_P`` = 6.5 on
  the angle is ``Lambda_q`` = 13 on the quaternion vector part), a factor ~4 below the rate loop.
* **Rate loop.** ``K_omega`` defaults to ``J * rate_bandwidth_radps`` with bandwidths
  ``(20, 20, 10) rad/s``: for a rate loop closed through a first-order motor lag ``tau_m`` the
  damping ratio is ``zeta = sqrt(J / (K tau_m)) / 2``, so ``K/J = 20 /s`` with ``tau_m`` = 30 ms
  gives zeta = 0.65 (yaw, driven by weak rotor drag torques, is kept slower).
* **Prediction-error filter.** ``lowpass_cutoff_hz = 10`` (the paper); shared, since every
  law's log holds the prediction error of its theta-hat.
* **omega_d feed-forward off.** ``omega_d`` must be differenced from ``R_d``, and in the wing
  regime ``R_d`` follows the measured flow direction: with the probe's ~0.3 deg angle noise and
  4 % turbulence, ``omega_d`` and ``omega_d'`` (even filtered at 5 Hz) added ~0.3 N m rms of pitch
  torque and saturated the mixer 70-95 % of the time in the paper_comparison scenario, against
  0.1 N m and < 1 % (outside the 9 m/s segment) without them. ``Lambda_q`` = 10 /s tracks the slow
  changes of ``R_d`` in that experiment without feed-forward; turn it on for smooth references.
* **What ``vtoladapt tune`` searches of these** (:data:`TUNABLE`, every law's search space
  besides its own gains; :mod:`vtoladapt.experiments.tuning`): ``K_v`` horizontal and vertical,
  ``Lambda_p`` horizontal and vertical, ``Lambda_q`` roll and pitch. Every registered law uses all
  five (``K_v`` in eq:f_ctrl or as the PID's velocity P gain, ``Lambda_p`` in eq:wr, ``Lambda_q``
  in the shared attitude loop), so a law that may tune extra loop gains of its own (the PID's
  integral and derivative) no longer competes against laws held at PX4's loop gains. Horizontal
  and vertical are separate because the two loops act through different actuators (tilt through
  the attitude loop; the lift rotors directly). ``Lambda_q`` is searched because it sets how fast
  the horizontal force follows the command (measured on six tuning draws: roll/pitch 10 -> 20 /s
  takes C. Adapt's and L1's RMS velocity error from 0.046 to 0.037 m/s, the PID's stays 0.104);
  yaw's is not (the fan blows head-on). Not searched: the rate loop's ``rate_bandwidth_radps``
  (20 -> 40 rad/s does about what ``Lambda_q`` 10 -> 20 does; the attitude cascade's speed is
  searched once, through ``Lambda_q``, and each extra dimension thins the equal budget of every
  law), the filters and the safety limits.
* **Safety limits** (not in the paper): a tilt limit and a minimum lift for the multirotor
  attitude (PX4 ``MPC_TILTMAX_AIR`` = 45 deg), a 2 g limit on the commanded acceleration, a
  5 m/s limit on the position loop's velocity correction and a 10 m/s limit on the velocity error,
  so that a wild measurement or reference can never command a wild attitude.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Mapping, Optional

from ..bases import basis_ids
from ..components import component_tables
from ..config import ConfigError, Validated, build, check_flag, read_toml, setting
from .registry import CONTROLLERS, ControllerInfo, controller_ids, controller_info


TUNABLE = (("K_v[0:2]", 0.5, 8.0, True), ("K_v[2]", 1.0, 20.0, True),
           ("Lambda_p[0:2]", 0.2, 5.0, True), ("Lambda_p[2]", 0.2, 5.0, True),
           ("Lambda_q[0:2]", 3.0, 30.0, True))
"""The shared ``[controller]`` gains ``vtoladapt tune`` searches for every law, besides the law's own
``TUNABLE`` (:mod:`vtoladapt.experiments.tuning`): (setting, low, high, log scale). Boxes: ``K_v``
a factor ~4 each side of PX4's defaults (1.8, 4.0 /s); ``Lambda_p`` 0.2-5 /s around PX4's 0.95-1.0;
``Lambda_q`` 3-30 /s, whose top keeps the attitude loop's ``Lambda_q / 2`` = 15 rad/s below the
rate loop's 20 rad/s."""

LOOP_RATE_MIN_HZ = 10.0
"""Slowest controller rate: the compiled step takes a tick longer than 0.1 s for a fault."""
LOOP_RATE_MAX_HZ = 10000.0
"""Fastest controller rate (a scenario's ``dt_control_s`` >= 1e-4 s)."""


@dataclass(frozen=True, init=False)
class ControllerConfig(Validated):
    """Gains and settings of one controller: the scenario's ``[controller]`` table.

    Its keys are the fields below; each registered law's own settings are its table
    ``[controller.<id>]``, read as the attribute ``<id>`` (that law's ``Settings``; its defaults
    where the table is absent) and given as the keyword ``<id>=`` (``ControllerConfig(kind="pid",
    pid=PIDSettings(K_I=...))``, ``dataclasses.replace(config, pid=...)``). Only the law named by
    ``kind`` flies; the others' tables are kept so that a comparison can switch ``kind``. The law
    tables are stored in :attr:`laws` (those that differ from their defaults, by id).

    All 3-vectors are diagonals of the paper's gain matrices, in NED (``K_v``, ``Lambda_p``) or
    body FRD (``Lambda_q``, ``K_omega``) axes. Built in Python it is validated as a file's table
    is (:class:`vtoladapt.config.Validated`).
    """

    config_section = "controller"

    kind: str = setting("-", "which controller: an id of vtoladapt.control.registry (`vtoladapt controllers` "
                        "lists them with what each law is)", default="composite", choices=controller_ids)
    basis: Optional[str] = setting("-", "the force-model basis theta-hat adapts: an id of vtoladapt.bases "
                                   "(`vtoladapt bases` lists them); default: the vehicle file's `basis`",
                                   default=None, choices=basis_ids)
    K_v: tuple[float, ...] = setting("1/s", "velocity-error gain K_v (eq:f_ctrl); the PID's velocity "
                                     "P gain", default=(1.8, 1.8, 4.0), gt=0.0, length=3)
    Lambda_p: tuple[float, ...] = setting("1/s", "position-error gain Lambda_p (eq:wr); the PID's "
                                          "position P gain", default=(0.95, 0.95, 1.0), gt=0.0, length=3)
    Lambda_q: tuple[float, ...] = setting("1/s", "attitude-error gain Lambda_q (eq:wr)",
                                          default=(10.0, 10.0, 6.0), gt=0.0, length=3)
    K_omega: Optional[tuple[float, ...]] = setting(
        "N m s", "rate-error gain K_omega (eq:m_ctrl); default J * rate_bandwidth_radps",
        default=None, gt=0.0, length=3)
    rate_bandwidth_radps: tuple[float, ...] = setting(
        "rad/s", "K_omega / J per body axis, used when K_omega is not given",
        default=(20.0, 20.0, 10.0), gt=0.0, length=3)
    lowpass_cutoff_hz: float = setting("Hz", "first-order filter [.]_f on the accelerometer and Phi "
                                       "(eq:prediction_error)", default=10.0, gt=0.0)
    gamma: float = setting("-", "weight gamma of the attitude term in the Lyapunov function",
                           default=1.0, gt=0.0)
    adaptation_holdoff_s: float = setting(
        "s", "an adaptive law resumes adapting this long after the probe or accelerometer is valid "
        "again (filters re-settle)", default=0.05, ge=0.0)
    alpha_max_deg: Optional[float] = setting("deg", "largest desired angle of attack; default: the "
                                             "vehicle's envelope", default=None, gt=0.0, le=45.0)
    alpha_min_deg: Optional[float] = setting("deg", "smallest desired angle of attack; default: "
                                             "-alpha_max", default=None, ge=-45.0, lt=45.0)
    tilt_max_deg: float = setting("deg", "tilt limit of the multirotor (low-airspeed) attitude",
                                  default=45.0, gt=0.0, lt=90.0)
    min_lift_mps2: float = setting("m/s^2", "least upward force the multirotor attitude assumes, so "
                                   "f_r = 0 or downward still gives an upright attitude",
                                   default=1.0, gt=0.0)
    accel_max_mps2: float = setting("m/s^2", "limit on |f_r + g| (the commanded acceleration)",
                                    default=19.6, gt=0.0)
    velocity_correction_max_mps: float = setting(
        "m/s", "limit on |Lambda_p p~| in v_r (eq:wr)", default=5.0, gt=0.0)
    velocity_error_max_mps: float = setting(
        "m/s", "limit on |v~| used in eq:f_ctrl and eq:th_adapt", default=10.0, gt=0.0)
    regressor_motor_lag: bool = setting(
        "-", "throttles in Phi pass through the vehicle's nominal motor lag (actuators time constants), "
        "so W theta compares with the accelerometer's lagged thrust; false: the raw commands",
        default=True)
    omega_d_feedforward: bool = setting(
        "-", "feed the desired frame's rate omega_d (differenced from R_d) forward in eq:wr and eq:m_ctrl; "
        "off by default: R_d follows the probe's noisy flow direction", default=False)
    omega_d_cutoff_hz: float = setting("Hz", "two-stage low-pass deriving omega_d and its rate from "
                                       "R_d", default=5.0, gt=0.0)
    omega_d_max_radps: float = setting("rad/s", "limit on |omega_d|", default=3.0, ge=0.0)
    omega_d_dot_max_radps2: float = setting("rad/s^2", "limit on |omega_d-dot|", default=30.0, ge=0.0)
    torque_max_Nm: Optional[tuple[float, ...]] = setting(
        "N m", "limit on each body moment command; default: the lift rotors' authority "
        "(2 T_max |y|, 2 T_max |x|, 2 T_max k_m)", default=None, gt=0.0, length=3)
    probe_airspeed_max_mps: float = setting("m/s", "probe readings faster than this are invalid",
                                            default=60.0, gt=0.0)
    wind_estimate_time_constant_s: float = setting(
        "s", "low-pass of the wind estimate v - R v_i used while the probe is invalid",
        default=1.0, gt=0.0)
    wind_estimate_fade_s: float = setting(
        "s", "while the probe is invalid the wind estimate fades toward zero with this time constant",
        default=2.0, gt=0.0)
    loop_rate_hz: float = setting(
        "Hz", "the rate the controller runs at: the Python API's first tick and the tick that replaces an invalid "
        "one, and the dt of the laws' stability checks (L1's a_s dt, the sigma step); in a scenario it is "
        "1/dt_control_s (set from it; a different value is refused)",
        default=250.0, ge=LOOP_RATE_MIN_HZ, le=LOOP_RATE_MAX_HZ)
    weathervane_airspeed_mps: Optional[tuple[float, ...]] = setting(
        "m/s", "the commanded heading turns into the flow above the second horizontal airspeed and back to "
        "the reference yaw below the first (hysteresis); default: 0.75 and 1 times the vehicle's "
        "hover-blend start", default=None, ge=0.0, le=100.0, length=2)
    heading_time_constant_s: float = setting(
        "s", "time constant of the commanded heading's approach to its target (flow or reference yaw)",
        default=1.0, gt=0.0, le=100.0)
    heading_rate_max_degps: float = setting(
        "deg/s", "rate limit of the commanded heading's turn (the reference yaw's own change passes "
        "unlimited); 90: a tail wind's 180 deg turn takes 2 s, not 6 s flown blind (the rotors' yaw "
        "authority allows ~2 rad/s^2 on both shipped vehicles)", default=90.0, gt=0.0, le=720.0)
    wing_heading_tolerance_deg: tuple[float, ...] = setting(
        "deg", "the wing attitude takes full weight while the commanded heading is within the first angle "
        "of the flow direction, none beyond the second", default=(10.0, 30.0), gt=0.0, lt=90.0, length=2)
    alpha_protect_gain_per_s: float = setting(
        "1/s", "flow-angle protection: integral gain lowering the alpha_d limit by the measured alpha's "
        "excess over alpha_max (0: off)", default=2.0, ge=0.0, le=100.0)
    alpha_protect_filter_hz: float = setting(
        "Hz", "flow-angle protection: low-pass of the probe's measured alpha", default=1.0, gt=0.0, le=125.0)
    alpha_protect_trim_max_deg: float = setting(
        "deg", "flow-angle protection: largest shift of an alpha_d limit", default=10.0, ge=0.0, le=45.0)
    alpha_protect_sigmas: float = setting(
        "-", "flow-angle protection: the guarded alpha is the filtered measured alpha plus (minus) this many "
        "of its measured standard deviations", default=3.0, ge=0.0, le=10.0)
    alpha_protect_spread_time_constant_s: float = setting(
        "s", "flow-angle protection: time constant of the measured alpha's variance estimate",
        default=1.0, gt=0.0, le=100.0)
    unseen_flow_accel_mps2: tuple[float, ...] = setting(
        "m/s^2", "an invalid probe reading is taken as still air only while the body-horizontal prediction "
        "error is below the second value (again once it falls below the first); above, the airflow is "
        "one the probe cannot see (from the side, from behind); (0.1, 0.2): a tail wind's drag at 3.9 m/s "
        "(~0.37 m/s^2) stayed below 0.4, and the hover p95 is ~0.1", default=(0.1, 0.2), gt=0.0, le=100.0,
        length=2)
    unseen_flow_estimate: bool = setting(
        "-", "while the probe cannot see the flow (unseen_flow_accel_mps2), estimate the horizontal airflow from "
        "the body-horizontal force the model cannot explain (the model's drag and rotor side force inverted, "
        "vtoladapt.control.airflow_estimate) and feed it to the wind estimate; false (default): the stale wind "
        "estimate fades as before, bit for bit. Off by default: measured, it did not help (README, envelope "
        "section): the model's horizontal force at 2-5 m/s (0.1-0.3 m/s^2) is the size of the accelerometer's "
        "bias, so the inverted airspeed is off by ~50 %", default=False)
    unseen_flow_estimate_time_constant_s: float = setting(
        "s", "time constant with which that estimate enters the wind estimate (the accelerometer it inverts is "
        "already low-passed at lowpass_cutoff_hz)", default=0.2, gt=0.0, le=100.0)
    lift_rotor_reserve_mps2: float = setting(
        "m/s^2", "lift (per unit mass) the wing solution leaves to the lift rotors, so that their collective "
        "keeps moment authority at speed (the aircraft's only moment effectors; not in the paper's eq:alphad, "
        "0 gives it); 5 (~0.5 g): 2.5 still left the mixer saturated 22 % of a fan step to 12.9 m/s, since "
        "gusts of +-3 deg alpha swing the wing's lift by ~2.3 m/s^2 there; at most 8 (0.8 g): near g the wing "
        "is asked for no lift or a downward one (alpha_d negative) and measured, 10 lost the aircraft",
        default=5.0, ge=0.0, le=8.0)
    laws: Any = setting("-", "the law tables [controller.<id>] that differ from their defaults: ((id, settings), "
                        "...) sorted by id (read them as config.<id>)", default=())

    def __init__(self, **values) -> None:
        names = {f.name for f in dataclasses.fields(self)}
        tables = dict(values.pop("laws", ()) or ())
        for key in [k for k in values if k not in names]:
            if key not in CONTROLLERS:
                raise TypeError(f"ControllerConfig: unexpected keyword {key!r}: neither a [controller] key nor a "
                                f"registered law ({', '.join(controller_ids())})")
            tables[key] = values.pop(key)
        for f in dataclasses.fields(self):
            object.__setattr__(self, f.name, values[f.name] if f.name in values else f.default)
        object.__setattr__(self, "laws", _law_tables(tables))
        self.__post_init__()

    def __getattr__(self, name: str):
        # reached only for names that are not fields: a law's table, looked up in the registry now
        if name.startswith("_") or name not in CONTROLLERS:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        for key, settings in self.__dict__.get("laws", ()):
            if key == name:
                return settings
        return _law_settings_class(name)()

    @classmethod
    def sub_tables(cls) -> dict[str, type]:
        """The ``[controller.<id>]`` tables a file may hold, each the law's ``Settings`` class, for the
        laws registered now (what documentation that walks the settings lists under ``controller``)."""
        return {law_id: _law_settings_class(law_id) for law_id in controller_ids()}

    @classmethod
    def component_tables(cls, data: Mapping[str, Any], *, source: str, section: str) -> tuple[dict, dict]:
        """The ``[controller.<id>]`` sub-tables of a registered law, built as that law's ``Settings``
        (:func:`vtoladapt.config.build`; :func:`vtoladapt.components.component_tables`); the rest of the
        table is returned for the shared keys."""
        rest, laws = component_tables(
            data, CONTROLLERS, _law_settings_class, own={f.name for f in dataclasses.fields(cls)},
            source=source, section=section, refused="laws",
            refusal=lambda laws: (f"{source}: [{section}] laws = {laws!r:.40}: unknown key; a law's settings are "
                                  "its own table [controller.<id>]"))
        return rest, dict(laws)

    def _check(self, source: str) -> None:
        wv = self.weathervane_airspeed_mps
        if wv is not None and not wv[0] < wv[1]:
            raise ConfigError(f"{source}: [controller] weathervane_airspeed_mps = {list(wv)}: the first "
                              "(off) must be below the second (on)")
        un = self.unseen_flow_accel_mps2
        if not un[0] < un[1]:
            raise ConfigError(f"{source}: [controller] unseen_flow_accel_mps2 = {list(un)}: the first (off) "
                              "must be below the second (on)")
        tol = self.wing_heading_tolerance_deg
        if not tol[0] < tol[1]:
            raise ConfigError(f"{source}: [controller] wing_heading_tolerance_deg = {list(tol)}: the first "
                              "(full wing weight) must be below the second (none)")
        amax = self.alpha_max_deg
        if amax is not None and self.alpha_min_deg is not None and not self.alpha_min_deg < amax:
            raise ConfigError(f"{source}: [controller] alpha_min_deg = {self.alpha_min_deg}: must be "
                              f"below alpha_max_deg = {amax}")
        for key, settings in self.laws:
            cls = _law_settings_class(key)
            if not isinstance(settings, cls):
                raise ConfigError(f"{source}: [controller.{key}] = {settings!r:.60}: must be a {cls.__name__} "
                                  f"(the {key} law's Settings)")
        self.check_law(self.kind, source)

    def check_law(self, kind: str, source: str) -> None:
        """The rules law ``kind``'s settings must meet together with the shared ones (its module's
        ``check_config``, e.g. L1's ``a_s dt < 0.5`` at :attr:`loop_rate_hz`); a
        :class:`~vtoladapt.config.ConfigError` naming ``source`` otherwise. Checked for the law that
        flies (:attr:`kind`) when the configuration is made, and by a scenario for each law it compares."""
        law = controller_info(kind).law
        check = getattr(law, "check_config", None)
        if check is not None:
            check(getattr(self, kind), self, source)

    @property
    def dt_nominal_s(self) -> float:
        """The controller's tick, ``1 / loop_rate_hz`` (s)."""
        return 1.0 / self.loop_rate_hz

    @property
    def info(self) -> ControllerInfo:
        """The registry entry of :attr:`kind`."""
        return controller_info(self.kind)

    @property
    def law_settings(self):
        """The settings of the law :attr:`kind` names (its ``[controller.<kind>]`` table)."""
        return getattr(self, self.kind)

    def to_kernel(self, vehicle, theta_0=None, P0_diag=None, theta_lower=None, theta_upper=None):
        """Kernel parameter array for this configuration (see :func:`.step.controller_params`)."""
        from .step import controller_params

        return controller_params(self, vehicle, theta_0=theta_0, P0_diag=P0_diag,
                                 theta_lower=theta_lower, theta_upper=theta_upper)

    @classmethod
    def moved_key(cls, key: str) -> Optional[str]:
        """Where a law gain written in ``[controller]`` itself belongs now (None if it is no law's)."""
        tables = [f"[controller.{c.id}] {key}" for c in CONTROLLERS.values()
                  if key in {f.name for f in dataclasses.fields(c.settings)}]
        if not tables:
            return None
        return "moved to the law's own table: " + ", ".join(tables)


def _law_settings_class(law_id: str) -> type:
    """Law ``law_id``'s ``Settings`` (its ``[controller.<id>]`` table, named so in its messages)."""
    if law_id in {f.name for f in dataclasses.fields(ControllerConfig)}:
        raise TypeError(f"controller id {law_id!r} clashes with a [controller] key")
    cls = controller_info(law_id).settings
    # the table the law's settings are in a file, for the messages of a Validated Settings made by hand
    cls.config_section = f"controller.{law_id}"
    return cls


def _law_tables(tables: Mapping[str, Any]) -> tuple:
    """``((id, settings), ...)`` sorted by id, leaving out settings equal to their law's defaults (so two
    configurations that fly the same gains are equal)."""
    out = []
    for key, settings in sorted(tables.items()):
        if key not in CONTROLLERS:
            raise TypeError(f"ControllerConfig: law table {key!r}: not a registered law ({', '.join(controller_ids())})")
        cls = _law_settings_class(key)
        if isinstance(settings, cls) and settings == cls():
            continue
        out.append((key, settings))
    return tuple(out)


def controller_config_from_mapping(data: Mapping[str, Any], source: str = "<controller>") -> ControllerConfig:
    """Validate a ``[controller]`` table; errors name ``source``, the key, the value and the range."""
    return build(ControllerConfig, dict(data), source=source, section="controller")


SCENARIO_DT_RANGE_S = (1e-4, 0.05)
"""The controller periods a scenario's ``dt_control_s`` may take (s): 20 to 10000 Hz."""
SCENARIO_DT_DEFAULT_S = 0.004
"""A scenario's ``dt_control_s`` when it gives none (250 Hz, the paper's rate)."""
LOOP_RATE_RTOL = 1e-9
"""``[controller] loop_rate_hz`` and a scenario's ``1 / dt_control_s`` agree within this relative tolerance."""


def rate_from_dt(data: dict, source: str, dt_default: float) -> float:
    """Set ``data["controller"]["loop_rate_hz"]`` to ``1 / dt_control_s`` of a scenario mapping where the
    table leaves it out, so that the controller's checks (L1's ``a_s dt``, the sigma step) and nominal tick
    are the run's; a rate the file sets is kept for :func:`check_rate_matches_dt`. Returns ``dt_control_s``
    (``dt_default`` if absent), checked as the scenario's key (:data:`SCENARIO_DT_RANGE_S`)."""
    dt = check_flag(f"{source}: dt_control_s", data.get("dt_control_s", dt_default), unit="s",
                    ge=SCENARIO_DT_RANGE_S[0], le=SCENARIO_DT_RANGE_S[1])
    controller = data.get("controller", {})
    if isinstance(controller, Mapping) and "loop_rate_hz" not in controller:
        data["controller"] = {**controller, "loop_rate_hz": 1.0 / dt}
    # otherwise a bad table is build's to report, and a set rate is compared, never overwritten
    return dt


def check_rate_matches_dt(loop_rate_hz: float, dt_control_s: float, source: str) -> None:
    """A :class:`ConfigError` naming ``source`` unless ``loop_rate_hz`` is ``1 / dt_control_s``: the rate
    the controller's checks and nominal tick assume must be the rate a run steps it at."""
    if not abs(loop_rate_hz * dt_control_s - 1.0) <= LOOP_RATE_RTOL:
        raise ConfigError(
            f"{source}: [controller] loop_rate_hz = {loop_rate_hz:g}: the controller runs at the scenario's rate, "
            f"1/dt_control_s = {1.0 / dt_control_s:g} Hz (dt_control_s = {dt_control_s:g}); leave loop_rate_hz "
            f"out (it is set from dt_control_s) or make the two agree")


def load_controller_config(path) -> ControllerConfig:
    """The ``[controller]`` table of a scenario TOML file (defaults if the table is absent), with the
    scenario's rate: ``loop_rate_hz`` is ``1 / dt_control_s`` (set from it; a different value is refused)."""
    data = dict(read_toml(path))
    dt = rate_from_dt(data, str(path), dt_default=SCENARIO_DT_DEFAULT_S)
    config = controller_config_from_mapping(data.get("controller", {}), source=str(path))
    check_rate_matches_dt(config.loop_rate_hz, dt, str(path))
    return config


__all__ = ["LOOP_RATE_MAX_HZ", "LOOP_RATE_MIN_HZ", "LOOP_RATE_RTOL", "SCENARIO_DT_DEFAULT_S",
           "SCENARIO_DT_RANGE_S", "TUNABLE",
           "ControllerConfig", "check_rate_matches_dt", "rate_from_dt",
           "controller_config_from_mapping",
           "load_controller_config"]
