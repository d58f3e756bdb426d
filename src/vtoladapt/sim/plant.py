"""The simulated aircraft ("plant"): its own truth, separate from the controller's model.

The plant starts from the vehicle's published coefficients but has its own parameter set (the
scenario's ``[plant]`` table overrides any of them) and the effects the paper's linear model
lacks, each switchable:

* **stall and post-stall**: lift and drag blend from the linear polars to a flat plate with the
  sigmoid of Beard & McLain (*Small Unmanned Aircraft*, 2012, eq. 4.10),
  ``sigma(a) = (1 + e^{-M(a-a0)} + e^{M(a+a0)}) / ((1 + e^{-M(a-a0)})(1 + e^{M(a+a0)}))``;
  flat plate ``C_N = 2 sin(a)`` (lift ``C_N cos a``, drag ``C_D0 + C_N sin a``);
* **side force** ``C_Y = C_Y_beta beta`` (the model assumes ``C_Y = 0``);
* **pusher thrust loss with advance ratio**: ``T = T_static(u) * C_T(J)/C_T(0)``, with
  ``C_T(J)/C_T(0) = 1 + a1 J + a2 J^2`` fitted to the UIUC propeller database's 7x4 propeller
  (Master Airscrew GF 7x4, volume 1; Brandt, Deters, Ananda, Dantsker & Selig, UIUC Propeller
  Database; the data set holds no APC 7x4). The rotor speed is linear in throttle, with the full
  speed that makes the static thrust equal the vehicle's ``CTx`` at 100 %;
* **motor lag and saturation**: first-order lag per motor, commands clipped to [0, 1];
* **the pusher's reaction torque** about body x (the lift rotors' about body z are always on: they
  are the aircraft's yaw control);
* **aerodynamic rate damping** (roll, pitch, yaw) proportional to airspeed;
* **control surfaces** (the vehicle file's ``[[surfaces]]``): force and moment linear in deflection and
  in the free stream's dynamic pressure, each moved by a servo with a first-order lag and a slew-rate
  limit (:mod:`vtoladapt.sim.surfaces`, where the slipstream question is answered: none counts).

The physical parameters the vehicle file gives (stall angle, motor and servo lags, mass, inertia, air
density, surface effectiveness) are the plant's unless the scenario's ``[plant]`` sets them or draws
them (``physical_from = "draw"``, :mod:`vtoladapt.sim.truth`); the controller keeps the file's values.

Rotor/wing interaction (slipstream over the wing) is not modelled: the lift rotors sit outboard
of the wing root on booms and the paper gives nothing to calibrate it against.

Kernels take the plant parameter array built once by :meth:`PlantConfig.to_kernel` (its layout:
:data:`PLANT_PARAMS`). The
rigid-body derivative runs 16 times per controller tick (four RK4 steps at 1 kHz), so the force
kernels it calls take and return scalars and are inlined into it (``inline="always"``): as
separate calls, the reference counting of the parameter array alone took a fifth of the
plant's time.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Optional

import numpy as np
from numba import njit

from .. import forces
from ..config import ConfigError, Validated, build, setting
from ..frames import GRAVITY_MPS2
from ..layout import (ACT_SURFACE, IN_SERVO_SLOWDOWN, IN_SURFACE_LOSS, MOTOR_PUSHER, N_ACTUATORS, N_LIFT,
                     N_MOTORS, N_SURFACES, PLANT_INPUT_SIZE, X_MOTOR, X_OMEGA_B, X_P_W, X_Q_WB, X_SERVO, X_SIZE,
                     X_V_W, BlockLayout, Field)
from ..scaling import theta_to_scaled
from ..vehicle import PARAMETER_NAMES, Vehicle
from .surfaces import servo_response, surface_kernel_fields

#: UIUC magf 7x4 static thrust coefficient (mean of the 16 static points, 3069-7203 RPM).
UIUC_7X4_STATIC_CT = 0.08188
#: UIUC magf 7x4 C_T(J)/C_T(0) - 1 = a1 J + a2 J^2: the fit of
#: :func:`vtoladapt.fitting.pusher_thrust_ratio_model` (J sweeps and static points, J in [0, 0.78]),
#: kept here as numbers so the plant does not load the fitting stack; a test pins them to the fit.
UIUC_7X4_CT_RATIO_COEFFS = (-0.84419, -1.10227)


@dataclass(frozen=True)
class PlantCoefficients(Validated):
    """Optional overrides of the plant's true force-model coefficients (Table I units)."""

    config_section = "plant.coefficients"

    CTx: Optional[float] = setting("m/s^2 per %^2", "true pusher thrust coefficient", default=None, gt=0.0, le=0.01)
    CTz: Optional[float] = setting("m/s^2 per %^2", "true lift thrust coefficient", default=None, gt=0.0, le=0.01)
    CS: Optional[float] = setting("m/s^2 per (%^k1 (m/s)^(2-k1))", "true rotor side-force coefficient",
                                  default=None, ge=0.0, le=0.01)
    k1: Optional[float] = setting("-", "true side-force exponent", default=None, gt=0.0, lt=2.0)
    k2: Optional[float] = setting("rad", "true side-force offset", default=None, gt=math.pi / 2, le=100.0)
    CD0: Optional[float] = setting("-", "true CD0", default=None, ge=0.0, le=2.0)
    CD1: Optional[float] = setting("1/rad", "true CD1", default=None, ge=-10.0, le=10.0)
    CD2: Optional[float] = setting("1/rad^2", "true CD2", default=None, ge=0.0, le=20.0)
    CL0: Optional[float] = setting("-", "true CL0", default=None, ge=-3.0, le=3.0)
    CL1: Optional[float] = setting("1/rad", "true CL1", default=None, gt=0.0, le=10.0)


