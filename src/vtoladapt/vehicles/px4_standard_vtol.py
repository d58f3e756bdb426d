"""How ``px4_standard_vtol.toml``'s force model is derived from PX4's Gazebo ``standard_vtol`` model.

PX4's Gazebo ``standard_vtol`` (the reference SITL VTOL) models its lift and pusher rotors as
``T = k_motor omega^2`` with a commanded rotor speed up to ``omega_max``, a rotor drag
``F = -c_rd omega v_perp`` on each lift rotor, and each wing half with Gazebo's lift-drag plugin
``CL = cla (alpha + a0)``, ``CD = cda |alpha + a0|`` below stall. We map throttle ``u`` (percent)
to rotor speed linearly, ``omega = omega_max u / 100``, as the paper does for its motors.

Its control surfaces (:func:`px4_standard_vtol_surfaces`) are the model's three actuated joints, each
driving the lift-drag plugin named after it through ``control_joint_rad_to_cl``: the lift coefficient of
that plugin's panel changes by that much per radian of the joint. Read from PX4-SITL_gazebo-classic's
``models/standard_vtol/standard_vtol.sdf.jinja`` at commit 807b67bb3007113ea52fd36ec2cefae4a5fa3f85 (the
repository's newest, 2025; :data:`SDF_COMMIT`; the file last changed in 70683dc, March 2025):

* ``left_elevon_joint``, ``right_elevon_joint``: -1.0 /rad on the wing half (``left_wing_lift``,
  ``right_wing_lift``, 0.50 m^2 each, centre of pressure at (-0.05, +-0.3, 0.05) m, Gazebo's x forward,
  y left, z up);
* ``elevator_joint``: -12.0 /rad on the ``elevator`` panel of 0.01 m^2 at (-0.5, 0, 0) m (the panel's own
  ``a0`` of -0.2 rad, a constant nose-up trim moment, is not modelled: our surfaces are increments);
* joint limits +-0.53 rad (the file's comment: -30/+30 deg);
* the ``rudder`` plugin has no control joint (its joint is limited to +-0.01 rad and not driven by the
  MAVLink interface's channels): the model has no rudder, and neither do we.

(The 2016 file, commit 7ee67ba, had -0.5 and -4.0 on 0.12 m^2 wing halves of a 1.5 kg airframe; the
numbers before issue #35 took those with the 5 kg model's wing and a hover-rotor moment constant of 0.016,
which neither file says: both say 0.06.)

The hover rotors (:func:`px4_standard_vtol_rotors`): ``rotor_0`` .. ``rotor_3`` at (+-0.35, +-0.35) m,
``turningDirection`` ccw, ccw, cw, cw, ``momentConstant`` 0.06 m, ``rotorDragCoefficient`` 0.000106428.
In our frame (FRD) a position ``(x, y)`` of Gazebo's FLU is ``(x, -y)``; a ccw rotor (spin -1 in the vehicle
file) yaws the airframe positively about body z (down) with its drag torque.

What PX4 itself believes about the rotors and surfaces (the flight computer's allocation) is not the
sdf: it is the airframe file's ``CA_*`` parameters (:data:`PX4_AIRFRAME_1040`,
:func:`px4_ca_settings`), which place the rotors at (+-0.1515, +-0.245 / +-0.1875) m with
``CA_ROTORn_KM`` = +-0.05 -- truth and belief differ, as on a real PX4 build.

In our frame (FRD) a panel's lift change is a body-z force ``dF_z = -q A dCL``; its moment ``r x F`` at the
centre of pressure gives the derivatives, divided by ``q S`` (forces), ``q S b`` (roll, yaw) or ``q S c``
(pitch), ``c = S / b``.
"""
from __future__ import annotations

import numpy as np

SDF_COMMIT = "807b67bb3007113ea52fd36ec2cefae4a5fa3f85"
"""PX4-SITL_gazebo-classic commit whose ``models/standard_vtol/standard_vtol.sdf.jinja`` the numbers are from."""

