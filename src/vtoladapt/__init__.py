"""vtoladapt: adaptive nonlinear control of fixed-wing VTOL aircraft with airflow-vector sensing.

Start with :func:`load_vehicle`, :func:`load_scenario` and :func:`simulate`; the force model is in :mod:`vtoladapt.models`; frames and
rotation conventions in :mod:`vtoladapt.frames`.
"""
from ._kernel_cache import ensure_fresh_kernel_cache, when_imported


def _process_safe_disk_cache() -> None:
    from . import _numba_abi  # noqa: F401  (makes Numba's disk cache safe for several processes)


ensure_fresh_kernel_cache()
when_imported("numba", _process_safe_disk_cache)

from ._version import __version__  # noqa: E402

_VEHICLE_EXPORTS = ("PARAMETER_NAMES", "Vehicle", "available_vehicles", "load_vehicle")
_SIM_EXPORTS = ("Scenario", "SimulationResult", "load_scenario", "simulate", "simulate_many")
__all__ = ["ConfigError", *_VEHICLE_EXPORTS, *_SIM_EXPORTS]


def __getattr__(name: str):
    # everything is imported on first use: the vehicle and the simulator pull in Numba (0.3 s), and
    # the command line (vtoladapt.cli) takes over Ctrl-C before that, so one during start-up is
    # one line too, never a traceback from the middle of an import
    if name == "ConfigError":
        from .config import ConfigError

        return ConfigError
    if name in _VEHICLE_EXPORTS:
        from . import vehicle

        return getattr(vehicle, name)
    if name in _SIM_EXPORTS:
        from . import sim

        return getattr(sim, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
