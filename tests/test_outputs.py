"""Output folders: refusal of foreign folders, stale outputs removed, atomic writes, valid JSON."""
from __future__ import annotations

import json
import math

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
    assert manifest["files"]["report.md"][0] == len("hello")


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
