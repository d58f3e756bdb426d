"""Scenarios: validation with clear errors, determinism by seed, results round trip, the CLI."""
import dataclasses
import json

import numpy as np
import pytest

from vtoladapt.cli import main
from vtoladapt.config import ConfigError
from vtoladapt.sim.results import SimulationResult
from vtoladapt.sim.scenario import load_scenario, scenario_from_mapping
from vtoladapt.sim.driver import simulate, simulate_many

BASE = {"name": "t", "vehicle": "caltech_vtol", "duration_s": 2.0, "seed": 5,
        "wind": {"fan_array": {"schedule": [[0, 30], [2, 30]]},
                 "turbulence": {"enabled": True, "mean_wind_fraction": [0.05, 0.05, 0.03]}}}


@pytest.mark.parametrize("change, fragment", [
    ({"duraton_s": 3.0}, r"duraton_s.*did you mean 'duration_s'"),
    ({"duration_s": -1.0}, r"duration_s = -1.0: out of range"),
    ({"controller": {"kind": "lqr"}}, r"kind = 'lqr': unknown"),
    ({"wind": {"fan_array": {"schedule": [[0, 30], [1, 130]]}}}, r"130"),
    ({"vehicle": "no_such_plane"}, r"no_such_plane.*unknown name"),
    ({"plant": {"coefficients": {"CTz": -1.0}}}, r"CTz = -1.0"),
    ({"experiment": {"kind": "comparison", "controllers": ["pid", "pid"]}}, r"without repeats"),
    ({"reference": {"kind": "waypoints", "waypoints": [[0, 0, 0, -1]]}}, r"at least two rows"),
])
def test_bad_scenarios_fail_naming_key_and_value(change, fragment):
    with pytest.raises(ConfigError, match=fragment):
        scenario_from_mapping({**BASE, **change}, "bad.toml")


