"""Calibration JSON round trip; CSV format; clear errors on bad input."""
from __future__ import annotations

from conftest import REPO_DATA_DIR

import json
from pathlib import Path

import numpy as np
import pytest

from vtoladapt.probe import (
    ProbeError,
    ProbeTip,
    calibrate,
    load_calibration,
    read_nasa_pcf,
    read_probe_csv,
    save_calibration,
    simulate_calibration_sweep,
    write_probe_csv,
)
from vtoladapt.probe.data import read_probe_data

NASA = REPO_DATA_DIR / "nasa-multihole-probe"


@pytest.fixture(scope="module")
def sim():
    data = simulate_calibration_sweep(ProbeTip(), np.random.default_rng(4), n_rings=6, n_test=20)
    return data, calibrate(data)


def test_calibration_json_round_trip(tmp_path, sim):
    data, models = sim
    path = save_calibration(tmp_path / "cal.json", models, source="simulated")
    doc = json.loads(path.read_text())
    assert doc["format"] == "vtoladapt.probe.calibration" and doc["version"] == 1
    assert set(doc["models"]) == {"single_k", "calibrated"}
    loaded = load_calibration(path)
    assert loaded["single_k"] == models["single_k"]
    for name in models:
        assert np.array_equal(loaded[name].to_kernel(), models[name].to_kernel())
        v0, ok0 = models[name].estimate(data.q_Pa, data.rho)
        v1, ok1 = loaded[name].estimate(data.q_Pa, data.rho)
        assert np.array_equal(v0, v1) and np.array_equal(ok0, ok1)
    one = load_calibration(path, model="calibrated")
    assert np.array_equal(one.centres, models["calibrated"].centres)
    assert path.stat().st_size < 200_000  # "small": a few tens of kB


def _edit(tmp_path, sim, fn):
    path = save_calibration(tmp_path / "cal.json", sim[1])
    doc = json.loads(path.read_text())
    fn(doc)
    path.write_text(json.dumps(doc))
    return path


