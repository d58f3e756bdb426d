"""Every ordinary mistake of issue #15, retried: one line on stderr, the documented exit code, no
traceback, no hang, nothing written and no file overwritten.

The commands run in this process through :func:`vtoladapt.cli.main`; none of them reaches a
simulation (each fails validation first), except where a fake handler stands in for one.
"""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from cli_helpers import one_error_line
from vtoladapt.cli import main
from vtoladapt.errors import ExitCode
from vtoladapt.outputs import MANIFEST_NAME, OutputDir, write_text

SINGLE = """name = "t"
vehicle = "caltech_vtol"
duration_s = 2.0
"""


def _scenario(tmp_path: Path, extra: str = "", text: str = SINGLE, name: str = "s.toml") -> Path:
    path = tmp_path / name
    path.write_text(text + extra)
    return path


def _check(argv, capsys, code: ExitCode, *needles: str) -> str:
    rc = main([str(a) for a in argv])
    line = one_error_line(capsys)
    assert rc == code, (rc, line)
    for n in needles:
        assert n in line, (n, line)
    return line


# --- unbounded sizes ---------------------------------------------------------------------------------
@pytest.mark.parametrize("flag, needle", [("1e7", "<= 3600"), ("inf", "must be finite"),
                                          ("nan", "must be finite"), ("-1", "> 0")])
def test_run_duration_flag_has_the_files_range(tmp_path, capsys, flag, needle):
    out = tmp_path / "o"
    _check(["run", _scenario(tmp_path), "--out", out, "--duration", flag, "--quiet"], capsys,
           ExitCode.BAD_INPUT, "--duration", needle)
    assert not out.exists()


def test_tiny_control_period_is_refused(tmp_path, capsys):
    path = _scenario(tmp_path, "dt_control_s = 1e-9\n")
    _check(["run", path, "--out", tmp_path / "o"], capsys, ExitCode.BAD_INPUT,
           "dt_control_s = 1e-09", ">= 0.0001")


def test_log_size_ceiling_names_the_bytes_and_the_budget(tmp_path, capsys):
    path = _scenario(tmp_path, text=SINGLE.replace("2.0", "3600.0") + "dt_control_s = 1e-4\n")
    from vtoladapt.sim.limits import ANALYSIS_COLUMNS_PER_RUN, ANALYSIS_TRANSIENT_COLUMNS

    # what a run holds, counted (vtoladapt.sim.limits.run_memory): 36 M ticks of the analysed columns
    _check(["run", path, "--out", tmp_path / "o"], capsys, ExitCode.BAD_INPUT,
           f"analysing 1 run(s) x 36000000 ticks x {ANALYSIS_COLUMNS_PER_RUN} columns + "
           f"{ANALYSIS_TRANSIENT_COLUMNS} transient, x 8 bytes", "needs 27.4 GiB", "memory budget")
    assert not (tmp_path / "o").exists()


def test_huge_tunnel_repeats_and_walkers_and_runs_are_refused(tmp_path, capsys):
    _check(["tunnel", "--out", tmp_path / "d.csv", "--repeats", "100000000"], capsys,
           ExitCode.BAD_INPUT, "--repeats", "memory budget")
    (tmp_path / "d.csv").write_text("a,b\n1,2\n")
    _check(["fit", tmp_path / "d.csv", "--out", tmp_path / "f", "--walkers", "100000000"], capsys,
           ExitCode.BAD_INPUT, "--walkers", "memory budget")
    _check(["campaign", _scenario(tmp_path), "--runs", "100000000", "--out", tmp_path / "c",
            "--scheduler", "none", "--quiet"], capsys, ExitCode.BAD_INPUT,
           "--runs = 100000000: out of range; allowed: >= 1 and <= 100000")
    assert not (tmp_path / "f").exists() and not (tmp_path / "c").exists()


