"""The envelope campaign: campaign files validate (one-line errors), draws are seeded and stratified,
a tiny campaign writes its outputs, and the summary's fractions and Wilson intervals are right on a
hand-built table (checked against scipy's Wilson interval)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import binomtest

from conftest import SHORT_FAN_SCENARIO, examples
from vtoladapt.campaign.runner import VaryEntry, load_campaign_file, plan_campaign_file, run_campaign
from vtoladapt.cli import main
from vtoladapt.config import ConfigError
from vtoladapt.control.registry import controller_ids
from vtoladapt.errors import ExitCode
from vtoladapt.experiments.envelope import (ALPHA_EXCURSION_MAX_S, PRED_ERR_BOUND_G, alpha_excursions,
                                            envelope_summary)
from vtoladapt.experiments.envelope_readme import envelope_tables, readme_block
from vtoladapt.sim.run_metrics import airspeed_bin_labels

CONTROLLER_IDS = controller_ids()

REPO = Path(__file__).resolve().parents[1]
ENVELOPE = REPO / "scenarios" / "envelope.toml"
BINS = airspeed_bin_labels()


def _wilson(k: int, n: int) -> list[float]:
    ci = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    return [ci.low, ci.high]


# --- the shipped file -----------------------------------------------------------------------------
def test_envelope_file_covers_the_issue_and_draws_a_latin_hypercube():
    cf = load_campaign_file(ENVELOPE)
    # every law of the comparison (composite_indi, registered after the committed campaign, flies the same
    # draws in docs/measure_kalman.py until the campaign is flown again)
    assert set(cf.config.controllers) == set(CONTROLLER_IDS) - {"composite_indi"}
    vary = {v.keys[0] if len(v.keys) == 1 else "coefficients": v for v in cf.config.vary}
    coeff = vary["coefficients"]
    assert coeff.relative_to_vehicle and (coeff.low, coeff.high) == (0.75, 1.25) and len(coeff.keys) == 8
    assert (vary["plant.stall_angle_deg"].low, vary["plant.stall_angle_deg"].high) == (12.0, 18.0)
    assert (vary["wind.turbulence.mean_wind_fraction"].low, vary["wind.turbulence.mean_wind_fraction"].high) == (0.0, 0.1)
    assert (vary["wind.fan_array.array_bearing_deg"].low, vary["wind.fan_array.array_bearing_deg"].high) == (0.0, 360.0)
    assert set(cf.choices["vehicle"]) == {"caltech_vtol", "px4_standard_vtol"}
    peaks = [max(u for _, u in o["wind.fan_array.schedule"]) for o in cf.choices["fan_schedule"].values()]
    assert max(peaks) == 100.0 and len(peaks) >= 3

    n = 8
    cf, specs = plan_campaign_file(ENVELOPE, runs=n)
    assert len(specs) == n * len(cf.config.controllers)
    again = plan_campaign_file(ENVELOPE, runs=n)[1]
    assert [s.drawn for s in specs] == [s.drawn for s in again]
    draws = [s for s in specs if s.controller == cf.config.controllers[0]]
    for d in draws:  # every controller of a draw flies the same mapping and seed
        same = [s for s in specs if s.index == d.index]
        assert {s.drawn["seed"] for s in same} == {d.drawn["seed"]} and all(s.mapping is d.mapping for s in same)
    # Latin hypercube: exactly one draw in each of the n strata of every range, options equally often
    stall = np.array([d.drawn["plant.stall_angle_deg"] for d in draws])
    assert sorted(np.floor((stall - 12.0) / 6.0 * n).astype(int)) == list(range(n))
    factors = np.array([d.drawn["plant.coefficients.CL1:factor"] for d in draws])
    assert sorted(np.floor((factors - 0.75) / 0.5 * n).astype(int)) == list(range(n))
    vehicles = [d.drawn["choice.vehicle"] for d in draws]
    assert vehicles.count("caltech_vtol") == vehicles.count("px4_standard_vtol") == n // 2
    # relative coefficients are factors on the draw's own vehicle; the turbulence vector is [x, x, 0.75 x]
    from vtoladapt.vehicle import load_vehicle
    for d in draws:
        fm = load_vehicle(d.drawn["choice.vehicle"]).force_model
        assert d.mapping["plant"]["coefficients"]["CL1"] == pytest.approx(fm.CL1 * d.drawn["plant.coefficients.CL1:factor"])
        x = d.drawn["wind.turbulence.mean_wind_fraction"]
        assert d.mapping["wind"]["turbulence"]["mean_wind_fraction"] == pytest.approx([x, x, 0.75 * x])
        assert d.mapping["experiment"] == {"kind": "single"}


@pytest.mark.parametrize("value, sector", [(0.0, "[315,45) deg"), (350.0, "[315,45) deg"),
                                           (44.9, "[315,45) deg"), (45.0, "[45,135) deg"),
                                           (180.0, "[135,225) deg"), (314.9, "[225,315) deg")])
def test_bearing_sectors_are_centred_on_the_compass_points(value, sector):
    v = VaryEntry(keys=("wind.fan_array.array_bearing_deg",), low=0.0, high=360.0, bands=4, angle=True)
    assert v.band(value, "deg") == sector


# --- one-line errors ------------------------------------------------------------------------------
GOOD = """
[campaign]
base = "base.toml"
runs = 2
seed = 1
controllers = ["composite", "pid"]
[campaign.set]
duration_s = 3.0
[[campaign.vary]]
keys = ["plant.stall_angle_deg"]
low = 12.0
high = 18.0
bands = 2
"""
BASE = SHORT_FAN_SCENARIO


def _campaign(tmp_path: Path, text: str = GOOD) -> Path:
    (tmp_path / "base.toml").write_text(BASE)
    path = tmp_path / "c.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("old, new, needles", [
    ("runs = 2", "runs = 0", ["[campaign] runs = 0", "out of range", ">= 1"]),
    ('controllers = ["composite", "pid"]', 'controllers = ["composit"]', ["controllers[0] = 'composit'", "'composite'"]),
    ("seed = 1", "seed = 1\nsampling = 'sobol'", ["sampling = 'sobol'", "'latin_hypercube'"]),
    ("high = 18.0", "high = 10.0", ["low = 12, high = 10", "low <= high"]),
    ("seed = 1", "seed = 1\nrun = 3", ["[campaign] run = 3", "did you mean 'runs'"]),
    ('keys = ["plant.stall_angle_deg"]', 'keys = ["plant.stall_angle_deg"]\nrelative_to_vehicle = true',
     ["relative_to_vehicle", "plant.coefficients.<name>"]),
    ("duration_s = 3.0", "seed = 4", ["[campaign.set] 'seed'", "set by the campaign itself"]),
    ("[campaign.set]", "choices = 3\n[campaign.set]", ["choices = 3", "must be a table"]),
    ('base = "base.toml"', 'base = "nowhere.toml"', ["nowhere.toml"]),
    ("duration_s = 3.0", "duration_s = -1.0", ["duration_s = -1.0", "> 0"]),
])
def test_bad_campaign_fields_give_one_line_errors(tmp_path, old, new, needles):
    path = _campaign(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(ConfigError) as exc:
        plan_campaign_file(path)
    msg = str(exc.value)
    assert "\n" not in msg and str(tmp_path) in msg, msg
    for n in needles:
        assert n in msg, (n, msg)


def test_a_drawn_value_out_of_the_scenario_range_is_refused_before_anything_runs(tmp_path):
    path = _campaign(tmp_path, GOOD.replace("low = 12.0", "low = 70.0").replace("high = 18.0", "high = 80.0"))
    with pytest.raises(ConfigError, match=r"stall_angle_deg = \d+.*out of range; allowed: > 0 and < 60"):
        plan_campaign_file(path)


def test_cli_flags_that_a_campaign_file_sets_itself_are_refused(tmp_path, capsys):
    path = _campaign(tmp_path)
    rc = main(["campaign", str(path), "--vary", "plant.mass_kg=1:2", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert rc == ExitCode.BAD_INPUT and "\n" not in err and "--vary" in err and "[[campaign.vary]]" in err
    rc = main(["campaign", str(tmp_path / "base.toml"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert rc == ExitCode.BAD_INPUT and "--runs: required" in err
    assert not (tmp_path / "o").exists()


# --- a tiny campaign ------------------------------------------------------------------------------
def test_tiny_campaign_writes_one_row_per_draw_and_controller(tmp_path):
    path = _campaign(tmp_path)
    cf, specs = plan_campaign_file(path)
    out = tmp_path / "out"
    rows = run_campaign(specs, out, scheduler="none", show_progress=False, campaign={"file": str(path)})
    table = pq.read_table(out / "campaign.parquet").to_pydict()
    assert table["run"] == [0, 0, 1, 1] and table["controller"] == ["composite", "pid"] * 2
    assert table["seed"][0] == table["seed"][1] != table["seed"][2]
    assert all(f == 1.0 for f in table["finite"]) and len(rows) == 4
    # the fan's 7.7 m/s puts the composite run's prediction error in the [5,8) bin; PID has none
    assert np.isfinite(table[f"pred_err_p95_g{BINS[2]}"][0]) and np.isnan(table[f"pred_err_p95_g{BINS[2]}"][1])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["campaign"]["draws"] == 2 and summary["campaign"]["file"] == str(path)
    assert summary["targets"]["finite_logs"]["n"] == 2
    assert summary["targets"]["beats_pid_pd"]["n"] == 0  # no PD flown: not judged
    assert set(summary["groups"]["plant.stall_angle_deg"]) <= {"[12,15) deg", "[15,18] deg"}
    assert (out / "fig_campaign.png").stat().st_size > 10_000
    assert summary["targets"] == json.loads(json.dumps(envelope_summary(table)["targets"]))


# --- the summary on a hand-built table ------------------------------------------------------------
def _row(run: int, cid: str, vel: float, *, pred=None, alpha=(0.0, 0.0), finite=1.0, diverged=0.0,
         group="a") -> dict:
    nan = float("nan")
    row = {"run": run, "controller": cid, "group.side": group, "vel_err_rms_mps": vel, "finite": finite,
           "diverged": diverged, "flown_s": 10.0, "wall_time_s": 0.1, "alpha_abs_max_deg": 5.0,
           "mixer_saturated_fraction": 0.0, "alpha_over_protect_fraction": alpha[0],
           "alpha_over_protect_longest_s": alpha[1], "alpha_over_stall_fraction": 0.0,
           "alpha_over_stall_longest_s": 0.0}
    for i, lab in enumerate(BINS):
        row[f"pred_err_p95_g{lab}"] = nan if pred is None or pred[i] is None else pred[i]
        row[f"vel_err_rms_mps{lab}"] = vel
        row[f"alpha_over_protect_fraction{lab}"] = alpha[0]
        row[f"alpha_over_protect_longest_s{lab}"] = alpha[1]
    return row


def test_summary_fractions_and_wilson_intervals_on_a_hand_built_parquet(tmp_path):
    ok = [0.01, 0.02, None, 0.04, None]          # every non-empty bin below 0.05 g
    bad = [0.01, 0.02, 0.06, 0.04, None]         # the [5,8) bin fails
    rows = []
    # draw: (composite pred bins, composite vel, tracking_only vel, pid vel, pd vel, alpha, group)
    draws = [(ok, 0.1, 0.2, 0.3, 0.4, (0.0, 0.0), "a"),
             (ok, 0.1, 0.5, 0.3, 0.4, (0.005, 0.2), "a"),     # tracking_only loses to PID
             (bad, 0.1, 0.2, 0.3, 0.4, (0.02, 0.2), "b"),     # alpha too often
             (ok, 0.5, 0.2, 0.3, 0.4, (0.001, ALPHA_EXCURSION_MAX_S), "b"),  # composite loses; excursion too long
             (bad, 0.1, 0.2, 0.3, 0.4, (0.0, 0.0), "b")]
    for d, (pred, vc, vt, vp, vd, alpha, g) in enumerate(draws):
        rows += [_row(d, "composite", vc, pred=pred, alpha=alpha, group=g),
                 _row(d, "tracking_only", vt, group=g), _row(d, "pid", vp, group=g), _row(d, "pd", vd, group=g)]
    rows[-1]["finite"] = 0.0  # one non-finite PD log in the last draw
    keys = list(rows[0])
    pq.write_table(pa.table({k: [r[k] for r in rows] for k in keys}), tmp_path / "hand.parquet")
    s = envelope_summary(pq.read_table(tmp_path / "hand.parquet").to_pydict())

    def check(entry, k, n):
        assert (entry["successes"], entry["n"]) == (k, n)
        assert entry["fraction"] == pytest.approx(k / n)
        assert entry["ci95"] == pytest.approx(_wilson(k, n), abs=1e-12)

    t = s["targets"]
    check(t["pred_err_every_bin"], 3, 5)
    check(t["alpha_protect_brief"], 3, 5)
    check(t["finite_logs"], 4, 5)
    check(t["beats_pid_pd"], 3, 5)
    check(s["by_airspeed"]["[5,8)"]["pred_err_every_bin"], 0, 2)    # only the two bad draws have the bin
    check(s["by_airspeed"]["[0,2)"]["pred_err_every_bin"], 5, 5)
    assert s["by_airspeed"]["[11,inf)"]["pred_err_every_bin"]["n"] == 0
    check(s["groups"]["side"]["a"]["pred_err_every_bin"], 2, 2)
    check(s["groups"]["side"]["b"]["pred_err_every_bin"], 1, 3)
    check(s["groups"]["side"]["b"]["beats_pid_pd"], 2, 3)
    check(s["controllers"]["tracking_only"]["beats_pid_pd"], 4, 5)
    check(s["controllers"]["composite"]["beats_pid_pd"], 4, 5)
    check(s["controllers"]["pd"]["finite_logs"], 4, 5)
    assert "beats_pid_pd" not in s["controllers"]["pid"]
    assert s["controllers"]["composite"]["pred_err_p95_g_worst_bin"]["median"] == pytest.approx(0.04)  # 3 of 5 at 0.04
    assert PRED_ERR_BOUND_G == 0.05


@settings(max_examples=examples(60), deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.booleans()), min_size=1, max_size=60),
       st.floats(0.001, 0.1))
def test_alpha_excursions_match_a_plain_loop(samples, dt):
    counted = np.array([c for c, _ in samples])
    past = np.array([p for _, p in samples])
    alpha = np.where(past, 0.5, 0.1)
    frac, longest = alpha_excursions(alpha, counted, 0.3, dt)
    run = best = hits = 0
    for c, p in samples:
        run = run + 1 if (c and p) else 0
        best = max(best, run)
        hits += c and p
    n = int(counted.sum())
    assert frac == pytest.approx(hits / n if n else 0.0)
    assert longest == pytest.approx(best * dt if n else 0.0)


# --- the README -----------------------------------------------------------------------------------
def test_readme_envelope_tables_are_generated_from_the_committed_summary():
    """The site's envelope page holds what envelope_readme renders from docs/envelope_summary.json, and
    the README its targets."""
    from vtoladapt.experiments.envelope_readme import HEADLINE_BEGIN, HEADLINE_END, envelope_headline
    from vtoladapt.experiments.readme import readme_block as block_between

    summary = json.loads((REPO / "docs" / "envelope_summary.json").read_text())
    assert readme_block((REPO / "docs" / "explanation" / "envelope.md").read_text()) == envelope_tables(summary)
    assert block_between((REPO / "README.md").read_text(), HEADLINE_BEGIN, HEADLINE_END) == \
        envelope_headline(summary).strip("\n") + "\n"


def test_the_envelope_readme_tool_refuses_bad_input_and_writes_nothing(tmp_path, capsys):
    """A missing or foreign summary, or a README without the markers: one line, status 2, no write."""
    import json
    import shutil

    from vtoladapt.experiments import envelope_readme as tool

    readme = tmp_path / "README.md"
    readme.write_text(f"intro\n{tool.BEGIN}\nold\n{tool.END}\n")
    DOCS_SUMMARY = REPO / "docs" / "envelope_summary.json"
    good = json.loads(DOCS_SUMMARY.read_text())
    foreign = tmp_path / "foreign.json"
    foreign.write_text(json.dumps({**good, "campaign": {**good["campaign"], "file": "tiny.toml"}}))
    partial = tmp_path / "partial" / "summary.json"
    partial.parent.mkdir()
    partial.write_text(json.dumps({"campaign": {"file": "scenarios/envelope.toml"}}))
    no_markers = tmp_path / "plain.md"
    no_markers.write_text("no block here\n")
    cases = [([str(tmp_path / "missing.json"), str(readme)], "no such file"),
             ([str(foreign), str(readme)], "campaign file = 'tiny.toml'"),
             ([str(partial), str(readme)], "not a complete envelope summary.json"),
             ([str(DOCS_SUMMARY), str(no_markers)], "README has no block"),
             ([str(readme)], "usage:")]
    for argv, needle in cases:
        assert tool.run_tool("envelope_readme", "usage: ...", argv, {(2, None): tool.update_readme}) == 2
        err = capsys.readouterr().err
        assert needle in err and len(err.strip().splitlines()) == 1, err
    assert readme.read_text() == f"intro\n{tool.BEGIN}\nold\n{tool.END}\n"
    assert no_markers.read_text() == "no block here\n"
    assert not (tmp_path / "docs").exists()
    # a README in a folder without docs/: the folder is made, the block and the copy written
    shutil.copyfile(DOCS_SUMMARY, tmp_path / "summary.json")
    assert tool.run_tool("envelope_readme", "", [str(tmp_path / "summary.json"), str(readme)],
                         {(2, None): tool.update_readme}) == 0
    assert tool.readme_block(readme.read_text()) == tool.envelope_tables(good).strip("\n") + "\n"
    assert json.loads((tmp_path / "docs" / "envelope_summary.json").read_text()) == good
