"""``vtoladapt probe calibrate`` / ``evaluate`` end to end, through a small argparse parser."""
from __future__ import annotations

from conftest import REPO_DATA_DIR

import json
from pathlib import Path

import numpy as np

from vtoladapt.probe import ProbeTip, simulate_calibration_sweep, write_probe_csv

NASA = REPO_DATA_DIR / "nasa-multihole-probe"


def run_cli(argv: list[str]) -> int:
    """The command through ``vtoladapt.cli.main`` (errors: one line, exit code 2)."""
    from vtoladapt.cli import main

    return main(argv)


def _check_metrics(path: Path, points: str) -> dict:
    doc = json.loads(path.read_text())
    for name in ("single_k", "calibrated"):
        m = doc[name]
        for key in ("angle_rms_deg", "angle_max_deg", "speed_rms_rel"):
            assert isinstance(m[key], float) and np.isfinite(m[key])
        assert m["points"] == points
    assert doc["info"]["format"] == "vtoladapt.probe.metrics"
    return doc


def _check_png(path: Path) -> None:
    import matplotlib.image as mpimg

    img = mpimg.imread(path)
    assert img.shape[0] >= 400 and img.shape[1] >= 800
    assert float(np.std(img[..., :3])) > 0.05  # not blank


def test_cli_calibrate_and_evaluate_on_nasa(tmp_path, capsys):
    out = tmp_path / "cal"
    assert run_cli(["probe", "calibrate", str(NASA / "16328-1_M050.csv"), "--out", str(out)]) == 0
    assert "calibration.json" in capsys.readouterr().out
    doc = _check_metrics(out / "metrics.json", "test")
    assert doc["calibrated"]["angle_rms_deg"] <= 0.05
    assert 0.5 <= doc["single_k"]["angle_rms_deg"] <= 0.75
    assert doc["calibrated"]["n_points"] == 95
    assert "Mirhashemi" in doc["info"]["data_citation"]
    _check_png(out / "linearity.png")
    cal = json.loads((out / "calibration.json").read_text())
    assert set(cal["models"]) == {"single_k", "calibrated"}

    ev = tmp_path / "cross"
    assert run_cli(["probe", "evaluate", str(out / "calibration.json"),
                    str(NASA / "16328-2_M050.csv"), "--out", str(ev)]) == 0
    doc2 = _check_metrics(ev / "metrics.json", "test")
    assert doc2["calibrated"]["angle_rms_deg"] > doc["calibrated"]["angle_rms_deg"]
    _check_png(ev / "linearity.png")

    one = tmp_path / "one"
    assert run_cli(["probe", "evaluate", str(out / "calibration.json"),
                    str(NASA / "16328-1_M050.csv"), "--out", str(one), "--models", "calibrated",
                    "--points", "all"]) == 0
    d1 = json.loads((one / "metrics.json").read_text())
    assert "single_k" not in d1 and d1["calibrated"]["n_points"] == 585


def test_cli_on_user_csv_without_test_split(tmp_path, capsys):
    data = simulate_calibration_sweep(ProbeTip(), np.random.default_rng(2), n_rings=6, n_test=0)
    csv_path = write_probe_csv(tmp_path / "my_probe.csv", data)
    out = tmp_path / "out"
    assert run_cli(["probe", "calibrate", str(csv_path), "--out", str(out)]) == 0
    doc = _check_metrics(out / "metrics.json", "all")
    assert doc["calibrated"]["angle_rms_deg"] < doc["single_k"]["angle_rms_deg"]
    assert "in-sample" in capsys.readouterr().out
    assert (out / "calibration.json").is_file() and (out / "linearity.png").is_file()


def test_cli_bad_input_returns_error_code_with_message(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("alpha_deg,beta_deg,q_inf_Pa\n1,2,3\n")
    assert run_cli(["probe", "calibrate", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "bad.csv: missing column 'q_alpha_Pa'" in err

    data = simulate_calibration_sweep(ProbeTip(), np.random.default_rng(2), n_rings=5, n_test=5)
    csv_path = write_probe_csv(tmp_path / "p.csv", data)
    out = tmp_path / "o2"
    assert run_cli(["probe", "calibrate", str(csv_path), "--out", str(out)]) == 0
    capsys.readouterr()
    assert run_cli(["probe", "evaluate", str(out / "calibration.json"), str(csv_path),
                    "--out", str(tmp_path / "o3"), "--models", "single_k,magic"]) == 2
    assert "model name 'magic' unknown" in capsys.readouterr().err
    doc = json.loads((out / "calibration.json").read_text())
    doc["version"] = 99
    (out / "calibration.json").write_text(json.dumps(doc))
    assert run_cli(["probe", "evaluate", str(out / "calibration.json"), str(csv_path),
                    "--out", str(tmp_path / "o4")]) == 2
    assert "calibration.json: version = 99: unsupported" in capsys.readouterr().err


def test_cli_calibrate_refuses_points_on_one_line_naming_the_file(tmp_path, capsys):
    """An alpha sweep at beta = 0 cannot fix the spline's affine part: the error named no file and
    advised a smoothing > 0, which gives the same error."""
    from vtoladapt.cli import main

    rows = ["alpha_deg,beta_deg,q_inf_Pa,q_alpha_Pa,q_beta_Pa,rho_kgpm3,V_mps"]
    rows += [f"{a},0,137,{2.0 * a},0,1.225,15" for a in range(-6, 7)]
    data = tmp_path / "sweep.csv"
    data.write_text("\n".join(rows) + "\n")
    for extra in ([], ["--smoothing", "0.1"]):
        code = main(["probe", "calibrate", str(data), "--out", str(tmp_path / "cal"), *extra])
        err = capsys.readouterr().err
        assert code == 2
        assert "sweep.csv" in err and "lie on one line" in err and "both alpha and beta" in err
        assert "smoothing > 0" not in err
        assert not (tmp_path / "cal").exists()
