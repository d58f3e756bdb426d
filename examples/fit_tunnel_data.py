"""Fitting wind-tunnel data: a virtual force-balance campaign on the paper's aircraft, then the
Bayesian fit of the force model (Table I) to it, and the fitted means against the truth.

    python examples/fit_tunnel_data.py --out out/fit

The same two commands a user runs on a real balance's CSV (``vtoladapt tunnel``, ``vtoladapt fit``);
``--fast`` keeps it to seconds. Writes ``data.csv``, ``data.truth.json`` and the fit's folder
``fit/`` (posterior.json, table1.md, corner.png, trace.png, residuals.png, side_force.png).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from vtoladapt.cli import main as vtoladapt


def main(out: Path) -> dict[str, float]:
    out.mkdir(parents=True, exist_ok=True)
    data = out / "data.csv"
    # a simulated balance: wing sweeps, static thrust steps, rotors at an angle; the truth beside it
    assert vtoladapt(["tunnel", "--vehicle", "caltech_vtol", "--out", str(data), "--seed", "0", "--force"]) == 0
    assert vtoladapt(["fit", str(data), "--out", str(out / "fit"), "--vehicle", "caltech_vtol",
                      "--truth", str(data.with_suffix(".truth.json")), "--fast", "--force"]) == 0
    posterior = json.loads((out / "fit" / "posterior.json").read_text())
    truth = json.loads(data.with_suffix(".truth.json").read_text())
    z = {}
    for name in ("CTx", "CTz", "CL0", "CL1"):
        p = posterior["parameters"][name]
        z[name] = (p["mean"] - truth["coefficients"][name]) / p["std"]
        print(f"{name:4s} posterior {p['mean']:.4g} ± {p['std']:.2g}, truth {truth['coefficients'][name]:.4g}, "
              f"z = {z[name]:+.2f}")
    return z


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/fit"), help="output folder")
    main(parser.parse_args().out)
