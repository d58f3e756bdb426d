"""Real data: NASA five-hole probe calibrations (github.com/nasa/multihole-probe-calibration,
NOSA 1.3; Mirhashemi, Juangphanich & Miki, ASME Turbo Expo 2024), vendored in the
repository's ``data/nasa-multihole-probe/`` (see its SOURCE.md)."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import REPO_DATA_DIR

from vtoladapt.probe import calibrate, evaluate_calibration, read_nasa_pcf

DATA = REPO_DATA_DIR / "nasa-multihole-probe"
FILES = ("16328-1_M050.csv", "16328-1_M100.csv", "16328-2_M050.csv")


@pytest.fixture(scope="module")
def nasa():
    return {f: read_nasa_pcf(DATA / f) for f in FILES}


@pytest.fixture(scope="module")
def models(nasa):
    return {f: calibrate(nasa[f]) for f in ("16328-1_M050.csv", "16328-1_M100.csv")}


def test_reader_shapes_and_physics(nasa):
    """585 rows (490 calibration + 95 test); on the axis q_inf / q_dyn ~ 1; V from Mach."""
    for name, d in nasa.items():
        assert len(d) == 585
        assert int(np.sum(~d.is_test)) == 490 and int(np.sum(d.is_test)) == 95
        axis = d.cone_angle_deg < 0.2
        assert np.all(np.abs(d.q_Pa[axis, 0] / d.q_dyn_Pa[axis] - 1.0) < 0.01)
        assert np.all((d.rho > 1.1) & (d.rho < 1.2))
        mach = 0.05 if "M050" in name else 0.10
        a = np.sqrt(1.4 * 287.05 * 288.0)
        assert np.median(d.V_mps) == pytest.approx(mach * a, rel=0.05)
        assert np.max(d.cone_angle_deg) == pytest.approx(20.41, abs=0.05)


def test_port_pairs_respond_to_alpha_and_beta_with_positive_sign(nasa):
    """The mapping verified from the pressures (see vtoladapt.probe.nasa): within 6 deg of the
    axis, q_alpha/q_dyn ~ a n_z + b n_y and q_beta/q_dyn ~ c n_z + d n_y with a, d in 3.0..3.7
    and cross-talk |b|, |c| < 3 % of a, d; and sign(q_alpha) = sign(alpha), sign(q_beta) =
    sign(beta) at every point more than 1 deg off the other axis' zero."""
    for d in nasa.values():
        n = d.v_i_B / d.V_mps[:, None]
        near = d.cone_angle_deg < 6.0
        A = np.column_stack([np.ones(near.sum()), n[near, 2], n[near, 1]])
        _, a, b = np.linalg.lstsq(A, d.q_Pa[near, 1] / d.q_dyn_Pa[near], rcond=None)[0]
        _, c, dd = np.linalg.lstsq(A, d.q_Pa[near, 2] / d.q_dyn_Pa[near], rcond=None)[0]
        assert 3.0 < a < 3.7 and 3.0 < dd < 3.7
        assert abs(b) < 0.03 * a and abs(c) < 0.03 * dd
        sa = np.abs(d.alpha_deg) > 1.0
        sb = np.abs(d.beta_deg) > 1.0
        assert np.all(np.sign(d.q_Pa[sa, 1]) == np.sign(d.alpha_deg[sa]))
        assert np.all(np.sign(d.q_Pa[sb, 2]) == np.sign(d.beta_deg[sb]))


def test_targets_on_16328_1_mach_050_test_points(nasa, models):
    """Single k: 0.5-0.75 deg RMS flow-angle error on the 95 test points (the paper's model);
    our calibration: <= 0.05 deg RMS (measured 0.031), max <= 0.1 deg, speed RMS <= 0.2 %."""
    m = models["16328-1_M050.csv"]
    d = nasa["16328-1_M050.csv"]
    s = evaluate_calibration(m["single_k"], d, "test")
    c = evaluate_calibration(m["calibrated"], d, "test")
    assert s.points == c.points == "test" and c.n_points == 95
    assert 0.5 <= s.angle_rms_deg <= 0.75
    assert c.n_valid == 95
    assert c.angle_rms_deg <= 0.05
    assert c.angle_max_deg <= 0.1
    assert c.speed_rms_rel <= 2e-3
    assert s.speed_rms_rel > 10 * c.speed_rms_rel


def test_targets_on_16328_1_mach_100_test_points(nasa, models):
    m = models["16328-1_M100.csv"]
    d = nasa["16328-1_M100.csv"]
    s = evaluate_calibration(m["single_k"], d, "test")
    c = evaluate_calibration(m["calibrated"], d, "test")
    assert 0.5 <= s.angle_rms_deg <= 0.75
    assert c.angle_rms_deg <= 0.05
    assert c.speed_rms_rel <= 2e-3


def test_cross_probe_16328_1_to_16328_2(nasa, models):
    """Calibrate on probe 16328-1, evaluate on probe 16328-2 (same model, Mach 0.05): the
    probe-to-probe differences dominate (measured 0.34 deg RMS calibrated vs 0.58 single k on the
    test points); the calibration still beats single k, and stays below 0.45 deg."""
    m = models["16328-1_M050.csv"]
    d2 = nasa["16328-2_M050.csv"]
    s = evaluate_calibration(m["single_k"], d2, "test")
    c = evaluate_calibration(m["calibrated"], d2, "test")
    assert c.angle_rms_deg < s.angle_rms_deg
    assert 0.2 < c.angle_rms_deg < 0.45
    # and it is much worse than the probe's own calibration: a probe needs its own calibration
    own = evaluate_calibration(calibrate(d2)["calibrated"], d2, "test")
    assert own.angle_rms_deg < 0.3 * c.angle_rms_deg
