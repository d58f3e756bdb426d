"""report.md and report.html from the experiments' metrics, and every file the experiments write.

The report is first built as plain data (:class:`Report`: title, paragraphs, tables of words and
numbers, figures); two Jinja2 templates (``templates/report.md.j2``, ``templates/report.html.j2``)
render that same data as Markdown and as a standalone HTML page with the figures inline. Table
headers and row labels come from :data:`vtoladapt.sim.run_metrics.METRIC_INFO` (words with units), and
every path shown is relative to the output folder, so a report says nothing about the machine
that made it.

All output files go through the small ``_write_*`` / ``_save_figure`` helpers at the end of this
module, the one place to change how files are written.
"""
from __future__ import annotations

import base64
import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Optional

from .. import outputs
from ..control.registry import CONTROLLERS
from ..sim.run_metrics import METRIC_INFO, metric_display_value

TEMPLATE_DIR = Path(__file__).with_name("templates")
PACKAGE_DIR = Path(__file__).resolve().parents[1]

COMPARISON_COLUMNS = ("vel_err_rms_mps", "vel_err_max_mps", "vel_err_rms_high_wind_mps",
                      "overshoot_after_fan_off_mps", "pred_err_rms_g", "pred_err_p95_g",
                      "mixer_saturated_fraction")
"""Metrics of the comparison table, in this order (one row each, one column per controller)."""


# --- the report as data ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Cell:
    """One table cell: its text, whether it is a number (right-aligned) and whether it stands out
    (a claim that does not hold)."""

    text: str
    numeric: bool = False
    strong: bool = False


@dataclass(frozen=True)
class Table:
    """A table with a caption (a sentence above it), column headers in words and rows of cells."""

    caption: str
    headers: tuple[str, ...]
    rows: tuple[tuple[Cell, ...], ...]


Paragraph = tuple[tuple[str, bool], ...]
"""A paragraph as segments ``(text, is_code)``: code segments are file names, commands, keys."""


@dataclass(frozen=True)
class Section:
    """A headed part of the report: paragraphs, then tables."""

    heading: str
    paragraphs: tuple[Paragraph, ...] = ()
    tables: tuple[Table, ...] = ()


@dataclass(frozen=True)
class FigureRef:
    """A figure of the report: its file, relative to the output folder, and a caption."""

    file: str
    caption: str


@dataclass(frozen=True)
class Report:
    """Everything report.md and report.html show, in reading order."""

    title: str
    intro: tuple[Paragraph, ...] = ()
    sections: tuple[Section, ...] = ()
    figures: tuple[FigureRef, ...] = field(default_factory=tuple)


def paragraph(text: str) -> Paragraph:
    """A paragraph from text in which `backticks` mark code (the only markup notes use)."""
    parts = text.split("`")
    if len(parts) % 2 == 0:          # a stray backtick (e.g. in a user's description): plain text
        return ((text, False),)
    return tuple((p, i % 2 == 1) for i, p in enumerate(parts) if p)


def fmt_number(x) -> str:
    """Four significant figures; ``n/a`` for NaN or a missing value."""
    if x is None:
        return "n/a"
    if isinstance(x, float):
        return "n/a" if not math.isfinite(x) else f"{x:.4g}"
    return str(x)


def _num(x) -> Cell:
    return Cell(fmt_number(x), numeric=True)


def _unit_text(unit: str) -> str:
    return "–" if unit in ("-", "") else unit


def run_metrics_table(run: dict) -> Table:
    """Every metric of one run: quantity, value, unit (rows in :data:`METRIC_INFO` order)."""
    keys = [k for k in METRIC_INFO if k in run] + [k for k in run if k not in METRIC_INFO]
    rows = []
    for k in keys:
        label, unit = METRIC_INFO.get(k, (k, ""))
        value = run[k]
        if isinstance(value, dict):  # per-bin values: "bin: value" pairs in one cell
            cell = Cell("; ".join(f"{b} {fmt_number(v)}" for b, v in value.items()), numeric=True)
        else:
            cell = _num(metric_display_value(k, value))
        rows.append((Cell(label), cell, Cell(_unit_text(unit))))
    return Table("", ("quantity", "value", "unit"), tuple(rows))


def comparison_table(comparison: dict) -> Table:
    """One row per metric (label and unit in words), one column per controller."""
    ctrl = comparison["controllers"]
    headers = ("quantity", "unit") + tuple(CONTROLLERS[c].label if c in CONTROLLERS else c for c in ctrl)
    rows = []
    for key in COMPARISON_COLUMNS:
        label, unit = METRIC_INFO[key]
        cells = [Cell(label), Cell(_unit_text(unit))]
        for m in ctrl.values():
            cells.append(_num(metric_display_value(key, m[key])) if key in m else Cell("–", numeric=True))
        rows.append(tuple(cells))
    return Table("", headers, tuple(rows))


