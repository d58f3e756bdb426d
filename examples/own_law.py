"""Your own control law: ``example_law.py`` beside this script is a complete law (eq:f_ctrl with θ̂
held and the shared K_v scaled by a gain of its own), in a module of your own: nothing in
``vtoladapt`` is edited. Registered by one call, it flies like a shipped law; here a hold from 0.47 m
off the setpoint, against the shipped ``nominal`` law (the same eq:f_ctrl with K_v unscaled).

    python examples/own_law.py --out out/own_law

Prints each law's final position error and the law's own diagnostics column, and writes
``own_law.png`` (the position error of both against time).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # example_law.py, your module

import example_law  # noqa: E402

from vtoladapt import components  # noqa: E402
from vtoladapt.sim import simulate  # noqa: E402
from vtoladapt.sim.scenario import scenario_from_mapping  # noqa: E402


def main(out: Path) -> dict[str, float]:
    if "example" not in components.registry("law"):
        components.register("law", example_law.INFO)   # once per process, before a scenario names it
    error_m, curves = {}, {}
    for kind, table in (("example", {"example": {"gain_scale": 1.2}}), ("nominal", {})):
        result = simulate(scenario_from_mapping({
            "name": f"hold_{kind}", "vehicle": "caltech_vtol", "duration_s": 4.0,
            "initial": {"position_m": [0.2, 0.3, -1.2]}, "reference": {"position_m": [0.0, 0.0, -1.5]},
            "controller": {"kind": kind, **table}}, f"own_law.py ({kind})")).raise_if_diverged()
        p_err_m = np.linalg.norm(result.position_error_W, axis=1)
        error_m[kind], curves[kind] = float(p_err_m[-1]), (result.time_s, p_err_m)
        print(f"{kind:8s} position error after 4 s: {error_m[kind]:.4f} m")
        if kind == "example":
            print(f"example  diagnostics: K_v north flown {result['example_K_v_N_per_s'][-1]:.2f} 1/s")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3))
    for kind, (t_s, e_m) in curves.items():
        ax.plot(t_s, e_m, label=kind, lw=1)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("‖p − p_d‖ (m)")
    ax.legend()
    fig.tight_layout()
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "own_law.png", dpi=100)
    plt.close(fig)
    return error_m


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/own_law"), help="output folder")
    main(parser.parse_args().out)
