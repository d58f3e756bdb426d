"""Your own control law: ``example_law.py`` beside this script is a complete law (eq:f_ctrl with the
shared K_v scaled by a gain of its own). A law is added as one module in
``vtoladapt/control/laws/`` and one entry in ``vtoladapt/control/registry.py``; this script checks
the module against the law interface, then adds it that way to a copy of the package in ``--out``.

    python examples/own_law.py --out out/own_law          # check it, make the copy (seconds)
    python examples/own_law.py --out out/own_law --fly    # and fly it (compiles the controller: minutes)

With ``--fly`` the copy's interpreter builds ``[controller] kind = "example"`` from a scenario
table and holds a point with it. In your own checkout you would add the two edits to ``src/`` and
run ``vtoladapt run SCENARIO --controller example``.
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import vtoladapt
from vtoladapt.control.laws import LawContext, check_law

LAW = Path(__file__).resolve().parent / "example_law.py"
ENTRY = ('    ControllerInfo("example", "Example (scaled K_v)", "tab:olive", False, False,\n'
         '                   "a user\'s minimal law: eq:f_ctrl with its own gain factor", "example"),\n')
FLY = """
import vtoladapt
from dataclasses import replace
from vtoladapt.control.config import controller_config_from_mapping
cfg = controller_config_from_mapping({"kind": "example", "example": {"gain_scale": 1.2}}, "user.toml")
scenario = vtoladapt.load_scenario("gym_hold")
result = vtoladapt.simulate(replace(scenario, duration_s=5.0, controller=cfg)).raise_if_diverged()
print("flew", cfg.info.label, "for 5 s; worst position error", abs(result.position_error_W).max(), "m")
"""


def main(out: Path, fly: bool = False) -> Path:
    spec = importlib.util.spec_from_file_location("example_law", LAW)
    module = importlib.util.module_from_spec(spec)
    sys.modules["example_law"] = module                  # dataclasses look their module up
    spec.loader.exec_module(module)
    check_law(module)                                    # the interface every law meets
    params = module.fill_params(module.Settings(gain_scale=1.5), LawContext(None, None, None, None, 0.004))
    print("interface check passed; parameter block", params.tolist())

    pkg = out / "vtoladapt"
    if pkg.exists():
        shutil.rmtree(pkg)
    shutil.copytree(Path(vtoladapt.__file__).resolve().parent, pkg, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copyfile(LAW, pkg / "control" / "laws" / "example.py")          # edit 1: the module
    registry = pkg / "control" / "registry.py"
    text = registry.read_text()
    end = text.index("), package=", text.index("CONTROLLERS: Registry = Registry("))
    registry.write_text(text[:end] + ENTRY + text[end:])                  # edit 2: the registry entry
    print("package with the law:", pkg)
    if fly:
        env = dict(os.environ, PYTHONPATH=str(out))
        subprocess.run([sys.executable, "-c", FLY], env=env, cwd=out, check=True)
    return pkg


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/own_law"), help="output folder")
    parser.add_argument("--fly", action="store_true", help="fly the law (compiles the controller: minutes)")
    args = parser.parse_args()
    main(args.out, args.fly)
