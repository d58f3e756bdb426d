"""Frames, rotations and quaternions (vtoladapt.frames) against scipy.spatial.transform.Rotation.

scipy is an independent implementation; it stores quaternions scalar LAST, ours are scalar FIRST,
so every comparison converts with ``q[[1, 2, 3, 0]]`` / ``q[[3, 0, 1, 2]]``. A quaternion and its
negative are the same rotation, so quaternions are compared up to sign.

Tolerances: 1e-12 absolute on unit-size quantities (matrices, quaternions, cross products scaled
by the inputs); Euler angles 1e-9 rad away from gimbal lock (|pitch| <= pi/2 - 0.01).
Also here: the plant-state layout (vtoladapt.layout), which packs the quaternion q_WB.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from conftest import examples
from vtoladapt import frames, layout

ATOL = 1e-12
PI = math.pi

unit = st.floats(-1.0, 1.0, allow_nan=False)
axis_components = st.tuples(unit, unit, unit).filter(lambda a: np.linalg.norm(a) > 0.1)
angles = st.floats(0.0, PI)
near_pi = st.floats(PI - 1e-9, PI)
quat_components = st.tuples(unit, unit, unit, unit).filter(lambda q: np.linalg.norm(q) > 0.1)


def unit_axis(a) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    return a / np.linalg.norm(a)


def unit_quat(q) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q)


def to_scipy(q_wxyz: np.ndarray) -> Rotation:
    return Rotation.from_quat(np.asarray(q_wxyz)[[1, 2, 3, 0]])


def from_scipy(rot: Rotation) -> np.ndarray:
    return rot.as_quat()[[3, 0, 1, 2]]


def assert_quat_equal_up_to_sign(q, q_ref, atol=ATOL):
    q, q_ref = np.asarray(q), np.asarray(q_ref)
    err = min(np.abs(q - q_ref).max(), np.abs(q + q_ref).max())
    assert err <= atol, f"{q} != +-{q_ref} (max error {err:.3e})"


def rotation_180(axis) -> np.ndarray:
    """Exactly a half turn: R = 2 n n^T - I (no sin(pi) round-off)."""
    n = unit_axis(axis)
    return 2.0 * np.outer(n, n) - np.eye(3)


# --- skew and cross ---------------------------------------------------------------------------

@given(st.tuples(*[st.floats(-1e3, 1e3)] * 3), st.tuples(*[st.floats(-1e3, 1e3)] * 3))
def test_skew_times_b_is_cross_product(a, b):
    a, b = np.array(a), np.array(b)
    S = frames.skew(a)
    scale = 1e-15 * (np.abs(a).max() * np.abs(b).max() + 1.0) * 4
    np.testing.assert_allclose(S @ b, np.cross(a, b), rtol=0, atol=scale)
    np.testing.assert_allclose(frames.cross3(a, b), np.cross(a, b), rtol=0, atol=scale)
    np.testing.assert_array_equal(S, -S.T)


# --- quaternion <-> rotation matrix ---------------------------------------------------------

@given(quat_components)
def test_quat_to_rotmat_matches_scipy(q):
    q = unit_quat(q)
    np.testing.assert_allclose(frames.quat_to_rotmat(q), to_scipy(q).as_matrix(), rtol=0, atol=ATOL)


@settings(max_examples=examples(300))
@given(axis_components, angles)
@example((1.0, 0.0, 0.0), PI).via("half turn about x")
@example((0.0, 1.0, 0.0), PI).via("half turn about y")
@example((0.0, 0.0, 1.0), PI).via("half turn about z")
@example((1.0, 1.0, 1.0), 0.0).via("identity")
def test_rotmat_to_quat_matches_scipy(axis, angle):
    R = Rotation.from_rotvec(unit_axis(axis) * angle).as_matrix()
    q = frames.rotmat_to_quat(R)
    assert q[0] >= 0.0
    assert abs(np.linalg.norm(q) - 1.0) <= 1e-15 * 4
    assert_quat_equal_up_to_sign(q, from_scipy(Rotation.from_matrix(R)))
    np.testing.assert_allclose(frames.quat_to_rotmat(q), R, rtol=0, atol=ATOL)


@settings(max_examples=examples(300))
@given(axis_components, near_pi)
@example((0.3, -0.2, 0.9), PI - 1e-9)
@example((0.0, 0.0, 1.0), PI - 1e-9)
def test_rotmat_to_quat_near_half_turn(axis, angle):
    """angle in [pi - 1e-9, pi]: w -> 0, where the naive trace formula loses all its digits."""
    n = unit_axis(axis)
    R = Rotation.from_rotvec(n * angle).as_matrix()
    q = frames.rotmat_to_quat(R)
    assert q[0] >= 0.0
    # scipy's own quaternion of the same matrix, and the analytic one from axis and angle
    assert_quat_equal_up_to_sign(q, from_scipy(Rotation.from_matrix(R)))
    q_exact = np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * n])
    assert_quat_equal_up_to_sign(q, q_exact)
    np.testing.assert_allclose(frames.quat_to_rotmat(q), R, rtol=0, atol=ATOL)
    # the recovered rotation angle, 2 atan2(|qv|, w), is good to round-off even here
    assert abs(2.0 * math.atan2(np.linalg.norm(q[1:]), q[0]) - angle) <= 1e-14 * 10


@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, -2, 3),
                                  (-0.3, 0.9, -0.1), (1e-3, 1, 1e-3)])
def test_rotmat_to_quat_exact_half_turn(axis):
    """Exactly 180 degrees (w = 0), exercising each of Shepperd's branches."""
    R = rotation_180(axis)
    q = frames.rotmat_to_quat(R)
    assert abs(q[0]) <= ATOL
    assert_quat_equal_up_to_sign(q, np.concatenate([[0.0], unit_axis(axis)]))
    assert_quat_equal_up_to_sign(q, from_scipy(Rotation.from_matrix(R)))
    np.testing.assert_allclose(frames.quat_to_rotmat(q), R, rtol=0, atol=ATOL)


