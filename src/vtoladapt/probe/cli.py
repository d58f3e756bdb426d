"""``vtoladapt probe``: calibrate an airflow probe and evaluate a calibration.

::

    vtoladapt probe calibrate DATA --out DIR
    vtoladapt probe evaluate CALIBRATION DATA --out DIR

``DATA`` is a NASA/Aeroprobe PCF file or the CSV format of :mod:`vtoladapt.probe.data`.
``calibrate`` writes ``calibration.json`` (both models), ``metrics.json`` and ``linearity.png``
into ``DIR``; ``evaluate`` writes ``metrics.json`` and ``linearity.png``.

``metrics.json``::

    {"single_k":   {"angle_rms_deg": ..., "angle_max_deg": ..., "speed_rms_rel": ..., ...},
     "calibrated": {...},
     "info": {"format": "vtoladapt.probe.metrics", "version": 1, "data": ..., "points": ...}}
"""
from __future__ import annotations

import argparse
from pathlib import Path

from vtoladapt.config import check_flag, check_input_file
from vtoladapt.errors import ExitCode
from vtoladapt.outputs import OutputDir, add_force_argument, atomic_path, output_path, write_json
from vtoladapt.probe.calibration import (
    DEFAULT_Q_INF_MIN_PA,
    MODEL_NAMES,
    calibrate,
    evaluate_calibration,
    load_calibration,
    save_calibration,
)
from vtoladapt.probe.data import read_probe_data
from vtoladapt.probe.errors import ProbeError
from vtoladapt.probe.figures import plot_linearity

METRICS_FORMAT = "vtoladapt.probe.metrics"
METRICS_VERSION = 1


def register_cli(subparsers) -> argparse.ArgumentParser:
    """Add the ``probe`` sub-command (``calibrate``, ``evaluate``) to ``subparsers``.

    Each leaf parser sets ``handler`` to its handler ``handler(args) -> int`` (exit code),
    which ``vtoladapt.cli.main`` calls; bad input raises ``ProbeError`` (a ``ConfigError``:
    exit code 2, one line) before anything is written.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        From ``parser.add_subparsers()``.

    Returns
    -------
    argparse.ArgumentParser
        The ``probe`` parser.
    """
    probe = subparsers.add_parser(
        "probe", help="calibrate the 3-D airflow probe and evaluate calibrations",
        description="Calibrate the five-hole airflow probe (the paper's eq:aoa single k and our "
                    "spline calibration) and evaluate a calibration on tunnel data.")
    sub = probe.add_subparsers(dest="probe_command", metavar="{calibrate,evaluate}")
    sub.required = True

    cal = sub.add_parser(
        "calibrate", help="fit single-k and calibrated models to probe calibration data",
        description="Fit both models to the calibration points of DATA (a NASA/Aeroprobe PCF "
                    "file or the vtoladapt probe CSV format), evaluate them on the test points "
                    "(or on all points when the file has none), and write calibration.json, "
                    "metrics.json and linearity.png into DIR.")
    cal.add_argument("data", metavar="DATA", type=Path, help="calibration data file")
    cal.add_argument("--out", metavar="DIR", type=output_path, required=True, help="output folder")
    cal.add_argument("--format", dest="fmt", choices=("auto", "nasa", "csv"), default="auto",
                     help="data format (default: recognise a PCF file by its first line)")
    cal.add_argument("--smoothing", type=float, default=None,
                     help="spline smoothing (default: chosen by leave-one-out cross-validation)")
    cal.add_argument("--q-inf-min-Pa", dest="q_inf_min_Pa", type=float,
                     default=DEFAULT_Q_INF_MIN_PA,
                     help="readings with q_inf below this are flagged invalid (Pa, default "
                          f"{DEFAULT_Q_INF_MIN_PA:g})")
    add_force_argument(cal)
    cal.set_defaults(handler=cmd_calibrate)

    ev = sub.add_parser(
        "evaluate", help="evaluate a calibration file on probe data",
        description="Evaluate the models in CALIBRATION on DATA (its test points when it has "
                    "them) and write metrics.json and linearity.png into DIR.")
    ev.add_argument("calibration", metavar="CALIBRATION", type=Path,
                    help="calibration.json written by 'probe calibrate'")
    ev.add_argument("data", metavar="DATA", type=Path, help="probe data file")
    ev.add_argument("--out", metavar="DIR", type=output_path, required=True, help="output folder")
    ev.add_argument("--format", dest="fmt", choices=("auto", "nasa", "csv"), default="auto",
                    help="data format (default: recognise a PCF file by its first line)")
    ev.add_argument("--models", default=None,
                    help="comma-separated model names to evaluate (default: all in the file; "
                         f"names: {', '.join(MODEL_NAMES)})")
    ev.add_argument("--points", choices=("auto", "test", "calibration", "all"), default="auto",
                    help="which points to evaluate (default: test points if any, else all)")
    add_force_argument(ev)
    ev.set_defaults(handler=cmd_evaluate)
    return probe


