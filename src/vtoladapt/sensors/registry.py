"""The sensor channels: the ``"sensor"`` kind of :mod:`vtoladapt.components`, and its step's signature.

A sensor channel (the interface is :mod:`vtoladapt.parts`'s, plus ``WRITES``: the fields of the
measurement, :data:`vtoladapt.layout.MEASUREMENT`, it writes) samples the truth of a tick into the
measurement the controller sees. Its step is a C kernel (decorate it with :func:`sensor_step`) of the
signature :data:`SENSOR_STEP_SIGNATURE`::

    step(params, state, t, dt, x_true, truth, draws, meas) -> None

(``params``, ``state``: its blocks; ``t``, ``dt`` in s; ``x_true``: the plant state,
:data:`vtoladapt.layout.STATE`; ``truth``: the tick's wind, specific force and incident velocity,
:data:`vtoladapt.layout.TRUTH`; ``draws``: its ``NORMALS_PER_STEP`` standard normals then
``UNIFORMS_PER_STEP`` uniforms for this step; ``meas``: the measurement, of which it writes its
``WRITES`` fields). It advances ``state`` in place.

A scenario's sensor suite is the channels named in ``[sensors] channels`` (default: the package's
four, ``imu``, ``mocap``, ``attitude``, ``probe``), run in that order; together they must write every
field of the measurement exactly once. A channel registered from outside takes its settings from
its own table, ``[sensors.<id>]``.
"""
from __future__ import annotations

from numba import types

from ..components import Registry
from ..parts import ARRAY, PartInfo, PartKind, function_loader

SENSOR_STEP_SIGNATURE = types.void(ARRAY, ARRAY, types.float64, types.float64, ARRAY, ARRAY, ARRAY, ARRAY)
"""``step(params, state, t, dt, x_true, truth, draws, meas)`` of every sensor channel."""

SENSOR_KIND = PartKind("sensor", SENSOR_STEP_SIGNATURE, extra_attributes=("WRITES",))

sensor_step = SENSOR_KIND.kernel
"""Decorator: compile a sensor channel's ``step`` as a C kernel of :data:`SENSOR_STEP_SIGNATURE` (a
Numba ``cfunc``, cached on disk, no reference counting; see :meth:`vtoladapt.parts.PartKind.kernel`)."""

load_sensor_step = function_loader(SENSOR_STEP_SIGNATURE)
"""Compiled: row ``j`` of a sensor part table as a callable step."""

_PACKAGE_CHANNELS = (
    PartInfo("imu", "imu", "gyroscope and accelerometer (Pixhawk-class MEMS)", field="imu"),
    PartInfo("mocap", "mocap", "motion-capture position and velocity, delayed", field="mocap"),
    PartInfo("attitude", "attitude", "attitude estimate: the true attitude with a small random rotation",
             field="attitude"),
    PartInfo("probe", "airflow_probe", "the airflow probe: incident velocity (noise and lag, or the "
             "pressure model end to end)", field="probe"),
)
SENSOR_CHANNELS: Registry = Registry("sensor", SENSOR_KIND.check, _PACKAGE_CHANNELS, package=__package__)
"""The sensor channels."""

BUILTIN_SENSOR_CHANNELS: tuple[str, ...] = tuple(info.id for info in _PACKAGE_CHANNELS)
"""The package's own channels: the default suite, in its order."""