# --- physical ranges ------------------------------------------------------------------------------------
@pytest.mark.parametrize("extra, needle", [
    ("[plant]\ncoefficients = { CTz = 1e10 }\n", "CTz"),
    ("[plant]\ncoefficients = { CL1 = 1e9 }\n", "CL1"),
    ("[plant]\ncoefficients = { k2 = 1e6 }\n", "k2"),
    ("[plant]\nmass_kg = 1e6\n", "mass_kg"),
    ("[wind.fan_array]\nmax_speed_mps = 1e4\n", "max_speed_mps"),
    ("[wind]\nconstant_mps = [1e5, 0.0, 0.0]\n", "constant_mps[0]"),
    ("[initial]\nvelocity_mps = [0.0, 0.0, 1e4]\n", "velocity_mps[2]"),
    ("[controller]\nK_v = [1e12, 1.0, 1.0]\n", "magnitude <= 1e+09"),
    ("seed = 99999999999999999999999\n", "seed"),
])
def test_out_of_range_keys_are_refused_naming_file_key_value(tmp_path, capsys, extra, needle):
    path = _scenario(tmp_path, extra)
    line = _check(["run", path, "--out", tmp_path / "o", "--quiet"], capsys, ExitCode.BAD_INPUT,
                  needle, str(path))
    assert "allowed" in line


# --- outputs lost or mixed ------------------------------------------------------------------------------
def test_run_into_a_reproduce_folder_is_refused(tmp_path, capsys):
    out = tmp_path / "repro"
    with OutputDir(out, "reproduce"):
        write_text(out / "metrics.json", '{"claims": {}}')
        write_text(out / "report.md", "# the claims")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    _check(["run", _scenario(tmp_path), "--out", out, "--quiet"], capsys, ExitCode.BAD_INPUT,
           "holds the outputs of 'vtoladapt reproduce'", "--force")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_tunnel_never_overwrites_a_file_it_did_not_write(tmp_path, capsys):
    precious = tmp_path / "precious.toml"
    precious.write_text("mine")
    _check(["tunnel", "--out", precious], capsys, ExitCode.BAD_INPUT, "ending in .csv")
    data = tmp_path / "precious.csv"
    data.write_text("my measurements")
    _check(["tunnel", "--out", data], capsys, ExitCode.BAD_INPUT, "not an output of 'vtoladapt tunnel'")
    assert precious.read_text() == "mine" and data.read_text() == "my measurements"


def test_tunnel_replaces_its_own_output(tmp_path, capsys):
    csv = tmp_path / "d.csv"
    assert main(["tunnel", "--out", str(csv), "--seed", "1"]) == 0
    first = csv.read_bytes()
    assert main(["tunnel", "--out", str(csv), "--seed", "2"]) == 0
    assert csv.read_bytes() != first and (tmp_path / "d.truth.json").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.csv", "d.truth.json"]
    capsys.readouterr()


