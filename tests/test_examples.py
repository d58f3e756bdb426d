"""Every script in examples/ runs as the tutorials show it, and prints what they say it prints.

Each runs in a fresh interpreter (as a user runs it) with its output folder in a temporary
directory. ``examples/example_law.py`` is a module, not a script: ``own_law.py`` flies it, and
``tests/test_extension_law.py`` holds it to its references.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

EXPECTED = {
    # script: (a line it prints, the files its --out folder must then hold)
    "first_flight.py": ("composite  RMS velocity error", ("first_flight.png",)),
    "scenario_variant.py": ("variant  composite", ("my_variant.toml", "variant/metrics.json",
                                                   "variant/fig_tracking_comparison.png")),
    "own_vehicle.py": ("my_plane: 2.04 kg", ("my_plane.toml",)),
    "own_law.py": ("K_v north flown 2.16 1/s", ("own_law.png",)),
    "fit_tunnel_data.py": ("z = ", ("fit/posterior.json", "fit/side_force.png")),
    "calibrate_probe.py": ("calibrated flow-angle error RMS", ("probe_cal.json", "linearity.png")),
    "replay_flight_log.py": ("prediction error with the adapted", ("metrics.json", "fig_replay.png")),
    "gym_env.py": ("episode: 500 steps", ()),
    "campaign.py": ("6 runs (0 diverged)", ("mc/campaign.parquet", "mc/fig_campaign.png")),
}


def test_every_example_is_listed():
    scripts = {p.name for p in EXAMPLES.glob("*.py")} - {"example_law.py"}  # the law is a module, not a script
    assert scripts == set(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_example_runs(name, tmp_path):
    printed, files = EXPECTED[name]
    args = [sys.executable, str(EXAMPLES / name)] + ([] if name == "gym_env.py" else ["--out", str(tmp_path / "out")])
    env = dict(os.environ, MPLBACKEND="Agg")
    done = subprocess.run(args, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    assert printed in done.stdout + done.stderr, done.stdout[-2000:]
    for f in files:
        assert (tmp_path / "out" / f).is_file(), f