@dataclass(frozen=True)
class PlantConfig(Validated):
    """The simulated aircraft's own parameters and which unmodelled effects are on."""

    config_section = "plant"

    engine: str = setting(
        "-", "what integrates the aircraft: 'native' (this module, compiled RK4; the fast path) or 'jsbsim' "
        "(JSBSim flies the same aircraft written as JSBSim XML, vtoladapt.sim.jsbsim_engine; needs the optional "
        "dependency jsbsim)", default="native", choices=("native", "jsbsim"))
    coefficients: PlantCoefficients = setting("-", "true coefficients (default: vehicle's Table I)",
                                              default=PlantCoefficients())
    coefficients_from: str = setting(
        "-", "where the coefficients not set in [plant.coefficients] come from: 'table_i_means' (the "
        "vehicle's published means, the controller's theta_0) or 'table_i_draw' (one draw from Table "
        "I's mean +- std, seeded by the run seed; see draw_table_i_coefficients)",
        default="table_i_means", choices=("table_i_means", "table_i_draw"))
    mass_kg: Optional[float] = setting("kg", "true mass (default: vehicle's)", default=None, ge=0.1, le=150.0)
    inertia_kgm2: Optional[tuple[float, ...]] = setting(
        "kg m^2", "true principal inertia (default: vehicle's)", default=None, ge=1e-5, le=500.0, length=3)
    air_density_kgpm3: Optional[float] = setting("kg/m^3", "true air density", default=None, ge=0.3, le=2.0)
    stall: bool = setting("-", "blend to flat-plate aerodynamics past stall", default=True)
    stall_angle_deg: Optional[float] = setting(
        "deg", "angle of attack where the blend is half way (default: the vehicle's [envelope] stall_angle_deg)",
        default=None, gt=0.0, lt=60.0)
    stall_blend_rate_per_rad: float = setting("1/rad", "sharpness M of the stall blend (Beard & McLain: 50)", default=50.0, gt=0.0, le=1000.0)
    side_force: bool = setting("-", "aerodynamic side force C_Y(beta)", default=True)
    CY_beta_per_rad: float = setting("1/rad", "side-force slope (fuselage and V-tail)", default=-0.3, ge=-10.0, le=0.0)
    pusher_advance_ratio_loss: bool = setting("-", "pusher thrust falls with advance ratio (UIUC 7x4)",
                                              default=True)
    pusher_static_CT: float = setting("-", "pusher static C_T (UIUC 7x4)", default=UIUC_7X4_STATIC_CT, gt=0.0, le=1.0)
    pusher_CT_ratio_coeffs: tuple[float, ...] = setting(
        "-", "a1, a2 of C_T(J)/C_T(0) = 1 + a1 J + a2 J^2 (UIUC 7x4)",
        default=UIUC_7X4_CT_RATIO_COEFFS, ge=-10.0, le=10.0, length=2)
    motor_lag: bool = setting("-", "first-order motor lag (else motors follow commands instantly)",
                              default=True)
    lift_motor_time_constant_s: Optional[float] = setting("s", "true lift motor lag (default: vehicle's)",
                                                          default=None, ge=0.001, le=1.0)
    pusher_motor_time_constant_s: Optional[float] = setting("s", "true pusher lag (default: vehicle's)",
                                                            default=None, ge=0.001, le=1.0)
    servo_lag: bool = setting("-", "control-surface servos lag and slew-limit (else surfaces follow commands "
                              "instantly)", default=True)
    servo_time_constant_factors: Optional[tuple[float, ...]] = setting(
        "-", "each servo's true time constant over the vehicle file's, one per [[surfaces]] entry of the vehicle, "
        "surface order (default: all 1)", default=None, gt=0.0, le=10.0, max_items=N_SURFACES)
    surface_effectiveness: Optional[tuple[float, ...]] = setting(
        "-", "each surface's true effectiveness over the vehicle file's derivatives, one per [[surfaces]] entry "
        "of the vehicle, surface order (default: all 1)", default=None, ge=0.0, le=3.0, max_items=N_SURFACES)
    physical_from: str = setting(
        "-", "where the physical parameters not set here come from (stall angle, motor and servo lags, mass, "
        "inertia, air density, surface effectiveness): 'vehicle' (the file's values, the controller's "
        "belief) or 'draw' (one draw from the file's [uncertainty], seeded by the run seed on its own "
        "stream; see vtoladapt.sim.truth.draw_physical_parameters)",
        default="vehicle", choices=("vehicle", "draw"))
    rotor_reaction_torque: bool = setting(
        "-", "the pusher's drag torque rolls the airframe (unmodelled by the controller); the lift "
        "rotors' yaw torques are always on: they are how the aircraft yaws", default=True)
    aero_rate_damping: bool = setting("-", "aerodynamic roll/pitch/yaw rate damping", default=True)
    Clp: float = setting("-", "roll damping derivative", default=-0.4, ge=-100.0, le=0.0)
    Cmq: float = setting("-", "pitch damping derivative (V-tail)", default=-6.0, ge=-100.0, le=0.0)
    Cnr: float = setting("-", "yaw damping derivative", default=-0.15, ge=-100.0, le=0.0)

    def resolved(self, vehicle: Vehicle, seed: int) -> "PlantConfig":
        """This config with a ``table_i_draw`` made concrete: the drawn coefficients written into
        ``coefficients`` (explicit overrides kept) and ``coefficients_from = 'table_i_means'``.
        Likewise ``physical_from = 'draw'``: the drawn physical parameters written into the fields left
        unset, and ``physical_from = 'vehicle'``. A config without a draw comes back unchanged."""
        out = self
        for name in ("surface_effectiveness", "servo_time_constant_factors"):
            value = getattr(out, name)
            if value is not None and len(value) != len(vehicle.surfaces):
                raise ConfigError(f"[plant] {name} = {list(value)}: {len(value)} entries; allowed: "
                                  f"{len(vehicle.surfaces)} (one per [[surfaces]] entry of {vehicle.name}) or unset")
        if out.physical_from == "draw":
            from .truth import draw_physical_parameters

            drawn = draw_physical_parameters(vehicle, seed)
            out = replace(out, physical_from="vehicle",
                          **{k: v for k, v in drawn.items() if getattr(out, k) is None})
        if out.coefficients_from != "table_i_draw":
            return out
        drawn = draw_table_i_coefficients(vehicle, seed)
        given = {n: getattr(out.coefficients, n) for n in drawn}
        merged = {n: (given[n] if given[n] is not None else drawn[n]) for n in drawn}
        return replace(out, coefficients=PlantCoefficients(**merged), coefficients_from="table_i_means")

    def true_stall_angle_deg(self, vehicle: Vehicle) -> float:
        """The plant's stall angle (deg): this config's, else the vehicle's."""
        return self.stall_angle_deg if self.stall_angle_deg is not None else vehicle.envelope.stall_angle_deg

    def true_coefficients(self, vehicle: Vehicle) -> dict[str, float]:
        """The plant's coefficients in Table I units: vehicle's means with this config's overrides."""
        out = {n: getattr(vehicle.force_model, n) for n in (*PARAMETER_NAMES, "k1", "k2")}
        for name in out:
            value = getattr(self.coefficients, name)
            if value is not None:
                out[name] = value
        return out

    def theta_true_scaled(self, vehicle: Vehicle) -> np.ndarray:
        """The linear-model part of the truth in the adaptation scaling (for analysis only)."""
        c = self.true_coefficients(vehicle)
        return theta_to_scaled(np.array([c[n] for n in PARAMETER_NAMES]), c["k1"])

    def to_kernel(self, vehicle: Vehicle) -> np.ndarray:
        """Kernel parameter array (layout: :data:`PLANT_PARAMS`)."""
        c = self.true_coefficients(vehicle)
        theta = self.theta_true_scaled(vehicle)
        mass = self.mass_kg if self.mass_kg is not None else vehicle.mass.mass_kg
        inertia = np.array(self.inertia_kgm2 if self.inertia_kgm2 is not None else vehicle.mass.inertia_kgm2)
        J = np.diag(inertia)
        J[0, 2] = J[2, 0] = -vehicle.mass.product_of_inertia_xz_kgm2
        rho = self.air_density_kgpm3 if self.air_density_kgpm3 is not None else vehicle.envelope.air_density_kgpm3
        S = vehicle.geometry.wing_area_m2
        b = vehicle.geometry.wingspan_m
        D = vehicle.geometry.pusher_prop_diameter_m
        # full pusher rotor speed (rev/s) at which the static thrust is CTx_s * m
        n_max = math.sqrt(theta[0] * vehicle.mass.mass_kg / (self.pusher_static_CT * rho * D**4))
        tau_lift = self.lift_motor_time_constant_s or vehicle.actuators.lift_motor_time_constant_s
        tau_push = self.pusher_motor_time_constant_s or vehicle.actuators.pusher_motor_time_constant_s
        alpha_stall = math.radians(self.true_stall_angle_deg(vehicle))
        a1, a2 = self.pusher_CT_ratio_coeffs
        rotors = vehicle.geometry.lift_rotor_positions_m
        return PLANT_PARAMS.pack(
            MASS=mass, FORCE_MASS=vehicle.mass.mass_kg, J=J.ravel(), JINV=np.linalg.inv(J).ravel(),
            THETA=theta, K1=c["k1"], K2=c["k2"], RHO=rho, S=S, SPAN=b, CHORD=S / b,
            STALL_ON=float(self.stall), ALPHA_STALL=alpha_stall, STALL_M=self.stall_blend_rate_per_rad,
            STALL_EXP=math.exp(min(self.stall_blend_rate_per_rad * alpha_stall, 700.0)),
            CY_BETA=self.CY_beta_per_rad if self.side_force else 0.0,
            PUSH_J_ON=float(self.pusher_advance_ratio_loss), CT_A1=a1, CT_A2=a2, PUSH_NMAX=n_max, PUSH_D=D,
            LAG_ON=float(self.motor_lag), TAU_LIFT=tau_lift, TAU_PUSH=tau_push,
            ROTOR_X=[x for x, _ in rotors], ROTOR_Y=[y for _, y in rotors],
            ROTOR_SPIN=vehicle.geometry.lift_rotor_spin[:N_LIFT],
            KM=vehicle.actuators.yaw_torque_per_thrust_m,
            KM_PUSHER=vehicle.actuators.yaw_torque_per_thrust_m if self.rotor_reaction_torque else 0.0,
            DAMP_ON=float(self.aero_rate_damping), CLP=self.Clp, CMQ=self.Cmq, CNR=self.Cnr,
            **surface_kernel_fields(vehicle, self.surface_effectiveness or (1.0,) * N_SURFACES,
                                    self.servo_time_constant_factors or (1.0,) * N_SURFACES, self.servo_lag))


