"""The shipped vehicles: the paper's numbers exactly, and the PX4 conversion re-derived.

* caltech_vtol: Table I (force model, mean and std), Table II (airframe), Table III (P0) of
  Shi et al., ICRA 2020, typed in here from the paper and also parsed from the paper's LaTeX
  tables, vendored in ``data/paper/shi2020_tables.tex`` (see its SOURCE.md).
* px4_standard_vtol: every force-model number equals vehicles.px4_standard_vtol.px4_standard_vtol_force_model()
  to 4 significant figures (rel 5e-4), and the conversion is checked by independent physics
  (hover thrust of four Gazebo rotors, a continuous least-squares fit of the rotor drag).
"""
from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

from vtoladapt import PARAMETER_NAMES, load_vehicle, models
from vtoladapt.vehicles.px4_standard_vtol import PX4_STANDARD_VTOL, px4_standard_vtol_force_model
from vtoladapt.frames import GRAVITY_MPS2

PAPER = Path(__file__).resolve().parents[1] / "data" / "paper" / "shi2020_tables.tex"

# Table I of the paper: mean, std (throttle in percent, forces per unit mass)
TABLE_I = {
    "CTx": (3.02e-3, 2.25e-5), "CTz": (2.87e-3, 5.00e-6), "CS": (2.31e-5, 1.18e-5),
    "k1": (1.425, 0.010), "k2": (3.126, 0.087),
    "CL0": (0.3705, 0.06523), "CL1": (3.2502, 0.04434), "CD0": (0.1551, 0.00394),
    "CD1": (0.1782, 0.06518), "CD2": (1.6000, 0.10820),
}
TABLE_III_P0 = [200, 200, 0.1, 1, 5, 20, 0.1, 0.1]


@pytest.mark.parametrize("name", ["caltech_vtol", "px4_standard_vtol"])
def test_shipped_vehicles_load(name):
    veh = load_vehicle(name)
    assert veh.name == name
    assert Path(veh.source_path).name == f"{name}.toml"
    assert veh.theta_scaled.shape == (8,) and np.all(np.isfinite(veh.theta_scaled))
    J = veh.mass.inertia_matrix
    np.testing.assert_array_equal(J, J.T)
    assert np.all(np.linalg.eigvalsh(J) > 0)


def test_caltech_vtol_is_the_papers_aircraft(caltech):
    # Table II
    assert caltech.mass.mass_kg == 1.70
    assert caltech.geometry.wingspan_m == 1.08
    assert caltech.geometry.wing_area_m2 == 0.223
    assert caltech.geometry.lift_prop_diameter_m == pytest.approx(6 * 0.0254, abs=1e-12)   # 6x4
    assert caltech.geometry.pusher_prop_diameter_m == pytest.approx(7 * 0.0254, abs=1e-12)  # 7x4
    assert caltech.geometry.pusher_prop_pitch_m == pytest.approx(4 * 0.0254, abs=1e-12)
    # Table I, means and standard deviations, exactly
    for name, (mean, std) in TABLE_I.items():
        assert getattr(caltech.force_model, name) == mean, name
        assert getattr(caltech.force_model_std, name) == std, name
    # Table III
    assert list(caltech.adaptation.P0_diag) == TABLE_III_P0
    # theta in the paper's order
    assert PARAMETER_NAMES == ("CTx", "CTz", "CS", "CD0", "CD1", "CD2", "CL0", "CL1")
    np.testing.assert_array_equal(caltech.force_model.as_table_theta(),
                                  [TABLE_I[n][0] for n in PARAMETER_NAMES])


def _paper_text() -> str:
    return PAPER.read_text()


def _latex_number(cell: str) -> float:
    m = re.search(r"\\expnumber\{([-\d.]+)\}\{([-\d]+)\}", cell)
    if m:
        return float(f"{m.group(1)}e{m.group(2)}")
    return float(re.search(r"[-\d.]+", cell.replace("$", "")).group(0))


