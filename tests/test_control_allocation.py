"""Thruster allocation (eq:f_proj) and the full force realisation (eq:fbar_solve)."""
from __future__ import annotations

import numpy as np
import pytest

from vtoladapt import forces
from vtoladapt.control.allocation import SAT_HIGH, SAT_LOW, allocate_thrusters
from vtoladapt.control.attitude import wing_attitude
from vtoladapt.frames import GRAVITY_MPS2

MASK = np.array([1.0, 0.0, 1.0])


def _v_i(rng, V_max=15.0):
    V = rng.uniform(0.0, V_max)
    alpha = rng.uniform(-0.35, 0.35)
    beta = rng.uniform(-0.2, 0.2)
    return V * np.array([np.cos(alpha) * np.cos(beta), np.sin(beta), np.sin(alpha) * np.cos(beta)])


def test_round_trip_inside_the_achievable_set(any_vehicle, rng):
    theta, model = any_vehicle.theta_scaled, any_vehicle.model_kernel
    for _ in range(500):
        v_i = _v_i(rng)
        ux, uz = rng.uniform(0.05, 0.95, 2)
        f = forces.body_force(v_i, ux, uz, theta, model)
        u_x, u_z, res, sat_x, sat_z = allocate_thrusters(f, v_i, theta, model, 1.0)
        assert (sat_x, sat_z) == (0.0, 0.0)
        np.testing.assert_allclose([u_x, u_z], [ux, uz], rtol=1e-9, atol=1e-12)
        assert np.max(np.abs(res)) < 1e-10        # m/s^2


def test_eq_fbar_solve_attitude_and_allocation_realise_the_command(caltech, rng):
    """R_d f_b-hat(v_i in the desired frame, u) = f_r (eq:fbar_solve) for achievable commands."""
    theta, model = caltech.theta_scaled, caltech.model_kernel
    a = caltech.aero_scale_per_m
    amax = np.radians(caltech.envelope.alpha_max_deg)
    n_checked = 0
    for _ in range(400):
        V = rng.uniform(4.0, 20.0)
        heading = rng.uniform(-np.pi, np.pi)
        v_i_W = V * np.array([np.cos(heading), np.sin(heading), rng.uniform(-0.1, 0.1)])
        f_r = np.array([0.0, 0.0, -GRAVITY_MPS2]) + rng.normal(0, 1.5, 3)
        R_d = np.array(wing_attitude(v_i_W, f_r, theta[6], theta[7], a, -amax, amax, np.zeros(3), False, 0.0)[0])
        v_i_B = R_d.T @ v_i_W
        u_x, u_z, res, sat_x, sat_z = allocate_thrusters(R_d.T @ f_r, v_i_B, theta, model, 1.0)
        if (sat_x, sat_z) != (0.0, 0.0):
            continue
        n_checked += 1
        f_b = np.array(forces.body_force(v_i_B, u_x, u_z, theta, model))
        np.testing.assert_allclose(R_d @ f_b, f_r, atol=1e-9)      # m/s^2
    assert n_checked > 100


def _brute_force(f_rb, v_i, theta, model, n=401):
    """Smallest |M (f_rb - f_b(u))| over an n x n throttle grid, refined once around the best cell."""
    def search(ux_grid, uz_grid):
        best = (np.inf, 0.0, 0.0)
        for ux in ux_grid:
            for uz in uz_grid:
                f = forces.body_force(v_i, ux, uz, theta, model)
                r = np.linalg.norm(MASK * (f_rb - f))
                if r < best[0]:
                    best = (r, ux, uz)
        return best

    r, ux, uz = search(np.linspace(0, 1, n), np.linspace(0, 1, n))
    h = 2.0 / (n - 1)
    return search(np.clip(np.linspace(ux - h, ux + h, 81), 0, 1), np.clip(np.linspace(uz - h, uz + h, 81), 0, 1))[0]


@pytest.mark.parametrize("case", ["too_much_lift", "needs_downforce", "needs_braking", "too_much_thrust"])
def test_outside_the_achievable_set_residual_is_reported_and_minimal(caltech, case):
    theta, model = caltech.theta_scaled, caltech.model_kernel
    v_i = np.array([8.0, 0.5, 1.0])
    f_rb = {"too_much_lift": np.array([1.0, 0.0, -40.0]),
            "needs_downforce": np.array([1.0, 0.0, 6.0]),
            "needs_braking": np.array([-8.0, 0.0, -9.0]),
            "too_much_thrust": np.array([45.0, 0.0, -9.0])}[case]
    u_x, u_z, res, sat_x, sat_z = allocate_thrusters(f_rb, v_i, theta, model, 1.0)
    expected = {"too_much_lift": (0.0, SAT_HIGH), "needs_downforce": (0.0, SAT_LOW),
                "needs_braking": (SAT_LOW, 0.0), "too_much_thrust": (SAT_HIGH, 0.0)}[case]
    assert (sat_x, sat_z) == expected
    assert 0.0 <= u_x <= 1.0 and 0.0 <= u_z <= 1.0
    f = forces.body_force(v_i, u_x, u_z, theta, model)
    np.testing.assert_allclose(res, f_rb - np.array(f), atol=1e-12)   # the reported residual is the true one
    ours = np.linalg.norm(MASK * res)
    assert ours > 0.1
    assert ours <= _brute_force(f_rb, v_i, theta, model) + 1e-3   # m/s^2


def test_throttle_limit_is_respected(caltech):
    theta, model = caltech.theta_scaled, caltech.model_kernel
    u_x, u_z, res, sat_x, sat_z = allocate_thrusters(np.array([0.0, 0.0, -GRAVITY_MPS2]), np.zeros(3), theta,
                                                     model, 0.5)
    assert sat_z == SAT_HIGH and u_z == 0.5
    assert res[2] == pytest.approx(-GRAVITY_MPS2 + theta[1] * 0.25, abs=1e-12)
