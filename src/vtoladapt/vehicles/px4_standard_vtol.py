"""How ``px4_standard_vtol.toml``'s force model is derived from PX4's Gazebo ``standard_vtol`` model.

PX4's Gazebo ``standard_vtol`` (the reference SITL VTOL) models its lift and pusher rotors as
``T = k_motor omega^2`` with a commanded rotor speed up to ``omega_max``, a rotor drag
``F = -c_rd omega v_perp`` on each lift rotor, and each wing half with Gazebo's lift-drag plugin
``CL = cla (alpha + a0)``, ``CD = cda |alpha + a0|`` below stall. We map throttle ``u`` (percent)
to rotor speed linearly, ``omega = omega_max u / 100``, as the paper does for its motors.
"""
from __future__ import annotations

import numpy as np

#: PX4 Gazebo standard_vtol parameters (PX4-SITL_gazebo ``standard_vtol.sdf``).
PX4_STANDARD_VTOL = {
    "mass_kg": 5.0,
    "lift_motor_constant": 2e-5,          # N/(rad/s)^2
    "lift_omega_max_radps": 1500.0,
    "pusher_motor_constant": 8.54858e-6,  # N/(rad/s)^2
    "pusher_omega_max_radps": 3500.0,
    "rotor_drag_coefficient": 8.06428e-5, # N/((rad/s)(m/s)) per rotor
    "cla_per_rad": 4.7528,
    "a0_rad": 0.05984,
    "cda_per_rad": 0.6417112299,
    "alpha_stall_rad": 0.33914,
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
