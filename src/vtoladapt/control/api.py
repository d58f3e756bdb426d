"""The controller as a Python object, for use in your own loop (outside our simulator).

>>> import numpy as np, vtoladapt
>>> from vtoladapt.control import Controller, ControllerConfig, Measurement, Reference
>>> ctrl = Controller(vtoladapt.load_vehicle("caltech_vtol"), ControllerConfig(kind="composite"))
>>> meas = Measurement.from_parts(p_W=(0, 0, -1.5), v_W=(0, 0, 0), q_WB=(1, 0, 0, 0),
...                               omega_B=(0, 0, 0), accel_B=(0, 0, -9.80665), v_i_B=(0, 0, 0))
>>> cmd = ctrl.step(0.0, meas, Reference.hold((0, 0, -1.5)))
>>> 0.55 < cmd.u_z < 0.61      # hover throttle: sqrt(g / C_Tz) with C_Tz = 28.7 m/s^2
True

``step`` does no Python-level work beyond checking its arguments (a Measurement, a Reference, a
finite increasing time: the compiled step reads the records' arrays by offset, unchecked) and one
call of the compiled kernel (:func:`.step.controller_step_at`, which calls the law and the basis by
the addresses the controller took when it was made): the records are thin named views of float64
arrays in the layouts of :mod:`vtoladapt.layout`. The same class steps every registered law (the
config's ``kind``) with every force-model basis (the config's ``basis``, default the vehicle's);
:attr:`Controller.state` names the shared memory and, by :meth:`ControllerState.law_field`, the law's
own (its ``STATE`` layout).
"""
from __future__ import annotations

import math
import numbers

import numpy as np

from .. import layout as L
from .blocks import S_LAW
from .settings import ControllerConfig
from .step import (
    basis_names,
    controller_functions,
    controller_initial_state,
    controller_params,
    controller_step_at,
    default_theta_bounds,
    diagnostics_columns,
    diagnostics_size,
    function_table,
    law_of_params,
    state_P,
    state_P_inv,
)
from . import step as _k


def _fill(a: np.ndarray, off: int, value, n: int, name: str) -> None:
    v = np.asarray(value, dtype=float)
    if v.shape != (n,):
        raise ValueError(f"{name} must have {n} elements, got shape {v.shape}")
    a[off:off + n] = v


class _Record:
    """A named view of one float64 array (``.array``), passed to the kernel as it is."""

    __slots__ = ("_a",)
    SIZE = 0
    COLUMNS: tuple[str, ...] = ()

    def __init__(self, array=None):
        if array is None:
            self._a = np.zeros(self.SIZE)
        else:
            a = np.asarray(array, dtype=np.float64)
            if a.shape != (self.SIZE,):
                raise ValueError(f"{type(self).__name__} array must have shape ({self.SIZE},), got {a.shape}")
            self._a = np.ascontiguousarray(a)

    @property
    def array(self) -> np.ndarray:
        """The underlying float64 array (shared, not a copy)."""
        return self._a

    def as_dict(self) -> dict[str, float]:
        """``{column name: value}`` (units in the names)."""
        return {n: float(v) for n, v in zip(self.COLUMNS, self._a)}

    def copy(self):
        """A record with its own copy of the array."""
        return type(self)(self._a.copy())

    def __repr__(self) -> str:
        body = ", ".join(f"{n}={v:.6g}" for n, v in zip(self.COLUMNS, self._a))
        return f"{type(self).__name__}({body})"

    def __eq__(self, other) -> bool:
        return type(other) is type(self) and np.array_equal(self._a, other._a, equal_nan=True)

    __hash__ = None


def _vec_property(off: int, n: int, doc: str):
    def get(self):
        return self._a[off:off + n]

    def set(self, value):
        _fill(self._a, off, value, n, doc.split(",")[0])

    return property(get, set, doc=doc)


def _scalar_property(off: int, doc: str):
    def get(self):
        return float(self._a[off])

    def set(self, value):
        self._a[off] = float(value)

    return property(get, set, doc=doc)


