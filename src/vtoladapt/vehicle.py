"""Vehicle configuration: what an aircraft is, as the controller and the plant start from it.

A vehicle file (TOML) describes one aircraft: mass properties, geometry, the force-model
coefficients in the paper's Table I units (throttle in percent, forces normalised by mass), their
standard deviations, the initial adaptation gains (Table III), actuator and flight-envelope limits.
Two ship with the package: ``caltech_vtol`` (the paper's aircraft) and ``px4_standard_vtol``
(PX4's Gazebo standard VTOL, converted). Load either, or your own file, with
:func:`load_vehicle`.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
import functools
from functools import cached_property
from pathlib import Path

import numpy as np

from .config import ConfigError, Validated, build, read_toml, refuse_internal_keys, setting
from typing import Any, Mapping
from .scaling import model_kernel_params, theta_to_scaled

VEHICLE_DIR = Path(__file__).with_name("vehicles")
PARAMETER_NAMES = ("CTx", "CTz", "CS", "CD0", "CD1", "CD2", "CL0", "CL1")
"""The adapted parameters theta, in the paper's order."""


@dataclass(frozen=True)
class MassProperties(Validated):
    """Mass and inertia about the centre of mass, body FRD axes."""

    config_section = "mass"

    mass_kg: float = setting("kg", "take-off mass (small UAS: <= 150 kg)", ge=0.1, le=150.0)
    inertia_kgm2: tuple[float, ...] = setting(
        "kg m^2", "principal moments of inertia Ixx, Iyy, Izz", ge=1e-5, le=500.0, length=3)
    product_of_inertia_xz_kgm2: float = setting("kg m^2", "product of inertia Ixz", default=0.0, ge=-500.0, le=500.0)

    def _check(self, source: str) -> None:
        ixx, iyy, izz = self.inertia_kgm2
        # A physical body satisfies the triangle inequalities on its principal moments.
        if ixx + iyy < izz or iyy + izz < ixx or ixx + izz < iyy:
            raise ConfigError(
                f"{source}: [mass] inertia_kgm2 = {list(self.inertia_kgm2)}: violates the triangle "
                "inequality of principal moments (each must be <= the sum of the other two)")

    @property
    def inertia_matrix(self) -> np.ndarray:
        """Inertia matrix about the centre of mass, body FRD (kg m^2), with the xz product."""
        ixx, iyy, izz = self.inertia_kgm2
        ixz = self.product_of_inertia_xz_kgm2
        return np.array([[ixx, 0.0, -ixz], [0.0, iyy, 0.0], [-ixz, 0.0, izz]])


@dataclass(frozen=True)
class Geometry(Validated):
    """Where things are on the airframe (body FRD, metres from the centre of mass)."""

    config_section = "geometry"

    wing_area_m2: float = setting("m^2", "reference wing area S_ref", ge=0.01, le=50.0)
    wingspan_m: float = setting("m", "wingspan", ge=0.1, le=40.0)
    lift_rotor_positions_m: tuple[tuple[float, ...], ...] = setting(
        "m", "body x, y of the four lift rotors (front-right, rear-left, front-left, rear-right)",
        ge=-10.0, le=10.0, length=4)
    lift_rotor_spin: tuple[int, ...] = setting(
        "-", "+1 if the rotor turns clockwise seen from above (yaw reaction torque -z), else -1",
        length=4, choices=None)
    lift_prop_diameter_m: float = setting("m", "lift propeller diameter", ge=0.025, le=3.0)
    pusher_prop_diameter_m: float = setting("m", "pusher propeller diameter", ge=0.025, le=3.0)
    pusher_prop_pitch_m: float = setting("m", "pusher propeller geometric pitch", ge=0.01, le=3.0)

    def _check(self, source: str) -> None:
        for i, pos in enumerate(self.lift_rotor_positions_m):
            if len(pos) != 2:
                raise ConfigError(
                    f"{source}: [geometry] lift_rotor_positions_m[{i}] = {list(pos)}: must be [x, y]")
        for i, s in enumerate(self.lift_rotor_spin):
            if s not in (-1, 1):
                raise ConfigError(
                    f"{source}: [geometry] lift_rotor_spin[{i}] = {s}: must be +1 or -1")
        if sum(self.lift_rotor_spin) != 0:
            raise ConfigError(
                f"{source}: [geometry] lift_rotor_spin = {list(self.lift_rotor_spin)}: two rotors must "
                "turn each way, or hover needs a constant yaw torque")


