"""The force-model bases in ``vtoladapt reproduce``: a live ceiling per basis and the committed envelope comparison.

The paper's claims stay the paper's basis's. Beside them the report shows, per basis (paper,
extended physics, learned):

* computed in the run: the constant-weights ceiling (:func:`vtoladapt.learn.evaluate.ceiling_fit`)
  on the comparison experiment's composite log (its p95 error per airspeed bin and RMS), seconds of
  work on a log the reproduction flew anyway;
* the envelope campaign per basis (``docs/basis_comparison.json``), which takes far longer than
  ``make reproduce``'s budget (:mod:`vtoladapt.learn.evaluate` regenerates it), shown as committed,
  with the command, draws and seeds that made it.
"""
from __future__ import annotations

import json
from pathlib import Path

COMPARISON_FILE = Path(__file__).resolve().parents[3] / "docs" / "basis_comparison.json"
BASES = ("paper", "extended", "learned")


def bases_metrics(comparison_dir: Path, scenario) -> dict:
    """The ``bases`` entry of metrics.json: the ceiling per basis on the comparison's composite log and
    the committed envelope comparison (if the file is there)."""
    from ..bases import describe_basis
    from ..sim.results import SimulationResult
    from .evaluate import ceiling_fit

    out: dict = {"ceiling": {}}
    log = Path(comparison_dir) / "runs" / f"{scenario.name}_composite.parquet"
    if log.is_file():
        res = SimulationResult.from_parquet(log)
        veh = scenario.load_vehicle()
        for b in BASES:
            fit = ceiling_fit(res, veh, describe_basis(veh, b))
            out["ceiling"][b] = fit
    if COMPARISON_FILE.is_file():
        out["envelope"] = json.loads(COMPARISON_FILE.read_text())
    return out


def _cell(d) -> str:
    if not d or not d.get("n"):
        return "n/a"
    lo, hi = d["ci95"]
    return f"{d['fraction']:.2f} ({d['successes']}/{d['n']}) [{lo:.2f}, {hi:.2f}]"


def bases_section(m: dict):
    """The report's section "Force-model bases compared"."""
    from ..experiments.report import Cell, Section, Table, paragraph

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
        rows = [("composite p95 < 0.05 g in every bin", *[_cell(env["rows"][n]["targets"]["pred_err_every_bin"])
                                                          for n in names]),
                ("every adaptive law beats PID and PD", *[_cell(env["rows"][n]["targets"]["beats_pid_pd"])
                                                          for n in names])]
        for b in env["rows"][names[0]]["by_airspeed"]:
            rows.append((f"p95 < 0.05 g, bin {b} m/s", *[_cell(env["rows"][n]["by_airspeed"].get(b)) for n in names]))
        tables.append(table("Fraction of draws where the target holds (successes/judged) [95 % Wilson interval].",
                            ("target", *names), tuple(rows)))
        if env.get("ceiling"):
            bases = list(env["ceiling"])
            tables.append(table("Constant-weights ceiling over the same draws (least squares on the true force).",
                                ("draws", *bases), tuple((k, *[_cell(env["ceiling"][b].get(k)) for b in bases])
                                                         for k in env["ceiling"][bases[0]])))
    return Section("Force-model bases compared", paragraphs=tuple(paras), tables=tuple(tables))
