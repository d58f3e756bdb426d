"""The prediction yardstick (:mod:`vtoladapt.experiments.yardstick`, issue #34) against answers known by construction.

* **Probe-valid scoring**: a sample counts once the probe has been used for the settle time without
  a break; the indices are counted by hand from the pattern.
* **Hold baseline**: on a constant acceleration it is exact (zero error); on a ramp its error is the
  ramp's slope times the hold's lag.
* **Horizon**: with theta-hat constant and exact the frozen prediction's error is the measurement
  noise itself; with a moving theta-hat it equals ``W_k theta-hat_{k-m} - a_m,k`` computed sample by
  sample (a loop, not the vectorised form); one tick of horizon is the logged one-tick error.
* **One log end to end**: a synthetic log whose probe is out for a known share of the run and whose
  accelerometer is constant: the blind fraction, the hold's pass and the scored share are the
  constructed ones; the envelope summary and the basis comparison carry the per-law entries.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from vtoladapt.experiments import yardstick as ys
from vtoladapt.frames import GRAVITY_MPS2 as G
from vtoladapt.sim.results import SimulationResult

DT = 0.004


def test_probe_valid_mask_waits_the_settle_time_after_every_gap():
    used = np.r_[np.ones(100), np.zeros(10), np.ones(200)]
    m = ys.probe_valid_mask(used, DT, settle_s=0.5)
    # 0.5 s is 125 ticks: the first stretch (100 ticks) never settles; the second from its 126th sample on
    expected = np.zeros(310, dtype=bool)
    expected[110 + 125:] = True
    np.testing.assert_array_equal(m, expected)
    np.testing.assert_array_equal(ys.probe_valid_mask(used, DT, settle_s=0.0), used > 0.5)


def test_hold_is_exact_on_a_constant_acceleration_and_lags_a_ramp():
    a = np.tile([0.3, -9.81, 1.2], (400, 1))
    for lag in (1, 125):
        err = ys.hold_error(a, lag)
        assert np.all(np.isnan(err[:lag]))
        np.testing.assert_array_equal(err[lag:], 0.0)
    slope = np.array([0.5, -1.0, 2.0])                              # m/s^3
    ramp = np.arange(400)[:, None] * DT * slope
    np.testing.assert_allclose(ys.hold_error(ramp, 125)[125:], np.tile(-125 * DT * slope, (275, 1)), atol=1e-12)


def _synthetic_regression(rng, N=600, n=5, noise=0.05, moving=True):
    W = np.cumsum(rng.normal(0.0, 0.05, (N, 3, n)), axis=0) + rng.normal(0.0, 1.0, (1, 3, n))
    theta_true = rng.normal(0.0, 1.0, n)
    v = rng.normal(0.0, noise, (N, 3))
    a_m = np.einsum("kij,j->ki", W, theta_true) + v
    if moving:                                                       # theta-hat converging to the truth
        theta = theta_true + np.exp(-np.arange(N) / 150.0)[:, None] * rng.normal(0.0, 1.0, n)
    else:
        theta = np.tile(theta_true, (N, 1))
    # the logged one-tick error: the regressor at k with theta-hat after the update at k-1
    e = np.full((N, 3), np.nan)
    e[1:] = np.einsum("kij,kj->ki", W[1:], theta[:-1]) - a_m[1:]
    return W, theta, a_m, e, v


def test_horizon_error_with_a_constant_exact_theta_is_the_noise():
    W, theta, a_m, e, v = _synthetic_regression(np.random.default_rng(3), moving=False)
    err = ys.frozen_theta_error(e, W, theta, 125)
    np.testing.assert_allclose(err[125:], -v[125:], rtol=0.0, atol=1e-12)


def test_horizon_error_is_the_frozen_prediction_sample_by_sample():
    W, theta, a_m, e, _ = _synthetic_regression(np.random.default_rng(4))
    m = 125
    err = ys.frozen_theta_error(e, W, theta, m)
    for k in (m, m + 1, 300, 599):
        np.testing.assert_allclose(err[k], W[k] @ theta[k - m] - a_m[k], rtol=0.0, atol=1e-10)
    assert np.all(np.isnan(err[:m]))
    np.testing.assert_allclose(ys.frozen_theta_error(e, W, theta, 1)[1:], e[1:], rtol=0.0, atol=1e-12)
    # a theta-hat that still moves predicts worse frozen than one tick ahead, early on
    early = slice(m, 300)
    assert np.linalg.norm(err[early]) > 2.0 * np.linalg.norm(e[early])
    with pytest.raises(ValueError, match="at least one tick"):
        ys.frozen_theta_error(e, W, theta, 0)


def _log(N=3000, blind=(1000, 1500)):
    """A constant-acceleration log (10 s at 250 Hz) with the probe out between two rows and a
    never-moving theta-hat: 3 m/s airspeed; the one-tick error 0.01 g except 0.2 g while blind."""
    t = np.arange(N) * DT
    used = np.ones(N)
    used[blind[0]:blind[1]] = 0.0
    e = np.zeros((N, 3))
    e[:, 0] = 0.01 * G
    e[blind[0]:blind[1], 0] = 0.2 * G
    a_m = np.tile([0.0, 0.0, -G], (N, 1))
    cols = {"t_s": t, "probe_valid_used": used, "airspeed_mps": np.full(N, 3.0),
            **{c: e[:, i] for i, c in enumerate(ys.PRED_ERR_COLUMNS)},
            **{c: a_m[:, i] for i, c in enumerate(ys.A_M_COLUMNS)}, "theta_hat_A": np.full(N, 2.0)}
    return SimulationResult(tuple(cols), np.column_stack(list(cols.values())))


class _Spec:
    names = ("A",)


def test_a_synthetic_log_end_to_end():
    y = ys.prediction_yardstick(_log(), vehicle=None, spec=_Spec())
    late = np.arange(3000) * DT >= 2.0                               # 2500 samples scored at most
    assert y["blind_fraction"] == pytest.approx(500 / late.sum())
    # scored: after 2 s, and not within 0.5 s (125 ticks) after the probe is back
    assert y["scored_fraction"] == pytest.approx((late.sum() - 500 - 125) / late.sum())
    assert y["one_tick"]["pass"] is True and y["one_tick"]["p95_g"] == pytest.approx(0.01)
    assert y["horizon"] == y["one_tick"]                            # theta-hat never moved
    for k in ("hold_one_tick", "hold_horizon"):
        assert y[k]["pass"] is True and y[k]["p95_g"] == 0.0
    assert ys.worst_bin(y["one_tick"]) == pytest.approx(0.01)
    # scored on every sample after 2 s the blind stretch would fail it: 500 of 2500 samples at 0.2 g
    e = np.linalg.norm(_log().columns_like(ys.PRED_ERR_COLUMNS), axis=1)[late] / G
    assert np.percentile(e, 95) == pytest.approx(0.2)


def test_summary_and_comparison_report_the_yardstick_per_law(tmp_path):
    from vtoladapt.experiments.envelope import YARDSTICK_KEYS, envelope_summary
    from vtoladapt.learn.evaluate import compare
    from vtoladapt.sim.run_metrics import airspeed_bin_labels

    rows = []
    for run in range(4):
        for cid in ("composite", "pid"):
            r = {"run": run, "controller": cid, "vel_err_rms_mps": 0.1, "finite": 1.0, "diverged": 0.0,
                 "flown_s": 10.0, "wall_time_s": 0.1, "alpha_abs_max_deg": 5.0, "mixer_saturated_fraction": 0.0,
                 "alpha_over_protect_fraction": 0.0, "alpha_over_protect_longest_s": 0.0,
                 "alpha_over_stall_fraction": 0.0, "alpha_over_stall_longest_s": 0.0, "blind_fraction": 0.1 * run}
            for lab in airspeed_bin_labels():
                r[f"pred_err_p95_g{lab}"] = 0.01 if cid == "composite" else float("nan")
                r[f"vel_err_rms_mps{lab}"] = 0.1
                r[f"alpha_over_protect_fraction{lab}"] = 0.0
                r[f"alpha_over_protect_longest_s{lab}"] = 0.0
            for k in YARDSTICK_KEYS:
                r[k] = float(run < 3) if k != "hold_horizon_pass" else 0.0
                r[k[:-len("_pass")] + "_worst_g"] = 0.04 if run < 3 else 0.06
            rows.append(r)
    cols = {k: [r.get(k, float("nan")) for r in rows] for k in rows[0]}
    s = envelope_summary(cols)
    c = s["controllers"]["composite"]
    assert (c["pred_horizon_pass"]["successes"], c["pred_horizon_pass"]["n"]) == (3, 4)
    assert c["hold_horizon_pass"]["successes"] == 0
    assert c["blind_fraction"]["median"] == pytest.approx(0.15)
    folder = tmp_path / "learned"
    folder.mkdir()
    s["campaign"].update(runs=4, seed=1)
    (folder / "summary.json").write_text(json.dumps(s))
    table = compare(tmp_path, {"learned": folder})
    assert table["ceiling"]["learned"]["pid"]["true inputs"]["successes"] == 3    # the law's own flights
    md = (tmp_path / "comparison.md").read_text()
    assert "| composite | 0.75 (3/4)" in md and "hold, horizon" in md and "15.0 %" in md