@dataclass(frozen=True)
class ForceModelCoefficients(Validated):
    """The paper's force model (Table I units): throttle in percent, forces per unit mass.

    ``T_x = CTx u_x^2``, ``T_z = CTz u_z^2`` (m/s^2, u in %), ``F_S = CS G(alpha, V, u_z)``
    with ``G = u_z^k1 V^(2-k1) ((pi/2)^2 - alpha^2)(alpha + k2)``, wing
    ``CL = CL0 + CL1 alpha``, ``CD = CD0 + CD1 alpha + CD2 alpha^2`` (alpha in rad).
    """

    config_section = "force_model"

    CTx: float = setting("m/s^2 per %^2", "pusher thrust coefficient (0.01: 10 g at full throttle)", gt=0.0, le=0.01)
    CTz: float = setting("m/s^2 per %^2", "total lift-rotor thrust coefficient (0.01: 10 g at full throttle)", gt=0.0, le=0.01)
    CS: float = setting("m/s^2 per (%^k1 (m/s)^(2-k1))", "rotor side-force coefficient", ge=0.0, le=0.01)
    k1: float = setting("-", "side-force exponent on rotor speed (eq:model_Fs)", gt=0.0, lt=2.0)
    k2: float = setting("rad", "side-force asymmetry offset (eq:model_Fs)", gt=math.pi / 2, le=100.0)
    CD0: float = setting("-", "zero-alpha drag coefficient", ge=0.0, le=2.0)
    CD1: float = setting("1/rad", "linear drag coefficient", ge=-10.0, le=10.0)
    CD2: float = setting("1/rad^2", "quadratic drag coefficient", ge=0.0, le=20.0)
    CL0: float = setting("-", "zero-alpha lift coefficient", ge=-3.0, le=3.0)
    CL1: float = setting("1/rad", "lift-curve slope (thin airfoil: 2 pi)", gt=0.0, le=10.0)

    def as_table_theta(self) -> np.ndarray:
        """theta in the paper's order and Table I units (throttle in percent)."""
        return np.array([getattr(self, n) for n in PARAMETER_NAMES])


def parameter_signs() -> np.ndarray:
    """The sign physics gives each adapted parameter (:data:`PARAMETER_NAMES` order): +1 never negative,
    -1 never positive, 0 either.

    Read from the ranges :class:`ForceModelCoefficients` declares (a lower limit ``gt`` or ``ge`` of
    0 or more: +1; an upper limit ``lt`` or ``le`` of 0 or less: -1), the one place they are
    stated: thrust along the rotor axis (C_Tx, C_Tz > 0), the rotor's in-plane force against the
    flow (C_S >= 0), drag at zero alpha and its quadratic growth (C_D0, C_D2 >= 0), a positive lift
    slope (C_L1 > 0); the linear drag term and the zero-alpha lift have either sign. The adaptation
    scaling multiplies by positive factors only, so the signs hold for theta-hat too.
    """
    fields = {f.name: f.metadata for f in dataclasses.fields(ForceModelCoefficients)}
    signs = []
    for name in PARAMETER_NAMES:
        m = fields[name]
        low = m["gt"] if m["gt"] is not None else m["ge"]
        high = m["lt"] if m["lt"] is not None else m["le"]
        signs.append(1 if low is not None and low >= 0.0 else -1 if high is not None and high <= 0.0 else 0)
    return np.array(signs)


@dataclass(frozen=True)
class ForceModelStd(Validated):
    """Posterior standard deviations of the force model (Table I), same units as the means."""

    config_section = "force_model_std"

    CTx: float = setting("m/s^2 per %^2", "std of CTx", gt=0.0, le=0.01)
    CTz: float = setting("m/s^2 per %^2", "std of CTz", gt=0.0, le=0.01)
    CS: float = setting("m/s^2 per (%^k1 (m/s)^(2-k1))", "std of CS", gt=0.0, le=0.01)
    k1: float = setting("-", "std of k1", ge=0.0, le=2.0)
    k2: float = setting("rad", "std of k2", ge=0.0, le=100.0)
    CD0: float = setting("-", "std of CD0", gt=0.0, le=2.0)
    CD1: float = setting("1/rad", "std of CD1", gt=0.0, le=10.0)
    CD2: float = setting("1/rad^2", "std of CD2", gt=0.0, le=20.0)
    CL0: float = setting("-", "std of CL0", gt=0.0, le=3.0)
    CL1: float = setting("1/rad", "std of CL1", gt=0.0, le=10.0)

    def as_table_theta(self) -> np.ndarray:
        """Standard deviations in the paper's order and Table I units (throttle in percent)."""
        return np.array([getattr(self, n) for n in PARAMETER_NAMES])


