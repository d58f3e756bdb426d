"""Force-model bases: the regressor ``Phi(x)`` that the adaptation, the fit and the replay share.

The controller's model of the specific force is linear in its parameters, ``f_b-hat = Phi(x)
theta``. A *basis* says what ``Phi`` is: its columns, their parameters' names, units and
scaling, the prior (mean, standard deviation, P0), the bounds rule, the physics it encodes and
what the controller needs from it. The dimension of theta is the basis's everywhere: the
adaptation (information matrix, projection, forgetting, scratch), every law, the Bayesian fit and
its posterior files, replay, reports, figures and the log's ``theta_hat_<name>`` and
``P_diag_<name>`` columns. The paper's eight-parameter basis (:mod:`.paper`) is the default; a
vehicle file names its basis (``basis = "paper"``) and a scenario's ``[controller] basis`` may
name another.

The basis interface
-------------------
A basis is a module with these names (:func:`check_basis` checks them) and one
:class:`BasisInfo` registered in :data:`BASES` (the ``"basis"`` kind of
:mod:`vtoladapt.components`: in the package's list below, by
``vtoladapt.components.register("basis", info)`` or by an entry point in the group
``vtoladapt.basis``):

``Settings``
    A frozen :class:`vtoladapt.config.Validated` dataclass of the basis's own settings (for
    example the prior of an extra column); a vehicle file gives them in
    ``[basis_settings.<id>]``, otherwise the defaults hold.
``describe(vehicle, settings) -> BasisSpec``
    Python, once per run: everything about the basis for this vehicle (:class:`BasisSpec`).
``regressor``
    The compiled regressor, a Numba ``cfunc`` of :data:`REGRESSOR_SIGNATURE` (decorate it with
    :func:`regressor_kernel`): ``regressor(block, x, phi, work)`` writes ``Phi(x)`` row-major
    (3 rows of ``n``, body FRD axes, m/s^2 per adaptation unit) into ``phi`` from the input
    block ``x`` (:data:`INPUT`) and the basis's constants ``block`` (``BasisSpec.block``);
    ``work`` is ``BasisSpec.work_size`` floats of scratch. It must not allocate (the controller
    step is compiled without reference counting) and must be cheap: it runs every tick inside a
    controller step of about 2 us.
``parameter_names(block) -> tuple[str, ...]``
    The names of the ``n`` parameters given the basis's constants (names are Python
    identifiers: they make the log's column names).

Optional: ``truth(coefficients, spec) -> array or None``: the plant's true theta in this basis
(adaptation scaling) from the plant's true Table I coefficients (a mapping by name, with
``k1``, ``k2``), or None where the plant has no such truth; the simulator uses it only for the
parameter term of the logged Lyapunov function, which is left out for a basis without one.

What the controller needs from a basis
--------------------------------------
The first :data:`N_PHYSICS` columns of every basis are the paper's physics columns, in the
paper's order and scaling (``CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1``, :mod:`vtoladapt.forces`):
the desired attitude (the wing's lift ``C_L0``, ``C_L1``), the flow-angle protection and the
thrust allocation (``C_Tx``, ``C_Tz``, ``C_S`` and the polars) invert that physics with the
first eight entries of theta-hat. The columns after them are *extra* columns: their predicted
force ``Phi_extra(x) theta_extra`` (at the throttles the regressor was evaluated at, those that
produced the measured force; through the controller's filter ``[.]_f``, so that the throttle solve
follows only the physics columns' throttle dependence,
:func:`vtoladapt.control.backend.extra_force`) is handed to the allocation as a known additive force. So a basis
is naturally "the paper's eight columns plus extra ones" (a side force ``C_Y(beta)``, a post-stall
normal force, a learned block ``phi_net(x)`` evaluated from stored weights inside ``regressor``);
a basis that wants the physics columns fixed gives them a tiny prior standard deviation and P0.
The inputs are only what the flight computer has before the force acts (:data:`INPUT`: the
incident flow and its validity, the throttles, attitude, rates, velocity; never the
accelerometer, which is what the basis predicts).

Adding a basis is one module (the names above) and one registration; README "Adding a
force-model basis" is the recipe, and ``tests/test_extension_basis.py`` flies an example basis
from a module outside the package through :func:`vtoladapt.simulate`, the Gymnasium environment
and the Bayesian fit.
"""
from __future__ import annotations

import dataclasses
import zlib
from dataclasses import dataclass
from types import ModuleType
from typing import Any, Callable, Mapping, Optional

import numpy as np
from numba import njit, types