#: PX4 Gazebo standard_vtol parameters (PX4-SITL_gazebo-classic ``standard_vtol.sdf.jinja`` at :data:`SDF_COMMIT`).
PX4_STANDARD_VTOL = {
    "mass_kg": 5.0,
    "lift_motor_constant": 2e-5,          # N/(rad/s)^2
    "lift_omega_max_radps": 1500.0,
    "lift_moment_constant_m": 0.06,       # momentConstant of rotor_0 .. rotor_3
    # rotor_0 .. rotor_3 link poses (Gazebo FLU, m) and turningDirection
    "lift_rotor_positions_flu_m": ((0.35, -0.35), (-0.35, 0.35), (0.35, 0.35), (-0.35, -0.35)),
    "lift_turning_direction": ("ccw", "ccw", "cw", "cw"),
    "pusher_motor_constant": 8.54858e-6,  # N/(rad/s)^2
    "pusher_omega_max_radps": 3500.0,
    "rotor_drag_coefficient": 0.000106428,  # N/((rad/s)(m/s)) per rotor
    "cla_per_rad": 4.7528,
    "a0_rad": 0.05984,
    "cda_per_rad": 0.6417112299,
    "alpha_stall_rad": 0.33914,
    # control surfaces (the same file): control_joint_rad_to_cl, panel area (None: half of our wing),
    # centre of pressure in Gazebo's x forward, y left, z up
    "elevon_rad_to_cl": -1.0,
    "elevon_cp_m": (-0.05, 0.3, 0.05),
    "elevator_rad_to_cl": -12.0,
    "elevator_area_m2": 0.01,
    "elevator_cp_m": (-0.5, 0.0, 0.0),
    "surface_limit_rad": 0.53,
}


PX4_AIRFRAME_1040 = {
    "file": "ROMFS/px4fmu_common/init.d-posix/airframes/1040_gazebo-classic_standard_vtol",
    "commit": "041e5069cbe2b2978ce334aab9f33ebff0f5019d",
    "CA_ROTOR0_PX": 0.1515, "CA_ROTOR0_PY": 0.245, "CA_ROTOR0_KM": 0.05,
    "CA_ROTOR1_PX": -0.1515, "CA_ROTOR1_PY": -0.1875, "CA_ROTOR1_KM": 0.05,
    "CA_ROTOR2_PX": 0.1515, "CA_ROTOR2_PY": -0.245, "CA_ROTOR2_KM": -0.05,
    "CA_ROTOR3_PX": -0.1515, "CA_ROTOR3_PY": 0.1875, "CA_ROTOR3_KM": -0.05,
    # CA_SV_CS0_TYPE 1 (left aileron), CS1_TYPE 2 (right aileron), CS2_TYPE 3 (elevator); unset torques are 0
    "CA_SV_CS0_TRQ_R": -0.5, "CA_SV_CS1_TRQ_R": 0.5, "CA_SV_CS2_TRQ_P": 1.0,
    "MC_AIRMODE": 1,
}
"""PX4's airframe parameters for this model (PX4-Autopilot's ``1040_gazebo-classic_standard_vtol`` at the
commit given): the flight computer's belief about its rotors and surfaces. PX4's rotor ``n`` is the sdf's
``rotor_n`` (``motorNumber``), its surfaces ``CS0..2`` our ``elevon_left``, ``elevon_right``, ``elevator``."""


def px4_standard_vtol_rotors(p: dict | None = None) -> dict:
    """The hover rotors in the vehicle file's terms: ``positions_m`` (FRD ``[x, y]``), ``spin`` (+1 cw,
    -1 ccw seen from above) and ``yaw_torque_per_thrust_m`` (the sdf's ``momentConstant``)."""
    p = dict(PX4_STANDARD_VTOL if p is None else p)
    positions = [[float(x), float(-y)] for x, y in p["lift_rotor_positions_flu_m"]]
    spin = [-1 if d == "ccw" else 1 for d in p["lift_turning_direction"]]
    return {"positions_m": positions, "spin": spin, "yaw_torque_per_thrust_m": p["lift_moment_constant_m"]}


def px4_ca_settings(a: dict | None = None) -> dict:
    """The vehicle file's ``[effectiveness_settings.px4_ca]`` table from PX4's airframe parameters."""
    a = dict(PX4_AIRFRAME_1040 if a is None else a)
    return {
        "rotor_px_m": [a[f"CA_ROTOR{i}_PX"] for i in range(4)],
        "rotor_py_m": [a[f"CA_ROTOR{i}_PY"] for i in range(4)],
        "rotor_km_m": [a[f"CA_ROTOR{i}_KM"] for i in range(4)],
        "surface_torque": [[a.get(f"CA_SV_CS{j}_TRQ_{ax}", 0.0) for ax in "RPY"] for j in range(3)],
    }


