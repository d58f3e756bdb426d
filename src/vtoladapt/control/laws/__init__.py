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

from ...config import ConfigError
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
    """The explicit sigma step is stable only while ``sigma * max eig(P0) * dt < 1``: a
    :class:`~vtoladapt.config.ConfigError` naming the three otherwise (a run names its file)."""
    eig = ctx.P0_max_eig
    x = sigma * eig * ctx.dt_nominal_s
    if not x < 1.0:
        raise ConfigError(
            f"[{table}] sigma = {sigma}: the explicit sigma step needs sigma * max eig(P0) * dt < 1, here {x:.3g} "
            f"with max eig(P0) = {eig:.3g} (the vehicle's [adaptation] P0_diag or the posterior) and dt = "
            f"{ctx.dt_nominal_s:g} s ([controller] loop_rate_hz = {1.0 / ctx.dt_nominal_s:g}; in a scenario "
            f"1/dt_control_s); lower sigma or P0, or run the controller faster")


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