from .. import _numba_abi, forces
from ..components import Registry
from ..config import ConfigError, Validated, build
from ..layout import BlockLayout, Field

N_PHYSICS = forces.N_THETA
"""The paper's physics columns, first in every basis (``CTx, CTz, CS, CD0, CD1, CD2, CL0, CL1``)."""

MAX_PARAMETERS = 52
"""Largest basis dimension: the projection keeps its active bounds as bits of a float64 slot (exact
up to 2^53)."""

REGRESSOR_SIGNATURE = types.void(types.float64[::1], types.float64[::1], types.float64[::1],
                                 types.float64[::1])
"""``regressor(block, x, phi, work)``: the basis's constants, the input block (:data:`INPUT`), the
output ``Phi`` (3 x n, row-major) and scratch."""


def regressor_kernel(fn: Callable) -> Any:
    """Compile a basis's ``regressor`` as a Numba ``cfunc`` of :data:`REGRESSOR_SIGNATURE`.

    Cached on disk and compiled without reference counting (``_nrt=False``), like every kernel of
    the controller's tick; the controller step receives it as a first-class function argument, so
    the step is compiled once for every basis.
    """
    return _numba_abi.c_kernel(REGRESSOR_SIGNATURE, fn)


INPUT = BlockLayout("basis input", [
    Field("V_I_B", 3, "m/s", "incident velocity the controller uses this tick (probe, or its fallback), body FRD"),
    Field("V_I_VALID", 1, "-", "1 if that is the probe's reading, 0 if the fallback (wind estimate)"),
    Field("U", 2, "-", "throttles that produced the measured force (pusher, lift collective; fraction, through "
          "the nominal motor lag)"),
    Field("Q_WB", 4, "-", "attitude quaternion, scalar first"),
    Field("OMEGA_B", 3, "rad/s", "body rate, FRD"),
    Field("V_W", 3, "m/s", "velocity, NED"),
    Field("FLOW", forces.FLOW_SIZE, "-", "forces.incident_flow of V_I_B with the vehicle's model constants "
          "(airspeed, alpha, its sine and cosine, the wing's pressure, stall weight, rotor flow angles)"),
])
"""What a basis may read: what the flight computer has before the force acts (never the
accelerometer). ``FLOW`` is evaluated once per tick for the physics columns, the allocation and
any basis that wants it."""
(IN_V_I_B, IN_V_I_VALID, IN_U, IN_Q_WB, IN_OMEGA_B, IN_V_W, IN_FLOW) = INPUT.offsets(
    *(f.name for f in INPUT.fields))
INPUT_SIZE = INPUT.size


