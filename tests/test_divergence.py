"""The divergence monitor: a run that leaves its [envelope] stops, keeps its log, says when and why."""
from __future__ import annotations

import copy
import dataclasses
import json

import numpy as np
import pytest

from vtoladapt.campaign.runner import RunSpec, run_campaign
from vtoladapt.config import ConfigError
from vtoladapt.layout import STATE_COLUMNS
from vtoladapt.sim.monitor import DivergenceError
from vtoladapt.sim.monitor import EnvelopeConfig as EnvelopeDefault
from vtoladapt.sim.results import SimulationResult
from vtoladapt.sim.scenario import scenario_from_mapping
from vtoladapt.sim.driver import simulate

DT = 0.004


def _mapping(**extra):
    data = {"name": "div", "vehicle": "caltech_vtol", "duration_s": 2.0, "seed": 1}
    data.update(extra)
    return data


def _run(**extra):
    return simulate(scenario_from_mapping(_mapping(**extra), "tests/test_divergence.py"))


def _forced(obj, **changes):
    """A copy of frozen settings ``obj`` with ``changes`` written past its validation."""
    out = copy.copy(obj)  # copies without __post_init__, so without the checks
    for name, value in changes.items():
        object.__setattr__(out, name, value)
    return out


def _absurd_thrust_scenario(duration_s: float = 2.0):
    """CTz = 1e10: the input ranges refuse it in a file and in Python (tests below), so the scenario
    is forced past them, as only a determined program can, to see that the loop itself still stops
    such a run."""
    s = scenario_from_mapping(_mapping(duration_s=duration_s), "tests/test_divergence.py")
    coeffs = _forced(s.plant.coefficients, CTz=1e10)
    return _forced(s, plant=_forced(s.plant, coefficients=coeffs))


def test_absurd_thrust_coefficient_is_refused_in_a_file():
    with pytest.raises(ConfigError, match=r"\[plant.coefficients\] CTz = 10000000000.0: out of range"):
        _run(plant={"coefficients": {"CTz": 1e10}})


def test_absurd_thrust_coefficient_is_refused_in_python():
    s = scenario_from_mapping(_mapping(), "tests/test_divergence.py")
    with pytest.raises(ConfigError, match=r"PlantCoefficients: \[plant.coefficients\] CTz = 10000000000.0: out"):
        dataclasses.replace(s.plant.coefficients, CTz=1e10)


def test_absurd_thrust_coefficient_stops_at_the_first_ticks():
    """Issue #15: CTz = 1e10 made NaN from the first tick and a run 'succeeded' with NaN metrics."""
    res = simulate(_absurd_thrust_scenario())
    assert res.diverged
    assert res.diverged_at_s <= 2 * DT
    assert len(res) == round(res.diverged_at_s / DT)
    assert res.divergence_reason.startswith(("non-finite state", "speed", "body rate"))
    assert "\n" not in res.divergence_reason
    state = res.columns_like(STATE_COLUMNS)
    assert np.isfinite(state).all()
    with pytest.raises(DivergenceError, match="run diverged: "):
        res.raise_if_diverged()


def test_a_healthy_run_is_not_diverged_and_returns_itself():
    res = _run(duration_s=0.5)
    assert not res.diverged and res.diverged_at_s is None and res.divergence_reason is None
    assert len(res) == 125
    assert res.raise_if_diverged() is res


def test_speed_limit_stops_the_run_where_the_logged_speed_crosses_it():
    """Envelope tightened below the turbulent hover's own speed: the monitor must stop at the
    first tick whose state exceeds it, so every logged row is inside and the next is not."""
    limit = 0.05
    res = _run(wind={"fan_array": {"schedule": [[0, 60], [2, 60]]}, "turbulence": {"enabled": True, "mean_wind_fraction": [0.04, 0.04, 0.03]}},
               envelope={"max_speed_mps": limit})
    assert res.diverged and "speed" in res.divergence_reason and f"{limit:g}" in res.divergence_reason
    speed = np.linalg.norm(res.velocity_W, axis=1)
    assert (speed <= limit).all()
    full = _run(wind={"fan_array": {"schedule": [[0, 60], [2, 60]]}, "turbulence": {"enabled": True, "mean_wind_fraction": [0.04, 0.04, 0.03]}},
                envelope={"enabled": False})
    full_speed = np.linalg.norm(full.velocity_W, axis=1)
    first_out = int(np.argmax(full_speed > limit))
    assert len(res) == first_out
    assert res.diverged_at_s == pytest.approx(first_out * DT)
    np.testing.assert_array_equal(res.data, full.data[:first_out])