def convergence_section(conv: dict) -> Section:
    """The spread of theta-hat and of the force it predicts across the random-start runs."""
    from .metrics import THETA_SCALED_UNITS

    text = (f"{conv['runs']} runs from random initial θ̂. The force the runs' θ̂ predict at the final "
            f"operating point spreads {fmt_number(conv['predicted_force_std_start_mps2'])} m/s² across "
            f"runs at the start and {fmt_number(conv['predicted_force_std_end_mps2'])} m/s² at the end "
            f"(ratio {fmt_number(conv['predicted_force_std_ratio'])}).")
    truth = conv.get("theta_true_scaled") or {}
    rows = tuple((Cell(n), Cell(_unit_text(THETA_SCALED_UNITS.get(n, "adaptation units"))),
                  _num(conv["param_std_ratio"][n]), _num(conv["theta_hat_final_mean_scaled"][n]),
                  _num(truth.get(n, float("nan"))))
                 for n in conv["param_std_ratio"])
    table = Table("Spread of each parameter across runs at the end over that at the start; θ̂ in the "
                  "adaptation scaling (throttle u ∈ [0, 1], forces per unit mass):",
                  ("parameter", "unit", "spread at end / at start", "final mean θ̂",
                   "plant's linear part"), rows)
    return Section("Parameter convergence", (paragraph(text),), (table,))


def claims_table(claims: dict) -> Table:
    """Each claim: statement, measured value, threshold, unit and verdict."""
    from .claims import CLAIM_UNITS

    rows = tuple((Cell(claim_label(name, c)), _num(c["value"]), _num(c["threshold"]),
                  Cell(CLAIM_UNITS.get(name, "")), Cell("yes" if c["holds"] else "no", strong=not c["holds"]))
                 for name, c in claims.items())
    return Table("", ("claim", "measured", "threshold", "unit", "holds"), rows)


# --- distributions over seeded variants ------------------------------------------------------------
DISTRIBUTION_COLUMNS = ("vel_err_rms_mps", "vel_err_rms_high_wind_mps", "overshoot_after_fan_off_mps",
                        "pos_err_rms_m", "pred_err_p95_g")
"""Per-controller metrics of the distribution table (median [IQR] over the variants)."""


def fmt_median_iqr(entry: Optional[dict], digits: int = 3) -> str:
    """``"0.0612 [0.0571, 0.0663]"``: median and interquartile range; ``–`` without values."""
    if not entry or entry.get("median") is None:
        return "–"
    q25, q75 = entry["iqr"]
    return f"{entry['median']:.{digits}g} [{q25:.{digits}g}, {q75:.{digits}g}]"


def fmt_fraction(entry: Optional[dict]) -> str:
    """``"0.93 (28/30) [0.79, 0.98]"``: fraction of variants, count, 95 % Wilson interval."""
    if not entry or entry.get("fraction") is None:
        return "–"
    lo, hi = entry["ci95"]
    return f"{entry['fraction']:.2f} ({entry['successes']}/{entry['n']}) [{lo:.2f}, {hi:.2f}]"


def claim_label(name: str, claim: dict) -> str:
    """The claim's statement, marked when the paper does not make it."""
    from .claims import NOT_A_PAPER_CLAIM

    text = claim["statement"]
    if not claim.get("paper_claim", True) and not text.startswith(NOT_A_PAPER_CLAIM):
        text = NOT_A_PAPER_CLAIM + text
    return text


def distribution_claims_table(dist: dict) -> Table:
    """Each claim over the variants: fraction holding with its 95 % Wilson interval, and the
    claim's measured value as median [IQR] against its threshold."""
    from .claims import CLAIM_UNITS

    rows = []
    for name, c in dist["claims"].items():
        strong = c["fraction"] is not None and c["ci95"][1] < 0.5
        rows.append((Cell(claim_label(name, c)), Cell(fmt_fraction(c), numeric=True, strong=strong),
                     Cell(fmt_median_iqr(c["value"]), numeric=True), _num(c["threshold"]),
                     Cell(CLAIM_UNITS.get(name, ""))))
    return Table(f"Over {dist['variants']} seeded variants (seed, plant draw from Table I, turbulence, "
                 "sensor noise): the fraction of variants where each claim holds, (count) and [95 % "
                 "Wilson interval]; the measured value as median [interquartile range]:",
                 ("claim", "holds in", "measured", "threshold", "unit"), tuple(rows))