def test_table_i_parsed_from_the_paper_source(caltech):
    """Table I as printed in the LaTeX source equals the shipped file."""
    text = _paper_text()
    table = text[text.index("\\caption{Fitted Parameters"):text.index("\\label{tab:param_fit}")]
    macro = {"C_{Tx}": "CTx", "C_{Tz}": "CTz", "C_{S}": "CS", "k_1": "k1", "k_2": "k2",
             "\\clo": "CL0", "\\cla": "CL1", "\\cdo": "CD0", "\\cda": "CD1", "\\cdaa": "CD2"}
    found = {}
    for line in table.splitlines():
        cells = [c.strip() for c in line.rstrip("\\ ").split("&")]
        if len(cells) != 4:
            continue
        for sym, val in ((cells[0], cells[1]), (cells[2], cells[3])):
            key = macro.get(sym.strip("$ "))
            if key:
                mean_txt, std_txt = val.split("\\pm")
                found[key] = (_latex_number(mean_txt), _latex_number(std_txt))
    assert set(found) == set(TABLE_I)
    for key, (mean, std) in found.items():
        assert getattr(caltech.force_model, key) == mean, key
        assert getattr(caltech.force_model_std, key) == std, key


def test_tables_ii_and_iii_parsed_from_the_paper_source(caltech):
    text = _paper_text()
    assert "Weight         & \\SI{1.70}{kg}" in text and caltech.mass.mass_kg == 1.70
    assert "Wingspan       & \\SI{1.08}{m}" in text and caltech.geometry.wingspan_m == 1.08
    assert "\\SI{0.223}{m^2}" in text and caltech.geometry.wing_area_m2 == 0.223
    table = text[text.index("Initial adaptation gains"):text.index("\\label{tab:adaptation_gains}")]
    row = [line for line in table.splitlines() if line.strip().startswith("$200$")][0]
    p0 = [float(c.strip(" $\\")) for c in row.split("&")]
    assert list(caltech.adaptation.P0_diag) == p0 == TABLE_III_P0


def test_derived_quantities(caltech):
    # rho S / (2 m) with rho = 1.225 (ISA; the paper does not give the tunnel's density)
    assert caltech.aero_scale_per_m == pytest.approx(1.225 * 0.223 / (2 * 1.70), rel=1e-15)
    np.testing.assert_allclose(caltech.model_kernel[:3], [1.225 * 0.223 / 3.4, 1.425, 3.126], rtol=1e-15)
    # adaptation scaling: thrust coefficients x 100^2, CS x 100^k1, aero unchanged
    expected = [3.02e-3 * 1e4, 2.87e-3 * 1e4, 2.31e-5 * 100**1.425,
                0.1551, 0.1782, 1.6000, 0.3705, 3.2502]
    np.testing.assert_allclose(caltech.theta_scaled, expected, rtol=1e-15)
    np.testing.assert_allclose(caltech.theta_std_scaled[:3],
                               [2.25e-5 * 1e4, 5.00e-6 * 1e4, 1.18e-5 * 100**1.425], rtol=1e-15)


def test_vehicle_is_frozen_and_replace_copies(caltech):
    with pytest.raises(dataclasses.FrozenInstanceError):
        caltech.name = "other"  # type: ignore[misc]
    heavier = caltech.replace(mass=dataclasses.replace(caltech.mass, mass_kg=3.4))
    assert heavier.aero_scale_per_m == pytest.approx(caltech.aero_scale_per_m / 2, rel=1e-15)
    assert caltech.mass.mass_kg == 1.70


# --- PX4 standard VTOL ----------------------------------------------------------------------

def test_px4_file_equals_conversion_to_4_significant_figures(px4):
    conv = px4_standard_vtol_force_model()
    for name, value in conv.items():
        shipped = getattr(px4.force_model, name)
        if value == 0.0:
            assert shipped == 0.0, name
        else:
            assert shipped == pytest.approx(value, rel=5e-4), name
    assert px4.mass.mass_kg == PX4_STANDARD_VTOL["mass_kg"]


def test_px4_conversion_by_hand():
    """Each coefficient re-derived from the Gazebo numbers with plain arithmetic."""
    conv = px4_standard_vtol_force_model()
    m = 5.0
    # four lift rotors of 2e-5 N/(rad/s)^2 at 1500 rad/s: 180 N, 36 m/s^2 per 100 %^2
    assert conv["CTz"] == pytest.approx(4 * 2e-5 * 1500**2 / m / 100**2, rel=1e-14)
    assert conv["CTz"] == pytest.approx(3.6e-3, rel=1e-14)
    assert conv["CTx"] == pytest.approx(8.54858e-6 * 3500**2 / m / 100**2, rel=1e-14)
    # Gazebo lift-drag: CL = cla (alpha + a0), CD = cda (alpha + a0) in attached flow
    assert conv["CL1"] == 4.7528 and conv["CL0"] == pytest.approx(4.7528 * 0.05984, rel=1e-14)
    assert conv["CD1"] == pytest.approx(0.6417112299, rel=1e-9)
    assert conv["CD0"] == pytest.approx(0.6417112299 * 0.05984, rel=1e-9)
    assert conv["CD2"] == 0.0 and conv["k1"] == 1.0 and conv["k2"] == 20.0


