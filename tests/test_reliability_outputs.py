"""Issue #27, items 3 and 5: a run refused for its input changes nothing on disk, and an output folder
belongs to one run at a time.

Before the fix, the checks that need the built vehicle and plant ran after ``--out`` was claimed, so
re-running into an earlier output folder deleted its figures, log, metrics and report and then exited
2; an initial state outside the envelope left a 0-row log (and, as a campaign, an internal KeyError);
two runs into one folder both exited 0 with their outputs mixed.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from vtoladapt.cli import main
from vtoladapt.folder_lock import LOCK_NAME
from vtoladapt.outputs import MANIFEST_NAME, OutputDir, OutputError, read_manifest, write_text

BASE = 'name = "h"\nvehicle = "caltech_vtol"\nduration_s = 0.3\nseed = 2\n'


def _snapshot(folder: Path) -> dict:
    """Every file under ``folder``: content hash, size and modification time (nothing may change)."""
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            st = p.stat()
            out[p.relative_to(folder).as_posix()] = (hashlib.sha256(p.read_bytes()).hexdigest(), st.st_size,
                                                     st.st_mtime_ns)
    return out


@pytest.fixture(scope="module")
def earlier(tmp_path_factory):
    """An earlier `vtoladapt run` output folder (a single run) and an earlier comparison's."""
    root = tmp_path_factory.mktemp("earlier")
    (root / "s.toml").write_text(BASE)
    assert main(["run", str(root / "s.toml"), "--out", str(root / "single"), "--quiet"]) == 0
    (root / "c.toml").write_text(BASE + '[experiment]\nkind = "comparison"\ncontrollers = ["pid", "pd"]\n')
    assert main(["run", str(root / "c.toml"), "--out", str(root / "comparison"), "--quiet"]) == 0
    return root


