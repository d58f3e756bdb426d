"""The divergence monitor: a run that leaves its [envelope] stops, keeps its log, says when and why."""
from __future__ import annotations

import json

import numpy as np
import pytest

from vtoladapt.campaign import RunSpec, run_campaign
from vtoladapt.config import ConfigError
from vtoladapt.monitor import DivergenceError
from vtoladapt.results import SimulationResult
from vtoladapt.scenario import scenario_from_mapping
from vtoladapt.simulate import simulate

DT = 0.004


def _mapping(**extra):
    data = {"name": "div", "vehicle": "caltech_vtol", "duration_s": 2.0, "seed": 1}
    data.update(extra)
    return data


def _run(**extra):
    return simulate(scenario_from_mapping(_mapping(**extra), "tests/test_divergence.py"))


def test_absurd_thrust_coefficient_stops_at_the_first_ticks():
    """Issue #15: CTz = 1e10 made NaN from the first tick and a run 'succeeded' with NaN metrics."""
    res = _run(plant={"coefficients": {"CTz": 1e10}})
    assert res.diverged
    assert res.diverged_at_s <= 2 * DT
    assert len(res) == round(res.diverged_at_s / DT)
    assert res.divergence_reason.startswith(("non-finite state", "speed", "body rate"))
    assert "\n" not in res.divergence_reason
    state = res.data[:, 1:1 + 18]
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
    res = _run(plant={"coefficients": {"CTz": 1e10}})
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
             RunSpec(1, _mapping(duration_s=0.5, plant={"coefficients": {"CTz": 1e10}}), "b.toml", {"seed": 2}),
             RunSpec(2, _mapping(duration_s=0.5, seed=3), "c.toml", {"seed": 3})]
    rows = run_campaign(specs, tmp_path, scheduler="none", n_workers=1, show_progress=False)
    assert [r["diverged"] for r in rows] == [0.0, 1.0, 0.0]
    assert np.isfinite(rows[2]["pos_err_max_m"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["diverged_runs"] == 1 and summary["runs"] == 3
