"""``vtoladapt replay``: real logs end to end, the readers against pyulog, a synthetic log with known theta.

The two real logs are the vendored ones: the PX4 standard-VTOL ULog (pyulog's test data) and the
MIT fixed-wing flight (a folder of ulog2csv topic CSVs). The synthetic log is written from the
force model itself in the PX4 CSV layout, so the whole chain (reader, resampling, incident
velocity from pitot + inertial direction, adaptation) must give zero prediction error on it.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import REPO_DATA_DIR

from vtoladapt import models
from vtoladapt.cli import main
from vtoladapt.frames import GRAVITY_MPS2, quat_from_euler, quat_to_rotmat
from vtoladapt.replay import ReadSettings, ReplaySettings, parse_throttle_source, read_csv_folder, read_ulog, run_replay
from vtoladapt.replay.flightlog import ReplayError
from vtoladapt.outputs import MANIFEST_NAME
from vtoladapt.replay.outputs import OUTPUT_FILES

VTOL_ULOG = REPO_DATA_DIR / "pyulog-testdata" / "sample_log_small.ulg"
FIXED_WING = REPO_DATA_DIR / "mit-solar-airplane-px4"
# this airframe (SYS_AUTOSTART 13014) drives its four lift motors on outputs 4-7, the pusher on 2
VTOL_THROTTLES = ["--lift-throttle", "actuator_outputs:4,5,6,7", "--pusher-throttle", "actuator_outputs:2"]


def _replay(args, capsys):
    rc = main(["replay", *map(str, args)])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def _metrics(out):
    return json.loads((out / "metrics.json").read_text())


# --- the two real logs, end to end through the CLI -------------------------------------------------

def test_vtol_ulog_replays_end_to_end(tmp_path, capsys):
    out = tmp_path / "vtol"
    rc, stdout, err = _replay([VTOL_ULOG, "--vehicle", "px4_standard_vtol", "--out", out, *VTOL_THROTTLES], capsys)
    assert rc == 0, err
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST_NAME) == sorted(OUTPUT_FILES)
    m = _metrics(out)
    assert m["format"] == "vtoladapt.replay.metrics"
    topics = set(m["log"]["topics"])
    assert {"vehicle_attitude#0", "vehicle_local_position#0", "sensor_combined#0", "airspeed#0",
            "actuator_outputs#0", "vehicle_land_detected#0", "wind_estimate#0"} <= topics
    assert m["log"]["sources"]["specific force"].startswith("sensor_combined.accelerometer")
    # the pitot reads -3.6..-1.1 m/s at rest: every reading is below the threshold, none is used
    assert m["log"]["samples_airspeed_from_pitot"] == 0
    assert any(n["quantity"] == "airspeed at low speed" for n in m["lacks"])
    # the land detector says airborne for about 1.15 s (22.67..23.82 s of boot time)
    assert 0.9 < m["log"]["used_s"] < 1.4
    for key in ("adapted", "prior"):
        s = m["prediction_error"][key]
        assert all(math.isfinite(v) for v in (s["rms_g"], s["p95_g"], s["max_g"]))
    # the lift motors stay below a third of full throttle while the accelerometer reads 0.98 g:
    # the ground carries the aircraft, which no flight force model explains
    assert m["prediction_error"]["prior"]["rms_g"] > 0.5
    assert m["by_airspeed_bin"][1]["samples"] == 0 and m["by_airspeed_bin"][1]["adapted_rms_g"] is None
    assert all(math.isfinite(v) for v in m["theta"]["final"].values())
    assert "report.html" in {p.name for p in out.iterdir()}
    assert "What the log lacks" in (out / "report.md").read_text()


def test_fixed_wing_csv_folder_replays_end_to_end(tmp_path, capsys):
    import pyarrow.parquet as pq

    out = tmp_path / "fw"
    rc, stdout, err = _replay([FIXED_WING, "--vehicle", "px4_standard_vtol", "--out", out], capsys)
    assert rc == 0, err
    m = _metrics(out)
    assert {"vehicle_attitude#0", "vehicle_local_position#0", "airspeed_validated#0", "airspeed_wind#0",
            "actuator_controls_0#0", "vehicle_status#0"} <= set(m["log"]["topics"])
    lacks = {n["quantity"]: n for n in m["lacks"]}
    assert "fixed-wing" in lacks["lift collective u_z"]["lacks"]
    assert "no accelerometer" in lacks["specific force"]["lacks"]
    assert "constant at 0" in lacks["pusher u_x"]["lacks"]
    assert "only a pitot" in lacks["angle of attack and sideslip"]["lacks"]
    assert 255.0 < m["log"]["duration_s"] < 261.0
    # airborne throughout, 6.6..20.8 m/s: the slow bins are empty (null), the others are not
    bins = m["by_airspeed_bin"]
    assert [b["samples"] for b in bins[:2]] == [0, 0] and bins[0]["adapted_rms_g"] is None
    assert all(b["samples"] > 0 and math.isfinite(b["adapted_rms_g"]) for b in bins[2:])
    # a different aircraft: theta_0 mispredicts, and adapting theta-hat lowers the error
    adapted, prior = m["prediction_error"]["adapted"]["rms_g"], m["prediction_error"]["prior"]["rms_g"]
    assert adapted < prior
    table = pq.read_table(out / "replay.parquet")
    assert table.num_rows == m["log"]["samples"]
    V = table.column("airspeed_mps").to_numpy()
    assert np.all(np.isfinite(V)) and V.min() > 5.0
    # no lift rotors and an unrecorded throttle: zero, not NaN
    assert np.all(table.column("throttle_z_pct").to_numpy() == 0.0)


def test_earlier_output_is_overwritten_but_other_folders_are_refused(tmp_path, capsys, px4):
    synthetic_log(tmp_path / "log", px4, duration_s=1.0)
    out = tmp_path / "out"
    args = [tmp_path / "log", "--vehicle", "px4_standard_vtol", "--out", out, "--no-adapt"]
    assert _replay(args, capsys)[0] == 0
    assert _replay(args, capsys)[0] == 0  # an earlier replay's output: replaced
    (out / "notes.txt").write_text("mine")
    assert _replay(args, capsys)[0] == 0  # a file of the user's beside it is neither refused nor touched
    assert (out / "notes.txt").read_text() == "mine"
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "precious.txt").write_text("keep")
    rc, _, err = _replay([tmp_path / "log", "--vehicle", "px4_standard_vtol", "--out", foreign, "--no-adapt"],
                         capsys)
    assert rc == 2 and "not empty" in err and "--force" in err and len(err.strip().splitlines()) == 1
    assert (foreign / "precious.txt").read_text() == "keep" and sorted(p.name for p in foreign.iterdir()) == ["precious.txt"]


# --- the readers against pyulog's own values ------------------------------------------------------

def _pyulog_topic(name, instance=0):
    from pyulog import ULog

    ulog = ULog(str(VTOL_ULOG), [name])
    return next(d.data for d in ulog.data_list if d.name == name and d.multi_id == instance)


def test_ulog_reader_matches_pyulog_samples():
    log = read_ulog(VTOL_ULOG, ReadSettings(lift_throttle=parse_throttle_source("actuator_outputs:4,5,6,7"),
                                            pusher_throttle=parse_throttle_source("actuator_outputs:2")))
    t_us = log.t0_us + log.t_s * 1e6
    rows = [0, 137, 700, log.n - 1]
    sc = _pyulog_topic("sensor_combined")
    for i in range(3):
        ref = np.interp(t_us[rows], sc["timestamp"].astype(float), sc[f"accelerometer_m_s2[{i}]"].astype(float))
        np.testing.assert_allclose(log.f_meas_B_mps2[rows, i], ref, rtol=0, atol=1e-6)
    lp = _pyulog_topic("vehicle_local_position")
    for i, f in enumerate(("vx", "vy", "vz")):
        ref = np.interp(t_us[rows], lp["timestamp"].astype(float), lp[f].astype(float))
        np.testing.assert_allclose(log.v_W_mps[rows, i], ref, atol=1e-6)
    att = _pyulog_topic("vehicle_attitude")
    # at an attitude sample's own time the quaternion is that sample (up to sign)
    exact = np.flatnonzero(np.isin(t_us.round(), att["timestamp"].astype(float)))
    assert exact.size > 0
    k = exact[min(3, exact.size - 1)]
    q_ref = np.array([att[f"q[{i}]"][att["timestamp"] == round(t_us[k])][0] for i in range(4)], float)
    assert abs(abs(np.dot(log.q_WB[k], q_ref / np.linalg.norm(q_ref))) - 1.0) < 1e-9
    # lift collective: RMS of the four PWM outputs mapped by the log's PWM_MIN/PWM_MAX (950/2000 us)
    ao = _pyulog_topic("actuator_outputs")
    m = rows[2]
    last = np.searchsorted(ao["timestamp"], t_us[m], side="right") - 1
    frac = (np.array([ao[f"output[{i}]"][last] for i in (4, 5, 6, 7)], float) - 950.0) / 1050.0
    assert log.throttle_z_pct[m] == pytest.approx(100.0 * np.sqrt(np.mean(np.clip(frac, 0, 1) ** 2)), abs=1e-9)


def test_csv_folder_reader_reads_ulog2csv_output_like_the_ulog(tmp_path):
    """pyulog's own ulog2csv writes the folder; both readers must give the same FlightLog."""
    from pyulog.ulog2csv import convert_ulog2csv

    topics = "vehicle_attitude,vehicle_local_position,sensor_combined,airspeed,wind_estimate,actuator_controls_0,actuator_controls_1,vehicle_land_detected,vehicle_status"
    convert_ulog2csv(str(VTOL_ULOG), topics, str(tmp_path), ",", None, None)
    assert (tmp_path / "sample_log_small_vehicle_attitude_0.csv").exists()
    a = read_ulog(VTOL_ULOG)
    b = read_csv_folder(tmp_path)
    assert a.n == b.n and a.t0_us == b.t0_us
    assert set(a.topics) == set(b.topics)
    for name in ("q_WB", "v_W_mps", "f_meas_B_mps2", "v_i_B_mps", "throttle_x_pct", "throttle_z_pct"):
        np.testing.assert_allclose(getattr(b, name), getattr(a, name), rtol=1e-6, atol=1e-6, err_msg=name)
    assert np.array_equal(a.landed, b.landed)


