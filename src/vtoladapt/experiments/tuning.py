"""One tuning budget for every law: ``vtoladapt tune SCENARIO --controller ID``.

Every law's search space is the same shared gains plus its own. The shared gains are declared once,
in :data:`vtoladapt.control.settings.TUNABLE` (``K_v`` and ``Lambda_p`` horizontal and vertical,
``Lambda_q`` roll and pitch: the loop gains every law flies, and why those, in that module's
notes), named here ``controller.<key>`` (``"controller.K_v[0:2]"``). Each law declares its own in
its module: ``TUNABLE``, a tuple of ``(setting, low, high, log_scale)``. ``setting`` is a key of the
law's ``[controller.<id>]`` table (``"cutoff_radps"``), components of a tuple-valued one set to one
value (``"K_I[0:2]"``: north and east, ``"K_I[2]"``: down), or ``"controller.<key>"`` for another
shared ``[controller]`` key that is the law's gain (INDI's filter, ``lowpass_cutoff_hz``). A law
without ``TUNABLE`` (nominal) searches the shared gains alone.

The search
----------
* **Objective**: the mean over the tuning draws of the run's RMS velocity error ``|v~|`` (the
  comparison's headline metric); a draw that leaves the envelope counts as
  :data:`DIVERGED_PENALTY_MPS`. The draws are fixed for the whole search (common random numbers),
  so the objective is a deterministic function of the gains. ``v~ = v - v_r`` weighs the position
  error by ``Lambda_p`` (eq:wr), a searched gain: every run is measured with the scenario's
  ``Lambda_p`` whatever it flies (:meth:`vtoladapt.sim.results.SimulationResult.measured_with`),
  so the yardstick is the same for every law and every evaluation (measured with its own, a law
  would score better simply by flying a lower position gain).
* **Tuning draws**: seeds ``0 .. draws-1`` of ``SeedSequence([seed, TUNING_STREAM])`` (each its own
  plant draw from Table I, turbulence and sensor noise), disjoint from the evaluation variants of
  ``SeedSequence([seed, VARIANT_STREAM])`` that ``make reproduce`` reports (checked, not assumed).
* **Budget**: the same for every law: :data:`EVALUATIONS` evaluations of the objective, each on
  :data:`DRAWS` draws; the first is the law's defaults, the rest the optimiser's. The tuned
  settings are the best evaluated, so on the tuning draws they are never worse than the defaults.
* **Optimiser**: DIRECT (Jones, Perttunen & Stuckman 1993) in its locally biased form, DIRECT-L
  (Gablonsky & Kelley 2001), from SciPy (``scipy.optimize.direct``), over the declared box (log
  coordinates where declared). Why: it is derivative-free and deterministic (the same budget gives
  the same answer, which a shipped result needs), it needs no starting point or step size (the
  laws' gains span decades), it works in the five to nine dimensions of these spaces (nominal: the
  five shared gains; the PID: nine), it explores the whole box globally before it refines, which
  suits a budget of about fifteen evaluations per dimension on a box of unknown shape, and SciPy
  is already a dependency: nothing is added. CMA-ES (pycma) and Optuna's samplers need a
  population or a model over tens of points before they beat a space-filling search at this
  budget and are stochastic (a shipped result would depend on their seed); Nelder-Mead and Powell
  are local and need a start and a step.

The result is written as a controller settings file (:func:`tuned_file_text`): ``dt_control_s``,
a ``[controller]`` table with ``kind``, the tuned shared keys and the law's table of tuned gains,
and a ``[tuning]`` table with the search's record. :func:`vtoladapt.control.load_controller_config`
loads it (the other tables are ignored); :func:`tuned_controller` puts its gains into a scenario's
controller (``vtoladapt run SCENARIO --tuned FILE``). The tuned files ``make reproduce`` reports
ship in ``scenarios/tuned/`` (:func:`shipped_tuned_file`); ``make tune`` searches them again.
"""
from __future__ import annotations

import dataclasses
import json
import math
import re
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

from ..config import ConfigError
from ..sim.scenario import SCENARIO_DIR, Scenario

