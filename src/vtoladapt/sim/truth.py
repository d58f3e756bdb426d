"""The plant's physical parameters drawn from the vehicle file's stated uncertainty.

Table I gives the force model's spread (:func:`vtoladapt.sim.plant.draw_table_i_coefficients`); the
vehicle file's ``[uncertainty]`` gives the rest: the stall angle, the motor and servo lags, the mass, the
inertia, the air density and each surface's effectiveness. A scenario's ``[plant] physical_from =
"draw"`` flies one such aircraft; the controller keeps the file's values (its belief).
"""
from __future__ import annotations

import numpy as np

from ..layout import N_SURFACES
from ..vehicle import Vehicle

PHYSICAL_DRAW_STREAM = 0x9B15A1
"""Second entropy word of the physical draw's seed sequence: its own stream, so drawing it shifts neither
the Table I draw (:data:`vtoladapt.sim.plant.PLANT_DRAW_STREAM`) nor the run's other random draws."""
PHYSICAL_DRAW_CLIP_SIGMAS = 2.0
"""A drawn parameter stays within this many standard deviations of the file's value."""
PHYSICAL_DRAW_ORDER = ("stall_angle_deg", "lift_motor_time_constant_s", "pusher_motor_time_constant_s",
                       *(f"servo_time_constant_factor_{j + 1}" for j in range(N_SURFACES)), "mass_kg",
                       "inertia_xx", "inertia_yy", "inertia_zz", "air_density_kgpm3",
                       *(f"surface_effectiveness_{j + 1}" for j in range(N_SURFACES)))
"""The order of the standard normals the draw takes (one each, whether or not the vehicle has the surface)."""


def draw_physical_parameters(vehicle: Vehicle, seed: int) -> dict:
    """One plausible airframe: the :class:`~vtoladapt.sim.plant.PlantConfig` fields of the physical
    parameters, drawn about the vehicle file's values with its ``[uncertainty]``.

    The rule: generator ``numpy.random.default_rng(SeedSequence([seed, PHYSICAL_DRAW_STREAM]))``, one
    standard normal ``z`` per entry of :data:`PHYSICAL_DRAW_ORDER`, each clipped to
    +-:data:`PHYSICAL_DRAW_CLIP_SIGMAS`. The stall angle is ``mean + std z`` (deg); every other parameter
    is positive and scales, so it is the file's value times ``exp(frac z)`` (log-normal: the relative
    spread is ``frac`` to first order and nothing crosses zero). The three principal inertias are drawn
    independently (the product of inertia stays the file's); no correlations are stated, so none are drawn.
    """
    u = vehicle.uncertainty
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), PHYSICAL_DRAW_STREAM]))
    z = dict(zip(PHYSICAL_DRAW_ORDER, np.clip(rng.standard_normal(len(PHYSICAL_DRAW_ORDER)),
                                              -PHYSICAL_DRAW_CLIP_SIGMAS, PHYSICAL_DRAW_CLIP_SIGMAS)))

    def scaled(value: float, frac: float, name: str) -> float:
        return float(value * np.exp(frac * z[name]))

    inertia = vehicle.mass.inertia_kgm2
    surfaces = range(len(vehicle.surfaces))  # normals were drawn for every slot; the vehicle's surfaces use theirs
    return {
        "stall_angle_deg": float(vehicle.envelope.stall_angle_deg + u.stall_angle_deg * z["stall_angle_deg"]),
        "lift_motor_time_constant_s": scaled(vehicle.actuators.lift_motor_time_constant_s,
                                             u.lift_motor_time_constant_frac, "lift_motor_time_constant_s"),
        "pusher_motor_time_constant_s": scaled(vehicle.actuators.pusher_motor_time_constant_s,
                                               u.pusher_motor_time_constant_frac, "pusher_motor_time_constant_s"),
        "servo_time_constant_factors": tuple(scaled(1.0, u.servo_time_constant_frac,
                                                    f"servo_time_constant_factor_{j + 1}") for j in surfaces),
        "mass_kg": scaled(vehicle.mass.mass_kg, u.mass_frac, "mass_kg"),
        "inertia_kgm2": tuple(scaled(inertia[i], u.inertia_frac, f"inertia_{a}") for i, a in
                              enumerate(("xx", "yy", "zz"))),
        "air_density_kgpm3": scaled(vehicle.envelope.air_density_kgpm3, u.air_density_frac, "air_density_kgpm3"),
        "surface_effectiveness": tuple(scaled(1.0, u.surface_effectiveness_frac, f"surface_effectiveness_{j + 1}")
                                       for j in surfaces),
    }
