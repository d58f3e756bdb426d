"""End to end through the CLI handlers: tunnel -> fit -> posterior.json -> controller prior."""
import json

import numpy as np
import pytest

import vtoladapt
from vtoladapt.fitting.posterior import controller_prior, load_posterior
from conftest import REPO_DATA_DIR

DATA = REPO_DATA_DIR


def run(argv) -> int:
    """The command through ``vtoladapt.cli.main`` (errors: one line, exit code 2)."""
    from vtoladapt.cli import main

    return main([str(a) for a in argv])


def test_tunnel_fit_posterior_end_to_end(cli_fit):
    """tunnel -> fit -> posterior.json -> controller prior (the run: conftest's ``cli_fit``)."""
    csv_path, side, out = cli_fit.csv_path, cli_fit.side, cli_fit.out
    assert cli_fit.tunnel_rc == 0
    assert csv_path.exists() and side.exists()
    assert cli_fit.fit_rc == 0
    for name in ("posterior.json", "table1.md", "corner.png", "trace.png", "side_force.png",
                 "residuals.png"):
        assert (out / name).stat().st_size > 0, name
    post = load_posterior(out / "posterior.json")
    raw = post.raw
    assert raw["data"]["n_rows"] == 511 and raw["data"]["path"] == str(csv_path)
    assert "rhat_split" in raw["diagnostics"] and "ess" in raw["diagnostics"]
    assert raw["priors"]["k1"] == "uniform on (0, 2)"
    veh = vtoladapt.load_vehicle("caltech_vtol")
    # even short chains land within 5 std of the truth on these data
    for name, t in raw["truth_check"].items():
        assert abs(t["z"]) < 5, (name, t)
    np.testing.assert_allclose(post.theta_table, veh.force_model.as_table_theta(), rtol=0.05)
    cp = controller_prior(post, veh)
    assert np.all(cp.lower_bounds_scaled < cp.theta_0_scaled)
    assert np.all(cp.theta_0_scaled < cp.upper_bounds_scaled)
    table = (out / "table1.md").read_text()
    assert "| Thruster | mean ± std | Aero | mean ± std |" in table and "| C_Tx |" in table
    assert "wrote" in cli_fit.stdout and "posterior.json" in cli_fit.stdout


def test_fit_reports_malformed_csv(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("airspeed_mps,alpha_deg,beta_deg,throttle_x_pct,throttle_z_pct,force_x_N,force_y_N,force_z_N\n"
                   "5,0,0,0,0,1,0,2\n5,0,0,150,0,1,0,2\n")
    assert run(["fit", bad, "--out", tmp_path / "o"]) == 2
    err = capsys.readouterr().err
    assert "line 3" in err and "column 'throttle_x_pct'" in err and "vtoladapt fit: error" in err
    assert not (tmp_path / "o" / "posterior.json").exists()


def test_tunnel_rejects_unknown_vehicle(tmp_path, capsys):
    assert run(["tunnel", "--vehicle", "nope", "--out", tmp_path / "x.csv"]) == 2
    assert "unknown name" in capsys.readouterr().err


def test_fit_realdata_command(tmp_path):
    out = tmp_path / "real"
    assert run(["fit-realdata", "--out", out, "--data-dir", DATA]) == 0
    res = json.loads((out / "realdata.json").read_text())
    assert res["uiuc_static_ct"]["prop"] == "magf 7.0x4.0"
    assert res["implied_pusher_full_throttle"]["speed_rpm"] > 0
    for name in ("realdata.md", "uiuc_7x4.png", "tudelft_polar.png"):
        assert (out / name).stat().st_size > 0


@pytest.mark.slow
def test_fit_validate_quick(tmp_path, capsys):
    assert run(["fit-validate", "--out", tmp_path, "--quick"]) == 0
    res = json.loads((tmp_path / "validation.json").read_text())
    assert len(res["sqrt_n"]["n_rows"]) == 2 and (tmp_path / "sqrt_n.png").exists()
    # progress on stderr: 1 full fit + 3 seeds + 2 sizes, each announced
    err = capsys.readouterr().err
    assert "6/6 fits" in err and "calibration study: seed 3" in err and "measured 4 times" in err