TUNING_STREAM = 0x7E5E
"""Second entropy word of the tuning draws' seed sequence (the evaluation variants use
:data:`vtoladapt.experiments.distribution.VARIANT_STREAM`)."""
EVALUATIONS = 150
"""Evaluations of the objective per law (the first is the law's defaults): about fifteen per searched
dimension for the largest space (the PID's nine; issue #25's first budget was 60 for at most four)."""
DRAWS = 10
"""Tuning draws each evaluation flies."""
OBJECTIVE = "vel_err_rms_mps"
TRACKING_CLAIMS = ("pd_large_errors_at_high_wind", "pid_overshoots_when_fan_stops", "adaptive_track_best")
"""The paper's tracking claims :func:`tuned_comparison` judges again with every law's tuned settings."""
EDGE_FRACTION = 0.1
"""A tuned gain within this fraction of its box's width (log width where log-scaled) of a bound is
reported as at that edge of its box (:func:`box_edge`): the optimum may lie beyond it. A tenth, not
less: DIRECT samples the centres of thirds, so after two refinements its points nearest a bound are
1/18 of the width from it."""
DIVERGED_PENALTY_MPS = 10.0
"""A tuning draw that leaves the envelope counts as this RMS velocity error (m/s)."""
OPTIMISER = "DIRECT-L (scipy.optimize.direct, locally_biased=True)"
NOT_IN_SHIPPED_FILES = ("adaptation_gain_scale", "measurement_noise_scale", "process_noise_scale",
                        "kalman_time_scale_s", "regularisation_lambda")
"""Gains declared after the shipped tuned files (``scenarios/tuned/``) were searched: the adaptive laws'
adaptation gain (issue #34, defect 5) and the composite law's Kalman form's noise weights, time scale and
regularisation (issue #34; the shipped files fly the paper form, which ignores them). Those files fly them at
their defaults until the adaptive laws are tuned again (``make tune``, issue #34's fair re-tuning)."""
TUNED_DIR = SCENARIO_DIR / "tuned"

_NAME = re.compile(r"^(controller\.)?([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)(?::(\d+))?\])?$")


@dataclass(frozen=True)
class Tunable:
    """One declared gain: where it is (``shared`` or the law's table), which components, its box."""

    name: str                   # as declared, e.g. "K_I[0:2]" or "controller.lowpass_cutoff_hz"
    key: str                    # the setting's key
    shared: bool                # True: a [controller] key, False: the law's [controller.<id>] key
    components: Optional[tuple[int, ...]]   # of a tuple-valued setting; None: a scalar
    low: float
    high: float
    log_scale: bool

    def value(self, u: float) -> float:
        """The gain at ``u`` in [0, 1] of the box (log coordinates if ``log_scale``)."""
        if self.log_scale:
            return float(self.low * (self.high / self.low) ** u)
        return float(self.low + u * (self.high - self.low))

    def unit(self, value: float) -> float:
        """Where ``value`` lies in the box, 0 at ``low`` and 1 at ``high`` (log coordinates if ``log_scale``)."""
        if self.log_scale:
            return float(math.log(value / self.low) / math.log(self.high / self.low))
        return float((value - self.low) / (self.high - self.low))


def box_edge(value: float, low: float, high: float, log_scale: bool) -> Optional[str]:
    """``"bottom"`` or ``"top"`` if ``value`` lies within :data:`EDGE_FRACTION` of that end of the box
    ``[low, high]`` (log coordinates if ``log_scale``), else None."""
    u = Tunable("", "", False, None, float(low), float(high), bool(log_scale)).unit(float(value))
    return "bottom" if u <= EDGE_FRACTION else "top" if u >= 1.0 - EDGE_FRACTION else None


