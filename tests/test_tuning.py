"""One tuning budget for every law (:mod:`vtoladapt.experiments.tuning`, ``vtoladapt tune``).

* Every law's declared gains are settings of the law, inside their allowed ranges; bad declarations
  are refused.
* The search spends exactly its budget, starts from the defaults and finds the minimum of an
  analytic objective (no flight: the objective is replaced).
* The tuning draws are disjoint from the evaluation variants.
* The tuned settings file round-trips through TOML and ``load_controller_config``; the shipped
  files cover every law with one budget.
* The command line writes the files, refuses bad input with exit 2, and ``run --tuned`` flies the
  tuned law.
"""
from __future__ import annotations

import json
import math
import tomllib
from dataclasses import replace

import numpy as np
import pytest

from vtoladapt.cli import main
from vtoladapt.control import ControllerConfig, load_controller_config
from vtoladapt.control.registry import CONTROLLERS, controller_ids
from vtoladapt.experiments import tuning
from vtoladapt.experiments.distribution import variant_seeds
from vtoladapt.sim.scenario import SCENARIO_DIR, load_scenario, scenario_from_mapping

SHORT = """name = "short"
vehicle = "caltech_vtol"
duration_s = 1.0
seed = 5
[wind.fan_array]
schedule = [[0, 40], [1, 40]]
"""


SHARED = ["controller.K_v[0:2]", "controller.K_v[2]", "controller.Lambda_p[0:2]", "controller.Lambda_p[2]",
          "controller.Lambda_q[0:2]"]


def test_every_law_searches_the_shared_gains_and_its_own_inside_their_ranges():
    for cid in controller_ids():
        specs = tuning.tunables(cid)
        assert [t.name for t in specs[:len(SHARED)]] == SHARED          # the same shared space for every law
        config = ControllerConfig(kind=cid)
        # the defaults are what the first evaluation flies: setting them changes nothing
        assert tuning.with_gains(config, cid, tuning.settings_of(config, cid)) == config
        # the box's corners and centre are settings each gain accepts (a combination a law's own rule
        # refuses, e.g. INDI's filter against the largest K_v, is refused as a whole: not flown)
        for u in (0.0, 0.5, 1.0):
            for t in specs:
                tuned = tuning.with_gains(replace(config, K_v=(0.5, 0.5, 1.0)), cid, {t.name: t.value(u)})
                assert tuning.settings_of(tuned, cid)[t.name] == pytest.approx(t.value(u), rel=1e-12)
    assert [t.name for t in tuning.tunables("nominal")] == SHARED
    assert [t.name for t in tuning.tunables("l1")] == SHARED + ["cutoff_radps", "predictor_pole_radps"]
    indi = tuning.tunables("indi")[len(SHARED)]
    assert indi.shared and indi.key == "lowpass_cutoff_hz"


def test_components_of_a_tuple_gain_are_set_together():
    config = ControllerConfig(kind="pid")
    tuned = tuning.with_gains(config, "pid", {"K_I[0:2]": 1.5, "K_I[2]": 3.0})
    assert tuned.pid.K_I == (1.5, 1.5, 3.0) and tuned.pid.K_D == config.pid.K_D
    assert tuned.K_v == config.K_v


@pytest.mark.parametrize("entry, match", [
    (("no_such", 0.1, 1.0, True), "has no key"),
    (("K_I", 0.1, 1.0, True), "is a tuple"),
    (("K_I[2:5]", 0.1, 1.0, True), "components"),
    (("K_I[0]", 1.0, 0.5, True), "non-empty"),
    (("K_D[0]", 0.0, 1.0, True), "above 0"),
    (("K_D[0]", -1.0, 1.0, False), "allowed range"),
    (("controller.no_such", 1.0, 2.0, True), "has no key"),
    (("controller.K_v[0:2]", 1.0, 2.0, True), "already searched"),     # a shared gain declared again
    (("controller.Lambda_q[1]", 1.0, 2.0, True), "already searched"),   # ... or a component of one
])
def test_bad_declarations_are_refused(monkeypatch, entry, match):
    monkeypatch.setattr(CONTROLLERS["pid"].law, "TUNABLE", (entry,))
    with pytest.raises(ValueError, match=match):
        tuning.tunables("pid")


