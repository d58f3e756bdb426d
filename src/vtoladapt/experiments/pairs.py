"""Paired differences between laws over seeded variants, and the ranking they allow.

Every law flies the same variants (seed, plant draw, turbulence, sensor noise), so two laws are
compared variant by variant: ``d_i = m_A(i) - m_B(i)`` for a metric ``m``. The method is a paired
rank test, Wilcoxon's signed-rank test, with its estimate and interval of the difference:

* **estimate**: the Hodges-Lehmann estimate, the median of the Walsh averages ``(d_i + d_j) / 2``
  (``i <= j``);
* **95 % interval**: the Walsh averages between the signed-rank test's critical values (Hollander,
  Wolfe & Chicken, *Nonparametric Statistical Methods*, 3rd ed., sec. 3.3): the ``(C + 1)``-th
  smallest and largest, ``C`` the largest count with ``P(W+ <= C) <= 0.025`` under the null; the
  interval holds the shifts the two-sided test at 5 % does not reject. ``P(W+ <= C)`` is the exact
  null distribution of the signed-rank statistic (all ``2^n`` sign patterns, counted by the
  subset-sum recursion), so the interval's coverage is at least 95 % for any continuous
  distribution of the differences symmetric about its centre, whatever its shape;
* **p**: :func:`scipy.stats.wilcoxon`, two-sided (exact below 50 variants without ties or zeros).

Why this and not a bootstrap: with 30 variants a bootstrap interval of a median is coarse (the
resampled medians take few values) and a percentile or BCa bootstrap falls short of its nominal
coverage at this size, while the rank interval is exact; and the differences have outliers (a
variant where a law nearly loses the aircraft), which move a mean, and so a bootstrap of it, but
not the Hodges-Lehmann estimate. What it assumes: the variants are independent (they are: each
has its own seed) and the differences are symmetric about their centre (for the interval to be
that centre's; a skewed difference still gets a valid interval for its pseudo-median).

A pair is **tied** on a metric when the interval contains 0. The ranking orders the laws by their
median over the variants and gives each a rank range: ``1 +`` the number of laws significantly
below it, to the number of laws minus the number significantly above it; laws whose ranges
overlap are not told apart. Each interval is a 95 % interval for its own pair: with 28 pairs, a
law separated from another by one interval alone is one of many comparisons (about one in twenty
truly equal pairs would be).
"""
from __future__ import annotations

import itertools
import math
from typing import Iterable, Optional, Sequence

import numpy as np

CONFIDENCE = 0.95
MIN_PAIRS = 6
"""Below this many variants the signed-rank interval at 95 % is the whole line (no ``C`` exists)."""


def signed_rank_null_cdf(n: int) -> np.ndarray:
    """``P(W+ <= w)`` for ``w = 0 .. n(n+1)/2``: the exact null distribution of the signed-rank statistic.

    Each of the ``2^n`` sign patterns of ranks ``1..n`` is equally likely; the counts of patterns
    per sum come from the subset-sum recursion (add rank ``k`` or not).
    """
    if n < 0:
        raise ValueError(f"n = {n}: must be >= 0")
    m = n * (n + 1) // 2
    counts = np.zeros(m + 1)
    counts[0] = 1.0
    for k in range(1, n + 1):          # patterns with rank k positive shift their sum by k
        counts[k:] += counts[:m + 1 - k].copy()
    return np.cumsum(counts) / 2.0 ** n


def signed_rank_critical(n: int, confidence: float = CONFIDENCE) -> Optional[int]:
    """The largest ``C`` with ``P(W+ <= C) <= (1 - confidence) / 2``; None if there is none (too few pairs)."""
    cdf = signed_rank_null_cdf(n)
    ok = np.flatnonzero(cdf <= (1.0 - confidence) / 2.0 + 1e-12)
    return int(ok[-1]) if ok.size else None


def walsh_averages(d: np.ndarray) -> np.ndarray:
    """``(d_i + d_j) / 2`` for ``i <= j``, sorted."""
    i, j = np.triu_indices(d.size)
    return np.sort(0.5 * (d[i] + d[j]))