def tunables(cid: str) -> tuple[Tunable, ...]:
    """The gains ``vtoladapt tune`` searches for law ``cid``: the shared gains
    (:data:`vtoladapt.control.settings.TUNABLE`, named ``controller.<key>``), then the law's own
    (its module's ``TUNABLE``), each checked against its setting.

    Raises ``ValueError`` naming the declaration and the entry if a name is not a setting of the law
    (or of ``[controller]``), a component is out of range, the box is empty, a log box does not
    start above 0, the box leaves the setting's allowed range, or a law declares a shared gain again.
    """
    from ..control import settings as shared_module
    from ..control.settings import ControllerConfig
    from ..control.registry import CONTROLLERS

    info = CONTROLLERS[cid]
    declared = [(f"{shared_module.__name__}.TUNABLE", (f"controller.{e[0]}", *e[1:]) if len(e) == 4 else e)
                for e in shared_module.TUNABLE]
    declared += [(f"{info.law.__name__}.TUNABLE", e) for e in getattr(info.law, "TUNABLE", ())]
    out = []
    for source, entry in declared:
        where = f"{source} {entry!r}"
        if len(entry) != 4:
            raise ValueError(f"{where}: must be (setting, low, high, log_scale)")
        name, low, high, log_scale = entry
        m = _NAME.match(str(name))
        if m is None:
            raise ValueError(f"{where}: '{name}' is not a setting name, name[i] or name[i:j]")
        shared, key = m.group(1) is not None, m.group(2)
        cls = ControllerConfig if shared else info.settings
        # [controller]'s own keys (its law tables are not among them)
        fields = {f.name: f for f in dataclasses.fields(cls) if not (shared and f.name == "laws")}
        if key not in fields:
            raise ValueError(f"{where}: {'[controller]' if shared else f'[controller.{cid}]'} has no key '{key}'")
        default = getattr(cls(), key)
        components = None
        if m.group(3) is not None:
            i0 = int(m.group(3))
            i1 = int(m.group(4)) if m.group(4) is not None else i0 + 1
            if not isinstance(default, tuple) or not 0 <= i0 < i1 <= len(default):
                raise ValueError(f"{where}: components [{i0}:{i1}] of '{key}' (a {type(default).__name__})")
            components = tuple(range(i0, i1))
        elif isinstance(default, tuple):
            raise ValueError(f"{where}: '{key}' is a tuple: name its components, e.g. '{key}[0:2]'")
        for t in out:
            if t.shared == shared and t.key == key and (
                    components is None or t.components is None or set(components) & set(t.components)):
                raise ValueError(f"{where}: '{key}' is already searched by '{t.name}' (the shared gains are "
                                 f"{shared_module.__name__}.TUNABLE); declare each gain once")
        low, high = float(low), float(high)
        if not (math.isfinite(low) and math.isfinite(high) and low < high) or (log_scale and low <= 0.0):
            raise ValueError(f"{where}: box [{low}, {high}] must be finite and non-empty, above 0 if log-scaled")
        meta = fields[key].metadata
        for bound, ok in ((meta.get("gt"), lambda b: low > b), (meta.get("ge"), lambda b: low >= b),
                          (meta.get("lt"), lambda b: high < b), (meta.get("le"), lambda b: high <= b)):
            if bound is not None and not ok(bound):
                raise ValueError(f"{where}: box [{low}, {high}] leaves the setting's allowed range")
        out.append(Tunable(str(name), key, shared, components, low, high, bool(log_scale)))
    return tuple(out)


def with_gains(config, cid: str, values: dict[str, float]):
    """``config`` (a ControllerConfig) flying ``cid`` with the declared gains ``values`` (name -> value).

    Validated as any ControllerConfig (a combination a law's own rules refuse raises ``ConfigError``).
    """
    specs = {t.name: t for t in tunables(cid)}
    shared: dict = {}
    law: dict = {}
    for name, v in values.items():
        t = specs[name]
        target = shared if t.shared else law
        source = config if t.shared else getattr(config, cid)
        if t.components is None:
            target[t.key] = float(v)
        else:
            current = list(target.get(t.key, getattr(source, t.key)))
            for i in t.components:
                current[i] = float(v)
            target[t.key] = tuple(current)
    return replace(config, kind=cid, **shared, **{cid: replace(getattr(config, cid), **law)})


def settings_of(config, cid: str) -> dict:
    """The values of the declared gains in ``config`` (name -> value; a component group by its first)."""
    out = {}
    for t in tunables(cid):
        v = getattr(config if t.shared else getattr(config, cid), t.key)
        out[t.name] = float(v if t.components is None else v[t.components[0]])
    return out


def tuning_seeds(seed: int, draws: int) -> list[int]:
    """The ``draws`` tuning seeds of a scenario seed; ``ValueError`` if one is also an evaluation variant's."""
    from .distribution import variant_seeds

    seeds = [int(s) for s in np.random.SeedSequence([int(seed), TUNING_STREAM]).generate_state(draws)]
    clash = set(seeds) & set(variant_seeds(seed, 10000))
    if clash:
        raise ValueError(f"tuning seeds {sorted(clash)} are also evaluation variants' seeds")
    return seeds


