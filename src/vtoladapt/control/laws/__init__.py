"""The control laws, one module each; the interface they share is in :mod:`vtoladapt.control`.

Each module here is listed once in :data:`vtoladapt.control.registry.CONTROLLERS`. This package
also holds :class:`LawContext`, what a law's ``fill_params`` gets besides its own settings,
:func:`law_update`, the decorator of a law's compiled ``update``, and :func:`check_law`, which
tells whether a module meets the interface.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit, types

from ... import _numba_abi

from ...config import ConfigError
from ...layout import BlockLayout
from ..blocks import T_ADAPT_ACTIVE, T_F_R, T_LAW_FAULTS, T_R_WB

REQUIRED = ("Settings", "PARAMS", "STATE", "DIAG", "fill_params", "init_state", "update")
"""The names every law module defines (see :mod:`vtoladapt.control`)."""

UPDATE_SIGNATURE = types.void(types.float64[::1], types.float64[::1], types.float64[::1], types.float64[::1])
"""``update(params, state, tick, diag)``: the whole parameter and state arrays, the tick block (a view of the
state, :data:`vtoladapt.control.blocks.TICK`) and the whole diagnostics array."""


def law_update(fn):
    """Compile a law's ``update`` as a Numba ``cfunc`` of :data:`UPDATE_SIGNATURE`.

    Cached on disk and compiled without reference counting (it must not allocate), like every kernel
    of the simulator's tick (:func:`vtoladapt._numba_abi.c_kernel`); the controller step receives it
    as a first-class function argument, so the step is compiled once for every law, a user's included.
    """
    return _numba_abi.c_kernel(UPDATE_SIGNATURE, fn)


@dataclass(frozen=True)
class LawContext:
    """What a law's ``fill_params`` may read besides its own settings (all in SI units).

    ``config`` is the whole :class:`~vtoladapt.control.settings.ControllerConfig` (the shared gains);
    ``vehicle`` the controller's model of the aircraft; ``theta_0`` (n,) the prior mean and
    ``P0`` (n, n) the initial adaptation gain, both in the adaptation scaling (n is the force-model
    basis's, ``basis``: its :class:`vtoladapt.bases.BasisSpec`); ``dt_nominal_s`` the nominal tick (s).
    """

    config: Any
    vehicle: Any
    theta_0: np.ndarray
    P0: np.ndarray
    dt_nominal_s: float
    basis: Any = None

    @property
    def P0_max_eig(self) -> float:
        """Largest eigenvalue of ``P0`` (for the explicit sigma step's stability check)."""
        return float(np.linalg.eigvalsh(self.P0).max())


@njit(cache=True, inline="always")
def tick3(tick, o) -> tuple:
    """The 3-vector of the tick block at ``o`` (``T_V_TILDE``, ``T_V_R_DOT``, ...), as a tuple."""
    return (tick[o], tick[o + 1], tick[o + 2])


@njit(cache=True, inline="always")
def tick_R(tick) -> tuple:
    """The tick's attitude ``R_WB`` as three row tuples."""
    o = T_R_WB
    return ((tick[o], tick[o + 1], tick[o + 2]), (tick[o + 3], tick[o + 4], tick[o + 5]),
            (tick[o + 6], tick[o + 7], tick[o + 8]))


@njit(cache=True, inline="always")
def finish(tick, f_r, adapt_active, faults) -> None:
    """What every law's ``update`` leaves in the tick: the force command ``f_r`` (m/s^2 NED, gravity included),
    whether theta-hat was updated and the law's ``FAULT_*`` bits."""
    tick[T_F_R] = f_r[0]
    tick[T_F_R + 1] = f_r[1]
    tick[T_F_R + 2] = f_r[2]
    tick[T_ADAPT_ACTIVE] = 1.0 if adapt_active else 0.0
    tick[T_LAW_FAULTS] = faults


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
    for block in ("PARAMS", "STATE", "DIAG"):
        if not isinstance(getattr(module, block), BlockLayout):
            raise TypeError(f"control law {name}: {block} must be a vtoladapt.layout.BlockLayout")
    if not _numba_abi.is_c_kernel(module.update, UPDATE_SIGNATURE):
        raise TypeError(f"control law {name}: update must be a numba cfunc of {UPDATE_SIGNATURE} (decorate it "
                        "with vtoladapt.control.laws.law_update)")


__all__ = ["LawContext", "REQUIRED", "UPDATE_SIGNATURE", "check_law", "check_sigma_step", "finish", "law_update",
           "tick3", "tick_R"]