# --- a synthetic log with known theta ----------------------------------------------------------------

def _write_topic(folder, topic, t_us, cols):
    names = ["timestamp", *cols]
    data = np.column_stack([t_us, *cols.values()])
    lines = [",".join(names)] + [",".join([str(int(r[0]))] + [repr(float(v)) for v in r[1:]]) for r in data]
    (folder / f"synthetic_{topic}_0.csv").write_text("\n".join(lines) + "\n")


def synthetic_log(folder, vehicle, duration_s=12.0, rate_hz=250.0):
    """A PX4 topic-CSV folder whose accelerometer is the vehicle's force model (zero wind, exact pitot)."""
    n = int(duration_s * rate_hz)
    t = np.arange(n) / rate_hz
    t_us = 10_000_000 + np.arange(n) * int(1e6 / rate_hz)
    q = np.array([quat_from_euler(0.4 + 0.1 * np.sin(0.2 * s), 0.08 * np.sin(0.5 * s), 0.1 * np.sin(0.3 * s))
                  for s in t])
    V = 3.5 + 6.0 * t / duration_s
    alpha = 0.12 * np.sin(0.7 * t)
    v_B = np.column_stack([V * np.cos(alpha), 0.4 * np.sin(0.4 * t), V * np.sin(alpha)])
    u_x = 30.0 + 10.0 * np.sin(0.6 * t)
    u_z = 55.0 + 15.0 * np.sin(0.9 * t)
    f_B = np.array([models.body_force(v_B[k], u_x[k], u_z[k], vehicle) for k in range(n)])
    v_W = np.array([quat_to_rotmat(q[k]) @ v_B[k] for k in range(n)])
    folder.mkdir(parents=True, exist_ok=True)
    _write_topic(folder, "vehicle_attitude", t_us, {f"q[{i}]": q[:, i] for i in range(4)})
    _write_topic(folder, "vehicle_local_position", t_us, {"vx": v_W[:, 0], "vy": v_W[:, 1], "vz": v_W[:, 2]})
    _write_topic(folder, "sensor_combined", t_us, {f"accelerometer_m_s2[{i}]": f_B[:, i] for i in range(3)})
    _write_topic(folder, "airspeed", t_us, {"true_airspeed_m_s": np.linalg.norm(v_B, axis=1)})
    _write_topic(folder, "actuator_controls_0", t_us, {"control[3]": u_z / 100.0})
    _write_topic(folder, "actuator_controls_1", t_us, {"control[3]": u_x / 100.0})
    return v_B, f_B


