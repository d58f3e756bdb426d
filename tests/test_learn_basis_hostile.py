"""Issue #33's ``learn-basis`` reproducers and the other messages of its item 13, each a test: exit 2, one line
naming the file, nothing written or changed (the inputs' bytes and times, no new file in any folder)."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from vtoladapt.cli import main
from vtoladapt.vehicle import VEHICLE_DIR

from test_learned_files_hostile import folder_state, refused


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    """One short simulator log (1.5 s) to copy and tamper with."""
    from vtoladapt import simulate
    from vtoladapt.sim.scenario import scenario_from_mapping

    path = tmp_path_factory.mktemp("logs") / "flight.parquet"
    simulate(scenario_from_mapping({"name": "f", "vehicle": "caltech_vtol", "duration_s": 1.5, "seed": 1},
                                   "test")).to_parquet(path)
    return path


def tampered(log, dest, rows=None, **metadata):
    from vtoladapt.sim.results import SimulationResult

    res = SimulationResult.from_parquet(log)
    if rows is not None:
        res = SimulationResult(res.columns, res.data[:rows], res.metadata)
    res.metadata.update(metadata)
    res.to_parquet(dest)
    return dest


def test_a_log_of_0_rows_is_refused(log, tmp_path, capsys):
    """Reproducer 6: IndexError in _select (t_s[0])."""
    empty = tampered(log, tmp_path / "empty.parquet", rows=0)
    shutil.copy2(log, tmp_path / "ok.parquet")
    err = refused(["learn-basis", tmp_path / "ok.parquet", empty, "--out", tmp_path / "n.npz"], capsys, tmp_path)
    assert "empty.parquet: 0 rows" in err


@pytest.mark.parametrize("key, value, message", [
    ("draw", [1, 2], r"metadata draw = \[1, 2\]; allowed: a table"),
    ("vehicle", 5, r"metadata vehicle = 5; allowed"),
    ("seed", "x", r"metadata seed = 'x'; allowed: a whole number"),
])
def test_metadata_of_the_wrong_type_is_refused(log, tmp_path, capsys, key, value, message):
    """Reproducer 7: a draw that is a list raised TypeError in data.read_flight."""
    bad = tampered(log, tmp_path / "bad.parquet", **{key: value})
    err = refused(["learn-basis", bad, "--out", tmp_path / "n.npz"], capsys, tmp_path)
    assert str(bad) in err and __import__("re").search(message, err), err


@pytest.mark.parametrize("content", [b"", b"a text file\n", b"ULog\x01\x12\x35" + b"\x01garbage" * 50])
def test_a_ulg_that_is_not_a_ulog_is_bad_input(tmp_path, capsys, content):
    """Reproducer 8: exit 1 "internal error ReplayError ... please report it"."""
    path = tmp_path / "flight.ulg"
    path.write_bytes(content)
    err = refused(["learn-basis", path, "--vehicle", "caltech_vtol", "--out", tmp_path / "n.npz"], capsys, tmp_path)
    assert str(path) in err


def test_an_out_that_is_a_folder_is_refused_even_with_force(log, tmp_path, capsys):
    """Reproducer 9: exit 2 "DIR.part: Is a directory" and DIR.part (7 KB) left behind."""
    (tmp_path / "DIR").mkdir()
    shutil.copy2(log, tmp_path / "a.parquet")
    err = refused(["learn-basis", tmp_path / "a.parquet", "--out", tmp_path / "DIR", "--force"], capsys, tmp_path)
    assert "is a folder" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["DIR", "a.parquet"]


@pytest.mark.parametrize("which", ["first", "second"])
def test_an_out_that_is_an_input_log_is_refused_even_with_force(log, tmp_path, capsys, which):
    """Reproducer 10: `learn-basis a.parquet b.parquet --out a.parquet --force` replaced the input log."""
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    shutil.copy2(log, a)
    shutil.copy2(log, b)
    b.write_bytes(b.read_bytes())  # another file, same flight: distinct by identity
    out = a if which == "first" else b
    err = refused(["learn-basis", a, b, "--out", out, "--force"], capsys, tmp_path)
    assert f"--out {out}: is the log" in err


def test_an_out_that_is_a_named_input_file_is_refused(tmp_path, capsys):
    vehicle = tmp_path / "v.toml"
    vehicle.write_text((VEHICLE_DIR / "caltech_vtol.toml").read_text())
    err = refused(["learn-basis", tmp_path, "--vehicle", vehicle, "--out", vehicle, "--force"], capsys, tmp_path)
    assert "is the --vehicle input" in err


def test_the_same_log_twice_is_refused(log, tmp_path, capsys):
    """Reproducer 11: `learn-basis LOG LOG LOG` counted three flights; also a log given directly and in its folder."""
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy2(log, logs / "a.parquet")
    err = refused(["learn-basis", logs / "a.parquet", logs / "a.parquet", logs / "a.parquet", "--out",
                   tmp_path / "n.npz"], capsys, tmp_path)
    assert "the same log as" in err and "each flight once" in err
    refused(["learn-basis", logs, logs / "a.parquet", "--out", tmp_path / "n.npz"], capsys, tmp_path)


@pytest.mark.parametrize("name", ["../../../../etc/passwd", "{vehicle_file}", "no_such_vehicle", "caltech_vtol/.."])
def test_a_vehicle_named_by_a_log_is_only_a_shipped_name(log, tmp_path, capsys, monkeypatch, name):
    """Reproducer 12: the log's vehicle = "../../../../etc/passwd" was opened as TOML. A path in a log is never
    opened, not even to a valid vehicle file (that one trained: the log chose the file)."""
    vehicle_file = tmp_path / "mine.toml"
    vehicle_file.write_text((VEHICLE_DIR / "caltech_vtol.toml").read_text())
    name = name.format(vehicle_file=vehicle_file)
    bad = tampered(log, tmp_path / "bad.parquet", vehicle=name)
    import vtoladapt.vehicle as vehicle_module

    opened = []
    real = vehicle_module.read_toml
    monkeypatch.setattr(vehicle_module, "read_toml", lambda p, *a, **k: opened.append(str(p)) or real(p, *a, **k))
    err = refused(["learn-basis", bad, "--out", tmp_path / "n.npz"], capsys, tmp_path)
    assert "not a shipped vehicle" in err and "--vehicle" in err
    assert not [p for p in opened if "passwd" in p or "mine.toml" in p]


# --- the other messages of item 13 ----------------------------------------------------------------------
SCENARIO = 'name = "s"\nvehicle = "{vehicle}"\nduration_s = 0.2\n'


def test_a_surface_fault_on_a_vehicle_without_surfaces_says_so(tmp_path, capsys):
    """Item 13: "allowed: 1 to 0"."""
    text = (VEHICLE_DIR / "caltech_vtol.toml").read_text()
    vehicle = tmp_path / "bare.toml"
    vehicle.write_text(text[:text.index("[[surfaces]]")])
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO.format(vehicle=vehicle) + '[[faults]]\nkind = "surface_lost"\nstart_s = 0.1\n'
                        'end_s = 0.2\nsurface = 1\n')
    err = refused(["run", scenario, "--out", tmp_path / "out", "--quiet"], capsys, tmp_path)
    assert "surface = 1" in err and "1 to 0" not in err and "no [[surfaces]]" in err


def test_tune_names_an_integer_flag_as_an_integer(tmp_path, capsys):
    """Item 13: `--evaluations = 0.0` for an integer."""
    err = refused(["tune", "gym_hold", "--controller", "composite", "--evaluations", "0", "--out", tmp_path / "o"],
                  capsys, tmp_path)
    assert "--evaluations = 0:" in err and "0.0" not in err
    err = refused(["tune", "gym_hold", "--controller", "composite", "--draws", "0", "--out", tmp_path / "o"],
                  capsys, tmp_path)
    assert "--draws = 0:" in err


def test_surface_effectiveness_has_one_entry_per_surface_of_the_vehicle(tmp_path, capsys):
    """Item 13: `[plant] surface_effectiveness` demanded exactly 4 entries on a 3-surface vehicle."""
    from vtoladapt.sim.driver import prepare
    from vtoladapt.sim.scenario import scenario_from_mapping

    base = {"name": "s", "vehicle": "caltech_vtol", "duration_s": 0.2}
    for key in ("surface_effectiveness", "servo_time_constant_factors"):
        sc = scenario_from_mapping({**base, "plant": {key: [1.0, 0.5, 1.2]}}, "test")
        prepare(sc)  # three surfaces, three entries: accepted
        scenario = tmp_path / "s.toml"
        scenario.write_text(SCENARIO.format(vehicle="caltech_vtol") + f"[plant]\n{key} = [1.0, 0.5, 1.2, 1.0]\n")
        err = refused(["run", scenario, "--out", tmp_path / "out", "--quiet"], capsys, tmp_path)
        assert f"{key} = [1.0, 0.5, 1.2, 1.0]: 4 entries; allowed: 3 (one per [[surfaces]] entry" in err
        scenario.unlink()


def test_a_drawn_plant_has_one_effectiveness_per_surface_and_the_same_numbers():
    """The draw keeps its stream (one normal per slot) and hands the vehicle's surfaces the same values."""
    from vtoladapt import load_vehicle
    from vtoladapt.sim.truth import draw_physical_parameters

    veh = load_vehicle("caltech_vtol")
    d = draw_physical_parameters(veh, 3)
    assert len(d["surface_effectiveness"]) == len(veh.surfaces) == len(d["servo_time_constant_factors"])
    assert np.all(np.isfinite(d["surface_effectiveness"]))


def test_an_out_that_is_a_pipe_or_a_file_that_is_no_log_is_refused(log, tmp_path, capsys):
    """A pipe (or a device) as --out would be replaced by the renamed file even with --force; a LOG that is
    neither .parquet nor .ulg was read as a PX4 log."""
    import os

    shutil.copy2(log, tmp_path / "a.parquet")
    os.mkfifo(tmp_path / "fifo")
    err = refused(["learn-basis", tmp_path / "a.parquet", "--out", tmp_path / "fifo", "--force"], capsys, tmp_path)
    assert "is not a regular file" in err
    (tmp_path / "notes.toml").write_text("x = 1\n")
    err = refused(["learn-basis", tmp_path / "notes.toml", "--out", tmp_path / "n.npz"], capsys, tmp_path)
    assert "notes.toml: not a log file" in err