class Measurement(_Record):
    """What the controller sees (layout ``MEAS_*``): NED world, FRD body, SI units."""

    __slots__ = ()
    SIZE = L.MEAS_SIZE
    COLUMNS = L.MEASUREMENT_COLUMNS
    p_W = _vec_property(L.MEAS_P_W, 3, "position, m NED (motion capture)")
    v_W = _vec_property(L.MEAS_V_W, 3, "velocity, m/s NED")
    q_WB = _vec_property(L.MEAS_Q_WB, 4, "attitude quaternion q_WB, scalar first")
    omega_B = _vec_property(L.MEAS_OMEGA_B, 3, "body rate, rad/s FRD (gyro)")
    accel_B = _vec_property(L.MEAS_ACCEL_B, 3, "specific force a - g, m/s^2 body (accelerometer)")
    v_i_B = _vec_property(L.MEAS_V_I_B, 3, "incident velocity, m/s body (airflow probe)")
    v_i_valid = _scalar_property(L.MEAS_V_I_VALID, "1.0 if the probe reading is valid, else 0.0")

    @classmethod
    def from_parts(cls, p_W, v_W, q_WB, omega_B, accel_B, v_i_B, v_i_valid=True) -> "Measurement":
        """A measurement from named parts (see the properties for units and frames)."""
        m = cls()
        a = m._a
        _fill(a, L.MEAS_P_W, p_W, 3, "p_W")
        _fill(a, L.MEAS_V_W, v_W, 3, "v_W")
        _fill(a, L.MEAS_Q_WB, q_WB, 4, "q_WB")
        _fill(a, L.MEAS_OMEGA_B, omega_B, 3, "omega_B")
        _fill(a, L.MEAS_ACCEL_B, accel_B, 3, "accel_B")
        _fill(a, L.MEAS_V_I_B, v_i_B, 3, "v_i_B")
        a[L.MEAS_V_I_VALID] = 1.0 if v_i_valid else 0.0
        return m


class Reference(_Record):
    """What the controller is asked to do (layout ``REF_*``)."""

    __slots__ = ()
    SIZE = L.REF_SIZE
    COLUMNS = L.REFERENCE_COLUMNS
    p_W = _vec_property(L.REF_P_W, 3, "desired position, m NED")
    v_W = _vec_property(L.REF_V_W, 3, "desired velocity, m/s NED")
    a_W = _vec_property(L.REF_A_W, 3, "desired acceleration, m/s^2 NED")
    yaw_rad = _scalar_property(L.REF_YAW, "desired heading, rad (0 = north)")
    yaw_rate_radps = _scalar_property(L.REF_YAW_RATE, "desired heading rate, rad/s (informative)")

    @classmethod
    def from_parts(cls, p_W, v_W=(0.0, 0.0, 0.0), a_W=(0.0, 0.0, 0.0), yaw_rad=0.0,
                   yaw_rate_radps=0.0) -> "Reference":
        """A reference from named parts (see the properties for units and frames)."""
        return cls(L.pack_reference(p_W, v_W, a_W, yaw_rad, yaw_rate_radps))

    @classmethod
    def hold(cls, p_W, yaw_rad=0.0) -> "Reference":
        """Hold a position (m NED) at a heading (rad)."""
        return cls.from_parts(p_W, yaw_rad=yaw_rad)


class Command(_Record):
    """The controller's output (layout ``CMD_*``), held until the next tick."""

    __slots__ = ()
    SIZE = L.CMD_SIZE
    COLUMNS = L.COMMAND_COLUMNS
    u_x = _scalar_property(L.CMD_U_X, "pusher throttle, fraction [0, 1]")
    u_z = _scalar_property(L.CMD_U_Z, "collective lift throttle, fraction [0, 1]")
    tau_B = _vec_property(L.CMD_TAU_B, 3, "body moment command, N m FRD")

    @property
    def throttle_x_pct(self) -> float:
        """Pusher throttle, percent."""
        return 100.0 * float(self._a[L.CMD_U_X])

    @property
    def throttle_z_pct(self) -> float:
        """Collective lift throttle, percent."""
        return 100.0 * float(self._a[L.CMD_U_Z])


class ControllerSnapshot:
    """A copy of a controller's complete memory (from :meth:`Controller.get_state`)."""

    __slots__ = ("state", "t_last")

    def __init__(self, state: np.ndarray, t_last):
        self.state = state
        self.t_last = t_last


