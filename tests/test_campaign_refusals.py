"""What ``vtoladapt campaign`` refuses before anything runs, each as one line naming where it was
written: a scenario key set in two places (the later silently replaced the earlier and rows were
labelled with a value that was not flown), a bad vehicle or base named by the campaign file,
``--runs`` past its range (a scenario and a campaign file alike), and a ``--listen`` host that is
not an address of this machine. None of these tests flies a run."""
from __future__ import annotations

from pathlib import Path

import pytest

from conftest import SHORT_FAN_SCENARIO
import vtoladapt.campaign.cluster as campaign_cluster
import vtoladapt.campaign.runner as campaign
from vtoladapt.campaign.cluster import check_listen
from vtoladapt.campaign.runner import MAX_CAMPAIGN_RUNS, Variation, plan_campaign, plan_campaign_file
from vtoladapt.cli import main
from vtoladapt.config import ConfigError
from vtoladapt.errors import ExitCode

BASE = SHORT_FAN_SCENARIO
HEAD = """[campaign]
base = "base.toml"
runs = 4
seed = 1
controllers = ["composite"]
"""
VEHICLES = """[campaign.choices.vehicle.caltech]
vehicle = "caltech_vtol"
[campaign.choices.vehicle.px4]
vehicle = "px4_standard_vtol"
"""
BEARING = """[[campaign.vary]]
keys = ["wind.fan_array.array_bearing_deg"]
low = 0.0
high = 360.0
"""


def _campaign(tmp_path: Path, body: str) -> Path:
    (tmp_path / "base.toml").write_text(BASE)
    path = tmp_path / "c.toml"
    path.write_text(HEAD + body)
    return path


def _refused(path: Path, *needles: str) -> str:
    with pytest.raises(ConfigError) as exc:
        plan_campaign_file(path)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"{path}: "), msg
    for n in needles:
        assert n in msg, (n, msg)
    return msg


# --- a key written in two places --------------------------------------------------------------------
@pytest.mark.parametrize("body, first, second, key", [
    # two choice dimensions: rows said choice.vehicle = px4_standard_vtol for draws that flew caltech_vtol
    (VEHICLES + '[campaign.choices.other.a]\nvehicle = "caltech_vtol"\n[campaign.choices.other.b]\n'
     'vehicle = "caltech_vtol"\n', "[campaign.choices.vehicle.caltech]", "[campaign.choices.other.a]", "'vehicle'"),
    ('[campaign.set]\n"wind.fan_array.array_bearing_deg" = 45.0\n' + BEARING,
     "[campaign.set]", "[[campaign.vary]] keys = ['wind.fan_array.array_bearing_deg']",
     "'wind.fan_array.array_bearing_deg'"),
    (VEHICLES.replace('vehicle = "px4_standard_vtol"\n', 'vehicle = "px4_standard_vtol"\n'
                      '"wind.fan_array.array_bearing_deg" = 45.0\n') + BEARING,
     "[campaign.choices.vehicle.px4]", "[[campaign.vary]]", "'wind.fan_array.array_bearing_deg'"),
    ('[campaign.set]\nvehicle = "px4_standard_vtol"\n' + VEHICLES,
     "[campaign.set]", "[campaign.choices.vehicle.caltech]", "'vehicle'"),
    # a whole table and a key inside it
    ('[campaign.set]\n"plant.coefficients.CL1" = 3.0\n[[campaign.vary]]\nkeys = ["plant.coefficients"]\n'
     'low = 1.0\nhigh = 2.0\n', "[campaign.set]", "[[campaign.vary]] keys = ['plant.coefficients']",
     "'plant.coefficients.CL1' / 'plant.coefficients'"),
])
def test_a_key_set_in_two_places_is_refused_naming_both(tmp_path, body, first, second, key):
    msg = _refused(_campaign(tmp_path, body), first, second, f"both set {key}", "allowed: each scenario key in one place")
    assert msg.index(first) < msg.index(second)


def test_a_key_written_dotted_and_nested_in_one_table_is_refused(tmp_path):
    body = '[campaign.set]\n"plant.stall_angle_deg" = 14.0\n[campaign.set.plant]\nstall_angle_deg = 15.0\n'
    _refused(_campaign(tmp_path, body), "[campaign.set] 'plant.stall_angle_deg'", "written twice")


def test_the_options_of_one_choice_write_the_same_key_and_each_row_reports_what_it_flies(tmp_path):
    """The options of one dimension are alternatives: allowed, and each draw's reported option is
    the vehicle its scenario flies."""
    _, specs = plan_campaign_file(_campaign(tmp_path, VEHICLES + BEARING))
    vehicles = {"caltech": "caltech_vtol", "px4": "px4_standard_vtol"}
    assert {s.drawn["choice.vehicle"] for s in specs} == set(vehicles)  # Latin hypercube: both come up
    assert all(s.mapping["vehicle"] == vehicles[s.drawn["choice.vehicle"]] for s in specs)


