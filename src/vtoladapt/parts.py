"""Parts the simulator is composed of (wind parts, sensor channels): their interface, and how the
compiled loop calls them.

A *part* is one module, registered as a member of its kind in :mod:`vtoladapt.components`
(``"wind"``: :mod:`vtoladapt.wind.registry`; ``"sensor"``: :mod:`vtoladapt.sensors.registry`).
The package's own parts and a user's are the same kind of thing and reach the compiled loop the
same way. A part's module holds:

``Settings``
    its settings dataclass (fields declared with :func:`vtoladapt.config.setting`), built from the
    part's table in a scenario (``[wind.<id>]``, ``[sensors.<id>]``);
``PARAMS``, ``STATE``
    :class:`~vtoladapt.layout.BlockLayout` declarations of its parameter and state blocks;
``NORMALS_PER_STEP``, ``UNIFORMS_PER_STEP``
    how many standard normals, then uniforms on [0, 1), every step consumes, whatever the
    settings (so changing one setting never shifts another part's random stream);
``pack(settings, context) -> numpy.ndarray``
    the parameter block (``PARAMS.size`` floats), computed once per run; ``context`` is the kind's
    (the whole ``[wind]`` configuration, or the sensors' :class:`~vtoladapt.sensors.SensorContext`);
``initial_state(params, rng) -> numpy.ndarray``
    a fresh state block (``STATE.size`` floats); it may draw from ``rng`` (a
    ``numpy.random.Generator``), a number of draws that depends on the settings only;
``step``
    a C kernel of the kind's fixed signature (a Numba ``cfunc``: decorate it with the kind's
    :meth:`PartKind.kernel`, e.g. :func:`vtoladapt.wind.registry.wind_step`), random numbers
    arriving pre-drawn in its ``draws`` argument (normals first, then uniforms). Like a control
    law's ``update`` it must not allocate arrays, nor raise: an exception cannot cross its C entry
    point (it would be printed and ignored), so a part's settings are checked when it is packed.

How the loop calls them
-----------------------
The compiled loop is compiled once and never for a particular part: it receives each kind's
configured parts as a *part table* (:class:`Assembly`), an int64 array with one row per part
(:data:`PART_ROW`): the address of the C entry point of the part's ``step`` and where its blocks
sit in the kind's parameter, state and draws arrays. :func:`function_loader` turns a row back into a
Numba first-class function of the kind's signature (``numba.types.FunctionType``), which the loop
calls (an indirect call, a few nanoseconds). Control laws and force-model bases reach the controller
step the same way (:func:`vtoladapt.control.step.function_table`): every compiled part of a run is
called through the C ABI, and what that takes of Numba's internals is in
:mod:`vtoladapt._numba_abi`, nowhere else. Handing the functions over as a tuple instead would type them
the same way, but Numba then converts the tuple from Python objects on every call of the compiled
function (60-180 us measured): too slow for the Gymnasium environment, which calls its step for
every batch of environments. The table's addresses are valid in this process only; it is never
stored, and its :class:`Assembly` holds the modules, so the functions it points to stay alive.

Every step draws its random numbers from the run's generator through the loop (:func:`draw`), part
by part in table order, a fixed count per step, so the streams are those of a step that drew them
itself.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from types import ModuleType
from typing import Any, Callable, Optional, Sequence

import numpy as np
from numba import njit, types

from . import _numba_abi
from .layout import BlockLayout, Field

ARRAY = types.float64[::1]
"""A contiguous float64 array: every array argument of a part's step."""


@dataclass(frozen=True)
class PartInfo:
    """A part's registry entry: ``id`` (its table's name in a scenario), ``module`` (dotted, or
    relative to the kind's package), a one-line ``summary``, and, for the package's own parts only,
    ``field``: the attribute of the kind's configuration holding its settings (a user's part has
    its settings in the configuration's ``parts``)."""

    id: str
    module: str
    summary: str = ""
    field: Optional[str] = None