def test_empty_out_is_a_usage_error(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc = main(["run", str(_scenario(tmp_path)), "--out", ""])
    err = capsys.readouterr().err
    assert rc == ExitCode.BAD_INPUT and "empty path" in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


# --- tracebacks for ordinary mistakes --------------------------------------------------------------------
def test_out_is_an_existing_file_or_below_one(tmp_path, capsys):
    f = tmp_path / "f"
    f.write_text("x")
    _check(["run", _scenario(tmp_path), "--out", f], capsys, ExitCode.BAD_INPUT, "is a file, not a folder")
    _check(["run", _scenario(tmp_path), "--out", f / "sub"], capsys, ExitCode.BAD_INPUT,
           "cannot hold a folder")
    assert f.read_text() == "x"


def test_scenario_that_is_a_folder_or_binary_or_missing(tmp_path, capsys):
    _check(["run", tmp_path, "--out", tmp_path / "o"], capsys, ExitCode.BAD_INPUT, "is a folder")
    binary = tmp_path / "b.toml"
    binary.write_bytes(bytes(range(256)) * 4)
    _check(["run", binary, "--out", tmp_path / "o"], capsys, ExitCode.BAD_INPUT, str(binary),
           "not a text (UTF-8) file")
    _check(["run", tmp_path / "nope.toml", "--out", tmp_path / "o"], capsys, ExitCode.BAD_INPUT,
           "not found")


@pytest.mark.parametrize("argv, needle", [
    (["campaign", "x.toml", "--runs", "1.5", "--out", "o"], "argument --runs: invalid int value"),
    (["fit"], "required: DATA.csv, --out"),
    (["probe", "evaluate"], "required: CALIBRATION, DATA, --out"),
    (["no-such-command"], "invalid choice"),
    ([], "required: command"),
])
def test_a_command_line_mistake_is_one_line_naming_the_help_to_read(capsys, argv, needle):
    """argparse prints its usage block before the error; the usage is one --help away."""
    line = _check(argv, capsys, ExitCode.BAD_INPUT, needle, "--help')")
    assert line.startswith("vtoladapt")


def test_an_input_that_is_a_device_or_a_pipe_is_refused_before_it_is_read(tmp_path, capsys):
    """/dev/zero has size 0 to stat() and never ends: read, it would fill the memory."""
    import os

    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)  # nobody writes to it: opening it to read would block forever
    for path in (Path("/dev/zero"), fifo):
        _check(["run", path, "--out", tmp_path / "o"], capsys, ExitCode.BAD_INPUT, str(path),
               "not a regular file")
    _check(["fit", "/dev/zero", "--out", tmp_path / "f"], capsys, ExitCode.BAD_INPUT, "not a regular file")
    topics = tmp_path / "csvs"
    topics.mkdir()
    (topics / "log_vehicle_attitude_0.csv").symlink_to("/dev/zero")
    _check(["replay", topics, "--vehicle", "caltech_vtol", "--out", tmp_path / "r"], capsys,
           ExitCode.BAD_INPUT, "log_vehicle_attitude_0.csv", "not a regular file")
    assert not any((tmp_path / d).exists() for d in ("o", "f", "r"))


def test_very_long_vehicle_string(tmp_path, capsys):
    line = _check(["tunnel", "--vehicle", "x" * 5000, "--out", tmp_path / "d.csv"], capsys,
                  ExitCode.BAD_INPUT, "--vehicle", "at most 4096")
    assert len(line) < 700
    _check(["tunnel", "--vehicle", "x" * 300, "--out", tmp_path / "d.csv"], capsys,
           ExitCode.BAD_INPUT, "--vehicle", "over 255 characters")
    path = _scenario(tmp_path, text=SINGLE.replace('"caltech_vtol"', '"' + "v" * 5000 + '"'))
    _check(["run", path, "--out", tmp_path / "o"], capsys, ExitCode.BAD_INPUT, "vehicle", "at most 4096")


def test_fit_truth_that_is_a_json_list(tmp_path, capsys):
    csv = tmp_path / "d.csv"
    assert main(["tunnel", "--out", str(csv)]) == 0
    capsys.readouterr()
    truth = tmp_path / "t.json"
    truth.write_text("[1, 2, 3]")
    _check(["fit", csv, "--out", tmp_path / "f", "--truth", truth, "--fast"], capsys,
           ExitCode.BAD_INPUT, "--truth", "JSON list")
    assert not (tmp_path / "f").exists()


def test_reproduce_with_a_tiny_duration_scale_writes_nothing(tmp_path, capsys):
    _check(["reproduce", "--out", tmp_path / "r", "--duration-scale", "1e-6", "--quiet"], capsys,
           ExitCode.BAD_INPUT, "--duration-scale", ">= 0.02")
    assert not (tmp_path / "r").exists()


def test_campaign_with_an_unreachable_scheduler_gives_up_quickly(tmp_path, capsys):
    _check(["campaign", _scenario(tmp_path), "--runs", "2", "--out", tmp_path / "c",
            "--scheduler", "tcp://127.0.0.1:1", "--quiet"], capsys, ExitCode.BAD_INPUT,
           "--scheduler", "no Dask scheduler answered within 5 s")
    assert not (tmp_path / "c").exists()