class ControllerState:
    """Named, read-only view of a controller's memory (``Controller.state``).

    The shared memory has a property each; the law's own fields (its module's ``STATE`` layout)
    are read by :meth:`law_field` and listed by :attr:`law_fields`.
    """

    __slots__ = ("_s", "_law_state", "_p")

    def __init__(self, s: np.ndarray, law_state=None, params=None):
        self._s = s
        self._law_state = law_state
        self._p = params

    @property
    def names(self) -> tuple[str, ...]:
        """The names of theta-hat's entries (the force-model basis's parameters)."""
        return basis_names(self._p)

    @property
    def law_fields(self) -> tuple[str, ...]:
        """Names of the law's own state fields."""
        return () if self._law_state is None else tuple(f.name for f in self._law_state.fields)

    def law_field(self, name: str) -> np.ndarray:
        """Field ``name`` of the law's own state (copy); ``KeyError`` naming the fields otherwise."""
        if self._law_state is None:
            raise KeyError(f"no law state layout known; cannot read {name!r}")
        return self._law_state.view(self._s[S_LAW:], name).copy()

    @property
    def theta_hat(self) -> np.ndarray:
        """theta-hat (n,), adaptation scaling (copy); n and the names (:attr:`names`) are the basis's."""
        return _k.state_theta_hat(self._p, self._s).copy()

    @property
    def P(self) -> np.ndarray:
        """Adaptation gain P (n, n) (copy)."""
        return state_P(self._p, self._s)

    @property
    def P_inv(self) -> np.ndarray:
        """Information matrix P^-1 (n, n) (copy)."""
        return state_P_inv(self._p, self._s).copy()

    @property
    def integrator(self) -> np.ndarray:
        """The law's integral term (3,), m/s^2 NED: its ``INTEGRATOR`` state field, zeros if it has none (copy)."""
        if "INTEGRATOR" in self.law_fields:
            return self.law_field("INTEGRATOR")
        return np.zeros(3)

    @property
    def filtered_accel(self) -> np.ndarray:
        """Filtered specific force a_m (3,), m/s^2 body (copy)."""
        return _k.state_filtered_accel(self._p, self._s).copy()

    @property
    def filtered_regressor(self) -> np.ndarray:
        """Filtered regressor W (3, n) (copy)."""
        return _k.state_filtered_regressor(self._p, self._s).copy()

    @property
    def wind_estimate(self) -> np.ndarray:
        """Wind estimate (3,), m/s NED (copy)."""
        return _k.state_wind_estimate(self._s).copy()

    @property
    def last_command_throttles(self) -> np.ndarray:
        """``[u_x, u_z]`` of the last command (copy)."""
        return _k.state_last_command(self._s).copy()

    @property
    def array(self) -> np.ndarray:
        """The raw state array (copy)."""
        return self._s.copy()