PLANT_DRAW_STREAM = 0x7AB1E1
"""Second entropy word of the plant draw's seed sequence: the draw gets its own stream, so drawing
the plant does not shift the run's other random draws (sensor noise, turbulence)."""
TABLE_I_DRAW_CLIP_SIGMAS = 2.0
"""A drawn coefficient stays within this many standard deviations of its mean."""


def draw_table_i_coefficients(vehicle: Vehicle, seed: int) -> dict[str, float]:
    """One plausible aircraft: the ten force-model coefficients of Table I (Table I units), each
    drawn independently from a normal with the published mean and standard deviation.

    The rule: generator ``numpy.random.default_rng(SeedSequence([seed, PLANT_DRAW_STREAM]))``,
    one standard normal per coefficient in the order CTx, CTz, CS, k1, k2, CD0, CD1, CD2, CL0, CL1,
    each clipped to +-:data:`TABLE_I_DRAW_CLIP_SIGMAS` std (a posterior's tails are where a
    Gaussian summary is least trustworthy) and to the coefficient's physical range (CS, CD0,
    CD2 >= 0; k2 > pi/2). Table I gives no correlations, so none are drawn.
    """
    names = ("CTx", "CTz", "CS", "k1", "k2", "CD0", "CD1", "CD2", "CL0", "CL1")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), PLANT_DRAW_STREAM]))
    z = np.clip(rng.standard_normal(len(names)), -TABLE_I_DRAW_CLIP_SIGMAS, TABLE_I_DRAW_CLIP_SIGMAS)
    out = {}
    for name, zi in zip(names, z):
        value = getattr(vehicle.force_model, name) + zi * getattr(vehicle.force_model_std, name)
        if name in ("CS", "CD0", "CD2"):
            value = max(value, 0.0)
        elif name == "k2":
            value = max(value, math.pi / 2 + 1e-6)
        out[name] = float(value)
    return out


def plant_config_from_mapping(data: dict | None, source: str) -> PlantConfig:
    """Build a :class:`PlantConfig` from a scenario's ``[plant]`` table."""
    return build(PlantConfig, data or {}, source=source, section="plant")


