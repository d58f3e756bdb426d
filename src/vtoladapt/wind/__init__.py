"""Wind acting on the simulated aircraft: fan array, constant wind, discrete gusts, Dryden turbulence.

The total wind velocity (NED, m/s) is the sum of the package's four parts, each set in a scenario's
``[wind]`` table (see :class:`WindConfig`), each in its own module, and of any part registered from
outside the package:

* :mod:`~vtoladapt.wind.fan_array`: the paper's CAST fan array, a throttle schedule and a mean
  wind linear in throttle (12.9 m/s at 100 %), with an optional spin-up lag solved in closed
  form (:func:`fan_mean_wind_speed`); the paper's two profiles (:func:`paper_fan_array`);
* :mod:`~vtoladapt.wind.gusts`: ``"one_minus_cosine"`` and ``"step"`` discrete gusts;
* :mod:`~vtoladapt.wind.dryden`: Dryden turbulence (MIL-F-8785C), discretised exactly;
* :mod:`~vtoladapt.wind.constant`: a constant wind, a fixed NED vector;
* :mod:`~vtoladapt.wind.composer`: :class:`WindConfig`, the run's parts laid out
  (:meth:`WindConfig.assemble`) and the compiled wind of a tick, :func:`wind_at`;
* :mod:`~vtoladapt.wind.registry`: the ``"wind"`` kind of :mod:`vtoladapt.components`, which lists
  them, and the signature of a part's step.

Kernels and randomness
----------------------
Each part is a module with the interface of :mod:`vtoladapt.parts` (settings, parameter and state
layouts, draws per step, a compiled ``step`` of the fixed signature
:data:`~vtoladapt.wind.registry.WIND_STEP_SIGNATURE`). :meth:`WindConfig.assemble` converts the
configuration once into the parts' parameter blocks and the table the compiled loop calls them
through; :func:`wind_at` zeroes the tick's wind and lets every part add to it, in registration order.
The random numbers are drawn for the parts by the loop, a fixed count per part and step
(``WIND_DRAWS_PER_STEP`` for the package's: the turbulence's five, on or off), so switching
turbulence on or off never shifts the random stream of anything else sharing the generator; the
turbulence's stationary start is drawn with its initial state.

Adding a wind part
------------------
A module of your own (the README's "Adding a wind model" is a complete one, flown by the tests):
its ``Settings`` (fields declared with :func:`vtoladapt.config.setting`), ``PARAMS`` and ``STATE``
layouts (:class:`vtoladapt.layout.BlockLayout`), ``NORMALS_PER_STEP`` and ``UNIFORMS_PER_STEP``,
``pack(settings, wind_config)``, ``initial_state(params, rng)`` and a ``step`` decorated with
:func:`~vtoladapt.wind.registry.wind_step` (a C kernel of ``WIND_STEP_SIGNATURE``) that adds its velocity to the tick's wind
(:data:`vtoladapt.layout.WIND`). Register it by a call, ``vtoladapt.components.register("wind",
PartInfo("my_id", "my_module"))``, or by an entry point in the group ``vtoladapt.wind``; a
scenario's ``[wind.my_id]`` table then adds it to the run. The compiled loop is not recompiled: it
calls every part through the same table. :func:`run_wind_model` drives any assembly of parts at a
fixed point; ``tests/example_wind_part.py`` is a complete part (a wind shear that depends on the
height), flown through ``simulate`` and the Gymnasium environment by ``tests/test_wind_interface.py``.
"""
from .composer import (
    WIND_DRAWS_INITIAL,
    WIND_DRAWS_PER_STEP,
    WIND_KERNEL_SIZE,
    WIND_PARAMS,
    WindConfig,
    fan_mean_wind_speed,
    fan_throttle_pct,
    gust_wind_W,
    run_wind_model,
    wind_at,
    wind_series,
)
from .dryden import FT_M, KNOT_MPS, TurbulenceConfig, dryden_low_altitude, dryden_psd
from .fan_array import (
    FAN_MAX_SPEED_MPS,
    MAX_BREAKPOINTS,
    PAPER_PROFILES,
    FanArrayConfig,
    comparison_schedule,
    convergence_schedule,
    paper_fan_array,
    paper_schedule,
)
from .gusts import GUST_SHAPES, MAX_GUSTS, GustConfig
from .registry import WIND_PARTS, WIND_STEP_SIGNATURE

__all__ = [
    "FAN_MAX_SPEED_MPS", "FT_M", "FanArrayConfig", "GUST_SHAPES", "GustConfig", "KNOT_MPS",
    "MAX_BREAKPOINTS", "MAX_GUSTS", "PAPER_PROFILES", "TurbulenceConfig", "WIND_DRAWS_INITIAL",
    "WIND_DRAWS_PER_STEP", "WIND_KERNEL_SIZE", "WIND_PARAMS", "WIND_PARTS", "WIND_STEP_SIGNATURE",
    "WindConfig", "comparison_schedule", "convergence_schedule", "dryden_low_altitude", "dryden_psd",
    "fan_mean_wind_speed", "fan_throttle_pct", "gust_wind_W", "paper_fan_array",
    "paper_schedule", "run_wind_model", "wind_at", "wind_series",
]
