"""A Monte-Carlo campaign: a short variant of the paper's hold in the fan array's wind, flown over
drawn plants (lift slope and stall angle uniform in a range), the same command that runs on a
cluster.

    python examples/campaign.py --out out/campaign

On a laptop ``--scheduler none`` runs the draws in this process (one thread per core); on a cluster
pass ``--scheduler tcp://HOST:8786`` instead and nothing else changes: the same command gives the
same campaign. Writes campaign.parquet (one row per run), summary.json and fig_campaign.png.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from vtoladapt.cli import main as vtoladapt

SCENARIO = '''\
name = "campaign_example"
description = "The fan array's wind at 60 % for 3 s, then off: a short hold for a campaign example."
vehicle = "caltech_vtol"
duration_s = 6.0
seed = 7
plant_substeps = 1

[reference]
kind = "hold"
position_m = [0.0, 0.0, -1.5]

[initial]
position_m = [0.0, 0.0, -1.5]

[wind.fan_array]
schedule = [[0, 0], [1, 0], [1, 60], [4, 60], [4, 0], [6, 0]]
max_speed_mps = 12.9
spin_up_time_constant_s = 1.0
'''


def main(out: Path, scheduler: str = "none") -> dict:
    out.mkdir(parents=True, exist_ok=True)
    scenario = out / "campaign_example.toml"
    scenario.write_text(SCENARIO)
    code = vtoladapt(["campaign", str(scenario), "--controller", "composite", "--runs", "6", "--seed", "1",
                      "--vary", "plant.coefficients.CL1=2.8:3.6", "--vary", "plant.stall_angle_deg=12:18",
                      "--scheduler", scheduler, "--workers", "2", "--quiet", "--out", str(out / "mc"), "--force"])
    assert code == 0
    summary = json.loads((out / "mc" / "summary.json").read_text())
    return summary


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/campaign"), help="output folder")
    parser.add_argument("--scheduler", default="none", help="'none', 'local' or tcp://HOST:PORT")
    args = parser.parse_args()
    main(args.out, args.scheduler)
