"""The ``vtoladapt`` command line::

    vtoladapt reproduce --out DIR           the paper's experiments, figures and report
    vtoladapt run SCENARIO.toml --out DIR   one scenario (a single run or an experiment); --vehicle,
                                            --controller, --plugin MY_LAW.py, --log-rate HZ, --no-log
    vtoladapt scenario list | show NAME     shipped scenarios; show prints one to start a file of one's own
    vtoladapt export RUN --format csv|mat|parquet   a run's log for MATLAB, a spreadsheet or pandas
    vtoladapt tune SCENARIO --controller ID tune a law's declared gains (one budget for every law)
    vtoladapt campaign SCENARIO --runs N    Monte-Carlo campaign on a Dask cluster
    vtoladapt vehicle list | show NAME      shipped vehicles and their parameters
    vtoladapt controllers | bases           the control laws and force-model bases (registered ones too)
    vtoladapt tunnel / fit / fit-realdata   virtual wind tunnel and Bayesian model fitting
    vtoladapt probe calibrate / evaluate    airflow-probe calibration
    vtoladapt replay LOG --vehicle NAME     replay a real PX4 flight log (open-loop adaptation)

Every command validates its input before writing anything. Exit status (one convention for all,
:class:`vtoladapt.errors.ExitCode`): 0 done, 1 the run failed, 2 bad input (a one-line message
naming the file, key and value), 3 fit not converged (``--require-converged``), 130
interrupted, 143 terminated (SIGTERM). ``--debug`` (anywhere on the line) adds the traceback. Outputs follow
:mod:`vtoladapt.outputs`: no foreign file is overwritten, no file is left truncated.

A sub-command registers itself with a function ``register(subparsers)`` in
:func:`build_parser`; its handler ``handler(args) -> int`` returns the exit code and raises
for errors (``ConfigError`` for bad input), which :func:`main` reports.
"""
from __future__ import annotations

import os
import signal
import sys


def _interrupted_while_starting(signum, frame) -> None:
    """Ctrl-C or SIGTERM before :func:`main` takes them over (the imports take up to a second on a busy
    machine; Python's own handler raised KeyboardInterrupt from the middle of an import, a traceback
    and status -2): one line and the command's status. Nothing was written yet."""
    term = signum == signal.SIGTERM
    os.write(2, f"vtoladapt: {'terminated (SIGTERM)' if term else 'interrupted'} while starting; nothing "
                "was written\n".encode())
    os._exit(143 if term else 130)


if __name__ == "__main__" or os.path.basename(sys.argv[0]) == "vtoladapt":  # the command, not an import
    signal.signal(signal.SIGINT, _interrupted_while_starting)
    signal.signal(signal.SIGTERM, _interrupted_while_starting)

import argparse  # noqa: E402
import atexit  # noqa: E402
import json  # noqa: E402
import traceback  # noqa: E402

from .config import check_value  # noqa: E402
from .errors import ExitCode, Terminated, exit_code_for, interrupt_requested, one_line, sigint_handling  # noqa: E402
from .outputs import OutputDir, add_force_argument, output_path  # noqa: E402


