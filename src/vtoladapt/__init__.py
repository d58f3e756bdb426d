"""vtoladapt: adaptive nonlinear control of fixed-wing VTOL aircraft with airflow-vector sensing.

Start with :func:`load_vehicle`; the force model is in :mod:`vtoladapt.models`; frames and
rotation conventions in :mod:`vtoladapt.frames`.
"""
from ._kernel_cache import ensure_fresh_kernel_cache

ensure_fresh_kernel_cache()

from .config import ConfigError  # noqa: E402
from .vehicle import PARAMETER_NAMES, Vehicle, available_vehicles, load_vehicle  # noqa: E402

__version__ = "0.1.0"
__all__ = ["ConfigError", "PARAMETER_NAMES", "Vehicle", "available_vehicles", "load_vehicle"]