def test_synthetic_log_from_the_model_gives_zero_error_and_theta_stays(tmp_path, capsys, px4):
    folder = tmp_path / "log"
    v_B, _ = synthetic_log(folder, px4)
    out = tmp_path / "out"
    rc, _, err = _replay([folder, "--vehicle", "px4_standard_vtol", "--out", out, "--no-motor-lag"], capsys)
    assert rc == 0, err
    m = _metrics(out)
    assert m["log"]["rate_hz"] == pytest.approx(250.0)
    assert m["log"]["samples_airspeed_from_pitot"] == m["log"]["samples"]
    assert m["prediction_error"]["adapted"]["max_g"] < 1e-9
    assert m["prediction_error"]["prior"]["max_g"] < 1e-9
    for name, v in m["theta"]["theta_0"].items():
        assert m["theta"]["final"][name] == pytest.approx(v, rel=1e-9, abs=1e-15), name
    # the reader rebuilt the incident velocity from pitot magnitude + inertial direction exactly
    log = read_csv_folder(folder)
    np.testing.assert_allclose(log.v_i_B_mps, v_B[: log.n], atol=1e-9)


def test_adaptation_recovers_a_wrong_lift_coefficient_on_the_synthetic_log(tmp_path, px4):
    folder = tmp_path / "log"
    synthetic_log(folder, px4, duration_s=12.0)
    log = read_csv_folder(folder)
    theta = px4.theta_scaled.copy()
    start = theta.copy()
    start[1] *= 1.2  # C_Tz 20 % high
    r = run_replay(log, px4, ReplaySettings(motor_lag=False), theta_init=start)
    assert r.theta_hat[0, 1] > 1.15 * theta[1]
    assert r.theta_hat[-1, 1] == pytest.approx(theta[1], rel=0.01)
    e_start = np.linalg.norm(r.e_mps2[5])
    e_end = np.linalg.norm(r.e_mps2[-250:], axis=1).max()
    assert e_end < 0.02 * e_start


