"""Layouts of the flat arrays the compiled kernels exchange, and the one way to declare them.

The simulator, the sensors and the controller meet in four small float64 arrays: the plant
state, the measurement, the reference and the command. Each is declared here once as a
:class:`BlockLayout` (:data:`STATE`, :data:`MEASUREMENT`, :data:`REFERENCE`, :data:`COMMAND`);
the index constants (``X_*``, ``MEAS_*``, ``REF_*``, ``CMD_*``) and the ``*_COLUMNS`` tuples that
name every slot, with its unit, in the logs are derived from those declarations.

Every other flat array of a kernel (a component's parameters, state, scratch and diagnostics) is
declared with :class:`BlockLayout`: named fields with sizes and units, in order. Offsets are
derived from the declaration, never typed, and a diagnostics block's column names come from the
same declaration. Numba freezes module-level integers into the compiled code, so a module binds
the offsets it uses once, at import::

    PARAMS = BlockLayout("plant parameters", [
        Field("MASS", 1, "kg", "vehicle mass"),
        Field("J", 9, "kg m^2", "inertia, row-major"),
    ])
    P_MASS, P_J = PARAMS.offsets("MASS", "J")
    P_SIZE = PARAMS.size

Frames: world NED, body FRD (see :mod:`vtoladapt.frames`). Quaternions scalar first.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Optional

import numpy as np


@dataclass(frozen=True)
class Field:
    """One named field of a flat array: ``size`` float64 slots, their unit and meaning.

    ``columns`` names each slot (units in the names) where the block is logged; by default
    ``name.lower()`` for a scalar and ``name.lower()_0 .. _{size-1}`` otherwise.
    """

    name: str
    size: int
    unit: str = "-"
    doc: str = ""
    columns: Optional[tuple[str, ...]] = None

    def __post_init__(self):
        if not self.name.isidentifier() or self.size < 0:
            raise ValueError(f"field {self.name!r}: a Python identifier and a size >= 0 are required")
        if self.columns is not None and len(self.columns) != self.size:
            raise ValueError(f"field {self.name!r}: {len(self.columns)} column names for size {self.size}")

    @property
    def column_names(self) -> tuple[str, ...]:
        """One name per slot of this field (``columns``, or derived from the field's name)."""
        if self.columns is not None:
            return tuple(self.columns)
        base = self.name.lower()
        return (base,) if self.size == 1 else tuple(f"{base}_{i}" for i in range(self.size))


class BlockLayout:
    """Named fields laid out one after another in a flat float64 array.

    Offsets follow from the order and sizes of the fields; :meth:`offset`/:meth:`offsets` give
    them, :meth:`view` names a slice of an array, :attr:`columns` names every slot.
    A field may nest another layout (``Field`` of size ``sub.size``): :meth:`nested` gives the
    absolute offsets of the sub-layout's fields inside this one.
    """

    def __init__(self, title: str, fields: Iterable[Field]):
        self.title = title
        self.fields: tuple[Field, ...] = tuple(fields)
        self._offset: dict[str, int] = {}
        self._field: dict[str, Field] = {}
        n = 0
        for f in self.fields:
            if f.name in self._offset:
                raise ValueError(f"{title}: field {f.name!r} declared twice")
            self._offset[f.name] = n
            self._field[f.name] = f
            n += f.size
        self.size: int = n

    def __contains__(self, name: str) -> bool:
        return name in self._offset

    def field(self, name: str) -> Field:
        """The declaration of field ``name``."""
        try:
            return self._field[name]
        except KeyError:
            pass
        raise KeyError(f"{self.title}: no field {name!r}; fields: {', '.join(self._offset)}")

    def offset(self, name: str) -> int:
        """First slot of field ``name``."""
        try:
            return self._offset[name]
        except KeyError:
            raise KeyError(f"{self.title}: no field {name!r}; fields: {', '.join(self._offset)}") from None

    def offsets(self, *names: str) -> tuple[int, ...]:
        """First slots of several fields, in the order asked (for binding module constants)."""
        return tuple(self.offset(n) for n in names)

    def nested(self, name: str, sub: "BlockLayout", *sub_names: str) -> tuple[int, ...]:
        """Absolute offsets of ``sub``'s fields, ``sub`` being laid out in field ``name``."""
        f = self.field(name)
        if f.size != sub.size:
            raise ValueError(f"{self.title}: field {name!r} has size {f.size}, {sub.title} needs {sub.size}")
        base = self.offset(name)
        return tuple(base + sub.offset(n) for n in sub_names)

    def slice(self, name: str) -> slice:
        """The slots of field ``name`` as a slice of the flat array."""
        o = self.offset(name)
        return slice(o, o + self.field(name).size)

    def view(self, array: np.ndarray, name: str) -> np.ndarray:
        """The slots of field ``name`` in ``array`` (last axis), as a view."""
        return array[..., self.slice(name)]

    @property
    def columns(self) -> tuple[str, ...]:
        """One name per slot, in order (units in the names)."""
        return tuple(c for f in self.fields for c in f.column_names)

    def describe(self) -> list[tuple[str, int, int, str, str]]:
        """``(name, offset, size, unit, doc)`` per field, for documentation and tests."""
        return [(f.name, self._offset[f.name], f.size, f.unit, f.doc) for f in self.fields]

    def bounds(self) -> np.ndarray:
        """The first slot of every field, in order, then :attr:`size` (int64, ``len(fields) + 1``):
        field ``i`` spans ``bounds[i]:bounds[i + 1]``, for a kernel whose layout is known only at run
        time (sizes chosen per run) while the order of its fields is fixed."""
        return np.array([self._offset[f.name] for f in self.fields] + [self.size], dtype=np.int64)

    def pack(self, **values) -> np.ndarray:
        """A zero array of :attr:`size` with the named fields filled (scalars or sequences)."""
        out = np.zeros(self.size)
        for name, value in values.items():
            out[self.slice(name)] = value
        return out

    def __repr__(self) -> str:
        return f"BlockLayout({self.title!r}, {len(self.fields)} fields, size {self.size})"

# --- plant state x ---------------------------------------------------------------------------
N_SURFACES = 4
"""Control-surface slots of the airframe (ailerons, elevator, rudder, ruddervators, elevons: the vehicle
file's ``[[surfaces]]`` fill them in order; an unused slot has no effect and is never commanded)."""

ACTUATORS = BlockLayout("actuator commands", [
    Field("LIFT", 4, "-", "the four lift rotors' throttles, fractions (rotor order of the vehicle file)",
          columns=("motor1_cmd_frac", "motor2_cmd_frac", "motor3_cmd_frac", "motor4_cmd_frac")),
    Field("PUSHER", 1, "-", "the pusher's throttle, fraction", columns=("pusher_cmd_frac",)),
    Field("SURFACE", N_SURFACES, "rad", "control-surface deflection commands (surface order of the vehicle file)",
          columns=tuple(f"surface{i + 1}_cmd_rad" for i in range(N_SURFACES))),
])
"""What the allocator writes and the plant's actuators follow (after the actuator faults): the actuator
command vector. The plant state's ``MOTOR`` and ``SERVO`` blocks hold the same actuators' outputs after
their lags."""
N_LIFT = ACTUATORS.field("LIFT").size
N_MOTORS = N_LIFT + ACTUATORS.field("PUSHER").size
"""The rotors (lift and pusher): the first ``N_MOTORS`` actuators."""
N_ACTUATORS = ACTUATORS.size
MOTOR_PUSHER, ACT_SURFACE = ACTUATORS.offsets("PUSHER", "SURFACE")

PLANT_INPUT = BlockLayout("plant input", [
    Field("ACT", N_ACTUATORS, "-", "the actuator commands (ACTUATORS)"),
    Field("SURFACE_LOSS", N_SURFACES, "-", "share of each surface's effectiveness lost: 0 healthy, 1 gone (a "
          "surface_lost fault)"),
    Field("SERVO_SLOWDOWN", N_SURFACES, "-", "each servo's time constant over the plant's, minus 1 (its rate "
          "limit is divided by the same factor): 0 healthy, more for a servo_slow fault"),
])
"""What reaches the plant every tick: the allocator's actuator commands and the actuators' condition, which
only faults change (:func:`vtoladapt.sim.faults.apply_actuator_faults` writes it whole each tick). Zero
beyond the commands is a healthy airframe, so a zeroed scratch array is one."""
IN_ACT, IN_SURFACE_LOSS, IN_SERVO_SLOWDOWN = PLANT_INPUT.offsets("ACT", "SURFACE_LOSS", "SERVO_SLOWDOWN")
PLANT_INPUT_SIZE = PLANT_INPUT.size


STATE = BlockLayout("plant state", [
    Field("P_W", 3, "m", "position, NED", columns=("p_N_m", "p_E_m", "p_D_m")),
    Field("V_W", 3, "m/s", "velocity, NED", columns=("v_N_mps", "v_E_mps", "v_D_mps")),
    Field("Q_WB", 4, "-", "attitude quaternion q_WB, scalar first", columns=("q_w", "q_x", "q_y", "q_z")),
    Field("OMEGA_B", 3, "rad/s", "body rate, FRD",
          columns=("omega_x_radps", "omega_y_radps", "omega_z_radps")),
    Field("MOTOR", N_MOTORS, "-", "motor outputs after lag, fraction of full throttle: 4 lift rotors "
          "then pusher", columns=("motor1_frac", "motor2_frac", "motor3_frac", "motor4_frac", "pusher_frac")),
    Field("SERVO", N_SURFACES, "rad", "control-surface deflections after their servos (right after MOTOR: "
          "the actuator outputs are one block, ordered as ACTUATORS)",
          columns=tuple(f"surface{i + 1}_rad" for i in range(N_SURFACES))),
])
X_P_W, X_V_W, X_Q_WB, X_OMEGA_B, X_MOTOR, X_SERVO = STATE.offsets("P_W", "V_W", "Q_WB", "OMEGA_B", "MOTOR", "SERVO")
X_SIZE = STATE.size
STATE_COLUMNS = STATE.columns

# --- measurement (what the controller sees) ---------------------------------------------------
MEASUREMENT = BlockLayout("measurement", [
    Field("P_W", 3, "m", "motion-capture position, NED", columns=("meas_p_N_m", "meas_p_E_m", "meas_p_D_m")),
    Field("V_W", 3, "m/s", "motion-capture velocity, NED",
          columns=("meas_v_N_mps", "meas_v_E_mps", "meas_v_D_mps")),
    Field("Q_WB", 4, "-", "attitude estimate q_WB", columns=("meas_q_w", "meas_q_x", "meas_q_y", "meas_q_z")),
    Field("OMEGA_B", 3, "rad/s", "gyro, FRD",
          columns=("meas_omega_x_radps", "meas_omega_y_radps", "meas_omega_z_radps")),
    Field("ACCEL_B", 3, "m/s^2", "accelerometer: specific force a - g in body axes",
          columns=("meas_accel_x_mps2", "meas_accel_y_mps2", "meas_accel_z_mps2")),
    Field("V_I_B", 3, "m/s", "incident velocity from the airflow probe, body",
          columns=("meas_v_i_x_mps", "meas_v_i_y_mps", "meas_v_i_z_mps")),
    Field("V_I_VALID", 1, "-", "1.0 if the probe reading is valid, else 0.0", columns=("meas_v_i_valid",)),
])
MEAS_P_W, MEAS_V_W, MEAS_Q_WB, MEAS_OMEGA_B, MEAS_ACCEL_B, MEAS_V_I_B, MEAS_V_I_VALID = MEASUREMENT.offsets(
    "P_W", "V_W", "Q_WB", "OMEGA_B", "ACCEL_B", "V_I_B", "V_I_VALID")
MEAS_SIZE = MEASUREMENT.size
MEASUREMENT_COLUMNS = MEASUREMENT.columns

# --- reference (what the controller is asked to do) -------------------------------------------
REFERENCE = BlockLayout("reference", [
    Field("P_W", 3, "m", "desired position, NED", columns=("ref_p_N_m", "ref_p_E_m", "ref_p_D_m")),
    Field("V_W", 3, "m/s", "desired velocity, NED", columns=("ref_v_N_mps", "ref_v_E_mps", "ref_v_D_mps")),
    Field("A_W", 3, "m/s^2", "desired acceleration, NED",
          columns=("ref_a_N_mps2", "ref_a_E_mps2", "ref_a_D_mps2")),
    Field("YAW", 1, "rad", "desired heading", columns=("ref_yaw_rad",)),
    Field("YAW_RATE", 1, "rad/s", "desired heading rate", columns=("ref_yaw_rate_radps",)),
])
REF_P_W, REF_V_W, REF_A_W, REF_YAW, REF_YAW_RATE = REFERENCE.offsets("P_W", "V_W", "A_W", "YAW", "YAW_RATE")
REF_SIZE = REFERENCE.size
REFERENCE_COLUMNS = REFERENCE.columns

# --- command (what the controller outputs, held between ticks) --------------------------------
COMMAND = BlockLayout("command", [
    Field("U_X", 1, "-", "pusher throttle, fraction [0, 1]", columns=("cmd_u_x_frac",)),
    Field("U_Z", 1, "-", "collective lift throttle, fraction [0, 1] (total lift = CTz_s u_z^2 per "
          "unit mass)", columns=("cmd_u_z_frac",)),
    Field("TAU_B", 3, "N m", "body moment command, FRD", columns=("cmd_tau_x_Nm", "cmd_tau_y_Nm", "cmd_tau_z_Nm")),
])
CMD_U_X, CMD_U_Z, CMD_TAU_B = COMMAND.offsets("U_X", "U_Z", "TAU_B")
CMD_SIZE = COMMAND.size
COMMAND_COLUMNS = COMMAND.columns

# --- the truth of a tick: the wind at the vehicle, what the plant gives the sensors -------------
WIND_COLUMNS = ("wind_N_mps", "wind_E_mps", "wind_D_mps")

WIND = BlockLayout("wind at the vehicle", [
    Field("V_W", 3, "m/s", "wind velocity, NED: the sum of every wind part's contribution", columns=WIND_COLUMNS),
    Field("MEAN_W", 3, "m/s", "the steady parts' sum (fan array, constant wind), NED: what convects the "
          "turbulence and scales its fractional intensities",
          columns=("wind_mean_N_mps", "wind_mean_E_mps", "wind_mean_D_mps")),
])
"""What the wind parts add to, each tick (:mod:`vtoladapt.wind`)."""
W_V_W, W_MEAN_W = WIND.offsets("V_W", "MEAN_W")
WIND_SIZE = WIND.size

TRUTH = BlockLayout("truth of a tick", [
    Field("WIND", WIND.size, "m/s", "the wind at the vehicle (WIND), held over the tick"),
    Field("F_B", 3, "m/s^2", "true specific force a - g, body FRD (what an accelerometer measures)",
          columns=("f_B_x_mps2", "f_B_y_mps2", "f_B_z_mps2")),
    Field("V_I_B", 3, "m/s", "true incident velocity (the air relative to the vehicle), body FRD",
          columns=("v_i_x_mps", "v_i_y_mps", "v_i_z_mps")),
])
"""Each tick's truth beyond the plant state: the wind parts write its wind, the plant's first stage
its specific force and incident velocity, and every sensor channel reads it."""
TRUTH_WIND, TRUTH_F_B, TRUTH_V_I_B = TRUTH.offsets("WIND", "F_B", "V_I_B")
TRUTH_V_WIND_W, TRUTH_MEAN_WIND_W = TRUTH.nested("WIND", WIND, "V_W", "MEAN_W")
TRUTH_SIZE = TRUTH.size


def pack_state(p_W, v_W, q_WB, omega_B, motor_frac, surface_rad=(0.0,) * N_SURFACES) -> np.ndarray:
    """Plant state vector from named parts (surfaces neutral unless given)."""
    x = np.zeros(X_SIZE)
    x[X_P_W:X_P_W + 3] = p_W
    x[X_V_W:X_V_W + 3] = v_W
    x[X_Q_WB:X_Q_WB + 4] = q_WB
    x[X_OMEGA_B:X_OMEGA_B + 3] = omega_B
    x[X_MOTOR:X_MOTOR + N_MOTORS] = motor_frac
    x[X_SERVO:X_SERVO + N_SURFACES] = surface_rad
    return x


def unpack_state(x: np.ndarray) -> dict[str, np.ndarray]:
    """Named views of a plant state vector (or of a ``(T, X_SIZE)`` history)."""
    return {"p_W": x[..., X_P_W:X_P_W + 3], "v_W": x[..., X_V_W:X_V_W + 3],
            "q_WB": x[..., X_Q_WB:X_Q_WB + 4], "omega_B": x[..., X_OMEGA_B:X_OMEGA_B + 3],
            "motor_frac": x[..., X_MOTOR:X_MOTOR + N_MOTORS], "surface_rad": x[..., X_SERVO:X_SERVO + N_SURFACES]}


def pack_reference(p_W, v_W=(0.0, 0.0, 0.0), a_W=(0.0, 0.0, 0.0), yaw_rad=0.0,
                   yaw_rate_radps=0.0) -> np.ndarray:
    """Reference vector from named parts."""
    r = np.zeros(REF_SIZE)
    r[REF_P_W:REF_P_W + 3] = p_W
    r[REF_V_W:REF_V_W + 3] = v_W
    r[REF_A_W:REF_A_W + 3] = a_W
    r[REF_YAW] = yaw_rad
    r[REF_YAW_RATE] = yaw_rate_radps
    return r
