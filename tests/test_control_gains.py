"""The default gains against a linearised, sampled model of each loop (the stability argument for the defaults).

Each loop is linearised about hover, the plant (with the first-order motor lag of the vehicle
file) is discretised exactly for the 4 ms zero-order hold, and the controller's law (eq:wr,
eq:f_ctrl, eq:m_ctrl, or the PX4 PID) closes the loop at the ticks. The closed loop must be
stable with damped poles. ``omega_d`` feed-forward is left out (it is filtered and only helps).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.linalg import expm

from vtoladapt.control import ControllerConfig
from vtoladapt.frames import GRAVITY_MPS2

DT = 0.004


def _discretise(A, B):
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A
    M[:n, n:] = B
    E = expm(M * DT)
    return E[:n, :n], E[:n, n:]


def _closed_loop_poles(A, B, F):
    Ad, Bd = _discretise(A, B)
    z = np.linalg.eigvals(Ad + Bd @ F)
    return z


def _damping(z):
    s = np.log(z.astype(complex)) / DT
    return -s.real / np.abs(s)


def _attitude_rows(J, tau_m, Lq, Kw):
    """States [theta, omega, tau_actual]; tau_c = J w_r' - K_w (w - w_r), w_r = -Lq theta/2."""
    A = np.array([[0, 1, 0], [0, 0, 1 / J], [0, 0, -1 / tau_m]])
    B = np.array([[0], [0], [1 / tau_m]])
    F = np.array([[-Kw * Lq / 2, -J * Lq / 2 - Kw, 0.0]])
    return A, B, F


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_attitude_loop_is_stable_and_damped(any_vehicle, axis):
    cfg = ControllerConfig()
    J = any_vehicle.mass.inertia_kgm2[axis]
    Kw = J * cfg.rate_bandwidth_radps[axis]
    tau_m = any_vehicle.actuators.lift_motor_time_constant_s
    z = _closed_loop_poles(*_attitude_rows(J, tau_m, cfg.Lambda_q[axis], Kw))
    assert np.abs(z).max() < 0.99
    assert _damping(z).min() > 0.45


def _ff_lp(cfg, kind, Lp):
    """The velocity coefficient the reference feed-forward adds: v_r' = -Lp v in hover (eq:f_ctrl and
    the baselines' ``feedforward = "v_r_dot"``); 0 for a baseline feeding forward a_d only."""
    return Lp if kind == "adaptive" or getattr(cfg, kind).feedforward == "v_r_dot" else 0.0


def _with_feedforward(cfg, kind, feedforward):
    return cfg if feedforward is None else dataclasses.replace(
        cfg, **{kind: dataclasses.replace(getattr(cfg, kind), feedforward=feedforward)})


KINDS = [("adaptive", None), ("pid", "v_r_dot"), ("pid", "a_d"), ("pd", "v_r_dot"), ("pd", "a_d")]