def test_calibration_file_errors_name_file_field_and_value(tmp_path, sim):
    p = _edit(tmp_path, sim, lambda d: d.update(version=2))
    with pytest.raises(ProbeError, match=r"cal\.json: version = 2: unsupported"):
        load_calibration(p)
    p = _edit(tmp_path, sim, lambda d: d.update(format="something else"))
    with pytest.raises(ProbeError, match="format = 'something else'"):
        load_calibration(p)
    p = _edit(tmp_path, sim, lambda d: d["models"].update(fancy=d["models"]["single_k"]))
    with pytest.raises(ProbeError, match=r"cal\.json: models\.fancy: unknown model name"):
        load_calibration(p)
    p = _edit(tmp_path, sim, lambda d: d["models"]["single_k"].update(kind="neural"))
    with pytest.raises(ProbeError, match=r"models\.single_k: kind = 'neural': unknown model kind"):
        load_calibration(p)
    p = _edit(tmp_path, sim, lambda d: d["models"]["single_k"].update(k=-1.0))
    with pytest.raises(ProbeError, match=r"models\.single_k: k = -1\.0: out of range"):
        load_calibration(p)
    p = _edit(tmp_path, sim, lambda d: d["models"]["calibrated"].pop("weights"))
    with pytest.raises(ProbeError, match=r"models\.calibrated: missing field 'weights'"):
        load_calibration(p)
    p = _edit(tmp_path, sim, lambda d: d["models"]["calibrated"].update(centres=[[0, 0]]))
    with pytest.raises(ProbeError, match=r"models\.calibrated: centres has shape"):
        load_calibration(p)
    p = save_calibration(tmp_path / "ok.json", sim[1])
    with pytest.raises(ProbeError, match=r"ok\.json: model = 'best': unknown model name"):
        load_calibration(p, model="best")
    with pytest.raises(ProbeError, match="file not found"):
        load_calibration(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(ProbeError, match=r"bad\.json: not valid JSON"):
        load_calibration(tmp_path / "bad.json")
    with pytest.raises(ProbeError, match="model name 'mine' unknown"):
        save_calibration(tmp_path / "x.json", {"mine": sim[1]["single_k"]})


def test_csv_round_trip(tmp_path, sim):
    data, _ = sim
    path = write_probe_csv(tmp_path / "probe.csv", data, comment="simulated sweep\nsecond line")
    back = read_probe_csv(path)
    assert read_probe_data(path).source == str(path)
    for name in ("alpha_deg", "beta_deg", "V_mps", "rho", "q_Pa", "is_test"):
        assert np.array_equal(getattr(back, name), getattr(data, name)), name


def _csv(tmp_path, text, name="p.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


HEADER = "alpha_deg,beta_deg,q_inf_Pa,q_alpha_Pa,q_beta_Pa,rho_kgpm3,V_mps,split\n"
ROW = "2.0,1.0,130.0,10.0,5.0,1.2,15.0,calibration\n"


def test_csv_q_dyn_column_and_split(tmp_path):
    p = _csv(tmp_path, "# comment\n\nalpha_deg,beta_deg,q_inf_Pa,q_alpha_Pa,q_beta_Pa,"
                       "rho_kgpm3,q_dyn_Pa\n1,2,100,3,4,1.25,160\n")
    d = read_probe_csv(p)
    assert d.V_mps[0] == pytest.approx(16.0)
    assert not d.has_test_points
    p = _csv(tmp_path, HEADER + ROW + ROW.replace("calibration", "test")
             + ROW.replace("calibration", ""))
    assert list(read_probe_csv(p).is_test) == [False, True, False]


@pytest.mark.parametrize("text,match", [
    (HEADER.replace("q_beta_Pa,", "") + ROW.replace("5.0,", ""),
     r"p\.csv: missing column 'q_beta_Pa'"),
    (HEADER + ROW + "2.0,1.0,130.0,10.0,5.0,1.2\n", r"p\.csv: line 3: 6 fields, expected 8"),
    (HEADER + ROW.replace("130.0", "abc"),
     r"p\.csv: line 2, column 'q_inf_Pa': value 'abc' is not a number"),
    (HEADER + ROW.replace("130.0", "nan"), r"line 2, column 'q_inf_Pa': value 'nan' is not finite"),
    (HEADER + ROW.replace("calibration", "validation"),
     r"line 2, column 'split': value 'validation' is unknown"),
    (HEADER.replace("split", "splt") + ROW, r"line 1: unknown column 'splt'"),
    (HEADER.replace("V_mps", "q_dyn_Pa,V_mps") + ROW.replace("15.0", "1,15.0"),
     "exactly one of the columns 'V_mps'"),
    (HEADER + ROW.replace("1.2,", "-1.2,"), r"line 2, column 'rho_kgpm3': value -1\.2 is out"),
    (HEADER + ROW.replace("1.0,130", "95.0,130"), r"column 'beta_deg': value 95\.0 is out"),
    (HEADER, "header only"),
    ("# nothing\n", "no header line"),
])
def test_csv_errors_name_file_row_field_value(tmp_path, text, match):
    with pytest.raises(ProbeError, match=match):
        read_probe_csv(_csv(tmp_path, text))


def test_read_probe_data_rejects_unknown_format(tmp_path):
    with pytest.raises(ProbeError, match="format = 'xlsx': unknown"):
        read_probe_data(_csv(tmp_path, HEADER + ROW), "xlsx")
    with pytest.raises(ProbeError, match="file not found"):
        read_probe_csv(tmp_path / "nope.csv")


def test_nasa_reader_errors_name_file_line_value(tmp_path):
    """A corrupted copy (in tmp_path only) gives errors naming the file, line and value."""
    lines = (NASA / "16328-1_M050.csv").read_text().splitlines()
    bad = list(lines)
    bad[20] = bad[20].replace("1.2", "x.2", 1)
    p = tmp_path / "bad_value.csv"
    p.write_text("\n".join(bad) + "\n")
    with pytest.raises(ProbeError, match=r"bad_value\.csv: line 21, column '.*': value 'x\.2"):
        read_nasa_pcf(p)
    bad = list(lines)
    bad[30] = "\t".join(bad[30].split("\t")[:5])
    p = tmp_path / "short_row.csv"
    p.write_text("\n".join(bad) + "\n")
    with pytest.raises(ProbeError, match=r"short_row\.csv: line 31: 5 values, expected 11"):
        read_nasa_pcf(p)
    bad = list(lines)
    bad[13] = bad[13].replace("P4[Torr]", "P4")
    p = tmp_path / "no_col.csv"
    p.write_text("\n".join(bad) + "\n")
    with pytest.raises(ProbeError, match=r"no_col\.csv: line 14: missing column 'P4\[Torr\]'"):
        read_nasa_pcf(p)
    p = tmp_path / "truncated.csv"
    p.write_text("\n".join(lines[:-5]) + "\n")
    with pytest.raises(ProbeError, match="580 data rows, but the header says CalPts = 490"):
        read_nasa_pcf(p)
    p = tmp_path / "not_pcf.csv"
    p.write_text(HEADER + ROW)
    with pytest.raises(ProbeError, match="not an Aeroprobe PCF file"):
        read_nasa_pcf(p)
