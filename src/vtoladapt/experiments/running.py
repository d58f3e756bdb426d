"""Running the experiments: one scenario (``vtoladapt run``) or both of the paper's
(``vtoladapt reproduce``), with a progress bar, writing logs, metrics.json, figures and the report.
"""
from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Optional


from ..sim.run_metrics import run_metrics
from ..sim.monitor import DivergenceError
from ..sim.results import SimulationResult
from ..sim.scenario import SCENARIO_DIR, Scenario, load_scenario
from .claims import check_claims
from .figures import (CONTROLLER_LABELS, figure_parameter_convergence, figure_single_run,
                      figure_tracking_axes, figure_tracking_comparison)
from .metrics import comparison_metrics, convergence_metrics, fan_throttle_series
from .report import (FigureRef, _copy_file, _write_json, build_report, display_path, display_paths_in,
                     write_report)

FIGURE_CAPTIONS = {
    "fig_run.png": "Airspeed, velocity error, θ̂ and prediction error of the run",
    "fig_tracking_comparison.png": "Measured airspeed, velocity-error norm and prediction-error norm "
                                   "of every controller",
    "fig_tracking_axes.png": "Velocity error per NED axis and prediction error per body axis",
    "fig_parameter_convergence.png": "θ̂ of every random-start run over time, with the fan wind",
}
EXPERIMENT_WORDS = {"single": "one run", "comparison": "controller comparison",
                    "convergence": "parameter convergence"}


# --- progress ------------------------------------------------------------------------------------
class _Progress:
    """A tqdm bar over simulated seconds of all runs, or nothing when quiet.

    The bar is first drawn after ``DELAY_S`` (tqdm's ``delay``), so a stage renamed by :meth:`set`
    before its first step, or one that ends before then, leaves no 0 % bar behind; :meth:`set`
    replaces the label as given (tqdm's ``set_description`` would append a second ``": "`` to the
    one the bar's format already writes: "comparison of 8 controllers: :")."""

    DELAY_S = 0.5

    def __init__(self, total_s: float, show: bool, desc: str):
        self.bar = None
        if show:
            from ..progress import progress_bar

            self.bar = progress_bar(total=round(total_s, 1), unit="sim s", desc=desc, delay=self.DELAY_S,
                                    bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} "
                                               "sim s [{elapsed}<{remaining}]")
        self.done = 0.0

    def callback(self):
        start = self.done

        def cb(sim_s, _total):
            if self.bar is not None:
                self.bar.update(round(start + sim_s - self.bar.n, 3))
        return cb

    def finish_run(self, duration_s: float):
        self.done += duration_s

    def adder(self):
        """A thread-safe ``add(sim_s)`` for runs reported one whole run at a time."""
        import threading

        lock = threading.Lock()

        def add(sim_s: float) -> None:
            with lock:
                self.done += sim_s
                if self.bar is not None:  # rounding must not carry the bar past its total
                    self.bar.update(round(min(self.done, self.bar.total) - self.bar.n, 3))
        return add

    def set(self, desc: str):
        if self.bar is not None:
            self.bar.set_description_str(desc, refresh=False)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _note(msg: str, show: bool) -> None:
    if show:
        print(msg, file=sys.stderr, flush=True)


def _warm_up(scenario: Scenario, show: bool) -> None:
    """Compile (or load from the on-disk cache) the kernels, telling the user."""
    from ..sim.driver import load_kernels

    t0 = time.perf_counter()
    _note("Loading compiled kernels (the first run on a machine compiles them: about 90 s on 2 idle "
          "cores, longer on a busy machine)...", show)
    load_kernels(replace(scenario, experiment=replace(scenario.experiment, kind="single")))
    _note(f"  kernels ready in {time.perf_counter() - t0:.1f} s", show)


