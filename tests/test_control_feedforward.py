"""The PID's and PD's reference feed-forward (``[controller.pid|pd] feedforward``), one step, no plant.

The force command of one tick is computed by hand from the measurement and the reference
(eq:wr: ``v_r = v_d - Lambda_p p~``, ``v_r' = a_d - Lambda_p (v - v_d)``) and compared with the
controller's ``f_r``. On the first tick the derivative filter has no sample yet (``a_f = 0``) and
the integral has moved once, by ``K_I (v_r - v) dt``.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from vtoladapt.config import ConfigError
from vtoladapt.control import Controller, ControllerConfig, Measurement, Reference
from vtoladapt.control.settings import controller_config_from_mapping
from vtoladapt.control.laws.pd import PDSettings
from vtoladapt.control.laws.pid import PIDSettings
from vtoladapt.frames import GRAVITY_MPS2

P_D = np.array([1.0, -2.0, -1.5])
V_D = np.array([0.6, -0.3, 0.1])
A_D = np.array([0.2, 0.1, -0.05])
P_TILDE = np.array([0.15, -0.08, 0.04])          # small: |Lambda_p p~| far below its 5 m/s limit
V = V_D + np.array([-0.25, 0.4, 0.12])


def _f_r(config: ControllerConfig, vehicle) -> np.ndarray:
    """``f_r`` (m/s^2 NED) of the first step with the module's measurement and reference."""
    ctrl = Controller(vehicle, config)
    meas = Measurement.from_parts(p_W=P_D + P_TILDE, v_W=V, q_WB=(1.0, 0.0, 0.0, 0.0), omega_B=(0.0, 0.0, 0.0),
                                  accel_B=(0.0, 0.0, -GRAVITY_MPS2), v_i_B=V, v_i_valid=True)
    ref = Reference.from_parts(P_D, V_D, A_D)
    ctrl.step(0.0, meas, ref)
    d = ctrl.diagnostics
    return np.array([d[f"f_r_{a}_mps2"] for a in "NED"])


def _by_hand(cfg: ControllerConfig, K_I, feedforward: str) -> np.ndarray:
    K_v, L_p = np.array(cfg.K_v), np.array(cfg.Lambda_p)
    v_r = V_D - L_p * P_TILDE
    v_r_dot = A_D - L_p * (V - V_D)
    ff = v_r_dot if feedforward == "v_r_dot" else A_D
    integral = np.asarray(K_I) * (v_r - V) / cfg.loop_rate_hz
    return ff + K_v * (v_r - V) + integral - np.array([0.0, 0.0, GRAVITY_MPS2])


@pytest.mark.parametrize("kind", ["pid", "pd"])
@pytest.mark.parametrize("feedforward", ["v_r_dot", "a_d"])
def test_force_command_matches_the_hand_computation(caltech, kind, feedforward):
    base = ControllerConfig(kind=kind)
    law = dataclasses.replace(getattr(base, kind), feedforward=feedforward)
    cfg = dataclasses.replace(base, **{kind: law})
    K_I = cfg.pid.K_I if kind == "pid" else (0.0, 0.0, 0.0)
    np.testing.assert_allclose(_f_r(cfg, caltech), _by_hand(cfg, K_I, feedforward), rtol=0, atol=1e-12)


@pytest.mark.parametrize("kind", ["pid", "pd"])
def test_v_r_dot_adds_exactly_minus_lambda_p_times_the_velocity_error(caltech, kind):
    """The two settings differ by ``-Lambda_p (v - v_d)`` and nothing else."""
    cfgs = [dataclasses.replace(ControllerConfig(kind=kind), **{kind: dataclasses.replace(
        getattr(ControllerConfig(), kind), feedforward=ff)}) for ff in ("v_r_dot", "a_d")]
    diff = _f_r(cfgs[0], caltech) - _f_r(cfgs[1], caltech)
    np.testing.assert_allclose(diff, -np.array(cfgs[0].Lambda_p) * (V - V_D), rtol=0, atol=1e-12)


def test_pd_without_derivative_is_the_nominal_law(caltech):
    """With v_r' fed forward and K_D = 0 the PD *is* eq:f_ctrl with theta_0 (the fairness argument)."""
    pd = ControllerConfig(kind="pd", pd=PDSettings(K_D=(0.0, 0.0, 0.0), feedforward="v_r_dot"))
    np.testing.assert_array_equal(_f_r(pd, caltech), _f_r(ControllerConfig(kind="nominal"), caltech))


def test_defaults_feed_forward_v_r_dot():
    """The reproduction's setting: the same feed-forward as eq:f_ctrl (see laws/pid.py)."""
    assert PIDSettings().feedforward == "v_r_dot" and PDSettings().feedforward == "v_r_dot"


@pytest.mark.parametrize("kind", ["pid", "pd"])
def test_a_bad_feedforward_is_refused_in_one_line(kind):
    with pytest.raises(ConfigError) as info:
        controller_config_from_mapping({"kind": kind, kind: {"feedforward": "v_d_dot"}}, source="s.toml")
    msg = str(info.value)
    assert "\n" not in msg
    for part in ("s.toml", f"[controller.{kind}] feedforward", "'v_d_dot'", "'v_r_dot'", "'a_d'"):
        assert part in msg, (part, msg)