BAD_INPUTS = {
    "plant cannot hover": ("[plant]\nmass_kg = 5.0\n", "[plant] cannot hover: needs lift throttle 100.2 % > 100 %"),
    "initial state outside the envelope": ("[envelope]\nmin_height_m = 5.0\n",
                                           "[initial] the run starts outside its [envelope]: height 1.5 m below"),
    "mocap latency beyond its ring": ('dt_control_s = 0.001\n[sensors.mocap]\nlatency_s = 0.2\n',
                                      "[sensors.mocap] latency_s = 0.2: 200 ticks"),
    "fault latency beyond its ring": ('dt_control_s = 0.001\n[[faults]]\nkind = "mocap_latency"\nstart_s = 0.1\n'
                                      'end_s = 0.2\nextra_latency_s = 0.4\n', "[faults][0] mocap_latency"),
    "degenerate rotor layout": ('vehicle = "flat.toml"\n', "cannot produce independent thrust, roll, pitch"),
}


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_a_rerun_refused_for_its_input_leaves_the_earlier_outputs_as_they_were(earlier, tmp_path, case, capsys):
    extra, message = BAD_INPUTS[case]
    out = tmp_path / "out"
    shutil.copytree(earlier / "single", out, copy_function=shutil.copy2)
    before = _snapshot(out)
    text = BASE + extra
    if "flat.toml" in extra:  # every lift rotor on the body x axis: no roll moment
        vehicle = (Path(__file__).resolve().parents[1] / "src/vtoladapt/vehicles/caltech_vtol.toml").read_text()
        lines = [ln if not ln.startswith("lift_rotor_positions_m") else
                 "lift_rotor_positions_m = [[0.3, 0.0], [-0.3, 0.0], [0.2, 0.0], [-0.2, 0.0]]"
                 for ln in vehicle.splitlines()]
        (tmp_path / "flat.toml").write_text("\n".join(lines) + "\n")
        text = text.replace('vehicle = "caltech_vtol"\n', "")
    (tmp_path / "bad.toml").write_text(text)
    capsys.readouterr()
    assert main(["run", str(tmp_path / "bad.toml"), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err and str(tmp_path) in err, err
    assert _snapshot(out) == before


def test_a_users_file_named_like_an_output_is_refused_before_anything_is_deleted(earlier, tmp_path, capsys):
    """The earlier comparison wrote no fig_run.png; the user's own one stops a single run up front."""
    out = tmp_path / "out"
    shutil.copytree(earlier / "comparison", out, copy_function=shutil.copy2)
    (out / "fig_run.png").write_bytes(b"the user's figure")
    before = _snapshot(out)
    capsys.readouterr()
    assert main(["run", str(earlier / "s.toml"), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "fig_run.png exists and is not an output of 'vtoladapt run'" in err
    assert _snapshot(out) == before


def test_a_campaign_whose_draws_start_outside_the_envelope_is_refused_naming_the_draw(tmp_path, capsys):
    """Before: every run diverged at tick 0 and the summary failed with KeyError 'vel_err_rms_mps' (exit 1)."""
    (tmp_path / "s.toml").write_text(BASE + "[envelope]\nmin_height_m = 5.0\n")
    capsys.readouterr()
    assert main(["campaign", str(tmp_path / "s.toml"), "--runs", "3", "--scheduler", "none",
                 "--out", str(tmp_path / "c"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "(campaign run 0, {'seed':" in err and "starts outside its [envelope]" in err, err
    assert not (tmp_path / "c").exists()


# --- item 5: one run per folder ------------------------------------------------------------------------

def test_a_second_claim_of_a_folder_is_refused_in_one_line(tmp_path):
    out = tmp_path / "o"
    with OutputDir(out, "run"):
        write_text(out / "a.txt", "first")
        with pytest.raises(OutputError, match=r"in use by another vtoladapt run \(pid \d+ on .*'vtoladapt run'"):
            OutputDir(out, "run")
        second = OutputDir(tmp_path / "o2", "run")  # another folder is free
        with second:
            pass
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST_NAME, "a.txt"]  # the lock went with the run
    with OutputDir(out, "run"):  # and the folder is free again
        pass


HOLDER = textwrap.dedent("""
    import sys, time
    from vtoladapt.outputs import OutputDir, write_text
    with OutputDir(sys.argv[1], "run") as claim:
        write_text(claim.path / "log.parquet", "the first run's")
        print("claimed", flush=True)
        sys.stdin.readline()
""")


def test_a_run_into_a_folder_another_process_holds_exits_2_and_changes_nothing(tmp_path, capsys):
    out = tmp_path / "o"
    (tmp_path / "s.toml").write_text(BASE)
    holder = subprocess.Popen([sys.executable, "-c", HOLDER, str(out)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "claimed"
        before = _snapshot(out)
        capsys.readouterr()
        assert main(["run", str(tmp_path / "s.toml"), "--out", str(out), "--quiet"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and f"in use by another vtoladapt run (pid {holder.pid} " in err, err
        assert _snapshot(out) == before
    finally:
        holder.stdin.write("\n")
        holder.stdin.close()
        holder.wait(timeout=60)
    assert holder.returncode == 0
    assert read_manifest(out)["status"] == "complete" and not (out / LOCK_NAME).exists()


def test_the_lock_of_a_killed_run_does_not_block_the_next(tmp_path):
    """SIGKILL leaves the lock file behind; the kernel released the lock with the process."""
    out = tmp_path / "o"
    holder = subprocess.Popen([sys.executable, "-c", HOLDER, str(out)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "claimed"
    os.kill(holder.pid, signal.SIGKILL)
    holder.wait(timeout=60)
    assert (out / LOCK_NAME).exists()
    with OutputDir(out, "run"):
        write_text(out / "log.parquet", "the second run's")
    assert not (out / LOCK_NAME).exists()
    assert (out / "log.parquet").read_text() == "the second run's"


@pytest.mark.slow
def test_two_runs_started_together_never_mix_their_outputs(tmp_path):
    """Two `vtoladapt run` processes into one --out: one runs, the other is refused (exit 2), or they
    run one after the other; the folder ends with exactly one run's outputs, all listed."""
    (tmp_path / "a.toml").write_text(BASE)
    (tmp_path / "b.toml").write_text(BASE.replace('name = "h"', 'name = "h"\ndescription = "b"') +
                                     '[experiment]\nkind = "comparison"\ncontrollers = ["pid", "pd"]\n')
    out = tmp_path / "o"
    procs = [subprocess.Popen([sys.executable, "-m", "vtoladapt.cli", "run", str(tmp_path / f"{n}.toml"),
                               "--out", str(out), "--quiet"], stderr=subprocess.PIPE, text=True)
             for n in ("a", "b")]
    codes = [p.wait(timeout=900) for p in procs]
    errs = [p.stderr.read() for p in procs]
    assert sorted(codes) in ([0, 0], [0, 2]), (codes, errs)
    if 2 in codes:
        assert "in use by another vtoladapt run" in errs[codes.index(2)]
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    listed = sorted(read_manifest(out)["files"])
    assert files == sorted(listed + [MANIFEST_NAME])
    assert ("log.parquet" in listed) != any(f.startswith("runs/") for f in listed)  # one run's, not a mix


# --- item 11: SIGTERM ends a command as Ctrl-C does -------------------------------------------------------

TERMINATED_RUN = textwrap.dedent("""
    import sys, time
    import vtoladapt.experiments as experiments
    from vtoladapt.outputs import write_text

    def slow(scenario, out, show_progress=True, **kw):  # one output written, then a long run
        write_text(out / "metrics.json", "{}")
        print("written", flush=True)
        time.sleep(300)

    experiments.run_experiment = slow
    from vtoladapt.cli import console
    sys.argv = ["vtoladapt", "run", sys.argv[1], "--out", sys.argv[2], "--quiet"]
    console()
""")


def test_sigterm_ends_a_run_in_one_line_with_the_manifest_saying_so(tmp_path):
    """Before: SIGTERM killed the process and left the manifest at "running"."""
    (tmp_path / "s.toml").write_text(BASE)
    out = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-c", TERMINATED_RUN, str(tmp_path / "s.toml"), str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "written", proc.stderr.read()
        assert read_manifest(out)["status"] == "running"
        proc.terminate()
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, err
    assert err.strip().splitlines() == ["vtoladapt run: terminated (SIGTERM); outputs completed so far are kept, "
                                        "none is truncated"], err
    assert read_manifest(out)["status"] == "terminated" and sorted(read_manifest(out)["files"]) == ["metrics.json"]
    assert not (out / LOCK_NAME).exists()
