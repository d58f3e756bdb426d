"""Training samples from logs: the throttles through the nominal motor lag (the exact first-order step
response, restarted after a gap), body rates from the attitude quaternion (a constant rotation), and a real
PX4 log read as replay reads it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vtoladapt import load_vehicle
from vtoladapt.learn.data import lagged_throttles, quaternion_rates, read_flight

from conftest import REPO_DATA_DIR


def test_lagged_throttles_are_the_first_order_step_response():
    dt, tau = 0.004, 0.03
    cmd = np.zeros((60, 2))
    cmd[10:] = [1.0, 0.5]
    out = lagged_throttles(cmd, dt, tau, 2 * tau)
    a = np.array([math.exp(-dt / tau), math.exp(-dt / (2 * tau))])
    for t in range(11, 60):   # the command of tick t-1 acts from tick t on
        np.testing.assert_allclose(out[t], [1.0, 0.5] * (1.0 - a ** (t - 10)), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(out[:11], 0.0)


def test_lagged_throttles_restart_after_a_gap():
    cmd = np.full((20, 2), 0.4)
    cmd[5] = np.nan
    out = lagged_throttles(cmd, 0.004, 0.03, 0.03)
    assert np.all(np.isnan(out[6]))
    np.testing.assert_allclose(out[8:], 0.4, atol=1e-12)   # not NaN for ever after


def test_body_rates_of_a_constant_rotation():
    dt, w = 0.01, np.array([0.3, -0.2, 0.5])
    rate = np.linalg.norm(w)
    axis = w / rate
    t = np.arange(200) * dt
    q = np.column_stack([np.cos(rate * t / 2), np.outer(np.sin(rate * t / 2), axis)])
    np.testing.assert_allclose(quaternion_rates(q, dt)[1:-1], np.tile(w, (198, 1)), atol=1e-4)


def test_a_px4_log_gives_airborne_samples():
    log = REPO_DATA_DIR / "pyulog-testdata" / "sample_log_small.ulg"
    flight = read_flight(log, load_vehicle("px4_standard_vtol"), stride=1)
    assert len(flight.f) > 100 and np.all(np.isfinite(flight.x)) and np.all(np.isfinite(flight.f))
    # the samples on the ground are left out: the hover's specific force is about g upward
    assert np.median(flight.f[:, 2]) == pytest.approx(-9.8, abs=2.0)