# --- running ---------------------------------------------------------------------------------------
def run_comparison(scenario: Scenario, progress: Optional[_Progress] = None,
                   out: Optional[Path] = None) -> dict[str, SimulationResult]:
    """The same scenario flown by each controller of ``[experiment] controllers`` (runs in parallel);
    with ``out``, each log is streamed to its file there (:func:`log_names`) and read back by column."""
    ids = scenario.experiment.controllers
    runs = [replace(scenario, controller=replace(scenario.controller, kind=cid)) for cid in ids]
    logs = [out / name for name in log_names(scenario)] if out is not None else None
    return dict(zip(ids, _run_all(runs, progress, f"comparison of {len(ids)} controllers", logs)))


def run_convergence(scenario: Scenario, progress: Optional[_Progress] = None,
                    out: Optional[Path] = None) -> list[SimulationResult]:
    """``[experiment] runs`` runs from random initial theta-hat, seeds spawned from the scenario seed;
    with ``out``, each log is streamed to its file there (:func:`log_names`)."""
    from .distribution import convergence_runs

    runs = convergence_runs(scenario)
    logs = [out / name for name in log_names(scenario)] if out is not None else None
    return _run_all(runs, progress, f"convergence: {len(runs)} runs", logs)


def _run_all(runs: list[Scenario], progress: Optional[_Progress], desc: str,
             logs: Optional[list[Path]] = None) -> list[SimulationResult]:
    """Every run side by side, one thread per core (bit-identical to running them one by one): in
    memory, or each streamed to its log file in ``logs`` (:func:`vtoladapt.sim.longrun.stream_many`)."""
    from ..sim.driver import simulate_many
    from ..sim.longrun import stream_many

    if progress is not None:
        progress.set(desc)
    callback = progress.callback() if progress else None
    if logs is None:
        results = simulate_many(runs, progress=callback)
    else:
        results = stream_many(list(zip(runs, logs)), progress=callback)
    if progress is not None:
        progress.finish_run(sum(sc.duration_s for sc in runs))
    return results


def _scenario_notes(scenario: Scenario, result: SimulationResult, out: Path) -> list[str]:
    meta = result.metadata
    notes = [f"Scenario `{scenario.name}` (`{display_path(scenario.source_path, out)}`), "
             f"{scenario.duration_s:g} s, seed {scenario.seed}"
             + (f": {scenario.description}" if scenario.description else ".")]
    notes.append(f"Vehicle `{meta['vehicle']}`; controller model from "
                 f"{display_paths_in(str(meta['controller_prior']), out)}; airflow probe: "
                 f"{display_paths_in(str(meta['probe_model']), out)}.")
    return notes


def _experiment_title(scenario: Scenario) -> str:
    kind = scenario.experiment.kind
    if kind == "single":
        what = f"one run with {CONTROLLER_LABELS.get(scenario.controller.kind, scenario.controller.kind)}"
    elif kind == "comparison":
        what = f"comparison of {len(scenario.experiment.controllers)} controllers"
    else:
        what = f"parameter convergence over {scenario.experiment.runs} runs"
    return f"vtoladapt: scenario {scenario.name}, {what}"


FIGURES = {"single": ("fig_run.png",), "comparison": ("fig_tracking_comparison.png", "fig_tracking_axes.png"),
           "convergence": ("fig_parameter_convergence.png",)}
"""The figures :func:`run_experiment` writes, per experiment kind."""


def log_names(scenario: Scenario) -> list[str]:
    """The logs :func:`run_experiment` writes, relative to its folder, in the order of its runs."""
    kind = scenario.experiment.kind
    if kind == "single":
        return ["log.parquet"]
    if kind == "comparison":
        return [f"runs/{scenario.name}_{cid}.parquet" for cid in scenario.experiment.controllers]
    return [f"runs/{scenario.name}_run{i + 1}.parquet" for i in range(scenario.experiment.runs)]


def planned_outputs(scenario: Scenario) -> list[str]:
    """Every file :func:`run_experiment` writes for ``scenario`` (relative to its folder), so
    ``--out`` is checked for a name taken by someone else's file before anything is written."""
    return log_names(scenario) + list(FIGURES[scenario.experiment.kind]) + ["metrics.json", "report.md",
                                                                             "report.html"]