def distribution_controllers_table(dist: dict) -> Table:
    """One row per controller, median [IQR] over the variants of each metric of
    :data:`DISTRIBUTION_COLUMNS`."""
    headers = ("controller",) + tuple(metric_label_text(k) for k in DISTRIBUTION_COLUMNS)
    rows = []
    for cid, m in dist["controllers"].items():
        label = CONTROLLERS[cid].label if cid in CONTROLLERS else cid
        rows.append((Cell(label),) + tuple(Cell(fmt_median_iqr(m.get(k)), numeric=True)
                                           for k in DISTRIBUTION_COLUMNS))
    return Table(f"Each controller over {dist['variants']} seeded variants: median [interquartile range]:",
                 headers, tuple(rows))


def convergence_distribution_table(dist: dict) -> Table:
    """Per parameter: spread of theta-hat at the end over at the start, median [IQR] over variants."""
    rows = tuple((Cell(p), Cell(fmt_median_iqr(e), numeric=True)) for p, e in dist["param_std_ratio"].items())
    return Table(f"Spread of θ̂ across the runs at the end over at the start, over {dist['variants']} "
                 "seeded variants: median [interquartile range]:", ("parameter", "spread ratio"), rows)


def metric_label_text(key: str) -> str:
    """``"RMS velocity error (m/s)"`` for a table header."""
    label, unit = METRIC_INFO[key]
    return f"{label} ({_unit_text(unit)})"


def ablation_table(ablation: dict) -> Table:
    """Claim x plant configuration: fraction of variants where the claim holds [95 % interval]."""
    from .distribution import ABLATION_EFFECTS

    configs = list(ablation)
    labels = {"all_on": "every effect on"}
    labels.update({f"{k}_off": f"{lab} off" for k, (_f, lab) in ABLATION_EFFECTS.items()})
    names = list(dict.fromkeys(n for cfg in ablation.values() for n in cfg["claims"]))
    rows = []
    for name in names:
        first = next(cfg["claims"][name] for cfg in ablation.values() if name in cfg["claims"])
        cells = [Cell(claim_label(name, first))]
        for cfg in configs:
            c = ablation[cfg]["claims"].get(name)
            cells.append(Cell(fmt_fraction(c), numeric=True))
        rows.append(tuple(cells))
    n = next(iter(ablation.values()))["variants"]
    return Table(f"Ablation: each unmodelled effect of the plant switched off in turn; the fraction of "
                 f"{n} seeded variants where each comparison claim holds (count) [95 % Wilson interval]:",
                 ("claim",) + tuple(labels.get(c, c) for c in configs), tuple(rows))


def wind_table_table(wind: dict) -> Table:
    """Method x wind condition (Neural-Fly's table): mean position error and RMS velocity error,
    medians over the variants."""
    from .distribution import WIND_CONDITIONS

    conds = list(wind["conditions"])
    ids = list(next(iter(wind["conditions"].values())))
    rows = []
    for cid in ids:
        cells = [Cell(CONTROLLERS[cid].label if cid in CONTROLLERS else cid)]
        for cond in conds:
            e = wind["conditions"][cond][cid]
            p, v = e["pos_err_mean_m"]["median"], e["vel_err_rms_mps"]["median"]
            cells.append(Cell("–" if p is None else f"{p:.3f} / {v:.3f}", numeric=True))
        rows.append(tuple(cells))
    return Table(f"Method × wind condition: mean position error (m) / RMS velocity error ‖ṽ‖ (m/s), "
                 f"median over {wind['variants']} seeded variants of a {wind['hold_s']:g} s hold "
                 f"(the first {wind['settle_s']:g} s left out). Gusty: fan 50 % with 1 − cos gusts of "
                 "3 m/s every 3 s:", ("controller",) + tuple(WIND_CONDITIONS.get(c, c) for c in conds),
                 tuple(rows))


def fault_table_table(rows: list) -> Table:
    """The fault scenarios (``scenarios/faults/``): worst position error and whether it recovered."""
    out = []
    for r in rows:
        start, end = r["window_s"]
        sat = r["saturated_during_fault"]
        out.append((Cell(r["faults"].replace("_", " ")), Cell(f"{start:g}-{end:g}", numeric=True),
                    Cell(f"{r['pos_err_before_m']:.2f}", numeric=True),
                    Cell(f"{r['pos_err_worst_m']:.2f}", numeric=True),
                    Cell(f"{r['pos_err_final_m']:.2f}", numeric=True),
                    Cell("–" if sat is None else f"{100 * sat:.0f}", numeric=True),
                    Cell("yes" if r["recovered"] else ("diverged: " + r["diverged"] if r["diverged"] else "no"))))
    return Table("One fault each, in a 40 % fan hold with turbulence (the control-surface faults at 80 %, where "
                 "the surfaces carry moments; scenarios/faults/): worst position error before and from the "
                 "fault on, over the last 2 s, and the share of the fault window with the allocator "
                 "saturated (the limit physics hit). Recovered: final error below 0.3 m.", ("fault", "window (s)", "before (m)", "worst (m)", "final (m)",
                            "mixer saturated (%)", "recovered"), tuple(out))