@dataclass(frozen=True, eq=False)
class BasisSpec:
    """One basis for one vehicle: what a basis module's ``describe`` returns (arrays of length ``n``).

    ``names``: parameter names; ``units``: their Table-I units (throttle in percent); ``scale``:
    ``theta_scaled = theta_table * scale`` (the adaptation scaling, throttle as a fraction), in which
    the units are ``scaled_units`` (default: the Table-I unit where the scale is 1);
    ``theta_table``, ``std_table``: the prior mean and standard deviation (Table-I units);
    ``P0_diag``: the initial adaptation gain (adaptation scaling); ``bound_fraction``,
    ``bound_sigmas``: theta-hat stays within ``max(bound_fraction |theta_0|, bound_sigmas std)``
    of theta_0 (:func:`vtoladapt.scaling.theta_bound_half_widths`); ``sign``: +1 (-1) where
    the parameter is known to be positive (negative) by its physics, 0 where either sign is
    possible; ``wing``: the column is the wing's (zero with the wing off in a wind tunnel);
    ``block``: the constants the compiled regressor reads; ``work_size``: its scratch;
    ``physics``: one paragraph on what the columns encode; ``source``: where the prior came from;
    ``trained_spread``: per column, True if its prior std is the spread of the per-flight weights a training
    found (the learned block; the Kalman form's P0 and Q of that weight come from it).
    """

    id: str
    names: tuple[str, ...]
    units: tuple[str, ...]
    scale: np.ndarray
    theta_table: np.ndarray
    std_table: np.ndarray
    P0_diag: np.ndarray
    bound_fraction: np.ndarray
    bound_sigmas: float
    sign: np.ndarray
    wing: np.ndarray
    block: np.ndarray
    regressor: Any
    work_size: int = 0
    physics: str = ""
    source: str = ""
    scaled_units: tuple[str, ...] = ()
    trained_spread: Any = ()

    def __post_init__(self) -> None:
        n = len(self.names)
        # which columns' prior std is the spread of per-flight weights found in training (the learned block):
        # the Kalman form takes their P0 and Q from it (vtoladapt.control.kalman); default none
        ts = np.zeros(n, dtype=bool) if len(self.trained_spread) == 0 else np.array(self.trained_spread, dtype=bool)
        if ts.shape != (n,):
            raise ValueError(f"basis {self.id!r}: trained_spread must be {n} booleans, got {ts.tolist()}")
        ts.setflags(write=False)
        object.__setattr__(self, "trained_spread", ts)
        if not 1 <= n <= MAX_PARAMETERS:
            raise ValueError(f"basis {self.id!r}: {n} parameters; allowed: 1 to {MAX_PARAMETERS}")
        for name in self.names:
            if not (isinstance(name, str) and name.isidentifier()):
                raise ValueError(f"basis {self.id!r}: parameter name {name!r} must be a Python identifier")
        if len(set(self.names)) != n:
            raise ValueError(f"basis {self.id!r}: parameter names {list(self.names)} repeat")
        if len(self.units) != n:
            raise ValueError(f"basis {self.id!r}: {len(self.units)} units for {n} parameters")
        if not self.scaled_units:
            # a column the scaling leaves alone has its Table-I unit
            object.__setattr__(self, "scaled_units", tuple(u if s == 1.0 else "adaptation units"
                                                           for u, s in zip(self.units, np.asarray(self.scale))))
        if len(self.scaled_units) != n:
            raise ValueError(f"basis {self.id!r}: {len(self.scaled_units)} scaled units for {n} parameters")
        for field in ("scale", "theta_table", "std_table", "P0_diag", "bound_fraction", "sign", "wing"):
            a = np.array(getattr(self, field), dtype=bool if field == "wing" else float)
            if a.shape != (n,) or (field != "wing" and not np.all(np.isfinite(a))):
                raise ValueError(f"basis {self.id!r}: {field} must be {n} finite numbers, got {a.tolist()}")
            a.setflags(write=False)
            object.__setattr__(self, field, a)
        for field in ("scale", "std_table", "P0_diag", "bound_fraction"):
            a = getattr(self, field)
            if not np.all(a > 0.0):
                raise ValueError(f"basis {self.id!r}: every {field} must be > 0, got {a.tolist()}")
        if not set(np.unique(self.sign)) <= {-1.0, 0.0, 1.0}:
            raise ValueError(f"basis {self.id!r}: sign must hold -1, 0 or +1, got {self.sign.tolist()}")
        block = np.ascontiguousarray(self.block, dtype=float)
        if block.ndim != 1 or not np.all(np.isfinite(block)):
            raise ValueError(f"basis {self.id!r}: block must be a finite 1-D array")
        block.setflags(write=False)
        object.__setattr__(self, "block", block)
        if self.work_size < 0:
            raise ValueError(f"basis {self.id!r}: work_size = {self.work_size} must be >= 0")

    @property
    def n(self) -> int:
        """The number of parameters."""
        return len(self.names)

    @property
    def theta_scaled(self) -> np.ndarray:
        """The prior mean in the adaptation scaling."""
        return self.theta_table * self.scale

    @property
    def std_scaled(self) -> np.ndarray:
        """The prior standard deviation in the adaptation scaling."""
        return self.std_table * self.scale

    def to_scaled(self, theta_table) -> np.ndarray:
        """Table-I units -> adaptation scaling (last axis)."""
        return np.asarray(theta_table, dtype=float) * self.scale

    def from_scaled(self, theta_scaled) -> np.ndarray:
        """Adaptation scaling -> Table-I units (last axis)."""
        return np.asarray(theta_scaled, dtype=float) / self.scale

    def describe_columns(self) -> list[dict]:
        """One row per parameter: name, unit, scale, prior mean and std (Table-I units), P0, sign, wing."""
        return [{"name": n, "unit": u, "scale": float(s), "mean": float(m), "std": float(sd), "P0": float(p),
                 "sign": int(g), "wing": bool(w)}
                for n, u, s, m, sd, p, g, w in zip(self.names, self.units, self.scale, self.theta_table,
                                                   self.std_table, self.P0_diag, self.sign, self.wing)]


@dataclass(frozen=True)
class BasisInfo:
    """What the rest of the package needs to know about one basis before it is built.

    ``id``: its name in vehicle and scenario files; ``label`` for figures and tables;
    ``module``: its module, relative to :mod:`vtoladapt.bases` or absolute; ``description``: one
    line for ``--help`` and the README.
    """

    id: str
    label: str
    module: str
    description: str


REQUIRED = ("Settings", "describe", "regressor", "parameter_names")
"""The names every basis module defines."""


