"""The shared first-order low-pass (:mod:`vtoladapt.control.filters`), checked against SciPy's filters.

The compiled step ``y <- y + c (x - y)`` is the difference equation ``y_k = c x_k + (1 - c) y_(k-1)``,
which :func:`scipy.signal.lfilter` runs with ``b = [c]``, ``a = [1, c - 1]``; its gain is that of the
continuous ``1 / (tau s + 1)``, ``tau = 1 / (2 pi f_c)``, discretised exactly for an input held over the
tick (:func:`scipy.signal.cont2discrete`, zero-order hold), whose pole is ``1 - c``.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import cont2discrete, lfilter

from vtoladapt.control import adaptation, filters


def _run(x: np.ndarray, c: float, y_start: float) -> np.ndarray:
    out = np.empty_like(x)
    y = y_start
    for k in range(len(x)):
        y = filters.lowpass(y, x[k], c)
        out[k] = y
    return out


@pytest.mark.parametrize("cutoff_hz, dt_s, y_start", [(10.0, 0.004, 0.0), (2.0, 0.01, 3.5), (40.0, 0.001, -1.25)])
def test_lowpass_is_scipys_first_order_filter(cutoff_hz, dt_s, y_start):
    x = np.random.default_rng(7).normal(size=500) * 4.0 + 1.0
    c = filters.lowpass_gain(cutoff_hz, dt_s)
    # lfilter's state before the first sample: (1 - c) times the filter's output before it
    ref, _ = lfilter([c], [1.0, c - 1.0], x, zi=[(1.0 - c) * y_start])
    np.testing.assert_allclose(_run(x, c, y_start), ref, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("cutoff_hz, dt_s", [(10.0, 0.004), (0.5, 0.02), (40.0, 0.001)])
def test_lowpass_gain_is_the_zero_order_hold_discretisation(cutoff_hz, dt_s):
    tau_s = 1.0 / (2.0 * np.pi * cutoff_hz)
    num, den, _ = cont2discrete(([1.0], [tau_s, 1.0]), dt_s, method="zoh")
    pole = -den[1]
    c = filters.lowpass_gain(cutoff_hz, dt_s)
    assert c == pytest.approx(1.0 - pole, rel=1e-12)
    assert c == pytest.approx(float(np.sum(num)), rel=1e-12)   # unit DC gain: the held input's step


def test_a_decaying_state_reaches_zero_not_the_subnormals():
    y = 1.0
    for _ in range(20000):                    # (1 - c)^k passes 1e-100 after about 1900 ticks at c = 0.11
        y = filters.lowpass(y, 0.0, 0.11)
    assert y == 0.0
    assert filters.flush_tiny(0.5 * filters.TINY) == 0.0
    assert filters.flush_tiny(-2.0 * filters.TINY) == -2.0 * filters.TINY


def test_the_adaptation_still_names_the_filters():
    """``vtoladapt.control.adaptation.lowpass`` and ``lowpass_gain`` were the adaptation's: the same kernels."""
    assert adaptation.lowpass is filters.lowpass
    assert adaptation.lowpass_gain is filters.lowpass_gain
