"""The ``vtoladapt`` command line.

    vtoladapt reproduce --out DIR           the paper's experiments, figures and report
    vtoladapt run SCENARIO.toml --out DIR   one scenario (a single run or an experiment)
    vtoladapt campaign SCENARIO --runs N    Monte-Carlo campaign on a Dask cluster
    vtoladapt vehicle list | show NAME      shipped vehicles and their parameters
    vtoladapt tunnel / fit / fit-realdata   virtual wind tunnel and Bayesian model fitting
    vtoladapt probe calibrate / evaluate    airflow-probe calibration
    vtoladapt replay LOG --vehicle NAME     replay a real PX4 flight log (open-loop adaptation)

Every command validates its input before writing anything and exits with status 2 and a message
naming the bad file, key and value on a configuration error.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .config import ConfigError


def _add_run(sub) -> None:
    p = sub.add_parser("run", help="run a scenario file (single run or experiment)",
                       description="Run a scenario and write log.parquet (per run), metrics.json and "
                                   "figures into --out.")
    p.add_argument("scenario", help="scenario TOML (or the name of a shipped scenario)")
    p.add_argument("--out", required=True, type=Path, help="output directory")
    p.add_argument("--duration", type=float, default=None, help="override duration_s (s)")
    p.add_argument("--seed", type=int, default=None, help="override the seed")
    p.add_argument("--controller", default=None,
                   help="override [controller] kind: an id of vtoladapt.control.registry (that controller only)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=_cmd_run)


def _add_reproduce(sub) -> None:
    p = sub.add_parser("reproduce", help="reproduce the paper's experiments, figures and report",
                       description="Run the convergence and comparison experiments of the paper and "
                                   "write figures, metrics.json, report.md and report.html into --out.")
    p.add_argument("--out", required=True, type=Path, help="output directory")
    p.add_argument("--duration-scale", type=float, default=1.0,
                   help="scale every experiment's duration (e.g. 0.1 for a quick look)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=_cmd_reproduce)


def _add_vehicle(sub) -> None:
    p = sub.add_parser("vehicle", help="list shipped vehicles or show one")
    vsub = p.add_subparsers(dest="vehicle_cmd", required=True)
    vsub.add_parser("list", help="names of the shipped vehicles").set_defaults(handler=_cmd_vehicle_list)
    show = vsub.add_parser("show", help="a vehicle's validated parameters with units (TOML layout)")
    show.add_argument("name", help="shipped name or path to a vehicle TOML")
    show.set_defaults(handler=_cmd_vehicle_show)


def _cmd_run(args) -> int:
    from .experiments import run_scenario_file

    run_scenario_file(args.scenario, args.out, duration_s=args.duration, seed=args.seed,
                      controller=args.controller, show_progress=not args.quiet)
    return 0


def _cmd_reproduce(args) -> int:
    from .experiments import reproduce

    reproduce(args.out, duration_scale=args.duration_scale, show_progress=not args.quiet)
    return 0


def _cmd_vehicle_list(args) -> int:
    from .vehicle import available_vehicles

    print("\n".join(available_vehicles()))
    return 0


def _cmd_vehicle_show(args) -> int:
    """Print a vehicle's validated parameters in its file's TOML layout, each with unit and meaning."""
    print(format_vehicle(args.name))
    return 0


def format_vehicle(name_or_path) -> str:
    """The vehicle's parameters section by section as ``key = value  # [unit] meaning`` lines
    (TOML, so the output can start a vehicle file of one's own)."""
    import dataclasses

    from .vehicle import load_vehicle

    veh = load_vehicle(name_or_path)

    def value(v) -> str:
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, bool):
            return str(v).lower()
        if isinstance(v, (tuple, list)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)

    def block(obj) -> list[str]:
        rows = [(f"{f.name} = {value(getattr(obj, f.name))}", f.metadata.get("unit", "-"), f.metadata.get("doc", ""))
                for f in dataclasses.fields(obj) if not dataclasses.is_dataclass(getattr(obj, f.name))
                and f.name != "source_path"]
        width = max((len(r[0]) for r in rows), default=0)
        return [f"{text:<{width}}  # [{unit}] {doc}" for text, unit, doc in rows]

    lines = [f"# vehicle {veh.name}" + (f" (from {veh.source_path})" if veh.source_path else ""),
             "# each value: [unit] and meaning; [-] = dimensionless",
             f"name = {value(veh.name)}", f"description = {value(veh.description)}"]
    for f in dataclasses.fields(veh):
        sub = getattr(veh, f.name)
        if dataclasses.is_dataclass(sub):
            lines += ["", f"[{f.name}]  # {f.metadata.get('doc', '')}"] + block(sub)
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    from .campaign import register_cli as register_campaign
    from .fitting.cli import register_cli as register_fitting
    from .probe.cli import register_cli as register_probe
    from .replay.cli import register_cli as register_replay

    parser = argparse.ArgumentParser(prog="vtoladapt", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    _add_reproduce(sub)
    _add_run(sub)
    _add_vehicle(sub)
    register_campaign(sub)
    register_fitting(sub)
    register_probe(sub)
    register_replay(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args) or 0)
    except ConfigError as exc:
        print(f"vtoladapt: configuration error: {exc}", file=sys.stderr)
        return 2
    except (FileNotFoundError, ValueError) as exc:
        print(f"vtoladapt: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
