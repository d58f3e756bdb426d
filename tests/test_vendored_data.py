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


MIT_SUBSET = {  # file -> (header, rows) as SOURCE.md's "Vendored subset" states
    "flight3_vehicle_attitude_0.csv": (["timestamp", "q[0]", "q[1]", "q[2]", "q[3]"], 5200),
    "flight3_vehicle_local_position_0.csv": (["timestamp", "x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az"], 2600),
    "flight3_airspeed_validated_0.csv": (["timestamp", "indicated_airspeed_m_s", "true_airspeed_m_s",
                                          "airspeed_sensor_measurement_valid"], 1300),
    "flight3_airspeed_wind_0.csv": (["timestamp", "windspeed_north", "windspeed_east"], 260),
    "flight3_actuator_controls_0_0.csv": (["timestamp", "control[0]", "control[1]", "control[2]", "control[3]"], 5200),
    "flight3_vehicle_status_0.csv": (["timestamp", "nav_state", "arming_state", "vehicle_type", "is_vtol"], 533),
}


def test_mit_fixed_wing_subset_is_the_stated_window_and_columns():
    folder = REPO_DATA_DIR / "mit-solar-airplane-px4"
    assert sorted(p.name for p in folder.glob("*.csv")) == sorted(MIT_SUBSET)
    assert sum(p.stat().st_size for p in folder.iterdir()) < 1_500_000
    source = (folder / "SOURCE.md").read_text()
    assert "## Vendored subset" in source and "1117500000 <= timestamp <= 1377500000" in source
    for name, (header, n_rows) in MIT_SUBSET.items():
        with (folder / name).open(newline="") as fh:
            reader = csv.reader(fh)
            assert next(reader) == header, name
            rows = list(reader)
        assert len(rows) == n_rows, name
        assert f"{name} | {', '.join(header)} | {n_rows} " in source, name
        t = [int(r[0]) for r in rows]
        assert t == sorted(t) and 1117500000 <= t[0] and t[-1] <= 1377500000, name
    with (folder / "flight3_vehicle_status_0.csv").open(newline="") as fh:
        assert {r["vehicle_type"] for r in csv.DictReader(fh)} == {"2"}  # fixed wing throughout
