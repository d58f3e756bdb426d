"""Paired differences between laws (:mod:`vtoladapt.experiments.pairs`) against independent references.

* The signed-rank null distribution against brute-force enumeration of every sign pattern, and its
  critical values against scipy's exact Wilcoxon p-values and the published table (n = 30: 137).
* The Hodges-Lehmann estimate against the median of the Walsh averages built pair by pair.
* The interval against the test it inverts: shifts just inside are not rejected by
  ``scipy.stats.wilcoxon`` at 5 %, shifts just outside are.
* Coverage over many samples of 30 from symmetric distributions (normal, Student t with 3 degrees
  of freedom): near 95 %.
* The ranking on laws with known separations.
"""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import stats

from vtoladapt.experiments.pairs import (
    compare_laws, pair_value, paired_difference, rank_laws, signed_rank_critical, signed_rank_null_cdf,
)


@pytest.mark.parametrize("n", [1, 2, 5, 9, 12])
def test_null_distribution_is_the_enumeration_of_sign_patterns(n):
    sums = [sum(r for r, s in zip(range(1, n + 1), signs) if s) for signs in itertools.product((0, 1), repeat=n)]
    counts = np.bincount(sums, minlength=n * (n + 1) // 2 + 1)
    np.testing.assert_allclose(signed_rank_null_cdf(n), np.cumsum(counts) / 2 ** n, rtol=1e-14)


@pytest.mark.parametrize("n", [6, 10, 20, 30, 45])
def test_critical_values_against_scipys_exact_test(n):
    """``P(W <= C)`` at 2.5 % or less, ``P(W <= C + 1)`` above: the two-sided exact p-values of data
    whose positive ranks sum to C and to C + 1 straddle 0.05."""
    C = signed_rank_critical(n)

    def data_with_positive_sum(s):
        pos, left = set(), s
        for r in range(n, 0, -1):              # greedy: ranks summing to s
            if r <= left:
                pos.add(r)
                left -= r
        assert left == 0
        return np.array([r if r in pos else -r for r in range(1, n + 1)], dtype=float)

    assert stats.wilcoxon(data_with_positive_sum(C), method="exact").pvalue <= 0.05
    assert stats.wilcoxon(data_with_positive_sum(C + 1), method="exact").pvalue > 0.05
    if n == 30:
        assert C == 137                        # Hollander, Wolfe & Chicken, Table A.4
    assert signed_rank_critical(5) is None     # too few pairs for any 95 % interval


def test_estimate_and_interval_invert_the_signed_rank_test(rng):
    for trial in range(20):
        a = rng.normal(size=30)
        b = a + rng.normal(0.2, 0.5, size=30) * rng.choice([1, -1])
        r = paired_difference(a, b)
        d = a - b
        walsh = sorted((d[i] + d[j]) / 2 for i in range(30) for j in range(i, 30))
        assert r["estimate"] == pytest.approx(np.median(walsh), rel=1e-12)
        lo, hi = r["ci95"]
        eps = 1e-9 * (hi - lo)
        for shift, rejected in ((lo + eps, False), (hi - eps, False), (lo - eps, True), (hi + eps, True)):
            p = stats.wilcoxon(d - shift, method="exact").pvalue
            assert (p < 0.05) == rejected, (trial, shift, p)
        assert r["p_value"] == pytest.approx(stats.wilcoxon(d).pvalue)
        assert r["verdict"] == ("lower" if hi < 0 else "higher" if lo > 0 else "tied")


@pytest.mark.parametrize("dist", ["normal", "t3"])
def test_interval_covers_the_centre_95_percent_of_the_time(dist):
    rng = np.random.default_rng(7)
    hits = 0
    n_rep = 2000
    for _ in range(n_rep):
        d = rng.normal(size=30) if dist == "normal" else rng.standard_t(3, size=30)
        lo, hi = paired_difference(d + 0.3, np.zeros(30))["ci95"]
        hits += lo <= 0.3 <= hi
    # exact for a continuous symmetric law: the test's level is 1 - 2 P(W <= 137) = 0.9572
    assert abs(hits / n_rep - 0.957) < 3.5 * np.sqrt(0.957 * 0.043 / n_rep)


def test_identical_laws_are_tied_with_a_zero_interval():
    a = np.linspace(0.04, 0.06, 30)
    r = paired_difference(a, a)
    assert r["estimate"] == 0.0 and r["ci95"] == [0.0, 0.0] and r["verdict"] == "tied" and r["p_value"] == 1.0
    few = paired_difference(a[:5], a[:5] + 1.0)
    assert few["estimate"] is None and few["verdict"] == "tied" and few["n"] == 5
    with pytest.raises(ValueError, match="pair up"):
        paired_difference(a, a[:10])


def test_ranking_gives_rank_ranges_where_laws_are_tied(rng):
    """A clearly below B and C; B and C the same law plus noise: A ranks 1, B and C share 2-3."""
    base = rng.normal(0.05, 0.005, size=30)
    per = {"A": {"m": list(base - 0.02)},
           "B": {"m": list(base + rng.normal(0.0, 0.001, 30))},
           "C": {"m": list(base + rng.normal(0.0, 0.001, 30))}}
    out = compare_laws(per, ["m"])
    rank = {e["id"]: e for e in out["ranking"]["m"]}
    assert (rank["A"]["rank_lo"], rank["A"]["rank_hi"]) == (1, 1)
    assert {(rank[i]["rank_lo"], rank[i]["rank_hi"]) for i in "BC"} == {(2, 3)}
    assert rank["B"]["tied_with"] == ["C"] and rank["A"]["tied_with"] == []
    assert [e["id"] for e in out["ranking"]["m"]][0] == "A"
    ab = out["pairs"]["m"]["A|B"]
    ba = pair_value(out["pairs"]["m"], "B", "A")
    assert ba["estimate"] == -ab["estimate"] and ba["ci95"] == [-ab["ci95"][1], -ab["ci95"][0]]
    assert (ab["verdict"], ba["verdict"]) == ("lower", "higher")


def test_missing_variants_are_left_out_pairwise():
    a = [0.1 + 0.01 * i for i in range(30)]
    b = [x + 0.005 for x in a]
    b[3] = None
    per = {"A": {"m": a}, "B": {"m": b}}
    r = compare_laws(per, ["m"])["pairs"]["m"]["A|B"]
    assert r["n"] == 29 and r["estimate"] == pytest.approx(-0.005)
    assert rank_laws(["A", "B"], {"A": 0.1, "B": 0.2}, {"A|B": r})[0]["id"] == "A"