@dataclass(frozen=True)
class Adaptation(Validated):
    """Initial adaptation gains (Table III): the diagonal of P0 in the adaptation scaling."""

    config_section = "adaptation"

    P0_diag: tuple[float, ...] = setting(
        "adaptation units (see vtoladapt.models.scaling)",
        "diagonal of P0 for CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1", gt=0.0, le=1e6, length=8)
    bound_fraction: tuple[float, ...] = setting(
        "-", "theta-hat may move this fraction of |theta_0| either side (per parameter)",
        gt=0.0, le=10.0, length=8)
    bound_sigmas: float = setting(
        "-", "...and at least this many Table I standard deviations either side", ge=0.0, le=100.0)


@dataclass(frozen=True)
class Actuators(Validated):
    """Motor dynamics and limits."""

    config_section = "actuators"

    throttle_max_pct: float = setting("%", "maximum throttle of every motor", gt=0.0, le=100.0)
    lift_motor_time_constant_s: float = setting("s", "first-order lag of a lift motor", ge=0.001, le=1.0)
    pusher_motor_time_constant_s: float = setting("s", "first-order lag of the pusher", ge=0.001, le=1.0)
    yaw_torque_per_thrust_m: float = setting(
        "m", "lift-rotor reaction torque per unit thrust (Nm/N)", ge=0.001, le=1.0)


SURFACE_DERIVATIVE_NAMES = ("CX", "CY", "CZ", "Cl", "Cm", "Cn")
"""The six derivatives of a control surface, per radian of deflection: body FRD force coefficients
(``F = q S C``) and moment coefficients (roll and yaw ``M = q S b C``, pitch ``M = q S c C``, ``c = S / b``)."""


@dataclass(frozen=True)
class Surface(Validated):
    """One control surface (a ``[[surfaces]]`` entry): what a radian of it does and how its servo moves.

    Its force and moment are ``q S C delta`` (moments times ``b`` or ``c``) with ``q = rho V^2 / 2`` of the
    incident flow: linear in deflection and in dynamic pressure (:mod:`vtoladapt.sim.surfaces`).
    Positive deflection is the servo's positive direction; the derivatives' signs say what it does.
    """

    config_section = "surfaces"

    name: str = setting("-", "what the surface is (aileron, elevator, rudder, ruddervator_left, ...)",
                        pattern=r"[A-Za-z][A-Za-z0-9_]{0,31}")
    derivatives_per_rad: tuple[float, ...] = setting(
        "1/rad", "CX, CY, CZ, Cl, Cm, Cn per radian (body FRD; moments about the centre of mass)",
        ge=-20.0, le=20.0, length=6)
    limit_deg: float = setting("deg", "deflection limit either way", gt=0.0, le=60.0)
    time_constant_s: float = setting("s", "servo first-order lag", ge=0.001, le=1.0)
    rate_limit_degps: float = setting("deg/s", "servo slew-rate limit", gt=0.0, le=5000.0)

    @property
    def derivatives(self) -> dict[str, float]:
        """The derivatives by name (:data:`SURFACE_DERIVATIVE_NAMES`)."""
        return dict(zip(SURFACE_DERIVATIVE_NAMES, self.derivatives_per_rad))


