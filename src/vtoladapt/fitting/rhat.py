"""The fit's convergence diagnostic, one number everywhere: the split R-hat per reported quantity
and the largest of them, which ``vtoladapt fit``, ``table1.md`` and ``trace.png`` all print."""
from __future__ import annotations

from .bayes import Table1Fit
from .posterior import POSTERIOR_NAMES

SAMPLED_TO_QUANTITY = {"log10_sigma_abs_N": "sigma_abs_N"}
"""Sampled parameter -> the reported quantity it is a transform of (same name otherwise)."""


def rhat_by_quantity(fit: Table1Fit) -> dict[str, float]:
    """Split R-hat over the posterior draws of each reported quantity (the ten Table I ones and
    the noise): the values ``posterior.json`` stores as ``diagnostics.rhat_split``."""
    s = fit.summary()
    return {n: s[n]["rhat"] for n in POSTERIOR_NAMES + ("sigma_abs_N", "sigma_rel")}


def largest_rhat(rhat_split: dict[str, float]) -> tuple[str, float]:
    """The quantity with the largest split R-hat and that R-hat: the one number table1.md,
    trace.png and ``vtoladapt fit`` report as the fit's R-hat. ``("none", nan)`` if empty."""
    if not rhat_split:
        return "none", float("nan")
    name = max(rhat_split, key=lambda n: rhat_split[n])
    return name, float(rhat_split[name])