def _write_outputs(results: dict, data, out: Path, title: str) -> tuple[Path, Path]:
    any_metrics = next(iter(results.values()))
    doc = {name: m.to_dict() for name, m in results.items()}
    doc["info"] = {"format": METRICS_FORMAT, "version": METRICS_VERSION, "data": data.source,
                   "points": any_metrics.points, "n_points": any_metrics.n_points,
                   "angle_error": "angle between estimated and true flow direction (deg)",
                   "speed_error": "|V_est - V_true| / V_true",
                   "statistics_over": "points with an estimate (n_used), including readings "
                                      "flagged outside the calibrated range; n_valid counts "
                                      "the readings flagged valid"}
    if data.info.get("citation"):
        doc["info"]["data_citation"] = data.info["citation"]
    metrics_path = write_json(out / "metrics.json", doc, indent=1)
    fig_path = out / "linearity.png"
    with atomic_path(fig_path) as tmp:
        plot_linearity(results, tmp, title=title)
    return metrics_path, fig_path


def _summary(results: dict) -> str:
    lines = [f"{'model':<12} {'points':<12} {'angle RMS':>10} {'angle max':>10} "
             f"{'speed RMS':>10}  valid"]
    for name, m in results.items():
        lines.append(f"{name:<12} {m.points:<12} {m.angle_rms_deg:>8.4f}deg "
                     f"{m.angle_max_deg:>8.4f}deg {100 * m.speed_rms_rel:>9.3f}%  "
                     f"{m.n_valid}/{m.n_points}")
    return "\n".join(lines)


SMOOTHING_MAX = 1e6
Q_INF_MIN_PA_MAX = 1e5
"""Dynamic pressure of ~400 m/s at sea level: above it no reading could be valid."""


def cmd_calibrate(args: argparse.Namespace) -> int:
    """Handler of ``vtoladapt probe calibrate``; returns the exit code."""
    smoothing = args.smoothing
    if smoothing is not None:
        smoothing = check_flag("--smoothing", smoothing, ge=0.0, le=SMOOTHING_MAX)
    q_min = check_flag("--q-inf-min-Pa", args.q_inf_min_Pa, unit="Pa", ge=0.0, le=Q_INF_MIN_PA_MAX)
    data = read_probe_data(check_input_file(args.data, "probe data file"), args.fmt)
    target = OutputDir(args.out, "probe calibrate", force=args.force)
    models = calibrate(data, smoothing=smoothing, q_inf_min_Pa=q_min)
    results = {name: evaluate_calibration(m, data, "auto", name=name)
               for name, m in models.items()}
    points = next(iter(results.values())).points
    title = f"{Path(data.source).name}: {points} points"
    if points != "test":
        title += " (in-sample: the file has no test points)"
    with target:
        cal_path = target.path / "calibration.json"
        with atomic_path(cal_path) as tmp:
            save_calibration(tmp, models, source=data.source, notes=data.info.get("citation", ""))
        metrics_path, fig_path = _write_outputs(results, data, target.path, title)
    print(f"k = {models['single_k'].k:.6g}; spline smoothing = "
          f"{models['calibrated'].smoothing:g}")
    print(_summary(results))
    if points != "test":
        print("note: the data has no test points (split = test); these errors are in-sample")
    print(f"wrote {cal_path}\nwrote {metrics_path}\nwrote {fig_path}")
    return ExitCode.OK


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Handler of ``vtoladapt probe evaluate``; returns the exit code."""
    models = load_calibration(check_input_file(args.calibration, "calibration file"))
    if args.models:
        names = [n.strip() for n in args.models.split(",") if n.strip()]
        for n in names:
            if n not in MODEL_NAMES:
                raise ProbeError(f"--models: model name {n!r} unknown; allowed: "
                                 f"{', '.join(MODEL_NAMES)}")
            if n not in models:
                raise ProbeError(f"{args.calibration}: model {n!r} not in this file (it "
                                 f"has {', '.join(models)})")
        if not names:
            raise ProbeError(f"--models {args.models!r}: no model name; allowed: "
                             f"{', '.join(MODEL_NAMES)}")
        models = {n: models[n] for n in names}
    data = read_probe_data(check_input_file(args.data, "probe data file"), args.fmt)
    target = OutputDir(args.out, "probe evaluate", force=args.force)
    results = {name: evaluate_calibration(m, data, args.points, name=name)
               for name, m in models.items()}
    points = next(iter(results.values())).points
    title = f"{Path(args.calibration).name} on {Path(data.source).name}: {points} points"
    with target:
        metrics_path, fig_path = _write_outputs(results, data, target.path, title)
    print(_summary(results))
    print(f"wrote {metrics_path}\nwrote {fig_path}")
    return ExitCode.OK