@dataclass(frozen=True)
class PartKind:
    """What every part of one kind provides: its step's ``signature`` and any further attributes."""

    name: str
    signature: Any
    extra_attributes: tuple[str, ...] = ()

    def kernel(self, fn: Callable) -> Any:
        """``fn`` compiled as a step of this kind: a C kernel (``numba.cfunc``) of :attr:`signature`,
        cached on disk, without reference counting, with NumPy's error model
        (:func:`vtoladapt._numba_abi.c_kernel`). Use it as a decorator."""
        return _numba_abi.c_kernel(self.signature, fn)

    def check(self, module: ModuleType) -> None:
        """Raise ``TypeError`` naming what ``module`` lacks to be a part of this kind."""
        name = module.__name__
        missing = [a for a in ("Settings", "PARAMS", "STATE", "NORMALS_PER_STEP", "UNIFORMS_PER_STEP", "pack",
                               "initial_state", "step") + self.extra_attributes if not hasattr(module, a)]
        if missing:
            raise TypeError(f"{self.name} part {name}: missing {', '.join(missing)} (see vtoladapt.parts)")
        for a in ("PARAMS", "STATE"):
            if not isinstance(getattr(module, a), BlockLayout):
                raise TypeError(f"{self.name} part {name}: {a} must be a vtoladapt.layout.BlockLayout")
        for a in ("NORMALS_PER_STEP", "UNIFORMS_PER_STEP"):
            v = getattr(module, a)
            if not isinstance(v, int) or isinstance(v, bool) or v < 0:
                raise TypeError(f"{self.name} part {name}: {a} = {v!r}: must be an int >= 0")
        for a in ("pack", "initial_state"):
            if not callable(getattr(module, a)):
                raise TypeError(f"{self.name} part {name}: {a} must be a function")
        if not _numba_abi.is_c_kernel(module.step, self.signature):
            raise TypeError(f"{self.name} part {name}: step must be a numba cfunc of the kind's signature, "
                            f"{self.name.upper()}_STEP_SIGNATURE = {self.signature} (decorate it with "
                            f"vtoladapt.{self.name}.registry.{self.name}_step)")


PART_ROW = BlockLayout("part table row", [
    Field("C_ADDRESS", 1, "-", "address of the step's C entry point (vtoladapt._numba_abi.c_address)"),
    Field("PARAMS_START", 1, "-", "first slot of the part's block in the kind's parameter array"),
    Field("PARAMS_END", 1, "-", "slot after it"),
    Field("STATE_START", 1, "-", "first slot of the part's block in the kind's state array"),
    Field("STATE_END", 1, "-", "slot after it"),
    Field("DRAWS_START", 1, "-", "first slot of the part's draws in the kind's draws array"),
    Field("NORMALS_END", 1, "-", "slot after its normals (its uniforms follow)"),
    Field("DRAWS_END", 1, "-", "slot after its uniforms"),
])
"""One row of a part table (int64 entries)."""
(T_C, T_P0, T_P1, T_S0, T_S1, T_D0, T_N1, T_D1) = PART_ROW.offsets(*(f.name for f in PART_ROW.fields))


def function_loader(signature) -> Callable:
    """A compiled ``load(table, j)`` giving row ``j`` of a part table as a first-class function of
    ``signature`` (``numba.types.FunctionType``), to be called like any function.

    ``table`` is an int64 ``(n, PART_ROW.size)`` array built by :class:`Assembly` (an address not
    made there is a crash: kernels trust their tables as they trust their parameter arrays).
    """
    return _numba_abi.function_loader(signature, T_C)


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def draw(rng, table, draws) -> None:
    """Fill each part's slots of ``draws`` from ``rng``: part by part in table order, its normals
    then its uniforms (what each step would have drawn itself, in the same order)."""
    for j in range(table.shape[0]):
        for i in range(table[j, T_D0], table[j, T_N1]):
            draws[i] = rng.standard_normal()
        for i in range(table[j, T_N1], table[j, T_D1]):
            draws[i] = rng.random()