# --- bad input: one line naming what is wrong, exit status 2 ----------------------------------------

@pytest.mark.parametrize("case", ["missing_topic", "not_a_log", "empty_folder", "missing_path",
                                  "bad_throttle", "bad_vehicle", "missing_field"])
def test_bad_input_is_one_line_and_status_2(tmp_path, capsys, case):
    out = tmp_path / "out"
    extra = []
    if case == "missing_topic":
        log = tmp_path / "log"
        log.mkdir()
        (log / "x_vehicle_attitude_0.csv").write_text("timestamp,q[0],q[1],q[2],q[3]\n1,1,0,0,0\n2,1,0,0,0\n")
        expect = "vehicle_local_position"
    elif case == "not_a_log":
        log = tmp_path / "notes.ulg"
        log.write_text("hello")
        expect = "not a PX4 ULog"
    elif case == "empty_folder":
        log = tmp_path / "empty"
        log.mkdir()
        expect = "no .csv files"
    elif case == "missing_path":
        log = tmp_path / "nowhere.ulg"
        expect = "no such file"
    elif case == "bad_throttle":
        log = FIXED_WING
        extra = ["--lift-throttle", "motors:1"]
        expect = "--lift-throttle"
    elif case == "bad_vehicle":
        log = FIXED_WING
        expect = "no_such_plane"
    else:
        log = tmp_path / "log"
        log.mkdir()
        (log / "x_vehicle_attitude_0.csv").write_text("timestamp,q[0],q[1],q[2],q[3]\n1,1,0,0,0\n2,1,0,0,0\n")
        (log / "x_vehicle_local_position_0.csv").write_text("timestamp,vx,vy\n1,0,0\n2,0,0\n")
        expect = "has no field vz"
    vehicle = "no_such_plane" if case == "bad_vehicle" else "px4_standard_vtol"
    rc, stdout, err = _replay([log, "--vehicle", vehicle, "--out", out, *extra], capsys)
    assert rc == 2
    assert len(err.strip().splitlines()) == 1, err
    assert expect in err
    assert not out.exists()


