"""A small closed loop: the controller flying a 6-DOF rigid body whose force model differs from its own.

The plant here is deliberately minimal and independent of the project's simulator: eq:pos_dyn and
eq:att_dyn with the paper's linear force model at a *different* theta (the truth), first-order
lag on throttles and moments, constant wind after a ramp, perfect sensors. The adaptive
controller must learn the difference; the PD baseline, with the same gains and the prior model,
must keep a steady position error.
"""
from __future__ import annotations

import numpy as np
import pytest

from vtoladapt import forces
from vtoladapt.control import Controller, ControllerConfig, Measurement, Reference
from vtoladapt.frames import GRAVITY_MPS2, quat_multiply, quat_normalize, quat_to_rotmat

TRUTH_FACTORS = np.array([1.0, 0.93, 1.5, 1.4, 1.0, 1.0, 0.7, 0.95])
DT = 0.004
SUB = 4
LAG_S = 0.03


def _fly(vehicle, kind, duration_s=25.0):
    theta_true = vehicle.theta_scaled * TRUTH_FACTORS
    model = vehicle.model_kernel
    J = vehicle.mass.inertia_matrix
    J_inv = np.linalg.inv(J)
    ctrl = Controller(vehicle, ControllerConfig(kind=kind))
    ref = Reference.hold((0.0, 0.0, -1.5))
    p = np.array([0.0, 0.0, -1.5])
    v = np.zeros(3)
    q = np.array([1.0, 0.0, 0.0, 0.0])
    w = np.zeros(3)
    u = np.array([0.0, np.sqrt(GRAVITY_MPS2 / theta_true[1])])
    tau = np.zeros(3)
    f = np.empty(3)
    meas = Measurement()
    n = int(duration_s / DT)
    log = {"p": np.empty((n, 3)), "e": np.empty((n, 3)), "theta": np.empty((n, 8))}
    h = DT / SUB
    for k in range(n):
        t = k * DT
        wind = np.array([-6.0 * min(max((t - 2.0) / 2.0, 0.0), 1.0), 0.0, 0.0])
        R = quat_to_rotmat(q)
        v_i = R.T @ (v - wind)
        forces.body_force(v_i, u[0], u[1], theta_true, model, f)
        a = meas.array
        a[0:3], a[3:6], a[6:10], a[10:13], a[13:16], a[16:19], a[19] = p, v, q, w, f, v_i, 1.0
        cmd = ctrl.step(t, meas, ref)
        for _ in range(SUB):
            R = quat_to_rotmat(q)
            forces.body_force(R.T @ (v - wind), u[0], u[1], theta_true, model, f)
            v_dot = R @ f + np.array([0.0, 0.0, GRAVITY_MPS2])
            w_dot = J_inv @ (np.cross(J @ w, w) + tau)
            p = p + h * v
            v = v + h * v_dot
            q = quat_normalize(q + 0.5 * h * quat_multiply(q, np.array([0.0, *w])))
            w = w + h * w_dot
            u = u + h / LAG_S * (np.array([cmd.u_x, cmd.u_z]) - u)
            tau = tau + h / LAG_S * (cmd.tau_B - tau)
        d = ctrl.diagnostics_array
        log["p"][k] = p
        log["e"][k] = [ctrl.diagnostics[f"pred_err_{c}_mps2"] for c in "xyz"] if k % 50 == 0 else np.nan
        log["theta"][k] = ctrl.state.theta_hat if k % 50 == 0 else np.nan
        assert np.all(np.isfinite(d))
    return log, theta_true


PD_DURATION_S = 12.0
"""The PD learns nothing, so its flight only has to settle: the wind ramp ends at 4 s and its slowest
closed-loop mode decays at about 1 /s with the shared gains (vertical ``s^2 + (K_v + Lambda_p) s +
K_v Lambda_p`` = (s + 1)(s + 4)), so from 7 s its error is steady to e^-3 and its last 5 s compare
with the composite's last 5 s of a 25 s flight, at half the PD flight's cost (a Python loop)."""


@pytest.fixture(scope="module")
def flights(caltech):
    return {"composite": _fly(caltech, "composite"), "pd": _fly(caltech, "pd", PD_DURATION_S)}


def test_composite_learns_the_model_and_holds_position(flights):
    log, theta_true = flights["composite"]
    p_err_late = np.linalg.norm(log["p"][-1250:] - [0.0, 0.0, -1.5], axis=1)
    assert p_err_late.max() < 0.05                                    # m, last 5 s
    e = log["e"][-2500:]
    e = np.linalg.norm(e[np.isfinite(e[:, 0])], axis=1)
    assert np.sqrt(np.mean(e ** 2)) < 0.05 * GRAVITY_MPS2             # the paper's 0.05 g
    # the well-excited lift coefficient moved most of the way to the truth. (0.35: the flow-angle
    # protection flies this truth's weaker wing at a lower alpha and gives the lift to the rotors;
    # the wing/rotor lift split is what these data fix least: 31 % of the prior's error left with
    # it, 28 % without, measured.)
    th = log["theta"][np.isfinite(log["theta"][:, 0])][-1]
    th0 = theta_true / TRUTH_FACTORS
    assert abs(th[1] - theta_true[1]) < 0.35 * abs(th0[1] - theta_true[1])


def test_pd_with_the_prior_model_keeps_a_steady_error(flights):
    log_pd, _ = flights["pd"]
    log_c, _ = flights["composite"]
    err = {k: np.linalg.norm(lg["p"][-1250:] - [0.0, 0.0, -1.5], axis=1).mean()
           for k, lg in (("pd", log_pd), ("composite", log_c))}
    assert err["pd"] > 0.1
    assert err["pd"] > 5 * err["composite"]
