"""The first-order low-pass filters the controller and its estimators share, and the flush of decaying states.

``[.]_f`` (eq:prediction_error) is a first-order low-pass at ``f_c``, discretised exactly for an input
held over the tick: ``y <- y + c (x - y)`` with ``c = 1 - exp(-2 pi f_c dt)`` (:func:`lowpass_gain`).
The adaptation filters the regressor and the accelerometer with it; the laws (PID's derivative, L1's
sigma filter), the front end's wind estimate, the back end's filters and the replay's estimator use the
same step. It is a module of its own so that a law that needs a filter does not import the adaptation.

Compiled (``cache=True``) as every kernel; a caller's compiled code calls them directly.
"""
from __future__ import annotations

import numpy as np
from numba import njit

TINY = 1e-100
"""States decaying toward zero are set to zero below this magnitude: no physical quantity here is
that small, and subnormal floats (below 2.2e-308, reached after a few thousand ticks of exponential
decay) make every operation on them about a hundred times slower."""


@njit(cache=True)
def flush_tiny(x: float) -> float:
    """``x``, or 0 if ``|x| < TINY`` (keeps decaying states out of the subnormal range)."""
    return x if abs(x) >= TINY else 0.0


@njit(cache=True)
def lowpass(y: float, x: float, c: float) -> float:
    """One step of the low-pass, ``y + c (x - y)``, flushing tiny values to zero."""
    return flush_tiny(y + c * (x - y))


@njit(cache=True)
def lowpass_gain(cutoff_hz: float, dt: float) -> float:
    """Gain ``c = 1 - exp(-2 pi f_c dt)`` of the exactly discretised first-order low-pass."""
    return 1.0 - np.exp(-2.0 * np.pi * cutoff_hz * dt)


__all__ = ["TINY", "flush_tiny", "lowpass", "lowpass_gain"]