def objective(scenario: Scenario, config, seeds: Sequence[int], progress: Optional[Callable[[float], None]] = None
              ) -> tuple[float, list[float]]:
    """``(mean, per draw)`` of the RMS velocity error of ``config`` flying ``scenario`` at each seed (m/s)."""
    from ..sim.run_metrics import run_metrics
    from ..sim.driver import simulate
    from .distribution import _pool_map
    from .metrics import fan_throttle_series

    def fly(seed: int) -> float:
        # measured with the scenario's Lambda_p whatever position gain the law flies: one yardstick
        res = simulate(replace(scenario, seed=seed, controller=config)).measured_with(scenario.controller.Lambda_p)
        if progress is not None:
            progress(scenario.duration_s)
        if res.diverged:
            return DIVERGED_PENALTY_MPS
        value = run_metrics(res, fan_throttle_series(scenario, res.time_s))[OBJECTIVE]
        return value if math.isfinite(value) else DIVERGED_PENALTY_MPS

    per_draw = _pool_map(fly, list(seeds))
    return float(np.mean(per_draw)), [float(x) for x in per_draw]


def tune(scenario: Scenario, cid: str, evaluations: int = EVALUATIONS, draws: int = DRAWS,
         progress: Optional[Callable[[float], None]] = None) -> dict:
    """Search law ``cid``'s declared gains on ``scenario`` (module notes); the record of the search.

    Returns ``{scenario, controller, objective, optimiser, budget, seed_stream, tuning_seeds,
    tunables, default, tuned, trace}``; ``default`` and ``tuned`` hold ``settings`` (name -> value)
    and the ``objective`` (m/s) on the tuning draws.
    """
    from scipy.optimize import direct

    if evaluations < 1 or draws < 1:
        raise ValueError(f"evaluations = {evaluations}, draws = {draws}: each must be >= 1")
    specs = tunables(cid)
    seeds = tuning_seeds(scenario.seed, draws)
    base = replace(scenario.controller, kind=cid)
    vehicle = scenario.load_vehicle()
    trace: list[dict] = []

    def record(values: dict) -> float:
        try:
            config = with_gains(base, cid, values)
            # the rules that need the vehicle too (sigma max eig(P0) dt < 1 with a scaled P0), before any flight
            config.to_kernel(vehicle)
        except ConfigError as exc:     # a combination the law's own rules refuse: no flight
            trace.append({"settings": values, "objective": math.inf, "refused": str(exc)})
            return math.inf
        mean, per_draw = objective(scenario, config, seeds, progress)
        trace.append({"settings": values, "objective": mean, "per_draw": per_draw})
        return mean

    record(settings_of(base, cid))
    if specs and evaluations > 1:
        def f(u: np.ndarray) -> float:
            if len(trace) >= evaluations:      # the budget is spent: DIRECT's last calls fly nothing
                return 1e9
            return record({t.name: t.value(float(x)) for t, x in zip(specs, u)})

        direct(f, [(0.0, 1.0)] * len(specs), maxfun=evaluations - 1, locally_biased=True)
    best = min(range(len(trace)), key=lambda i: trace[i]["objective"])
    return {
        "scenario": scenario.name, "controller": cid, "objective": OBJECTIVE,
        "objective_description": "mean over the tuning draws of the run's RMS velocity error (m/s); "
                                 f"a diverged draw counts {DIVERGED_PENALTY_MPS:g} m/s",
        "optimiser": OPTIMISER if specs else "none (no tunable gains)",
        "budget": {"evaluations": len(trace), "evaluations_allowed": evaluations, "draws": draws,
                   "simulated_s": sum(draws * scenario.duration_s for e in trace if "per_draw" in e)},
        "seed_stream": TUNING_STREAM, "tuning_seeds": seeds,
        "tunables": [{"name": t.name, "low": t.low, "high": t.high, "log_scale": t.log_scale} for t in specs],
        "default": {"settings": trace[0]["settings"], "objective": trace[0]["objective"]},
        "tuned": {"settings": trace[best]["settings"], "objective": trace[best]["objective"],
                  "evaluation": best + 1},
        "trace": trace,
    }


# --- the tuned settings file ------------------------------------------------------------------------
def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf" if v < 0 else "nan")
    return repr(v)