def test_campaign_on_a_comparison_scenario_asks_which_controller(tmp_path, capsys):
    path = _scenario(tmp_path, '[experiment]\nkind = "comparison"\n')
    _check(["campaign", path, "--runs", "2", "--out", tmp_path / "c", "--scheduler", "none"],
           capsys, ExitCode.BAD_INPUT, "kind = 'comparison'", "--controller")


@pytest.mark.parametrize("argv, needle", [
    (["tunnel", "--air-density", "0"], "--air-density = 0.0"),
    (["tunnel", "--noise-rel", "1"], "--noise-rel"),
    (["tunnel", "--seed", "-1"], "--seed"),
])
def test_zero_density_and_bad_noise_are_refused(tmp_path, capsys, argv, needle):
    _check(argv + ["--out", tmp_path / "d.csv"], capsys, ExitCode.BAD_INPUT, needle)
    assert not (tmp_path / "d.csv").exists()


def test_fit_rho_ref_zero_is_refused(tmp_path, capsys):
    (tmp_path / "d.csv").write_text("x\n")
    _check(["fit", tmp_path / "d.csv", "--out", tmp_path / "f", "--rho-ref", "0"], capsys,
           ExitCode.BAD_INPUT, "--rho-ref = 0.0", ">= 0.3")


def test_binary_data_files_are_named(tmp_path, capsys):
    binary = tmp_path / "blob.csv"
    binary.write_bytes(b"\xff\xfe\x00garbage" * 50)
    _check(["fit", binary, "--out", tmp_path / "f"], capsys, ExitCode.BAD_INPUT, str(binary))
    _check(["probe", "calibrate", binary, "--out", tmp_path / "p"], capsys, ExitCode.BAD_INPUT,
           str(binary))
    assert not (tmp_path / "f").exists() and not (tmp_path / "p").exists()


# --- interrupts and internal errors ------------------------------------------------------------------------
def test_ctrl_c_exits_130_and_leaves_no_truncated_file(tmp_path, capsys, monkeypatch):
    import vtoladapt.experiments as experiments

    def interrupted_run(scenario, out, show_progress=True, warm=True):
        (out / "runs").mkdir(parents=True)
        write_text(out / "runs" / "complete.parquet", "a whole log")
        (out / "fig_run.png").write_bytes(b"\x89PNG\r\n half of a figure")  # a direct writer
        raise KeyboardInterrupt

    monkeypatch.setattr(experiments, "run_experiment", interrupted_run)
    out = tmp_path / "o"
    _check(["run", _scenario(tmp_path), "--out", out], capsys, ExitCode.INTERRUPTED, "interrupted")
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert files == [MANIFEST_NAME, "runs/complete.parquet"]
    assert json.loads((out / MANIFEST_NAME).read_text())["status"] == "interrupted"


def test_internal_error_is_one_line_and_debug_shows_the_traceback(tmp_path, capsys, monkeypatch):
    import vtoladapt.experiments as experiments

    def broken(*args, **kwargs):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(experiments, "run_experiment", broken)
    path = _scenario(tmp_path)
    _check(["run", path, "--out", tmp_path / "o"], capsys, ExitCode.RUN_FAILED,
           "internal error ZeroDivisionError", "--debug")
    assert not (tmp_path / "o").exists()
    assert main(["run", str(path), "--out", str(tmp_path / "o"), "--debug"]) == ExitCode.RUN_FAILED
    assert "Traceback" in capsys.readouterr().err