# --- kernel parameter layout -------------------------------------------------------------------
PLANT_PARAMS = BlockLayout("plant parameters", [
    Field("MASS", 1, "kg", "true mass"),
    Field("FORCE_MASS", 1, "kg", "mass the coefficients are normalised by (the vehicle's): newtons = "
          "FORCE_MASS x coefficient"),
    Field("J", 9, "kg m^2", "true inertia matrix about the centre of mass, body FRD, row-major"),
    Field("JINV", 9, "1/(kg m^2)", "its inverse, row-major"),
    Field("THETA", 8, "adaptation scaling", "true linear-model coefficients (forces.I_* order)"),
    Field("K1", 1, "-", "side-force exponent k1"),
    Field("K2", 1, "rad", "side-force offset k2"),
    Field("RHO", 1, "kg/m^3", "air density"),
    Field("S", 1, "m^2", "wing reference area"),
    Field("SPAN", 1, "m", "wingspan"),
    Field("CHORD", 1, "m", "mean chord S / b"),
    Field("STALL_ON", 1, "-", "1.0: blend to flat-plate aerodynamics past stall"),
    Field("ALPHA_STALL", 1, "rad", "angle of attack where the stall blend is half way"),
    Field("STALL_M", 1, "1/rad", "sharpness M of the stall blend"),
    Field("STALL_EXP", 1, "-", "exp(M alpha_stall) (clamped): the stall blend needs one exp per call"),
    Field("CY_BETA", 1, "1/rad", "side-force slope (0 when the side force is off)"),
    Field("PUSH_J_ON", 1, "-", "1.0: pusher thrust falls with advance ratio"),
    Field("CT_A1", 1, "-", "a1 of C_T(J)/C_T(0) = 1 + a1 J + a2 J^2"),
    Field("CT_A2", 1, "-", "a2 of the same"),
    Field("PUSH_NMAX", 1, "rev/s", "pusher speed at full throttle"),
    Field("PUSH_D", 1, "m", "pusher diameter"),
    Field("LAG_ON", 1, "-", "1.0: first-order motor lag"),
    Field("TAU_LIFT", 1, "s", "lift-motor time constant"),
    Field("TAU_PUSH", 1, "s", "pusher time constant"),
    Field("ROTOR_X", N_LIFT, "m", "body x of the lift rotors"),
    Field("ROTOR_Y", N_LIFT, "m", "body y of the lift rotors"),
    Field("ROTOR_SPIN", N_LIFT, "-", "spin direction of the lift rotors (+1 / -1)"),
    Field("KM", 1, "m", "lift-rotor reaction torque per thrust"),
    Field("KM_PUSHER", 1, "m", "pusher drag torque per thrust (0 when rotor_reaction_torque is off)"),
    Field("DAMP_ON", 1, "-", "1.0: aerodynamic rate damping"),
    Field("CLP", 1, "-", "roll damping derivative"),
    Field("CMQ", 1, "-", "pitch damping derivative"),
    Field("CNR", 1, "-", "yaw damping derivative"),
    Field("SURF_F", 3 * N_SURFACES, "N/(Pa rad)", "each surface's body force per dynamic pressure and radian "
          "(S [CX, CY, CZ] times its true effectiveness), surface-major"),
    Field("SURF_M", 3 * N_SURFACES, "N m/(Pa rad)", "each surface's body moment per dynamic pressure and radian "
          "(S [b Cl, c Cm, b Cn] times its true effectiveness), surface-major"),
    Field("SURF_LIMIT", N_SURFACES, "rad", "deflection limit either way (0: no surface in the slot)"),
    Field("SURF_TAU", N_SURFACES, "s", "true servo time constant"),
    Field("SURF_RATE", N_SURFACES, "rad/s", "servo slew-rate limit"),
    Field("SERVO_LAG_ON", 1, "-", "1.0: servos lag and slew-limit"),
    Field("N_SURF", 1, "-", "surfaces the vehicle has (the first slots)"),
])
"""The plant's kernel parameter array, built by :meth:`PlantConfig.to_kernel`."""
(P_MASS, P_FORCE_MASS, P_J, P_JINV, P_THETA, P_K1, P_K2, P_RHO, P_S, P_SPAN, P_CHORD, P_STALL_ON,
 P_ALPHA_STALL, P_STALL_M, P_STALL_EXP, P_CY_BETA, P_PUSH_J_ON, P_CT_A1, P_CT_A2, P_PUSH_NMAX, P_PUSH_D,
 P_LAG_ON, P_TAU_LIFT, P_TAU_PUSH, P_ROTOR_X, P_ROTOR_Y, P_ROTOR_SPIN, P_KM, P_KM_PUSHER, P_DAMP_ON,
 P_CLP, P_CMQ, P_CNR, P_SURF_F, P_SURF_M, P_SURF_LIMIT, P_SURF_TAU, P_SURF_RATE, P_SERVO_LAG_ON,
 P_N_SURF) = PLANT_PARAMS.offsets(
    "MASS", "FORCE_MASS", "J", "JINV", "THETA", "K1", "K2", "RHO", "S", "SPAN", "CHORD", "STALL_ON",
    "ALPHA_STALL", "STALL_M", "STALL_EXP", "CY_BETA", "PUSH_J_ON", "CT_A1", "CT_A2", "PUSH_NMAX", "PUSH_D",
    "LAG_ON", "TAU_LIFT", "TAU_PUSH", "ROTOR_X", "ROTOR_Y", "ROTOR_SPIN", "KM", "KM_PUSHER", "DAMP_ON",
    "CLP", "CMQ", "CNR", "SURF_F", "SURF_M", "SURF_LIMIT", "SURF_TAU", "SURF_RATE", "SERVO_LAG_ON", "N_SURF")
P_SIZE = PLANT_PARAMS.size
PUSHER_J_MAX = 0.8  # edge of the UIUC data; the quadratic is not extrapolated beyond
N_BODY = X_MOTOR    # the rigid-body part of the state: p, v, q, omega (the motors and servos follow)
ROTOR_TERMS_SIZE = 13


@njit(cache=True, inline="always")
def stall_blend(alpha_rad: float, M: float, exp_M_alpha_stall: float) -> float:
    """Beard & McLain's stall blending sigmoid: 0 in attached flow, 1 past stall.

    ``sigma = (1 + e1 + e2) / ((1 + e1)(1 + e2))`` with ``e1 = e^{-M(|a| - a0)}``,
    ``e2 = e^{M(|a| + a0)}`` (sigma is even in alpha) is ``s1 + s2 - s1 s2`` with
    ``s1 = 1/(1 + z C)``, ``s2 = z/(z + C)``, ``z = e^{-M|a|} <= 1``, ``C = e^{M a0}``: one exp per
    call (``C`` is a constant of the run, ``exp_M_alpha_stall``) and nothing overflows.
    """
    z = np.exp(-min(M * min(abs(alpha_rad), np.pi), 700.0))
    s1 = 1.0 / (1.0 + z * exp_M_alpha_stall)
    s2 = z / (z + exp_M_alpha_stall)
    return s1 + s2 - s1 * s2


@njit(cache=True, inline="always")
def true_aero_coefficients(alpha_rad: float, sin_alpha: float, cos_alpha: float, p: np.ndarray) -> tuple:
    """True lift and drag coefficients: linear polars blended into a flat plate past stall.

    ``sin_alpha``, ``cos_alpha`` are passed in because the caller has them from v_i already.
    The attached-flow drag is ``|C_D(alpha)|`` of the polar (eq:model_cd): drag never pushes the
    aircraft forward. This is Gazebo's LiftDrag rule (``cd = fabs(cd)``), where
    ``px4_standard_vtol`` comes from: its polar ``C_D0 + C_D1 alpha`` (Gazebo's ``cda (a0 + alpha)``)
    crosses zero at -3.4 deg. The controller's model keeps the paper's polynomial, so below that
    angle it is wrong, as a model fitted to attached flow is. Where the polar stays positive (the
    Table I aircraft, all its draws) this changes nothing.
    """
    CL = forces.lift_coefficient(alpha_rad, p[P_THETA + forces.I_CL0], p[P_THETA + forces.I_CL1])
    CD = abs(forces.drag_coefficient(alpha_rad, p[P_THETA + forces.I_CD0], p[P_THETA + forces.I_CD1],
                                     p[P_THETA + forces.I_CD2]))
    if p[P_STALL_ON] > 0.0:
        s = stall_blend(alpha_rad, p[P_STALL_M], p[P_STALL_EXP])
        if s > 1e-12:
            CN = 2.0 * sin_alpha
            CL = (1.0 - s) * CL + s * CN * cos_alpha
            CD = (1.0 - s) * CD + s * (p[P_THETA + forces.I_CD0] + CN * sin_alpha)
    return CL, CD


