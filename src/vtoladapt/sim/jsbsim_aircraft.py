"""A vehicle file as a JSBSim aircraft: the XML JSBSim reads, and the map from our actuator vector to it.

:func:`write_aircraft` writes a folder JSBSim opens as its root directory
(``FGFDMExec(root_dir=...)``, ``load_model(name)``, or ``JSBSim --root=DIR --aircraft=NAME``)::

    DIR/aircraft/NAME/NAME.xml          the aircraft (metrics, mass, propulsion, control, aerodynamics)
    DIR/aircraft/NAME/actuator_map.toml our actuator columns -> the fcs/ properties they command
    DIR/engine/NAME_lift_motor.xml      electric engines (power sized to the rotors' full thrust)
    DIR/engine/NAME_pusher_motor.xml
    DIR/engine/direct.xml               JSBSim's direct thruster

Every number comes from the plant's own parameter array
(:meth:`vtoladapt.sim.plant.PlantConfig.to_kernel`), so the XML is the native plant's truth for that
scenario (a drawn plant writes its draw), expressed in JSBSim's terms:

* **mass and inertia** at a centre of gravity placed at the structural origin; JSBSim's structural frame
  is x aft, y right, z up, so a body FRD point ``(x, y, z)`` sits at ``(-x, y, -z)``.
* **rotors**: one electric engine with a *direct* thruster per rotor. An electric engine hands its
  thruster ``P_max x throttle`` (ft lbf/s) and a direct thruster turns that number into thrust (lbf), so
  thrust is linear in the engine's throttle position; the flight control sets that position to
  ``w^2`` (``w`` the lagged rotor speed fraction), times the pusher's ``C_T(J)/C_T(0)``, which is the
  vehicle's thrust model ``T = T_max w^2``. The alternative, an electric engine turning a JSBSim
  propeller, integrates rotor speed from a power balance and needs a motor constant and a propeller
  inertia the vehicle files do not have, so its thrust would differ from the native plant's by
  whatever those guesses were; with the direct thruster a cross-check compares the flight-dynamics
  engine, not two propeller models. The lift rotors point up (pitch 90 deg) at their positions, so
  JSBSim makes their roll and pitch moments from location x force itself.
* **rotor reaction torques** (lift rotors about body z, the pusher's about body x) as external moments.
* **motor lag and servos** in the flight control: first-order ``lag_filter``s (JSBSim's are discretised
  by the bilinear transform; the native plant solves the lag exactly) and, per surface, a clip to the
  deflection limit followed by an ``actuator`` with lag and rate limit.
* **aerodynamics** in body axes (X, Y, Z, ROLL, PITCH, YAW) as functions of ``aero/alpha-rad``,
  ``aero/beta-rad``, the airspeed, the density and the surfaces' deflections, valid over all of
  alpha in [-180, 180] deg: the linear polars blended into a flat plate past stall, the side force
  C_Y(beta), the rotors' side force, the surfaces and the rate damping, each the formula of
  :func:`vtoladapt.sim.plant.true_forces_moments` written as a JSBSim ``<function>``, not a table.
* **the planet**: a sphere of Earth's mean radius that does not rotate, with ``GM = g (R + h0)^2`` so
  that gravity at a run's origin (:data:`ORIGIN_ALTITUDE_M` up) is the native plant's ``g``: the native
  plant's world (flat, uniform gravity, inertial) as JSBSim can express it. JSBSim still integrates over
  a curved surface.

The actuator map (:data:`ACTUATOR_PROPERTIES`) names, for each column of
:data:`vtoladapt.layout.ACTUATORS`, the fcs/ property its command is written to; unused surface slots
have none. ``fcs/vtol/surface-N-loss`` takes a surface_lost fault's share.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from ..config import ConfigError
from ..frames import GRAVITY_MPS2
from ..layout import ACTUATORS, MOTOR_PUSHER, N_LIFT, N_MOTORS, N_SURFACES
from ..vehicle import Vehicle
from . import plant as P

# --- unit conversions (JSBSim's XML and properties are in English units unless an attribute says so) ---
FT_M = 0.3048
N_PER_LBF = 4.4482216152605
NM_PER_LBFFT = N_PER_LBF * FT_M
KGPM3_PER_SLUGPFT3 = 515.3788184
FTLBFPS_PER_HP = 550.0   # JSBSim's hptoftlbssec
W_PER_HP = 745.7         # JSBSim's hptowatts
EARTH_RADIUS_M = 6371000.0
LB_KG = 0.45359237
SLUG_KG = LB_KG * 32.174049  # JSBSim's slug: its pound mass times its standard gravity in ft/s^2
ORIGIN_ALTITUDE_M = 10.0
"""Altitude of a run's NED origin above the planet's surface (m): gravity there is the native plant's."""