@given(axis_components, angles)
def test_rotmat_from_axis_angle_matches_scipy(axis, angle):
    n = unit_axis(axis)
    np.testing.assert_allclose(frames.rotmat_from_axis_angle(n, angle),
                               Rotation.from_rotvec(n * angle).as_matrix(), rtol=0, atol=ATOL)


@given(quat_components, quat_components)
def test_quat_multiply_composes_like_matrices(p, q):
    p, q = unit_quat(p), unit_quat(q)
    pq = frames.quat_multiply(p, q)
    np.testing.assert_allclose(frames.quat_to_rotmat(pq),
                               frames.quat_to_rotmat(p) @ frames.quat_to_rotmat(q), rtol=0, atol=ATOL)
    # Hamilton product, not up to sign: scipy composes the same way
    np.testing.assert_allclose(pq, from_scipy(to_scipy(p) * to_scipy(q)), rtol=0, atol=ATOL)
    # the conjugate is the inverse
    np.testing.assert_allclose(frames.quat_multiply(p, frames.quat_conjugate(p)), [1, 0, 0, 0],
                               rtol=0, atol=ATOL)


def test_quat_normalize_degenerate_inputs_give_identity():
    for bad in (np.zeros(4), np.full(4, np.nan), np.array([np.inf, 0, 0, 0])):
        np.testing.assert_array_equal(frames.quat_normalize(bad), [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(frames.quat_normalize(np.array([0.0, 0.0, 3.0, 4.0])),
                               [0.0, 0.0, 0.6, 0.8], rtol=0, atol=1e-16)


# --- Euler angles (yaw-pitch-roll, 3-2-1 intrinsic = scipy 'ZYX') -------------------------------

yaw_roll = st.floats(-PI + 1e-6, PI - 1e-6)
pitch_ok = st.floats(-PI / 2 + 0.01, PI / 2 - 0.01)


@given(yaw_roll, pitch_ok, yaw_roll)
def test_quat_from_euler_matches_scipy_zyx(yaw, pitch, roll):
    q = frames.quat_from_euler(yaw, pitch, roll)
    assert_quat_equal_up_to_sign(q, from_scipy(Rotation.from_euler("ZYX", [yaw, pitch, roll])))


@given(quat_components)
def test_euler_from_quat_matches_scipy_zyx(q):
    q = unit_quat(q)
    # away from gimbal lock (|pitch| = pi/2, R[2, 0] = -sin(pitch) = +-1), where yaw and roll
    # are not unique
    assume(abs(to_scipy(q).as_matrix()[2, 0]) < math.cos(0.01))
    ref = to_scipy(q).as_euler("ZYX")  # [yaw, pitch, roll]
    ypr = frames.euler_from_quat(q)
    wrapped = np.angle(np.exp(1j * (ypr - ref)))
    np.testing.assert_allclose(wrapped, 0.0, rtol=0, atol=1e-9)


@given(yaw_roll, pitch_ok, yaw_roll)
def test_euler_round_trip(yaw, pitch, roll):
    ypr = frames.euler_from_quat(frames.quat_from_euler(yaw, pitch, roll))
    np.testing.assert_allclose(np.angle(np.exp(1j * (ypr - [yaw, pitch, roll]))), 0.0, rtol=0, atol=1e-9)


def test_euler_sign_conventions_in_ned_frd():
    """Nose-up pitch puts the body x axis above the horizon (world -z in NED); right roll lowers
    the right wing (body y gets +z world); positive yaw turns north towards east."""
    R = frames.quat_to_rotmat(frames.quat_from_euler(0.0, 0.3, 0.0))
    assert R[2, 0] == pytest.approx(-math.sin(0.3), abs=ATOL)
    R = frames.quat_to_rotmat(frames.quat_from_euler(0.0, 0.0, 0.3))
    assert R[2, 1] == pytest.approx(math.sin(0.3), abs=ATOL)
    R = frames.quat_to_rotmat(frames.quat_from_euler(0.3, 0.0, 0.0))
    assert R[1, 0] == pytest.approx(math.sin(0.3), abs=ATOL)


@pytest.mark.parametrize("pitch", [PI / 2, -PI / 2])
def test_euler_at_gimbal_lock_is_finite(pitch):
    q = frames.quat_from_euler(0.4, pitch, -0.2)
    ypr = frames.euler_from_quat(q)
    assert np.all(np.isfinite(ypr))
    assert ypr[1] == pytest.approx(pitch, abs=1e-7)


# --- constrained quaternion error (eq:wr) ---------------------------------------------------

@settings(max_examples=examples(300))
@given(quat_components, axis_components, st.floats(0.0, 2.0 * PI))
@example((1, 0, 0, 0), (0, 0, 1), PI - 1e-9)
@example((1, 0, 0, 0), (0, 0, 1), PI + 1e-6)
def test_quat_error_constrained(q_d, axis, angle):
    """q0 >= 0; its rotation is R_d^T R; its vector part is the short way round.

    R = R_d R_err with R_err a rotation by ``angle`` in [0, 2 pi] about ``axis``; for angle > pi
    the short way is 2 pi - angle about -axis. scipy's as_rotvec (angle in [0, pi]) of R_d^T R is
    the independent reference for the short rotation.
    """
    R_d = frames.quat_to_rotmat(unit_quat(q_d))
    n = unit_axis(axis)
    R = R_d @ Rotation.from_rotvec(n * angle).as_matrix()
    q = frames.quat_error_constrained(R_d, R)
    assert q[0] >= 0.0
    np.testing.assert_allclose(frames.quat_to_rotmat(q), R_d.T @ R, rtol=0, atol=1e-11)
    if abs(angle - PI) > 1e-6:  # at a half turn both directions are equally short
        short = Rotation.from_matrix(R_d.T @ R).as_rotvec()
        theta = 2.0 * math.atan2(np.linalg.norm(q[1:]), q[0])
        assert theta <= PI
        r = np.linalg.norm(short)
        expected_qv = math.sin(r / 2) * short / r if r > 0.0 else np.zeros(3)
        np.testing.assert_allclose(q[1:], expected_qv, rtol=0, atol=1e-9)
        assert abs(theta - r) <= 1e-9
        expected_sign = 1.0 if angle < PI else -1.0
        if 1e-6 < angle < 2 * PI - 1e-6:
            assert expected_sign * float(q[1:] @ n) > 0.0


def test_quat_error_known_case():
    """Body yawed 30 deg right of the desired attitude: error 30 deg about +z; yawed 330 deg: -30."""
    R_d = np.eye(3)
    q = frames.quat_error_constrained(R_d, frames.rotmat_from_axis_angle(np.array([0, 0, 1.0]),
                                                                         math.radians(30)))
    np.testing.assert_allclose(q, [math.cos(math.radians(15)), 0, 0, math.sin(math.radians(15))],
                               rtol=0, atol=ATOL)
    q = frames.quat_error_constrained(R_d, frames.rotmat_from_axis_angle(np.array([0, 0, 1.0]),
                                                                         math.radians(330)))
    np.testing.assert_allclose(q, [math.cos(math.radians(15)), 0, 0, -math.sin(math.radians(15))],
                               rtol=0, atol=ATOL)


# --- orthonormalize -------------------------------------------------------------------------

def _is_rotation(R, atol):
    np.testing.assert_allclose(R.T @ R, np.eye(3), rtol=0, atol=atol)
    assert abs(np.linalg.det(R) - 1.0) <= atol


@given(quat_components)
def test_orthonormalize_leaves_a_rotation_unchanged(q):
    R = to_scipy(unit_quat(q)).as_matrix()
    np.testing.assert_allclose(frames.orthonormalize(R), R, rtol=0, atol=ATOL)


@given(quat_components, st.floats(1e-12, 1e-3), st.integers(0, 2**32 - 1))
def test_orthonormalize_returns_a_nearby_rotation(q, eps, seed):
    """A drifted R -> an orthonormal matrix with det +1 within a few eps of the polar factor
    (the nearest rotation, from an SVD). The bound is first order: see frames.orthonormalize."""
    R = to_scipy(unit_quat(q)).as_matrix()
    drifted = R + eps * np.random.default_rng(seed).uniform(-1.0, 1.0, (3, 3))
    Rn = frames.orthonormalize(drifted)
    _is_rotation(Rn, atol=1e-14 * 10)
    U, _, Vt = np.linalg.svd(drifted)
    nearest = U @ Vt
    assert np.abs(Rn - nearest).max() <= 10.0 * eps + 1e-14


def test_gravity_is_ned_down():
    np.testing.assert_array_equal(frames.gravity_W(), [0.0, 0.0, frames.GRAVITY_MPS2])
    assert frames.GRAVITY_MPS2 == 9.80665


# --- plant-state layout (vtoladapt.layout) ----------------------------------------------------

def test_state_pack_unpack_round_trip(rng):
    parts = {"p_W": rng.normal(size=3), "v_W": rng.normal(size=3),
             "q_WB": unit_quat(rng.normal(size=4)), "omega_B": rng.normal(size=3),
             "motor_frac": rng.uniform(size=layout.N_MOTORS), "surface_rad": rng.uniform(-0.4, 0.4, layout.N_SURFACES)}
    x = layout.pack_state(**parts)
    assert x.shape == (layout.X_SIZE,)
    back = layout.unpack_state(x)
    assert set(back) == set(parts)
    for name, value in parts.items():
        np.testing.assert_array_equal(back[name], value)
    # every slot is written exactly once: the parts fill the vector without gaps or overlap
    np.testing.assert_array_equal(np.sort(np.concatenate(list(back.values()))),
                                  np.sort(np.concatenate(list(parts.values()))))
    assert sum(v.size for v in back.values()) == layout.X_SIZE
    # a (T, X_SIZE) history unpacks to (T, k) views
    hist = np.stack([x, 2 * x])
    np.testing.assert_array_equal(layout.unpack_state(hist)["q_WB"][1], 2 * parts["q_WB"])


def test_layout_column_names_match_sizes():
    assert len(layout.STATE_COLUMNS) == layout.X_SIZE
    assert len(layout.MEASUREMENT_COLUMNS) == layout.MEAS_SIZE
    assert len(layout.REFERENCE_COLUMNS) == layout.REF_SIZE
    assert len(layout.COMMAND_COLUMNS) == layout.CMD_SIZE
    for cols in (layout.STATE_COLUMNS, layout.MEASUREMENT_COLUMNS, layout.REFERENCE_COLUMNS,
                 layout.COMMAND_COLUMNS):
        assert len(set(cols)) == len(cols)
    assert layout.STATE_COLUMNS[layout.X_Q_WB] == "q_w"
    assert layout.MEASUREMENT_COLUMNS[layout.MEAS_V_I_VALID] == "meas_v_i_valid"
    assert layout.REFERENCE_COLUMNS[layout.REF_YAW] == "ref_yaw_rad"
    assert layout.COMMAND_COLUMNS[layout.CMD_TAU_B] == "cmd_tau_x_Nm"


def test_reference_pack_places_named_parts():
    r = layout.pack_reference([1, 2, 3], v_W=[4, 5, 6], a_W=[7, 8, 9], yaw_rad=0.5,
                              yaw_rate_radps=-0.1)
    named = dict(zip(layout.REFERENCE_COLUMNS, r))
    assert named["ref_p_E_m"] == 2 and named["ref_v_D_mps"] == 6 and named["ref_a_N_mps2"] == 7
    assert named["ref_yaw_rad"] == 0.5 and named["ref_yaw_rate_radps"] == -0.1


def test_quats_to_rotmats_is_quat_to_rotmat_for_a_history():
    """The vectorised form (replay, long-run checks) against scipy and the compiled single form."""
    from scipy.spatial.transform import Rotation

    from vtoladapt.frames import quat_to_rotmat, quats_to_rotmats

    q = np.random.default_rng(7).normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    R = quats_to_rotmats(q)
    np.testing.assert_allclose(R, Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix(), atol=1e-12)
    for k in (0, 17, 49):
        np.testing.assert_array_equal(R[k], quat_to_rotmat(q[k]))
