"""Wind acting on the simulated aircraft: fan array, constant wind, discrete gusts, Dryden turbulence.

The total wind velocity (NED, m/s) is the sum of four parts, each set in a scenario's ``[wind]``
table (see :class:`WindConfig`), each in its own module:

* :mod:`~vtoladapt.wind.fan_array`: the paper's CAST fan array, a throttle schedule and a mean
  wind linear in throttle (12.9 m/s at 100 %), with an optional spin-up lag solved in closed
  form (:func:`fan_mean_wind_speed`); the paper's two profiles (:func:`paper_fan_array`);
* a **constant wind**, a fixed NED vector;
* :mod:`~vtoladapt.wind.gusts`: ``"one_minus_cosine"`` and ``"step"`` discrete gusts;
* :mod:`~vtoladapt.wind.dryden`: Dryden turbulence (MIL-F-8785C), discretised exactly;
* :mod:`~vtoladapt.wind.composer`: :class:`WindConfig`, the parameter layout
  :data:`WIND_PARAMS` made of the parts' blocks, and the compiled model :func:`wind_step`.

Kernels and randomness
----------------------
:meth:`WindConfig.to_kernel` converts the configuration once to a float64 array;
:func:`wind_initial_state`, :func:`wind_step`, :func:`fan_mean_wind_speed` and
:func:`fan_throttle_pct` are compiled. Every :func:`wind_step` call draws exactly
``WIND_DRAWS_PER_STEP`` standard normals (and ``WIND_DRAWS_FIRST_STEP`` on the first call),
whether turbulence is on or not, so switching turbulence on or off never shifts the random stream
of anything else sharing the generator.

The wind-model interface
------------------------
A wind model is three things; the simulator and the tools here use nothing else:

1. **Settings**: a frozen dataclass whose fields are declared with
   :func:`vtoladapt.config.setting` (unit, meaning, allowed values) and built from a TOML table
   with :func:`vtoladapt.config.build`, with a ``to_kernel()`` that returns the model's float64
   parameter array. Declare that array's layout once with a :class:`vtoladapt.layout.BlockLayout`
   and bind the offsets the kernels use at import (``_A, _B = PARAMS.offsets("A", "B")``).
2. ``initial_state(params) -> state``: a fresh float64 state array (layout declared the same way).
3. A compiled ``step(params, state, t, dt, p_W, rng, out_v_wind_W)`` (``numba.njit``) that writes
   the wind velocity at time ``t`` (s) and position ``p_W`` (NED, m) into ``out_v_wind_W``
   (NED, m/s, shape (3,)) and advances ``state`` in place to ``t + dt``. Randomness comes only
   from ``rng`` (a ``numpy.random.Generator``) and the number of draws per call is fixed,
   whatever the settings, so changing one setting never shifts the random stream of the
   sensors that share the generator.

:func:`run_wind_model` drives any such model at a fixed point (the composed model's
:func:`wind_series` is built on it); ``tests/test_wind_interface.py`` writes a model of its own
(a wind shear that depends on ``p_W``) and holds it and the composed model to the same contract.

The closed loop (:mod:`vtoladapt.sim.loop`) calls the composed model, :func:`wind_step`.
To bring a new kind of wind into scenarios, add it as a part: a module here with its settings
class, a ``BlockLayout`` of its parameter block (and state block, if any), a ``pack_*`` function
and a compiled ``add_*`` / ``*_step`` that adds its velocity to ``out_v_wind_W`` reading its
block at a base offset; then one field in :class:`WindConfig`, one block in :data:`WIND_PARAMS`
(and :data:`WIND_STATE`) and one call in :func:`wind_step`. A part that draws random numbers
draws them after the existing parts', a fixed number per call, so existing runs stay
bit-identical.
"""
from .composer import (
    WIND_DRAWS_FIRST_STEP,
    WIND_DRAWS_PER_STEP,
    WIND_KERNEL_SIZE,
    WIND_PARAMS,
    WIND_STATE,
    WIND_STATE_SIZE,
    WindConfig,
    fan_mean_wind_speed,
    fan_throttle_pct,
    gust_wind_W,
    mean_wind_W,
    run_wind_model,
    wind_initial_state,
    wind_series,
    wind_step,
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

__all__ = [
    "FAN_MAX_SPEED_MPS", "FT_M", "FanArrayConfig", "GUST_SHAPES", "GustConfig", "KNOT_MPS",
    "MAX_BREAKPOINTS", "MAX_GUSTS", "PAPER_PROFILES", "TurbulenceConfig", "WIND_DRAWS_FIRST_STEP",
    "WIND_DRAWS_PER_STEP", "WIND_KERNEL_SIZE", "WIND_PARAMS", "WIND_STATE", "WIND_STATE_SIZE",
    "WindConfig", "comparison_schedule", "convergence_schedule", "dryden_low_altitude", "dryden_psd",
    "fan_mean_wind_speed", "fan_throttle_pct", "gust_wind_W", "mean_wind_W", "paper_fan_array",
    "paper_schedule", "run_wind_model", "wind_initial_state", "wind_series", "wind_step",
]