def test_a_real_ctrl_c_exits_130_in_one_line(tmp_path):
    """SIGINT to a real ``vtoladapt run`` process once it has claimed its folder.

    Once the status is decided the console command ignores SIGINT: the interpreter's teardown
    (seconds of freeing compiled kernels) runs with SIGINT's default action, and a signal then
    used to kill the process (status -2) after it had printed its one line."""
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-m", "vtoladapt.cli", "run", str(_scenario(tmp_path)),
                             "--out", str(out), "--quiet"], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not (out / MANIFEST_NAME).exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    # a signal that lands inside a cold Numba compile is honoured when the compile ends (LLVM
    # cannot be interrupted): up to a couple of minutes on a loaded 2-core machine
    _, err = proc.communicate(timeout=400)
    lines = [ln for ln in err.splitlines() if ln.strip() and "sim s" not in ln]
    assert proc.returncode == ExitCode.INTERRUPTED, err
    assert "Traceback" not in err and len(lines) == 1 and "interrupted" in lines[0], err
    leftovers = [p for p in out.rglob("*") if p.is_file()] if out.exists() else []
    assert all(p.name == MANIFEST_NAME or p.stat().st_size > 0 for p in leftovers)
    assert not any(p.name.startswith(".partial-") for p in leftovers)


@pytest.mark.slow
def test_fit_no_figures_into_an_old_fit_folder_leaves_no_old_figures(tmp_path, capsys):
    csv = tmp_path / "d.csv"
    assert main(["tunnel", "--out", str(csv)]) == 0
    out = tmp_path / "fit"
    assert main(["fit", str(csv), "--out", str(out), "--fast"]) == 0
    assert (out / "corner.png").exists()
    assert main(["fit", str(csv), "--out", str(out), "--fast", "--no-figures"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST_NAME, "posterior.json", "table1.md"]
    capsys.readouterr()


def test_a_ctrl_c_that_python_dropped_still_interrupts(tmp_path, capsys, monkeypatch):
    """Python prints and drops a KeyboardInterrupt raised inside a callback from C (llvmlite's
    object-cache notification during a Numba compile): the command must not go on to exit 0."""
    import os
    import signal

    import vtoladapt.experiments as experiments

    def run_with_a_dropped_interrupt(scenario, out, show_progress=True, warm=True):
        try:
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):  # the handler runs at the next bytecode boundary
                pass
        except KeyboardInterrupt:
            pass  # what a C callback does with it
        (out / "done.txt").parent.mkdir(parents=True, exist_ok=True)

    monkeypatch.setattr(experiments, "run_experiment", run_with_a_dropped_interrupt)
    # what main() found: Python's default, or SIG_IGN when the suite runs as a background job
    # (a non-interactive shell starts those with SIGINT ignored)
    before = signal.getsignal(signal.SIGINT)
    assert main(["run", str(_scenario(tmp_path)), "--out", str(tmp_path / "o")]) == ExitCode.INTERRUPTED
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert "interrupted" in last and "after the last output" in last, last
    assert signal.getsignal(signal.SIGINT) is before  # main() restores the handler it found


def test_the_simulator_stops_between_chunks_on_a_dropped_ctrl_c():
    """A pending Ctrl-C request stops :func:`vtoladapt.sim.driver.simulate` at its next chunk."""
    import os
    import signal

    from vtoladapt.errors import sigint_handling
    from vtoladapt.sim.scenario import scenario_from_mapping
    from vtoladapt.sim.driver import simulate

    scenario = scenario_from_mapping({"name": "t", "vehicle": "caltech_vtol", "duration_s": 0.2}, "<t>")
    with sigint_handling():
        try:
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):
                pass
        except KeyboardInterrupt:
            pass
        with pytest.raises(KeyboardInterrupt):
            simulate(scenario)
    simulate(scenario)  # the request ends with the block


def test_a_plant_too_weak_to_hover_is_refused_naming_the_file(tmp_path, capsys):
    """The check runs while the run is set up; its message named neither the file nor the key's file."""
    path = tmp_path / "weak.toml"
    path.write_text('name = "weak"\nvehicle = "caltech_vtol"\nduration_s = 1.0\n'
                    '[plant.coefficients]\nCTz = 0.0005\n')
    out = tmp_path / "o"
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "weak.toml: " in err[0] and "cannot hover" in err[0]
    assert not out.exists()