@dataclass(frozen=True)
class Uncertainty(Validated):
    """How well the vehicle file knows what Table I does not give: the spread a plant draw uses
    (:func:`vtoladapt.sim.truth.draw_physical_parameters`). Each is one standard deviation; the
    controller always keeps the file's own values. A file without the table states no spread (every
    std 0): its drawn plant is the file's."""

    config_section = "uncertainty"

    stall_angle_deg: float = setting("deg", "std of the stall angle", default=0.0, ge=0.0, le=10.0)
    lift_motor_time_constant_frac: float = setting("-", "relative std of the lift motors' lag", default=0.0, ge=0.0, le=0.5)
    pusher_motor_time_constant_frac: float = setting("-", "relative std of the pusher's lag", default=0.0, ge=0.0, le=0.5)
    servo_time_constant_frac: float = setting("-", "relative std of the servos' lag", default=0.0, ge=0.0, le=0.5)
    mass_frac: float = setting("-", "relative std of the mass", default=0.0, ge=0.0, le=0.3)
    inertia_frac: float = setting("-", "relative std of each principal inertia", default=0.0, ge=0.0, le=0.5)
    air_density_frac: float = setting("-", "relative std of the air density", default=0.0, ge=0.0, le=0.3)
    surface_effectiveness_frac: float = setting("-", "relative std of each surface's effectiveness", default=0.0, ge=0.0,
                                                le=0.5)


@dataclass(frozen=True)
class Envelope(Validated):
    """Flight-envelope limits the controller respects."""

    config_section = "envelope"

    alpha_max_deg: float = setting("deg", "largest desired angle of attack (eq:alphad)", gt=0.0, le=45.0)
    hover_blend_airspeed_mps: tuple[float, ...] = setting(
        "m/s", "below the first airspeed the desired attitude is the multirotor solution, above the "
        "second the incident-wind solution; smooth blend between", ge=0.0, le=100.0, length=2)
    air_density_kgpm3: float = setting("kg/m^3", "air density the coefficients refer to", ge=0.3, le=2.0)
    stall_angle_deg: float = setting(
        "deg", "angle of attack at which the wing is believed to stall (the controller's belief, not the "
        "plant's truth)", gt=0.0, le=60.0)
    stall_margin_deg: float = setting(
        "deg", "margin kept below stall_angle_deg: the measured angle of attack is held below "
        "stall_angle_deg - stall_margin_deg", ge=0.0, le=30.0)

    @property
    def alpha_protect_deg(self) -> float:
        """The protected angle of attack ``stall_angle_deg - stall_margin_deg`` (deg)."""
        return self.stall_angle_deg - self.stall_margin_deg

    def _check(self, source: str) -> None:
        if not self.alpha_max_deg <= self.alpha_protect_deg:
            raise ConfigError(
                f"{source}: [envelope] alpha_max_deg = {self.alpha_max_deg}: must not exceed "
                f"stall_angle_deg - stall_margin_deg = {self.alpha_protect_deg:g}")
        lo, hi = self.hover_blend_airspeed_mps
        if not lo < hi:
            raise ConfigError(
                f"{source}: [envelope] hover_blend_airspeed_mps = {list(self.hover_blend_airspeed_mps)}: "
                "the first must be below the second")