@functools.lru_cache(maxsize=64)
def _layouts(kind: PartKind, modules: tuple, ids: tuple, params_sizes: tuple) -> tuple:
    """The layouts and the part table of an assembly: the same for every run of a
    configuration, so made once (the Gymnasium environment assembles its parts at every reset)."""
    params_layout = BlockLayout(f"{kind.name} parameters", [
        Field(i.upper(), n, "-", f"{m.__name__}.PARAMS") for i, m, n in zip(ids, modules, params_sizes)])
    state_layout = BlockLayout(f"{kind.name} state", [
        Field(i.upper(), m.STATE.size, "-", f"{m.__name__}.STATE") for i, m in zip(ids, modules)])
    draws_layout = BlockLayout(f"{kind.name} draws per step", [
        Field(i.upper(), m.NORMALS_PER_STEP + m.UNIFORMS_PER_STEP, "-", "normals, then uniforms")
        for i, m in zip(ids, modules)])
    table = np.zeros((len(ids), PART_ROW.size), dtype=np.int64)
    for j, (part_id, module) in enumerate(zip(ids, modules)):
        name = part_id.upper()
        p, s, d = params_layout.slice(name), state_layout.slice(name), draws_layout.slice(name)
        row = table[j]
        row[T_C] = _numba_abi.c_address(module.step, kind.signature)
        row[T_P0], row[T_P1] = p.start, p.stop
        row[T_S0], row[T_S1] = s.start, s.stop
        row[T_D0], row[T_N1], row[T_D1] = d.start, d.start + module.NORMALS_PER_STEP, d.stop
        if row[T_C] <= 0:  # the kernels would call address 0
            raise TypeError(f"{kind.name} part {part_id!r}: its step has no compiled code for {kind.signature}")
    return params_layout, state_layout, draws_layout, table


class Assembly:
    """The configured parts of one kind for one run: their blocks, one after another, and their table.

    Parameters
    ----------
    kind : PartKind
    modules : sequence of modules
        The parts, in the order the loop calls them (and draws for them).
    params : sequence of numpy.ndarray
        Each part's parameter block (``module.pack(settings, context)``), checked against its
        ``PARAMS.size``.
    ids : sequence of str
        The parts' ids (for layouts and messages).

    Attributes
    ----------
    params : numpy.ndarray
        The kind's parameter array (the blocks in order; layout :attr:`params_layout`).
    table : numpy.ndarray
        What the compiled loop calls the parts through (this process only): int64, shape
        ``(n, PART_ROW.size)``.
    draws_size : int
        Draws per step of all the parts (the loop's draws block for this kind).
    """

    def __init__(self, kind: PartKind, modules: Sequence[ModuleType], params: Sequence[np.ndarray],
                 ids: Sequence[str]):
        self.kind = kind
        self.ids = tuple(ids)
        self.modules = tuple(modules)
        blocks = []
        for part_id, module, p in zip(self.ids, self.modules, params):
            p = np.ascontiguousarray(p, dtype=float)
            # a part whose last field runs to the end of its block (size 0, e.g. the pressure probe's
            # calibration) packs more than PARAMS.size
            if p.ndim != 1 or p.size < module.PARAMS.size:
                raise ValueError(f"{kind.name} part {part_id!r}: pack() gave shape {p.shape}, its PARAMS "
                                 f"need ({module.PARAMS.size},)")
            blocks.append(p)
        self.params = np.concatenate(blocks) if blocks else np.zeros(0)
        self.params_layout, self.state_layout, self.draws_layout, table = _layouts(
            kind, self.modules, self.ids, tuple(b.size for b in blocks))
        self.table = table.copy()  # the cached one is shared
        self.draws_size = self.draws_layout.size

    def initial_state(self, rng: np.random.Generator) -> np.ndarray:
        """A fresh state array: each part's ``initial_state`` in order (their draws from ``rng``)."""
        blocks = []
        for part_id, module in zip(self.ids, self.modules):
            p = self.params[self.params_layout.slice(part_id.upper())]
            s = np.ascontiguousarray(module.initial_state(p, rng), dtype=float)
            if s.shape != (module.STATE.size,):
                raise ValueError(f"{self.kind.name} part {part_id!r}: initial_state() gave shape {s.shape}, its "
                                 f"STATE needs ({module.STATE.size},)")
            blocks.append(s)
        return np.concatenate(blocks) if blocks else np.zeros(0)

    def block(self, array: np.ndarray, part_id: str, of: str = "params") -> np.ndarray:
        """Part ``part_id``'s block (a view) of the kind's parameter (``of="params"``) or state array."""
        lay = self.params_layout if of == "params" else self.state_layout
        return lay.view(array, part_id.upper())


__all__ = ["ARRAY", "Assembly", "PART_ROW", "PartInfo", "PartKind", "draw", "function_loader"]
