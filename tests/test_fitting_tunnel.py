"""The virtual wind tunnel against the force model evaluated independently, and its noise model."""
import json

import numpy as np
import pytest

import vtoladapt
from vtoladapt import forces, models
from vtoladapt.fitting import tunnel
from vtoladapt.fitting.data import read_force_balance_csv


@pytest.fixture(scope="module")
def veh():
    return vtoladapt.load_vehicle("caltech_vtol")


def test_noise_free_tunnel_equals_body_force_kernel(veh):
    """Rows with the wing equal models.body_force (forces.body_force, not the regressor); rows
    without it equal the thruster force alone (forces.thruster_force)."""
    run = tunnel.run_virtual_tunnel(veh, np.random.default_rng(0),
                                    noise=tunnel.BalanceNoise(sigma_abs_N=0.0, sigma_rel=0.0))
    d = run.data
    m = veh.mass.mass_kg
    v = d.v_i_B
    for i in range(d.n_rows):
        if d.wing_on[i]:
            f = models.body_force(v[i], d.throttle_x_pct[i], d.throttle_z_pct[i], veh)
        else:
            f = np.empty(3)
            forces.thruster_force(v[i], d.throttle_x_pct[i] / 100, d.throttle_z_pct[i] / 100,
                                  veh.theta_scaled, veh.model_kernel, f)
        np.testing.assert_allclose(d.force_B_N[i], f * m, rtol=1e-12, atol=1e-12)


def test_design_covers_the_papers_ranges(veh):
    pts = tunnel.design_points(tunnel.TunnelDesign())
    wing = pts["wing_on"] & (pts["airspeed_mps"] > 0)
    side = ~pts["wing_on"]
    assert pts["airspeed_mps"].max() == 9.0
    assert pts["alpha_deg"][wing].min() == -10 and pts["alpha_deg"][wing].max() == 15
    assert pts["alpha_deg"][side].min() == -45 and pts["alpha_deg"][side].max() == 45
    assert np.all(pts["throttle_z_pct"][side] > 0) and np.all(pts["throttle_x_pct"][side] == 0)
    assert np.count_nonzero(pts["throttle_x_pct"] > 0) == 9
    n1 = pts["airspeed_mps"].size
    assert tunnel.design_points(tunnel.make_design(repeats=3))["airspeed_mps"].size == 3 * n1
    with pytest.raises(vtoladapt.ConfigError, match="repeats"):
        tunnel.make_design(repeats=0)


def test_noise_model_statistics(veh):
    """Residuals of many repeated readings have std 0.02 N + 1 % of |F| (within 4 %)."""
    design = tunnel.make_design(repeats=200, wing_airspeeds_mps=[9.0], wing_alpha_range_deg=[5.0, 5.0],
                                static_throttles_pct=[60.0], rotor_airspeeds_mps=[9.0],
                                rotor_throttles_pct=[60.0], rotor_alpha_range_deg=[0.0, 0.0],
                                rotor_beta_deg=[0.0])
    noisy = tunnel.run_virtual_tunnel(veh, np.random.default_rng(1), design=design)
    clean = tunnel.run_virtual_tunnel(veh, np.random.default_rng(1), design=design,
                                      noise=tunnel.BalanceNoise(0.0, 0.0))
    r = noisy.data.force_B_N - clean.data.force_B_N
    expected = 0.02 + 0.01 * np.abs(clean.data.force_B_N)
    z = r / expected
    # 4 rows x 200 repeats x 3 axes = 2400 standard-normal values: std within 4 %, mean ~ 0
    assert np.std(z) == pytest.approx(1.0, rel=0.04)
    assert abs(np.mean(z)) < 4 / np.sqrt(z.size)


def test_same_seed_same_file_and_side_file(veh, tmp_path):
    a = tunnel.write_tunnel_run(tunnel.run_virtual_tunnel(veh, np.random.default_rng(5), seed=5),
                                tmp_path / "a.csv")
    b = tunnel.write_tunnel_run(tunnel.run_virtual_tunnel(veh, np.random.default_rng(5), seed=5),
                                tmp_path / "b.csv")
    assert a[0].read_bytes().split(b"\n", 3)[3] == b[0].read_bytes().split(b"\n", 3)[3]
    info = tunnel.read_truth(a[1])
    assert info["coefficients"]["CTz"] == veh.force_model.CTz
    assert info["noise_model"]["sigma_abs_N"] == 0.02
    np.testing.assert_array_equal(info["theta_table"], veh.force_model.as_table_theta())
    d = read_force_balance_csv(a[0])
    assert d.n_rows == info["n_rows"] and d.mass_kg == veh.mass.mass_kg


def test_perturbed_truth_is_seeded_and_valid(veh):
    t1 = tunnel.true_coefficients(veh, True, np.random.default_rng(3))
    t2 = tunnel.true_coefficients(veh, True, np.random.default_rng(3))
    assert t1 == t2
    mean = veh.force_model.as_table_theta()
    std = veh.force_model_std.as_table_theta()
    z = (t1.as_table_theta() - mean) / std
    assert np.all(np.abs(z) < 6) and np.any(z != 0)
    assert 0 < t1.k1 < 2 and t1.k2 > np.pi / 2 and t1.CS >= 0


def test_truth_is_swappable(veh):
    """A user-supplied truth (here: a plant that only has drag) is what the tunnel measures."""
    def drag_only(v_i_B, u_x, u_z, wing_on, rho):
        V = np.linalg.norm(v_i_B, axis=1)
        return -0.1 * V[:, None] * v_i_B

    run = tunnel.run_virtual_tunnel(veh, np.random.default_rng(0), truth=drag_only,
                                    noise=tunnel.BalanceNoise(0.0, 0.0))
    v = run.data.v_i_B
    np.testing.assert_allclose(run.data.force_B_N,
                               -0.1 * np.linalg.norm(v, axis=1)[:, None] * v * veh.mass.mass_kg)
    assert run.truth is None and run.truth_info()["coefficients"] is None
    with pytest.raises(ValueError, match="perturb"):
        tunnel.run_virtual_tunnel(veh, np.random.default_rng(0), truth=drag_only, perturb=True)


def test_density_scaling_of_the_regressor(veh):
    """All model forces scale with rho: the regressor at 2 rho is twice the one at rho."""
    rng = np.random.default_rng(0)
    v = rng.normal(0, 5, (20, 3))
    ux, uz = rng.random(20), rng.random(20)
    wing = rng.random(20) < 0.5
    args = (veh.envelope.air_density_kgpm3, veh.aero_scale_per_m, 1.4, 3.1, veh.envelope.stall_angle_deg)
    P1 = tunnel.regressor_for_rows(v, ux, uz, wing, np.full(20, 1.225), *args)
    P2 = tunnel.regressor_for_rows(v, ux, uz, wing, np.full(20, 2.45), *args)
    np.testing.assert_allclose(P2, 2 * P1, rtol=1e-14)
    assert np.all(P1[~wing][:, :, forces.I_CD0:] == 0)
    json.dumps(tunnel.run_virtual_tunnel(veh, rng).truth_info())  # serialisable
