"""Output folders: refusal of foreign folders, stale outputs removed, atomic writes, valid JSON."""
from __future__ import annotations

import hashlib
import json
import math
import os

import numpy as np
import pytest

from vtoladapt.outputs import (
    MANIFEST_NAME,
    OutputDir,
    OutputError,
    atomic_path,
    check_output_files,
    json_safe,
    read_manifest,
    write_json,
    write_text,
)


def _files(folder):
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


def test_new_folder_gets_a_manifest_of_what_was_written(tmp_path):
    out = tmp_path / "a" / "b"
    with OutputDir(out, "run") as claim:
        write_text(out / "report.md", "hello")
        write_json(out / "runs" / "m.json", {"x": 1})
    manifest = read_manifest(out)
    assert manifest["command"] == "run" and manifest["status"] == "complete"
    assert sorted(manifest["files"]) == ["report.md", "runs/m.json"] == claim.files
    assert manifest["files"]["report.md"] == {"bytes": 5, "sha256": hashlib.sha256(b"hello").hexdigest()}


def test_foreign_non_empty_folder_is_refused_without_force(tmp_path):
    (tmp_path / "thesis.tex").write_text("precious")
    with pytest.raises(OutputError, match="not empty.*thesis.tex.*--force"):
        OutputDir(tmp_path, "run")
    with OutputDir(tmp_path, "run", force=True):
        write_text(tmp_path / "report.md", "new")
    assert (tmp_path / "thesis.tex").read_text() == "precious"


def test_force_never_deletes_a_foreign_file_even_on_failure(tmp_path):
    (tmp_path / "keep.txt").write_text("mine")
    with pytest.raises(RuntimeError):
        with OutputDir(tmp_path, "fit", force=True):
            (tmp_path / "half.png").write_bytes(b"\x89PNG")  # a writer outside this module
            raise RuntimeError("boom")
    assert _files(tmp_path) == ["keep.txt"]  # as it was: not even a manifest
    assert (tmp_path / "keep.txt").read_text() == "mine"


def test_another_commands_output_is_refused(tmp_path):
    with OutputDir(tmp_path, "reproduce"):
        write_text(tmp_path / "metrics.json", "{}")
    with pytest.raises(OutputError, match="holds the outputs of 'vtoladapt reproduce'"):
        OutputDir(tmp_path, "run")


def test_rerun_removes_the_earlier_runs_outputs_only(tmp_path):
    """An earlier comparison's five logs do not survive a one-controller rerun."""
    with OutputDir(tmp_path, "run"):
        for cid in ("composite", "pid", "pd"):
            write_text(tmp_path / "runs" / f"{cid}.parquet", cid)
        write_text(tmp_path / "fig.png", "old figure")
    (tmp_path / "notes.txt").write_text("the user's own notes")
    with OutputDir(tmp_path, "run"):
        write_text(tmp_path / "runs" / "pid.parquet", "new pid")
    assert _files(tmp_path) == [MANIFEST_NAME, "notes.txt", "runs/pid.parquet"]
    assert (tmp_path / "runs" / "pid.parquet").read_text() == "new pid"
    assert sorted(read_manifest(tmp_path)["files"]) == ["runs/pid.parquet"]


def test_a_rerun_keeps_what_it_drew_again_byte_for_byte(tmp_path):
    """A figure drawn again from the same seed (written by Matplotlib, not through this module) is the
    earlier run's file byte for byte: the rerun's end must keep it, not delete it as the earlier
    run's (``vtoladapt fit --force`` into its own folder lost every figure, exit 0)."""
    import time

    def run():
        with OutputDir(tmp_path, "fit", force=True):
            (tmp_path / "corner.png").write_bytes(b"the same pixels")   # a plain write, as savefig's
            time.sleep(0.01)                                             # a later time stamp
    run()
    assert sorted(read_manifest(tmp_path)["files"]) == ["corner.png"]
    run()
    assert _files(tmp_path) == [MANIFEST_NAME, "corner.png"]
    assert sorted(read_manifest(tmp_path)["files"]) == ["corner.png"]