def test_tuning_draws_are_disjoint_from_the_evaluation_variants():
    seeds = tuning.tuning_seeds(2020, 50)
    assert len(set(seeds)) == 50 and tuning.tuning_seeds(2020, 10) == seeds[:10]
    assert not set(seeds) & set(variant_seeds(2020, 10000))


def test_the_search_spends_its_budget_and_finds_an_analytic_minimum(monkeypatch):
    """The objective replaced by a bowl in log(K_v north/east), log(cutoff), log(pole) with its
    minimum inside the box (the shared gains cut to K_v's horizontal pair, so three dimensions):
    exactly ``evaluations`` evaluations, the first the defaults, the best near the minimum."""
    from vtoladapt.control import settings as shared_config

    monkeypatch.setattr(shared_config, "TUNABLE", (("K_v[0:2]", 0.5, 8.0, True),))
    target = {"controller.K_v[0:2]": 3.0, "cutoff_radps": 6.0, "predictor_pole_radps": 30.0}
    calls = []

    def bowl(scenario, config, seeds, progress=None):
        calls.append(config)
        x = math.log(config.l1.cutoff_radps / target["cutoff_radps"])
        y = math.log(config.l1.predictor_pole_radps / target["predictor_pole_radps"])
        z = math.log(config.K_v[0] / target["controller.K_v[0:2]"])
        return 0.04 + x * x + 0.5 * y * y + z * z, [0.0] * len(seeds)

    monkeypatch.setattr(tuning, "objective", bowl)
    scenario = scenario_from_mapping(tomllib.loads(SHORT), "short.toml")
    rec = tuning.tune(scenario, "l1", evaluations=80, draws=3)
    assert len(calls) == 80 == rec["budget"]["evaluations"]
    assert calls[0] == replace(scenario.controller, kind="l1")      # the defaults first
    assert rec["default"]["settings"] == {"controller.K_v[0:2]": 1.8, "cutoff_radps": 2.5,
                                          "predictor_pole_radps": 10.0}
    assert rec["tuned"]["objective"] <= rec["default"]["objective"]
    for k, v in target.items():
        assert abs(math.log(rec["tuned"]["settings"][k] / v)) < 0.15, (k, rec["tuned"]["settings"])
    assert all(c.K_v[2] == scenario.controller.K_v[2] for c in calls)   # the vertical gain is not searched here
    assert rec["tuning_seeds"] == tuning.tuning_seeds(5, 3)
    # a law with nothing to tune (no shared gains declared, none of its own): one evaluation, its defaults
    monkeypatch.setattr(shared_config, "TUNABLE", ())
    rec = tuning.tune(scenario, "nominal", evaluations=40, draws=3)
    assert rec["budget"]["evaluations"] == 1 and rec["tuned"]["settings"] == {}


def test_every_run_is_measured_with_the_scenarios_position_gain():
    """A law flying a tuned Lambda_p is scored with the scenario's: the objective equals the RMS of
    ``v - (v_d - Lambda_p,scenario (p - p_d))`` computed here from the log (no limit reached)."""
    from vtoladapt.sim.driver import simulate

    scenario = scenario_from_mapping(tomllib.loads(SHORT), "short.toml")
    config = replace(scenario.controller, kind="nominal", Lambda_p=(3.0, 3.0, 2.5))
    mean, per_draw = tuning.objective(scenario, config, [7])
    res = simulate(replace(scenario, seed=7, controller=config))
    p_err = res.position_W - res.columns_like(("ref_p_N_m", "ref_p_E_m", "ref_p_D_m"))
    v_d = res.columns_like(("ref_v_N_mps", "ref_v_E_mps", "ref_v_D_mps"))
    lam = np.asarray(scenario.controller.Lambda_p)
    expected = float(np.sqrt(np.mean(np.sum((res.velocity_W - v_d + lam * p_err) ** 2, axis=1))))
    assert mean == per_draw[0] == pytest.approx(expected, rel=1e-12)
    own = float(np.sqrt(np.mean(np.sum(res.velocity_error_W ** 2, axis=1))))   # with the gain it flew
    assert abs(own - expected) > 1e-6 * expected
    measured = res.measured_with(scenario.controller.Lambda_p)
    assert measured.data is res.data and res.metadata["Lambda_p"] == [3.0, 3.0, 2.5]    # shared, untouched
    with pytest.raises(ValueError, match="three finite values"):
        res.measured_with((1.0, float("nan"), 1.0))


