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
