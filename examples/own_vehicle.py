"""Your own vehicle: a vehicle file of your own (here the paper's aircraft made 20 % heavier, with a
larger wing), checked by ``load_vehicle``, then flown in a hold in the fan array's wind.

    python examples/own_vehicle.py --out out/own_vehicle

Start from a shipped file (``vtoladapt vehicle show caltech_vtol`` prints one with every unit) and
change what your airframe has; every key is in the configuration reference with its unit and range.
"""
from __future__ import annotations

import argparse
import re
from dataclasses import replace
from pathlib import Path

import numpy as np

import vtoladapt

SHIPPED = Path(vtoladapt.__file__).parent / "vehicles" / "caltech_vtol.toml"


def main(out: Path) -> float:
    out.mkdir(parents=True, exist_ok=True)
    text = SHIPPED.read_text()
    text = text.replace('name = "caltech_vtol"', 'name = "my_plane"')
    text = re.sub(r"mass_kg = [0-9.]+", "mass_kg = 2.04", text, count=1)
    text = re.sub(r"wing_area_m2 = [0-9.]+", "wing_area_m2 = 0.26", text, count=1)
    path = out / "my_plane.toml"
    path.write_text(text)
    vehicle = vtoladapt.load_vehicle(path)               # validated: a bad value is one line naming the key
    print(f"{vehicle.name}: {vehicle.mass.mass_kg} kg, wing {vehicle.geometry.wing_area_m2} m^2")

    scenario = vtoladapt.load_scenario("gym_hold")        # hold in the fan array's wind, 250 Hz plant
    # a path given in Python is read from the working directory (one written inside a scenario file, from
    # that file's folder); absolute here so the scenario can be copied anywhere
    scenario = replace(scenario, vehicle=str(path.resolve()), duration_s=10.0, name="my_plane_hold")
    result = vtoladapt.simulate(scenario).raise_if_diverged()
    p_err_m = np.linalg.norm(result.position_error_W, axis=1)
    print(f"hold for {scenario.duration_s:g} s: worst position error {p_err_m.max():.3f} m")
    return float(p_err_m.max())


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/own_vehicle"), help="output folder")
    main(parser.parse_args().out)
