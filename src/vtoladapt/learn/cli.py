"""``vtoladapt learn-basis``: train a learned force-model basis from flight logs."""
from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from ..config import ConfigError


def register_cli(subparsers) -> argparse.ArgumentParser:
    """Add the ``learn-basis`` sub-command."""
    p = subparsers.add_parser(
        "learn-basis", help="train a learned force-model basis from flight logs (meta-learning)",
        description="Read flight logs (simulator Parquet logs, PX4 .ulg files, or folders of them; or fly "
                    "training draws of a campaign file with --fly), one task per flight, fit the shared "
                    "network by meta-learning (each flight's linear weights solved in closed form inside the "
                    "loss) and write the basis file that `[controller] basis = \"learned\"` flies.")
    p.add_argument("logs", nargs="*", metavar="LOG", type=Path, help="log files or folders of logs")
    p.add_argument("--out", required=True, type=Path, metavar="FILE", help="basis file to write (.npz)")
    p.add_argument("--vehicle", default=None, help="vehicle family (shipped name or TOML path); default: the "
                   "one the simulator logs name (--fly: every draw of another vehicle is left out)")
    p.add_argument("--fly", type=Path, metavar="CAMPAIGN", default=None,
                   help="fly the training draws of this campaign file first (logs into --logs-dir)")
    p.add_argument("--runs", type=int, default=60, help="--fly: draws of the campaign to plan (default 60)")
    p.add_argument("--seed", type=int, default=2222, help="--fly: the draws' seed (default 2222; the envelope "
                   "campaign's evaluation draws use its own seed 1111)")
    p.add_argument("--logs-dir", type=Path, default=None, help="--fly: folder for the training logs "
                   "(default: beside --out, <out stem>_logs)")
    p.add_argument("--hold-out-schedule", action="append", default=[], metavar="NAME",
                   help="--fly: leave this fan schedule out of training (repeatable)")
    p.add_argument("--hold-out-bearing", action="append", default=[], metavar="LO:HI",
                   help="--fly: leave fan bearings in [LO, HI) deg out of training (repeatable)")
    p.add_argument("--h", type=int, default=4, help="learned columns (default 4)")
    p.add_argument("--hidden", type=int, default=32, help="width of each of the two hidden layers (default 32)")
    p.add_argument("--iterations", type=int, default=300, help="L-BFGS iterations (default 300)")
    p.add_argument("--train-seed", type=int, default=0, help="seed of the network's initial weights (default 0)")
    p.add_argument("--adversarial", type=float, default=0.0, metavar="ALPHA",
                   help="weight of the domain-adversarial term that keeps the network from telling the flights' "
                   "conditions apart (default 0: off; see the docs' bases page)")
    p.add_argument("--adversarial-rounds", type=int, default=8, help="--adversarial: classifier fits, each "
                   "followed by ITERATIONS / ROUNDS L-BFGS iterations (default 8)")
    p.add_argument("--stride", type=int, default=5, help="keep every N-th sample of a log (default 5: 50 Hz)")
    p.add_argument("--workers", type=int, default=2, help="--fly: flights in parallel (default 2)")
    p.add_argument("--force", action="store_true", help="replace an existing --out file")
    p.set_defaults(handler=cmd_learn_basis)
    return p


def _check(args) -> None:
    from ..bases.netfile import MAX_H, MAX_HIDDEN

    for name, lo, hi in (("h", 1, MAX_H), ("hidden", 2, MAX_HIDDEN), ("iterations", 1, 100_000), ("stride", 1, 10_000),
                         ("runs", 1, 100_000), ("workers", 1, 256), ("adversarial_rounds", 1, 1000)):
        v = getattr(args, name)
        if not lo <= v <= hi:
            raise ConfigError(f"--{name.replace('_', '-')} = {v}: out of range; allowed: {lo} to {hi}")
    if not (args.adversarial >= 0.0 and args.adversarial <= 1e3):   # also refuses nan
        raise ConfigError(f"--adversarial = {args.adversarial}: out of range; allowed: 0 to 1000")
    if args.out.is_dir():
        raise ConfigError(f"--out {args.out}: is a folder; allowed: a file name (.npz), not replaced by --force")
    if args.out.exists() and not args.out.is_file():   # a device or a pipe: replacing it is no user's wish
        raise ConfigError(f"--out {args.out}: exists and is not a regular file; allowed: a file name (.npz)")
    if args.out.exists() and not args.force:
        raise ConfigError(f"{args.out}: exists; allowed: a new file, or --force to replace it")
    if not args.out.parent.is_dir():
        raise ConfigError(f"--out {args.out}: folder {args.out.parent} does not exist; allowed: a file in an "
                          "existing folder")
    named = [("--fly", args.fly), ("--vehicle", Path(args.vehicle) if args.vehicle else None),
             ("--logs-dir", args.logs_dir)]
    for flag, p in named:
        if p is not None and _same(p, args.out):
            raise ConfigError(f"--out {args.out}: is the {flag} input {p}; allowed: a file no input is read from "
                              "(--force never replaces an input)")
    if args.fly is None and not args.logs:
        raise ConfigError("no logs: give LOG files or folders, or --fly CAMPAIGN")
    if args.fly is not None and args.logs:
        raise ConfigError("LOG arguments and --fly: allowed: one of them")