def test_box_edges():
    assert tuning.box_edge(0.5, 0.5, 100.0, True) == "bottom"
    assert tuning.box_edge(100.0 * 0.8, 0.5, 100.0, True) == "top"           # log: 0.8 x the top is 4 % below it
    assert tuning.box_edge(1.0, 0.0, 2.0, False) is None
    assert tuning.box_edge(1.85, 0.0, 2.0, False) == "top" and tuning.box_edge(1.75, 0.0, 2.0, False) is None
    assert tuning.box_edge(0.5 * 1.5, 0.5, 100.0, True) == "bottom"    # log: 1.5 x the bottom is 7.7 % above it


def test_tuned_file_round_trips_and_keeps_the_scenarios_other_settings(tmp_path):
    scenario = scenario_from_mapping({**tomllib.loads(SHORT), "controller": {"K_v": [2.0, 2.0, 4.5]}}, "s.toml")
    record = {"scenario": "short", "controller": "pid", "objective": "vel_err_rms_mps",
              "objective_description": "d", "optimiser": tuning.OPTIMISER,
              "budget": {"evaluations": 3, "draws": 2}, "tuning_seeds": [1, 2],
              "tunables": [{"name": t.name, "low": t.low, "high": t.high, "log_scale": t.log_scale}
                           for t in tuning.tunables("pid")],
              "default": {"settings": {"K_I[0:2]": 0.4}, "objective": 0.1},
              "tuned": {"settings": {"controller.K_v[0:2]": 3.0, "K_I[0:2]": 1.25, "K_I[2]": 3.5, "K_D[0:2]": 0.3,
                                     "derivative_cutoff_hz": 2.0}, "objective": 0.05, "evaluation": 2}}
    path = tmp_path / "short_pid.toml"
    path.write_text(tuning.tuned_file_text(record, scenario))
    config = load_controller_config(path)
    assert config.kind == "pid" and config.pid.K_I == (1.25, 1.25, 3.5) and config.pid.derivative_cutoff_hz == 2.0
    kind, shared, law, rec = tuning.read_tuned_file(path)
    assert kind == "pid" and shared["K_v"] == [3.0, 3.0, 4.5] and rec["tuned_objective_mps"] == 0.05
    assert rec["box"]["K_I[0:2]"] == [0.05, 20.0, "log"] and rec["box"]["K_D[0:2]"] == [0.0, 2.0, "linear"]
    assert rec["box"]["controller.K_v[0:2]"] == [0.5, 8.0, "log"]
    flown = tuning.tuned_controller(replace(scenario.controller, Lambda_q=(12.0, 12.0, 5.0)), path)
    assert flown.kind == "pid" and flown.pid.K_I == (1.25, 1.25, 3.5)
    assert flown.K_v == (3.0, 3.0, 4.5)                              # tuned north/east, the scenario's down
    # every searched shared gain comes from the file: one the search left is the tuning scenario's
    assert flown.Lambda_p == scenario.controller.Lambda_p
    assert flown.Lambda_q == (10.0, 10.0, 6.0)
    bad = tmp_path / "bad.toml"
    bad.write_text('[controller]\nkind = "pid"\n[controller.pid]\nK_I = [1.0, -1.0, 1.0]\n')
    with pytest.raises(ValueError, match="bad.toml"):
        tuning.tuned_controller(scenario.controller, bad)


