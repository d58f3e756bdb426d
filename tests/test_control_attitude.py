"""Desired attitude (eq:fbar_solve, eq:alphad, eq:Rd) and the hover blend."""
from __future__ import annotations

import numpy as np
import pytest

from vtoladapt.control.attitude import (
    desired_angle_of_attack,
    desired_attitude,
    hover_blend_weight,
    multirotor_attitude,
    wing_attitude,
)
from vtoladapt.frames import GRAVITY_MPS2, quat_to_rotmat

CL0, CL1 = 0.3705, 3.2502
A = 1.225 * 0.223 / (2 * 1.70)      # rho S / (2 m) of the paper's aircraft, 1/m
AMIN, AMAX = -np.radians(15), np.radians(15)
V_LO, V_HI = 2.0, 4.0
TILT, LIFT_MIN = np.radians(45), 1.0


def _desired(f_r, v_i_W, yaw=0.0, y_prev=(0.0, 1.0, 0.0), have_prev=False):
    q, _, alpha, w, formed = desired_attitude(np.asarray(f_r, float), np.asarray(v_i_W, float), yaw, CL0, CL1, A,
                                              AMIN, AMAX, V_LO, V_HI, TILT, LIFT_MIN, np.asarray(y_prev, float),
                                              have_prev)
    return np.array(q), alpha, w, formed


def _angles_in(R_d, v_i_W):
    v = R_d.T @ v_i_W
    return np.arctan2(v[2], v[0]), v[1] / np.linalg.norm(v)


def _draw_wingborne(rng):
    """An airspeed above the hover blend, a flow from any direction and a demanded force near 1 g."""
    V = rng.uniform(V_HI, 25.0)
    d = rng.normal(size=3)
    f_r = np.array([0.0, 0.0, -GRAVITY_MPS2]) + rng.normal(0, 3, 3)
    return V, V * d / np.linalg.norm(d), f_r


def test_wing_solution_flies_alpha_d_at_zero_sideslip_and_no_side_force(rng):
    n_unsat = 0
    for _ in range(300):
        V, v_i_W, f_r = _draw_wingborne(rng)
        R_d, alpha_d, lift = wing_attitude(v_i_W, f_r, CL0, CL1, A, AMIN, AMAX, np.zeros(3), False, 0.0)
        R_d = np.array(R_d)
        np.testing.assert_allclose(R_d.T @ R_d, np.eye(3), atol=1e-12)
        assert np.linalg.det(R_d) == pytest.approx(1.0, abs=1e-12)
        alpha, sin_beta = _angles_in(R_d, v_i_W)
        assert alpha == pytest.approx(alpha_d, abs=1e-10)     # eq:Rd realises eq:alphad's angle
        assert abs(sin_beta) < 1e-12                          # beta = 0: no side force needed
        assert abs(R_d[:, 1] @ f_r) < 1e-9 * np.linalg.norm(f_r)   # y_i normal to f_r
        # the lift demanded is the part of f_r normal to the flow
        x = v_i_W / V
        assert lift == pytest.approx(np.linalg.norm(f_r - (f_r @ x) * x), rel=1e-9)
        if AMIN < alpha_d < AMAX:
            n_unsat += 1
            q = A * V * V
            assert q * (CL0 + CL1 * alpha_d) == pytest.approx(lift, rel=1e-10)
    assert n_unsat > 30


def test_lift_rotor_reserve_leaves_that_much_lift_to_the_rotors(rng):
    """With a reserve r the wing's model lift at alpha_d is the demanded lift minus r (eq:alphad solved
    for lift - r) wherever that is inside the alpha limits; the attitude is otherwise the same
    construction (same flow axes, sideslip 0), and r = 0 is the paper's alpha_d bit for bit."""
    reserve = 5.0
    n_unsat = 0
    for _ in range(200):
        V, v_i_W, f_r = _draw_wingborne(rng)
        R0, a0, lift0 = wing_attitude(v_i_W, f_r, CL0, CL1, A, AMIN, AMAX, np.zeros(3), False, 0.0)
        Rr, ar, liftr = wing_attitude(v_i_W, f_r, CL0, CL1, A, AMIN, AMAX, np.zeros(3), False, 0.0, reserve)
        Rz, az, _ = wing_attitude(v_i_W, f_r, CL0, CL1, A, AMIN, AMAX, np.zeros(3), False, 0.0, 0.0)
        assert az == a0 and np.array_equal(np.array(Rz), np.array(R0))
        assert liftr == lift0                                   # the demanded lift is unchanged
        assert ar <= a0                                         # the wing never flies higher alpha
        np.testing.assert_allclose(np.array(Rr)[:, 1], np.array(R0)[:, 1], atol=1e-12)   # same y_i
        alpha, sin_beta = _angles_in(np.array(Rr), v_i_W)
        assert alpha == pytest.approx(ar, abs=1e-10) and abs(sin_beta) < 1e-12
        if AMIN < ar < AMAX:
            n_unsat += 1
            assert A * V * V * (CL0 + CL1 * ar) == pytest.approx(lift0 - reserve, rel=1e-10, abs=1e-10)
    assert n_unsat > 30