def px4_standard_vtol_force_model(p: dict | None = None) -> dict[str, float]:
    """Our force-model coefficients (Table I units: throttle in %, per unit mass) for PX4's VTOL.

    * ``CTz = 4 k_lift omega_max^2 / m / 100^2`` and ``CTx = k_push omega_max^2 / m / 100^2``.
    * Rotor drag is linear in rotor speed and in-plane airspeed, so ``k1 = 1``; Gazebo's drag is
      symmetric in the rotor's angle of attack, so ``k2`` is made large (20 rad) and ``CS`` is the
      least-squares fit of ``CS ((pi/2)^2 - a^2)(a + k2)`` to ``4 c_rd (omega_max/100) cos(a) / m``
      over ``|a| <= 45 deg``, the paper's side-force test range.
    * ``CL0 = cla a0``, ``CL1 = cla``; ``CD0 + CD1 a + CD2 a^2`` is the least-squares fit of
      ``cda |a + a0|`` over the attached-flow range ``a + a0`` in ``[0, alpha_stall]``
      (what the linear model is for). There ``a + a0 >= 0``, so the fit is exact: ``CD2 = 0``.
    """
    p = dict(PX4_STANDARD_VTOL if p is None else p)
    m = p["mass_kg"]
    ctz = 4.0 * p["lift_motor_constant"] * p["lift_omega_max_radps"] ** 2 / m / 100.0**2
    ctx = p["pusher_motor_constant"] * p["pusher_omega_max_radps"] ** 2 / m / 100.0**2
    k2 = 20.0
    a = np.linspace(-np.pi / 4, np.pi / 4, 181)
    basis = ((np.pi / 2) ** 2 - a**2) * (a + k2)
    target = 4.0 * p["rotor_drag_coefficient"] * (p["lift_omega_max_radps"] / 100.0) * np.cos(a) / m
    cs = float(basis @ target / (basis @ basis))
    alpha = np.linspace(-p["a0_rad"], p["alpha_stall_rad"] - p["a0_rad"], 201)
    cd = p["cda_per_rad"] * np.abs(alpha + p["a0_rad"])
    cd2, cd1, cd0 = np.polyfit(alpha, cd, 2)
    return {
        "CTx": ctx, "CTz": ctz, "CS": cs, "k1": 1.0, "k2": k2,
        "CD0": float(cd0), "CD1": float(cd1), "CD2": round(float(cd2), 12),
        "CL0": p["cla_per_rad"] * p["a0_rad"], "CL1": p["cla_per_rad"],
    }


def _panel_derivatives(rad_to_cl: float, area_m2: float, cp_flu_m, S: float, b: float) -> list[float]:
    """CX..Cn per radian of a panel whose lift coefficient changes by ``rad_to_cl`` per radian."""
    c = S / b
    r = np.array([cp_flu_m[0], -cp_flu_m[1], -cp_flu_m[2]])  # Gazebo FLU -> our FRD
    F = np.array([0.0, 0.0, -rad_to_cl * area_m2])          # lift is along -z (FRD); per unit q and radian
    M = np.cross(r, F)
    return [float(v) for v in (F[0] / S, F[1] / S, F[2] / S, M[0] / (S * b), M[1] / (S * c), M[2] / (S * b))]


def px4_standard_vtol_surfaces(wing_area_m2: float, wingspan_m: float, p: dict | None = None) -> dict[str, list[float]]:
    """The derivatives per radian (CX, CY, CZ, Cl, Cm, Cn) of the model's elevons and elevator.

    ``wing_area_m2`` and ``wingspan_m`` are our vehicle file's reference area and span; each elevon
    acts on half of the wing area (module docstring).
    """
    p = dict(PX4_STANDARD_VTOL if p is None else p)
    S, b = wing_area_m2, wingspan_m
    x, y, z = p["elevon_cp_m"]
    return {
        "elevon_left": _panel_derivatives(p["elevon_rad_to_cl"], S / 2, (x, y, z), S, b),
        "elevon_right": _panel_derivatives(p["elevon_rad_to_cl"], S / 2, (x, -y, z), S, b),
        "elevator": _panel_derivatives(p["elevator_rad_to_cl"], p["elevator_area_m2"], p["elevator_cp_m"], S, b),
    }