@njit(cache=True, inline="always")
def pusher_thrust_ratio(v_axial_mps: float, n_revps: float, p: np.ndarray) -> float:
    """C_T(J)/C_T(0) of the pusher at the current advance ratio (UIUC 7x4 fit)."""
    if p[P_PUSH_J_ON] <= 0.0:
        return 1.0
    if n_revps <= 1e-9:
        return 1.0  # no thrust anyway (T ~ n^2); avoids J = inf
    J = max(v_axial_mps, 0.0) / (n_revps * p[P_PUSH_D])
    J = min(J, PUSHER_J_MAX)
    return 1.0 + p[P_CT_A1] * J + p[P_CT_A2] * J * J


@njit(cache=True, inline="always")
def rotor_terms(motor, off, p, loss, loss_off) -> tuple:
    """What the actuators contribute that depends on their outputs only: the five rotors at
    ``motor[off:off+5]`` and the surfaces' deflections right after them (the state's MOTOR and SERVO
    blocks are one block, as ACTUATORS orders them), each surface's effectiveness reduced by its loss
    ``loss[loss_off + j]`` (0 healthy, 1 gone).

    Returns ``(T_lift_N, roll_Nm, pitch_Nm, yaw_Nm, sum_i u_i^k1, T_pusher_static_N, n_pusher_revps,
    sFx, sFy, sFz, sMx, sMy, sMz)``: total lift-rotor thrust, the lift rotors' moments (differential
    thrust and reaction torque), the sum that scales the rotor side force, the pusher's static thrust
    and speed (its advance-ratio loss needs the airflow, see :func:`true_forces_moments`), and the
    surfaces' force (N) and moment (N m) per pascal of dynamic pressure. Evaluated once per distinct
    actuator state (RK4 stages 2 and 3 share one).
    """
    m_ref = p[P_FORCE_MASS]  # coefficients are per unit of the vehicle's mass: newtons = m_ref * coeff
    T_unit = m_ref * p[P_THETA + forces.I_CTZ] / N_LIFT  # N at full throttle, per rotor
    k1 = p[P_K1]
    tx = 0.0
    ty = 0.0
    tz = 0.0
    T_total = 0.0
    u_k1_sum = 0.0
    for i in range(N_LIFT):
        w = motor[off + i]
        T = T_unit * w * w
        T_total += T
        tx -= p[P_ROTOR_Y + i] * T
        ty += p[P_ROTOR_X + i] * T
        tz -= p[P_ROTOR_SPIN + i] * p[P_KM] * T
        if w > 0.0:
            u_k1_sum += w**k1
    wp = motor[off + MOTOR_PUSHER]
    sfx = 0.0
    sfy = 0.0
    sfz = 0.0
    smx = 0.0
    smy = 0.0
    smz = 0.0
    for j in range(int(p[P_N_SURF])):
        d = motor[off + ACT_SURFACE + j] * (1.0 - loss[loss_off + j])
        sfx += p[P_SURF_F + 3 * j] * d
        sfy += p[P_SURF_F + 3 * j + 1] * d
        sfz += p[P_SURF_F + 3 * j + 2] * d
        smx += p[P_SURF_M + 3 * j] * d
        smy += p[P_SURF_M + 3 * j + 1] * d
        smz += p[P_SURF_M + 3 * j + 2] * d
    return (T_total, tx, ty, tz, u_k1_sum, m_ref * p[P_THETA + forces.I_CTX] * wp * wp,
            p[P_PUSH_NMAX] * wp, sfx, sfy, sfz, smx, smy, smz)


@njit(cache=True, inline="always")
def true_forces_moments(vx, vy, vz, wx, wy, wz, rotors, p) -> tuple:
    """True specific force (m/s^2, body) and moment (N m, body): ``(fx, fy, fz, Mx, My, Mz)``.

    ``(vx, vy, vz)`` is the incident velocity v_i in body axes (eq:vi), ``(wx, wy, wz)`` the body
    rate, ``rotors`` the :func:`rotor_terms` of the current motor outputs. Scalars in, scalars
    out: it runs 16 times per controller tick.
    """
    V2 = vx * vx + vy * vy + vz * vz
    V = np.sqrt(V2)
    mass = p[P_MASS]
    m_ref = p[P_FORCE_MASS]
    T_total, tx, ty, tz, u_k1_sum, Tp_static, n_pusher, sfx, sfy, sfz, smx, smy, smz = rotors
    # rotor side force: each rotor's share of G is (u_i^k1 / 4) times G at full throttle
    h = np.sqrt(vx * vx + vy * vy)
    side = 0.0
    cb = 1.0
    sb = 0.0
    if h > 0.0 and u_k1_sum > 0.0:
        alpha_disk = np.arctan2(vz, h)
        G_full = forces.side_force_basis(alpha_disk, V, 1.0, p[P_K1], p[P_K2])
        side = 0.25 * m_ref * p[P_THETA + forces.I_CS] * G_full * u_k1_sum
        cb = vx / h
        sb = vy / h
    Tp = Tp_static * pusher_thrust_ratio(vx, n_pusher, p)
    tx -= p[P_KM_PUSHER] * Tp  # pusher drag torque rolls the airframe
    # wing
    r = np.sqrt(vx * vx + vz * vz)
    alpha = np.arctan2(vz, vx)
    sa, ca = (vz / r, vx / r) if r > 0.0 else (0.0, 1.0)
    CL, CD = true_aero_coefficients(alpha, sa, ca, p)
    qS = 0.5 * p[P_RHO] * V2 * p[P_S]
    beta = np.arcsin(min(1.0, max(-1.0, vy / V))) if V > 0.0 else 0.0
    CY = p[P_CY_BETA] * beta
    q = 0.5 * p[P_RHO] * V2  # the surfaces' force and moment scale with the free stream's dynamic pressure
    fx = (Tp - side * cb + qS * (CL * sa - CD * ca) + q * sfx) / mass
    fy = (-side * sb + qS * CY + q * sfy) / mass
    fz = (-T_total + qS * (-CL * ca - CD * sa) + q * sfz) / mass
    tx += q * smx
    ty += q * smy
    tz += q * smz
    if p[P_DAMP_ON] > 0.0:
        # L = q S b Clp (p b / 2V) = 1/4 rho V S b^2 Clp p: smooth at V = 0
        k = 0.25 * p[P_RHO] * V * p[P_S]
        tx += k * p[P_SPAN] ** 2 * p[P_CLP] * wx
        ty += k * p[P_CHORD] ** 2 * p[P_CMQ] * wy
        tz += k * p[P_SPAN] ** 2 * p[P_CNR] * wz
    return fx, fy, fz, tx, ty, tz


