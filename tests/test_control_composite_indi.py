"""composite_indi (vtoladapt.control.laws.composite_indi): a constant force outside span(Phi), closed loop.

The plant is the minimal rigid body of tests/test_control_closed_loop.py's kind (independent of the project's
simulator): the paper's force model at the controller's own theta (the model is right), plus a constant
external force ``d`` east (NED y) in still air at hover. There every column of Phi is zero along body y (no
airflow, no side force), so no theta-hat can express ``d``: the composite law settles where its velocity loop
balances it, ``K_v v~ = d`` with ``v~ = Lambda_p p~`` (the position loop's reference velocity), i.e. a steady
east position error ``d / (K_v Lambda_p)`` (analytic); composite_indi's increment measures ``d`` through the
accelerometer and cancels it: its steady error must be a small fraction of that.
"""
from __future__ import annotations

import numpy as np
import pytest

from vtoladapt import forces
from vtoladapt.control import Controller, ControllerConfig, Measurement, Reference
from vtoladapt.control.settings import controller_config_from_mapping
from vtoladapt.control.registry import adaptive_ids, composite_ids, controller_ids, controller_info
from vtoladapt.frames import GRAVITY_MPS2, quat_multiply, quat_normalize, quat_to_rotmat

DT = 0.004
SUB = 4
LAG_S = 0.03
D_EAST_MPS2 = 0.8


def _fly(vehicle, kind, duration_s, estimator="paper"):
    theta = vehicle.theta_scaled
    model = vehicle.model_kernel
    J = vehicle.mass.inertia_matrix
    J_inv = np.linalg.inv(J)
    ctrl = Controller(vehicle, controller_config_from_mapping({"kind": kind, kind: {"estimator": estimator}}))
    ref = Reference.hold((0.0, 0.0, -1.5))
    p = np.array([0.0, 0.0, -1.5])
    v = np.zeros(3)
    q = np.array([1.0, 0.0, 0.0, 0.0])
    w = np.zeros(3)
    u = np.array([0.0, np.sqrt(GRAVITY_MPS2 / theta[1])])
    tau = np.zeros(3)
    f = np.empty(3)
    meas = Measurement()
    n = int(duration_s / DT)
    log = np.empty((n, 3))
    h = DT / SUB
    d_W = np.array([0.0, D_EAST_MPS2, 0.0])
    for k in range(n):
        t = k * DT
        R = quat_to_rotmat(q)
        forces.body_force(np.zeros(3), u[0], u[1], theta, model, f)
        a = meas.array
        # the accelerometer feels the external force too (specific force, body axes)
        a[0:3], a[3:6], a[6:10], a[10:13], a[13:16], a[16:19], a[19] = p, v, q, w, f + R.T @ d_W, 0.0, 1.0
        cmd = ctrl.step(t, meas, ref)
        for _ in range(SUB):
            R = quat_to_rotmat(q)
            forces.body_force(np.zeros(3), u[0], u[1], theta, model, f)
            v_dot = R @ f + d_W + np.array([0.0, 0.0, GRAVITY_MPS2])
            w_dot = J_inv @ (np.cross(J @ w, w) + tau)
            p = p + h * v
            v = v + h * v_dot
            q = quat_normalize(q + 0.5 * h * quat_multiply(q, np.array([0.0, *w])))
            w = w + h * w_dot
            u = u + h / LAG_S * (np.array([cmd.u_x, cmd.u_z]) - u)
            tau = tau + h / LAG_S * (cmd.tau_B - tau)
        log[k] = p - (0.0, 0.0, -1.5)
        assert np.all(np.isfinite(ctrl.diagnostics_array))
    return log


@pytest.mark.slow
def test_constant_force_outside_span_is_rejected_by_composite_indi_not_composite(caltech):
    """Composite: mean east error over the last 4 s = d / (K_v Lambda_p) to 5 %; composite_indi: below 2 % of it."""
    cfg = ControllerConfig()
    static = D_EAST_MPS2 / (cfg.K_v[1] * cfg.Lambda_p[1])
    comp = _fly(caltech, "composite", 14.0)
    hyb = _fly(caltech, "composite_indi", 14.0)
    last = slice(-1000, None)
    assert comp[last, 1].mean() == pytest.approx(static, rel=0.05)
    assert np.abs(hyb[last, 1]).max() < 0.02 * static


def test_registered_as_an_adaptive_composite_law():
    assert "composite_indi" in controller_ids()
    assert "composite_indi" in adaptive_ids() and "composite_indi" in composite_ids()
    info = controller_info("composite_indi")
    assert info.adapts_theta and info.law.Settings().estimator == "paper"
