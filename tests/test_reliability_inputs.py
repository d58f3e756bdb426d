"""Issue #27, items 8-12: inputs that are refused for what they mean, not only for their type.

Before the fix: in-range values that cannot be flown (a 5e-324 kg vehicle raised ZeroDivisionError, a
1e-4 kg plant, a 1e-300 inertia or turbulence length scale, a 5e-324 m wingspan diverged with exit 1,
``fit`` with a 1e300 N force raised LinAlgError), a 50 MB scenario of ignored waypoints took two minutes
and 1.7 GB, an unusable replay column exited 0 with null metrics, and the gym took complex actions.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from vtoladapt.cli import main
from vtoladapt.errors import ExitCode

VEHICLE = (Path(__file__).resolve().parents[1] / "src/vtoladapt/vehicles/caltech_vtol.toml").read_text()
BASE = 'name = "h"\nvehicle = "caltech_vtol"\nduration_s = 0.3\n'


def _vehicle_with(key: str, value: str) -> str:
    lines = VEHICLE.splitlines()
    hits = [i for i, ln in enumerate(lines) if re.match(rf"{key}\s*=", ln)]
    assert len(hits) == 1, key
    lines[hits[0]] = f"{key} = {value}"
    return "\n".join(lines) + "\n"


def _run(tmp_path, capsys, scenario: str, vehicle: str | None = None) -> tuple[int, str]:
    if vehicle is not None:
        (tmp_path / "v.toml").write_text(vehicle)
        scenario = scenario.replace('vehicle = "caltech_vtol"', 'vehicle = "v.toml"')
    (tmp_path / "s.toml").write_text(scenario)
    capsys.readouterr()
    rc = main(["run", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--quiet"])
    return rc, capsys.readouterr().err.strip()


@pytest.mark.parametrize("key, value, needle", [
    ("mass_kg", "5e-324", "[mass] mass_kg = 5e-324: out of range; allowed: >= 0.1 and <= 150 (kg)"),
    ("wingspan_m", "5e-324", "[geometry] wingspan_m = 5e-324: out of range; allowed: >= 0.1"),
    ("inertia_kgm2", "[1e-300, 1e-300, 1e-300]", "[mass] inertia_kgm2[0] = 1e-300: out of range; allowed: >= 1e-05"),
    ("yaw_torque_per_thrust_m", "1e-9", "[actuators] yaw_torque_per_thrust_m = 1e-09: out of range"),
])
def test_a_vehicle_that_cannot_be_an_aircraft_is_refused(tmp_path, capsys, key, value, needle):
    rc, err = _run(tmp_path, capsys, BASE, _vehicle_with(key, value))
    assert rc == ExitCode.BAD_INPUT and "\n" not in err and needle in err and "v.toml" in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("extra, needle", [
    ("[plant]\nmass_kg = 1e-4\n", "[plant] mass_kg = 0.0001: out of range; allowed: >= 0.1"),
    ("[plant]\ninertia_kgm2 = [1e-300, 1e-300, 1e-300]\n", "[plant] inertia_kgm2[0] = 1e-300: out of range"),
    ("[wind.turbulence]\nenabled = true\nw20_mps = 3.0\nlength_scale_m = [1e-300, 1e-300, 1e-300]\n",
     "[wind.turbulence] length_scale_m[0] = 1e-300: out of range; allowed: >= 1"),
    ("[plant]\nlift_motor_time_constant_s = 0.002\n", None),  # in range, and the default 1 kHz step resolves it
    ("dt_control_s = 0.02\nplant_substeps = 1\n[plant]\nlift_motor_time_constant_s = 0.005\n",
     "plant_substeps = 1: the plant's RK4 step dt_control_s / plant_substeps = 0.02 s is unstable for "
     "[plant] lift_motor_time_constant_s = 0.005 s; allowed: plant_substeps >= 2"),
])
def test_a_plant_or_wind_that_cannot_be_flown_is_refused_before_anything_is_written(tmp_path, capsys, extra, needle):
    rc, err = _run(tmp_path, capsys, BASE + extra)
    if needle is None:
        assert rc == ExitCode.OK, err
        return
    assert rc == ExitCode.BAD_INPUT and "\n" not in err and needle in err and "s.toml" in err, err
    assert not (tmp_path / "o").exists()


def test_fit_refuses_a_force_no_aircraft_can_see(tmp_path, capsys):
    """Before: force_z_N = 1e300 overflowed the fit into an internal LinAlgError (exit 1)."""
    from vtoladapt.fitting.data import REQUIRED_COLUMNS

    rows = [",".join(REQUIRED_COLUMNS)] + [f"{5 + i},2,0,40,50,0.5,0.1,{'1e300' if i == 3 else -12.0}"
                                           for i in range(8)]
    (tmp_path / "d.csv").write_text("\n".join(rows) + "\n")
    capsys.readouterr()
    rc = main(["fit", str(tmp_path / "d.csv"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert rc == ExitCode.BAD_INPUT and "column 'force_z_N': value '1e300' out of range" in err, err
    assert "force_z_N >= -10000 and force_z_N <= 10000 (N)" in err
    assert not (tmp_path / "o").exists()


def test_the_range_table_gives_a_reason_for_every_physical_lower_bound():
    from vtoladapt.sim.limits import BOUND_REASONS, ranges_markdown

    table = ranges_markdown()
    for key, why in BOUND_REASONS.items():
        row = next(ln for ln in table.splitlines() if f"`{key}`" in ln)
        assert row.endswith(f"| {why} |"), row


# --- item 9: sizes against the memory budget, unused tables refused --------------------------------------

def test_waypoints_under_a_hold_reference_are_refused_not_ignored(tmp_path, capsys):
    """Before: ragged rows of a hold reference passed unchecked (and 5 M of them took 118 s and 1.7 GB)."""
    rc, err = _run(tmp_path, capsys, BASE + '[reference]\nkind = "hold"\nwaypoints = [[0, 1], [1, 2, 3]]\n')
    assert rc == ExitCode.BAD_INPUT and "[reference] waypoints = [[0, 1], [1, 2, 3]]: does not apply here " \
                                      "(kind = 'hold'); keys here: kind, position_m, yaw_deg" in err, err


def test_waypoints_in_python_under_a_hold_reference_are_refused():
    from vtoladapt.config import ConfigError
    from vtoladapt.sim.scenario import ReferenceConfig

    with pytest.raises(ConfigError, match="waypoints: 2 rows with kind = 'hold', which ignores them"):
        ReferenceConfig(kind="hold", waypoints=((0.0, 0, 0, -1), (5.0, 1, 0, -1)))


def test_a_table_longer_than_its_ceiling_is_refused_before_its_rows_are_read():
    """The row count is checked first: rows that are not even numbers are never looked at."""
    from vtoladapt.config import ConfigError
    from vtoladapt.sim.scenario import MAX_WAYPOINTS, scenario_from_mapping

    rows = ["not a row"] * (MAX_WAYPOINTS + 1)
    with pytest.raises(ConfigError, match=rf"\[reference\] waypoints: {MAX_WAYPOINTS + 1} entries; allowed: at most "
                                          rf"{MAX_WAYPOINTS}"):
        scenario_from_mapping({"name": "w", "vehicle": "caltech_vtol", "duration_s": 1.0,
                               "reference": {"kind": "waypoints", "waypoints": rows}}, "w.toml")
    with pytest.raises(ConfigError, match=r"\[wind.fan_array\] schedule: 65 entries; allowed: at most 64"):
        scenario_from_mapping({"name": "w", "vehicle": "caltech_vtol", "duration_s": 1.0,
                               "wind": {"fan_array": {"schedule": ["x"] * 65}}}, "w.toml")
    with pytest.raises(ConfigError, match=r"faults: 31 entries; allowed: at most 30"):
        scenario_from_mapping({"name": "w", "vehicle": "caltech_vtol", "duration_s": 1.0,
                               "faults": ["x"] * 31}, "w.toml")
    with pytest.raises(ConfigError, match=r"\[wind\] gusts: 17 entries; allowed: at most 16"):
        scenario_from_mapping({"name": "w", "vehicle": "caltech_vtol", "duration_s": 1.0,
                               "wind": {"gusts": ["x"] * 17}}, "w.toml")


def test_a_configuration_file_beyond_its_ceiling_is_refused_unread(tmp_path, capsys):
    """17 MiB of waypoint rows: refused from its size alone (16 MiB; about 40 bytes held per byte read)."""
    from vtoladapt.config import MAX_TOML_FILE_BYTES, MEMORY_BUDGET_BYTES, TOML_BYTES_HELD_PER_BYTE

    assert MAX_TOML_FILE_BYTES * TOML_BYTES_HELD_PER_BYTE <= MEMORY_BUDGET_BYTES
    row = "[0.0, 1.2345, -2.3456, -1.5],\n"
    text = BASE + '[reference]\nkind = "waypoints"\nwaypoints = [\n' + row * (17 * 2**20 // len(row)) + "]\n"
    rc, err = _run(tmp_path, capsys, text)
    assert rc == ExitCode.BAD_INPUT and "s.toml: 17 MiB; a TOML file may have at most 16 MiB" in err, err


# --- item 10: a replay of unusable data is bad input -------------------------------------------------------

def _replay_log(tmp_path, px4, column: str | None, value: str | None):
    """The synthetic log of test_replay with one column rewritten in every row (or none)."""
    from test_replay import synthetic_log

    folder = tmp_path / "log"
    synthetic_log(folder, px4, duration_s=2.0)
    if column is not None:
        topic, field = column.split(".")
        path = folder / f"synthetic_{topic}_0.csv"
        lines = path.read_text().splitlines()
        header = lines[0].split(",")
        cols = [i for i, h in enumerate(header) if h.startswith(field)]
        rows = []
        for ln in lines[1:]:
            cells = ln.split(",")
            for i in cols:
                cells[i] = value
            rows.append(",".join(cells))
        path.write_text("\n".join([lines[0]] + rows) + "\n")
    return folder


@pytest.mark.parametrize("column, value, needle", [
    ("vehicle_attitude.q", "text", "vehicle_attitude.q[0..3] is never a unit quaternion"),
    ("vehicle_attitude.q", "nan", "vehicle_attitude.q[0..3] is never a unit quaternion"),
    ("vehicle_attitude.q", "inf", "vehicle_attitude.q[0..3] is never a unit quaternion"),
    ("vehicle_attitude.q", "0", "vehicle_attitude.q[0..3] is never a unit quaternion"),
    ("vehicle_local_position.v", "1e300", "vehicle_local_position.vx, vy, vz is never a finite velocity within 200"),
    ("sensor_combined.accelerometer_m_s2", "nan", "sensor_combined.accelerometer_m_s2[0..2] is never a finite"),
])
def test_a_replay_with_no_usable_samples_exits_2_naming_the_column(tmp_path, capsys, px4, column, value, needle):
    """Before: "0.0 s used", every metric null, exit 0 (and numpy's warnings for 1e300 m/s)."""
    import warnings

    folder = _replay_log(tmp_path, px4, column, value)
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no stray numpy warning on the way to the one line
        rc = main(["replay", str(folder), "--vehicle", "px4_standard_vtol", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert rc == ExitCode.BAD_INPUT and "\n" not in err and f"no usable samples: {needle}" in err, err
    assert not (tmp_path / "o").exists()


def test_a_replay_whose_every_sample_is_on_the_ground_says_so(tmp_path, capsys, px4):
    from test_replay import _write_topic
    import numpy as np

    folder = _replay_log(tmp_path, px4, None, None)
    _write_topic(folder, "vehicle_land_detected", np.array([10_000_000, 20_000_000]), {"landed": np.ones(2)})
    capsys.readouterr()
    rc = main(["replay", str(folder), "--vehicle", "px4_standard_vtol", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert rc == ExitCode.BAD_INPUT and "on the ground per vehicle_land_detected.landed; add --use-landed" in err, err
    assert main(["replay", str(folder), "--vehicle", "px4_standard_vtol", "--out", str(tmp_path / "o"),
                 "--use-landed"]) == ExitCode.OK


# --- item 11: messages -------------------------------------------------------------------------------------

def test_the_hover_message_has_a_readable_throttle_and_never_says_100_over_100(caltech):
    from vtoladapt.config import ConfigError
    from vtoladapt.sim.plant import PlantCoefficients, PlantConfig, hover_trim_motor

    with pytest.raises(ConfigError) as info:  # before: a 150-digit throttle
        hover_trim_motor(caltech, PlantConfig(coefficients=PlantCoefficients(CTz=1e-300)))
    need = 100 * (9.80665 / (1e-300 * 100.0**2)) ** 0.5  # u = sqrt(g m / (m CTz 100^2)), in %
    assert f"needs lift throttle {need:.3g} % > 100 %" in str(info.value) and len(str(info.value)) < 250
    # just above the limit: before, "100 % > 100 %"
    u1 = caltech.mass.mass_kg * caltech.force_model.CTz * 1e4 / 9.80665  # mass that needs exactly 100 %
    with pytest.raises(ConfigError, match=r"needs lift throttle 100\.0*[1-9]\d* % > 100 %"):
        hover_trim_motor(caltech, PlantConfig(mass_kg=round(u1 * 1.00001, 6)))


def test_a_campaign_draw_that_cannot_hover_is_named(tmp_path, capsys):
    (tmp_path / "s.toml").write_text(BASE)
    capsys.readouterr()
    rc = main(["campaign", str(tmp_path / "s.toml"), "--runs", "4", "--vary", "plant.mass_kg=4.9:6", "--scheduler",
               "none", "--out", str(tmp_path / "c"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert rc == ExitCode.BAD_INPUT and re.search(r"s\.toml \(campaign run \d, \{'seed': \d+, 'plant.mass_kg': "
                                                  r"[\d.]+\}\): \[plant\] cannot hover", err), err
    assert not (tmp_path / "c").exists()


# --- item 12: gym inputs ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def envs():
    from vtoladapt.gym.env import HoldEnv
    from vtoladapt.gym.vector import HoldVectorEnv

    single, vector = HoldEnv(), HoldVectorEnv(num_envs=2, workers=1)
    yield single, vector
    single.close()
    vector.close()


def test_complex_actions_are_refused_not_cast(envs):
    """Before: the imaginary part was dropped and the real part flown."""
    import numpy as np

    single, vector = envs
    single.reset(seed=1)
    with pytest.raises(ValueError, match="must be 5 finite numbers"):
        single.step(np.full(5, 0.1 + 0.5j))
    with pytest.raises(ValueError, match="must be 5 finite numbers"):
        single.step([0.1j] * 5)
    vector.reset(seed=1)
    with pytest.raises(ValueError, match=r"must be \(2, 5\) finite numbers"):
        vector.step(np.full((2, 5), 0.1 + 0.5j))
    single.step(np.zeros(5))  # a real action still flies
    vector.step(np.zeros((2, 5)))


@pytest.mark.parametrize("seed", [1.5, -1, True, "7", [1, 2.5]])
def test_a_reset_seed_that_is_not_a_whole_number_is_refused_in_one_line(envs, seed):
    """Before: vector reset(seed=1.5) raised a bare TypeError ('float' object is not iterable)."""
    from vtoladapt.config import ConfigError

    single, vector = envs
    with pytest.raises(ConfigError, match="reset seed"):
        vector.reset(seed=seed)
    if not isinstance(seed, list):
        with pytest.raises(ConfigError, match="must be None or a whole number >= 0"):
            single.reset(seed=seed)
