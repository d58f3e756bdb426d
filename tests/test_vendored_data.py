"""The real data vendored in ``data/``: intact, documented, and the only data the suite needs.

A user clones only this repository, so the default suite must not read anything beside it. The
checksums are those of the original files (the project's data index); the UIUC file is a row
subset and is checked row by row against its own structure instead.
"""
from __future__ import annotations

import csv
import hashlib
import re
from pathlib import Path

import pytest
from conftest import REPO_DATA_DIR

REPO = REPO_DATA_DIR.parent

SHA256 = {
    "nasa-multihole-probe/16328-1_M050.csv": "58b509b0d73e935985a2b84bb73ab05acc1e670171c0e7a4c6753093535fad2f",
    "nasa-multihole-probe/16328-1_M100.csv": "438c44c6d43a87c411c91bde7e259dc9497828cd09c71c56df8d1fdd3743428f",
    "nasa-multihole-probe/16328-2_M050.csv": "fe8eebd549777c3ac2b0b3e670b97582bdbd55883ad2b8c792192d2316e97c97",
    "tudelft-v3-kite-windtunnel/WindTunnel_Re5e5_alpha_sweep_beta_0_Poland2025.csv":
        "b6b6e8c2a939e681e6947df72836cf419dc6cdf0db64b37f8dbc1b99686bd447",
    "tudelft-v3-kite-windtunnel/WindTunnel_Re5e5_beta_sweep_alpha_13_Poland2025.csv":
        "8757a5b367b05103ed73502e98f03931884f7cf91d337fa4da7b65bbe7104ac5",
    "tudelft-v3-kite-windtunnel/WindTunnel_Re5e5_beta_sweep_alpha_7_Poland2025.csv":
        "d9552b271fec3f8c2f5914367a5d234d099a398b435156c7a620fed33f4300cf",
    "pyulog-testdata/sample_log_small.ulg": "68d1020f688109f027dba08d2950247cc0ae34aaefdcf37e4a7d60838f3e1aa3",
}


@pytest.mark.parametrize("rel", sorted(SHA256))
def test_vendored_file_is_the_original(rel):
    assert hashlib.sha256((REPO_DATA_DIR / rel).read_bytes()).hexdigest() == SHA256[rel]


def test_every_data_folder_says_where_it_comes_from():
    folders = [d for d in REPO_DATA_DIR.iterdir() if d.is_dir()]
    assert len(folders) >= 5
    for d in folders:
        text = (d / "SOURCE.md").read_text()
        assert re.search(r"[Ll]icen[cs]e", text), d
        assert ("Repository" in text or "Paper" in text), d


def test_uiuc_subset_is_the_7x4_rows_only():
    with (REPO_DATA_DIR / "uiuc-propdb" / "magf_7x4_exp.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 76
    assert {r["BladeName"] for r in rows} == {"magf 7.0x4.0"}
    static = [r for r in rows if float(r["J"]) == 0.0]
    assert len(static) >= 10  # the static sweep the pusher's C_T(0) is fitted to


def test_nothing_reads_outside_the_repository():
    """No source, test or benchmark names the workspace's ``shared`` folder."""
    pattern = re.compile(r"""["']shared["']\s*/|\.\./shared|/shared/data|/shared/paper""")
    offenders = []
    for sub in ("src", "tests", "benchmarks"):
        for path in (REPO / sub).rglob("*.py"):
            if path.name == Path(__file__).name:
                continue
            if pattern.search(path.read_text(encoding="utf-8")):
                offenders.append(str(path.relative_to(REPO)))
    assert offenders == []
