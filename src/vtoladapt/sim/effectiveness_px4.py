"""An airframe's effectiveness from PX4's control-allocation parameters (``CA_*``): the flight computer's belief.

The ``"px4_ca"`` member of the ``"effectiveness"`` kind (:mod:`vtoladapt.sim.allocation`). PX4 describes a
multicopter's and a VTOL's actuators as data (``CA_ROTOR_COUNT``, ``CA_ROTORn_PX``, ``CA_ROTORn_PY``,
``CA_ROTORn_KM``, ``CA_SV_CS_COUNT``, ``CA_SV_CSn_TRQ_R/P/Y``), and its allocator builds the effectiveness
matrix from those numbers, not from the aircraft: what a PX4 build believes about its rotors can differ from
what they are (the Gazebo model and its airframe file do, on purpose). This module builds the same belief
for our allocator from the vehicle file's ``[effectiveness_settings.px4_ca]`` table (:class:`Settings`):

* lift rotor ``i`` (PX4's rotor ``i``, body FRD, thrust along -z): ``[1, -PY_i, PX_i, KM_i]`` per newton,
  as PX4's ``ActuatorEffectivenessRotors`` gives for an upward axis (``KM > 0``: a counter-clockwise rotor,
  whose drag torque yaws the airframe clockwise seen from above, i.e. positive about body z down);
  its thrust at full throttle is the vehicle file's (``CTz``: PX4's ``CA_ROTORn_CT`` is normalised away);
* surface ``j`` (PX4's ``CA_SV_CSj``): moment per pascal and radian only on the axes its ``TRQ_R/P/Y`` names
  (non-zero), with the sign PX4 gives, and the size of the vehicle file's derivative on that axis (PX4's
  torques are normalised: the size lives in PX4's fixed-wing rate gains). PX4's allocator gives a surface no
  lift, so neither does this belief. A sign that disagrees with the vehicle file's surface, or an axis the
  file's surface does not act on, is the file's mistake (a ConfigError naming it).

The pusher is not allocated (as in :mod:`.effectiveness`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import ConfigError, Validated, build, setting
from ..layout import N_LIFT, N_SURFACES
from .allocation import N_ALLOC, N_OUT, Effectiveness
from .effectiveness import with_actuator_limits

SECTION = "effectiveness_settings.px4_ca"


@dataclass(frozen=True)
class Settings(Validated):
    """PX4's ``CA_*`` parameters of an airframe (the vehicle file's ``[effectiveness_settings.px4_ca]``)."""

    config_section = SECTION

    rotor_px_m: tuple[float, ...] = setting("m", "CA_ROTORn_PX of the lift rotors 0..3 (body x, forward)",
                                            length=N_LIFT, ge=-10.0, le=10.0)
    rotor_py_m: tuple[float, ...] = setting("m", "CA_ROTORn_PY of the lift rotors 0..3 (body y, right)",
                                            length=N_LIFT, ge=-10.0, le=10.0)
    rotor_km_m: tuple[float, ...] = setting("m", "CA_ROTORn_KM of the lift rotors 0..3 (moment per thrust; "
                                            "positive: counter-clockwise seen from above)", length=N_LIFT,
                                            ge=-1.0, le=1.0)
    surface_torque: tuple[tuple[float, ...], ...] = setting(
        "-", "CA_SV_CSn_TRQ_R, _TRQ_P, _TRQ_Y of each control surface, in the vehicle file's [[surfaces]] order",
        default=(), max_items=N_SURFACES, ge=-10.0, le=10.0)
    source: str = setting("-", "where the numbers come from (PX4 file and commit)", default="")

    def _check(self, source: str) -> None:
        for j, t in enumerate(self.surface_torque):
            if len(t) != 3:
                raise ConfigError(f"{source}: [{SECTION}] surface_torque[{j}] = {list(t)}: must be "
                                  "[TRQ_R, TRQ_P, TRQ_Y]")


def settings_of(vehicle) -> Settings:
    """The vehicle file's ``[effectiveness_settings.px4_ca]``, validated; a ConfigError if it has none."""
    where = getattr(vehicle, "source_path", "") or getattr(vehicle, "name", "<vehicle>")
    table = vehicle.effectiveness_table("px4_ca") if hasattr(vehicle, "effectiveness_table") else None
    if table is None:
        raise ConfigError(f"{where}: effectiveness 'px4_ca' needs a [{SECTION}] table (PX4's CA_ROTORn_PX, "
                          "_PY, _KM and CA_SV_CSn_TRQ_R/P/Y); allowed: add it, or effectiveness = "
                          "'lift_rotors_surfaces'")
    return build(Settings, table, source=where, section=SECTION)


def effectiveness(vehicle) -> Effectiveness:
    """The belief of PX4's parameters about ``vehicle``'s lift rotors and surfaces (module docstring)."""
    st = settings_of(vehicle)
    where = getattr(vehicle, "source_path", "") or vehicle.name
    B0 = np.zeros((N_OUT, N_ALLOC))
    Bq = np.zeros((N_OUT, N_ALLOC))
    for i in range(N_LIFT):
        B0[:, i] = [1.0, -st.rotor_py_m[i], st.rotor_px_m[i], st.rotor_km_m[i]]
    if np.linalg.matrix_rank(B0[:, :N_LIFT]) < N_OUT:
        raise ConfigError(f"{where}: [{SECTION}] rotor_px_m, rotor_py_m, rotor_km_m: the four rotors cannot "
                          "make independent thrust, roll, pitch and yaw; allowed: rotors on both sides of both "
                          "axes, two of each KM sign")
    surfaces = vehicle.surfaces[:N_SURFACES]
    if len(st.surface_torque) != len(surfaces):
        raise ConfigError(f"{where}: [{SECTION}] surface_torque has {len(st.surface_torque)} rows; allowed: one "
                          f"per [[surfaces]] entry ({len(surfaces)})")
    S = vehicle.geometry.wing_area_m2
    b = vehicle.geometry.wingspan_m
    c = vehicle.wing_chord_m
    for j, sf in enumerate(surfaces):
        _cx, _cy, _cz, cl, cm, cn = sf.derivatives_per_rad
        physical = (S * b * cl, S * c * cm, S * b * cn)
        for k, (trq, size) in enumerate(zip(st.surface_torque[j], physical)):
            if trq == 0.0:
                continue
            if size == 0.0 or math.copysign(1.0, trq) != math.copysign(1.0, size):
                axis = "RPY"[k]
                raise ConfigError(f"{where}: [{SECTION}] surface_torque[{j}] TRQ_{axis} = {trq}: the vehicle's "
                                  f"surface {sf.name!r} has {'no' if size == 0.0 else 'the opposite'} moment on "
                                  "that axis; allowed: PX4's sign of the file's surface, or 0")
            Bq[1 + k, N_LIFT + j] = size
    return with_actuator_limits(vehicle, B0, Bq)