def check_basis(module: ModuleType) -> None:
    """Raise ``TypeError`` naming what is missing if ``module`` does not meet the basis interface."""
    name = getattr(module, "__name__", repr(module))
    missing = [n for n in REQUIRED if not hasattr(module, n)]
    if missing:
        raise TypeError(f"force-model basis {name}: missing {', '.join(missing)} (see vtoladapt.bases)")
    if not (isinstance(module.Settings, type) and dataclasses.is_dataclass(module.Settings)):
        raise TypeError(f"force-model basis {name}: Settings must be a dataclass")
    if not _numba_abi.is_c_kernel(module.regressor, REGRESSOR_SIGNATURE):
        raise TypeError(f"force-model basis {name}: regressor must be a numba cfunc of {REGRESSOR_SIGNATURE} "
                        "(decorate it with vtoladapt.bases.regressor_kernel)")


BASES: Registry = Registry("basis", check_basis, (
    BasisInfo("paper", "Paper (8)", "paper",
              "the paper's force model: thrust, rotor side force, lift and drag polars (eq:fThat, eq:fAhat), "
              "8 parameters"),
    BasisInfo("extended", "Extended physics (13)", "extended",
              "the paper's eight and the physics it lacks: side force C_Y(beta), the post-stall plate's C_N90, "
              "the lift slope near stall, the pusher's advance-ratio thrust loss; 13 parameters"),
    BasisInfo("learned", "Learned (13 + h)", "learned",
              "the extended physics columns and h columns of a network trained on flight logs by meta-learning "
              "(vtoladapt learn-basis); the vehicle's shipped file or [basis_settings.learned] file"),
), package=__name__)

DEFAULT_BASIS = "paper"


def basis_ids() -> tuple[str, ...]:
    """The registered bases' ids, now (a basis registered after import is included)."""
    return BASES.ids()


def basis_key(basis_id: str) -> float:
    """The number a controller's parameter array stores for its basis (CRC-32 of the id, exact in
    a float64): the look-up does not depend on the registration order."""
    return float(zlib.crc32(basis_id.encode()))


def basis_of_key(key: float) -> BasisInfo:
    """The registered basis whose :func:`basis_key` is ``key``; ``KeyError`` otherwise."""
    for info in BASES.values():
        if basis_key(info.id) == key:
            return info
    raise KeyError(f"no registered force-model basis has key {key!r}; registered: {', '.join(BASES)}")


def basis_module(basis_id: str) -> ModuleType:
    """The basis's module (imported and checked against the interface on first use)."""
    return BASES.module(basis_id)


def basis_settings(basis_id: str, vehicle, source: str = "") -> Any:
    """The basis's ``Settings``: the vehicle file's ``[basis_settings.<id>]`` table, or the defaults."""
    module = basis_module(basis_id)
    table = vehicle.basis_table(basis_id) if hasattr(vehicle, "basis_table") else None
    if table is None:
        return module.Settings()
    return build(module.Settings, dict(table), source=source or getattr(vehicle, "source_path", "") or "<vehicle>",
                 section=f"basis_settings.{basis_id}")


def describe_basis(vehicle, basis_id: Optional[str] = None, settings: Any = None) -> BasisSpec:
    """The :class:`BasisSpec` of ``basis_id`` (default: the vehicle's ``basis``) for ``vehicle``.

    Raises :class:`~vtoladapt.config.ConfigError` naming the allowed ids for an unknown basis.
    """
    basis_id = basis_id or getattr(vehicle, "basis", DEFAULT_BASIS) or DEFAULT_BASIS
    if basis_id not in BASES:
        source = getattr(vehicle, "source_path", "") or "<vehicle>"
        raise ConfigError(f"{source}: basis = {basis_id!r}: unknown force-model basis; allowed: "
                          f"{', '.join(BASES)}")
    module = basis_module(basis_id)
    if settings is None:
        settings = basis_settings(basis_id, vehicle)
    spec = module.describe(vehicle, settings)
    if not isinstance(spec, BasisSpec):
        raise TypeError(f"{module.__name__}.describe returned {type(spec).__name__}, not a BasisSpec")
    if spec.id != basis_id:
        raise TypeError(f"{module.__name__}.describe returned a spec with id {spec.id!r}, not {basis_id!r}")
    if tuple(module.parameter_names(spec.block)) != spec.names:
        raise TypeError(f"{module.__name__}.parameter_names(block) = {module.parameter_names(spec.block)} "
                        f"disagrees with describe's names {spec.names}")
    return spec


