"""Fits to real data: UIUC propeller database (Brandt & Selig) and TU Delft V3 kite (MIT).

Both vendored in the repository's ``data/`` (the UIUC 7x4 rows and the TU Delft polars, each with
its SOURCE.md).
"""
from conftest import REPO_DATA_DIR

import numpy as np
import pytest

from vtoladapt.fitting import realdata

DATA = REPO_DATA_DIR


def test_uiuc_static_ct_matches_the_datas_own_column():
    """The fitted C_T of T = C_T rho n^2 D^4 equals the mean of the database's C_T column at J = 0
    within 0.5 % (with a relative noise model the estimate is that mean: this checks the unit
    chain rpm -> rev/s, inch -> m), lies inside the column's range, and its posterior std is the
    standard error of the mean of 16 values (column std / 4) within 25 %."""
    r = realdata.fit_uiuc_static_ct(data_dir=DATA, rng=np.random.default_rng(0))
    col = r["column"]
    assert r["n_static_rows"] == 16 and r["diameter_m"] == pytest.approx(7 * 0.0254)
    assert abs(r["CT"]["mean"] - col["mean"]) / col["mean"] < 0.005
    assert col["min"] < r["CT"]["mean"] < col["max"]
    assert r["CT"]["std"] == pytest.approx(col["std"] / np.sqrt(col["n"]), rel=0.25)
    assert r["converged"]
    assert r["CT_trend_per_1000rpm"] > 0         # Reynolds effect: C_T rises with rpm


def test_thrust_ratio_constants_are_the_fit():
    """The stored pusher thrust-ratio model is what fit_uiuc_ct_of_j gives (1e-6), it is 1 at
    J = 0 and 0 at J_zero, and the quadratic follows the data within 0.01 in C_T."""
    r = realdata.fit_uiuc_ct_of_j(data_dir=DATA, rng=np.random.default_rng(0))
    stored = realdata.pusher_thrust_ratio_model()
    np.testing.assert_allclose(stored.coefficients, r["ratio_coefficients"], rtol=1e-6)
    assert stored.J_zero == pytest.approx(r["J_zero"], rel=1e-6)
    assert stored.J_max_fit == pytest.approx(r["fit_range_J"][1])
    assert stored.ratio(0.0) == 1.0 and abs(stored.ratio(stored.J_zero)) < 1e-12
    assert r["max_abs_residual"] < 0.01 and r["rms_residual"] < 0.005
    # the data: C_T at the highest-J point of each sweep is near or below zero, J_zero inside
    prop = realdata.read_uiuc_propeller(data_dir=DATA)
    assert 0.5 < r["J_zero"] < prop.J.max()
    # posterior means agree with the deterministic (MAP-noise) coefficients within 4 MC errors
    for k, name in enumerate(("c0", "c1", "c2")):
        c = r["coefficients"][name]
        assert abs(c["mean"] - r["coefficients_map"][k]) < 4 * c["mcse"]


def test_unknown_propeller_is_named():
    with pytest.raises(realdata.FitDataError, match="no propeller named 'apc 7.0x4.0'"):
        realdata.read_uiuc_propeller("apc 7.0x4.0", DATA)


def test_linear_range_rule_on_a_synthetic_stall():
    """A lift curve linear from -6 to 10 deg (2 deg steps, noise 0.001), flatter outside, over 40
    noise draws: the range never includes a stalled point, and it is the whole linear part in
    most draws (each step of the 95 % rule rejects a good point with probability 5 %, so about
    0.95^4 ~ 80 % of the draws reach -6 deg; at least 60 % required)."""
    a = np.arange(-12.0, 21.0, 2.0)
    cl = np.where(a <= 10, 0.08 * a + 0.2, 0.08 * 10 + 0.2 + 0.005 * (a - 10))
    cl = np.where(a < -6, 0.08 * -6 + 0.2 + 0.01 * (a + 6), cl)
    exact = 0
    for seed in range(40):
        noisy = cl + 1e-3 * np.random.default_rng(seed).standard_normal(a.size)
        lo, hi = realdata.linear_lift_range(a, noisy)["alpha_range_deg"]
        assert lo >= -6.0 and hi <= 10.0
        exact += (lo, hi) == (-6.0, 10.0)
    assert exact >= 24


def test_tudelft_polar_fit_and_range():
    """Range chosen from the data by the 95 % prediction-interval rule: -6.1 to 9.4 deg (the
    points at -11.6 and 11.5 deg leave the line: negative stall and stall); the Bayesian fit
    agrees with ordinary least squares on that range within one posterior std, and the lift
    slope is 0.06-0.09 /deg."""
    r = realdata.fit_tudelft_polar(DATA, np.random.default_rng(0))
    lo, hi = r["alpha_range_deg"]
    assert lo == pytest.approx(-6.10, abs=0.01) and hi == pytest.approx(9.38, abs=0.01)
    polar = realdata.read_tudelft_polar(DATA)
    m = (polar.alpha_deg >= lo - 1e-9) & (polar.alpha_deg <= hi + 1e-9)
    a = np.radians(polar.alpha_deg[m])
    ls = np.polyfit(a, polar.CL[m], 1)
    c = r["coefficients"]
    assert abs(c["CL1"]["mean"] - ls[0]) < c["CL1"]["std"]
    assert abs(c["CL0"]["mean"] - ls[1]) < c["CL0"]["std"]
    assert 0.06 < np.radians(c["CL1"]["mean"]) < 0.09
    lsd = np.polyfit(a, polar.CD[m], 2)
    assert abs(c["CD0"]["mean"] - lsd[2]) < c["CD0"]["std"]
    assert r["converged"]
