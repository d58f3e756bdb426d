"""Every entry point compiles from an empty kernel cache, whichever kernel it reaches first.

Numba compiles a callee with its caller's ``_nrt`` (reference counting) setting unless the callee
states its own, and the tick's kernels are compiled without (:mod:`vtoladapt.sim.loop`). A
callee that allocates therefore compiles or fails depending on which caller reached it first, and
a warm cache hides the order. Each case here runs in a fresh process with its own empty
``NUMBA_CACHE_DIR``, so nothing is compiled before its entry point.
"""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

ENTRY_POINTS = {
    "vector env, residual mode": (
        "import numpy as np\n"
        "from vtoladapt.gym import HoldVectorEnv\n"
        "v = HoldVectorEnv(num_envs=2, workers=2, residual=True)\n"
        "v.reset(seed=0)\n"
        "obs = v.step(np.zeros((2, 5), dtype=np.float32))[0]\n"
        "assert np.isfinite(obs).all()\n"),
    "controller step API, every law": (
        "import vtoladapt\n"
        "from vtoladapt.control import Controller, ControllerConfig, Measurement, Reference\n"
        "from vtoladapt.control.registry import controller_ids\n"
        "meas = Measurement()\n"
        "meas.q_WB = (1.0, 0.0, 0.0, 0.0)\n"
        "meas.v_i_valid = True\n"
        "for kind in controller_ids():\n"
        "    c = Controller(vtoladapt.load_vehicle('caltech_vtol'), ControllerConfig(kind=kind))\n"
        "    for k in range(3):\n"
        "        cmd = c.step(0.004 * k, meas, Reference())\n"
        "    assert 0.0 <= cmd.u_z <= 1.0, (kind, cmd)\n"),
}


@pytest.mark.slow
def test_each_entry_point_compiles_from_an_empty_cache(tmp_path):
    procs = {}
    for i, (name, code) in enumerate(ENTRY_POINTS.items()):
        env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / f"cache{i}"))
        procs[name] = subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE,
                                       stderr=subprocess.PIPE, text=True)
    for name, p in procs.items():
        out, err = p.communicate(timeout=1200)
        assert p.returncode == 0, f"{name}: {err[-3000:]}"