@dataclass(frozen=True)
class Vehicle(Validated):
    """A validated vehicle configuration (see the module docstring)."""

    name: str = setting("-", "short identifier")
    description: str = setting("-", "one line on where the numbers come from")
    mass: MassProperties = setting("-", "mass properties")
    geometry: Geometry = setting("-", "geometry")
    force_model: ForceModelCoefficients = setting("-", "force-model means (Table I units)")
    force_model_std: ForceModelStd = setting("-", "force-model standard deviations (Table I units)")
    adaptation: Adaptation = setting("-", "adaptation prior (Table III)")
    actuators: Actuators = setting("-", "actuators")
    envelope: Envelope = setting("-", "flight envelope")
    uncertainty: Uncertainty = setting("-", "spread of the physical parameters a plant draw uses",
                                       default=Uncertainty())
    surfaces: tuple[Surface, ...] = setting(
        "-", "control surfaces ([[surfaces]] entries, at most vtoladapt.layout.N_SURFACES)", default=(),
        max_items=4)
    basis: str = setting("-", "the force-model basis the controller adapts (an id of vtoladapt.bases: 'paper' is the "
                         "paper's eight parameters; a scenario's [controller] basis may name another)",
                         default="paper", pattern=r"[A-Za-z_][A-Za-z0-9_]{0,63}")
    basis_settings: Any = setting(
        "-", "[basis_settings.<id>] tables: each basis's own settings (e.g. the prior of its extra columns), read "
        "when that basis flies", default=())
    effectiveness: str = setting(
        "-", "the flight computer's effectiveness for the allocator (an id of the 'effectiveness' kind, "
        "vtoladapt.sim.allocation; a scenario's [allocation] effectiveness may name another): "
        "'lift_rotors_surfaces' believes this file's geometry, 'px4_ca' PX4's CA_* parameters",
        default="lift_rotors_surfaces", pattern=r"[A-Za-z_][A-Za-z0-9_]{0,63}")
    effectiveness_settings: Any = setting(
        "-", "[effectiveness_settings.<id>] tables: each effectiveness's own settings (e.g. PX4's CA_* airframe "
        "parameters for 'px4_ca'), read when that effectiveness allocates", default=())
    source_path: str = setting("-", "file the vehicle was read from", default="")

    def __post_init__(self) -> None:
        object.__setattr__(self, "basis_settings", _frozen_tables(self.basis_settings, self.source_path))
        object.__setattr__(self, "effectiveness_settings",
                           _frozen_tables(self.effectiveness_settings, self.source_path, "effectiveness_settings"))
        super().__post_init__()

    @cached_property
    def aero_scale_per_m(self) -> float:
        """``rho S_ref / (2 m)`` (1/m): dynamic pressure times area, per mass, per V^2."""
        return 0.5 * self.envelope.air_density_kgpm3 * self.geometry.wing_area_m2 / self.mass.mass_kg

    @cached_property
    def model_kernel(self) -> np.ndarray:
        """Kernel parameters of the force model (see :mod:`vtoladapt.forces`)."""
        return _read_only(model_kernel_params(self.aero_scale_per_m, self.force_model.k1, self.force_model.k2,
                                              self.envelope.stall_angle_deg))

    @cached_property
    def theta_scaled(self) -> np.ndarray:
        """theta_0 in the adaptation scaling (see :func:`vtoladapt.scaling.theta_to_scaled`)."""
        return _read_only(theta_to_scaled(self.force_model.as_table_theta(), self.force_model.k1))

    @cached_property
    def theta_std_scaled(self) -> np.ndarray:
        """The coefficients' standard deviations in the adaptation scaling."""
        return _read_only(theta_to_scaled(self.force_model_std.as_table_theta(), self.force_model.k1))

    def basis_table(self, basis_id: str) -> dict | None:
        """The vehicle file's ``[basis_settings.<basis_id>]`` table (a dict), or None if it has none."""
        for key, table in self.basis_settings:
            if key == basis_id:
                return _thawed(table)
        return None

    def effectiveness_table(self, effectiveness_id: str) -> dict | None:
        """The vehicle file's ``[effectiveness_settings.<effectiveness_id>]`` table (a dict), or None."""
        for key, table in self.effectiveness_settings:
            if key == effectiveness_id:
                return _thawed(table)
        return None

    def _check(self, source: str) -> None:
        names = [sf.name for sf in self.surfaces]
        for i, n in enumerate(names):
            if n in names[:i]:
                raise ConfigError(f"{source}: [[surfaces]][{i}] name = {n!r}: used twice; allowed: one entry per surface")
        # the mixer inverts this matrix every tick; a layout it cannot invert is the file's mistake
        cond = np.linalg.cond(lift_allocation_matrix(self.geometry, self.actuators.yaw_torque_per_thrust_m))
        if not cond < LIFT_ALLOCATION_COND_MAX:
            positions = [list(p) for p in self.geometry.lift_rotor_positions_m]
            raise ConfigError(
                f"{source}: [geometry] lift_rotor_positions_m = {positions}, lift_rotor_spin = {list(self.geometry.lift_rotor_spin)}: the four lift rotors cannot produce "
                f"independent thrust, roll, pitch and yaw moments (allocation condition number {cond:.3g}); "
                "allowed: rotors on both sides of both body axes, two spinning each way")

    @cached_property
    def wing_chord_m(self) -> float:
        """Mean aerodynamic chord ``S / b`` (m): the pitch moment's reference length."""
        return self.geometry.wing_area_m2 / self.geometry.wingspan_m

    def replace(self, **changes) -> "Vehicle":
        """A copy with some top-level sections replaced (validated sections, not dicts)."""
        return dataclasses.replace(self, **changes)