def test_height_band():
    res = _run(reference={"kind": "hold", "position_m": [0.0, 0.0, -3.0]}, envelope={"max_height_m": 2.0})
    assert res.diverged and res.divergence_reason.startswith("height")
    assert (-res["p_D_m"] <= 2.0).all()


def test_divergence_survives_the_parquet_round_trip(tmp_path):
    res = simulate(_absurd_thrust_scenario())
    back = SimulationResult.from_parquet(res.to_parquet(tmp_path / "log.parquet"))
    assert back.diverged_at_s == res.diverged_at_s and back.divergence_reason == res.divergence_reason


def test_envelope_errors_are_one_line():
    with pytest.raises(ConfigError) as exc:
        scenario_from_mapping(_mapping(envelope={"min_height_m": 5.0, "max_height_m": 1.0}), "e.toml")
    assert "\n" not in str(exc.value) and "e.toml: [envelope] min_height_m = 5" in str(exc.value)
    with pytest.raises(ConfigError, match=r"\[envelope\] max_speed_mps = -1"):
        scenario_from_mapping(_mapping(envelope={"max_speed_mps": -1.0}), "e.toml")


def test_campaign_counts_diverged_runs_and_goes_on(tmp_path):
    specs = [RunSpec(0, _mapping(duration_s=0.5), "a.toml", {"seed": 1}),
             # climbs through a 2 m ceiling at about 0.5 s: leaves its envelope, the campaign goes on
             RunSpec(1, _mapping(duration_s=1.0, reference={"kind": "hold", "position_m": [0.0, 0.0, -3.0]},
                                 envelope={"max_height_m": 2.0}), "b.toml", {"seed": 2}),
             RunSpec(2, _mapping(duration_s=0.5, seed=3), "c.toml", {"seed": 3})]
    rows = run_campaign(specs, tmp_path, scheduler="none", n_workers=1, show_progress=False)
    assert [r["diverged"] for r in rows] == [0.0, 1.0, 0.0]
    assert np.isfinite(rows[2]["pos_err_max_m"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["diverged_runs"] == 1 and summary["runs"] == 3


def test_cli_run_that_diverges_exits_1_with_one_line_and_keeps_its_outputs(tmp_path, capsys):
    from vtoladapt.cli import main

    path = tmp_path / "height_band.toml"
    path.write_text('name = "height_band"\nvehicle = "caltech_vtol"\nduration_s = 3.0\n'
                    '[reference]\nkind = "hold"\nposition_m = [0.0, 0.0, -3.0]\n'
                    '[envelope]\nmax_height_m = 2.0\n')
    out = tmp_path / "o"
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "height_band: run diverged: height" in err[0] and "max_height_m = 2" in err[0]
    metrics = json.loads((out / "metrics.json").read_text())
    (entry,) = metrics["divergence"]
    assert entry["run"] == "height_band" and 0.0 < entry["diverged_at_s"] < 3.0
    back = SimulationResult.from_parquet(out / "log.parquet")
    assert back.diverged_at_s == entry["diverged_at_s"] and np.all(np.isfinite(back["p_D_m"]))
    # the reports said nothing of it: their metrics cover the time before, not the 3 s in the title
    for name in ("report.md", "report.html"):
        text = (out / name).read_text()
        assert "Diverged:" in text and f"t = {entry['diverged_at_s']:g} s of 3 s" in text, name


def test_the_readme_divergence_example_runs_as_written():
    """README "The envelope": the example used CTz = 1e10, which the input ranges refuse."""
    import re
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    (code,) = [b for b in re.findall(r"```python\n(.*?)```", readme, re.S) if "raise_if_diverged()" in b]
    lines = code.splitlines()
    setup = "\n".join(line for line in lines if not line.startswith("res."))
    namespace: dict = {}
    exec(compile(setup, "README.md", "exec"), namespace)
    res = namespace["res"]
    shown = {m.group(1): m.group(2) for m in (re.match(r"res\.(\w+)\(?\)?\s+# (.*)", line) for line in lines) if m}
    assert res.diverged
    assert shown["diverged_at_s"].startswith(f"{res.diverged_at_s:g}:")
    assert shown["divergence_reason"] == repr(res.divergence_reason)
    with pytest.raises(DivergenceError):
        res.raise_if_diverged()


def test_a_vehicle_far_from_its_reference_is_lost_whatever_its_speed_and_height():
    """A run pushed off its hold point stops at the first tick whose distance from the reference,
    computed from the same run's log without the bound, exceeds envelope.max_position_error_m."""
    gusty = {"duration_s": 4.0, "wind": {"gusts": [{"shape": "step", "start_s": 0.5, "duration_s": 1.0, "amplitude_mps": [8.0, 0.0, 0.0]}]}}
    free = _run(**gusty)
    err_m = np.linalg.norm(free.columns_like(["p_N_m", "p_E_m", "p_D_m"])
                           - free.columns_like(["ref_p_N_m", "ref_p_E_m", "ref_p_D_m"]), axis=1)
    assert not free.diverged and err_m.max() > 0.2
    bound_m = 0.5 * err_m.max()
    first = int(np.argmax(err_m > bound_m))
    res = _run(envelope={"max_position_error_m": bound_m}, **gusty)
    assert res.diverged and res.diverged_at_s == pytest.approx(first * DT)
    np.testing.assert_array_equal(res.data, free.data[:first])   # the same flight up to there
    assert res.divergence_reason.startswith(f"position {err_m[first]:.3g} m from the reference, above "
                                            f"envelope.max_position_error_m = {bound_m:g}")
    # the default bound is far outside that flight
    assert EnvelopeDefault().max_position_error_m == 1000.0 > 100 * err_m.max()


def test_a_start_far_from_the_reference_stops_before_the_first_tick():
    res = _run(initial={"position_m": [0.0, 0.0, -1.5]},
               reference={"kind": "hold", "position_m": [3.0, 4.0, -1.5]},
               envelope={"max_position_error_m": 2.0})
    assert res.diverged and res.diverged_at_s == 0.0 and len(res) == 0
    assert res.divergence_reason == ("position 5 m from the reference, above envelope.max_position_error_m = 2, "
                                     "at t = 0.000 s")


# --- issue #27, item 7: a non-finite state stops the run with the envelope off too --------------------

def _nan_without_envelope():
    """A plant of 1e-300 kg (refused by the ranges, forced past them) with [envelope] enabled = false:
    before the fix NaN from the first tick, every metric null, exit 0."""
    s = scenario_from_mapping(_mapping(duration_s=1.0, envelope={"enabled": False}), "nan.toml")
    return _forced(s, plant=_forced(s.plant, mass_kg=1e-300))


def test_a_non_finite_state_stops_the_run_with_the_envelope_off():
    res = simulate(_nan_without_envelope())
    assert res.diverged and res.divergence_reason.startswith("non-finite state")
    assert np.isfinite(res.columns_like(STATE_COLUMNS)).all()
    with pytest.raises(DivergenceError):
        res.raise_if_diverged()


def test_cli_run_with_a_non_finite_state_exits_1_with_the_envelope_off(tmp_path, monkeypatch, capsys):
    import vtoladapt.cli as cli

    monkeypatch.setattr(cli, "load_run_scenario", lambda *a, **k: _nan_without_envelope())
    assert cli.main(["run", "nan.toml", "--out", str(tmp_path / "o"), "--quiet"]) == 1
    assert "run diverged: non-finite state" in capsys.readouterr().err


def test_campaign_counts_a_non_finite_run_as_diverged_with_the_envelope_off(tmp_path, monkeypatch):
    import vtoladapt.sim.scenario as scenario_module

    real = scenario_module.scenario_from_mapping
    monkeypatch.setattr(scenario_module, "scenario_from_mapping",
                        lambda m, source, **k: _nan_without_envelope() if source == "nan.toml" else real(m, source, **k))
    specs = [RunSpec(0, _mapping(duration_s=0.5), "a.toml", {"seed": 1}),
             RunSpec(1, _mapping(duration_s=0.5), "nan.toml", {"seed": 2})]
    rows = run_campaign(specs, tmp_path, scheduler="none", n_workers=1, show_progress=False)
    assert [r["diverged"] for r in rows] == [0.0, 1.0]
    assert json.loads((tmp_path / "summary.json").read_text())["diverged_runs"] == 1