@njit(cache=True, _nrt=False)
def rigid_body_derivative(x, xo, rotors, v_wind_W, p, xdot, do) -> tuple:
    """d/dt of the rigid-body state ``x[xo:xo+N_BODY]`` (p, v, q, omega) into ``xdot[do:do+N_BODY]``.

    eq:pos_dyn (``p' = v``, ``v' = g + R f_b``) and eq:att_dyn (``q' = q * [0, omega] / 2``,
    ``J omega' = (J omega) x omega + tau``), with the true forces at the motor state whose
    :func:`rotor_terms` are ``rotors``. Returns ``(f_b, v_i)`` flattened to six scalars: the
    specific force (body, m/s^2, what an accelerometer measures) and the incident velocity
    (body, m/s, what the airflow probe meets). The offsets ``xo``, ``do`` let the RK4 stages live
    in one work array without slicing it 16 times per tick.
    """
    q0, q1, q2, q3 = x[xo + X_Q_WB], x[xo + X_Q_WB + 1], x[xo + X_Q_WB + 2], x[xo + X_Q_WB + 3]
    # R_WB of q (as frames.quat_to_rotmat), as scalars
    r00 = 1.0 - 2.0 * (q2 * q2 + q3 * q3)
    r01 = 2.0 * (q1 * q2 - q0 * q3)
    r02 = 2.0 * (q1 * q3 + q0 * q2)
    r10 = 2.0 * (q1 * q2 + q0 * q3)
    r11 = 1.0 - 2.0 * (q1 * q1 + q3 * q3)
    r12 = 2.0 * (q2 * q3 - q0 * q1)
    r20 = 2.0 * (q1 * q3 - q0 * q2)
    r21 = 2.0 * (q2 * q3 + q0 * q1)
    r22 = 1.0 - 2.0 * (q1 * q1 + q2 * q2)
    # eq:vi: v_i = R^T (v - v_w)
    d0 = x[xo + X_V_W] - v_wind_W[0]
    d1 = x[xo + X_V_W + 1] - v_wind_W[1]
    d2 = x[xo + X_V_W + 2] - v_wind_W[2]
    wx, wy, wz = x[xo + X_OMEGA_B], x[xo + X_OMEGA_B + 1], x[xo + X_OMEGA_B + 2]
    vx = r00 * d0 + r10 * d1 + r20 * d2
    vy = r01 * d0 + r11 * d1 + r21 * d2
    vz = r02 * d0 + r12 * d1 + r22 * d2
    fx, fy, fz, mx, my, mz = true_forces_moments(vx, vy, vz, wx, wy, wz, rotors, p)
    xdot[do + X_P_W] = x[xo + X_V_W]
    xdot[do + X_P_W + 1] = x[xo + X_V_W + 1]
    xdot[do + X_P_W + 2] = x[xo + X_V_W + 2]
    xdot[do + X_V_W] = r00 * fx + r01 * fy + r02 * fz
    xdot[do + X_V_W + 1] = r10 * fx + r11 * fy + r12 * fz
    xdot[do + X_V_W + 2] = r20 * fx + r21 * fy + r22 * fz + GRAVITY_MPS2
    xdot[do + X_Q_WB] = 0.5 * (-q1 * wx - q2 * wy - q3 * wz)
    xdot[do + X_Q_WB + 1] = 0.5 * (q0 * wx + q2 * wz - q3 * wy)
    xdot[do + X_Q_WB + 2] = 0.5 * (q0 * wy - q1 * wz + q3 * wx)
    xdot[do + X_Q_WB + 3] = 0.5 * (q0 * wz + q1 * wy - q2 * wx)
    hx = p[P_J] * wx + p[P_J + 1] * wy + p[P_J + 2] * wz
    hy = p[P_J + 3] * wx + p[P_J + 4] * wy + p[P_J + 5] * wz
    hz = p[P_J + 6] * wx + p[P_J + 7] * wy + p[P_J + 8] * wz
    mx += hy * wz - hz * wy
    my += hz * wx - hx * wz
    mz += hx * wy - hy * wx
    xdot[do + X_OMEGA_B] = p[P_JINV] * mx + p[P_JINV + 1] * my + p[P_JINV + 2] * mz
    xdot[do + X_OMEGA_B + 1] = p[P_JINV + 3] * mx + p[P_JINV + 4] * my + p[P_JINV + 5] * mz
    xdot[do + X_OMEGA_B + 2] = p[P_JINV + 6] * mx + p[P_JINV + 7] * my + p[P_JINV + 8] * mz
    return fx, fy, fz, vx, vy, vz


@njit(cache=True)
def motor_time_constant(i, p) -> float:
    """Lag time constant of motor ``i`` (s)."""
    return p[P_TAU_PUSH] if i == MOTOR_PUSHER else p[P_TAU_LIFT]


@njit(cache=True)
def plant_derivative(x, u_in, v_wind_W, p, xdot, f_B) -> None:
    """Time derivative of the whole plant state (eq:pos_dyn, eq:att_dyn, motor lag, servos) into ``xdot``.

    ``u_in``: the plant input (:data:`vtoladapt.layout.PLANT_INPUT`). ``f_B`` receives the true specific
    force (what an accelerometer measures). This is the right-hand side the ``solve_ivp`` reference
    integrates; the fixed-step path (:func:`plant_advance`) solves the motors and servos exactly instead.
    """
    f = rigid_body_derivative(x, 0, rotor_terms(x, X_MOTOR, p, u_in, IN_SURFACE_LOSS), v_wind_W, p, xdot, 0)
    for i in range(3):
        f_B[i] = f[i]
    lag = p[P_LAG_ON] > 0.0
    for i in range(N_MOTORS):
        if lag:
            cmd = min(max(u_in[i], 0.0), 1.0)
            xdot[X_MOTOR + i] = (cmd - x[X_MOTOR + i]) / motor_time_constant(i, p)
        else:
            xdot[X_MOTOR + i] = 0.0
    for j in range(N_SURFACES):
        xdot[X_SERVO + j] = 0.0
        if p[P_SERVO_LAG_ON] > 0.0 and j < p[P_N_SURF]:
            slow = 1.0 + u_in[IN_SERVO_SLOWDOWN + j]
            lim = p[P_SURF_LIMIT + j]
            c = min(max(u_in[ACT_SURFACE + j], -lim), lim)
            r = p[P_SURF_RATE + j] / slow
            xdot[X_SERVO + j] = min(max((c - x[X_SERVO + j]) / (p[P_SURF_TAU + j] * slow), -r), r)


