"""The force-balance CSV format: round trip, and errors that name the line and the column."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from conftest import examples
from vtoladapt import forces
from vtoladapt.config import ConfigError
from vtoladapt.fitting.data import (FitDataError, ForceBalanceData, incident_velocity_from_angles,
                                    read_force_balance_csv, write_force_balance_csv)

HEADER = "airspeed_mps,alpha_deg,beta_deg,throttle_x_pct,throttle_z_pct,force_x_N,force_y_N,force_z_N"
GOOD_ROWS = ["0,0,0,50,0,7.5,0.01,-0.02", "9,5,0,0,0,-0.8,0.0,-8.7", "9,-30,10,0,60,-0.9,-0.03,-17.6"]


def write(tmp_path, text, name="data.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_reads_good_file_with_comments_and_defaults(tmp_path):
    p = write(tmp_path, "# a comment\n\n" + HEADER + "\n" + "\n".join(GOOD_ROWS) + "\n")
    d = read_force_balance_csv(p)
    assert d.n_rows == 3
    assert d.comments == ("a comment",)
    assert d.air_density_kgpm3 is None and d.mass_kg is None
    assert d.wing_on.all()
    np.testing.assert_array_equal(d.line_numbers, [4, 5, 6])
    np.testing.assert_allclose(d.alpha_rad, np.radians([0, 5, -30]), rtol=0, atol=1e-15)
    np.testing.assert_allclose(d.force_B_N[2], [-0.9, -0.03, -17.6])


def make_data(n, rng, with_optional=True):
    return ForceBalanceData(
        airspeed_mps=rng.uniform(0, 9, n), alpha_rad=np.radians(rng.uniform(-45, 45, n)),
        beta_rad=np.radians(rng.uniform(-20, 20, n)), throttle_x_pct=rng.uniform(0, 100, n),
        throttle_z_pct=rng.uniform(0, 100, n), force_B_N=rng.normal(0, 10, (n, 3)),
        air_density_kgpm3=rng.uniform(1.0, 1.3, n) if with_optional else None,
        mass_kg=1.7 if with_optional else None, wing_on=rng.random(n) < 0.5,
        label=tuple(f"run{i}" for i in range(n)) if with_optional else None)


@settings(max_examples=examples(25), deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 30), opt=st.booleans())
def test_round_trip(tmp_path_factory, seed, n, opt):
    d = make_data(n, np.random.default_rng(seed), opt)
    p = write_force_balance_csv(tmp_path_factory.mktemp("rt") / "d.csv", d, ["hello"])
    e = read_force_balance_csv(p)
    # 10 significant digits in the file
    for name in ("airspeed_mps", "alpha_rad", "beta_rad", "throttle_x_pct", "throttle_z_pct", "force_B_N"):
        np.testing.assert_allclose(getattr(e, name), getattr(d, name), rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(e.wing_on, d.wing_on)
    assert e.label == d.label and e.mass_kg == d.mass_kg and e.comments == ("hello",)
    if opt:
        np.testing.assert_allclose(e.air_density_kgpm3, d.air_density_kgpm3, rtol=1e-9)


@settings(max_examples=examples(50), deadline=None)
@given(V=st.floats(0.1, 30), a=st.floats(-1.5, 1.5), b=st.floats(-1.5, 1.5))
def test_incident_velocity_inverts_airflow_angles(V, a, b):
    """v_i from (V, alpha, beta) gives back the same angles through the control kernel (eq:alphabeta)."""
    v = incident_velocity_from_angles(V, a, b)
    V2, a2, b2 = forces.airflow_angles(np.asarray(v, float))
    assert V2 == pytest.approx(V, rel=1e-12)
    assert a2 == pytest.approx(a, abs=1e-9)
    assert b2 == pytest.approx(b, abs=1e-7)


BAD_CASES = [
    # (header, rows, expected fragments of the message)
    (HEADER.replace(",force_z_N", ""), ["0,0,0,50,0,7.5,0.01"], ["line 1", "missing required column 'force_z_N'"]),
    (HEADER, ["0,0,0,50,0,7.5,0.01,-0.02", "9,abc,0,0,0,-0.8,0.0,-8.7"],
     ["line 3", "data row 2", "column 'alpha_deg'", "'abc'", "not a number"]),
    (HEADER, ["0,0,0,50,0,7.5,nan,-0.02"], ["line 2", "data row 1", "column 'force_y_N'", "not finite"]),
    (HEADER, GOOD_ROWS[:2] + ["9,0,0,0,120,-0.8,0.0,-8.7"],
     ["line 4", "data row 3", "column 'throttle_z_pct'", "'120'", "out of range", "<= 100"]),
    (HEADER, ["-1,0,0,0,0,-0.8,0.0,-8.7"], ["line 2", "column 'airspeed_mps'", "'-1'", ">= 0"]),
    (HEADER, ["0,0,0,-5,0,7.5,0.01,-0.02"], ["column 'throttle_x_pct'", "out of range"]),
    (HEADER, ["0,95,0,0,0,7.5,0.01,-0.02"], ["column 'alpha_deg'", "< 90"]),
    (HEADER, ["0,0,0,50,0,7.5,0.01"], ["line 2", "7 fields", "8"]),
    (HEADER, ["0,0,0,50,0,7.5,,0.2"], ["line 2", "column 'force_y_N'", "empty value"]),
    (HEADER + ",air_density", GOOD_ROWS, ["unknown column 'air_density'", "did you mean 'air_density_kgpm3'"]),
    (HEADER + ",wing_on", [GOOD_ROWS[0] + ",2"], ["line 2", "column 'wing_on'", "0 or 1"]),
    (HEADER + ",mass_kg", [GOOD_ROWS[0] + ",1.7", GOOD_ROWS[1] + ",1.8"],
     ["line 3", "column 'mass_kg'", "same in every row"]),
    (HEADER + ",air_density_kgpm3", [GOOD_ROWS[0] + ",0"], ["column 'air_density_kgpm3'", ">= 0.3"]),
    (HEADER + ",force_x_N", [GOOD_ROWS[0] + ",1"], ["'force_x_N' appears twice"]),
    (HEADER, [], ["no data rows"]),
]


@pytest.mark.parametrize("header,rows,fragments", BAD_CASES)
def test_malformed_file_names_row_and_column(tmp_path, header, rows, fragments):
    p = write(tmp_path, header + "\n" + "\n".join(rows) + "\n")
    with pytest.raises(FitDataError) as info:
        read_force_balance_csv(p)
    msg = str(info.value)
    assert str(p) in msg
    for frag in fragments:
        assert frag in msg, (frag, msg)


def test_errors_are_config_errors_and_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="file not found"):
        read_force_balance_csv(tmp_path / "nope.csv")
    with pytest.raises(FitDataError, match="no header"):
        read_force_balance_csv(write(tmp_path, "# only a comment\n"))
