"""Monte-Carlo campaigns: planning is validated and seeded; runs go through Dask or in process."""
import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from vtoladapt.campaign.runner import Variation, plan_campaign, run_campaign
from vtoladapt.config import ConfigError

SCENARIO = """
name = "mc"
vehicle = "caltech_vtol"
duration_s = 1.0
seed = 3
[wind.fan_array]
schedule = [[0, 30], [1, 30]]
"""


@pytest.fixture()
def scenario_file(tmp_path):
    path = tmp_path / "mc.toml"
    path.write_text(SCENARIO)
    return path


def test_plan_is_seeded_and_draws_within_ranges(scenario_file):
    var = [Variation.parse("plant.coefficients.CL1=2.8:3.6")]
    a = plan_campaign(scenario_file, 5, var)
    b = plan_campaign(scenario_file, 5, var)
    assert [s.drawn for s in a] == [s.drawn for s in b]
    cl1 = [s.drawn["plant.coefficients.CL1"] for s in a]
    assert all(2.8 <= v <= 3.6 for v in cl1) and len(set(cl1)) == 5
    assert len({s.drawn["seed"] for s in a}) == 5
    c = plan_campaign(scenario_file, 5, var, seed=99)
    assert [s.drawn for s in c] != [s.drawn for s in a]


def test_bad_variation_fails_before_anything_runs(scenario_file, tmp_path):
    with pytest.raises(ConfigError, match="stal_angle_deg"):
        plan_campaign(scenario_file, 2, [Variation.parse("plant.stal_angle_deg=10:12")])
    with pytest.raises(ConfigError, match=r"stall_angle_deg = 8\d.*out of range"):
        plan_campaign(scenario_file, 2, [Variation.parse("plant.stall_angle_deg=80:90")])
    with pytest.raises(ConfigError, match="KEY=LOW:HIGH"):
        Variation.parse("plant.stall_angle_deg")
    with pytest.raises(ConfigError, match="LOW <= HIGH"):
        Variation.parse("plant.stall_angle_deg=12:10")
    with pytest.raises(ConfigError, match=r"--workers = 0: out of range; allowed: >= 1"):
        run_campaign(plan_campaign(scenario_file, 1, []), tmp_path / "out", "none", n_workers=0)
    assert not (tmp_path / "out").exists()


def test_in_process_campaign_writes_one_row_per_run(scenario_file, tmp_path):
    specs = plan_campaign(scenario_file, 3, [Variation.parse("plant.mass_kg=1.6:1.8")])
    rows = run_campaign(specs, tmp_path / "out", scheduler="none", show_progress=False)
    table = pq.read_table(tmp_path / "out" / "campaign.parquet").to_pydict()
    assert table["run"] == [0, 1, 2]
    np.testing.assert_allclose(table["plant.mass_kg"], [s.drawn["plant.mass_kg"] for s in specs])
    assert all(np.isfinite(r["vel_err_rms_mps"]) for r in rows)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["runs"] == 3 and "vel_err_rms_mps" in summary["columns"]
    assert (tmp_path / "out" / "fig_campaign.png").stat().st_size > 10_000


def test_local_dask_cluster_gives_the_same_rows_as_in_process(scenario_file, tmp_path):
    specs = plan_campaign(scenario_file, 2, [])
    local = run_campaign(specs, tmp_path / "a", scheduler="none", show_progress=False)
    dask = run_campaign(specs, tmp_path / "b", scheduler="local", n_workers=2, show_progress=False)
    for r1, r2 in zip(local, dask):
        assert r1["vel_err_rms_mps"] == r2["vel_err_rms_mps"]  # bit for bit: same seeds, same code


def test_campaign_file_resolves_the_base_scenarios_relative_paths_against_the_base(tmp_path):
    """A campaign file in one folder whose base scenario, in another, names its vehicle by a relative
    path: the draws were validated with the description "c.toml (campaign draw 0: ...)" as the
    scenario's location, so the vehicle was looked up as "A/c.toml ([campaign] base ../B/myveh.toml"."""
    from vtoladapt.campaign.runner import plan_campaign_file
    from vtoladapt.vehicle import VEHICLE_DIR

    (tmp_path / "A").mkdir()
    (tmp_path / "B" / "planes").mkdir(parents=True)
    text = (VEHICLE_DIR / "caltech_vtol.toml").read_text().replace('name = "caltech_vtol"', 'name = "myveh"')
    (tmp_path / "B" / "planes" / "myveh.toml").write_text(text)
    (tmp_path / "B" / "base.toml").write_text('name = "b"\nvehicle = "planes/myveh.toml"\nduration_s = 1.0\n')
    camp = tmp_path / "A" / "c.toml"
    camp.write_text('[campaign]\nbase = "../B/base.toml"\nruns = 2\nseed = 1\ncontrollers = ["composite"]\n'
                    '[[campaign.vary]]\nkeys = ["plant.coefficients.CL1"]\nlow = 0.9\nhigh = 1.1\n'
                    'relative_to_vehicle = true\n')
    _, specs = plan_campaign_file(camp)
    assert len(specs) == 2
    cl1 = 3.2502  # myveh is a copy of caltech_vtol
    assert all(0.9 * cl1 <= s.drawn["plant.coefficients.CL1"] <= 1.1 * cl1 for s in specs)
    # a scenario in a sub-folder flown with --vary: its relative vehicle path resolves the same way
    plan = plan_campaign(tmp_path / "B" / "base.toml", 2, [Variation.parse("plant.stall_angle_deg=12:18")])
    assert len(plan) == 2