def test_px4_side_force_is_the_least_squares_fit_of_rotor_drag():
    """CS minimises the integral of (CS basis - rotor drag)^2 over |alpha| <= 45 deg; the
    conversion sums over a 181-point grid, so the continuous optimum agrees to ~2e-4."""
    conv = px4_standard_vtol_force_model()
    k2 = conv["k2"]

    def basis(a):
        return ((math.pi / 2) ** 2 - a * a) * (a + k2)

    def rotor_drag(a):  # 4 rotors, F = c_rd omega V cos(alpha), per unit mass, per (% m/s)
        return 4 * 0.000106428 * (1500 / 100) * math.cos(a) / 5.0

    lim = math.pi / 4
    cs = quad(lambda a: basis(a) * rotor_drag(a), -lim, lim)[0] / quad(lambda a: basis(a) ** 2, -lim, lim)[0]
    assert conv["CS"] == pytest.approx(cs, rel=1e-3)


def test_px4_hover_check(px4):
    """Four Gazebo rotors at the rotor speed of the model's hover throttle lift exactly m g."""
    u_hover_pct = math.sqrt(GRAVITY_MPS2 / px4.force_model.CTz)
    omega = PX4_STANDARD_VTOL["lift_omega_max_radps"] * u_hover_pct / 100.0
    thrust_N = 4 * PX4_STANDARD_VTOL["lift_motor_constant"] * omega**2
    # the shipped CTz is rounded to 4 significant figures (exact here: 3.6e-3)
    assert thrust_N == pytest.approx(px4.mass.mass_kg * GRAVITY_MPS2, rel=5e-4)
    f = models.body_force(np.zeros(3), 0.0, u_hover_pct, px4)
    assert f[2] == pytest.approx(-thrust_N / px4.mass.mass_kg, rel=5e-4)
    assert 50.0 < u_hover_pct < 55.0  # 5 kg on a 36 m/s^2 lift system hovers at 52 %


def test_px4_rotors_are_the_current_sdfs(px4):
    """The plant's hover rotors are the sdf's (standard_vtol.sdf.jinja at SDF_COMMIT): rotor_n's FLU pose
    (x, y) becomes FRD (x, -y), ccw is spin -1, and the moment constant is the sdf's 0.06 (not the 0.016 the
    file had before issue #35)."""
    from vtoladapt.vehicles.px4_standard_vtol import SDF_COMMIT, px4_standard_vtol_rotors

    r = px4_standard_vtol_rotors()
    assert len(SDF_COMMIT) == 40 and SDF_COMMIT in (Path(px4.source_path).read_text())
    assert [list(p) for p in px4.geometry.lift_rotor_positions_m] == r["positions_m"]
    assert list(px4.geometry.lift_rotor_spin) == r["spin"]
    assert px4.actuators.yaw_torque_per_thrust_m == r["yaw_torque_per_thrust_m"] == 0.06
    # by hand: rotor_0 at Gazebo (0.35, -0.35), ccw -> FRD front right, yawing positively about z down
    assert r["positions_m"][0] == [0.35, 0.35] and r["spin"][0] == -1


def test_px4_allocator_belief_is_pxs_airframe_1040(px4):
    """[effectiveness_settings.px4_ca] is PX4's 1040 airframe's CA_* parameters, by px4_ca_settings() and by
    hand, and the vehicle's allocator believes them by default."""
    from vtoladapt.vehicles.px4_standard_vtol import PX4_AIRFRAME_1040, px4_ca_settings

    table = px4.effectiveness_table("px4_ca")
    derived = px4_ca_settings()
    for key in ("rotor_px_m", "rotor_py_m", "rotor_km_m"):
        assert table[key] == derived[key], key
    assert [list(t) for t in table["surface_torque"]] == derived["surface_torque"]
    assert table["rotor_py_m"] == [0.245, -0.1875, -0.245, 0.1875] and table["rotor_km_m"] == [0.05, 0.05, -0.05, -0.05]
    assert PX4_AIRFRAME_1040["commit"][:8] in table["source"] and px4.effectiveness == "px4_ca"