def test_an_output_changed_by_the_user_is_not_deleted(tmp_path):
    with OutputDir(tmp_path, "run"):
        write_text(tmp_path / "report.md", "generated")
    (tmp_path / "report.md").write_text("generated, then annotated by hand")
    with pytest.raises(OutputError, match="report.md was changed"):
        OutputDir(tmp_path, "run")
    with OutputDir(tmp_path, "run", force=True):  # forced: kept (this run writes no report.md)
        write_text(tmp_path / "other.md", "x")
    assert (tmp_path / "report.md").read_text().endswith("by hand")


def test_writers_refuse_to_replace_a_foreign_file_inside_a_claim(tmp_path):
    with OutputDir(tmp_path, "run"):
        write_text(tmp_path / "metrics.json", "{}")
    (tmp_path / "draft.md").write_text("user")
    with OutputDir(tmp_path, "run"):
        with pytest.raises(OutputError, match="draft.md: exists and was not written"):
            write_text(tmp_path / "draft.md", "generated")
    assert (tmp_path / "draft.md").read_text() == "user"


def test_failure_in_a_new_folder_leaves_nothing(tmp_path):
    out = tmp_path / "new" / "deep"
    with pytest.raises(ValueError):
        with OutputDir(out, "run"):
            (out / "runs").mkdir()
            (out / "runs" / "partial.parquet").write_bytes(b"PAR1")
            raise ValueError("bad input found late")
    assert not (tmp_path / "new").exists()


def test_interrupt_keeps_complete_files_and_drops_unfinished_ones(tmp_path):
    with pytest.raises(KeyboardInterrupt):
        with OutputDir(tmp_path / "o", "run"):
            write_text(tmp_path / "o" / "log1.parquet", "complete")
            with atomic_path(tmp_path / "o" / "fig.png") as tmp:
                tmp.write_bytes(b"\x89PNG truncated")
                raise KeyboardInterrupt
    out = tmp_path / "o"
    assert _files(out) == [MANIFEST_NAME, "log1.parquet"]
    assert read_manifest(out)["status"] == "interrupted"
    # the interrupted folder is still recognised as ours: a rerun cleans it and proceeds
    with OutputDir(out, "run"):
        write_text(out / "log2.parquet", "x")
    assert _files(out) == [MANIFEST_NAME, "log2.parquet"]


def test_atomic_path_keeps_the_old_file_when_the_writer_fails(tmp_path):
    target = tmp_path / "metrics.json"
    target.write_text('{"old": 1}')
    with pytest.raises(ZeroDivisionError):
        with atomic_path(target) as tmp:
            tmp.write_text('{"new"')
            1 / 0
    assert target.read_text() == '{"old": 1}'
    assert _files(tmp_path) == ["metrics.json"]