def run_experiment(scenario: Scenario, out: Path, show_progress: bool = True, warm: bool = True,
                   variants: Optional[int] = None) -> dict:
    """Run one scenario per its ``[experiment]`` kind; write logs, figures, metrics.json, report.

    A comparison or convergence experiment is also flown over ``variants`` seeded variants
    (default ``[experiment] variants``; 1: none): ``metrics["distribution"][kind]``
    (:mod:`vtoladapt.experiments.distribution`)."""
    from ..sim.longrun import stream_to_parquet

    out.mkdir(parents=True, exist_ok=True)
    if warm:
        _warm_up(scenario, show_progress)
    kind = scenario.experiment.kind
    n_runs = {"single": 1, "convergence": scenario.experiment.runs,
              "comparison": len(scenario.experiment.controllers)}[kind]
    progress = _Progress(n_runs * scenario.duration_s, show_progress, scenario.name)
    metrics: dict = {}
    figures: list[Path] = []
    try:
        if kind == "single":
            # every log is streamed to its file in row groups and read back by column: memory holds what
            # the metrics and figures use, whatever the duration (vtoladapt.sim.limits.check_run_size)
            res = stream_to_parquet(scenario, out / log_names(scenario)[0], progress.callback())
            metrics["run"] = run_metrics(res, fan_throttle_series(scenario, res.time_s))
            figures.append(figure_single_run(scenario, res, out / FIGURES[kind][0]))
            notes = _scenario_notes(scenario, res, out)
            notes.append("The full log is `log.parquet` (one column per signal, units in the names).")
        elif kind == "comparison":
            results = run_comparison(scenario, progress, out)
            metrics["comparison"] = comparison_metrics(scenario, results)
            figures.append(figure_tracking_comparison(scenario, results, out / FIGURES[kind][0]))
            figures.append(figure_tracking_axes(scenario, results, out / FIGURES[kind][1]))
            notes = _scenario_notes(scenario, next(iter(results.values())), out)
            notes.append("The log of each controller's run is in `runs/`.")
        else:
            results = run_convergence(scenario, progress, out)
            metrics["convergence"] = convergence_metrics(scenario, results)
            figures.append(figure_parameter_convergence(scenario, results, out / FIGURES[kind][0]))
            notes = _scenario_notes(scenario, results[0], out)
            notes.append("The log of each run is in `runs/`.")
    finally:
        progress.close()
    if scenario.output.thinned:
        notes[-1] = _thin_logs(scenario, out)
    metrics["claims"] = check_claims(metrics.get("comparison"), metrics.get("convergence"))
    n_variants = scenario.experiment.variants if variants is None else variants
    if kind != "single" and n_variants > 1:
        metrics["distribution"] = {kind: run_distribution(scenario, n_variants, show_progress)}
        notes.append(f"Distribution: the experiment flown over {n_variants} seeded variants (own seed, "
                     "plant draw, turbulence and sensor noise each).")
    runs = ({"": res} if kind == "single" else results if kind == "comparison"
            else {f"run{i + 1}": r for i, r in enumerate(results)})
    diverged = {name: r for name, r in runs.items() if r.diverged}
    # every run that left its envelope, with when and why; its log is kept up to that point
    metrics["divergence"] = [{"run": name or scenario.name, "diverged_at_s": r.diverged_at_s,
                              "reason": r.divergence_reason} for name, r in diverged.items()]
    # said at the top of the report, not only in metrics.json: a diverged run's metrics and figures
    # cover the time before it stopped, not the scenario's duration
    notes[1:1] = [f"Diverged: {'`' + name + '`' if name else 'the run'} left its envelope at "
                  f"t = {r.diverged_at_s:g} s of {scenario.duration_s:g} s ({r.divergence_reason}); "
                  "its log, metrics and figures cover only the time before." for name, r in diverged.items()]
    _write_json(out / "metrics.json", metrics)
    write_report(out, build_report(_experiment_title(scenario), metrics, _figure_refs(figures), notes))
    if diverged:
        name, res = next(iter(diverged.items()))
        count = f" (first of {len(diverged)} diverged runs)" if len(diverged) > 1 else ""
        raise DivergenceError(res, f"{scenario.name}{' ' + name if name else ''}{count}: ")
    return metrics