def truth_of(spec: BasisSpec, coefficients: Mapping[str, float]) -> Optional[np.ndarray]:
    """The plant's true theta in ``spec``'s basis (adaptation scaling), or None where the basis has none."""
    fn = getattr(basis_module(spec.id), "truth", None)
    if fn is None:
        return None
    theta = fn(coefficients, spec)
    if theta is None:
        return None
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (spec.n,):
        raise TypeError(f"basis {spec.id!r}: truth returned shape {theta.shape}, expected ({spec.n},)")
    return theta


# --- evaluating a basis outside the controller (fitting, replay, tests) ---------------------------

def input_rows(v_i_B, u_x, u_z, model, valid=None, q_WB=None, omega_B=None, v_W=None) -> np.ndarray:
    """The :data:`INPUT` block for N operating points, ``(N, INPUT.size)``.

    ``v_i_B`` (N, 3) m/s body, ``u_x``, ``u_z`` (N,) throttle fractions, ``model`` the vehicle's
    model constants (``vehicle.model_kernel``: the ``FLOW`` field is evaluated with them). The
    probe flag defaults to valid, the attitude to level, rates and velocity to zero.
    """
    v = np.ascontiguousarray(np.atleast_2d(np.asarray(v_i_B, dtype=float)))
    n = v.shape[0]
    x = np.zeros((n, INPUT.size))
    INPUT.view(x, "V_I_B")[:] = v
    INPUT.view(x, "V_I_VALID")[:] = 1.0 if valid is None else np.asarray(valid, dtype=float).reshape(n, 1)
    u = INPUT.view(x, "U")
    u[:, 0] = np.broadcast_to(np.asarray(u_x, dtype=float), (n,))
    u[:, 1] = np.broadcast_to(np.asarray(u_z, dtype=float), (n,))
    if q_WB is None:
        INPUT.view(x, "Q_WB")[:, 0] = 1.0
    else:
        INPUT.view(x, "Q_WB")[:] = np.asarray(q_WB, dtype=float)
    if omega_B is not None:
        INPUT.view(x, "OMEGA_B")[:] = np.asarray(omega_B, dtype=float)
    if v_W is not None:
        INPUT.view(x, "V_W")[:] = np.asarray(v_W, dtype=float)
    _fill_flow(v, np.ascontiguousarray(model, dtype=float), x)
    return x


@njit(cache=True)
def _fill_flow(v_i_B, model, x) -> None:
    for i in range(v_i_B.shape[0]):
        flow = forces.incident_flow((v_i_B[i, 0], v_i_B[i, 1], v_i_B[i, 2]), model)
        for k in range(forces.FLOW_SIZE):
            x[i, IN_FLOW + k] = flow[k]


@njit(cache=True)
def _evaluate_rows(regressor, block, x, phi, work) -> None:
    """``phi[i] = Phi(x[i])`` for every row (``phi`` (N, 3 n)), the regressor as a first-class function."""
    for i in range(x.shape[0]):
        regressor(block, x[i], phi[i], work)


def evaluate(spec: BasisSpec, x: np.ndarray) -> np.ndarray:
    """``Phi`` (N, 3, n) at the input rows ``x`` (:func:`input_rows`), by the basis's compiled regressor."""
    x = np.ascontiguousarray(np.atleast_2d(x), dtype=float)
    if x.shape[1] != INPUT.size:
        raise ValueError(f"input rows must have {INPUT.size} columns (vtoladapt.bases.INPUT), got {x.shape[1]}")
    phi = np.zeros((x.shape[0], 3 * spec.n))
    _evaluate_rows(spec.regressor, np.array(spec.block), x, phi, np.zeros(max(1, spec.work_size)))
    return phi.reshape(x.shape[0], 3, spec.n)


def physics_signs() -> np.ndarray:
    """Known signs of the paper's eight parameters from their physics (:func:`vtoladapt.vehicle.parameter_signs`:
    ``CTx, CTz, CL1 > 0``; ``CS, CD0, CD2 >= 0``; ``CD1``, ``CL0`` either sign): the first :data:`N_PHYSICS`
    entries of every basis's ``sign``."""
    from ..vehicle import parameter_signs

    return parameter_signs().astype(float)


__all__ = ["BASES", "DEFAULT_BASIS", "INPUT", "INPUT_SIZE", "MAX_PARAMETERS", "N_PHYSICS", "REGRESSOR_SIGNATURE", "REQUIRED",
           "BasisInfo", "BasisSpec", "basis_ids", "basis_key", "basis_module", "basis_of_key", "basis_settings",
           "check_basis", "describe_basis", "evaluate", "input_rows", "physics_signs", "regressor_kernel",
           "truth_of"]
