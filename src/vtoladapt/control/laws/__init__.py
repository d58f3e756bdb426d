"""The control laws, one module each; the interface they share is in :mod:`vtoladapt.control`.

Each module here is listed once in :data:`vtoladapt.control.registry.CONTROLLERS`. This package
also holds :class:`LawContext`, what a law's ``fill_params`` gets besides its own settings, and
:func:`check_law`, which tells whether a module meets the interface.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...layout import BlockLayout

REQUIRED = ("Settings", "PARAMS", "STATE", "fill_params", "init_state", "update")
"""The names every law module defines (see :mod:`vtoladapt.control`)."""


@dataclass(frozen=True)
class LawContext:
    """What a law's ``fill_params`` may read besides its own settings (all in SI units).

    ``config`` is the whole :class:`~vtoladapt.control.config.ControllerConfig` (the shared gains);
    ``vehicle`` the controller's model of the aircraft; ``theta_0`` (8,) the prior mean and
    ``P0`` (8, 8) the initial adaptation gain, both in the adaptation scaling; ``dt_nominal_s``
    the nominal tick (s).
    """

    config: Any
    vehicle: Any
    theta_0: np.ndarray
    P0: np.ndarray
    dt_nominal_s: float

    @property
    def P0_max_eig(self) -> float:
        """Largest eigenvalue of ``P0`` (for the explicit sigma step's stability check)."""
        return float(np.linalg.eigvalsh(self.P0).max())


def check_sigma_step(sigma: float, ctx: LawContext, table: str) -> None:
    """The explicit sigma step is stable only while ``sigma * max eig(P0) * dt < 1``: raise otherwise."""
    x = sigma * ctx.P0_max_eig * ctx.dt_nominal_s
    if x >= 1.0:
        raise ValueError(f"[{table}] sigma = {sigma}: the explicit sigma step needs sigma * max eig(P0) * dt < 1, "
                         f"here {x:.3g}; lower sigma or P0")


def check_law(module) -> None:
    """Raise ``TypeError`` naming what is missing if ``module`` does not meet the law interface."""
    name = getattr(module, "__name__", repr(module))
    missing = [n for n in REQUIRED if not hasattr(module, n)]
    if missing:
        raise TypeError(f"control law {name}: missing {', '.join(missing)} (see vtoladapt.control)")
    if not (isinstance(module.Settings, type) and dataclasses.is_dataclass(module.Settings)):
        raise TypeError(f"control law {name}: Settings must be a dataclass")
    for block in ("PARAMS", "STATE"):
        if not isinstance(getattr(module, block), BlockLayout):
            raise TypeError(f"control law {name}: {block} must be a vtoladapt.layout.BlockLayout")


__all__ = ["LawContext", "REQUIRED", "check_law", "check_sigma_step"]