# --- the paired comparison: ranking, every pair, default against tuned ---------------------------
RANKED_METRICS = ("vel_err_rms_mps", "vel_err_rms_rising_mps", "vel_err_rms_plateau_mps", "vel_err_rms_fan_off_mps",
                  "overshoot_after_fan_off_mps", "pos_err_rms_m", "pred_err_p95_g")
"""The metrics of the ranking and the paired-difference tables, in this order."""

SHORT_LABELS = {
    "vel_err_rms_mps": "RMS ‖ṽ‖ (m/s)",
    "vel_err_rms_rising_mps": "RMS ‖ṽ‖, rising wind (m/s)",
    "vel_err_rms_plateau_mps": "RMS ‖ṽ‖, plateau (m/s)",
    "vel_err_rms_fan_off_mps": "RMS ‖ṽ‖, fan-off transient (m/s)",
    "overshoot_after_fan_off_mps": "peak ‖ṽ‖ after the fan stops (m/s)",
    "pos_err_rms_m": "RMS ‖p̃‖ (m)",
    "pred_err_p95_g": "p95 prediction error (g)",
}
"""Column headers of these tables (the full labels are in :data:`vtoladapt.sim.run_metrics.METRIC_INFO` and
:data:`.metrics.PHASE_METRIC_INFO`)."""


def controller_label(cid: str) -> str:
    """The controller's label in words (its id if it is not registered)."""
    return CONTROLLERS[cid].label if cid in CONTROLLERS else cid


def metric_words(key: str) -> str:
    """The metric's label in words with its unit."""
    from .metrics import PHASE_METRIC_INFO

    text, unit = {**METRIC_INFO, **PHASE_METRIC_INFO}[key]
    return f"{text} ({unit})"


def fmt_difference(r: Optional[dict]) -> tuple[str, bool]:
    """``("-0.0021 [-0.0040, -0.00050]", separated)`` of a paired difference; ``("–", False)`` without one."""
    if not r or r.get("estimate") is None:
        return "–", False
    lo, hi = r["ci95"]
    return f"{r['estimate']:+.2g} [{lo:+.2g}, {hi:+.2g}]", r["verdict"] != "tied"


def ranking_rows(paired: dict, metrics=RANKED_METRICS):
    """``(ids in the order of the first metric's ranking, {metric: {id: entry}})``."""
    ranking = paired["ranking"]
    first = next(m for m in metrics if m in ranking)
    order = [e["id"] for e in ranking[first]]
    by_metric = {m: {e["id"]: e for e in ranking[m]} for m in metrics if m in ranking}
    return order, by_metric


def ranking_table(dist: dict, title: str = "", metrics=RANKED_METRICS):
    """Each law's median of each metric and its rank range (laws whose ranges overlap are tied)."""
    paired = dist["paired"]
    order, by_metric = ranking_rows(paired, metrics)
    cols = [m for m in metrics if m in by_metric]
    rows = []
    for cid in order:
        cells = [Cell(controller_label(cid))]
        for m in cols:
            e = by_metric[m].get(cid)
            if e is None or e["median"] is None:
                cells.append(Cell("–", numeric=True))
                continue
            rank = f"{e['rank_lo']}" if e["rank_lo"] == e["rank_hi"] else f"{e['rank_lo']}–{e['rank_hi']}"
            cells.append(Cell(f"{e['median']:.3g} ({rank})", numeric=True, strong=e["rank_lo"] == 1))
        rows.append(tuple(cells))
    n = dist["variants"]
    caption = (f"{title}Ranking over {n} seeded variants: each law's median and, in brackets, its rank range "
               f"(1 + the laws significantly below it, to {len(order)} − the laws significantly above it; "
               "significant: "
               "the paired signed-rank 95 % interval of the difference excludes 0). Laws whose ranges "
               "overlap are not told apart on that metric; bold: can rank first. Rows in the order of "
               "the first column:")
    return Table(caption, ("controller",) + tuple(SHORT_LABELS[m] for m in cols), tuple(rows))