def tuned_file_text(record: dict, scenario: Scenario) -> str:
    """The tuned settings file of a :func:`tune` record (TOML; see the module notes)."""
    from ..control.registry import CONTROLLERS

    cid = record["controller"]
    config = with_gains(replace(scenario.controller, kind=cid), cid, record["tuned"]["settings"])
    shared, law = {}, {}                 # key -> line: a tuple gain tuned in groups is one key
    for t in tunables(cid):
        v = getattr(config if t.shared else getattr(config, cid), t.key)
        (shared if t.shared else law)[t.key] = f"{t.key} = {_toml_value(v)}"
    b = record["budget"]
    lines = [
        f"# {CONTROLLERS[cid].label} tuned on scenario {record['scenario']} by `vtoladapt tune` "
        f"({record['optimiser']}).",
        f"# Objective: {record['objective_description']}.",
        f"# Budget: {b['evaluations']} evaluations x {b['draws']} tuning draws (the first the defaults); tuning "
        f"seeds from SeedSequence([seed, {TUNING_STREAM:#x}]), disjoint from the evaluation variants.",
        f"# Defaults {record['default']['objective']:.5g} m/s, tuned {record['tuned']['objective']:.5g} m/s "
        "on the tuning draws.",
        "# Load: vtoladapt.control.load_controller_config(path), or `vtoladapt run SCENARIO --tuned path`.",
        f"dt_control_s = {_toml_value(scenario.dt_control_s)}",
        "",
        "[controller]",
        f"kind = {_toml_value(cid)}",
        *shared.values(),
        "",
        f"[controller.{cid}]",
        *law.values(),
        "",
        "[tuning]",
        f"scenario = {_toml_value(record['scenario'])}",
        f"objective = {_toml_value(record['objective'])}",
        f"optimiser = {_toml_value(record['optimiser'])}",
        f"evaluations = {b['evaluations']}",
        f"draws = {b['draws']}",
        f"seed_stream = {TUNING_STREAM}",
        f"tuning_seeds = {_toml_value(record['tuning_seeds'])}",
        f"default_objective_mps = {_toml_value(record['default']['objective'])}",
        f"tuned_objective_mps = {_toml_value(record['tuned']['objective'])}",
        f"tuned_evaluation = {record['tuned']['evaluation']}",
    ]
    for name in ("default", "tuned"):
        lines += ["", f"[tuning.{name}]"] + [f"{json.dumps(k)} = {_toml_value(v)}"
                                             for k, v in record[name]["settings"].items()]
    # the box each gain was searched in: [low, high, "log" or "linear"]
    lines += ["", "[tuning.box]"] + [
        f"{json.dumps(t['name'])} = {_toml_value([t['low'], t['high'], 'log' if t['log_scale'] else 'linear'])}"
        for t in record.get("tunables", [])]
    return "\n".join(lines) + "\n"


def tuned_file_name(scenario_name: str, cid: str) -> str:
    """The tuned settings file's name for law ``cid`` on a scenario: ``<scenario>_<id>.toml``."""
    return f"{scenario_name}_{cid}.toml"


def shipped_tuned_file(scenario_name: str, cid: str) -> Path:
    """Where the shipped tuned settings of ``cid`` on a shipped scenario are (``scenarios/tuned/``)."""
    return TUNED_DIR / tuned_file_name(scenario_name, cid)


def read_tuned_file(path) -> tuple[str, dict, dict, dict]:
    """``(kind, shared keys, law keys, tuning record)`` of a tuned settings file, validated as a
    controller settings file (:func:`vtoladapt.control.load_controller_config`); ``ConfigError``
    naming the file otherwise."""
    from ..config import read_toml
    from ..control.settings import load_controller_config

    from ..file_kinds import check_file_kind

    check_file_kind(path, read_toml(path), "tuned settings", "--tuned")
    load_controller_config(path)                 # the file itself is a valid controller config
    data = read_toml(path)
    table = dict(data.get("controller", {}))
    kind = table.pop("kind", None)
    if kind is None:
        raise ConfigError(f"{path}: [controller] kind: missing; a tuned settings file names its law")
    law = dict(table.pop(kind, {}) or {})
    table.pop("loop_rate_hz", None)
    for other in [k for k, v in table.items() if isinstance(v, dict)]:
        table.pop(other)
    return kind, table, law, dict(data.get("tuning", {}))


