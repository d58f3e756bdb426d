"""Stepping the compiled controller from a test: its functions, its diagnostics columns, one call per tick.

The compiled step takes the law's and the basis's functions (``controller_functions(params)``);
from Python, one tick is cheapest through their addresses (:func:`vtoladapt.control.step.controller_step_at`),
which :func:`step` keeps, with the functions they point into, per law and basis.
"""
from __future__ import annotations

import numpy as np

from vtoladapt.control.blocks import P_BASIS_KEY, P_LAW_KEY
from vtoladapt.control.step import (controller_functions, controller_step_at, diagnostics_columns, diagnostics_size,
                                    function_table)

_BOUND: dict = {}


def addresses(params: np.ndarray) -> np.ndarray:
    """The addresses of ``params``'s law and basis functions (the functions kept alive here)."""
    key = (float(params[P_LAW_KEY]), float(params[P_BASIS_KEY]))
    if key not in _BOUND:
        fns = controller_functions(params)
        _BOUND[key] = (fns, function_table(fns))
    return _BOUND[key][1]


def step(params, state, meas, ref, dt, cmd, diag) -> None:
    """One compiled controller tick (:func:`vtoladapt.control.step.controller_step`) of ``params``'s law and basis."""
    controller_step_at(addresses(params), params, state, meas, ref, dt, cmd, diag)


def new_diag(params) -> np.ndarray:
    """A zero ``diag`` array of ``params``'s length."""
    return np.zeros(diagnostics_size(params))


def columns(params) -> dict[str, int]:
    """``{diagnostics column: index}`` of ``params``'s law and basis."""
    return {n: i for i, n in enumerate(diagnostics_columns(params))}
