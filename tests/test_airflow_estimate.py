"""The unseen-flow airflow estimate: the model's own force inverted, its guards, and the setting that turns it on.

The reference is the forward model: for a known wind the model's body force
(:func:`vtoladapt.forces.body_force`, at a given theta) is what the estimator is handed, and it must
give that wind back; guards and degenerate inputs must give "no estimate" and never NaN.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from conftest import examples
from vtoladapt import forces
from vtoladapt.config import ConfigError
from vtoladapt.control import ControllerConfig
from vtoladapt.control.airflow_estimate import SIN_SIDESLIP_MAX, estimate_horizontal_wind
from vtoladapt.control.settings import controller_config_from_mapping
from vtoladapt.control.blocks import P_FLOW_EST_ON, P_FLOW_EST_TAU
from vtoladapt.control.step import controller_params
from vtoladapt.vehicle import load_vehicle

VEHICLES = ("caltech_vtol", "px4_standard_vtol")


def _rows_yaw(psi):
    c, s = np.cos(psi), np.sin(psi)
    return ((c, -s, 0.0), (s, c, 0.0), (0.0, 0.0, 1.0))


def _incident(v_W, R, w):
    d = np.asarray(v_W) - np.asarray(w)
    return tuple(float(R[0][j] * d[0] + R[1][j] * d[1] + R[2][j] * d[2]) for j in range(3))


def _cold_solve(vehicle, airspeed, from_deg, yaw=0.0, u_z=0.5, u_x=0.0, factor=1.0):
    """The estimator handed the model's own force for a flow from ``from_deg`` (body, 0 = ahead).

    Returns ``(ok, residual, flow error / airspeed, (w_N, w_E))``."""
    veh = load_vehicle(vehicle)
    theta = tuple(veh.theta_scaled * factor)
    model = tuple(veh.model_kernel)
    R = _rows_yaw(yaw)
    # the body-frame direction the air comes from: the incident velocity points the other way
    rel = np.radians(from_deg)
    v_i_true = (airspeed * np.cos(rel), airspeed * np.sin(rel), 0.0)
    v_W = (0.3, -0.2, 0.0)
    f = forces.body_force(v_i_true, u_x, u_z, theta, model)
    ok, w_N, w_E, res = estimate_horizontal_wind(v_W, R, 0.0, 0.0, 0.0, True, u_x, u_z, theta, model, f[0], f[1],
                                                 1e-3, 60.0, 1.0)
    v_i = _incident(v_W, R, (w_N, w_E, 0.0))
    return ok, res, np.hypot(v_i[0] - v_i_true[0], v_i[1] - v_i_true[1]) / airspeed, (w_N, w_E)


@settings(max_examples=examples(60), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(vehicle=st.sampled_from(VEHICLES), airspeed=st.floats(2.0, 13.0),
       from_deg=st.sampled_from([90.0, 135.0, 180.0, 225.0, 270.0]), jitter_deg=st.floats(-20.0, 20.0),
       yaw=st.floats(-np.pi, np.pi), u_z=st.floats(0.3, 0.9), u_x=st.floats(0.0, 0.3),
       factor=st.floats(0.8, 1.2))
# found by this property when it demanded an answer everywhere: a cold start that needed more than
# the warm start's six iterations (now solved), and one Gauss-Newton cannot reach from its cold start
@example(vehicle="caltech_vtol", airspeed=11.75, from_deg=135.0, jitter_deg=4.0, yaw=0.0, u_z=0.375, u_x=0.0,
         factor=1.0)
@example(vehicle="caltech_vtol", airspeed=10.75, from_deg=135.0, jitter_deg=0.0, yaw=0.0, u_z=0.375, u_x=0.0,
         factor=1.0)
def test_an_accepted_estimate_of_a_wind_behind_or_beside_is_the_right_one(vehicle, airspeed, from_deg, jitter_deg,
                                                                         yaw, u_z, u_x, factor):
    """Flow from the side (beta = +-90 deg) and from behind at 2-13 m/s: whatever the estimator accepts is
    the wind that made the force (to 5 % of the airspeed); what it refuses leaves the start values, finite."""
    ok, res, err, w = _cold_solve(vehicle, airspeed, from_deg + jitter_deg, yaw, u_z, u_x, factor)
    if ok:
        assert res <= 1e-3
        # the force pins the wind to within tol / (smallest singular value of d f_h / d w): check the flow itself
        assert err < 0.05
    else:
        assert w == (0.0, 0.0) and res > 1e-3


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_a_wind_behind_or_beside_is_recovered_almost_everywhere(vehicle):
    """On a grid of flows from 70-290 deg, 2-13 m/s and lift throttles 0.3-0.9, the cold start finds the
    wind in at least 99 % of cases (measured: caltech_vtol 99.8 % on a finer grid, its misses at 10-13 m/s
    with the flow 70-145 deg off the nose and u_z <= 0.5, where Gauss-Newton stops short; px4_standard_vtol
    100 %). A miss is a refusal, never a wrong wind (the property above)."""
    found = total = 0
    for from_deg in (90.0, 135.0, 180.0, 225.0, 270.0):
        for jitter in np.arange(-20.0, 20.1, 2.0):
            for airspeed in np.arange(2.0, 13.01, 0.5):
                for u_z in (0.3, 0.45, 0.65, 0.9):
                    ok, _, err, _ = _cold_solve(vehicle, float(airspeed), from_deg + float(jitter), u_z=u_z)
                    total += 1
                    found += ok and err < 0.05
    assert found >= 0.99 * total, f"{found}/{total}"


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_warm_start_stays_on_the_solution(vehicle):
    veh = load_vehicle(vehicle)
    theta, model = tuple(veh.theta_scaled), tuple(veh.model_kernel)
    R = _rows_yaw(0.0)
    f = forces.body_force((-6.0, 0.5, 0.0), 0.0, 0.6, theta, model)
    ok, w_N, w_E, res = estimate_horizontal_wind((0.0, 0.0, 0.0), R, 0.0, 6.2, -0.3, False, 0.0, 0.6, theta, model,
                                                 f[0], f[1], 1e-4, 60.0, 1.0)
    assert ok and res <= 1e-4
    assert w_N == pytest.approx(6.0, abs=0.02) and w_E == pytest.approx(-0.5, abs=0.02)


def test_no_estimate_when_nothing_is_unexplained_or_the_model_has_no_horizontal_force():
    veh = load_vehicle("caltech_vtol")
    theta, model = tuple(veh.theta_scaled), tuple(veh.model_kernel)
    R = _rows_yaw(0.3)
    # still air, the model explains the force: the cold start has no direction, the solution stays at zero
    # wind and the caller's "wind gone" rule (airspeed below the hover blend) ends the estimate
    f = forces.body_force((0.0, 0.0, 0.0), 0.0, 0.6, theta, model)
    ok, w_N, w_E, res = estimate_horizontal_wind((0.0, 0.0, 0.0), R, 0.0, 0.0, 0.0, True, 0.0, 0.6, theta, model,
                                                 f[0], f[1], 0.1, 60.0, 1.0)
    assert (w_N, w_E) == (0.0, 0.0) and res <= 0.1
    # degenerate: no drag, no lift, no rotor side force -> the horizontal force does not depend on the wind
    flat = tuple(0.0 if k not in (forces.I_CTX, forces.I_CTZ) else theta[k] for k in range(8))
    ok, w_N, w_E, res = estimate_horizontal_wind((0.0, 0.0, 0.0), R, 0.0, 0.0, 0.0, True, 0.0, 0.6, flat, model,
                                                 0.5, 0.0, 0.1, 60.0, 1.0)
    assert not ok and np.isfinite(w_N) and np.isfinite(w_E)


def test_guards_reject_too_fast_too_far_sideways_and_unexplainable_forces():
    veh = load_vehicle("caltech_vtol")
    theta, model = tuple(veh.theta_scaled), tuple(veh.model_kernel)
    R = _rows_yaw(0.0)
    f = forces.body_force((-10.0, 0.0, 0.0), 0.0, 0.6, theta, model)
    args = ((0.0, 0.0, 0.0), R, 0.0, 0.0, 0.0, True, 0.0, 0.6, theta, model, f[0], f[1], 1e-3)
    assert estimate_horizontal_wind(*args, 60.0, 1.0)[0]
    assert not estimate_horizontal_wind(*args, 8.0, 1.0)[0]          # above the probe's maximum airspeed
    f = forces.body_force((0.0, 8.0, 0.0), 0.0, 0.6, theta, model)
    side = ((0.0, 0.0, 0.0), R, 0.0, 0.0, 0.0, True, 0.0, 0.6, theta, model, f[0], f[1], 1e-3, 60.0)
    assert estimate_horizontal_wind(*side, 1.0)[0]
    assert not estimate_horizontal_wind(*side, SIN_SIDESLIP_MAX)[0]  # beyond 30 deg of sideslip
    # 50 m/s^2 sideways: beyond anything the model gives below 60 m/s of airspeed -> not converged
    out = estimate_horizontal_wind((0.0, 0.0, 0.0), R, 0.0, 0.0, 0.0, True, 0.0, 0.6, theta, model, 0.0, 50.0,
                                   0.1, 60.0, 1.0)
    assert not out[0] and all(np.isfinite(out[1:3]))


BAD = st.sampled_from([np.nan, np.inf, -np.inf, 1e308, -1e308, 0.0, 1e-300])


@settings(max_examples=examples(80), deadline=None)
@given(a_x=BAD | st.floats(-30, 30), a_y=BAD | st.floats(-30, 30), v=BAD | st.floats(-20, 20),
       w0=BAD | st.floats(-20, 20), u_z=BAD | st.floats(0, 1), cold=st.booleans(), th=BAD | st.floats(0.5, 1.5))
def test_never_nan(a_x, a_y, v, w0, u_z, cold, th):
    """Non-finite or huge inputs: "no estimate" or a finite one, never NaN."""
    veh = load_vehicle("px4_standard_vtol")
    with np.errstate(invalid="ignore", over="ignore"):
        theta = tuple(veh.theta_scaled * th)
    out = estimate_horizontal_wind((v, 0.0, 0.0), _rows_yaw(0.4), 0.0, w0, 0.0, cold, 0.1, u_z, theta,
                                   tuple(veh.model_kernel), a_x, a_y, 0.1, 60.0, SIN_SIDESLIP_MAX)
    ok, w_N, w_E, res = out
    assert np.isfinite(w_N) and np.isfinite(w_E) and not np.isnan(res)
    if ok:
        assert res <= 0.1


def test_setting_is_validated_and_packed():
    veh = load_vehicle("caltech_vtol")
    assert ControllerConfig().unseen_flow_estimate is False
    p = controller_params(controller_config_from_mapping({"unseen_flow_estimate": True,
                                                           "unseen_flow_estimate_time_constant_s": 0.5}), veh)
    assert p[P_FLOW_EST_ON] == 1.0 and p[P_FLOW_EST_TAU] == 0.5
    assert controller_params(ControllerConfig(), veh)[P_FLOW_EST_ON] == 0.0
    with pytest.raises(ConfigError, match="unseen_flow_estimate_time_constant_s"):
        controller_config_from_mapping({"unseen_flow_estimate_time_constant_s": 0.0}, "s.toml")
    with pytest.raises(ConfigError, match="unseen_flow_estimate"):
        controller_config_from_mapping({"unseen_flow_estimate": "yes"}, "s.toml")


# sha256 of the 750 commands of _tail_wind_ticks with the default configuration, recorded from the code
# before the estimate existed (commit 13a5a19): the setting off is today's controller bit for bit.
COMMANDS_BEFORE_SHA256 = "daf43b26a8fac169c36a4e3ae6ed6dfc7c873c8c15546831bca18ba4f6d3410d"


def _tail_wind_ticks(config, probe_behind_flow=True):
    """Hover at rest and level, the probe reads "invalid, zero", the accelerometer feels a tail wind's drag
    growing from 0.5 s on (forward, up to 0.6 m/s^2): the open-loop situation of a fan starting behind."""
    import hashlib

    from vtoladapt.control import Controller, Measurement, Reference

    ctrl = Controller(load_vehicle("caltech_vtol"), config)
    ref = Reference.hold((0.0, 0.0, -1.5))
    cmds, est_on, wind = [], [], []
    for k in range(750):
        t = 0.004 * k
        drag = 0.0 if t < 0.5 else min(0.6, 0.4 * (t - 0.5))
        m = Measurement.from_parts((0.0, 0.0, -1.5), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                   (drag, 0.0, -9.80665), (0.0, 0.0, 0.0), v_i_valid=False)
        cmds.append(np.array(ctrl.step(t, m, ref)._a, dtype=float))
        est_on.append(ctrl.diagnostics["unseen_flow_estimate"])
        wind.append(ctrl.state.wind_estimate.copy())
    return hashlib.sha256(np.array(cmds).tobytes()).hexdigest(), np.array(est_on), np.array(wind)


def test_off_is_todays_controller_bit_for_bit_and_on_fires_in_a_tail_wind():
    digest, est_on, wind = _tail_wind_ticks(ControllerConfig())
    assert digest == COMMANDS_BEFORE_SHA256
    assert not est_on.any()
    digest_on, est_on, wind_on = _tail_wind_ticks(ControllerConfig(unseen_flow_estimate=True))
    assert digest_on != COMMANDS_BEFORE_SHA256
    assert est_on[-1] == 1.0 and not est_on[:125].any()
    # the drag pushes the aircraft forward (north): the wind blows north, from behind; the fallback alone
    # keeps a still-air wind estimate
    assert wind_on[-1][0] > 2.0 and abs(wind_on[-1][1]) < 0.1 * wind_on[-1][0]
    assert np.abs(wind[-1]).max() < 1e-9