def _thin_logs(scenario: Scenario, out: Path) -> str:
    """Thin or remove the run's logs per its ``[output]`` table (:func:`vtoladapt.sim.output.thin_log`),
    once the metrics and figures have read every tick from them; the report's note on the logs."""
    from ..sim.output import thin_log

    every = scenario.output.every_ticks(scenario.dt_control_s)
    for name in log_names(scenario):
        thin_log(out / name, every, keep=scenario.output.log)
    if not scenario.output.log:
        return "No log was kept (`[output] log = false`, `--no-log`); the metrics and figures used every tick."
    where = "`log.parquet`" if scenario.experiment.kind == "single" else "`runs/`"
    return (f"The log ({where}) keeps one row every {every} control ticks ({1.0 / (every * scenario.dt_control_s):g} "
            "Hz, `[output] log_rate_hz`); the metrics and figures used every tick.")


def run_distribution(scenario: Scenario, n: int, show_progress: bool = True) -> dict:
    """The experiment of ``scenario`` over ``n`` seeded variants, with a progress bar."""
    from .distribution import comparison_distribution, convergence_distribution

    kind = scenario.experiment.kind
    per = len(scenario.experiment.controllers) if kind == "comparison" else scenario.experiment.runs
    progress = _Progress(n * per * scenario.duration_s, show_progress, f"{scenario.name}: {n} variants")
    try:
        if kind == "comparison":
            return comparison_distribution(scenario, n, progress.adder())
        return convergence_distribution(scenario, n, progress.adder())
    finally:
        progress.close()


def _figure_refs(figures: list[Path]) -> list[FigureRef]:
    return [FigureRef(p.name, FIGURE_CAPTIONS.get(p.name, p.stem)) for p in figures]


ABLATION_VARIANTS = 30
"""Seeded variants per plant configuration of the ablation (every distribution claim: at least 30)."""
WIND_VARIANTS = 30
"""Seeded variants per controller and wind condition of the method x wind table."""


