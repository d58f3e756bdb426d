"""The force-model bases in ``vtoladapt reproduce``: a live ceiling per basis and the committed envelope comparison
(the report's section is :func:`vtoladapt.experiments.report.bases_section`).

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
    from .ceiling import ceiling_fit

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