class Controller:
    """Any registered controller (``config.kind``), stepping in the caller's loop.

    Parameters
    ----------
    vehicle : Vehicle
        The controller's model of the aircraft (inertia, force model, limits).
    config : ControllerConfig, optional
        Gains and settings (default: ``ControllerConfig()``, the composite controller), validated
        when it was made. Set its ``loop_rate_hz`` to the rate you call :meth:`step` at: the first
        tick and the laws' stability checks (L1's ``a_s dt``, the sigma step) use ``1/loop_rate_hz``.
    theta_0, P0_diag, theta_lower, theta_upper, theta_init : arrays, optional
        Prior mean, initial gain (diagonal or full n x n), bounds and initial theta-hat, all in the
        adaptation scaling, n the force-model basis's (see :func:`.step.controller_params`).
    """

    __slots__ = ("vehicle", "config", "_params", "_state", "_diag", "_t_last", "_dt_nominal", "_law_state", "_fns",
                 "_addresses", "_columns")

    def __init__(self, vehicle, config: ControllerConfig | None = None, theta_0=None, P0_diag=None,
                 theta_lower=None, theta_upper=None, theta_init=None):
        from ..vehicle import Vehicle

        if not isinstance(vehicle, Vehicle):
            raise TypeError(f"vehicle must be a vtoladapt Vehicle (vtoladapt.load_vehicle), "
                            f"got {type(vehicle).__name__}")
        self.vehicle = vehicle
        self.config = ControllerConfig() if config is None else config
        if not isinstance(self.config, ControllerConfig):
            raise TypeError(f"config must be a ControllerConfig, got {type(config).__name__}")
        self._params = controller_params(self.config, vehicle, theta_0=theta_0, P0_diag=P0_diag,
                                         theta_lower=theta_lower, theta_upper=theta_upper,
                                         theta_init=theta_init)
        self._dt_nominal = 1.0 / self.config.loop_rate_hz
        self._law_state = law_of_params(self._params).law.STATE
        self._diag = np.zeros(diagnostics_size(self._params))
        self._columns = diagnostics_columns(self._params)
        self._bind()
        self.reset()

    def _bind(self) -> None:
        # the law's and the basis's compiled functions, and their addresses for the compiled step (the
        # functions are kept here so the addresses stay valid)
        self._fns = controller_functions(self._params)
        self._addresses = function_table(self._fns)

    def __getstate__(self):
        # compiled functions do not pickle, and their addresses belong to this process: bound again on load
        return {k: getattr(self, k) for k in self.__slots__ if k not in ("_fns", "_addresses")}

    def __setstate__(self, values) -> None:
        for k, v in values.items():
            object.__setattr__(self, k, v)
        self._bind()

    def reset(self) -> None:
        """Back to the initial state (theta-hat = theta_init, P = P0, filters and the law's memory empty)."""
        self._state = controller_initial_state(self._params)
        self._diag[:] = 0.0
        self._t_last = None

    def step(self, t: float, measurement: Measurement, reference: Reference) -> Command:
        """Compute the command for time ``t`` (s) from a measurement and a reference.

        ``dt`` is ``t`` minus the previous call's ``t`` (``1/loop_rate_hz`` on the first call).
        Raises TypeError if ``measurement`` is not a :class:`Measurement` or ``reference`` not a
        :class:`Reference` (the compiled step reads their arrays by the layouts' offsets), and
        ValueError if ``t`` is not a finite number or does not increase; a refused call changes nothing.
        """
        if not (isinstance(measurement, Measurement) and isinstance(reference, Reference)):
            _refuse_records(measurement, reference)
        if type(t) is not float or not math.isfinite(t):
            t = _finite_time(t, self._t_last)
        t_last = self._t_last
        if t_last is None:
            dt = self._dt_nominal
        else:
            dt = t - t_last
            if not dt > 0.0:
                raise ValueError(f"t = {t!r}: must increase (previous step at t = {t_last!r})")
        cmd = Command.__new__(Command)
        cmd._a = np.empty(L.CMD_SIZE)
        controller_step_at(self._addresses, self._params, self._state, measurement._a, reference._a, dt, cmd._a,
                           self._diag)
        self._t_last = t
        return cmd

    def report_applied(self, throttle_x_pct: float, throttle_z_pct: float) -> None:
        """Tell the controller the throttles actually applied after its last :meth:`step`, in percent.

        Call it when your mixer saturated and changed the command (or anything else between the
        controller and the motors did): the next step's regressor and adaptation take these as the
        applied throttles (eq:prediction_error) instead of the command. ``throttle_z_pct`` is the
        collective the lift rotors amount to, ``sqrt(mean u_i^2)`` over the four rotors
        (:func:`vtoladapt.sim.mixer.applied_collective`, which the shipped simulation reports). Values are
        clipped to [0, the vehicle's throttle_max_pct]; a non-finite value raises ValueError.
        """
        u_max = self.vehicle.actuators.throttle_max_pct
        vals = []
        for name, value in (("throttle_x_pct", throttle_x_pct), ("throttle_z_pct", throttle_z_pct)):
            try:
                v = float(value)
            except (TypeError, ValueError):
                v = float("nan")
            if not np.isfinite(v):
                raise ValueError(f"report_applied: {name} = {value!r}: must be a finite number; "
                                 f"allowed: 0-{u_max:g} %")
            vals.append(min(max(v, 0.0), u_max) / 100.0)
        _k.set_last_command(self._state, vals[0], vals[1])

    @property
    def state(self) -> ControllerState:
        """Named view of the controller's memory (theta_hat, P, integrator, ... and the law's own fields)."""
        return ControllerState(self._state, self._law_state, self._params)

    def get_state(self) -> ControllerSnapshot:
        """A copy of the complete memory; :meth:`set_state` restores it bit for bit."""
        return ControllerSnapshot(self._state.copy(), self._t_last)

    def set_state(self, snapshot: ControllerSnapshot) -> None:
        """Restore a snapshot taken by :meth:`get_state` of a controller of the same kind.

        Allowed: a :class:`ControllerSnapshot` whose ``state`` has this controller's shape and only
        finite entries (a controller's memory never holds anything else: the step sanitises its
        inputs and guards its own arithmetic) and whose ``t_last`` is None (not stepped) or a finite
        time in s. Anything else raises TypeError or ValueError and leaves the controller as it was.
        """
        if not isinstance(snapshot, ControllerSnapshot):
            raise TypeError(f"set_state: expected a ControllerSnapshot (from get_state), got {type(snapshot).__name__}")
        try:
            s = np.array(snapshot.state, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"set_state: snapshot state = {snapshot.state!r:.60}: must be a float array") from None
        if s.shape != self._state.shape:
            raise ValueError(f"set_state: snapshot state has shape {s.shape}, expected {self._state.shape} "
                             f"(a snapshot of a {self.config.kind} controller)")
        bad = np.flatnonzero(~np.isfinite(s))
        if bad.size:
            raise ValueError(f"set_state: snapshot state[{bad[0]}] = {float(s[bad[0]])!r}: must be finite "
                             f"({bad.size} non-finite entries)")
        t_last = snapshot.t_last
        if t_last is not None:
            t_last = _finite_time(t_last, None, "set_state: snapshot t_last")
        self._state = s
        self._t_last = t_last

    @property
    def params(self) -> np.ndarray:
        """The kernel parameter array (copy)."""
        return self._params.copy()

    @property
    def diagnostics_columns(self) -> tuple[str, ...]:
        """Names of :attr:`diagnostics_array`'s entries (:func:`.step.diagnostics_columns`: the shared ones, the
        law's own, then theta-hat and diag(P) per parameter of the basis)."""
        return self._columns

    @property
    def diagnostics_array(self) -> np.ndarray:
        """Internals of the last step (copy), named by :attr:`diagnostics_columns`."""
        return self._diag.copy()

    @property
    def diagnostics(self) -> dict[str, float]:
        """``{name: value}`` of the last step's internals (units in the names)."""
        return {n: float(v) for n, v in zip(self._columns, self._diag)}


