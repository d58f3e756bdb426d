"""``vtoladapt replay LOG --vehicle NAME --out DIR``: replay a real flight log open loop.

``LOG`` is a PX4 ULog (``.ulg``) or a folder of PX4 topic CSVs (pyulog's ``ulog2csv`` output).
Writes ``replay.parquet``, ``metrics.json``, ``fig_replay.png``, ``report.md`` and ``report.html``
into ``DIR``. Exit status 0 on success, 2 on bad input (one line on stderr naming the file, the
field and the value).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..config import ConfigError
from ..outputs import OutputDir, add_force_argument
from .flightlog import FlightLog, ReadSettings, ReplayError, no_usable_samples, parse_throttle_source


def register_cli(subparsers) -> argparse.ArgumentParser:
    """Add the ``replay`` sub-command to ``subparsers`` (its handler returns the exit code)."""
    p = subparsers.add_parser(
        "replay", help="replay a real PX4 flight log: force-model prediction error and adaptation",
        description="Run the controller's force model and composite adaptation open loop on a PX4 "
                    "ULog or a folder of PX4 topic CSVs, and write replay.parquet, metrics.json, "
                    "fig_replay.png, report.md and report.html into --out.")
    p.add_argument("log", metavar="LOG", type=Path, help="PX4 ULog (.ulg) or folder of topic CSVs")
    p.add_argument("--vehicle", required=True, help="shipped vehicle name or vehicle TOML path")
    p.add_argument("--out", metavar="DIR", required=True, type=Path, help="output folder")
    add_force_argument(p)
    p.add_argument("--rate-hz", type=float, default=None,
                   help="resampling rate (Hz; default: the fastest required topic, at most 250)")
    p.add_argument("--airspeed-min", type=float, default=ReadSettings.airspeed_min_mps,
                   help="pitot readings below this are invalid (m/s, default %(default)g)")
    p.add_argument("--lift-throttle", default=None,
                   help="lift collective: 'actuator_controls_0:3' (default for a VTOL), "
                        "'actuator_outputs:I,J,...' (PWM, RMS over the motors) or 'none' "
                        "(default for a fixed-wing)")
    p.add_argument("--pusher-throttle", default=None,
                   help="pusher: 'actuator_controls_1:3' (default for a VTOL; actuator_controls_0:3 "
                        "for a fixed-wing), 'actuator_outputs:I' or 'none'")
    p.add_argument("--pwm-range", nargs=2, type=float, metavar=("MIN", "MAX"), default=None,
                   help="PWM (us) of zero and full throttle for actuator_outputs (default: the "
                        "log's PWM_MIN/PWM_MAX, else 1000 2000)")
    p.add_argument("--no-adapt", action="store_true", help="keep theta-hat at the vehicle's theta_0")
    p.add_argument("--no-motor-lag", action="store_true",
                   help="use the logged throttles as they are (no nominal motor lag)")
    p.add_argument("--use-landed", action="store_true",
                   help="also adapt on and score samples the land detector flags as on the ground")
    p.set_defaults(handler=cmd_replay)
    return p


def read_flight_log(path: Path, settings: ReadSettings) -> FlightLog:
    """A ULog file or a folder of topic CSVs -> :class:`FlightLog` (chosen by what ``path`` is)."""
    from .csvfolder import read_csv_folder
    from .ulog import is_ulog, read_ulog

    path = Path(path)
    if path.is_dir():
        return read_csv_folder(path, settings)
    if not path.exists():
        raise ReplayError(f"{path}: no such file or folder")
    if is_ulog(path):
        return read_ulog(path, settings)
    raise ReplayError(f"{path}: not a PX4 ULog file (no 'ULog' header magic); give a .ulg file or a "
                      "folder of PX4 topic CSVs")


def cmd_replay(args: argparse.Namespace) -> int:
    """Handler of ``vtoladapt replay``; returns the exit code."""
    from ..vehicle import load_vehicle
    from .estimator import ReplaySettings, run_replay
    from .outputs import write_outputs

    try:
        target = OutputDir(args.out, "replay", force=args.force)
        vehicle = load_vehicle(args.vehicle)
        read = ReadSettings(
            rate_hz=args.rate_hz, airspeed_min_mps=args.airspeed_min,
            lift_throttle=None if args.lift_throttle is None else parse_throttle_source(args.lift_throttle, "--lift-throttle"),
            pusher_throttle=None if args.pusher_throttle is None else parse_throttle_source(args.pusher_throttle, "--pusher-throttle"),
            pwm_range_us=None if args.pwm_range is None else tuple(args.pwm_range))
        settings = ReplaySettings(adapt=not args.no_adapt, motor_lag=not args.no_motor_lag,
                                  use_landed=args.use_landed)
        log = read_flight_log(args.log, read)
        result = run_replay(log, vehicle, settings)
        if not result.used.any():  # metrics of nothing (all null) with exit 0 passed for a replay
            raise ReplayError(no_usable_samples(log, settings.use_landed))
        with target:
            metrics = write_outputs(result, target.path)
    except ReplayError as exc:
        raise ConfigError(str(exc)) from exc
    a = metrics["prediction_error"]["adapted"]
    p = metrics["prediction_error"]["prior"]
    used = metrics["log"]["used_s"]

    def g(v):
        return "n/a" if v is None else f"{v:.3f} g"

    print(f"{log.source}: {log.duration_s:.1f} s at {log.rate_hz:.4g} Hz, {used:.1f} s used; "
          f"prediction error RMS {g(a['rms_g'])} adapting, {g(p['rms_g'])} with theta_0")
    for n in log.notes:
        print(f"  lacks {n.quantity}: {n.lacks} -> {n.filled}")
    print(f"wrote {args.out}/replay.parquet, metrics.json, fig_replay.png, report.md, report.html")
    return 0


__all__ = ["cmd_replay", "read_flight_log", "register_cli"]