# --- fixed-step integration -------------------------------------------------------------------
RK4_WORK = BlockLayout("RK4 work array", [
    Field("K1", N_BODY, "per s", "RK4 stage 1 of the rigid body (p, v, q, omega)"),
    Field("K2", N_BODY, "per s", "stage 2"),
    Field("K3", N_BODY, "per s", "stage 3"),
    Field("K4", N_BODY, "per s", "stage 4"),
    Field("XT", N_BODY, "state", "trial rigid-body state of the stage being evaluated"),
    Field("M_MID", N_ACTUATORS, "-", "actuator outputs (motors, then surfaces) at mid-step"),
    Field("M_END", N_ACTUATORS, "-", "actuator outputs at the end of the step"),
    Field("ROTORS", ROTOR_TERMS_SIZE, "mixed", "rotor_terms at the start of the next step"),
    Field("SURF_LOSS", N_SURFACES, "-", "the surfaces' loss of the last plant input (0 healthy): what the "
          "first stage of the next tick, evaluated before its input exists, flies with"),
    Field("SERVO_DECAY", N_SURFACES, "-", "exp(-h / (2 tau)) of each servo for the call's step h"),
])
"""Scratch of :func:`plant_first_stage` and :func:`plant_advance` (one per run, reused every tick)."""
_W_K1, _W_K2, _W_K3, _W_K4, _W_XT, _W_M_MID, _W_M_END, _W_ROTORS, _W_SURF_LOSS, _W_SERVO_DECAY = RK4_WORK.offsets(
    "K1", "K2", "K3", "K4", "XT", "M_MID", "M_END", "ROTORS", "SURF_LOSS", "SERVO_DECAY")
RK4_WORK_SIZE = RK4_WORK.size


@njit(cache=True, _nrt=False)
def _store_rotor_terms(rotors, work) -> None:
    for i in range(ROTOR_TERMS_SIZE):
        work[_W_ROTORS + i] = rotors[i]


@njit(cache=True, _nrt=False)
def _load_rotor_terms(work) -> tuple:
    w = work
    o = _W_ROTORS
    return (w[o], w[o + 1], w[o + 2], w[o + 3], w[o + 4], w[o + 5], w[o + 6], w[o + 7], w[o + 8], w[o + 9],
            w[o + 10], w[o + 11], w[o + 12])


@njit(cache=True, _nrt=False)
def plant_first_stage(x, v_wind_W, p, f_B, v_i_B, work) -> None:
    """Evaluate the first RK4 stage of the next step at ``x`` into ``work``.

    ``f_B`` receives the specific force and ``v_i_B`` the incident velocity (eq:vi), both body
    axes: what the sensors sample at the start of a tick.

    The sensors need the specific force at the start of the tick, and with motor lag on it is
    exactly RK4's first stage of the coming step (the command only moves the motors' targets),
    so :func:`plant_advance` called with ``first_stage_done=True`` (and ``x`` and the wind
    unchanged) reuses it instead of evaluating it again.
    """
    rotors = rotor_terms(x, X_MOTOR, p, work, _W_SURF_LOSS)
    f = rigid_body_derivative(x, 0, rotors, v_wind_W, p, work, _W_K1)
    _store_rotor_terms(rotors, work)
    for i in range(3):
        f_B[i] = f[i]
        v_i_B[i] = f[3 + i]


@njit(cache=True, _nrt=False)
def plant_advance(x, u_in, v_wind_W, p, h, n_steps, first_stage_done, work) -> None:
    """Advance ``x`` in place by ``n_steps`` fixed steps of ``h`` seconds, inputs held.

    ``u_in``: the plant input (:data:`vtoladapt.layout.PLANT_INPUT`: actuator commands, then the
    surfaces' loss and the servos' slowdown). The rigid body takes classical RK4 steps (quaternion
    renormalised after each). The motors' first-order lag toward the held, saturated command is solved
    exactly, ``u(t + s) = c + (u(t) - c) e^{-s/tau}``, and so are the servos (lag and slew limit,
    :func:`vtoladapt.sim.surfaces.servo_response`); RK4's stages see the actuators at their stage
    times: the non-autonomous RK4 stays fourth order, the actuators are exact, and stages 2 and 3
    (both at mid-step) share one set of rotor terms. With the lag off the motors (servos) jump to the
    command at the start.

    ``first_stage_done``: :func:`plant_first_stage` has already evaluated stage 1 of the first
    step at this ``x`` and wind (it is recomputed anyway when a lag is off, since the actuators
    jump to the new command, or when a surface's loss changed with this input).
    """
    lag = p[P_LAG_ON] > 0.0
    servo_lag = p[P_SERVO_LAG_ON] > 0.0
    n_surf = int(p[P_N_SURF])
    if lag:
        decay_lift = np.exp(-0.5 * h / p[P_TAU_LIFT])
        decay_push = np.exp(-0.5 * h / p[P_TAU_PUSH])
    else:
        decay_lift = 0.0
        decay_push = 0.0
        for i in range(N_MOTORS):
            x[X_MOTOR + i] = min(max(u_in[i], 0.0), 1.0)
    same_loss = True
    for j in range(N_SURFACES):
        if work[_W_SURF_LOSS + j] != u_in[IN_SURFACE_LOSS + j]:
            same_loss = False
        work[_W_SURF_LOSS + j] = u_in[IN_SURFACE_LOSS + j]
        if j < n_surf:
            lim = p[P_SURF_LIMIT + j]
            if not servo_lag:
                x[X_SERVO + j] = min(max(u_in[ACT_SURFACE + j], -lim), lim)
            else:
                work[_W_SERVO_DECAY + j] = np.exp(-0.5 * h / (p[P_SURF_TAU + j] * (1.0 + u_in[IN_SERVO_SLOWDOWN + j])))
        else:
            x[X_SERVO + j] = 0.0
    reuse_first_stage = first_stage_done and lag and servo_lag and same_loss
    rotors = _load_rotor_terms(work) if reuse_first_stage else rotor_terms(x, X_MOTOR, p, work, _W_SURF_LOSS)
    for step in range(n_steps):
        if step > 0 or not reuse_first_stage:
            rigid_body_derivative(x, 0, rotors, v_wind_W, p, work, _W_K1)
        for i in range(N_MOTORS):
            c = min(max(u_in[i], 0.0), 1.0)
            d = decay_push if i == MOTOR_PUSHER else decay_lift
            gap = (x[X_MOTOR + i] - c) * d
            work[_W_M_MID + i] = c + gap
            work[_W_M_END + i] = c + gap * d
        for j in range(N_SURFACES):
            d0 = x[X_SERVO + j]
            if j < n_surf and servo_lag:
                lim = p[P_SURF_LIMIT + j]
                c = min(max(u_in[ACT_SURFACE + j], -lim), lim)
                slow = 1.0 + u_in[IN_SERVO_SLOWDOWN + j]
                tau = p[P_SURF_TAU + j] * slow
                rate = p[P_SURF_RATE + j] / slow
                gap = d0 - c
                if abs(gap) <= rate * tau:  # below the slew limit all step long: the lag alone, exp precomputed
                    dec = work[_W_SERVO_DECAY + j]
                    work[_W_M_MID + ACT_SURFACE + j] = c + gap * dec
                    work[_W_M_END + ACT_SURFACE + j] = c + gap * dec * dec
                else:
                    work[_W_M_MID + ACT_SURFACE + j] = servo_response(d0, c, 0.5 * h, tau, rate)
                    work[_W_M_END + ACT_SURFACE + j] = servo_response(d0, c, h, tau, rate)
            else:
                work[_W_M_MID + ACT_SURFACE + j] = d0
                work[_W_M_END + ACT_SURFACE + j] = d0
        rotors_mid = rotor_terms(work, _W_M_MID, p, work, _W_SURF_LOSS)
        rotors_end = rotor_terms(work, _W_M_END, p, work, _W_SURF_LOSS)
        for i in range(N_BODY):
            work[_W_XT + i] = x[i] + 0.5 * h * work[_W_K1 + i]
        rigid_body_derivative(work, _W_XT, rotors_mid, v_wind_W, p, work, _W_K2)
        for i in range(N_BODY):
            work[_W_XT + i] = x[i] + 0.5 * h * work[_W_K2 + i]
        rigid_body_derivative(work, _W_XT, rotors_mid, v_wind_W, p, work, _W_K3)
        for i in range(N_BODY):
            work[_W_XT + i] = x[i] + h * work[_W_K3 + i]
        rigid_body_derivative(work, _W_XT, rotors_end, v_wind_W, p, work, _W_K4)
        for i in range(N_BODY):
            x[i] += h / 6.0 * (work[_W_K1 + i] + 2.0 * work[_W_K2 + i] + 2.0 * work[_W_K3 + i] + work[_W_K4 + i])
        for i in range(N_ACTUATORS):
            x[X_MOTOR + i] = work[_W_M_END + i]
        n = np.sqrt(x[X_Q_WB] ** 2 + x[X_Q_WB + 1] ** 2 + x[X_Q_WB + 2] ** 2 + x[X_Q_WB + 3] ** 2)
        for i in range(4):
            x[X_Q_WB + i] /= n
        rotors = rotors_end