def test_shipped_tuned_files_cover_every_law_with_one_budget():
    """make reproduce's tuned settings: one file per law, the same budget, never worse than the
    defaults on the tuning draws, every gain inside its declared box."""
    budgets = set()
    # the laws of the shipped comparison (a law registered after it, composite_indi, has no shipped file yet)
    for cid in load_scenario(SCENARIO_DIR / "paper_comparison.toml").experiment.controllers:
        path = tuning.shipped_tuned_file("paper_comparison", cid)
        kind, shared, law, rec = tuning.read_tuned_file(path)
        assert kind == cid
        assert rec["tuned_objective_mps"] <= rec["default_objective_mps"]
        assert rec["tuning_seeds"] == tuning.tuning_seeds(2020, rec["draws"])
        specs = tuning.tunables(cid)
        if specs:
            budgets.add((rec["evaluations"], rec["draws"]))
        config = tuning.tuned_controller(ControllerConfig(), path)
        for t in specs:
            v = tuning.settings_of(config, cid)[t.name]
            if t.name in tuning.NOT_IN_SHIPPED_FILES and t.name not in rec["box"]:
                default = tuning.settings_of(ControllerConfig(kind=cid), cid)[t.name]
                assert v == default, (cid, t.name, v)     # not searched yet: the default flies
                continue
            assert t.low <= v <= t.high, (cid, t.name, v)
            # the file was searched in the box declared today
            assert rec["box"][t.name] == [t.low, t.high, "log" if t.log_scale else "linear"], (cid, t.name)
        assert set(rec["box"]) == {t.name for t in specs} - set(tuning.NOT_IN_SHIPPED_FILES)
    assert budgets == {(tuning.EVALUATIONS, tuning.DRAWS)}
    assert load_scenario(SCENARIO_DIR / "paper_comparison.toml").seed == 2020


def test_tune_command_writes_the_files_and_refuses_bad_input(tmp_path, capsys):
    scenario = tmp_path / "short.toml"
    scenario.write_text(SHORT)
    out = tmp_path / "tuned"
    assert main(["tune", str(scenario), "--controller", "l1", "--out", str(out), "--evaluations", "2",
                 "--draws", "1", "--quiet"]) == 0
    rec = json.loads((out / "short_l1.json").read_text())
    assert rec["budget"]["evaluations"] == 2 and len(rec["trace"]) == 2
    assert load_controller_config(out / "short_l1.toml").kind == "l1"
    for args, match in ((["--controller", "nope"], "--controller 'nope'"),
                        (["--controller", "l1", "--evaluations", "0"], "--evaluations")):
        code = main(["tune", str(scenario), "--out", str(tmp_path / "x"), "--quiet", *args])
        err = capsys.readouterr().err
        assert code == 2 and match in err and not (tmp_path / "x").exists()
    # run --tuned flies the tuned law alone, with its gains
    run = tmp_path / "run"
    assert main(["run", str(scenario), "--tuned", str(out / "short_l1.toml"), "--out", str(run), "--quiet"]) == 0
    assert json.loads((run / "metrics.json").read_text())["run"]["vel_err_rms_mps"] > 0.0
    code = main(["run", str(scenario), "--tuned", str(out / "short_l1.toml"), "--controller", "pid",
                 "--out", str(tmp_path / "r2"), "--quiet"])
    assert code == 2 and "the file tunes l1" in capsys.readouterr().err


def test_tuned_comparison_pairs_tuned_with_default(monkeypatch, tmp_path):
    """Laws whose tuned settings are their defaults are not flown again: their tuned values are the
    default ones and their paired difference is exactly zero."""
    scenario = scenario_from_mapping({**tomllib.loads(SHORT), "experiment": {
        "kind": "comparison", "controllers": ["nominal", "pd"]}}, "s.toml")
    for cid in ("nominal", "pd"):
        record = {"scenario": "short", "controller": cid, "objective": "vel_err_rms_mps",
                  "objective_description": "d", "optimiser": "x", "budget": {"evaluations": 1, "draws": 1},
                  "tuning_seeds": [1], "default": {"settings": {}, "objective": 0.1},
                  "tuned": {"settings": {} if cid == "nominal" else {"K_D[0:2]": 0.5}, "objective": 0.1,
                            "evaluation": 1}}
        (tmp_path / f"short_{cid}.toml").write_text(tuning.tuned_file_text(record, scenario))
    from vtoladapt.experiments.distribution import comparison_distribution

    default = comparison_distribution(scenario, 6)
    tuned = tuning.tuned_comparison(scenario, 6, default, tuned_dir=tmp_path)
    assert tuned["flown"] == ["pd"]
    assert tuned["per_variant"]["nominal"] == default["per_variant"]["nominal"]
    d = tuned["vs_default"]["nominal"]["vel_err_rms_mps"]
    assert d["estimate"] == 0.0 and d["verdict"] == "tied"
    assert tuned["settings"]["pd"]["tuned"]["K_D[0:2]"] == 0.5
    assert tuned["per_variant"]["pd"]["vel_err_rms_mps"] != default["per_variant"]["pd"]["vel_err_rms_mps"]
    assert set(tuned["paired"]["pairs"]["vel_err_rms_mps"]) == {"nominal|pd"}
    assert np.isfinite(tuned["controllers"]["pd"]["vel_err_rms_mps"]["median"])
    assert replace(scenario.controller, kind="pd") != tuning.tuned_controller(scenario.controller,
                                                                            tmp_path / "short_pd.toml")


