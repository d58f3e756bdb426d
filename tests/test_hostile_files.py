"""A subset of the hostile pass, in the default suite: every tampered learned-basis file of
``tools/hostile_files.py`` (read through ``vtoladapt bases --vehicle``), judged as the pass judges it --
refused in one line naming the file with its folder unchanged, or, for the files that must be read
(float32, big-endian, compressed, at the bounds and caps), accepted. The flown cases, the logs and the
``learn-basis`` arguments run in ``tools/hostile_pass.py --only files``."""
from __future__ import annotations

import random
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import hostile_files  # noqa: E402

CASES = [c for c in hostile_files.net_cases(random.Random("0-files"), 1.0) if c["argv"][0] == "bases"]


def test_the_subset_covers_every_kind_of_tampering():
    kinds = {c["build"]["net"][0] for c in CASES}
    assert kinds == {"dtype", "shape", "value", "archive", "meta", "meta_text", "meta_array", "widths"}
    assert len(CASES) >= 350 and sum(c["expect"] == "accept" for c in CASES) >= 15


def test_every_tampered_network_file_is_refused_cleanly_or_read(tmp_path):
    findings = []
    outcomes = {}
    for i, case in enumerate(CASES):
        work = tmp_path / str(i)
        work.mkdir()
        (work / "assets").mkdir()
        (work / "assets" / "flight.parquet").write_bytes(b"")  # not used by the network cases
        outcome, detail = hostile_files.run_file_case(case, work, work / "baseline")
        outcomes[outcome] = outcomes.get(outcome, 0) + 1
        if outcome not in ("refused", "ok"):
            findings.append(f"{outcome}: {case['build']}: {detail[:200]}")
    assert not findings, "\n".join(findings[:10])
    assert outcomes["refused"] >= 300, outcomes
