"""Controller settings: the frozen, validated ``[controller]`` table of a scenario.

Every gain carries its unit (see :func:`vtoladapt.config.describe`). Defaults and why
----------------------------------------------------------------------------------------

The paper gives none of its gains; the defaults below are chosen for the 250 Hz loop, the
30-40 ms motor lag of the paper's aircraft and the PX4 multicopter defaults the baselines copy.
They are checked by ``tests/test_control_gains.py`` (discrete-time closed-loop eigenvalues of the
linearised attitude and velocity loops, with the motor lag and the one-tick hold).

* **Velocity and position loops (all five controllers).** ``K_v = (1.8, 1.8, 4.0) 1/s`` and
  ``Lambda_p = (0.95, 0.95, 1.0) 1/s`` are PX4's ``MPC_XY_VEL_P_ACC``, ``MPC_Z_VEL_P_ACC``,
  ``MPC_XY_P``, ``MPC_Z_P`` defaults. They are the "equivalent gains" of the paper's comparison:
  the adaptive controllers' ``K_v`` and ``Lambda_p`` *are* the PID's velocity and position P
  gains. The horizontal velocity loop acts through the attitude loop, so its 0.55 s time
  constant stays 3x slower than the attitude loop's; the vertical loop acts directly on the lift
  rotors (one motor lag, 30 ms) and can be faster.
* **PID/PD extras.** ``K_I = (0.4, 0.4, 2.0) 1/s^2`` and ``K_D = (0.2, 0.2, 0.0)`` are PX4's
  ``MPC_XY_VEL_I_ACC``, ``MPC_Z_VEL_I_ACC``, ``MPC_XY_VEL_D_ACC``, ``MPC_Z_VEL_D_ACC``
  defaults; the derivative acts on the measured velocity, filtered at 5 Hz
  (PX4 ``MPC_VELD_LP``). The integral time ``K_v/K_I`` = 4.5 s horizontally is what makes a PID
  slow to follow the fan-array steps, which is the paper's point.
* **Attitude loop.** ``Lambda_q = (10, 10, 6) 1/s``: with ``omega = omega_r``, eq:wr gives
  ``q_v' = -Lambda_q q_v / 2``, a 0.2 s roll/pitch time constant (PX4's ``MC_ROLL_P`` = 6.5 on
  the angle is ``Lambda_q`` = 13 on the quaternion vector part), a factor ~4 below the rate loop.
* **Rate loop.** ``K_omega`` defaults to ``J * rate_bandwidth_radps`` with bandwidths
  ``(20, 20, 10) rad/s``: for a rate loop closed through a first-order motor lag ``tau_m`` the
  damping ratio is ``zeta = sqrt(J / (K tau_m)) / 2``, so ``K/J = 20 /s`` with ``tau_m`` = 30 ms
  gives zeta = 0.65 (yaw, driven by weak rotor drag torques, is kept slower).
* **Adaptation.** ``lowpass_cutoff_hz = 10`` (the paper). ``forgetting_lambda = 0.5 1/s``: a
  2 s memory, short next to the 5 s fan steps of the comparison experiment; in excited
  directions the estimator's time constant is then about ``1/lambda`` = 2 s. ``sigma = 1e-4``:
  the smallest excitation the adaptation must follow is the pusher column (``u_x^2`` ~ 0.07 at
  9 m/s, ``W^T W`` ~ 4e-3), and the sigma bias is ``sigma / (W^T W + sigma)``, 2.4 % there;
  robustness in unexcited directions comes from the projection bounds, not from sigma.
* **omega_d feed-forward off.** ``omega_d`` must be differenced from ``R_d``, and in the wing
  regime ``R_d`` follows the measured flow direction: with the probe's ~0.3 deg angle noise and
  4 % turbulence, ``omega_d`` and ``omega_d'`` (even filtered at 5 Hz) added ~0.3 N m rms of pitch
  torque and saturated the mixer 70-95 % of the time in the paper_comparison scenario, against
  0.1 N m and < 1 % (outside the 9 m/s segment) without them. ``Lambda_q`` = 10 /s tracks the slow
  changes of ``R_d`` in that experiment without feed-forward; turn it on for smooth references.
* **Safety limits** (not in the paper): a tilt limit and a minimum lift for the multirotor
  attitude (PX4 ``MPC_TILTMAX_AIR`` = 45 deg), a 2 g limit on the commanded acceleration, a
  5 m/s limit on the position loop's velocity correction and a 10 m/s limit on the velocity error,
  so that a wild measurement or reference can never command a wild attitude.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Optional

from ..config import build, read_toml, setting
from .registry import CONTROLLER_IDS

CONTROLLER_KINDS = CONTROLLER_IDS
"""The five controllers of the paper's comparison, (I) to (V)."""


