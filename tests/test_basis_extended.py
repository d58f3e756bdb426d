"""The extended physics basis against independent references: the simulated aircraft's own force
kernel (a separate implementation of the same physics), the data its priors come from, and the
paper's basis for its first eight columns."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vtoladapt import load_vehicle
from vtoladapt.bases import describe_basis, evaluate, extended, input_rows
from vtoladapt.layout import MOTOR_PUSHER, N_ACTUATORS, N_MOTORS, N_SURFACES
from vtoladapt.sim import plant
from vtoladapt.sim.plant import PlantConfig

VEHICLES = ("caltech_vtol", "px4_standard_vtol")


def _rows(veh, n=200, seed=0, speed=12.0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3)) * speed
    return input_rows(v, rng.random(n), rng.random(n), veh.model_kernel)


@pytest.mark.parametrize("name", VEHICLES)
def test_first_eight_columns_are_the_papers_bit_for_bit(name):
    veh = load_vehicle(name)
    x = _rows(veh)
    np.testing.assert_array_equal(evaluate(describe_basis(veh, "extended"), x)[:, :, :8],
                                  evaluate(describe_basis(veh, "paper"), x))


def _plant_force(p, v_i_B, u_x, u_z):
    # the rotors, then the control surfaces at neutral and healthy (the columns carry no surface force)
    motor = np.zeros(N_ACTUATORS)
    motor[:N_MOTORS] = u_z
    motor[MOTOR_PUSHER] = u_x
    rotors = plant.rotor_terms(motor, 0, p, np.zeros(N_SURFACES), 0)
    return np.array(plant.true_forces_moments(v_i_B[0], v_i_B[1], v_i_B[2], 0.0, 0.0, 0.0, rotors, p)[:3])


def _theta_true(veh, cfg: PlantConfig, spec):
    coeffs = cfg.true_coefficients(veh)
    theta = np.empty(spec.n)
    theta[:8] = cfg.theta_true_scaled(veh)
    a1, a2 = cfg.pusher_CT_ratio_coeffs
    theta[8:] = [cfg.CY_beta_per_rad, 2.0 - coeffs["CL1"] / math.pi, 0.0, theta[0] * a1, theta[0] * a2]
    return theta


@pytest.mark.parametrize("name", VEHICLES)
@pytest.mark.parametrize("case", ["attached", "post_stall"])
def test_with_the_plants_coefficients_it_is_the_plants_force(name, case):
    """The plant (its own kernel) with the effects these columns carry: side force, the pusher's
    advance-ratio loss and, past stall, the flat plate of C_N = 2. Inside the attached range (above
    -3 deg, where px4_standard_vtol's drag polar is still positive: the plant takes its absolute value) with the
    plant's stall switched off, and deep past stall (where the plant's sigmoid and the model's blend are
    both 1), Phi_ext theta_true is the plant's specific force (the paper's basis is not)."""
    veh = load_vehicle(name)
    cfg = PlantConfig(stall=(case == "post_stall"))
    p = cfg.to_kernel(veh)
    spec = describe_basis(veh, "extended")
    theta = _theta_true(veh, cfg, spec)
    rng = np.random.default_rng(3)
    worst_ext = worst_paper = 0.0
    for _ in range(40):
        V = rng.uniform(3.0, 14.0)
        alpha = math.radians(rng.uniform(-3.0, 9.0) if case == "attached" else rng.uniform(50.0, 80.0))
        beta = math.radians(rng.uniform(-15.0, 15.0))
        v = V * np.array([math.cos(alpha) * math.cos(beta), math.sin(beta), math.sin(alpha) * math.cos(beta)])
        u_x, u_z = rng.uniform(0.2, 0.9), rng.uniform(0.3, 0.8)
        f_true = _plant_force(p, v, u_x, u_z)
        x = input_rows(v[None], u_x, u_z, veh.model_kernel)
        f_ext = evaluate(spec, x)[0] @ theta
        f_paper = evaluate(describe_basis(veh, "paper"), x)[0] @ theta[:8]
        worst_ext = max(worst_ext, float(np.max(np.abs(f_ext - f_true))))
        worst_paper = max(worst_paper, float(np.max(np.abs(f_paper - f_true))))
    assert worst_ext < 1e-9, worst_ext
    assert worst_paper > 0.05, worst_paper   # the paper's basis cannot carry these effects


def test_stall_bump_column_lives_only_near_the_believed_stall():
    veh = load_vehicle("caltech_vtol")
    spec = describe_basis(veh, "extended")
    k = spec.names.index("dCL1_stall")
    alpha_s = veh.envelope.stall_angle_deg
    for a_deg, inside in ((alpha_s - 8.0, False), (alpha_s - 3.0, True), (alpha_s, True), (alpha_s + 7.0, True),
                          (alpha_s + 9.0, False), (-alpha_s, True)):
        a = math.radians(a_deg)
        x = input_rows([[10 * math.cos(a), 0.0, 10 * math.sin(a)]], 0.3, 0.5, veh.model_kernel)
        col = evaluate(spec, x)[0, :, k]
        assert (np.abs(col).max() > 1e-3) == inside, (a_deg, col)
        # along the lift direction (sin a, 0, -cos a), with the sign of alpha
        if inside:
            lift_dir = np.array([math.sin(a), 0.0, -math.cos(a)])
            np.testing.assert_allclose(col / np.linalg.norm(col), np.sign(a) * lift_dir, atol=1e-12)


def test_priors_come_from_the_data_they_name():
    from vtoladapt.fitting import pusher_thrust_ratio_model

    # the UIUC 7x4 thrust-ratio fit (the same data the plant's numbers come from)
    model = pusher_thrust_ratio_model()
    np.testing.assert_allclose(model.coefficients[1:], extended.UIUC_7X4_CT_RATIO, rtol=1e-4)
    # the TU Delft kite's side-force slopes, |beta| <= 12 deg
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "data" / "tudelft-v3-kite-windtunnel"
    for alpha_tag, slope in zip(("7", "13"), extended.KITE_CY_SLOPE_ABS):
        d = np.genfromtxt(root / f"WindTunnel_Re5e5_beta_sweep_alpha_{alpha_tag}_Poland2025.csv", delimiter=",",
                          names=True)
        m = np.abs(d["beta"]) <= 12.0
        fitted = np.polyfit(np.radians(d["beta"][m]), d["CS"][m], 1)[0]
        assert abs(fitted) == pytest.approx(slope, abs=0.01)
    s = extended.Settings()
    assert min(extended.KITE_CY_SLOPE_ABS) <= s.CY_std <= max(extended.KITE_CY_SLOPE_ABS)
    veh = load_vehicle("caltech_vtol")
    spec = describe_basis(veh, "extended")
    ar = veh.geometry.wingspan_m ** 2 / veh.geometry.wing_area_m2
    i = spec.names.index("dCN90")
    assert spec.theta_table[i] == pytest.approx(1.11 + 0.018 * ar - veh.force_model.CL1 / math.pi)
    # the plate's thin-wing C_N90 = 2 lies within one prior std of the mean (the prior is wide, not tuned)
    assert abs(2.0 - veh.force_model.CL1 / math.pi - spec.theta_table[i]) < spec.std_table[i]


def test_settings_from_the_vehicle_file(tmp_path):
    from vtoladapt.vehicle import VEHICLE_DIR

    text = (VEHICLE_DIR / "caltech_vtol.toml").read_text() + "\n[basis_settings.extended]\nCY_std = 0.2\n"
    path = tmp_path / "v.toml"
    path.write_text(text)
    spec = describe_basis(load_vehicle(path), "extended")
    assert spec.std_table[spec.names.index("CY")] == 0.2
    from vtoladapt.config import ConfigError

    path.write_text(text.replace("CY_std = 0.2", "CY_mean = 0.5"))
    with pytest.raises(ConfigError, match=r"CY_mean = 0\.5.*allowed"):
        describe_basis(load_vehicle(path), "extended")