#: our actuator command column -> the fcs/ property that receives it (surface slots without a surface: none)
ACTUATOR_PROPERTIES = {
    **{ACTUATORS.columns[i]: f"fcs/vtol/lift-{i + 1}-cmd-norm" for i in range(N_LIFT)},
    ACTUATORS.columns[MOTOR_PUSHER]: "fcs/vtol/pusher-cmd-norm",
    **{ACTUATORS.columns[N_MOTORS + j]: f"fcs/vtol/surface-{j + 1}-cmd-rad" for j in range(N_SURFACES)},
}
#: the lagged actuator outputs (the plant state's MOTOR and SERVO blocks), as fcs/ properties
OUTPUT_PROPERTIES = (*(f"fcs/vtol/lift-{i + 1}-speed-norm" for i in range(N_LIFT)), "fcs/vtol/pusher-speed-norm",
                     *(f"fcs/vtol/surface-{j + 1}-pos-rad" for j in range(N_SURFACES)))
SURFACE_LOSS_PROPERTY = "fcs/vtol/surface-{}-loss"


@dataclass(frozen=True)
class JSBSimAircraft:
    """A written aircraft: JSBSim's root folder, the model name and the actuator map it was written with."""

    root: Path
    name: str
    actuator_map: dict
    n_surfaces: int

    @property
    def xml_path(self) -> Path:
        """The aircraft's main XML file, ``ROOT/aircraft/NAME/NAME.xml`` (JSBSim's own folder layout)."""
        return self.root / "aircraft" / self.name / f"{self.name}.xml"


# --- function-building helpers ---------------------------------------------------------------------
def _num(x) -> str:
    return repr(float(x))


def _el(tag: str, *children, text: Optional[str] = None, **attrs) -> ET.Element:
    e = ET.Element(tag, {k: str(v) for k, v in attrs.items()})
    if text is not None:
        e.text = text
    for c in children:
        e.append(c)
    return e


def _v(x: float) -> ET.Element:
    return _el("value", text=_num(x))


def _p(name: str) -> ET.Element:
    return _el("property", text=name)


def _op(tag: str, *args) -> ET.Element:
    return _el(tag, *[a if isinstance(a, ET.Element) else _v(a) for a in args])


def _fn(name: str, body: ET.Element, description: str = "") -> ET.Element:
    f = _el("function", body, name=name)
    if description:
        f.insert(0, _el("description", text=description))
    return f


def _triplet(tag: str, xyz, unit: str = "M", **attrs) -> ET.Element:
    return _el(tag, *[_el(a, text=_num(float(v))) for a, v in zip("xyz", xyz)], unit=unit, **attrs)


# properties the aerodynamics' pre-functions define once per step (SI, after JSBSim's auxiliary model)
RHO = "aero/vtol/rho-kgpm3"
V = "aero/vtol/airspeed-mps"
Q = "aero/vtol/qbar-pa"
SIDE = "aero/vtol/rotor-side-force-n"
CL = "aero/vtol/CL"
CD = "aero/vtol/CD"


