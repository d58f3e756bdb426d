"""The package's airframe for the allocator: four lift rotors, a pusher and the vehicle file's surfaces.

The ``"lift_rotors_surfaces"`` member of the ``"effectiveness"`` kind (:mod:`vtoladapt.sim.allocation`).
Its columns, from the flight computer's model (the vehicle file, never the plant's truth):

* lift rotor ``i`` at body ``(x_i, y_i)`` with spin ``s_i`` and thrust ``T_i`` along body -z gives
  ``[1, -y_i, x_i, -s_i k_m]`` (:func:`vtoladapt.vehicle.lift_allocation_matrix`), bounded by
  ``[0, T_unit u_max^2]``;
* surface ``j`` gives, per pascal of dynamic pressure and radian, ``[-S CZ_j, S b Cl_j, S c Cm_j,
  S b Cn_j]`` (its body-z force counts against the lift: lift is along -z), bounded by its limit.

The pusher is not allocated: the controller's pusher throttle passes through (PX4's standard VTOL
gives its forward thrust to the pusher directly, too).
"""
from __future__ import annotations

import math

import numpy as np

from ..layout import N_LIFT, N_SURFACES
from ..vehicle import lift_allocation_matrix
from .allocation import N_ALLOC, N_OUT, Effectiveness


def effectiveness(vehicle) -> Effectiveness:
    """The effectiveness of ``vehicle``'s lift rotors and surfaces (module docstring)."""
    B0 = np.zeros((N_OUT, N_ALLOC))
    Bq = np.zeros((N_OUT, N_ALLOC))
    B0[:, :N_LIFT] = lift_allocation_matrix(vehicle.geometry, vehicle.actuators.yaw_torque_per_thrust_m)
    S = vehicle.geometry.wing_area_m2
    b = vehicle.geometry.wingspan_m
    c = vehicle.wing_chord_m
    for j, sf in enumerate(vehicle.surfaces[:N_SURFACES]):
        _cx, _cy, cz, cl, cm, cn = sf.derivatives_per_rad
        Bq[:, N_LIFT + j] = [-S * cz, S * b * cl, S * c * cm, S * b * cn]
    return with_actuator_limits(vehicle, B0, Bq)


def with_actuator_limits(vehicle, B0: np.ndarray, B_per_Pa: np.ndarray) -> Effectiveness:
    """An :class:`Effectiveness` of the matrices ``B0`` and ``B_per_Pa`` with ``vehicle``'s actuator
    limits (lift rotors from zero to the thrust at full throttle, surfaces within their deflection
    limits) and the rotors' equal preferred share: what every effectiveness of the airframe shares."""
    lo = np.zeros(N_ALLOC)
    hi = np.zeros(N_ALLOC)
    u_max = vehicle.actuators.throttle_max_pct / 100.0
    t_unit = vehicle.mass.mass_kg * vehicle.theta_scaled[1] / N_LIFT
    hi[:N_LIFT] = t_unit * u_max * u_max
    for j, sf in enumerate(vehicle.surfaces[:N_SURFACES]):
        lim = math.radians(sf.limit_deg)
        lo[N_LIFT + j] = -lim
        hi[N_LIFT + j] = lim
    share = np.zeros(N_ALLOC)
    share[:N_LIFT] = 1.0 / N_LIFT
    return Effectiveness(B0=B0, B_per_Pa=B_per_Pa, lower=lo, upper=hi, preferred_share=share,
                         t_unit_N=float(t_unit), throttle_max=float(u_max))
