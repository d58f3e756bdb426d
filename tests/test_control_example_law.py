"""A user's control law, added the documented way, flies.

The documented way (README "Adding a controller", :mod:`vtoladapt.control`): one new module in
``vtoladapt/control/laws/`` and one entry in ``vtoladapt/control/registry.py``. The test does
exactly that to a copy of the package (so the installed one, and its compiled cache, are left
alone), then in a fresh interpreter validates a scenario table for the new law and flies it in
a small closed loop: a rigid body whose force model is the controller's own (Table I), released
0.3 m below and 0.2 m south of the setpoint. Reference: with an exact model the law's
eq:f_ctrl with gain ``scale * K_v`` makes the position error decay, so after 6 s it must be
below 2 cm, and the law's own state must have counted every tick.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import vtoladapt

EXAMPLE_LAW = (Path(__file__).resolve().parents[1] / "examples" / "example_law.py").read_text()
"""The user's law, as the tutorial "Your own control law" shows it (examples/example_law.py)."""

REGISTRY_ENTRY = ('    ControllerInfo("example", "Example (scaled K_v)", "tab:olive", False, False,\n'
                  '                   "a user\'s minimal law: eq:f_ctrl with its own gain factor", "example"),\n')

FLIGHT = textwrap.dedent('''
    import json
    import numpy as np
    import vtoladapt
    from vtoladapt import forces
    from vtoladapt.config import ConfigError
    from vtoladapt.control import Controller, Measurement, Reference
    from vtoladapt.control.config import controller_config_from_mapping
    from vtoladapt.frames import GRAVITY_MPS2, quat_multiply, quat_normalize, quat_to_rotmat
    from vtoladapt.sim.scenario import ExperimentConfig

    assert vtoladapt.__file__.startswith(PACKAGE_ROOT), vtoladapt.__file__
    cfg = controller_config_from_mapping({"kind": "example", "example": {"gain_scale": 1.2}}, "user.toml")
    try:
        controller_config_from_mapping({"gain_scale": 1.2}, "user.toml")
        moved = ""
    except ConfigError as exc:
        moved = str(exc)
    vehicle = vtoladapt.load_vehicle("caltech_vtol")
    ctrl = Controller(vehicle, cfg)
    theta, model, J = vehicle.theta_scaled, vehicle.model_kernel, vehicle.mass.inertia_matrix
    J_inv = np.linalg.inv(J)
    DT, SUB, LAG_S = 0.004, 4, 0.03
    p, v, q, w = np.array([0.2, 0.0, -1.2]), np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3)
    u, tau, f = np.array([0.0, np.sqrt(GRAVITY_MPS2 / theta[1])]), np.zeros(3), np.empty(3)
    ref, meas = Reference.hold((0.0, 0.0, -1.5)), Measurement()
    n = int(6.0 / DT)
    for k in range(n):
        R = quat_to_rotmat(q)
        forces.body_force(R.T @ v, u[0], u[1], theta, model, f)
        meas.array[:] = np.concatenate([p, v, q, w, f, R.T @ v, [1.0]])
        cmd = ctrl.step(k * DT, meas, ref)
        h = DT / SUB
        for _ in range(SUB):
            R = quat_to_rotmat(q)
            forces.body_force(R.T @ v, u[0], u[1], theta, model, f)
            v_dot = R @ f + np.array([0.0, 0.0, GRAVITY_MPS2])
            w_dot = J_inv @ (np.cross(J @ w, w) + tau)
            p, v = p + h * v, v + h * v_dot
            q = quat_normalize(q + 0.5 * h * quat_multiply(q, np.array([0.0, *w])))
            w = w + h * w_dot
            u = u + h / LAG_S * (np.array([cmd.u_x, cmd.u_z]) - u)
            tau = tau + h / LAG_S * (cmd.tau_B - tau)
    print(json.dumps({
        "final_error_m": float(np.linalg.norm(p - [0.0, 0.0, -1.5])),
        "ticks": float(ctrl.state.law_field("TICKS")[0]), "n": n,
        "gain_scale": cfg.example.gain_scale, "label": cfg.info.label, "moved": moved,
        "in_experiments": "example" in ExperimentConfig.__dataclass_fields__["controllers"].metadata["choices"],
    }))
''')


def _package_with_example_law(root: Path) -> Path:
    """Copy the package under ``root`` and add the law the documented way: one file, one registry entry."""
    src = Path(vtoladapt.__file__).resolve().parent
    pkg = root / "vtoladapt"
    shutil.copytree(src, pkg, ignore=shutil.ignore_patterns("__pycache__"))
    (pkg / "control" / "laws" / "example.py").write_text(EXAMPLE_LAW)
    registry = pkg / "control" / "registry.py"
    text = registry.read_text()
    end = text.index("), package=", text.index("CONTROLLERS: Registry = Registry("))
    registry.write_text(text[:end] + REGISTRY_ENTRY + text[end:])
    return root


@pytest.mark.slow
def test_a_law_added_as_one_file_and_one_registry_entry_flies(tmp_path):
    root = _package_with_example_law(tmp_path)
    env = dict(os.environ, PYTHONPATH=str(root))
    script = f"PACKAGE_ROOT = {str(root)!r}\n" + FLIGHT
    out = subprocess.run([sys.executable, "-c", script], env=env, cwd=tmp_path, capture_output=True, text=True,
                         timeout=1800)
    assert out.returncode == 0, out.stderr[-3000:]
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert r["gain_scale"] == 1.2 and r["label"] == "Example (scaled K_v)" and r["in_experiments"]
    assert "[controller.example] gain_scale" in r["moved"]
    assert r["ticks"] == r["n"]
    assert r["final_error_m"] < 0.02


def test_the_example_law_meets_the_interface_and_the_registry_gains_one_entry(tmp_path, monkeypatch):
    """The fast half: the law module passes the interface check and the copy's registry lists it last."""
    import ast
    import importlib.util

    from vtoladapt.control.laws import LawContext, check_law
    from vtoladapt.control.registry import CONTROLLER_IDS

    path = tmp_path / "example_law.py"
    path.write_text(EXAMPLE_LAW)
    spec = importlib.util.spec_from_file_location("example_law", path)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "example_law", module)     # dataclasses look their module up
    spec.loader.exec_module(module)
    check_law(module)
    block = module.fill_params(module.Settings(gain_scale=1.5), LawContext(None, None, None, None, 0.004))
    assert block.tolist() == [1.5] and module.STATE.size == 1

    root = _package_with_example_law(tmp_path / "copy")
    tree = ast.parse((root / "vtoladapt" / "control" / "registry.py").read_text())
    ids = [node.args[0].value for node in ast.walk(tree)
           if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "ControllerInfo"]
    assert ids == list(CONTROLLER_IDS) + ["example"]
    assert (root / "vtoladapt" / "control" / "laws" / "example.py").read_text() == EXAMPLE_LAW
