"""The wind parts: the ``"wind"`` kind of :mod:`vtoladapt.components`, and its step's signature.

A wind part (the interface is :mod:`vtoladapt.parts`'s) adds its velocity at time ``t`` and the
vehicle's position ``p_W`` to the tick's wind, a :data:`vtoladapt.layout.WIND` array: to ``V_W``
always, and to ``MEAN_W`` too if it is a steady part (the fan array, the constant wind), whose sum
convects the turbulence and scales its fractional intensities. Its step is a C kernel (decorate it
with :func:`wind_step`) of the signature :data:`WIND_STEP_SIGNATURE`::

    step(params, state, t, dt, p_W, draws, wind) -> None

(``params``, ``state``: its blocks; ``t``, ``dt`` in s; ``p_W`` NED, m; ``draws``: its
``NORMALS_PER_STEP`` standard normals then ``UNIFORMS_PER_STEP`` uniforms, drawn for this step;
``wind``: the tick's :data:`~vtoladapt.layout.WIND`, added to). It advances ``state`` to ``t + dt``.

The parts run in registration order, the package's first: each sees the mean wind of the parts
before it. A scenario's ``[wind]`` always has the package's four (they cost nothing when off, and
the turbulence draws whether on or not, so switching it never shifts another stream); a part
registered from outside is added to a run by its table, ``[wind.<id>]``.
"""
from __future__ import annotations

from numba import types

from ..components import Registry
from ..parts import ARRAY, PartInfo, PartKind, function_loader

WIND_STEP_SIGNATURE = types.void(ARRAY, ARRAY, types.float64, types.float64, ARRAY, ARRAY, ARRAY)
"""``step(params, state, t, dt, p_W, draws, wind)`` of every wind part."""

WIND_KIND = PartKind("wind", WIND_STEP_SIGNATURE)

wind_step = WIND_KIND.kernel
"""Decorator: compile a wind part's ``step`` as a C kernel of :data:`WIND_STEP_SIGNATURE` (a Numba
``cfunc``, cached on disk, no reference counting; see :meth:`vtoladapt.parts.PartKind.kernel`)."""

load_wind_step = function_loader(WIND_STEP_SIGNATURE)
"""Compiled: row ``j`` of a wind part table as a callable step."""

_PACKAGE_PARTS = (
    PartInfo("fan_array", "fan_array", "the CAST fan array: a throttle schedule, a mean wind linear in throttle",
             field="fan_array"),
    PartInfo("constant", "constant", "a constant wind vector, NED", field="constant_mps"),
    PartInfo("gusts", "gusts", "discrete gusts: 1 - cosine and step shapes", field="gusts"),
    PartInfo("turbulence", "dryden", "Dryden turbulence (MIL-F-8785C), discretised exactly", field="turbulence"),
)
WIND_PARTS: Registry = Registry("wind", WIND_KIND.check, _PACKAGE_PARTS, package=__package__)
"""The wind parts, in the order they are called."""

BUILTIN_WIND_PARTS: tuple[str, ...] = tuple(info.id for info in _PACKAGE_PARTS)
"""The package's own parts: every run has them."""