@dataclass(frozen=True)
class ControllerConfig:
    """Gains and settings of one controller (the scenario's ``[controller]`` table).

    All 3-vectors are diagonals of the paper's gain matrices, in NED (``K_v``, ``Lambda_p``,
    ``K_I``, ``K_D``, integrator limit) or body FRD (``Lambda_q``, ``K_omega``) axes.
    """

    kind: str = setting("-", "which controller: 'composite' (I, eq:th_adapt + eq:P_adapt), "
                        "'composite_pconst' (II, P-dot = 0), 'tracking_only' (III, theta-hat-dot = "
                        "P0 Phi^T R^T v~), 'pid' (IV), 'pd' (V)", default="composite",
                        choices=CONTROLLER_KINDS)
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
    K_I: tuple[float, ...] = setting("1/s^2", "velocity-error integral gain (pid only)",
                                     default=(0.4, 0.4, 2.0), ge=0.0, length=3)
    K_D: tuple[float, ...] = setting("-", "velocity-derivative gain on the measured acceleration "
                                     "(pid and pd)", default=(0.2, 0.2, 0.0), ge=0.0, length=3)
    integrator_limit_mps2: tuple[float, ...] = setting(
        "m/s^2", "clamp of the PID integral term per axis", default=(4.0, 4.0, 5.0), ge=0.0, length=3)
    derivative_cutoff_hz: float = setting("Hz", "low-pass on the PID's measured acceleration",
                                          default=5.0, gt=0.0)
    forgetting_lambda: float = setting("1/s", "forgetting factor lambda (eq:P_adapt, information form "
                                       "forgetting toward P0)", default=0.5, ge=0.0, le=100.0)
    sigma: float = setting("adaptation units", "sigma-modification toward theta_0 (eq:th_adapt)",
                           default=1e-4, ge=0.0, le=100.0)
    lowpass_cutoff_hz: float = setting("Hz", "first-order filter [.]_f on the accelerometer and Phi "
                                       "(eq:prediction_error)", default=10.0, gt=0.0)
    gamma: float = setting("-", "weight gamma of the attitude term in the Lyapunov function",
                           default=1.0, gt=0.0)
    information_trace_max: float = setting(
        "adaptation units", "cap on trace(P^-1 - P0^-1): bounds P below for any regressor",
        default=1e6, gt=0.0)
    adaptation_holdoff_s: float = setting(
        "s", "adaptation resumes this long after the probe or accelerometer is valid again "
        "(filters re-settle)", default=0.05, ge=0.0)
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
    loop_rate_hz: float = setting("Hz", "nominal controller rate (the Python API's first step)",
                                  default=250.0, gt=0.0)

    def _check(self, source: str) -> None:
        from ..config import ConfigError

        amax = self.alpha_max_deg
        if amax is not None and self.alpha_min_deg is not None and not self.alpha_min_deg < amax:
            raise ConfigError(f"{source}: [controller] alpha_min_deg = {self.alpha_min_deg}: must be "
                              f"below alpha_max_deg = {amax}")

    @property
    def kind_id(self) -> int:
        """The kind as the number the compiled kernel uses (index in :data:`CONTROLLER_KINDS`)."""
        return CONTROLLER_KINDS.index(self.kind)

    def to_kernel(self, vehicle, theta_0=None, P0_diag=None, theta_lower=None, theta_upper=None):
        """Kernel parameter array for this configuration (see :func:`.kernel.controller_params`)."""
        from .kernel import controller_params

        return controller_params(self, vehicle, theta_0=theta_0, P0_diag=P0_diag,
                                 theta_lower=theta_lower, theta_upper=theta_upper)


def controller_config_from_mapping(data: Mapping[str, Any], source: str = "<controller>") -> ControllerConfig:
    """Validate a ``[controller]`` table; errors name ``source``, the key, the value and the range."""
    return build(ControllerConfig, dict(data), source=source, section="controller")


def load_controller_config(path) -> ControllerConfig:
    """The ``[controller]`` table of a scenario TOML file (defaults if the table is absent)."""
    data = read_toml(path)
    return controller_config_from_mapping(data.get("controller", {}), source=str(path))


__all__ = ["CONTROLLER_KINDS", "ControllerConfig", "controller_config_from_mapping",
           "load_controller_config"]