@pytest.mark.parametrize("flags, needles", [
    (["plant.mass_kg=1.6:1.7", "plant.mass_kg=1.7:1.8"], ["--vary plant.mass_kg=1.6:1.7 and --vary plant.mass_kg=1.7:1.8"]),
    (["plant.coefficients=1:2", "plant.coefficients.CL1=2.8:3.6"], ["both draw the same value"]),
    (["experiment.runs=2:3"], ["'experiment.runs' is set by the campaign itself"]),
    (["seed=1:5"], ["'seed' is set by the campaign itself"]),
])
def test_cli_vary_flags_that_collide_are_refused(tmp_path, flags, needles):
    (tmp_path / "base.toml").write_text(BASE)
    with pytest.raises(ConfigError) as exc:
        plan_campaign(tmp_path / "base.toml", 2, [Variation.parse(f) for f in flags])
    for n in needles:
        assert n in str(exc.value), (n, str(exc.value))


# --- errors name the campaign file's table ---------------------------------------------------------
def test_a_bad_vehicle_in_a_choice_option_names_the_option_not_the_base(tmp_path):
    body = VEHICLES.replace('"px4_standard_vtol"', '"px5_vtol"')
    msg = _refused(_campaign(tmp_path, body),
                   "[campaign.choices.vehicle.px4]: vehicle = 'px5_vtol': unknown name; shipped vehicles: caltech_vtol")
    assert "base.toml" not in msg


def test_a_bad_vehicle_in_campaign_set_names_the_set_table(tmp_path):
    _refused(_campaign(tmp_path, '[campaign.set]\nvehicle = "nope"\n'),
             "[campaign.set]: vehicle = 'nope': unknown name")
    # a vehicle file that is missing: the option and the file it looked for
    body = VEHICLES.replace('"px4_standard_vtol"', '"planes/gone.toml"')
    _refused(_campaign(tmp_path, body), "[campaign.choices.vehicle.px4]: vehicle = 'planes/gone.toml'",
             str(tmp_path / "planes" / "gone.toml"), "not found")


def test_a_missing_base_names_the_campaign_files_base_key(tmp_path):
    path = _campaign(tmp_path, "")
    path.write_text(path.read_text().replace('base = "base.toml"', 'base = "nope.toml"'))
    _refused(path, "[campaign] base = 'nope.toml': ", "nope.toml: TOML file not found")


def test_a_bad_value_in_a_choice_option_names_the_option(tmp_path):
    body = VEHICLES + '"plant.stall_angle_deg" = 70.0\n'  # added to the px4 option
    _refused(_campaign(tmp_path, body), "[campaign.choices.vehicle.px4]: [plant] stall_angle_deg = 70.0",
             "out of range")


# --- --runs, --listen: checked before anything is read or started ----------------------------------------
def _must_not_plan(*args, **kwargs):
    raise AssertionError("the flag should have been refused before the campaign was planned")


@pytest.mark.parametrize("campaign_file", [False, True])
def test_runs_beyond_the_ceiling_is_refused_up_front_for_a_scenario_and_a_campaign_file(
        tmp_path, capsys, monkeypatch, campaign_file):
    path = _campaign(tmp_path, "") if campaign_file else tmp_path / "base.toml"
    (tmp_path / "base.toml").write_text(BASE.replace("seed = 3", 'seed = 3\n[experiment]\nkind = "comparison"'))
    monkeypatch.setattr(campaign, "plan_campaign", _must_not_plan)
    monkeypatch.setattr(campaign, "plan_campaign_file", _must_not_plan)
    flags = [] if campaign_file else ["--controller", "composite"]
    rc = main(["campaign", str(path), *flags, "--runs", str(2 * MAX_CAMPAIGN_RUNS), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert rc == ExitCode.BAD_INPUT and "\n" not in err, err
    assert f"--runs = {2 * MAX_CAMPAIGN_RUNS}: out of range; allowed: >= 1 and <= {MAX_CAMPAIGN_RUNS}" in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("host, needle", [
    ("my-laptop.invalid", "cannot be resolved"),  # .invalid never resolves (RFC 6761)
    ("999.1.1.1", "not an IPv4 address"),
    ("192.0.2.1", "not an address of this machine"),  # TEST-NET-1: documentation only, never assigned
    ("::1", "an IPv6 address"),
    ("bad_host", "not an IP address or host name"),
])
def test_a_listen_host_that_this_machine_cannot_listen_on_is_refused(tmp_path, capsys, monkeypatch, host, needle):
    monkeypatch.setattr(campaign_cluster, "local_cluster", _must_not_plan)
    path = _campaign(tmp_path, "")
    rc = main(["campaign", str(path), "--listen", host, "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert rc == ExitCode.BAD_INPUT and "\n" not in err, err
    assert f"--listen {host!r}: {needle}" in err and "allowed: an IPv4 address or host name" in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("host", ["127.0.0.1", "localhost", "0.0.0.0"])
def test_the_usual_listen_hosts_are_accepted(host):
    check_listen(host)