def test_readme_lists_every_declared_gain_with_its_box():
    """The how-to "Tuning a law's gains" (docs/howto/tuning.md): a row for the shared gains and one
    per law naming each of its own gains, each with its box."""
    from doc_pages import page

    section = page("docs/howto/tuning.md")
    rows = {line.strip().split("|")[1].strip().strip("`"): line for line in section.splitlines()
            if line.strip().startswith("| `")}
    rows["every law"] = next(line for line in section.splitlines() if line.startswith("  | every law"))
    for cid in controller_ids():
        for t in tuning.tunables(cid):
            row = rows["every law" if t.name in SHARED else cid]
            name = t.name.removeprefix("controller.") if t.name in SHARED else t.name
            low, high = (f"{x:g}".replace("e-0", "e-") for x in (t.low, t.high))
            assert f"`{name}` {low}-{high}" in row, (cid, t.name)
            assert ("(linear)" in row.split(f"`{name}`")[1].split(",")[0]) != t.log_scale, (cid, t.name)


def test_a_tuned_file_is_not_a_scenario():
    """The shipped tuned files sit beside the scenarios: not listed as scenarios, refused as one with a hint."""
    from vtoladapt.config import ConfigError
    from vtoladapt.sim.scenario import shipped_scenario_names

    assert not any(n.startswith("tuned/") for n in shipped_scenario_names())
    with pytest.raises(ConfigError, match=r"a tuned settings file .* vtoladapt run SCENARIO --tuned"):
        load_scenario(tuning.shipped_tuned_file("paper_comparison", "l1"))


def test_every_adaptive_law_searches_its_adaptation_gain():
    """Issue #34, defect 5: the adaptation gain (a log multiplier of P0, 1e-2 to 1e3) is in the space of every
    law whose theta-hat adapts, and a tuned value reaches the compiled P0 and its inverse; L1's adaptation rate
    is its predictor pole and filter, already searched."""
    from vtoladapt import load_vehicle
    from vtoladapt.bases import describe_basis
    from vtoladapt.control.blocks import A_GAMMA0, A_P0
    from vtoladapt.control.registry import theta_adaptive_ids

    assert set(theta_adaptive_ids()) == {"composite", "composite_pconst", "tracking_only", "composite_indi"}
    for cid in theta_adaptive_ids():
        t = {x.name: x for x in tuning.tunables(cid)}["adaptation_gain_scale"]
        assert (t.low, t.high, t.log_scale, t.shared) == (1e-2, 1e3, True, False)
    assert {"cutoff_radps", "predictor_pole_radps"} <= {x.name for x in tuning.tunables("l1")}
    vehicle = load_vehicle("caltech_vtol")
    P0_basis = np.diag(describe_basis(vehicle).P0_diag)
    n = len(P0_basis)
    for cid in theta_adaptive_ids():
        for k in (1.0, 37.0):
            config = tuning.with_gains(ControllerConfig(), cid, {"adaptation_gain_scale": k})
            assert getattr(config, cid).adaptation_gain_scale == k
            params = config.to_kernel(vehicle)
            P0 = params[int(params[A_P0]):int(params[A_P0]) + n * n].reshape(n, n)
            Gamma0 = params[int(params[A_GAMMA0]):int(params[A_GAMMA0]) + n * n].reshape(n, n)
            np.testing.assert_allclose(P0, k * P0_basis, rtol=1e-15, atol=0.0)
            np.testing.assert_allclose(Gamma0 @ P0, np.eye(n), rtol=0.0, atol=1e-12)
    # the default flies P0 bit for bit as before
    params = ControllerConfig(kind="composite").to_kernel(vehicle)
    np.testing.assert_array_equal(params[int(params[A_P0]):int(params[A_P0]) + n * n], P0_basis.ravel())
