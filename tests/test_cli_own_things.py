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

from cli_helpers import one_error_line
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


def test_a_vehicle_path_on_the_command_line_is_relative_to_the_working_directory(tmp_path, monkeypatch):
    from vtoladapt.cli import load_run_scenario

    _my_plane(tmp_path / "planes")
    (tmp_path / "scenarios").mkdir()
    (tmp_path / "scenarios" / "s.toml").write_text('name = "s"\nvehicle = "caltech_vtol"\nduration_s = 1.0\n')
    monkeypatch.chdir(tmp_path)
    sc = load_run_scenario("scenarios/s.toml", vehicle="planes/my_plane.toml")
    assert sc.load_vehicle().name == "my_plane"


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
    line = one_error_line(capsys)
    assert f"{vehicle}: this is a vehicle file (it has basis" in line
    assert "`vtoladapt run` (and load_scenario) takes a scenario file" in line and "--vehicle" in line
    assert not (tmp_path / "o").exists()


def test_a_scenario_given_to_vehicle_is_named_as_one(tmp_path, capsys):
    scenario = REPO / "src" / "vtoladapt" / "scenarios" / "gym_hold.toml"
    assert main(["run", "gym_hold", "--vehicle", str(scenario), "--out", str(tmp_path / "o")]) == ExitCode.BAD_INPUT
    line = one_error_line(capsys)
    assert f"{scenario}: this is a scenario file (it has duration_s" in line and "takes a vehicle file" in line
    assert main(["vehicle", "show", str(scenario)]) == ExitCode.BAD_INPUT
    assert "this is a scenario file" in one_error_line(capsys)


def test_a_scenario_given_to_tuned_and_a_misspelt_scenario_stay_what_they_are(tmp_path, capsys):
    scenario = REPO / "src" / "vtoladapt" / "scenarios" / "gym_hold.toml"
    assert main(["run", "gym_hold", "--tuned", str(scenario), "--out", str(tmp_path / "o")]) == ExitCode.BAD_INPUT
    assert "this is a scenario file" in one_error_line(capsys)
    typo = tmp_path / "typo.toml"
    typo.write_text('name = "t"\nvehicle = "caltech_vtol"\nduration_s = 1.0\nbasis = "paper"\n')
    assert main(["run", str(typo), "--out", str(tmp_path / "o")]) == ExitCode.BAD_INPUT
    assert "basis = 'paper': unknown key" in one_error_line(capsys)  # a scenario with a vehicle's key


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
    assert needle in one_error_line(capsys)
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