def _frozen(value: Any) -> Any:
    """A TOML value made hashable (tables and arrays to tuples), so a vehicle stays hashable."""
    if isinstance(value, Mapping):
        return tuple((str(k), _frozen(v)) for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return tuple(_frozen(v) for v in value)
    return value


def _thawed(value: Any) -> Any:
    """The inverse of :func:`_frozen` for one table: ``((key, value), ...)`` back to a dict."""
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in value}


def _frozen_tables(tables: Any, source: str, section: str = "basis_settings") -> tuple:
    """``[<section>.<id>]`` tables as ``((id, ((key, value), ...)), ...)``; a ConfigError if not tables."""
    if isinstance(tables, tuple) and all(isinstance(t, tuple) and len(t) == 2 for t in tables):
        return tables   # already frozen (a copy of a vehicle)
    if not isinstance(tables, Mapping) or not all(isinstance(t, Mapping) for t in tables.values()):
        raise ConfigError(f"{source or 'Vehicle'}: {section} = {tables!r:.60}: must be tables "
                          f"[{section}.<id>]")
    return tuple((str(k), _frozen(v)) for k, v in tables.items())
LIFT_ALLOCATION_COND_MAX = 1e6
"""Largest condition number of the lift rotors' allocation matrix a vehicle may have: the mixer
solves it every tick, and beyond this a rounding error in a command becomes a motor's full range."""


def lift_allocation_matrix(geometry: Geometry, yaw_torque_per_thrust_m: float) -> np.ndarray:
    """``A`` with ``[T, tau_x, tau_y, tau_z] = A [T_1 .. T_4]``: collective thrust and body moments
    of the four lift-rotor thrusts (body FRD; rotor i at ``(x_i, y_i)``, spin ``s_i``)."""
    A = np.zeros((4, 4))
    for i, (x, y) in enumerate(geometry.lift_rotor_positions_m):
        A[0, i] = 1.0
        A[1, i] = -y
        A[2, i] = x
        A[3, i] = -geometry.lift_rotor_spin[i] * yaw_torque_per_thrust_m
    return A


def _read_only(a: np.ndarray) -> np.ndarray:
    """A frozen vehicle hands out arrays that cannot be changed in place by mistake."""
    a.setflags(write=False)
    return a


def available_vehicles() -> list[str]:
    """Names of the vehicles shipped with the package."""
    return sorted(p.stem for p in VEHICLE_DIR.glob("*.toml"))


def vehicle_from_mapping(data: dict, source: str) -> Vehicle:
    """Build a :class:`Vehicle` from a parsed TOML mapping, naming ``source`` in errors."""
    data = dict(data)
    data.setdefault("source_path", source)
    return build(Vehicle, data, source=source)


def load_vehicle(name_or_path: str | Path) -> Vehicle:
    """Load and validate a vehicle by shipped name (``caltech_vtol``, ``px4_standard_vtol``) or path.

    Raises
    ------
    ConfigError
        If the name is unknown, the file is missing or invalid; the message names the file, the key,
        the value and what is allowed.
    """
    text = str(name_or_path)
    path = Path(text)
    # is_file, not exists: a folder named like a shipped vehicle (e.g. an output folder) is no config.
    if not (path.suffix == ".toml" or path.is_file()):
        path = VEHICLE_DIR / f"{text}.toml"
        if not path.exists():
            raise ConfigError(
                f"vehicle {text!r}: unknown name; shipped vehicles: {', '.join(available_vehicles())}, "
                "or give a path to a .toml file")
    try:
        stat = path.stat()
    except OSError:
        return vehicle_from_mapping(read_toml(path), str(path))  # read_toml names the missing file
    return _load_vehicle_file(str(path), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=32)
def _load_vehicle_file(path: str, mtime_ns: int, size: int) -> Vehicle:
    """Parse and validate a vehicle file once per version of it (keyed by time and size).

    Vehicles are frozen with read-only arrays, so one object can serve every run of a campaign;
    parsing the TOML took as long as a second of simulated flight.
    """
    data = read_toml(Path(path))
    from .file_kinds import check_file_kind

    check_file_kind(path, data, "vehicle", "--vehicle (and `vehicle show`, a scenario's `vehicle =`)")
    refuse_internal_keys(data, path)
    return vehicle_from_mapping(data, path)