def test_alpha_d_saturates_on_both_sides_and_is_continuous():
    V = 9.0
    q = A * V * V
    L_max = q * (CL0 + CL1 * AMAX)
    L_min = q * (CL0 + CL1 * AMIN)
    assert desired_angle_of_attack(L_max + 5, V, CL0, CL1, A, AMIN, AMAX) == AMAX
    assert desired_angle_of_attack(L_min - 5, V, CL0, CL1, A, AMIN, AMAX) == AMIN
    lifts = np.linspace(L_min - 1, L_max + 1, 20001)
    alphas = np.array([desired_angle_of_attack(L, V, CL0, CL1, A, AMIN, AMAX) for L in lifts])
    assert np.max(np.abs(np.diff(alphas))) <= (lifts[1] - lifts[0]) / (q * CL1) + 1e-12
    # V = 0: no lift available; any positive demand saturates at alpha_max, no NaN
    assert desired_angle_of_attack(9.8, 0.0, CL0, CL1, A, AMIN, AMAX) == AMAX


@pytest.mark.parametrize("yaw", [0.0, 1.0, -2.5])
def test_multirotor_attitude_hover_and_tilt(yaw):
    def R_d(f_r):
        return np.array(multirotor_attitude(np.asarray(f_r, float), yaw, TILT, LIFT_MIN))

    R = R_d([0.0, 0.0, -GRAVITY_MPS2])
    c, s = np.cos(yaw), np.sin(yaw)
    np.testing.assert_allclose(R, [[c, -s, 0], [s, c, 0], [0, 0, 1]], atol=1e-12)
    f_r = np.array([2.0, -1.0, -GRAVITY_MPS2])
    R = R_d(f_r)
    np.testing.assert_allclose(-R[:, 2], f_r / np.linalg.norm(f_r), atol=1e-12)   # body -z along f_r
    assert abs(R[:, 1] @ np.array([c, s, 0.0])) < 1e-12                           # heading kept
    # a horizontal command is tilt-limited; f_r = 0 and a downward f_r stay upright and finite
    R = R_d([50.0, 0.0, -1.0])
    assert np.degrees(np.arccos(R[2, 2])) == pytest.approx(45.0, abs=1e-9)
    for f in ([0.0, 0.0, 0.0], [0.0, 0.0, 30.0]):
        np.testing.assert_allclose(R_d(f)[:, 2], [0, 0, 1], atol=1e-12)


def test_blend_weight_is_c1_and_clamped():
    V = np.linspace(0, 6, 60001)
    w = np.array([hover_blend_weight(v, V_LO, V_HI) for v in V])
    assert w[V <= V_LO].max() == 0.0 and w[V >= V_HI].min() == 1.0
    dw = np.diff(w) / np.diff(V)
    assert np.max(np.abs(np.diff(dw))) < 1e-3     # derivative continuous (no kink at V_lo, V_hi)
    assert hover_blend_weight(np.nan, V_LO, V_HI) == 0.0


@pytest.mark.parametrize("heading_deg", [0.0, 30.0, 120.0])
def test_desired_attitude_continuous_across_the_blend_band(heading_deg):
    yaw = np.radians(heading_deg)
    f_r = np.array([0.5, 0.2, -GRAVITY_MPS2])
    d = np.array([np.cos(yaw), np.sin(yaw), 0.05])
    d /= np.linalg.norm(d)
    prev = None
    max_step = 0.0
    dV = 1e-3
    for V in np.arange(0.0, 6.0, dV):
        q, alpha, w, _ = _desired(f_r, V * d, yaw)
        assert np.all(np.isfinite(q))
        if prev is not None:
            max_step = max(max_step, 2 * np.arccos(min(1.0, abs(prev @ q))))
        prev = q
    # the two solutions differ by ~30 deg here; spread over 2 m/s the steepest slope is ~0.4 rad per m/s
    assert max_step < 1.0 * dV + 1e-9


def test_no_nan_in_degenerate_cases():
    cases = [
        ([0, 0, -GRAVITY_MPS2], [0, 0, 0]),           # V = 0
        ([0, 0, -GRAVITY_MPS2], [0, 0, 1e-300]),      # V tiny
        ([0, 0, -GRAVITY_MPS2], [0, 0, 5.0]),         # v_i parallel to f_r (vertical descent)
        ([0, 0, -GRAVITY_MPS2], [0, 0, -8.0]),        # v_i antiparallel to f_r (climb)
        ([0, 0, 0], [9.0, 0, 0]),                     # f_r = 0 in forward flight
        ([0, 0, 0], [0, 0, 0]),                       # both zero
        ([3.0, 0, 0], [9.0, 0, 0]),                   # f_r along the flow
    ]
    for f_r, v in cases:
        for have_prev in (False, True):
            q, alpha, w, formed = _desired(f_r, v, have_prev=have_prev)
            assert np.all(np.isfinite(q)) and np.isfinite(alpha) and np.isfinite(w)
            assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-12)


def test_y_i_continuous_when_f_r_passes_the_flow_direction():
    """f_r swinging through x_i in the x-z plane keeps y_i (no 180 deg roll flip from the fallback)."""
    v = np.array([9.0, 0.0, 0.0])
    y_prev = np.array([0.0, 1.0, 0.0])
    ys = []
    for eps in np.linspace(-1e-4, -1e-9, 50):
        f_r = np.array([3.0, 0.0, eps])      # normal component upward (-z), shrinking to ~0
        q, _, _, _ = _desired(f_r, v, y_prev=y_prev, have_prev=True)
        ys.append(quat_to_rotmat(q)[:, 1])
    ys = np.array(ys)
    assert np.all(ys[:, 1] > 0.99)