def paired_difference(a: Sequence[float], b: Sequence[float], confidence: float = CONFIDENCE) -> dict:
    """The paired difference ``a - b`` over the variants where both are finite (see the module notes).

    Returns ``{estimate, ci95: [lo, hi], p_value, n, verdict}``; ``verdict`` is ``"lower"`` (``a``
    below ``b``: the interval is below 0), ``"higher"`` or ``"tied"``. Fewer than
    :data:`MIN_PAIRS` finite pairs: estimate and interval None, verdict ``"tied"``.
    """
    from scipy.stats import wilcoxon

    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"paired_difference: {a.shape} values against {b.shape}: the variants must pair up")
    d = (a - b)[np.isfinite(a) & np.isfinite(b)]
    n = int(d.size)
    out = {"estimate": None, "ci95": [None, None], "p_value": None, "n": n, "verdict": "tied"}
    if n < MIN_PAIRS:
        return out
    w = walsh_averages(d)
    out["estimate"] = float(np.median(w))
    C = signed_rank_critical(n, confidence)
    lo, hi = float(w[C]), float(w[w.size - 1 - C])
    out["ci95"] = [lo, hi]
    if np.all(d == 0.0):
        out["p_value"] = 1.0
    else:
        out["p_value"] = float(wilcoxon(d).pvalue)
    out["verdict"] = "lower" if hi < 0.0 else "higher" if lo > 0.0 else "tied"
    return out


def law_median(values: Sequence[float]) -> Optional[float]:
    """Median over the finite values (None if there are none)."""
    v = np.asarray([x for x in values if x is not None], dtype=float)
    v = v[np.isfinite(v)]
    return float(np.median(v)) if v.size else None


def compare_laws(per_variant: dict, metrics: Iterable[str], ids: Optional[Sequence[str]] = None) -> dict:
    """Paired differences of every pair of laws and the ranking, per metric.

    ``per_variant``: law id -> metric -> list of values, one per variant in the same order for
    every law (None or NaN where a variant has no value). Returns ``{"pairs": {metric: {"A|B":
    paired_difference(A, B)}}, "ranking": {metric: [{id, median, rank_lo, rank_hi, tied_with}, ...]}}``
    with the ranking sorted by median (lowest first: every metric here is an error).
    """
    ids = list(per_variant) if ids is None else list(ids)
    pairs: dict = {}
    ranking: dict = {}
    for m in metrics:
        have = [i for i in ids if m in per_variant.get(i, {}) and law_median(per_variant[i][m]) is not None]
        if len(have) < 2:
            continue
        res = {}
        for x, y in itertools.combinations(have, 2):
            res[f"{x}|{y}"] = paired_difference(_values(per_variant[x][m]), _values(per_variant[y][m]))
        pairs[m] = res
        ranking[m] = rank_laws(have, {i: law_median(per_variant[i][m]) for i in have}, res)
    return {"pairs": pairs, "ranking": ranking}


def _values(values: Sequence) -> list[float]:
    return [math.nan if v is None else float(v) for v in values]


def rank_laws(ids: Sequence[str], medians: dict, pairs: dict) -> list[dict]:
    """Laws ordered by median with their rank ranges (module notes); ``pairs`` as :func:`compare_laws` makes them."""
    below: dict = {i: set() for i in ids}     # laws significantly lower than i
    above: dict = {i: set() for i in ids}
    tied: dict = {i: [] for i in ids}
    for key, r in pairs.items():
        x, y = key.split("|")
        if r["verdict"] == "lower":
            below[y].add(x)
            above[x].add(y)
        elif r["verdict"] == "higher":
            below[x].add(y)
            above[y].add(x)
        else:
            tied[x].append(y)
            tied[y].append(x)
    order = sorted(ids, key=lambda i: medians[i])
    n = len(ids)
    return [{"id": i, "median": medians[i], "rank_lo": 1 + len(below[i]), "rank_hi": n - len(above[i]),
             "tied_with": [j for j in order if j in tied[i]]} for i in order]


def pair_value(pairs_of_metric: dict, a: str, b: str) -> Optional[dict]:
    """The paired difference ``a - b`` from :func:`compare_laws`'s pairs of one metric (sign flipped
    if it was computed as ``b - a``); None if the pair is not there."""
    r = pairs_of_metric.get(f"{a}|{b}")
    if r is not None:
        return r
    r = pairs_of_metric.get(f"{b}|{a}")
    if r is None:
        return None
    flip = {"lower": "higher", "higher": "lower", "tied": "tied"}
    lo, hi = r["ci95"]
    return {**r, "estimate": None if r["estimate"] is None else -r["estimate"],
            "ci95": [None if hi is None else -hi, None if lo is None else -lo], "verdict": flip[r["verdict"]]}


__all__ = ["CONFIDENCE", "MIN_PAIRS", "compare_laws", "law_median", "pair_value", "paired_difference",
           "rank_laws", "signed_rank_critical", "signed_rank_null_cdf", "walsh_averages"]