def aircraft_documents(vehicle: Vehicle, plant: Optional[P.PlantConfig] = None, name: Optional[str] = None
                       ) -> dict[str, str]:
    """The aircraft's files as ``{path relative to the root: text}`` (see the module docstring)."""
    plant = plant if plant is not None else P.PlantConfig()
    p = plant.to_kernel(vehicle)
    name = name or vehicle.name
    n_surf = len(vehicle.surfaces)
    m_ref = p[P.P_FORCE_MASS]
    T_lift_max_N = m_ref * p[P.P_THETA + P.forces.I_CTZ] / N_LIFT
    T_push_max_N = m_ref * p[P.P_THETA + P.forces.I_CTX]
    root = _el("fdm_config", name=name, version="2.0", release="BETA")
    root.append(_el("fileheader", _el("author", text="vtoladapt"),
                    _el("description", text=f"{vehicle.name} written by vtoladapt from its vehicle file and the "
                        "plant's parameters (vtoladapt.sim.jsbsim_aircraft)")))
    R = EARTH_RADIUS_M
    root.append(_el("planet", _el("semimajor_axis", text=_num(R), unit="M"),
                    _el("semiminor_axis", text=_num(R), unit="M"),
                    _el("rotation_rate", text="0.0", unit="RAD/SEC"),
                    _el("GM", text=_num(GRAVITY_MPS2 * (R + ORIGIN_ALTITUDE_M) ** 2 / FT_M**3), unit="FT3/SEC2"),
                    _el("J2", text="0.0"), name="vtoladapt flat-world match"))
    root.append(_el("metrics",
                    _el("wingarea", text=_num(p[P.P_S]), unit="M2"),
                    _el("wingspan", text=_num(p[P.P_SPAN]), unit="M"),
                    _el("chord", text=_num(p[P.P_CHORD]), unit="M"),
                    _triplet("location", (0, 0, 0), name="AERORP"),
                    _triplet("location", (0, 0, 0), name="EYEPOINT"),
                    _triplet("location", (0, 0, 0), name="VRP")))
    J = p[P.P_J:P.P_J + 9].reshape(3, 3)
    # JSBSim's <ixz> is the product of inertia that enters its matrix negated (J[0, 2] = -ixz), as ours.
    # Written in JSBSim's own units: its KG*M2 conversion constant has five digits (a 1e-4 error)
    k = 1.0 / (SLUG_KG * FT_M**2)
    root.append(_el("mass_balance",
                    _el("ixx", text=_num(J[0, 0] * k), unit="SLUG*FT2"),
                    _el("iyy", text=_num(J[1, 1] * k), unit="SLUG*FT2"),
                    _el("izz", text=_num(J[2, 2] * k), unit="SLUG*FT2"), _el("ixy", text="0.0", unit="SLUG*FT2"),
                    _el("ixz", text=_num(-J[0, 2] * k), unit="SLUG*FT2"), _el("iyz", text="0.0", unit="SLUG*FT2"),
                    _el("emptywt", text=_num(p[P.P_MASS] / LB_KG), unit="LBS"),
                    _triplet("location", (0, 0, 0), name="CG")))
    root.append(_ground_reactions(p))
    root.append(_propulsion(name, p))
    root.append(_flight_control(p, n_surf))
    root.append(_aerodynamics(p, n_surf))
    root.append(_external_reactions(p, T_push_max_N))
    ET.indent(root)
    docs = {f"aircraft/{name}/{name}.xml": '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"}
    for engine, T_max in (("lift_motor", T_lift_max_N), ("pusher_motor", T_push_max_N)):
        # an electric engine gives its thruster P (ft lbf/s) = P_W / W_PER_HP * FTLBFPS_PER_HP at full
        # throttle, which the direct thruster takes as thrust in lbf: size P_W for the rotor's full thrust
        watts = (T_max / N_PER_LBF) * W_PER_HP / FTLBFPS_PER_HP
        e = _el("electric_engine", _el("power", text=_num(watts), unit="WATTS"), name=f"{name}_{engine}")
        ET.indent(e)
        docs[f"engine/{name}_{engine}.xml"] = '<?xml version="1.0"?>\n' + ET.tostring(e, encoding="unicode") + "\n"
    docs["engine/direct.xml"] = '<?xml version="1.0"?>\n<direct name="Direct"/>\n'
    cols = [c for c in ACTUATORS.columns]
    lines = ["# our actuator command columns (vtoladapt.layout.ACTUATORS) -> the JSBSim fcs/ property each is",
             "# written to every control tick; units: rotor commands fractions of full throttle, surfaces rad",
             "[actuators]"]
    for i, c in enumerate(cols):
        if i >= N_MOTORS + n_surf:
            continue
        lines.append(f'{c} = "{ACTUATOR_PROPERTIES[c]}"')
    docs[f"aircraft/{name}/actuator_map.toml"] = "\n".join(lines) + "\n"
    return docs


#: how far below the centre of gravity the skids touch (m): the vehicle files give no landing gear, so a guess
SKID_DEPTH_M = 0.10


def _ground_reactions(p: np.ndarray) -> ET.Element:
    """Four skid contacts under the lift rotors' booms, SKID_DEPTH_M below the centre of gravity, sprung so
    the aircraft's weight compresses them by 1 cm, damped near critically: enough to sit on and lift off from
    the ground. A run starts airborne; the skids only matter if it reaches the ground."""
    g = _el("ground_reactions")
    weight_N = p[P.P_MASS] * GRAVITY_MPS2
    k = weight_N / N_LIFT / 0.01
    c = 2.0 * math.sqrt(k * p[P.P_MASS] / N_LIFT)
    for i in range(N_LIFT):
        g.append(_el("contact", _triplet("location", (-p[P.P_ROTOR_X + i], p[P.P_ROTOR_Y + i], -SKID_DEPTH_M)),
                     _el("static_friction", text="0.8"), _el("dynamic_friction", text="0.5"),
                     _el("spring_coeff", text=_num(k), unit="N/M"), _el("damping_coeff", text=_num(c), unit="N/M/SEC"),
                     type="STRUCTURE", name=f"skid {i + 1}"))
    return g


def _propulsion(name: str, p: np.ndarray) -> ET.Element:
    prop = _el("propulsion")
    for i in range(N_MOTORS):
        lift = i < N_LIFT
        # body FRD -> JSBSim structural (x aft, y right, z up), centre of gravity at the origin
        loc = (-p[P.P_ROTOR_X + i], p[P.P_ROTOR_Y + i], 0.0) if lift else (0.0, 0.0, 0.0)
        orient = _el("orient", _el("roll", text="0.0"), _el("pitch", text="90.0" if lift else "0.0"),
                     _el("yaw", text="0.0"), unit="DEG")
        thruster = _el("thruster", _triplet("location", loc), orient, file="direct")
        label = f"lift rotor {i + 1}" if lift else "pusher"
        prop.append(_el("engine", thruster, file=f"{name}_{'lift' if lift else 'pusher'}_motor", name=label))
    return prop


def _lag(name: str, input_prop: str, tau_s: float, on: bool) -> ET.Element:
    """A first-order lag as a JSBSim ``actuator`` (its first run, at ``run_ic``, starts it at its input, so a
    run can start from trimmed motors; a ``lag_filter`` would start from zero)."""
    e = _el("actuator", _el("input", text=input_prop), name=name)
    if on:
        e.append(_el("lag", text=_num(1.0 / tau_s)))
    return e


def _clip(name: str, input_prop: str, lo: float, hi: float) -> ET.Element:
    return _el("pure_gain", _el("input", text=input_prop), _el("gain", text="1.0"),
               _el("clipto", _el("min", text=_num(lo)), _el("max", text=_num(hi))), name=name)


def _flight_control(p: np.ndarray, n_surf: int) -> ET.Element:
    fc = _el("flight_control", name="vtoladapt actuators")
    # the inputs the engine writes every tick (declared, so they exist before the first write)
    for col in ACTUATORS.columns[:N_MOTORS + n_surf]:
        fc.append(_el("property", text=ACTUATOR_PROPERTIES[col], value="0.0"))
    for j in range(n_surf):
        fc.append(_el("property", text=SURFACE_LOSS_PROPERTY.format(j + 1), value="0.0"))
        fc.append(_el("property", text=f"fcs/vtol/surface-{j + 1}-lag-per-s", value=_num(1.0 / p[P.P_SURF_TAU + j])))
        fc.append(_el("property", text=f"fcs/vtol/surface-{j + 1}-rate-limit-radps", value=_num(p[P.P_SURF_RATE + j])))
    ch = _el("channel", name="rotors")
    fc.append(ch)
    lag_on = p[P.P_LAG_ON] > 0.0
    for i in range(N_MOTORS):
        lift = i < N_LIFT
        stem = f"fcs/vtol/lift-{i + 1}" if lift else "fcs/vtol/pusher"
        cmd = ACTUATOR_PROPERTIES[ACTUATORS.columns[i]]
        ch.append(_clip(f"{stem}-cmd-clipped", cmd, 0.0, 1.0))
        tau = p[P.P_TAU_LIFT] if lift else p[P.P_TAU_PUSH]
        ch.append(_lag(f"{stem}-speed-norm", f"{stem}-cmd-clipped", tau, lag_on))
        w = _p(f"{stem}-speed-norm")
        if lift:
            frac = _op("product", w, _p(f"{stem}-speed-norm"))
        else:
            # C_T(J)/C_T(0) = 1 + a1 J + a2 J^2, J = max(u, 0) / (n D) capped at the data's edge; 1 when off.
            # The flight control runs before JSBSim's auxiliary model: u is the previous step's (1 ms old)
            n_D = _op("product", w, p[P.P_PUSH_NMAX] * p[P.P_PUSH_D])
            u_mps = _op("max", _op("product", _p("velocities/u-aero-fps"), FT_M), 0.0)
            ch.append(_el("fcs_function", _el("function", _op("min", _op("quotient", u_mps, _op("max", n_D, 1e-12)),
                                                              P.PUSHER_J_MAX)), name=f"{stem}-advance-ratio"))
            J = _p(f"{stem}-advance-ratio")
            ratio = _op("sum", 1.0, _op("product", p[P.P_CT_A1], J), _op("product", p[P.P_CT_A2], J, J))
            if p[P.P_PUSH_J_ON] <= 0.0:
                ratio = _v(1.0)
            frac = _op("product", w, _p(f"{stem}-speed-norm"), ratio)
        ch.append(_el("fcs_function", _el("function", frac), _el("output", text=f"fcs/throttle-pos-norm[{i}]"),
                      name=f"{stem}-thrust-norm"))
    if n_surf:
        sch = _el("channel", name="control surfaces")
        fc.append(sch)
        for j in range(n_surf):
            stem = f"fcs/vtol/surface-{j + 1}"
            lim = p[P.P_SURF_LIMIT + j]
            sch.append(_clip(f"{stem}-cmd-clipped", ACTUATOR_PROPERTIES[ACTUATORS.columns[N_MOTORS + j]], -lim, lim))
            if p[P.P_SERVO_LAG_ON] > 0.0:
                # lag (1/s) and rate limit (rad/s) are properties: a servo_slow fault changes both
                act = _el("actuator", _el("input", text=f"{stem}-cmd-clipped"), _el("lag", text=f"{stem}-lag-per-s"),
                          name=f"{stem}-pos-rad")
                if p[P.P_SURF_RATE + j] < 1e6:
                    act.append(_el("rate_limit", text=f"{stem}-rate-limit-radps"))
                sch.append(act)
            else:
                sch.append(_el("pure_gain", _el("input", text=f"{stem}-cmd-clipped"), _el("gain", text="1.0"),
                               name=f"{stem}-pos-rad"))
            # a surface_lost fault's share, 0 healthy (set by the engine each tick)
            sch.append(_el("fcs_function", _el("function", _op("product", _p(f"{stem}-pos-rad"),
                                                                _op("difference", 1.0, _p(f"{stem}-loss")))),
                           name=f"{stem}-effective-rad"))
    return fc


def _stall_blend(a: ET.Element, p: np.ndarray) -> None:
    """Beard & McLain's sigmoid of |alpha| as :func:`vtoladapt.sim.plant.stall_blend` computes it (one exp):
    ``z = e^{-M |a|}``, ``s1 = 1/(1 + z C)``, ``s2 = z/(z + C)``, ``sigma = s1 + s2 - s1 s2``."""
    M = p[P.P_STALL_M]
    C = p[P.P_STALL_EXP]
    a.append(_fn("aero/vtol/stall-z", _op("exp", _op("product", -M, _op("min", _op("abs", _p("aero/alpha-rad")),
                                                                       math.pi)))))
    z = _p("aero/vtol/stall-z")
    a.append(_fn("aero/vtol/stall-s1", _op("quotient", 1.0, _op("sum", 1.0, _op("product", z, C)))))
    a.append(_fn("aero/vtol/stall-s2", _op("quotient", z, _op("sum", z, C))))
    s1, s2 = _p("aero/vtol/stall-s1"), _p("aero/vtol/stall-s2")
    a.append(_fn("aero/vtol/stall-blend", _op("difference", _op("sum", s1, s2), _op("product", s1, s2)),
                 "0 in attached flow, 1 past stall (Beard & McLain)"))


def _aerodynamics(p: np.ndarray, n_surf: int) -> ET.Element:
    a = _el("aerodynamics")
    alpha = "aero/alpha-rad"
    # SI quantities once per step, after JSBSim's auxiliary model has the flow of this step
    a.append(_fn(RHO, _op("product", _p("atmosphere/rho-slugs_ft3"), KGPM3_PER_SLUGPFT3), "air density, kg/m^3"))
    a.append(_fn(V, _op("product", _p("velocities/vt-fps"), FT_M), "airspeed, m/s"))
    a.append(_fn(Q, _op("product", 0.5, _p(RHO), _p(V), _p(V)), "dynamic pressure, Pa"))
    th = P.P_THETA
    CL_lin = _op("sum", p[th + P.forces.I_CL0], _op("product", p[th + P.forces.I_CL1], _p(alpha)))
    CD_lin = _op("abs", _op("sum", p[th + P.forces.I_CD0], _op("product", p[th + P.forces.I_CD1], _p(alpha)),
                            _op("product", p[th + P.forces.I_CD2], _p(alpha), _p(alpha))))
    if p[P.P_STALL_ON] > 0.0:
        _stall_blend(a, p)
    else:
        a.append(_fn("aero/vtol/stall-blend", _v(0.0), "stall off: attached-flow polars at every angle"))
    s = _p("aero/vtol/stall-blend")
    one_minus_s = _op("difference", 1.0, _p("aero/vtol/stall-blend"))
    CN = _op("product", 2.0, _op("sin", _p(alpha)))
    a.append(_fn(CL, _op("sum", _op("product", one_minus_s, CL_lin),
                         _op("product", s, CN, _op("cos", _p(alpha)))), "lift coefficient, -180..180 deg"))
    a.append(_fn(CD, _op("sum", _op("product", one_minus_s, CD_lin),
                         _op("product", s, _op("sum", p[th + P.forces.I_CD0],
                                                  _op("product", CN, _op("sin", _p(alpha)))))),
                 "drag coefficient, -180..180 deg"))
    # the rotors' side force: 0.25 m C_S G(alpha_disk, V, 1) sum_i w_i^k1, against the in-plane flow
    k1, k2 = p[P.P_K1], p[P.P_K2]
    u, v, w = (_op("product", _p(f"velocities/{c}-aero-fps"), FT_M) for c in "uvw")
    a.append(_fn("aero/vtol/inplane-speed-mps", _op("pow", _op("sum", _op("pow", u, 2.0), _op("pow", v, 2.0)), 0.5)))
    h = _p("aero/vtol/inplane-speed-mps")
    a.append(_fn("aero/vtol/disk-alpha-rad", _op("atan2", w, h)))
    a_disk = _p("aero/vtol/disk-alpha-rad")
    wsum = _op("sum", *[_op("pow", _op("max", _p(f"fcs/vtol/lift-{i + 1}-speed-norm"), 0.0), k1)
                        for i in range(N_LIFT)])
    G = _op("product", _op("pow", _p(V), 2.0 - k1), _op("difference", (math.pi / 2) ** 2, _op("pow", a_disk, 2.0)),
            _op("sum", a_disk, k2))
    a.append(_fn(SIDE, _op("product", 0.25 * p[P.P_FORCE_MASS] * p[th + P.forces.I_CS], G, wsum),
                 "rotor side force magnitude, N (against the in-plane flow)"))
    S, b, c = p[P.P_S], p[P.P_SPAN], p[P.P_CHORD]
    sa, ca = _op("sin", _p(alpha)), _op("cos", _p(alpha))

    def surf(k: int, moment: bool) -> list:
        out = []
        base = P.P_SURF_M if moment else P.P_SURF_F
        for j in range(n_surf):
            coef = p[base + 3 * j + k]
            if coef != 0.0:
                out.append(_op("product", _p(Q), coef, _p(f"fcs/vtol/surface-{j + 1}-effective-rad")))
        return out

    lbf = 1.0 / N_PER_LBF
    lbfft = 1.0 / NM_PER_LBFFT
    X = [_op("product", _p(Q), S, _op("difference", _op("product", _p(CL), sa), _op("product", _p(CD), ca))),
         _op("product", -1.0, _p(SIDE), _op("quotient", u, _op("max", h, 1e-9))), *surf(0, False)]
    Y = [_op("product", _p(Q), S, p[P.P_CY_BETA], _p("aero/beta-rad")),
         _op("product", -1.0, _p(SIDE), _op("quotient", v, _op("max", h, 1e-9))), *surf(1, False)]
    Z = [_op("product", _p(Q), S, -1.0, _op("sum", _op("product", _p(CL), _op("cos", _p(alpha))),
                                            _op("product", _p(CD), _op("sin", _p(alpha))))), *surf(2, False)]
    damp_on = p[P.P_DAMP_ON] > 0.0
    # L = 1/4 rho V S b^2 Clp p (smooth at V = 0), likewise pitch (chord) and yaw
    rates = (("p", b * b * p[P.P_CLP]), ("q", c * c * p[P.P_CMQ]), ("r", b * b * p[P.P_CNR]))
    moments = []
    for k, (rate, coef) in enumerate(rates):
        terms = surf(k, True)
        if damp_on:
            terms.append(_op("product", 0.25 * S * coef, _p(RHO), _p(V), _p(f"velocities/{rate}-rad_sec")))
        moments.append(terms)
    for axis, terms, conv, what in (("X", X, lbf, "wing, rotor side force, surfaces"),
                                    ("Y", Y, lbf, "side force C_Y(beta), rotor side force, surfaces"),
                                    ("Z", Z, lbf, "wing, surfaces"),
                                    ("ROLL", moments[0], lbfft, "surfaces, roll damping"),
                                    ("PITCH", moments[1], lbfft, "surfaces, pitch damping"),
                                    ("YAW", moments[2], lbfft, "surfaces, yaw damping")):
        ax = _el("axis", name=axis, frame="BODY")
        body = _op("sum", *terms, 0.0) if terms else _v(0.0)
        ax.append(_fn(f"aero/vtol/{axis.lower()}", _op("product", conv, body), f"{what} (lbf or lbf ft)"))
        a.append(ax)
    return a


def _external_reactions(p: np.ndarray, T_push_max_N: float) -> ET.Element:
    ext = _el("external_reactions")
    m_ref = p[P.P_FORCE_MASS]
    T_unit = m_ref * p[P.P_THETA + P.forces.I_CTZ] / N_LIFT
    # lift rotors' reaction torque about body z: -spin_i k_m T_i (N m), T_i = T_unit w_i^2
    terms = [_op("product", -p[P.P_ROTOR_SPIN + i] * p[P.P_KM] * T_unit / NM_PER_LBFFT,
                 _p(f"fcs/throttle-pos-norm[{i}]")) for i in range(N_LIFT)]
    ext.append(_el("moment", _el("function", _op("sum", *terms)),
                   _el("direction", _el("x", text="0"), _el("y", text="0"), _el("z", text="1")),
                   name="lift-rotor-reaction", frame="BODY"))
    # the pusher's drag torque rolls the airframe: -k_m T_pusher about body x
    ext.append(_el("moment", _el("function", _op("product", -p[P.P_KM_PUSHER] * T_push_max_N / NM_PER_LBFFT,
                                                 _p(f"fcs/throttle-pos-norm[{MOTOR_PUSHER}]"))),
                   _el("direction", _el("x", text="1"), _el("y", text="0"), _el("z", text="0")),
                   name="pusher-reaction", frame="BODY"))
    return ext


def write_aircraft(vehicle: Vehicle, out_dir, plant: Optional[P.PlantConfig] = None,
                   name: Optional[str] = None, write_text=None) -> JSBSimAircraft:
    """Write the aircraft's files under ``out_dir`` (JSBSim's root; see the module docstring).

    ``write_text(path, text)`` writes one file (default: create its folder and write it; the CLI passes
    :func:`vtoladapt.outputs.write_text`, which writes atomically into a claimed output folder)."""
    root = Path(out_dir)
    name = name or vehicle.name
    docs = aircraft_documents(vehicle, plant, name)
    for rel, text in docs.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        if write_text is None:
            path.write_text(text, encoding="utf-8")
        else:
            write_text(path, text)
    amap = {c: ACTUATOR_PROPERTIES[c] for c in ACTUATORS.columns[:N_MOTORS + len(vehicle.surfaces)]}
    return JSBSimAircraft(root=root, name=name, actuator_map=amap, n_surfaces=len(vehicle.surfaces))


def read_actuator_map(path) -> dict:
    """An actuator map file (``[actuators] column = "fcs/property"``), checked: every actuator of the
    aircraft named, every name a known column, every value an fcs/ property."""
    import tomllib

    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read the actuator map: {exc}") from None
    table = data.get("actuators")
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: [actuators]: missing; allowed: a table of actuator column = \"fcs/...\"")
    for key, value in table.items():
        if key not in ACTUATORS.columns:
            raise ConfigError(f"{path}: [actuators] {key}: not an actuator column; allowed: "
                              f"{', '.join(ACTUATORS.columns)}")
        if not isinstance(value, str) or not value.startswith("fcs/"):
            raise ConfigError(f"{path}: [actuators] {key} = {value!r}: allowed: a JSBSim property under fcs/")
    return dict(table)


def check_actuator_map(amap: dict, n_surfaces: int, where: str) -> None:
    """Every actuator the vehicle has (five rotors, its surfaces) mapped: else one line naming the first missing."""
    for col in ACTUATORS.columns[:N_MOTORS + n_surfaces]:
        if col not in amap:
            raise ConfigError(f"{where}: [actuators] {col}: missing; every actuator of the vehicle needs an fcs/ "
                              f"property (e.g. {col} = \"{ACTUATOR_PROPERTIES[col]}\")")
