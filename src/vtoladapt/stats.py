"""Statistics for claims over many seeded runs: binomial confidence intervals and robust summaries.

A result of vtoladapt is a claim about a distribution of runs (seeds, plant draws, turbulence
realisations), so every claim is reported as the fraction of runs in which it holds with a 95 %
confidence interval, and every metric as its median and interquartile range.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Optional

import numpy as np
from scipy.special import ndtri

__all__ = ["Fraction", "MedianIQR", "wilson_interval", "fraction_holding", "median_iqr"]


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion (Wilson 1927).

    Unlike the normal ("Wald") interval it stays inside [0, 1] and does not collapse to a point
    when every run (or none) holds, which is the common case for a claim. ``n = 0`` gives the
    uninformative ``(0, 1)``.
    """
    if n < 0 or not 0 <= successes <= n:
        raise ValueError(f"successes = {successes}, n = {n}: need 0 <= successes <= n")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence = {confidence}: must lie in (0, 1)")
    if n == 0:
        return 0.0, 1.0
    z = float(ndtri(0.5 + confidence / 2.0))
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2.0 * n)) / denom
    half = z * math.sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n)) / denom
    # the exact endpoints at p = 0 and p = 1 are 0 and 1; rounding must not move them inside
    lo = 0.0 if successes == 0 else max(0.0, centre - half)
    hi = 1.0 if successes == n else min(1.0, centre + half)
    return lo, hi


@dataclass(frozen=True)
class Fraction:
    """How often a claim held: ``successes`` of ``n`` runs, the fraction and its 95 % Wilson interval."""

    successes: int
    n: int
    fraction: Optional[float]
    ci95: tuple[float, float]

    def as_dict(self) -> dict:
        """``{fraction, ci95, n, successes}`` (``fraction`` None when no run was judged)."""
        return {"fraction": self.fraction, "ci95": [self.ci95[0], self.ci95[1]], "n": self.n,
                "successes": self.successes}


def fraction_holding(outcomes: Iterable[Optional[bool]]) -> Fraction:
    """Fraction of runs in which a claim holds; ``None`` outcomes (claim not judged) are left out."""
    judged = [bool(o) for o in outcomes if o is not None]
    k, n = sum(judged), len(judged)
    return Fraction(k, n, (k / n) if n else None, wilson_interval(k, n))


@dataclass(frozen=True)
class MedianIQR:
    """Median and interquartile range (25th, 75th percentile) of the finite values, and their count."""

    median: Optional[float]
    iqr: tuple[Optional[float], Optional[float]]
    n: int

    def as_dict(self) -> dict:
        """``{median, iqr: [q25, q75], n}`` with None where there were no finite values."""
        return {"median": self.median, "iqr": [self.iqr[0], self.iqr[1]], "n": self.n}


def median_iqr(values: Iterable[Optional[float]]) -> MedianIQR:
    """Median and interquartile range over the finite values (None and NaN are left out)."""
    arr = np.array([v for v in values if v is not None], dtype=float)
    arr = arr[np.isfinite(arr)]
    if arr.size == 0:
        return MedianIQR(None, (None, None), 0)
    q25, q50, q75 = np.percentile(arr, [25.0, 50.0, 75.0])
    return MedianIQR(float(q50), (float(q25), float(q75)), int(arr.size))