# --- a thinned log; export ----------------------------------------------------------------------------
SHORT = 'name = "short"\nvehicle = "caltech_vtol"\nduration_s = 2.0\n'


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The same 2 s run with its full log, thinned to 50 Hz (--log-rate), thinned by the file, and none."""
    root = tmp_path_factory.mktemp("runs")
    (root / "short.toml").write_text(SHORT)
    (root / "short50.toml").write_text(SHORT + "\n[output]\nlog_rate_hz = 50.0\n")
    out = {}
    for name, argv in (("full", ["short.toml"]), ("flag", ["short.toml", "--log-rate", "50"]),
                       ("file", ["short50.toml"]), ("none", ["short.toml", "--no-log"])):
        assert main(["run", str(root / argv[0]), *argv[1:], "--out", str(root / name), "--quiet"]) == 0
        out[name] = root / name
    return out


def _run_metrics(folder: Path) -> dict:
    import json

    metrics = json.loads((folder / "metrics.json").read_text())["run"]
    metrics.pop("wall_time_s", None)  # the one that differs run to run
    return metrics


def test_metrics_use_every_tick_whatever_the_log_keeps(runs):
    full = _run_metrics(runs["full"])
    for name in ("flag", "file", "none"):
        assert _run_metrics(runs[name]) == full, name


def test_a_thinned_log_keeps_every_kth_tick_as_logged(runs):
    import pyarrow.parquet as pq

    from vtoladapt.sim.results import log_file_metadata

    full = pq.read_table(runs["full"] / "log.parquet")
    assert full.num_rows == 500  # 2 s at 250 Hz
    for name in ("flag", "file"):
        thin = pq.read_table(runs[name] / "log.parquet")
        assert thin.num_rows == 100  # duration x rate
        assert thin.equals(full.take(list(range(0, 500, 5))).replace_schema_metadata(thin.schema.metadata))
        meta = log_file_metadata(runs[name] / "log.parquet")
        assert meta["log_every_ticks"] == 5 and meta["log_rate_hz"] == 50.0


def test_no_log_writes_none_and_the_manifest_lists_none(runs):
    import json

    from vtoladapt.outputs import MANIFEST_NAME

    assert not (runs["none"] / "log.parquet").exists()
    assert "log.parquet" not in json.loads((runs["none"] / MANIFEST_NAME).read_text())["files"]
    assert "No log was kept" in (runs["none"] / "report.md").read_text()


def test_export_mat_reads_back_as_the_logs_columns_with_units(runs, tmp_path, capsys):
    import numpy as np
    import pyarrow.parquet as pq
    import scipy.io

    from vtoladapt.export import matlab_name

    out = tmp_path / "run.mat"
    assert main(["export", str(runs["flag"]), "--format", "mat", "--out", str(out)]) == 0
    table = pq.read_table(runs["flag"] / "log.parquet")
    mat = scipy.io.loadmat(out, squeeze_me=True, struct_as_record=False)
    taken = {"units", "columns", "vtoladapt_export"}
    for name in table.column_names:
        var = matlab_name(name, taken)
        assert var.isidentifier() and len(var) <= 63
        np.testing.assert_array_equal(np.atleast_1d(mat[var]), table.column(name).to_numpy(), err_msg=name)
    assert list(mat["columns"]) == table.column_names
    assert mat["units"].v_N_mps == "m/s" and mat["units"].t_s == "s"


def test_export_csv_reads_back_exactly_and_never_replaces_a_foreign_file(runs, tmp_path, capsys):
    import numpy as np
    import pyarrow.parquet as pq

    out = tmp_path / "run.csv"
    assert main(["export", str(runs["full"] / "log.parquet"), "--format", "csv", "--out", str(out)]) == 0
    table = pq.read_table(runs["full"] / "log.parquet")
    lines = out.read_text().splitlines()
    assert lines[0].startswith("# vtoladapt export") and lines[1].split(",") == table.column_names
    assert lines[2].split(",")[table.column_names.index("v_N_mps")] == "m/s"
    data = np.loadtxt(out, delimiter=",", skiprows=3)
    for i, name in enumerate(table.column_names):
        np.testing.assert_array_equal(data[:, i], table.column(name).to_numpy(), err_msg=name)
    assert main(["export", str(runs["full"]), "--format", "csv", "--out", str(out)]) == 0  # its own: replaced
    foreign = tmp_path / "mine.csv"
    foreign.write_text("my data\n")
    capsys.readouterr()
    assert main(["export", str(runs["full"]), "--format", "csv", "--out", str(foreign)]) == ExitCode.BAD_INPUT
    assert "not an output of 'vtoladapt export'" in one_error_line(capsys)
    assert foreign.read_text() == "my data\n"
    assert main(["export", str(runs["none"]), "--format", "csv", "--out", str(tmp_path / "x.csv")]) == 2
    assert "no log in this folder" in one_error_line(capsys)


def test_export_parquet_of_a_folder_is_its_log(runs, tmp_path):
    import pyarrow.parquet as pq

    from vtoladapt.sim.results import log_file_metadata

    out = tmp_path / "copy.parquet"
    assert main(["export", str(runs["file"]), "--format", "parquet", "--out", str(out)]) == 0
    assert pq.read_table(out).replace_schema_metadata(None).equals(
        pq.read_table(runs["file"] / "log.parquet").replace_schema_metadata(None))
    assert log_file_metadata(out)["log_every_ticks"] == 5


# --- a law of one's own -------------------------------------------------------------------------------
@pytest.fixture
def no_example_law():
    from vtoladapt import components

    yield
    if "example" in components.registry("law"):
        components.registry("law").unregister("example")


def test_plugin_file_makes_its_law_flyable(tmp_path, capsys, no_example_law):
    import json

    (tmp_path / "short.toml").write_text(SHORT)
    argv = ["run", str(tmp_path / "short.toml"), "--plugin", str(REPO / "examples" / "example_law.py"),
            "--controller", "example", "--duration", "1", "--out", str(tmp_path / "o"), "--quiet"]
    assert main(argv) == 0, capsys.readouterr().err
    assert json.loads((tmp_path / "o" / "metrics.json").read_text())["run"]["pos_err_max_m"] < 1.0
    assert main(["controllers", "--plugin", str(REPO / "examples" / "example_law.py")]) == 0
    assert "example" in capsys.readouterr().out


def test_plugin_errors_are_one_line(tmp_path, capsys, no_example_law):
    bad = tmp_path / "broken_law.py"
    bad.write_text("raise RuntimeError('oops')\n")
    for spec, needle in ((str(bad), "broken_law.py: cannot be loaded: RuntimeError: oops"),
                         ("no_such_module_37", "no module named 'no_such_module_37'"),
                         (str(tmp_path / "missing.py"), "missing.py: file not found")):
        assert main(["controllers", "--plugin", spec]) == ExitCode.BAD_INPUT
        assert f"--plugin {spec}" in (line := one_error_line(capsys)) and needle in line, line


def test_entry_point_plugins_are_loaded(monkeypatch, no_example_law):
    """An installed distribution's entry point in the group vtoladapt.plugins (faked here)."""
    import importlib.metadata
    import sys

    from vtoladapt import components, plugins

    class EntryPoint:
        name, value, group = "example", "example_law", plugins.PLUGIN_GROUP

        def load(self):
            import importlib

            return importlib.import_module("example_law")

    monkeypatch.syspath_prepend(str(REPO / "examples"))
    monkeypatch.setattr(importlib.metadata, "entry_points",
                        lambda group=None: [EntryPoint()] if group == plugins.PLUGIN_GROUP else [])
    monkeypatch.setattr(plugins, "_LOADED_ENTRY_POINTS", [False])
    assert plugins.load_entry_point_plugins() == ["example"]
    assert "example" in components.registry("law")
    assert "example_law" in sys.modules


