"""The report's and README's tables of the paired comparison: the ranking, every pair's difference,
default against tuned (data for :mod:`.report`'s templates and :mod:`.readme`)."""
from __future__ import annotations

from typing import Optional

from ..control.registry import CONTROLLERS
from ..sim.run_metrics import METRIC_INFO
from .metrics import PHASE_METRIC_INFO

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
"""Column headers of these tables (the full labels are in :data:`vtoladapt.metrics.METRIC_INFO` and
:data:`.metrics.PHASE_METRIC_INFO`)."""


def label(cid: str) -> str:
    return CONTROLLERS[cid].label if cid in CONTROLLERS else cid


def metric_words(key: str) -> str:
    """The metric's label in words with its unit."""
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
    from .report import Cell, Table

    paired = dist["paired"]
    order, by_metric = ranking_rows(paired, metrics)
    cols = [m for m in metrics if m in by_metric]
    rows = []
    for cid in order:
        cells = [Cell(label(cid))]
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
    from .report import Cell, Table

    paired = dist["paired"]["pairs"]
    cols = [m for m in metrics if m in paired]
    ids = list(dict.fromkeys(i for m in cols for key in paired[m] for i in key.split("|")))
    rows = []
    for i, a in enumerate(ids):
        for b in ids[i + 1:]:
            cells = [Cell(f"{label(a)} − {label(b)}")]
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
    from .report import Cell, Table, fmt_median_iqr

    key = "vel_err_rms_mps"
    rank_default = {e["id"]: e for e in default["paired"]["ranking"].get(key, [])}
    rank_tuned = {e["id"]: e for e in tuned["paired"]["ranking"].get(key, [])}
    rows = []
    for cid, s in tuned["settings"].items():
        rec = tuned["tuning"].get(cid, {})
        gains = "; ".join(f"{k} {_g(s['default'][k])} → {_g(s['tuned'][k])}" for k in s["tuned"]) or "(none)"
        obj = (f"{rec['default_objective_mps']:.4g} → {rec['tuned_objective_mps']:.4g}"
               if "default_objective_mps" in rec else "–")
        text, separated = fmt_difference(tuned["vs_default"][cid].get(key))
        rows.append((Cell(label(cid)), Cell(gains), Cell(obj, numeric=True),
                     Cell(fmt_median_iqr(default["controllers"][cid].get(key)), numeric=True),
                     Cell(fmt_median_iqr(tuned["controllers"][cid].get(key)), numeric=True),
                     Cell(text, numeric=True, strong=separated),
                     Cell(_rank(rank_default.get(cid)), numeric=True), Cell(_rank(rank_tuned.get(cid)), numeric=True)))
    first = next(iter(tuned["tuning"].values()), {})
    budget = (f"{first.get('evaluations', '?')} evaluations of the objective per law (the first its defaults) × "
              f"{first.get('draws', '?')} tuning draws each") if first else "the shipped budget"
    caption = (f"Default against tuned settings, RMS ‖ṽ‖ (m/s). Each law's declared gains were searched by "
               f"DIRECT-L with one budget for every law: {budget}, the tuning draws' seeds from their own "
               f"stream (SeedSequence([seed, {first.get('seed_stream', 0):#x}])), disjoint from the "
               f"{tuned['variants']} evaluation variants below (median [interquartile range]; tuned − default: "
               "paired Hodges–Lehmann estimate [95 % signed-rank interval], bold where it excludes 0; ranks "
               "among the eight laws with default and with tuned settings, as in the ranking table):")
    return Table(caption, ("controller", "gains, default → tuned", "objective on the tuning draws",
                           "default", "tuned", "tuned − default", "rank, default", "rank, tuned"), tuple(rows))


def _g(x: float) -> str:
    return f"{x:.3g}"


def _rank(e: Optional[dict]) -> str:
    if not e:
        return "–"
    return f"{e['rank_lo']}" if e["rank_lo"] == e["rank_hi"] else f"{e['rank_lo']}–{e['rank_hi']}"


def comparison_pair_tables(metrics: dict) -> list:
    """The ranking, the paired differences and (if flown) default against tuned, for a reproduce metrics.json."""
    dist = metrics.get("distribution", {}).get("comparison")
    if not dist or "paired" not in dist:
        return []
    tables = [ranking_table(dist), paired_table(dist)]
    if "tuned" in metrics:
        tables.append(tuned_table(metrics["tuned"], dist))
        tables.append(ranking_table(metrics["tuned"], title="With the tuned settings. "))
    return tables


__all__ = ["RANKED_METRICS", "SHORT_LABELS", "comparison_pair_tables", "fmt_difference", "metric_words",
           "paired_table", "ranking_table", "tuned_table"]