def paired_table(dist: dict, metrics=RANKED_METRICS, title: str = ""):
    """Every pair of laws: the paired difference (row − column law) of each metric with its 95 % interval."""
    from .pairs import pair_value
    paired = dist["paired"]["pairs"]
    cols = [m for m in metrics if m in paired]
    ids = list(dict.fromkeys(i for m in cols for key in paired[m] for i in key.split("|")))
    rows = []
    for i, a in enumerate(ids):
        for b in ids[i + 1:]:
            cells = [Cell(f"{controller_label(a)} − {controller_label(b)}")]
            for m in cols:
                text, separated = fmt_difference(pair_value(paired[m], a, b))
                cells.append(Cell(text, numeric=True, strong=separated))
            rows.append(tuple(cells))
    caption = (f"{title}Paired differences over {dist['variants']} seeded variants (every law flies every "
               "variant): Hodges–Lehmann estimate of the first law's metric minus the second's, and its "
               "95 % interval from Wilcoxon's signed-rank test (exact; negative: the first law lower). "
               "Bold: the interval excludes 0 (the pair is told apart); otherwise tied:")
    return Table(caption, ("pair",) + tuple(SHORT_LABELS[m] for m in cols), tuple(rows))


def tuned_table(tuned: dict, default: dict):
    """Default against tuned settings for every law on the evaluation variants, with the tuning's record."""
    key = "vel_err_rms_mps"
    rank_default = {e["id"]: e for e in default["paired"]["ranking"].get(key, [])}
    rank_tuned = {e["id"]: e for e in tuned["paired"]["ranking"].get(key, [])}
    rows = []
    for cid in tuned["settings"]:
        rec = tuned["tuning"].get(cid, {})
        obj = (f"{rec['default_objective_mps']:.4g} → {rec['tuned_objective_mps']:.4g}"
               if "default_objective_mps" in rec else "–")
        text, separated = fmt_difference(tuned["vs_default"][cid].get(key))
        rows.append((Cell(controller_label(cid)), Cell(obj, numeric=True),
                     Cell(fmt_median_iqr(default["controllers"][cid].get(key)), numeric=True),
                     Cell(fmt_median_iqr(tuned["controllers"][cid].get(key)), numeric=True),
                     Cell(text, numeric=True, strong=separated),
                     Cell(_rank(rank_default.get(cid)), numeric=True), Cell(_rank(rank_tuned.get(cid)), numeric=True)))
    first = next(iter(tuned["tuning"].values()), {})
    budget = (f"{first.get('evaluations', '?')} evaluations of the objective per law (the first its defaults) × "
              f"{first.get('draws', '?')} tuning draws each") if first else "the shipped budget"
    caption = (f"Default against tuned settings, RMS ‖ṽ‖ (m/s). Each law's gains, the shared loop gains and "
               f"its own, were searched by DIRECT-L with one budget for every law: {budget}, the tuning "
               f"draws' seeds from their own stream (SeedSequence([seed, {first.get('seed_stream', 0):#x}])), "
               f"disjoint from the {tuned['variants']} evaluation variants below; every run's ‖ṽ‖ measured with "
               "the scenario's Λ_p (median [interquartile range]; tuned − default: paired Hodges–Lehmann "
               "estimate [95 % signed-rank interval], bold where it excludes 0; ranks among the eight laws "
               "with default and with tuned settings, as in the ranking table):")
    return Table(caption, ("controller", "objective on the tuning draws", "default", "tuned", "tuned − default",
                           "rank, default", "rank, tuned"), tuple(rows))


def tuned_gains_table(tuned: dict):
    """Each law's searched gains, default → tuned: one column per shared gain, the law's own in the last;
    a gain within the box's outer :data:`.tuning.EDGE_FRACTION` is marked with the edge it is at."""
    from .tuning import EDGE_FRACTION, box_edge

    # a column for each shared gain every law searched (a law's own shared key, INDI's filter, is its own)
    laws = list(tuned["settings"].values())
    shared = [k for k in (laws[0]["tuned"] if laws else {}) if k.startswith("controller.")
              and all(k in s["tuned"] for s in laws)]

    def cell(cid: str, name: str) -> str:
        s = tuned["settings"][cid]
        text = f"{_g(s['default'][name])} → {_g(s['tuned'][name])}"
        box = tuned["tuning"].get(cid, {}).get("box", {}).get(name)
        edge = box_edge(s["tuned"][name], box[0], box[1], box[2] == "log") if box else None
        return f"{text} ({edge} tenth of box)" if edge else text

    rows = []
    for cid, s in tuned["settings"].items():
        own = "; ".join(f"{k} {cell(cid, k)}" for k in s["tuned"] if k not in shared) or "(none)"
        rows.append((Cell(controller_label(cid)), *(Cell(cell(cid, k), numeric=True) for k in shared), Cell(own)))
    caption = ("The gains each law flies, default → tuned (the boxes searched: the how-to \"Tuning a law's gains\"; "
               "[0:2]: north and east, or roll and pitch; [2]: down). \"top tenth of box\", \"bottom tenth of box\": "
               f"within {100 * EDGE_FRACTION:g} % of the box's width (log width where searched in log scale) "
               "of that bound: the optimum may lie beyond it:")
    return Table(caption, ("controller", *(k[len("controller."):] for k in shared), "the law's own gains"),
                 tuple(rows))