# --- the how-to page ------------------------------------------------------------------------------------
PAGE = REPO / "docs" / "howto" / "cli_own_things.md"


def test_the_pages_commands_run_in_order(tmp_path, monkeypatch, capsys, no_example_law):
    """docs/howto/cli_own_things.md: every command of its ``run by`` blocks, in page order, in an empty
    folder (with the repository's examples/), each exiting 0 (``> FILE`` writes the command's output)."""
    import re
    import shlex

    (tmp_path / "examples").symlink_to(REPO / "examples")
    monkeypatch.chdir(tmp_path)
    text = PAGE.read_text(encoding="utf-8")
    commands = [line for block in re.findall(r"<!-- run by: tests/test_cli_own_things.py -->\n```sh\n(.*?)```",
                                             text, re.S) for line in block.splitlines() if line.strip()]
    assert len(commands) >= 10
    for command in commands:
        words = shlex.split(command)
        target = None
        if ">" in words:
            words, target = words[:words.index(">")], words[words.index(">") + 1]
        assert words[0] == "vtoladapt", command
        capsys.readouterr()
        code = main(words[1:] + (["--quiet"] if words[1] == "run" else []))
        out, err = capsys.readouterr()
        assert code == 0, f"{command}: {err}"
        if target:
            Path(target).write_text(out)
    assert load_scenario("my_hold.toml").name == "gym_hold"
    assert Path("out/thin/log.csv").is_file() and Path("out/thin.mat").is_file()


@pytest.mark.parametrize("argv, kind", [
    (["campaign", "{vehicle}", "--runs", "2", "--out", "{out}"], "this is a vehicle file"),
    (["run", "gym_hold", "--vehicle", "{campaign}", "--out", "{out}"], "this is a campaign file"),
    (["export", "{vehicle}", "--format", "csv"], "this is a vehicle file"),
    (["run", "gym_hold", "--vehicle", "{tmp}/nosuch.toml", "--out", "{out}"], "--vehicle: "),
])
def test_wrong_kind_of_file_for_other_commands(tmp_path, capsys, argv, kind):
    names = dict(vehicle=_my_plane(tmp_path), out=tmp_path / "o", tmp=tmp_path,
                 campaign=REPO / "src" / "vtoladapt" / "scenarios" / "envelope.toml")
    assert main([a.format(**names) for a in argv]) == ExitCode.BAD_INPUT
    assert kind in one_error_line(capsys)
    assert not (tmp_path / "o").exists()


def test_tuned_with_its_own_law_as_controller_is_accepted(tmp_path, capsys):
    from vtoladapt.cli import load_run_scenario

    tuned = REPO / "src" / "vtoladapt" / "scenarios" / "tuned" / "paper_comparison_pd.toml"
    assert load_run_scenario("paper_comparison", controller=["pd"], tuned=str(tuned)).controller.kind == "pd"
    with pytest.raises(ConfigError, match="--controller composite with --tuned .*: the file tunes pd"):
        load_run_scenario("paper_comparison", controller=["composite"], tuned=str(tuned))
