"""Calibrating an airflow probe: both models (the paper's single-k and the calibrated spline) fitted
to a real five-hole probe's calibration file from NASA, judged on its held-out test points, saved,
and used to turn one pressure reading into the incident velocity.

    python examples/calibrate_probe.py --out out/probe

Writes ``probe_cal.json`` and ``linearity.png`` (estimated against true flow angles, by the command
``vtoladapt probe calibrate``, which writes the same calibration).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from vtoladapt.cli import main as vtoladapt
from vtoladapt.probe import (calibrate, evaluate_calibration, incident_velocity_from_pressures,
                             load_calibration, read_nasa_pcf, save_calibration)

DATA = Path(__file__).resolve().parents[1] / "data" / "nasa-multihole-probe" / "16328-1_M050.csv"


def main(out: Path) -> dict[str, float]:
    out.mkdir(parents=True, exist_ok=True)
    data = read_nasa_pcf(DATA)                          # vendored in the repository
    models = calibrate(data)                            # {"single_k": ..., "calibrated": ...}
    rms_deg = {}
    for name, model in models.items():
        m = evaluate_calibration(model, data)           # on the file's held-out test points
        rms_deg[name] = m.angle_rms_deg
        print(f"{name:10s} flow-angle error RMS {m.angle_rms_deg:.2f} deg, speed error RMS {100 * m.speed_rms_rel:.1f} %")
    save_calibration(out / "probe_cal.json", models, source=data.source)

    cal = load_calibration(out / "probe_cal.json", model="calibrated").to_kernel()
    v_i_B = np.empty(3)                                 # incident velocity, body FRD (m/s)
    q_Pa = np.array([160.0, 12.0, -5.0])                # q_inf, q_alpha, q_beta
    valid = incident_velocity_from_pressures(q_Pa, 1.2, cal, v_i_B)
    print("v_i_B =", np.round(v_i_B, 2), "m/s, valid:", bool(valid))
    # the command writes the same calibration plus metrics.json and the linearity figure
    assert vtoladapt(["probe", "calibrate", str(DATA), "--out", str(out / "cli"), "--force"]) == 0
    (out / "cli" / "linearity.png").replace(out / "linearity.png")
    return rms_deg


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/probe"), help="output folder")
    main(parser.parse_args().out)
