"""A variant of the paper's scenario: copy the shipped comparison, change one thing (the probe's
calibration, from the paper's single-k formula to the spline calibration), fly both with the
composite controller and the PID baseline on the same seeded draws, and compare.

    python examples/scenario_variant.py --out out/variant

A scenario file is the unit of work: the variant is a copy of ``scenarios/paper_comparison.toml``
with one line changed, run by ``vtoladapt run`` (here 12 s of it, ``--duration``, two of its laws and
4 of its 30 seeded variants, to keep the example to seconds). Writes both runs'
folders (log.parquet, metrics.json, figures, report) and prints their velocity errors.
"""
from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from vtoladapt.cli import main as vtoladapt

SHIPPED = Path(__file__).resolve().parents[1] / "scenarios" / "paper_comparison.toml"


def main(out: Path) -> dict[str, float]:
    out.mkdir(parents=True, exist_ok=True)
    text = SHIPPED.read_text()
    assert 'calibration = "single_k"' in text
    short = re.sub(r"controllers = \[.*\]", 'controllers = ["composite", "pid"]', text)
    short = re.sub(r"variants = 30", "variants = 4", short)
    files = {"paper": out / "paper.toml", "variant": out / "my_variant.toml"}
    files["paper"].write_text(short)
    files["variant"].write_text(short.replace('calibration = "single_k"', 'calibration = "calibrated"')
                                     .replace('name = "paper_comparison"', 'name = "my_variant"'))
    rms_mps = {}
    for name, path in files.items():
        assert vtoladapt(["run", str(path), "--out", str(out / name), "--duration", "12", "--quiet", "--force"]) == 0
        metrics = json.loads((out / name / "metrics.json").read_text())
        for law, m in metrics["distribution"]["comparison"]["controllers"].items():
            rms_mps[f"{name}/{law}"] = m["vel_err_rms_mps"]["median"]
            print(f"{name:8s} {law:10s} RMS velocity error, median of 4 draws: {rms_mps[f'{name}/{law}']:.4f} m/s")
    return rms_mps


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/variant"), help="output folder")
    main(parser.parse_args().out)