def _g(x: float) -> str:
    return f"{x:.3g}"


def _rank(e: Optional[dict]) -> str:
    if not e:
        return "–"
    return f"{e['rank_lo']}" if e["rank_lo"] == e["rank_hi"] else f"{e['rank_lo']}–{e['rank_hi']}"


def comparison_pair_tables(metrics: dict) -> list:
    """The ranking, the paired differences and (if flown) default against tuned, for a reproduce metrics.json."""
    dist = metrics.get("distribution", {}).get("comparison")
    if not dist or "paired" not in dist or not dist["paired"].get("ranking"):
        return []   # a comparison flown by one law ranks nothing
    tables = [ranking_table(dist), paired_table(dist)]
    if "tuned" in metrics:
        tables.append(tuned_table(metrics["tuned"], dist))
        tables.append(tuned_gains_table(metrics["tuned"]))
        if metrics["tuned"].get("claims"):
            claims = distribution_claims_table(metrics["tuned"])
            tables.append(Table("The paper's tracking claims with every law's tuned settings. " + claims.caption,
                                claims.headers, claims.rows))
        if metrics["tuned"].get("paired", {}).get("ranking"):
            tables.append(ranking_table(metrics["tuned"], title="With the tuned settings. "))
    return tables



def distribution_sections(metrics: dict) -> list[Section]:
    """The report's sections on the distributions, the ablation and the method x wind table."""
    sections = []
    dist = metrics.get("distribution", {})
    if "comparison" in dist:
        sections.append(Section("Controller comparison over seeded variants",
                                tables=(distribution_claims_table(dist["comparison"]),
                                        distribution_controllers_table(dist["comparison"]))))
        pair_tables = comparison_pair_tables(metrics)
        if pair_tables:
            sections.append(Section("Ranking and paired differences", tables=tuple(pair_tables)))
    if "convergence" in dist:
        sections.append(Section("Parameter convergence over seeded variants",
                                tables=(distribution_claims_table(dist["convergence"]),
                                        convergence_distribution_table(dist["convergence"]))))
    if "ablation" in metrics:
        sections.append(Section("Ablation of the unmodelled effects", tables=(ablation_table(metrics["ablation"]),)))
    if "wind_table" in metrics:
        sections.append(Section("Method × wind condition", tables=(wind_table_table(metrics["wind_table"]),)))
    if metrics.get("faults"):
        sections.append(Section("Faults in the loop", tables=(fault_table_table(metrics["faults"]),)))
    return sections


def identifiability_section(conv: dict) -> Section:
    """Per convergence run: how many directions of theta the data determine (information eigen-spectrum)."""
    runs = [r for r in conv.get("identifiability_per_run", []) if r]
    thr = runs[0]["threshold_sensitivity_mps2"]
    text = (f"Eigen-spectrum of each run's un-forgotten information Σ W^T W dt in relative parameter "
            f"coordinates (θ = diag(|θ_0|)(1 + δ)). A direction's sensitivity is the RMS change of the "
            f"predicted specific force over the run for a unit relative change δ along it; a direction is "
            f"determined if its sensitivity is at least {fmt_number(thr)} m/s² (a 10 % error along it moves "
            f"the prediction by 0.01 g RMS). Directions below are left to the prior.")
    per_run = tuple((Cell(str(i + 1)), _num(r["n_determined"]),
                     Cell(", ".join(fmt_number(d["sensitivity_mps2"]) for d in r["directions"]), numeric=True),
                     Cell(r["directions"][-1]["dominant"]))
                    for i, r in enumerate(runs))
    t1 = Table("Per run:", ("run", "directions determined", "sensitivities, m/s² (largest first)",
                            "least determined direction"), per_run)
    first = runs[0]["directions"]
    t2 = Table("Run 1, each direction (eigenvector's components of magnitude ≥ 0.3):",
               ("sensitivity", "unit", "determined", "direction"),
               tuple((_num(d["sensitivity_mps2"]), Cell("m/s²"), Cell("yes" if d["determined"] else "no"),
                      Cell(d["dominant"])) for d in first))
    return Section("Identifiability", (paragraph(text),), (t1, t2))