def _add_run(sub) -> None:
    p = sub.add_parser("run", help="run a scenario file (single run or experiment)",
                       description="Run a scenario and write log.parquet (per run), metrics.json and "
                                   "figures into --out.")
    p.add_argument("scenario", help="scenario TOML (or the name of a shipped scenario)")
    p.add_argument("--out", required=True, type=output_path, help="output directory")
    p.add_argument("--duration", type=float, default=None, help="override duration_s (s)")
    p.add_argument("--seed", type=int, default=None, help="override the seed")
    p.add_argument("--vehicle", default=None, metavar="FILE|NAME",
                   help="fly this vehicle instead of the scenario's: a shipped name (vtoladapt vehicle list) or a "
                        "vehicle TOML (a relative path is from the working directory)")
    p.add_argument("--controller", action="append", default=None, metavar="ID",
                   help="override [controller] kind: an id of `vtoladapt controllers` (a law of --plugin too). "
                        "A comparison flies exactly the ids given, in order: repeat the flag or separate ids "
                        "by commas (--controller composite,pd); a single run or a convergence study takes one")
    p.add_argument("--plugin", action="append", default=None, metavar="MODULE|FILE.py",
                   help="import a module of your own first, registering its laws, bases, wind parts or sensors "
                        "(repeatable; installed plug-ins of the entry-point group vtoladapt.plugins load too)")
    p.add_argument("--tuned", default=None, metavar="FILE",
                   help="fly the law of a tuned settings file (from `vtoladapt tune`, e.g. scenarios/tuned/...) "
                        "with its gains (that controller only)")
    p.add_argument("--log-rate", type=float, default=None, metavar="HZ",
                   help="override [output] log_rate_hz: keep every k-th control tick in the log "
                        "(k = control rate / HZ); the metrics still use every tick")
    p.add_argument("--no-log", action="store_true",
                   help="override [output] log = false: write no log file (metrics, figures and report only)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_force_argument(p)
    p.set_defaults(handler=_cmd_run)


def _add_scenario(sub) -> None:
    p = sub.add_parser("scenario", help="list shipped scenarios or show one")
    ssub = p.add_subparsers(dest="scenario_cmd", required=True)
    ssub.add_parser("list", help="names and descriptions of the shipped scenarios").set_defaults(
        handler=_cmd_scenario_list)
    show = ssub.add_parser("show", help="print a scenario file (e.g. > my.toml to start one of your own)")
    show.add_argument("name", help="shipped name (vtoladapt scenario list) or path to a scenario TOML")
    show.set_defaults(handler=_cmd_scenario_show)


def _cmd_scenario_list(args) -> int:
    """One line per shipped scenario: the name ``run`` and ``scenario show`` take, and its description."""
    from .config import read_toml
    from .sim.scenario import SCENARIO_DIR, shipped_scenario_names

    names = shipped_scenario_names()
    width = max(len(n) for n in names)
    for name in names:
        description = read_toml(SCENARIO_DIR / f"{name}.toml").get("description", "")
        print(f"{name:<{width}}  {description}")
    return ExitCode.OK


def _cmd_scenario_show(args) -> int:
    """The scenario's file as written (its comments say why each value was chosen), after a header
    naming where it came from. Validated first: what is printed loads back."""
    from .sim.scenario import load_scenario

    scenario = load_scenario(args.name)
    text = open(scenario.source_path, encoding="utf-8").read()
    sys.stdout.write(f"# scenario {scenario.name} (from {scenario.source_path}); every key is in the "
                     "configuration reference with its unit and range\n" + text.rstrip("\n") + "\n")
    return ExitCode.OK


def _controller_ids(values) -> list[str]:
    """``--controller`` values, repeated and/or comma-separated, as one list of ids."""
    return [part.strip() for v in values for part in str(v).split(",") if part.strip()]


def _add_reproduce(sub) -> None:
    p = sub.add_parser("reproduce", help="reproduce the paper's experiments, figures and report",
                       description="Run the convergence and comparison experiments of the paper and "
                                   "write figures, metrics.json, report.md and report.html into --out.")
    p.add_argument("--out", required=True, type=output_path, help="output directory")
    p.add_argument("--duration-scale", type=float, default=1.0,
                   help="scale every experiment's duration (e.g. 0.1 for a quick look; "
                        f"{DURATION_SCALE_MIN:g} to {DURATION_SCALE_MAX:g})")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_force_argument(p)
    p.set_defaults(handler=_cmd_reproduce)


def _add_vehicle(sub) -> None:
    p = sub.add_parser("vehicle", help="list shipped vehicles or show one")
    vsub = p.add_subparsers(dest="vehicle_cmd", required=True)
    vsub.add_parser("list", help="names of the shipped vehicles").set_defaults(handler=_cmd_vehicle_list)
    show = vsub.add_parser("show", help="a vehicle's validated parameters with units (TOML layout)")
    show.add_argument("name", help="shipped name or path to a vehicle TOML")
    show.set_defaults(handler=_cmd_vehicle_show)
    jsb = vsub.add_parser("jsbsim", help="write a vehicle as a JSBSim aircraft (XML, engines, actuator map)")
    jsb.add_argument("name", help="shipped name or path to a vehicle TOML")
    jsb.add_argument("--out", required=True, type=output_path,
                     help="folder to write (JSBSim's root: aircraft/NAME/NAME.xml, engine/)")
    add_force_argument(jsb)
    jsb.set_defaults(handler=_cmd_vehicle_jsbsim)


def _add_listings(sub) -> None:
    p = sub.add_parser("controllers", help="the control laws a scenario can fly (registered ones included)")
    p.add_argument("--plugin", action="append", default=None, metavar="MODULE|FILE.py",
                   help="import a module of your own first (its laws are listed too)")
    p.set_defaults(handler=_cmd_controllers)
    p = sub.add_parser("bases", help="the force-model bases the controller can adapt (registered ones included)")
    p.add_argument("--vehicle", default="caltech_vtol",
                   help="shipped name or path of the vehicle whose parameter names to show (default caltech_vtol)")
    p.add_argument("--plugin", action="append", default=None, metavar="MODULE|FILE.py",
                   help="import a module of your own first (its bases are listed too)")
    p.set_defaults(handler=_cmd_bases)


def _cmd_controllers(args) -> int:
    """One line per law of the registry (ids a scenario's ``kind`` and ``--controller`` take)."""
    from .control.registry import CONTROLLERS
    from .plugins import load_plugins

    load_plugins(args.plugin)
    for c in CONTROLLERS.values():
        print(f"{c.id:<18} {c.label:<22} {c.description}")
    return ExitCode.OK


def _cmd_bases(args) -> int:
    """One block per basis: id, label, description and its parameters for ``--vehicle``."""
    from .bases import BASES, describe_basis
    from .plugins import load_plugins
    from .vehicle import load_vehicle

    load_plugins(args.plugin)
    veh = load_vehicle(args.vehicle)
    for b in BASES.values():
        spec = describe_basis(veh, b.id)
        print(f"{b.id:<18} {b.label:<22} {b.description}")
        print(f"{'':<18} {spec.n} parameters: " + ", ".join(
            f"{name} [{unit}]" for name, unit in zip(spec.names, spec.units)))
    return ExitCode.OK


def load_run_scenario(path, duration_s=None, seed=None, controller=None, tuned=None, vehicle=None,
                      log_rate_hz=None, no_log=False):
    """The scenario of ``vtoladapt run`` with its command-line overrides, fully validated.

    ``vehicle``: a shipped name or a vehicle file (relative to the working directory) flown instead
    of the scenario's. ``controller``: one id, or a list of them (a comparison flies exactly those;
    a single run or a convergence study takes one). ``log_rate_hz`` / ``no_log``: ``[output]``
    ``log_rate_hz`` and ``log = false``.

    The overrides go through the same checks as the file's keys (``--duration`` has
    ``duration_s``'s range), and the logs must fit the memory budget (:mod:`vtoladapt.sim.limits`).
    ``tuned``: a tuned settings file (:mod:`vtoladapt.experiments.tuning`); its law flies alone, with
    its gains (``--controller`` must then name the same law or be left out).
    """
    from dataclasses import replace

    from .config import ConfigError
    from .control.registry import controller_ids
    from .control.settings import ControllerConfig
    from .sim.limits import check_run_size
    from .sim.scenario import Scenario, load_scenario
    from .vehicle import load_vehicle

    scenario = load_scenario(path)
    ids = None if controller is None else [controller] if isinstance(controller, str) else list(controller)
    if vehicle is not None:
        value = check_value(Scenario, "vehicle", str(vehicle), "--vehicle")
        try:  # checked alone: the mistake is the flag's, not the scenario file's
            load_vehicle(value)
        except ConfigError as exc:
            text = str(exc)
            raise ConfigError(text if "--vehicle" in text else f"--vehicle {value}: {text}" if value not in text
                              else f"--vehicle: {text}") from None
        scenario = replace(scenario, vehicle=value)
    if log_rate_hz is not None or no_log:
        from .sim.output import OutputConfig

        out = scenario.output
        if log_rate_hz is not None:
            out = replace(out, log_rate_hz=check_value(OutputConfig, "log_rate_hz", log_rate_hz, "--log-rate"))
        if no_log:
            out = replace(out, log=False)
        scenario = replace(scenario, output=out)
        scenario._check(f"{scenario.source_path} with --log-rate")
    if duration_s is not None:
        scenario = replace(scenario, duration_s=check_value(Scenario, "duration_s", duration_s,
                                                            "--duration"))
    if seed is not None:
        scenario = replace(scenario, seed=check_value(Scenario, "seed", seed, "--seed"))
    if tuned is not None:
        from .experiments.tuning import tuned_controller

        config = tuned_controller(scenario.controller, tuned)
        if controller is not None and list(ids) != [config.kind]:
            raise ConfigError(f"--controller {','.join(ids)} with --tuned {tuned}: the file tunes {config.kind}")
        scenario = replace(scenario, controller=config)
        controller, ids = config.kind, [config.kind]
    if controller is not None:
        kinds = tuple(check_value(ControllerConfig, "kind", cid, "--controller") for cid in ids)
        if not kinds:
            raise ConfigError("--controller: no id given; allowed: " + ", ".join(controller_ids()))
        if len(set(kinds)) != len(kinds):
            raise ConfigError(f"--controller {','.join(kinds)}: an id given twice; allowed: each id once")
        if len(kinds) > 1 and scenario.experiment.kind != "comparison":
            raise ConfigError(f"--controller {','.join(kinds)}: {scenario.source_path} is a "
                              f"{scenario.experiment.kind!r} experiment, which flies one law; allowed: one id "
                              "(several need [experiment] kind = 'comparison')")
        scenario = replace(scenario, controller=replace(scenario.controller, kind=kinds[0]))
        if scenario.experiment.kind == "comparison":  # compare exactly these, in the order given
            scenario = replace(scenario, experiment=replace(scenario.experiment, controllers=kinds))
        scenario._check(f"{scenario.source_path} with --controller")
    where = f"{scenario.source_path}" + (" with --duration" if duration_s is not None else "")
    check_run_size(scenario, where)
    return scenario


def _cmd_run(args) -> int:
    from .experiments import run_experiment
    from .experiments.running import planned_outputs

    from .config import ConfigError
    from .outputs import OutputError
    from .plugins import load_plugins
    from .preflight import check_experiment

    load_plugins(args.plugin)  # before the scenario is read: it may name a plug-in's law
    controller = _controller_ids(args.controller) if args.controller is not None else None
    scenario = load_run_scenario(args.scenario, args.duration, args.seed, controller, args.tuned, args.vehicle,
                                 args.log_rate, args.no_log)
    target = OutputDir(args.out, "run", force=args.force, planned=planned_outputs(scenario))
    # what needs the built vehicle and plant (hover, the law's prior, the envelope at the start),
    # for every run the experiment flies: all before the folder is claimed
    check_experiment(scenario, scenario.source_path or scenario.name)
    with target:
        try:
            run_experiment(scenario, target.path, show_progress=not args.quiet)
        except ConfigError as exc:
            # a check made while setting the run up (e.g. a plant too weak to hover) is about the
            # scenario file: name it, as every other input error does
            if isinstance(exc, OutputError) or not scenario.source_path or scenario.source_path in str(exc):
                raise
            raise ConfigError(f"{scenario.source_path}: {exc}") from exc
    if not args.quiet:
        print(f"wrote {args.out}/metrics.json, report.md, report.html and figures", file=sys.stderr)
    return ExitCode.OK


DURATION_SCALE_MIN = 0.02
"""Shortest ``reproduce --duration-scale``: the comparison's wind schedule keeps whole control
ticks in every phase and the metrics' windows (e.g. 5 s after the fan stops) stay non-empty."""
DURATION_SCALE_MAX = 10.0


def _cmd_reproduce(args) -> int:
    from .config import check_flag
    from .experiments import reproduce

    check_flag("--duration-scale", args.duration_scale, ge=DURATION_SCALE_MIN,
               le=DURATION_SCALE_MAX)
    _check_reproduce_size(args.duration_scale)
    target = OutputDir(args.out, "reproduce", force=args.force)
    with target:
        reproduce(target.path, duration_scale=args.duration_scale, show_progress=not args.quiet)
    return ExitCode.OK


def _check_reproduce_size(scale: float) -> None:
    from dataclasses import replace

    from .sim.limits import check_run_size
    from .sim.scenario import SCENARIO_DIR, load_scenario

    for name in ("paper_convergence", "paper_comparison"):
        sc = load_scenario(SCENARIO_DIR / f"{name}.toml")
        check_run_size(replace(sc, duration_s=sc.duration_s * scale),
                       f"--duration-scale {scale:g} ({name})")


def _cmd_vehicle_list(args) -> int:
    from .vehicle import available_vehicles

    print("\n".join(available_vehicles()))
    return 0


def _cmd_vehicle_show(args) -> int:
    """Print a vehicle's validated parameters in its file's TOML layout, each with unit and meaning."""
    print(format_vehicle(args.name))
    return 0


def _cmd_vehicle_jsbsim(args) -> int:
    """Write the vehicle's JSBSim aircraft (the plant's default truth) into ``--out``."""
    from .outputs import write_text
    from .sim.jsbsim_aircraft import write_aircraft
    from .vehicle import load_vehicle

    veh = load_vehicle(args.name)
    target = OutputDir(args.out, "vehicle jsbsim", force=args.force)
    with target:
        ac = write_aircraft(veh, target.path, write_text=write_text)
    print(f"wrote {ac.xml_path} and its engines; open it with JSBSim --root={target.path} --aircraft={ac.name}")
    return ExitCode.OK


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

    basis_doc = next(f for f in dataclasses.fields(veh) if f.name == "basis").metadata["doc"]
    effectiveness_doc = next(f for f in dataclasses.fields(veh) if f.name == "effectiveness").metadata["doc"]
    lines = [f"# vehicle {veh.name}" + (f" (from {veh.source_path})" if veh.source_path else ""),
             "# each value: [unit] and meaning; [-] = dimensionless",
             f"name = {value(veh.name)}", f"description = {value(veh.description)}",
             f"basis = {value(veh.basis)}  # [-] {basis_doc}",
             f"effectiveness = {value(veh.effectiveness)}  # [-] {effectiveness_doc}"]
    for f in dataclasses.fields(veh):
        sub = getattr(veh, f.name)
        if dataclasses.is_dataclass(sub):
            lines += ["", f"[{f.name}]  # {f.metadata.get('doc', '')}"] + block(sub)
    for sf in veh.surfaces:   # [[surfaces]]: one table per control surface, in the file's order
        lines += ["", "[[surfaces]]"] + block(sf)
    for basis_id, _ in veh.basis_settings:   # a basis's own settings, as the file gave them
        table = veh.basis_table(basis_id)
        lines += ["", f"[basis_settings.{basis_id}]"] + [f"{k} = {value(v)}" for k, v in table.items()]
    for eid, _ in veh.effectiveness_settings:   # an effectiveness's own settings (PX4's CA_* for px4_ca)
        table = veh.effectiveness_table(eid)
        lines += ["", f"[effectiveness_settings.{eid}]"] + [f"{k} = {value(v)}" for k, v in table.items()]
    return "\n".join(lines)


class _Parser(argparse.ArgumentParser):
    """argparse with a usage error on one line, like every other error (the usage is one --help away).

    Sub-command parsers are made by ``add_subparsers``, which takes its parent's class, so every
    sub-command's parser is one of these too.
    """

    def error(self, message: str):
        self.exit(int(ExitCode.BAD_INPUT), f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def help_description() -> str:
    """``vtoladapt --help``'s text: this module's summary and command list, without the reST markup
    (double back-quotes and roles) the API documentation needs and a terminal shows raw."""
    import re
    import textwrap

    def plain(text: str) -> str:  # :class:`vtoladapt.errors.ExitCode` -> the name; ``x`` -> x
        return re.sub(r":[a-z]+:`~?([^`]+)`", r"\1", text).replace("``", "")

    paragraphs = __doc__.split("\n\n")
    return ("vtoladapt: adaptive control of fixed-wing VTOL aircraft.\n\n" + plain(paragraphs[1]) + "\n\n"
            + textwrap.fill(plain(" ".join(paragraphs[2].split())), width=100))


def build_parser() -> argparse.ArgumentParser:
    """The ``vtoladapt`` parser: every sub-command registers itself here."""
    from .campaign.runner import register_cli as register_campaign
    from .experiments.tuning import register_cli as register_tune
    from .fitting.cli import register_cli as register_fitting
    from .learn.cli import register_cli as register_learn
    from .probe.cli import register_cli as register_probe
    from .replay.cli import register_cli as register_replay

    from ._version import __version__
    from .export import register_cli as register_export

    parser = _Parser(prog="vtoladapt", description=help_description(),
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"vtoladapt {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of an error (accepted anywhere on the line)")
    sub = parser.add_subparsers(dest="command", required=True)
    for register in (_add_reproduce, _add_run, register_tune, _add_vehicle, _add_scenario, _add_listings,
                     register_export, register_campaign,
                     register_fitting, register_learn, register_probe, register_replay):
        register(sub)
    return parser


def _command_name(args: argparse.Namespace) -> str:
    parts = [getattr(args, "command", None)]
    for sub in ("vehicle_cmd", "scenario_cmd", "probe_command"):
        if getattr(args, sub, None):
            parts.append(getattr(args, sub))
    return " ".join(p for p in parts if p)


_LABELS = {ExitCode.BAD_INPUT: "error", ExitCode.RUN_FAILED: "run failed",
           ExitCode.INTERRUPTED: "interrupted", ExitCode.TERMINATED: "terminated"}


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``) and return the exit status."""
    return _main(argv, ignore_sigint_after=False)


def _main(argv: list[str] | None, ignore_sigint_after: bool) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv or os.environ.get("VTOLADAPT_DEBUG", "") not in ("", "0")
    argv = [a for a in argv if a != "--debug"]
    name = "vtoladapt"
    interrupted = "interrupted; outputs completed so far are kept, none is truncated"
    try:
        with sigint_handling(ignore_after=ignore_sigint_after):
            parser = build_parser()
            try:
                args = parser.parse_args(argv)
            except SystemExit as exc:  # --help (0) or a usage error (2, already printed)
                return int(exc.code or 0) if not isinstance(exc.code, str) else ExitCode.BAD_INPUT
            name = f"vtoladapt {_command_name(args)}"
            code = int(args.handler(args) or 0)
            if interrupt_requested():  # Python dropped the KeyboardInterrupt after the last check
                print(f"{name}: {interrupted} (the interrupt came after the last output)", file=sys.stderr)
                return ExitCode.INTERRUPTED
            return code
    except KeyboardInterrupt as exc:
        if debug:
            traceback.print_exc()
        if isinstance(exc, Terminated):
            print(f"{name}: terminated (SIGTERM); outputs completed so far are kept, none is truncated",
                  file=sys.stderr)
            return ExitCode.TERMINATED
        print(f"{name}: {interrupted}", file=sys.stderr)
        return ExitCode.INTERRUPTED
    except Exception as exc:  # every error becomes one line and an exit code
        if debug:
            traceback.print_exc()
        code = exit_code_for(exc)
        print(f"{name}: {_LABELS.get(code, 'error')}: {one_line(exc)}", file=sys.stderr)
        return int(code)


def console() -> None:
    """The ``vtoladapt`` console command: :func:`main` on ``sys.argv``, then exit with its status.

    Once the status is decided, Ctrl-C is ignored (:func:`vtoladapt.errors.sigint_handling`), the
    exit handlers run (Dask's and multiprocessing's clean-up) and the process ends without the
    interpreter's teardown: that teardown spends 3-7 s freeing compiled kernels, and a Ctrl-C
    that reached a command which then caught it could still end the process by SIGINT (status -2
    after the one-line message, in about one of four runs under load) -- CPython's own exit
    path, which no handler can intercept.
    """
    code = _main(None, ignore_sigint_after=True)
    try:
        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(int(code))


if __name__ == "__main__":
    console()
