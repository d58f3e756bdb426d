"""The simulator: scenario files, the simulated aircraft (plant), mixer, faults, the envelope monitor,
the compiled closed loop and the driver that turns a scenario into a typed result.

The usual entry points are importable from here (and from :mod:`vtoladapt` itself)::

    from vtoladapt.sim import load_scenario, simulate
    result = simulate(load_scenario("paper_comparison"))

Modules: :mod:`.scenario` (scenario files), :mod:`.plant` (the aircraft's own truth), :mod:`.mixer`,
:mod:`.faults`, :mod:`.monitor` (the envelope), :mod:`.loop` (the compiled loop), :mod:`.driver`
(scenario -> arrays -> result), :mod:`.results` (typed results, Parquet), :mod:`.run_metrics`,
:mod:`.longrun` (streamed long runs), :mod:`.limits` (size ceilings).
"""
from __future__ import annotations

import importlib

_EXPORTS = {
    "simulate": "driver", "simulate_many": "driver", "prepare": "driver",
    "Scenario": "scenario", "load_scenario": "scenario", "scenario_from_mapping": "scenario",
    "SimulationResult": "results", "run_metrics": "run_metrics",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    # imported on first use: the simulator's modules pull in Numba, which a vehicle or config user
    # does not need
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