def _horizontal(vehicle, cfg, kind):
    """States [x, v, theta, omega, tau_a, I, a_f] for the pitch axis driving north velocity in hover.

    a_x = -g theta; theta_d = -f_x / g; f_x from eq:f_ctrl (adaptive) or PX4's PID (with its
    feed-forward: v_r' or a_d = 0); I and the filtered acceleration a_f evolve in continuous time
    (their sampling is immaterial at 250 Hz).
    """
    g = GRAVITY_MPS2
    J = vehicle.mass.inertia_kgm2[1]
    Kw = J * cfg.rate_bandwidth_radps[1]
    Lq = cfg.Lambda_q[1]
    tau_m = vehicle.actuators.lift_motor_time_constant_s
    Kv, Lp = cfg.K_v[0], cfg.Lambda_p[0]
    baseline = getattr(cfg, kind) if kind in ("pid", "pd") else cfg.pid     # the law's own table
    KI = baseline.K_I[0] if kind == "pid" else 0.0
    KD = baseline.K_D[0] if kind in ("pid", "pd") else 0.0
    wf = 2 * np.pi * baseline.derivative_cutoff_hz
    A = np.zeros((7, 7))
    A[0, 1] = 1.0
    A[1, 2] = -g
    A[2, 3] = 1.0
    A[3, 4] = 1 / J
    A[4, 4] = -1 / tau_m
    # v~ = v + Lp x ; I' = -K_I v~ ; a_f' = wf (v' - a_f) with v' = -g theta
    A[5, 0] = -KI * Lp
    A[5, 1] = -KI
    A[6, 2] = -wf * g
    A[6, 6] = -wf
    B = np.zeros((7, 1))
    B[4, 0] = 1 / tau_m
    # f_x as a row over the states
    if kind == "adaptive":
        fx = np.array([-Kv * Lp, -Kv - Lp, 0, 0, 0, 0, 0])          # v_r' - K_v v~
    else:
        # ff + K_v (v_sp - v) + I - K_D a_f
        fx = np.array([-Kv * Lp, -Kv - _ff_lp(cfg, kind, Lp), 0, 0, 0, 1.0, -KD])
    theta_d = -fx / g
    e_theta = np.zeros(7)
    e_theta[2] = 1.0
    e_theta -= theta_d
    F = (-Kw * Lq / 2) * e_theta
    F[3] += -J * Lq / 2 - Kw
    return A, B, F[None, :]


@pytest.mark.parametrize("kind,feedforward", KINDS)
def test_horizontal_velocity_loop_through_the_attitude_is_stable(any_vehicle, kind, feedforward):
    cfg = _with_feedforward(ControllerConfig(), kind, feedforward)
    A, B, F = _horizontal(any_vehicle, cfg, kind)
    keep = [i for i in range(7) if not (i == 5 and kind != "pid") and not (i == 6 and kind == "adaptive")]
    z = _closed_loop_poles(A[np.ix_(keep, keep)], B[keep], F[:, keep])   # drop states the law does not use
    assert np.abs(z).max() < 0.9999
    assert _damping(z).min() > 0.3


@pytest.mark.parametrize("kind,feedforward", KINDS)
def test_vertical_velocity_loop_through_the_lift_motors_is_stable(any_vehicle, kind, feedforward):
    """States [z, v, a_actual, I]; the lift acceleration follows its command through the motor lag."""
    cfg = _with_feedforward(ControllerConfig(), kind, feedforward)
    tau_m = any_vehicle.actuators.lift_motor_time_constant_s
    Kv, Lp = cfg.K_v[2], cfg.Lambda_p[2]
    KI = cfg.pid.K_I[2] if kind == "pid" else 0.0
    A = np.array([[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, -1 / tau_m, 0], [-KI * Lp, -KI, 0, 0]])
    B = np.array([[0], [0], [1 / tau_m], [0]])
    if kind == "adaptive":
        F = np.array([[-Kv * Lp, -Kv - Lp, 0, 0]])
    else:
        F = np.array([[-Kv * Lp, -Kv - _ff_lp(cfg, kind, Lp), 0, 1.0]])
    keep = [0, 1, 2, 3] if kind == "pid" else [0, 1, 2]
    z = _closed_loop_poles(A[np.ix_(keep, keep)], B[keep], F[:, keep])
    assert np.abs(z).max() < 0.9999
    assert _damping(z).min() > 0.3


def test_a_gain_far_too_high_is_caught():
    """The check can fail: a 10x rate bandwidth is unstable through the motor lag at 250 Hz."""
    cfg = ControllerConfig(rate_bandwidth_radps=(200.0, 200.0, 200.0))
    J = 0.06
    z = _closed_loop_poles(*_attitude_rows(J, 0.03, cfg.Lambda_q[1], J * 200.0))
    assert np.abs(z).max() >= 0.99 or _damping(z).min() < 0.45
