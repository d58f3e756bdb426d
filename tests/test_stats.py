"""Confidence intervals and robust summaries against scipy's references."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.stats import binomtest

from vtoladapt.stats import fraction_holding, median_iqr, wilson_interval


@given(st.integers(1, 400).flatmap(lambda n: st.tuples(st.integers(0, n), st.just(n))))
def test_wilson_matches_scipy(kn):
    k, n = kn
    ref = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    lo, hi = wilson_interval(k, n)
    assert lo == pytest.approx(ref.low, abs=1e-12)
    assert hi == pytest.approx(ref.high, abs=1e-12)
    assert 0.0 <= lo <= k / n <= hi <= 1.0


def test_wilson_known_values():
    # 30 of 30 runs: the interval is not the point 1 (Wald would say [1, 1])
    lo, hi = wilson_interval(30, 30)
    assert hi == 1.0 and lo == pytest.approx(0.8865, abs=1e-4)
    assert wilson_interval(0, 0) == (0.0, 1.0)
    with pytest.raises(ValueError, match="successes = 5, n = 3"):
        wilson_interval(5, 3)


def test_fraction_leaves_out_unjudged_runs():
    f = fraction_holding([True, False, None, True])
    assert (f.successes, f.n, f.fraction) == (2, 3, pytest.approx(2 / 3))
    assert f.as_dict()["ci95"][0] < 2 / 3 < f.as_dict()["ci95"][1]
    assert fraction_holding([None]).fraction is None


def test_median_iqr_matches_numpy_and_ignores_nan():
    rng = np.random.default_rng(3)
    x = rng.normal(size=101)
    m = median_iqr(list(x) + [float("nan"), None])
    assert m.n == 101
    assert m.median == pytest.approx(np.median(x))
    assert m.iqr == (pytest.approx(np.percentile(x, 25)), pytest.approx(np.percentile(x, 75)))
    assert median_iqr([None, float("nan")]).as_dict() == {"median": None, "iqr": [None, None], "n": 0}