def tuned_controller(config, path):
    """``config`` (a scenario's ControllerConfig) flying the law of the tuned file ``path`` with its
    gains: its ``kind``, the shared keys it sets and its law table replace the scenario's, every other
    setting stays. ``ConfigError`` naming the file if it is not a tuned settings file."""
    from ..control.settings import controller_config_from_mapping

    kind, shared, law, _ = read_tuned_file(path)
    # validated as a table of the file (the messages name it); its values as the settings hold them
    built = controller_config_from_mapping({"kind": kind, **shared, kind: law}, source=str(path))
    own = getattr(built, kind)
    return replace(config, kind=kind, **{k: getattr(built, k) for k in shared},
                   **{kind: replace(getattr(config, kind), **{k: getattr(own, k) for k in law})})


# --- the command line: vtoladapt tune ---------------------------------------------------------------
def register_cli(sub) -> None:
    """``vtoladapt tune SCENARIO --controller ID [--controller ID ...] --out DIR``."""
    from ..outputs import add_force_argument, output_path

    p = sub.add_parser("tune", help="tune a law's declared gains on a scenario (one budget for every law)",
                       description="Search the gains a law declares (its module's TUNABLE) with DIRECT-L on "
                                   "tuning draws of the scenario, disjoint from the evaluation variants, and "
                                   "write the tuned settings file <scenario>_<id>.toml and the search's record "
                                   "<scenario>_<id>.json into --out.")
    p.add_argument("scenario", help="scenario TOML (or the name of a shipped scenario)")
    p.add_argument("--controller", action="append", required=True, metavar="ID",
                   help="a law of vtoladapt.control.registry (repeat for several), or 'all'")
    p.add_argument("--out", required=True, type=output_path, help="output directory")
    p.add_argument("--evaluations", type=int, default=EVALUATIONS,
                   help=f"evaluations of the objective per law, the defaults' included (default {EVALUATIONS})")
    p.add_argument("--draws", type=int, default=DRAWS, help=f"tuning draws per evaluation (default {DRAWS})")
    p.add_argument("--plugin", action="append", default=None, metavar="MODULE|FILE.py",
                   help="import a module of your own first, registering its laws (repeatable; vtoladapt.plugins)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_force_argument(p)
    p.set_defaults(handler=_cmd_tune)


def _cmd_tune(args) -> int:
    from dataclasses import replace as _replace

    from ..config import check_flag
    from ..control.registry import controller_ids
    from ..errors import ExitCode
    from ..sim.limits import check_run_size
    from ..outputs import OutputDir, write_json, write_text
    from ..plugins import load_plugins
    from ..sim.scenario import load_scenario

    load_plugins(args.plugin)  # before the ids are checked: a plug-in's law is one of them
    known = controller_ids()
    ids = list(known) if "all" in args.controller else list(dict.fromkeys(args.controller))
    for cid in ids:
        if cid not in known:
            raise ConfigError(f"--controller {cid!r}: allowed: {', '.join(known)} or all")
    evaluations = check_flag("--evaluations", args.evaluations, ge=1, le=10000, integer=True)
    draws = check_flag("--draws", args.draws, ge=1, le=1000, integer=True)
    scenario = load_scenario(args.scenario)
    scenario = _replace(scenario, experiment=_replace(scenario.experiment, kind="single"))
    check_run_size(scenario, f"{scenario.source_path}")
    for cid in ids:
        with_gains(_replace(scenario.controller, kind=cid), cid, {})   # the scenario's settings fly this law
    target = OutputDir(args.out, "tune", force=args.force)
    with target:
        for cid in ids:
            bar, add = _progress(evaluations * draws * scenario.duration_s, not args.quiet, f"tune {cid}")
            try:
                record = tune(scenario, cid, evaluations, draws, add)
            finally:
                if bar is not None:
                    bar.close()
            write_text(target.path / tuned_file_name(scenario.name, cid), tuned_file_text(record, scenario))
            write_json(target.path / f"{scenario.name}_{cid}.json", record)
            if not args.quiet:
                print(f"{cid}: {record['default']['objective']:.5g} -> {record['tuned']['objective']:.5g} m/s "
                      f"on {draws} tuning draws ({record['budget']['evaluations']} evaluations): "
                      f"{record['tuned']['settings']}", file=sys.stderr)
    return ExitCode.OK


def _progress(total_s: float, show: bool, desc: str):
    """``(bar or None, add(sim_s))``: a progress bar over simulated seconds, ``add`` safe from threads."""
    import threading

    from ..progress import progress_bar

    bar = progress_bar(total=round(total_s, 1), unit="sim s", desc=desc) if show else None
    lock = threading.Lock()

    def add(sim_s: float) -> None:
        if bar is not None:
            with lock:
                bar.update(round(min(sim_s, bar.total - bar.n), 3))
    return bar, add


# --- default against tuned, on the evaluation variants ---------------------------------------------
def tuned_comparison(scenario: Scenario, n: int, default: dict, progress: Optional[Callable[[float], None]] = None,
                     tuned_dir: Optional[Path] = None) -> dict:
    """Every law of the comparison with its shipped tuned settings over the ``n`` evaluation variants.

    ``default`` is the comparison's own distribution over the same variants
    (:func:`vtoladapt.experiments.distribution.comparison_distribution`, with ``per_variant``). A law
    whose tuned settings are its defaults (nothing to tune, or the search kept them) is not flown
    again. Returns ``{variants, seeds, settings: {id: {default, tuned}}, tuning: {id: the file's
    [tuning] record}, controllers (median and IQR), per_variant, paired (the tuned laws against each
    other), vs_default: {id: {metric: paired difference tuned - default}}, claims}``; ``claims``: the
    paper's three tracking claims (:data:`TRACKING_CLAIMS`) judged in each variant with every law's
    tuned settings, as :func:`~vtoladapt.experiments.distribution.summarize_claims` reports them
    (the prediction-error claim needs each run's airspeed bins, which are not kept).
    """
    from .claims import check_claims
    from .distribution import (PAIRED_METRICS, fly_variants, per_variant_values, summarize_claims,
                               summarize_controllers, variant_seeds)
    from .pairs import compare_laws, paired_difference

    ids = list(scenario.experiment.controllers)
    configs, settings, records = {}, {}, {}
    for cid in ids:
        path = (Path(tuned_dir) if tuned_dir is not None else TUNED_DIR) / tuned_file_name(scenario.name, cid)
        base = replace(scenario.controller, kind=cid)
        config = tuned_controller(base, path)
        _, _, _, records[cid] = read_tuned_file(path)
        # a gain declared after the file was searched (NOT_IN_SHIPPED_FILES) flies its default: not reported as tuned
        unsearched = set(NOT_IN_SHIPPED_FILES) - set(records[cid].get("box", {}))
        settings[cid] = {k: {n: v for n, v in settings_of(c, cid).items() if n not in unsearched}
                         for k, c in (("default", base), ("tuned", config))}
        if config != base:
            configs[cid] = config
    flown = per_variant_values(fly_variants(scenario, n, progress, configs)) if configs else {}
    per_variant = {cid: flown.get(cid, default["per_variant"][cid]) for cid in ids}
    summary = summarize_controllers([{"controllers": {cid: {k: per_variant[cid][k][i] for k in per_variant[cid]}
                                                      for cid in ids}} for i in range(n)])
    vs_default = {cid: {m: paired_difference(_nan(per_variant[cid][m]), _nan(default["per_variant"][cid][m]))
                        for m in PAIRED_METRICS if m in per_variant[cid] and m in default["per_variant"][cid]}
                  for cid in ids}
    judged = []
    for i in range(n):
        runs = {cid: {k: v[i] for k, v in per_variant[cid].items() if v[i] is not None} for cid in ids}
        try:
            claims = check_claims({"scenario": scenario.name, "controllers": runs}, None)
        except KeyError:            # a law without a finite value this variant judges nothing there
            continue
        judged.append({"claims": {k: c for k, c in claims.items() if k in TRACKING_CLAIMS}})
    return {"variants": n, "seeds": variant_seeds(scenario.seed, n), "settings": settings, "tuning": records,
            "flown": sorted(configs), "controllers": summary, "per_variant": per_variant,
            "paired": compare_laws(per_variant, PAIRED_METRICS, ids), "vs_default": vs_default,
            "claims": summarize_claims(judged)}


def _nan(values: Sequence) -> list[float]:
    return [math.nan if v is None else float(v) for v in values]


__all__ = ["DIVERGED_PENALTY_MPS", "DRAWS", "EDGE_FRACTION", "EVALUATIONS", "OBJECTIVE", "OPTIMISER", "TUNED_DIR", "TUNING_STREAM",
           "TRACKING_CLAIMS", "Tunable", "box_edge", "objective", "read_tuned_file", "settings_of", "shipped_tuned_file", "tune",
           "tuned_comparison", "tuned_controller", "tuned_file_name", "tuned_file_text", "tuning_seeds", "tunables", "with_gains"]