def table_markdown(table: Table) -> str:
    """A :class:`Table` as Markdown (caption, header, rows), as report.md prints it."""
    esc = lambda s: str(s).replace("|", "\\|")  # noqa: E731
    lines = [table.caption, ""] if table.caption else []
    lines.append("| " + " | ".join(esc(h) for h in table.headers) + " |")
    lines.append("|" + "---|" * len(table.headers))
    for row in table.rows:
        lines.append("|" + "".join(f" **{esc(c.text)}** |" if c.strong else f" {esc(c.text)} |" for c in row))
    return "\n".join(lines) + "\n"


def build_report(title: str, metrics: dict, figures: Iterable[FigureRef], notes: Iterable[str]) -> Report:
    """The report of ``metrics`` (the content of metrics.json) with its figures and notes
    (paragraphs; `backticks` mark code)."""
    sections = []
    if "run" in metrics:
        sections.append(Section("Metrics of the run", tables=(run_metrics_table(metrics["run"]),)))
    if "comparison" in metrics:
        sections.append(Section("Controller comparison", tables=(comparison_table(metrics["comparison"]),)))
    if "convergence" in metrics:
        sections.append(convergence_section(metrics["convergence"]))
        if any(metrics["convergence"].get("identifiability_per_run") or ()):
            sections.append(identifiability_section(metrics["convergence"]))
    if metrics.get("claims"):
        sections.append(Section("The paper's claims, checked in simulation (single seed)",
                                tables=(claims_table(metrics["claims"]),)))
    sections.extend(distribution_sections(metrics))
    if metrics.get("bases"):
        sections.append(bases_section(metrics["bases"]))
    return Report(title, tuple(paragraph(n) for n in notes), tuple(sections), tuple(figures))


# --- the force-model bases (issue #23; the metrics: vtoladapt.experiments.ceiling.bases_metrics) ---------------
def _fraction_cell(d) -> str:
    if not d or not d.get("n"):
        return "n/a"
    lo, hi = d["ci95"]
    return f"{d['fraction']:.2f} ({d['successes']}/{d['n']}) [{lo:.2f}, {hi:.2f}]"


def bases_section(m: dict):
    """The report's section "Force-model bases compared"."""
    def table(caption, headers, rows):
        return Table(caption, tuple(headers), tuple(tuple(Cell(str(c), numeric=i > 0) for i, c in enumerate(r))
                                                    for r in rows))

    tables = []
    paras = [paragraph("The paper's claims above use the paper's eight-parameter basis. The extended physics "
                       "basis adds a side force C_Y(β), the post-stall plate's C_N90, the lift slope near "
                       "stall and the pusher's advance-ratio loss; the learned basis adds a network's columns "
                       "trained on flights of the same vehicle (README \"Force-model bases: extended physics "
                       "and learned\").")]
    ceil = m.get("ceiling", {})
    if ceil:
        bins = list(next(iter(ceil.values()))["p95_g"])
        rows = tuple((b, *[("–" if v["p95_g"][k] is None else f"{v['p95_g'][k]:.4f}") for k in bins],
                      "yes" if v["pass"] else "no") for b, v in ceil.items())
        tables.append(table("Constant-weights ceiling on the comparison's composite log (computed in this run): "
                            "p95 error (g) per true-airspeed bin (m/s) of the best constant weights of each basis, "
                            "fitted to the true specific force with the true flow and throttles.",
                            ("basis", *bins, "all bins < 0.05 g"), rows))
    env = m.get("envelope")
    if env:
        names = list(env["rows"])
        c = env["rows"][names[0]]["campaign"]
        paras.append(paragraph(f"Envelope campaign per basis (committed `docs/basis_comparison.json`, made by "
                               f"`python -m vtoladapt.learn.evaluate --runs {c.get('runs')}`: {c.get('runs')} draws of "
                               f"`scenarios/envelope.toml`, seed {c.get('seed')}; the learned bases were trained on "
                               "other draws, seed 2222; not re-flown here: it takes far longer than the reproduction)."))
        rows = [("composite p95 < 0.05 g in every bin", *[_fraction_cell(env["rows"][n]["targets"]["pred_err_every_bin"])
                                                          for n in names]),
                ("every adaptive law beats PID and PD", *[_fraction_cell(env["rows"][n]["targets"]["beats_pid_pd"])
                                                          for n in names])]
        for b in env["rows"][names[0]]["by_airspeed"]:
            rows.append((f"p95 < 0.05 g, bin {b} m/s", *[_fraction_cell(env["rows"][n]["by_airspeed"].get(b)) for n in names]))
        tables.append(table("Fraction of draws where the target holds (successes/judged) [95 % Wilson interval].",
                            ("target", *names), tuple(rows)))
        if env.get("ceiling"):
            bases = list(env["ceiling"])
            first = env["ceiling"][bases[0]]
            if all(isinstance(v, dict) and "true inputs" in v for v in first.values()):
                # per law, on its own flights (learn.evaluate since issue #34): {row: {law: {inputs: fraction}}}
                keys = [(cid, inp) for cid, v in first.items() for inp in v]
                rows = tuple((f"{cid}, {inp}", *[_fraction_cell(env["ceiling"][b].get(cid, {}).get(inp))
                                                 for b in bases]) for cid, inp in keys)
                caption = ("Constant-weights ceiling over the same draws, fitted on each law's own flights: least "
                           "squares on the true force with the true inputs; 'measured inputs': on the accelerometer "
                           "with the controller's own inputs, both filtered as the controller filters them.")
            else:
                rows = tuple((k, *[_fraction_cell(env["ceiling"][b].get(k)) for b in bases]) for k in first)
                caption = ("Constant-weights ceiling over the same draws: least squares on the true force with "
                           "the true inputs; in the columns 'measured inputs', on the accelerometer with the "
                           "controller's own inputs, both filtered as the controller filters them.")
            tables.append(table(caption, ("draws", *bases), rows))
    return Section("Force-model bases compared", paragraphs=tuple(paras), tables=tuple(tables))


