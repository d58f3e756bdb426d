"""Cost of ``vtoladapt replay``: the open-loop adaptation over a 10-minute log, and the readers.

``run()`` returns ``(name, value, unit)`` rows: the median wall time of :func:`run_replay` on a
10-minute, 250 Hz flight log (150 000 samples of smooth forward flight, the accelerometer from the
force model plus seeded noise), and of reading the two vendored real logs.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from vtoladapt import load_vehicle, models
from vtoladapt.replay import FlightLog, ReplaySettings, read_csv_folder, read_ulog, run_replay

DATA = Path(__file__).resolve().parents[1] / "data"


def _ten_minute_log(vehicle, rate_hz=250.0, minutes=10.0) -> FlightLog:
    rng = np.random.default_rng(7)
    n = int(minutes * 60 * rate_hz)
    t = np.arange(n) / rate_hz
    V = 8.0 + 3.0 * np.sin(2 * np.pi * t / 60.0)
    alpha = 0.08 * np.sin(0.7 * t)
    v_B = np.column_stack([V * np.cos(alpha), 0.3 * np.sin(0.4 * t), V * np.sin(alpha)])
    u_x = 30.0 + 10.0 * np.sin(0.6 * t)
    u_z = 40.0 + 10.0 * np.sin(0.9 * t)
    step = max(1, n // 2000)  # the model at 2000 points, interpolated: building the log is not timed work
    f = np.array([models.body_force(v_B[k], u_x[k], u_z[k], vehicle) for k in range(0, n, step)])
    f_B = np.column_stack([np.interp(t, t[::step], f[:, i]) for i in range(3)]) + rng.normal(0, 0.2, (n, 3))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return FlightLog(source="synthetic", log_format="synthetic", rate_hz=rate_hz, t0_us=0, t_s=t, q_WB=q,
                     v_W_mps=v_B, wind_W_mps=np.zeros((n, 3)), airspeed_pitot_mps=np.linalg.norm(v_B, axis=1),
                     v_i_B_mps=v_B, v_i_from_pitot=np.ones(n, bool), f_meas_B_mps2=f_B,
                     throttle_x_pct=u_x, throttle_z_pct=u_z, landed=np.zeros(n, bool))


def _median_s(fn, repeats: int) -> float:
    fn()  # compile / warm up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def run() -> list[tuple[str, float, str]]:
    """Time the replay; return ``(name, seconds, "s")`` rows."""
    vehicle = load_vehicle("px4_standard_vtol")
    log = _ten_minute_log(vehicle)
    settings = ReplaySettings()
    return [
        ("replay.run_replay[10 min at 250 Hz, composite]", _median_s(lambda: run_replay(log, vehicle, settings), 5), "s"),
        ("replay.read_ulog[standard VTOL, 6.5 s]",
         _median_s(lambda: read_ulog(DATA / "pyulog-testdata" / "sample_log_small.ulg"), 5), "s"),
        ("replay.read_csv_folder[MIT fixed-wing, 260 s]",
         _median_s(lambda: read_csv_folder(DATA / "mit-solar-airplane-px4"), 5), "s"),
    ]
