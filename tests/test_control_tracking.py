"""Tracking laws (eq:wr, eq:f_ctrl, eq:m_ctrl) against hand-derived cases, numpy and finite differences."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vtoladapt.control.tracking import (
    force_command,
    moment_command,
    quat_error_from_quats,
    reference_angular_acceleration,
    reference_angular_rate,
    reference_velocity,
)
from vtoladapt.frames import GRAVITY_MPS2, quat_error_constrained, quat_to_rotmat, skew


def _q(rot: Rotation) -> np.ndarray:
    """scipy (scalar last) -> ours (scalar first)."""
    return rot.as_quat()[[3, 0, 1, 2]]


def test_quaternion_error_matches_frames_for_random_rotations(rng):
    for _ in range(200):
        qa = _q(Rotation.random(random_state=rng.integers(1 << 31)))
        qb = _q(Rotation.random(random_state=rng.integers(1 << 31)))
        ours = quat_error_from_quats(qa, qb)
        ref = quat_error_constrained(quat_to_rotmat(qa), quat_to_rotmat(qb))
        assert ours[0] >= 0.0
        np.testing.assert_allclose(ours, ref, atol=1e-12)


@pytest.mark.parametrize("R_d, R, expected", [
    # body rolled 30 deg right of a level desired frame: q~ = [cos 15, sin 15, 0, 0]
    (Rotation.identity(), Rotation.from_euler("x", 30, degrees=True),
     [np.cos(np.radians(15)), np.sin(np.radians(15)), 0.0, 0.0]),
    # desired heading 90 deg, body heading 0: R~ = Rz(-90)
    (Rotation.from_euler("z", 90, degrees=True), Rotation.identity(),
     [np.cos(np.radians(45)), 0.0, 0.0, -np.sin(np.radians(45))]),
    # 200 deg about z is the long way: the constrained error is -160 deg, q0 > 0
    (Rotation.identity(), Rotation.from_euler("z", 200, degrees=True),
     [np.cos(np.radians(80)), 0.0, 0.0, -np.sin(np.radians(80))]),
])
def test_quaternion_error_hand_cases(R_d, R, expected):
    np.testing.assert_allclose(quat_error_from_quats(_q(R_d), _q(R)), expected, atol=1e-12)


def test_reference_velocity_and_force_command_hand_case():
    p_tilde = np.array([1.0, -2.0, 0.5])
    v_d = np.array([0.3, 0.0, -0.1])
    a_d = np.array([0.1, 0.2, 0.0])
    v = np.array([0.5, -0.2, 0.0])
    Lp = np.array([0.95, 0.95, 1.0])
    v_r_out = np.empty(3)
    v_r_dot_out = np.empty(3)
    v_r, v_r_dot, saturated = reference_velocity(p_tilde, v_d, a_d, v, Lp, 100.0, v_r_out, v_r_dot_out)
    assert not saturated
    np.testing.assert_allclose(v_r, [0.3 - 0.95, 1.9, -0.6], atol=1e-15)
    np.testing.assert_allclose(v_r_dot, [0.1 - 0.95 * 0.2, 0.2 + 0.95 * 0.2, -0.1], atol=1e-15)
    # the optional output arrays receive the same values, as does the call without them
    np.testing.assert_array_equal(v_r_out, v_r)
    np.testing.assert_array_equal(v_r_dot_out, v_r_dot)
    assert reference_velocity(p_tilde, v_d, a_d, v, Lp, 100.0) == (v_r, v_r_dot, saturated)
    Kv = np.array([1.8, 1.8, 4.0])
    v_tilde = v - np.array(v_r)
    f_r = force_command(v_r_dot, v_tilde, Kv)
    np.testing.assert_allclose(f_r, v_r_dot - Kv * v_tilde - np.array([0, 0, GRAVITY_MPS2]), atol=1e-14)


def test_saturated_reference_velocity_derivative_by_finite_differences():
    Lp = np.array([0.95, 0.8, 1.0])
    p_d = np.array([0.0, 0.0, -1.5])
    v_d = np.array([1.0, -0.5, 0.2])
    a_d = np.array([0.3, 0.1, -0.2])
    p = np.array([7.0, -3.0, 2.0])
    v = np.array([0.4, 1.1, -0.3])
    cmax = 2.0

    def vr(h):
        pt = (p + v * h) - (p_d + v_d * h + 0.5 * a_d * h * h)
        out, out_dot, sat = reference_velocity(pt, v_d + a_d * h, a_d, v, Lp, cmax)
        return np.array(out), np.array(out_dot), sat

    v0, vdot0, sat = vr(0.0)
    assert sat
    assert np.linalg.norm(v_d - v0) == pytest.approx(cmax, rel=1e-12)
    h = 1e-6
    fd = (vr(h)[0] - vr(-h)[0]) / (2 * h)
    np.testing.assert_allclose(vdot0, fd, atol=1e-7)


def test_reference_angular_rate_identity_error_passes_omega_d_through():
    w_d = np.array([0.1, -0.2, 0.3])
    out = reference_angular_rate(w_d, np.array([1.0, 0, 0, 0]), np.array([10.0, 10.0, 6.0]))
    np.testing.assert_allclose(out, w_d, atol=1e-15)


def _attitude_at(R0: Rotation, omega, alpha, t) -> Rotation:
    """Attitude after time t under body rate omega + alpha t (second-order Magnus, exact enough for h^2)."""
    omega = np.asarray(omega)
    alpha = np.asarray(alpha)
    return R0 * Rotation.from_rotvec(omega * t + 0.5 * alpha * t * t)


def test_reference_angular_acceleration_by_finite_differences(rng):
    Lq = np.array([10.0, 8.0, 6.0])
    for _ in range(20):
        R0 = Rotation.random(random_state=rng.integers(1 << 31))
        Rd0 = R0 * Rotation.from_rotvec(rng.normal(0, 0.6, 3))  # within ~1 rad of R
        w = rng.normal(0, 1.0, 3)
        w_d = rng.normal(0, 1.0, 3)
        w_d_dot = rng.normal(0, 2.0, 3)

        def omega_r(t):
            R = _attitude_at(R0, w, np.zeros(3), t)
            Rd = _attitude_at(Rd0, w_d, w_d_dot, t)
            q = quat_error_from_quats(_q(Rd), _q(R))
            return np.array(reference_angular_rate(quat_to_rotmat(q).T @ (w_d + w_d_dot * t), q, Lq))

        q0 = quat_error_from_quats(_q(Rd0), _q(R0))
        R_tilde = quat_to_rotmat(q0)
        analytic = reference_angular_acceleration(q0, w, R_tilde.T @ w_d, R_tilde.T @ w_d_dot, Lq)
        h = 1e-5
        fd = (omega_r(h) - omega_r(-h)) / (2 * h)
        np.testing.assert_allclose(analytic, fd, atol=1e-5)


def test_moment_command_matches_direct_evaluation_and_dissipates_rate_error(rng):
    J = np.array([[0.055, 0.0, -0.003], [0.0, 0.060, 0.0], [-0.003, 0.0, 0.105]])
    Kw = np.array([1.1, 1.2, 1.05])
    for _ in range(20):
        w, wr, wrd = rng.normal(0, 2, 3), rng.normal(0, 2, 3), rng.normal(0, 5, 3)
        tau = np.array(moment_command(J, w, wr, wrd, Kw))
        direct = J @ wrd - skew(J @ w) @ wr - Kw * (w - wr)
        np.testing.assert_allclose(tau, direct, atol=1e-13)
        # with the paper's plant J w' = S(J w) w + tau, d/dt (w~^T J w~ / 2) = -w~^T K_omega w~
        w_dot = np.linalg.solve(J, skew(J @ w) @ w + tau)
        wt = w - wr
        assert wt @ J @ (w_dot - wrd) == pytest.approx(-(wt * Kw) @ wt, rel=1e-9, abs=1e-12)