def _refuse_records(measurement, reference) -> None:
    """The TypeError of :meth:`Controller.step` given something other than a Measurement and a Reference."""
    for name, value, cls in (("measurement", measurement, Measurement), ("reference", reference, Reference)):
        if not isinstance(value, cls):
            raise TypeError(f"step: {name} must be a {cls.__name__} (vtoladapt.control.{cls.__name__}), "
                            f"got {type(value).__name__}")


def _finite_time(t, t_last, what: str = "step: t") -> float:
    """``t`` as a float if it is a finite real number (s); ValueError naming ``what`` otherwise."""
    ok = isinstance(t, numbers.Real) and not isinstance(t, (bool, np.bool_))
    if ok:
        t = float(t)
        ok = math.isfinite(t)
    if not ok:
        before = "" if t_last is None else f" (previous step at t = {t_last!r})"
        raise ValueError(f"{what} = {t!r}: must be a finite time in s{before}")
    return t


def controller_arrays(vehicle, config: ControllerConfig, theta_0=None, P0_diag=None, theta_lower=None,
                      theta_upper=None, theta_init=None, basis=None) -> tuple[np.ndarray, np.ndarray]:
    """``(params, initial state)`` kernel arrays for the simulator's compiled loop (its functions:
    :func:`.step.controller_functions` of ``params``)."""
    params = controller_params(config, vehicle, theta_0=theta_0, P0_diag=P0_diag, theta_lower=theta_lower,
                               theta_upper=theta_upper, theta_init=theta_init, basis=basis)
    return params, controller_initial_state(params)


__all__ = ["Command", "Controller", "ControllerSnapshot", "ControllerState", "Measurement", "Reference",
           "controller_arrays", "default_theta_bounds"]