# --- rendering -------------------------------------------------------------------------------------------
def _environment(autoescape: bool):
    import jinja2

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(TEMPLATE_DIR), autoescape=autoescape,
                             undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True,
                             keep_trailing_newline=True)
    env.filters["md_cell"] = lambda s: str(s).replace("|", "\\|")
    return env


def render_markdown(report: Report) -> str:
    """report.md's text."""
    return _environment(False).get_template("report.md.j2").render(report=report)


def render_html(report: Report, out: Path) -> str:
    """report.html's text: a standalone page, the figures (read from ``out``) inline."""
    images = {f.file: "data:image/png;base64," + base64.b64encode((Path(out) / f.file).read_bytes()).decode()
              for f in report.figures}
    return _environment(True).get_template("report.html.j2").render(report=report, images=images)


def write_report(out: Path, report: Report) -> tuple[Path, Path]:
    """Write report.md and report.html into ``out``."""
    out = Path(out)
    return (_write_text(out / "report.md", render_markdown(report)),
            _write_text(out / "report.html", render_html(report, out)))


# --- paths as the report shows them ---------------------------------------------------------------------
def display_path(path, out: Path) -> str:
    """``path`` as a reader of the output folder should see it: a shipped file as
    ``vtoladapt/...``, a nearby file relative to the output folder, anything else by its name."""
    if not str(path):
        return "(not from a file)"
    p = Path(path).resolve()
    try:
        return "vtoladapt/" + p.relative_to(PACKAGE_DIR).as_posix()
    except ValueError:
        pass
    rel = os.path.relpath(p, Path(out).resolve())
    if rel.split(os.sep)[:3].count("..") == 3:   # far away: its location tells the reader nothing
        return p.name
    return Path(rel).as_posix()


_ABS_PATH = re.compile(r"(?<![\w.~])/(?:[^\s/'\"`,;()]+/)*[^\s/'\"`,;()]+")


def display_paths_in(text: str, out: Path) -> str:
    """``text`` with every absolute path in it replaced by :func:`display_path`."""
    return _ABS_PATH.sub(lambda m: display_path(m.group(0), out), text)


# --- writing files (the one place outputs are written) ---------------------------------------------------
# Every output goes through vtoladapt.outputs: written under a temporary name and renamed (an
# interrupted run leaves no truncated file), recorded in the output folder's manifest, JSON with
# null for NaN.
def _write_text(path: Path, text: str) -> Path:
    return outputs.write_text(path, text)


def _write_bytes(path: Path, data: bytes) -> Path:
    return outputs.write_bytes(path, data)


def _write_json(path: Path, data: dict) -> Path:
    return outputs.write_json(path, data)


def _copy_file(src: Path, dst: Path) -> Path:
    return outputs.write_bytes(dst, Path(src).read_bytes())


def _save_figure(fig, path: Path, dpi: Optional[float] = None) -> Path:
    return outputs.save_figure(fig, path, dpi=dpi if dpi is not None else fig.dpi)
