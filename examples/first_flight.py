"""First flight: the paper's aircraft holds its position in the fan array's wind, flown by the
composite adaptive controller, then by the PID baseline on the same draw.

    python examples/first_flight.py --out out/first_flight

Writes ``first_flight.png`` (velocity-error norm of both laws against time) and prints each law's
RMS velocity error. A 20 s excerpt of the paper's comparison (``paper_comparison``): a few seconds
once the kernels are compiled.
"""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

import vtoladapt


def main(out: Path) -> dict[str, float]:
    scenario = vtoladapt.load_scenario("paper_comparison")          # a shipped scenario, by name
    scenario = replace(scenario, duration_s=20.0)                    # fan off, 30 %, then 40 %
    rms_mps = {}
    curves = {}
    for kind in ("composite", "pid"):
        one = replace(scenario, controller=replace(scenario.controller, kind=kind))
        result = vtoladapt.simulate(one).raise_if_diverged()
        v_err_mps = np.linalg.norm(result.velocity_error_W, axis=1)  # |v - v_d| in the world frame
        rms_mps[kind] = float(np.sqrt(np.mean(v_err_mps**2)))
        curves[kind] = (result.time_s, v_err_mps)
        print(f"{kind:10s} RMS velocity error {rms_mps[kind]:.3f} m/s")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3))
    for kind, (t_s, e_mps) in curves.items():
        ax.plot(t_s, e_mps, label=kind, lw=1)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("‖v − v_d‖ (m/s)")
    ax.legend()
    fig.tight_layout()
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "first_flight.png", dpi=100)
    plt.close(fig)
    return rms_mps


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/first_flight"), help="output folder")
    main(parser.parse_args().out)