def test_json_is_valid_json_with_nan_as_null(tmp_path):
    doc = {"a": float("nan"), "b": [1.0, float("inf"), -float("inf")], "c": np.float64(2.5),
           "d": np.array([np.nan, 1.0]), "e": (1, 2), 3: "key"}
    write_json(tmp_path / "m.json", doc)
    text = (tmp_path / "m.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    back = json.loads(text)
    assert back == {"a": None, "b": [1.0, None, None], "c": 2.5, "d": [None, 1.0], "e": [1, 2],
                    "3": "key"}


def test_bare_nan_written_by_other_code_is_repaired_on_completion(tmp_path):
    with OutputDir(tmp_path, "fit"):
        (tmp_path / "legacy.json").write_text(json.dumps({"x": math.nan}))
    doc = json.loads((tmp_path / "legacy.json").read_text(), parse_constant=lambda c: 1 / 0)
    assert doc == {"x": None}


@pytest.mark.parametrize("bad, message", [
    ("a_file", "is a file, not a folder"),
    ("a_file/sub", "is a file, so it cannot hold a folder"),
    ("x" * 300, "characters; allowed: at most"),
])
def test_impossible_output_paths_are_refused_before_anything(tmp_path, bad, message):
    (tmp_path / "a_file").write_text("x")
    with pytest.raises(OutputError, match=message):
        OutputDir(tmp_path / bad, "run")


def test_single_file_outputs_are_replaced_only_when_ours(tmp_path):
    precious = tmp_path / "precious.csv"
    precious.write_text("hand-made data")
    with pytest.raises(OutputError, match="not an output of 'vtoladapt tunnel'"):
        check_output_files([precious], "tunnel", is_ours=lambda p: False)
    check_output_files([precious], "tunnel", is_ours=lambda p: True)
    check_output_files([precious], "tunnel", is_ours=lambda p: False, force=True)
    with pytest.raises(OutputError, match="is a folder"):
        check_output_files([tmp_path], "tunnel", is_ours=lambda p: True)


def test_json_safe_rejects_unknown_objects():
    with pytest.raises(TypeError):
        json_safe({"x": object()})


# --- issue #27, item 6: a manifest is a claim, not proof ------------------------------------------------

def _plant(out, victim, manifest_version):
    """The issue's attack: ``out`` holds a manifest of 'run' listing ``sub/thesis.tex`` with the victim
    file's own size and time (version 1) or size and SHA-256 (version 2), and ``sub -> victim's folder``."""
    out.mkdir()
    target = victim / "thesis.tex"
    st = target.stat()
    entry = ([st.st_size, st.st_mtime_ns] if manifest_version == 1 else
             {"bytes": st.st_size, "sha256": hashlib.sha256(target.read_bytes()).hexdigest()})
    (out / MANIFEST_NAME).write_text(json.dumps({"format": "vtoladapt.outputs", "version": manifest_version,
                                                 "command": "run", "status": "complete",
                                                 "files": {"sub/thesis.tex": entry}}))
    os.symlink(victim, out / "sub")


@pytest.mark.parametrize("version", [1, 2])
def test_a_planted_manifest_and_link_cannot_delete_a_file_outside_the_folder(tmp_path, version):
    """Before the fix the rerun deleted victim/thesis.tex (its size and time matched the manifest)."""
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "thesis.tex").write_text("four years of work")
    out = tmp_path / "out"
    _plant(out, victim, version)
    with pytest.raises(OutputError, match="sub/thesis.tex is (reached through a symbolic link|listed by a manifest)"):
        OutputDir(out, "run")
    with OutputDir(out, "run", force=True):  # forced: written beside it, the listed file untouched
        write_text(out / "report.md", "new")
    assert (victim / "thesis.tex").read_text() == "four years of work"
    assert os.path.islink(out / "sub")


def test_a_plain_run_into_a_planted_folder_exits_2_and_deletes_nothing(tmp_path):
    from vtoladapt.cli import main

    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "thesis.tex").write_text("four years of work")
    _plant(tmp_path / "out", victim, 1)
    assert main(["run", "gym_hold", "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert (victim / "thesis.tex").read_text() == "four years of work"


def test_same_size_and_time_with_other_content_is_not_deleted(tmp_path):
    """Size and time are copied as easily as a name: only the content hash proves a file is ours."""
    with OutputDir(tmp_path, "run"):
        write_text(tmp_path / "report.md", "generated")
    before = (tmp_path / "report.md").stat()
    (tmp_path / "report.md").write_text("GENERATED")  # the user's, same size
    os.utime(tmp_path / "report.md", ns=(before.st_atime_ns, before.st_mtime_ns))
    with pytest.raises(OutputError, match="report.md was changed"):
        OutputDir(tmp_path, "run")
    with OutputDir(tmp_path, "run", force=True):
        write_text(tmp_path / "other.md", "x")
    assert (tmp_path / "report.md").read_text() == "GENERATED"


def test_a_listed_path_swapped_for_a_link_after_the_check_is_not_followed(tmp_path):
    """The check passed on a real folder; a link put in its place before the claim is not followed."""
    with OutputDir(tmp_path / "out", "run"):
        write_text(tmp_path / "out" / "runs" / "a.parquet", "log")
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "a.parquet").write_text("log")  # identical content, outside the folder
    target = OutputDir(tmp_path / "out", "run")
    os.rename(tmp_path / "out" / "runs", tmp_path / "moved")
    os.symlink(victim, tmp_path / "out" / "runs")
    target.check = lambda: None  # the swap lands between the second check and the removal
    with target:
        pass
    assert (victim / "a.parquet").read_text() == "log"


def test_writers_refuse_to_write_through_a_link_inside_the_folder(tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "a.parquet").write_text("the user's")
    out = tmp_path / "out"
    with OutputDir(out, "run"):
        write_text(out / "report.md", "x")
    os.symlink(elsewhere, out / "runs")
    with OutputDir(out, "run", force=True):
        with pytest.raises(OutputError, match="is a symbolic link"):
            write_text(out / "runs" / "a.parquet", "generated")
    assert (elsewhere / "a.parquet").read_text() == "the user's"