def reproduce(out: Path, duration_scale: float = 1.0, show_progress: bool = True,
              variants: Optional[int] = None, ablation_variants: int = ABLATION_VARIANTS,
              wind_variants: int = WIND_VARIANTS, tuned: bool = True) -> dict:
    """Both paper experiments, one combined metrics.json and report.

    Each experiment is flown once at its scenario seed (the figures) and over seeded variants
    (``variants``, default each scenario's ``[experiment] variants``): ``distribution.<experiment>``,
    the comparison's with every pair of laws compared (``distribution.comparison.paired``). Then
    every law with its shipped tuned settings over the same variants (``tuned``; ``tuned=False``
    skips it), the comparison's claims with each unmodelled effect off (``ablation``, over
    ``ablation_variants``) and the method x wind table (``wind_table``, over ``wind_variants``);
    0 skips either."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    conv = load_scenario(SCENARIO_DIR / "paper_convergence.toml")
    comp = load_scenario(SCENARIO_DIR / "paper_comparison.toml")
    if duration_scale != 1.0:
        if not 0 < duration_scale <= 10:
            raise ValueError(f"duration_scale = {duration_scale}: must be in (0, 10]")
        conv = _scaled(conv, duration_scale)
        comp = _scaled(comp, duration_scale)
    t0 = time.perf_counter()
    _warm_up(comp, show_progress)
    m_conv = run_experiment(conv, out / "convergence", show_progress, warm=False, variants=variants)
    m_comp = run_experiment(comp, out / "comparison", show_progress, warm=False, variants=variants)
    metrics = {"convergence": m_conv["convergence"], "comparison": m_comp["comparison"]}
    metrics["claims"] = check_claims(metrics["comparison"], metrics["convergence"])
    metrics["distribution"] = {**m_conv.get("distribution", {}), **m_comp.get("distribution", {})}
    from .distribution import (ABLATION_EFFECTS, WIND_CONDITIONS, WIND_HOLD_S, ablation, claim_controllers,
                               wind_table)
    from .tuning import tuned_comparison

    default = metrics["distribution"].get("comparison")
    if tuned and default is not None:
        n = default["variants"]
        metrics["tuned"] = _with_progress(
            lambda add: tuned_comparison(comp, n, default, add),
            n * len(comp.experiment.controllers) * comp.duration_s, show_progress, "tuned laws")
    if ablation_variants > 0:
        reused = default is not None and default["variants"] == ablation_variants
        metrics["ablation"] = _with_progress(
            lambda add: ablation(comp, ablation_variants, add, all_on=default),
            (len(ABLATION_EFFECTS) + (0 if reused else 1)) * ablation_variants
            * len(claim_controllers(comp.experiment.controllers)) * comp.duration_s, show_progress, "ablation")
    if wind_variants > 0:
        metrics["wind_table"] = _with_progress(
            lambda add: wind_table(comp, wind_variants, add, duration_scale),
            len(WIND_CONDITIONS) * wind_variants * len(comp.experiment.controllers) * WIND_HOLD_S
            * duration_scale, show_progress, "method x wind")
    metrics["faults"] = _fault_rows(show_progress)
    from .ceiling import bases_metrics

    metrics["bases"] = bases_metrics(out / "comparison", comp)
    figures = []
    for sub, name in (("convergence", "fig_parameter_convergence.png"),
                      ("comparison", "fig_tracking_comparison.png"), ("comparison", "fig_tracking_axes.png")):
        figures.append(_copy_file(out / sub / name, out / name))
    _write_json(out / "metrics.json", metrics)
    from ..sim.driver import controller_prior

    notes = [f"Generated by `vtoladapt reproduce` in {time.perf_counter() - t0:.0f} s "
             f"(duration scale {duration_scale:g}).",
             "The plant's force-model coefficients are drawn from Table I's mean ± std (seeded by each "
             "run's seed); the controllers start from the means. Each experiment is flown once at its "
             "scenario seed (the figures) and over seeded variants (the distribution tables: each "
             "claim's fraction of variants with a 95 % Wilson interval, each metric's median and "
             "interquartile range).",
             f"Convergence: `{display_path(conv.source_path, out)}`, {conv.experiment.runs} runs of "
             f"{conv.duration_s:g} s. Comparison: `{display_path(comp.source_path, out)}`, "
             f"{comp.duration_s:g} s per controller.",
             f"Controller model: {display_paths_in(controller_prior(comp, comp.load_vehicle())[-1], out)}; "
             f"airflow probe: {display_paths_in(comp.sensors.probe.describe(), out)}.",
             "Per-experiment logs (Parquet), figures and metrics are in `convergence/` and `comparison/`."]
    write_report(out, build_report("vtoladapt: reproduction of Shi et al., ICRA 2020, in simulation",
                                   metrics, _figure_refs(figures), notes))
    holds = sum(c["holds"] for c in metrics["claims"].values())
    _note(f"Reproduction done: {holds}/{len(metrics['claims'])} claims hold. "
          f"See {out / 'report.md'} (and report.html).", show_progress)
    for name, c in metrics["claims"].items():
        _note(f"  [{'holds' if c['holds'] else 'FAILS'}] {c['statement']}: {c['value']:.3g} "
              f"(threshold {c['threshold']:g})", show_progress)
    return metrics


def _fault_rows(show_progress: bool) -> list[dict]:
    """Fly the shipped fault scenarios (one fault each, a few seconds in all) and tabulate them."""
    from ..sim.faults import FAULT_KINDS, fault_table
    from ..sim.driver import simulate_many

    scenarios = [load_scenario(SCENARIO_DIR / "faults" / f"{k}.toml") for k in FAULT_KINDS]
    _note(f"Faults: {len(scenarios)} scenarios", show_progress)
    return fault_table(simulate_many(scenarios))


def _with_progress(fn, total_s: float, show: bool, desc: str):
    progress = _Progress(total_s, show, desc)
    try:
        return fn(progress.adder())
    finally:
        progress.close()


def _scaled(scenario: Scenario, scale: float) -> Scenario:
    """The scenario with its duration and wind schedule times scaled (quick looks and tests)."""
    return replace(scenario, duration_s=scenario.duration_s * scale, wind=scenario.wind.time_scaled(scale))