def test_cli_rejects_bad_scenario_and_writes_nothing(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "b"\nvehicle = "caltech_vtol"\nduration_s = -2.0\n')
    out = tmp_path / "out"
    assert main(["run", str(bad), "--out", str(out), "--quiet"]) == 2
    assert "duration_s = -2.0" in capsys.readouterr().err
    assert not out.exists()
    good = tmp_path / "good.toml"
    good.write_text('name = "g"\nvehicle = "caltech_vtol"\nduration_s = 1.0\n')
    assert main(["run", str(good), "--out", str(out), "--controller", "magic", "--quiet"]) == 2
    assert not out.exists()


def test_same_seed_bit_identical_different_seed_different():
    sc = scenario_from_mapping(BASE, "t")
    a, b = simulate(sc), simulate(sc)
    np.testing.assert_array_equal(a.data, b.data)
    c = simulate(sc.replace(seed=6))
    assert not np.array_equal(a.data, c.data)


def test_parallel_runs_are_bit_identical_to_sequential_ones():
    """simulate_many on two threads: each run as if alone, in the order given, progress summed."""
    base = scenario_from_mapping(BASE, "t")
    scenarios = [base.replace(seed=s, controller=dataclasses.replace(base.controller, kind=k))
                 for s, k in ((5, "composite"), (6, "pid"), (7, "composite_pconst"))]
    seen = []
    parallel = simulate_many(scenarios, workers=2, progress=lambda done, total: seen.append((done, total)))
    for sc, res in zip(scenarios, parallel):
        np.testing.assert_array_equal(res.data, simulate(sc).data)
        assert res.metadata["controller"] == sc.controller.kind
    assert seen[-1] == (6.0, 6.0) and all(d <= t for d, t in seen)
    with pytest.raises(ValueError, match="workers = 0"):
        simulate_many(scenarios, workers=0)


def test_result_parquet_round_trip(tmp_path):
    res = simulate(scenario_from_mapping(BASE, "t"))
    path = res.to_parquet(tmp_path / "log.parquet")
    back = SimulationResult.from_parquet(path)
    assert back.columns == res.columns
    np.testing.assert_array_equal(back.data, res.data)
    assert back.metadata["seed"] == 5 and back.metadata["controller"] == "composite"
    assert back.velocity_W.shape == (len(res), 3) and back.theta_hat.shape == (len(res), 8)


def test_velocity_error_is_the_controllers_reference_velocity_row_by_row():
    """``v~ = v - v_r`` of the log (computed for all rows at once) against the controller's own
    :func:`~vtoladapt.control.tracking.reference_velocity` row by row, with the correction limit
    reached on part of the run (starting 0.8 m from the held point, limit 0.5 m/s)."""
    from vtoladapt.control.tracking import reference_velocity

    data = {**BASE, "controller": {"velocity_correction_max_mps": 0.5},
            "initial": {"position_m": [0.8, 0.0, -1.5]}}
    res = simulate(scenario_from_mapping(data, "t"))
    lam = np.asarray(res.metadata["Lambda_p"])
    p_tilde = res.position_error_W
    v_d = res.columns_like(("ref_v_N_mps", "ref_v_E_mps", "ref_v_D_mps"))
    a_d = res.columns_like(("ref_a_N_mps2", "ref_a_E_mps2", "ref_a_D_mps2"))
    v = res.velocity_W
    saturated = 0
    for k in range(len(res)):
        v_r, _, sat = reference_velocity(p_tilde[k], v_d[k], a_d[k], v[k], lam, 0.5)
        saturated += sat
        np.testing.assert_allclose(res.velocity_error_W[k], v[k] - np.array(v_r), rtol=1e-14, atol=1e-15)
    assert 0 < saturated < len(res)


def test_run_writes_log_metrics_and_figure(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('name = "s"\nvehicle = "caltech_vtol"\nduration_s = 3.0\n'
                    '[wind.fan_array]\nschedule = [[0, 30], [3, 30]]\n')
    assert main(["run", str(path), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert np.isfinite(m["run"]["vel_err_rms_mps"])
    assert SimulationResult.from_parquet(tmp_path / "o" / "log.parquet")["t_s"][-1] == pytest.approx(2.996)
    assert (tmp_path / "o" / "fig_run.png").stat().st_size > 10_000


@pytest.mark.parametrize("name", ["paper_comparison", "paper_convergence"])
def test_shipped_scenarios_load(name):
    sc = load_scenario(name)
    assert sc.vehicle == "caltech_vtol" and sc.dt_control_s == 0.004
    assert sc.experiment.kind in ("comparison", "convergence")


@pytest.mark.slow
def test_cold_start_compiles_in_two_processes_and_fills_the_cache(tmp_path):
    """A first run on an empty kernel cache compiles (the controller in a helper process) and
    leaves every kernel cached: a second process then starts in seconds."""
    import os
    import subprocess
    import sys

    scen = tmp_path / "s.toml"
    scen.write_text('name = "cold"\nvehicle = "caltech_vtol"\nduration_s = 0.5\n')
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba_cache"))
    cmd = [sys.executable, "-m", "vtoladapt.cli", "run", str(scen), "--out", str(tmp_path / "out")]
    first = subprocess.run(cmd, env=env, capture_output=True, text=True)
    assert first.returncode == 0, first.stderr
    assert "Loading compiled kernels" in first.stderr
    cache = tmp_path / "numba_cache"
    assert list(cache.rglob("kernel.controller_step-*.nbi"))
    before = {p: p.stat().st_mtime_ns for p in cache.rglob("*.nb*")}
    second = subprocess.run(cmd + ["--quiet"], env=env, capture_output=True, text=True)
    assert second.returncode == 0, second.stderr
    after = {p: p.stat().st_mtime_ns for p in cache.rglob("*.nb*")}
    assert after == before  # everything loaded from the cache: nothing compiled or rewritten


def test_a_file_cannot_move_its_own_location_with_source_path(tmp_path):
    """source_path is filled in by the loader (relative vehicle and posterior paths are resolved
    against it); a file that sets it was accepted and silently re-pointed those paths."""
    from vtoladapt.vehicle import VEHICLE_DIR, load_vehicle

    sc = tmp_path / "sp.toml"
    sc.write_text('name = "x"\nvehicle = "caltech_vtol"\nduration_s = 1.0\nsource_path = "/etc/passwd"\n')
    with pytest.raises(ConfigError, match=r"sp\.toml: source_path = '/etc/passwd': unknown key"):
        load_scenario(sc)
    veh = tmp_path / "v.toml"
    veh.write_text('source_path = "elsewhere.toml"\n' + (VEHICLE_DIR / "caltech_vtol.toml").read_text())
    with pytest.raises(ConfigError, match=r"v\.toml: source_path = 'elsewhere.toml': unknown key"):
        load_vehicle(veh)
    typo = tmp_path / "typo.toml"
    typo.write_text('name = "x"\nvehicle = "caltech_vtol"\nduration_s = 1.0\nsourcepath = 1\n')
    with pytest.raises(ConfigError, match="unknown key") as err:
        load_scenario(typo)
    assert "source_path" not in str(err.value).lower().split("allowed keys:")[1]  # not offered as allowed


def test_a_missing_probe_calibration_file_is_refused_at_load_naming_scenario_and_key(tmp_path):
    """It was found missing only when the run was set up, in a message naming the JSON file alone."""
    sc = tmp_path / "cal.toml"
    sc.write_text('name = "x"\nvehicle = "caltech_vtol"\nduration_s = 1.0\n'
                  '[sensors.probe]\nmodel = "pressure"\ncalibration_file = "nothere.json"\n')
    with pytest.raises(ConfigError, match=r"cal\.toml: \[sensors.probe\] calibration_file = 'nothere.json': "
                                          r"file not found"):
        load_scenario(sc)


def test_unknown_scenario_lists_every_shipped_one_by_the_name_that_loads_it():
    with pytest.raises(ConfigError, match="file not found") as err:
        load_scenario("no_such_scenario")
    listed = str(err.value).split("shipped scenarios: ", 1)[1].split(", ")
    assert "paper_comparison" in listed and "faults/lift_motor_loss" in listed
    for name in listed:
        load_scenario(name)
    with pytest.raises(ConfigError, match="a campaign file .* vtoladapt campaign"):
        load_scenario("envelope")


@pytest.mark.parametrize("kind", ["pid", "pd", "nominal", "indi", "l1"])
def test_convergence_experiment_needs_a_law_that_adapts_theta(kind, tmp_path):
    """A convergence experiment judges how theta-hat converges: laws holding theta-hat = theta_0 are refused."""
    with pytest.raises(ConfigError, match=f"kind = '{kind}'.*convergence"):
        scenario_from_mapping({"name": "c", "vehicle": "caltech_vtol", "duration_s": 1.0,
                               "controller": {"kind": kind}, "experiment": {"kind": "convergence"}}, "c.toml")
    rc = main(["run", "paper_convergence", "--controller", kind, "--out", str(tmp_path / "o")])
    assert rc == 2 and not (tmp_path / "o").exists()
