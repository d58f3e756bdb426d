"""The command line for a user's own things (issue #37): a relative path's meaning, ``run --vehicle /
--controller / --plugin``, ``scenario list / show``, ``--version``, files of the wrong kind, a thinned
log (``[output] log_rate_hz``, ``--log-rate``, ``--no-log``) and ``export``.

Commands run in this process through :func:`vtoladapt.cli.main`; the few that fly keep to a
second or two of simulated time.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from vtoladapt.cli import main
from vtoladapt.config import ConfigError
from vtoladapt.errors import ExitCode
from vtoladapt.sim.scenario import load_scenario
from vtoladapt.vehicle import VEHICLE_DIR

REPO = Path(__file__).resolve().parents[1]


def _my_plane(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "my_plane.toml"
    path.write_text((VEHICLE_DIR / "caltech_vtol.toml").read_text().replace('name = "caltech_vtol"',
                                                                           'name = "my_plane"'))
    return path


def _err_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    return lines[0]


# --- a relative path ---------------------------------------------------------------------------------
def test_a_vehicle_path_given_in_python_is_relative_to_the_working_directory(tmp_path, monkeypatch):
    _my_plane(tmp_path / "out" / "own_vehicle")
    monkeypatch.chdir(tmp_path)
    scenario = replace(load_scenario("gym_hold"), vehicle="out/own_vehicle/my_plane.toml")
    assert scenario.load_vehicle().name == "my_plane"


def test_a_vehicle_path_written_in_a_scenario_file_is_relative_to_that_file(tmp_path, monkeypatch):
    _my_plane(tmp_path / "scenarios")
    (tmp_path / "scenarios" / "s.toml").write_text('name = "s"\nvehicle = "my_plane.toml"\nduration_s = 1.0\n')
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    scenario = load_scenario("../scenarios/s.toml")
    assert scenario.load_vehicle().name == "my_plane"
    assert Path(scenario.vehicle) == Path("../scenarios/my_plane.toml")  # now relative to the working directory


# --- --version, --help -------------------------------------------------------------------------------
def test_version_prints_the_package_version(capsys):
    from vtoladapt import __version__

    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"vtoladapt {__version__}"


def test_help_shows_no_rest_markup(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "``" not in out and ":class:" not in out and ":mod:" not in out
    assert "vtoladapt scenario list | show NAME" in out and "export RUN" in out


# --- files of the wrong kind --------------------------------------------------------------------------
def test_a_vehicle_file_given_to_run_is_named_as_one(tmp_path, capsys):
    vehicle = _my_plane(tmp_path)
    assert main(["run", str(vehicle), "--out", str(tmp_path / "o")]) == ExitCode.BAD_INPUT
    line = _err_line(capsys)
    assert f"{vehicle}: this is a vehicle file (it has basis" in line
    assert "`vtoladapt run` (and load_scenario) takes a scenario file" in line and "--vehicle" in line
    assert not (tmp_path / "o").exists()


def test_a_scenario_given_to_vehicle_is_named_as_one(tmp_path, capsys):
    scenario = REPO / "src" / "vtoladapt" / "scenarios" / "gym_hold.toml"
    assert main(["run", "gym_hold", "--vehicle", str(scenario), "--out", str(tmp_path / "o")]) == ExitCode.BAD_INPUT
    line = _err_line(capsys)
    assert f"{scenario}: this is a scenario file (it has duration_s" in line and "takes a vehicle file" in line
    assert main(["vehicle", "show", str(scenario)]) == ExitCode.BAD_INPUT
    assert "this is a scenario file" in _err_line(capsys)


def test_a_scenario_given_to_tuned_and_a_misspelt_scenario_stay_what_they_are(tmp_path, capsys):
    scenario = REPO / "src" / "vtoladapt" / "scenarios" / "gym_hold.toml"
    assert main(["run", "gym_hold", "--tuned", str(scenario), "--out", str(tmp_path / "o")]) == ExitCode.BAD_INPUT
    assert "this is a scenario file" in _err_line(capsys)
    typo = tmp_path / "typo.toml"
    typo.write_text('name = "t"\nvehicle = "caltech_vtol"\nduration_s = 1.0\nbasis = "paper"\n')
    assert main(["run", str(typo), "--out", str(tmp_path / "o")]) == ExitCode.BAD_INPUT
    assert "basis = 'paper': unknown key" in _err_line(capsys)  # a scenario with a vehicle's key


# --- --controller, --vehicle ----------------------------------------------------------------------------
@pytest.mark.parametrize("argv, needle", [
    (["--controller", "nosuch"], "--controller = 'nosuch': unknown; allowed: "),
    (["--controller", "composite,pd"], "'single' experiment, which flies one law; allowed: one id"),
    (["--controller", "pd", "--controller", "pd"], "an id given twice"),
    (["--vehicle", "nosuch_plane"], "vehicle 'nosuch_plane': unknown name; shipped vehicles: caltech_vtol"),
    (["--log-rate", "0"], "--log-rate = 0.0: out of range; allowed: > 0"),
    (["--log-rate", "1000"], "log_rate_hz = 1000: above the control rate; allowed: at most 250 Hz"),
])
def test_overrides_are_checked_in_one_line(tmp_path, capsys, argv, needle):
    assert main(["run", "gym_hold", "--out", str(tmp_path / "o"), *argv]) == ExitCode.BAD_INPUT
    assert needle in _err_line(capsys)
    assert not (tmp_path / "o").exists()


def test_controllers_of_a_comparison_are_the_ones_given_in_order(tmp_path):
    from vtoladapt.cli import _controller_ids, load_run_scenario

    ids = _controller_ids(["pd,composite", "nominal"])
    sc = load_run_scenario("paper_comparison", controller=ids, vehicle=str(_my_plane(tmp_path)))
    assert sc.experiment.controllers == ("pd", "composite", "nominal") and sc.controller.kind == "pd"
    assert sc.load_vehicle().name == "my_plane"


# --- scenario list / show -----------------------------------------------------------------------------
def test_scenario_list_names_the_shipped_ones(capsys):
    assert main(["scenario", "list"]) == 0
    names = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert "gym_hold" in names and "faults/imu_nan" in names and "envelope" not in names  # a campaign file


def test_scenario_show_writes_a_file_that_loads_back_as_the_same_scenario(tmp_path, capsys, monkeypatch):
    assert main(["scenario", "show", "gym_hold"]) == 0
    (tmp_path / "my.toml").write_text(capsys.readouterr().out)
    monkeypatch.chdir(tmp_path)
    mine, shipped = load_scenario("my.toml"), load_scenario("gym_hold")
    assert replace(mine, source_path="") == replace(shipped, source_path="")
