"""Replaying a real flight log: the controller's force model and composite adaptation run open loop
on a real PX4 flight (the MIT solar airplane's topic CSVs, vendored in ``data/``).

    python examples/replay_flight_log.py --out out/replay

Writes what ``vtoladapt replay`` writes (replay.parquet, metrics.json, fig_replay.png, report.md,
report.html) and prints the prediction error with the adapted θ̂ and with the vehicle file's θ₀.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from vtoladapt.cli import main as vtoladapt

LOG = Path(__file__).resolve().parents[1] / "data" / "mit-solar-airplane-px4"


def main(out: Path) -> dict:
    assert vtoladapt(["replay", str(LOG), "--vehicle", "px4_standard_vtol", "--out", str(out), "--force"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    error = metrics["prediction_error"]
    for which in ("prior", "adapted"):
        e = error[which]
        print(f"prediction error with the {which:7s} θ: RMS {e['rms_g']:.3f} g, p95 {e['p95_g']:.3f} g")
    return metrics


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/replay"), help="output folder")
    main(parser.parse_args().out)