def cmd_learn_basis(args: argparse.Namespace) -> int:
    """Read (or fly) the flights, train, write the basis file; one summary line on stderr."""
    from ..vehicle import load_vehicle
    from .basis import MIN_SAMPLES, learn_basis, save
    from .data import log_files, read_flight, shipped_vehicle
    from .flights import HoldOut, fly_draws, parse_sector, plan_flights
    from .meta import MetaSettings

    _check(args)
    from ..bases.learned import net_names  # noqa: F401  (the runtime's module must import: fail early)

    vehicle = load_vehicle(args.vehicle) if args.vehicle else None
    extra: dict = {}
    if args.fly is not None:
        hold = HoldOut(tuple(args.hold_out_schedule), tuple(parse_sector(s) for s in args.hold_out_bearing))
        specs = plan_flights(args.fly, args.runs, args.seed, vehicle.name if vehicle else None, hold)
        if not specs:
            raise ConfigError(f"--fly {args.fly}: none of the {args.runs} draws is left after the vehicle and "
                              "held-out conditions")
        logs_dir = args.logs_dir or args.out.with_name(args.out.stem + "_logs")
        print(f"learn-basis: flying {len(specs)} training draws of {args.fly} (seed {args.seed}) into {logs_dir}",
              file=sys.stderr)
        paths = fly_draws(specs, logs_dir, workers=args.workers)
        extra = {"campaign": str(args.fly), "campaign_runs": args.runs, "campaign_seed": args.seed,
                 "held_out": hold.describe()}
    else:
        paths = log_files(args.logs)
        if not paths:
            raise ConfigError(f"{', '.join(map(str, args.logs))}: no .parquet or .ulg logs")
        _distinct_inputs(paths, args.out)
    flights = [read_flight(p, vehicle, stride=args.stride) for p in paths]
    if vehicle is None:
        names = sorted({f.vehicle for f in flights})
        if len(names) != 1:
            raise ConfigError(f"the logs fly {names}; allowed: one vehicle family per basis (--vehicle NAME)")
        vehicle = shipped_vehicle(names[0], str(paths[0]))
    else:
        flights = [f for f in flights if f.vehicle == vehicle.name or not f.source.endswith(".parquet")]
    settings = MetaSettings(h=args.h, hidden=(args.hidden, args.hidden), max_iter=args.iterations,
                            seed=args.train_seed, adversarial=args.adversarial,
                            adversarial_rounds=args.adversarial_rounds)
    command = "vtoladapt learn-basis " + " ".join(shlex.quote(a) for a in sys.argv[2:]) \
        if len(sys.argv) > 1 and sys.argv[1] == "learn-basis" else ""
    net, summary = learn_basis(flights, vehicle, settings, command=command, extra_meta=extra)
    save(net, args.out, force=args.force)
    left_out = summary.get("left_out") or []
    left_note = (f" ({len(left_out)} left out: fewer than {MIN_SAMPLES} usable samples, e.g. {left_out[0]})"
                 if left_out else "")
    print(f"learn-basis: {args.out}: {summary['flights']} flights{left_note}, {summary['samples']} samples, "
          f"loss {summary['loss_physics_only']:.4g} (physics columns alone) -> {summary['loss_final']:.4g} "
          f"(with {args.h} learned columns) in {summary['train_seconds']:.0f} s" + _condition_note(summary),
          file=sys.stderr)
    return 0


def _identity(p: Path):
    try:
        st = p.stat()
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _same(a: Path, b: Path) -> bool:
    """Whether two paths are one file or folder (links and hard links included); False if either is missing."""
    ia = _identity(a)
    return ia is not None and ia == _identity(b)


def _distinct_inputs(paths: list[Path], out: Path) -> None:
    """Each log once (a flight counted twice would weigh twice in the loss: refused, not warned, since the
    file then records flights it did not see) and never the output."""
    seen: dict = {}
    out_id = _identity(out)
    for p in paths:
        ident = _identity(p)
        if ident is not None and ident == out_id:
            raise ConfigError(f"--out {out}: is the log {p}; allowed: a file no input is read from (--force never "
                              "replaces an input)")
        if ident in seen:
            raise ConfigError(f"{p}: the same log as {seen[ident]} (given twice, directly or in a folder); allowed: "
                              "each flight once")
        seen[ident] = p


def _condition_note(summary: dict) -> str:
    if summary.get("condition_accuracy") is None:
        return ""
    return (f"; a classifier tells the flights' {summary['conditions']} conditions from the network's outputs in "
            f"{100 * summary['condition_accuracy']:.0f} % of samples (largest condition "
            f"{100 * summary['condition_chance']:.0f} %)")
