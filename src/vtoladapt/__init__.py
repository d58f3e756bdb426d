"""vtoladapt: adaptive nonlinear control of fixed-wing VTOL aircraft with airflow-vector sensing.

Start with :func:`load_vehicle`, :func:`load_scenario` and :func:`simulate`; the force model is in :mod:`vtoladapt.models`; frames and
rotation conventions in :mod:`vtoladapt.frames`.
"""
from ._kernel_cache import ensure_fresh_kernel_cache

ensure_fresh_kernel_cache()

from .config import ConfigError  # noqa: E402
from .vehicle import PARAMETER_NAMES, Vehicle, available_vehicles, load_vehicle  # noqa: E402

__version__ = "0.1.0"
_SIM_EXPORTS = ("Scenario", "SimulationResult", "load_scenario", "simulate", "simulate_many")
__all__ = ["ConfigError", "PARAMETER_NAMES", "Vehicle", "available_vehicles", "load_vehicle", *_SIM_EXPORTS]


def __getattr__(name: str):
    # the simulator's entry points, imported on first use (they pull in Numba)
    if name in _SIM_EXPORTS:
        from . import sim

        return getattr(sim, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