def plant_input(motor_cmd) -> np.ndarray:
    """A healthy plant input (:data:`vtoladapt.layout.PLANT_INPUT`) from actuator commands: the five motor
    commands, optionally followed by the surfaces' (neutral when not given)."""
    cmd = np.asarray(motor_cmd, dtype=float).ravel()
    if cmd.size not in (N_MOTORS, N_ACTUATORS, PLANT_INPUT_SIZE):
        raise ValueError(f"motor_cmd: {cmd.size} entries; allowed: {N_MOTORS} (motors), {N_ACTUATORS} (motors "
                         f"and surfaces) or {PLANT_INPUT_SIZE} (a whole plant input)")
    u = np.zeros(PLANT_INPUT_SIZE)
    u[:cmd.size] = cmd
    return u


@njit(cache=True)
def rk4_step(x, u_in, v_wind_W, p, h, f_B) -> None:
    """Advance ``x`` in place by one fixed step of ``h`` seconds (see :func:`plant_advance`).

    Inputs (the plant input ``u_in``, wind) are held over the step, as the controller holds its command.
    ``f_B`` receives the specific force at the start of the step.
    """
    work = np.zeros(RK4_WORK_SIZE)
    for j in range(N_SURFACES):
        work[_W_SURF_LOSS + j] = u_in[IN_SURFACE_LOSS + j]
    v_i_B = np.empty(3)
    lag = p[P_LAG_ON] > 0.0
    if not lag:
        for i in range(N_MOTORS):
            x[X_MOTOR + i] = min(max(u_in[i], 0.0), 1.0)
    plant_first_stage(x, v_wind_W, p, f_B, v_i_B, work)
    plant_advance(x, u_in, v_wind_W, p, h, 1, lag, work)


def hover_trim_motor(vehicle: Vehicle, plant: PlantConfig) -> np.ndarray:
    """Motor outputs (fractions) that hold a level hover in still air for the plant's truth."""
    c = plant.true_coefficients(vehicle)
    m_true = plant.mass_kg if plant.mass_kg is not None else vehicle.mass.mass_kg
    u = math.sqrt(GRAVITY_MPS2 * m_true / (vehicle.mass.mass_kg * c["CTz"] * 100.0**2))
    if u > 1.0:
        # three significant digits (a 1e75 % throttle is not 76 digits), more if it would round to the 100 %
        # it exceeds ("needs 100 % > 100 %")
        digits = next((d for d in range(3, 16) if float(f"{100 * u:.{d}g}") > 100.0), 16)
        need = f"{100 * u:.{digits}g} % > 100 %"
        raise ConfigError(f"[plant] cannot hover: needs lift throttle {need} with its true "
                          f"CTz = {c['CTz']:g} and mass {m_true:g} kg; allowed: [plant.coefficients] CTz and "
                          f"[plant] mass_kg that hover below 100 %")
    return np.array([u, u, u, u, 0.0])


def integrate_reference(x0: np.ndarray, motor_cmd: np.ndarray, v_wind_W: np.ndarray, params: np.ndarray,
                        t_end_s: float, rtol: float = 1e-12, atol: float = 1e-12) -> np.ndarray:
    """Plant state at ``t_end_s`` by ``scipy.integrate.solve_ivp`` (DOP853), inputs held constant.

    ``motor_cmd``: the actuator commands (five motors, optionally the surfaces) or a whole plant input.

    The independent reference the fixed-step RK4 path is tested against; far too slow for
    closed-loop use. The quaternion is renormalised at the end only.
    """
    from scipy.integrate import solve_ivp

    u_in = plant_input(motor_cmd)
    v_wind_W = np.asarray(v_wind_W, dtype=float)
    x_start = np.asarray(x0, dtype=float).copy()
    if params[P_LAG_ON] <= 0.0:
        x_start[X_MOTOR:X_MOTOR + N_MOTORS] = np.clip(u_in[:N_MOTORS], 0.0, 1.0)
    if params[P_SERVO_LAG_ON] <= 0.0:
        lim = params[P_SURF_LIMIT:P_SURF_LIMIT + N_SURFACES]
        x_start[X_SERVO:X_SERVO + N_SURFACES] = np.clip(u_in[ACT_SURFACE:ACT_SURFACE + N_SURFACES], -lim, lim)
    f_B = np.empty(3)

    def rhs(_t, x):
        xd = np.empty(X_SIZE)
        plant_derivative(x, u_in, v_wind_W, params, xd, f_B)
        return xd

    sol = solve_ivp(rhs, (0.0, t_end_s), x_start, method="DOP853", rtol=rtol, atol=atol)
    if not sol.success:
        raise RuntimeError(f"solve_ivp failed: {sol.message}")
    x = sol.y[:, -1].copy()
    x[X_Q_WB:X_Q_WB + 4] /= np.linalg.norm(x[X_Q_WB:X_Q_WB + 4])
    return x