def test_gaps_become_nan_not_zero(tmp_path, px4):
    folder = tmp_path / "log"
    synthetic_log(folder, px4, duration_s=6.0)
    p = folder / "synthetic_sensor_combined_0.csv"
    lines = p.read_text().splitlines()
    # drop one second of accelerometer samples (rows 500..749 at 250 Hz)
    p.write_text("\n".join(lines[:501] + lines[751:]) + "\n")
    log = read_csv_folder(folder)
    gap = (log.t_s > 2.05) & (log.t_s < 2.95)
    assert np.all(np.isnan(log.f_meas_B_mps2[gap]))
    r = run_replay(log, px4, ReplaySettings(motor_lag=False))
    assert np.all(np.isnan(r.e_mps2[gap]))
    assert not r.used[gap].any()
    assert np.nanmax(np.linalg.norm(r.e_mps2, axis=1)) / GRAVITY_MPS2 < 1e-9


def test_fixed_wing_specific_force_is_velocity_derivative_minus_gravity_in_body_axes():
    """The folder has no accelerometer: f_B = R^T (a_W - g_W) from local_position.ax, ay, az."""
    import csv

    log = read_csv_folder(FIXED_WING)
    with open(FIXED_WING / "flight3_vehicle_local_position_0.csv") as fh:
        rows = list(csv.DictReader(fh))
    t = np.array([float(r["timestamp"]) for r in rows])
    a = np.array([[float(r[k]) for k in ("ax", "ay", "az")] for r in rows])
    k = 1234
    tk = log.t0_us + log.t_s[k] * 1e6
    a_W = np.array([np.interp(tk, t, a[:, i]) for i in range(3)])
    R = quat_to_rotmat(log.q_WB[k])
    np.testing.assert_allclose(log.f_meas_B_mps2[k], R.T @ (a_W - np.array([0, 0, GRAVITY_MPS2])), atol=1e-9)
    with pytest.raises(ReplayError, match="rate_hz"):
        ReadSettings(rate_hz=-1.0)


def test_truncated_ulog_is_refused_as_corrupt_in_one_line(tmp_path, capsys):
    """The first 20 kB of a ULog: pyulog printed its own line to stdout and the replay blamed a
    missing topic; it now says the file is damaged, in one line on stderr."""
    src = REPO_DATA_DIR / "pyulog-testdata" / "sample_log_small.ulg"
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(src.read_bytes()[:20000])
    with pytest.raises(ReplayError, match=r"cut\.ulg: corrupt or truncated ULog"):
        read_ulog(cut)
    code = main(["replay", str(cut), "--vehicle", "px4_standard_vtol", "--out", str(tmp_path / "o")])
    captured = capsys.readouterr()
    assert code == 2 and captured.out == ""
    assert len(captured.err.strip().splitlines()) == 1 and "corrupt or truncated" in captured.err
    assert not (tmp_path / "o").exists()


def test_csv_folder_with_a_nan_sample_or_a_header_only_topic_gives_no_stray_warnings(tmp_path):
    """A NaN and an infinity in attitude samples printed numpy's RuntimeWarning (two lines) before the summary;
    a header-only topic printed numpy's UserWarning before the one-line error."""
    import shutil
    import warnings

    src = REPO_DATA_DIR / "mit-solar-airplane-px4"
    nan_dir = tmp_path / "nan"
    shutil.copytree(src, nan_dir)
    att = nan_dir / "flight3_vehicle_attitude_0.csv"
    lines = att.read_text().splitlines()
    for row, value in ((50, "nan"), (60, "inf")):
        fields = lines[row].split(",")
        fields[1] = value
        lines[row] = ",".join(fields)
    att.write_text("\n".join(lines) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        log = read_csv_folder(nan_dir)
    assert np.isnan(log.q_WB).any() and np.isfinite(log.q_WB).any()
    empty_dir = tmp_path / "empty"
    shutil.copytree(src, empty_dir)
    (empty_dir / "flight3_vehicle_attitude_0.csv").write_text(lines[0] + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ReplayError, match="vehicle_attitude"):
            read_csv_folder(empty_dir)
