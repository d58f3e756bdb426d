"""Claims over distributions: each experiment flown over N seeded variants of itself.

A single seed is one draw of everything random in a run: the aircraft (its coefficients drawn from
Table I's mean +- std when the scenario says ``[plant] coefficients_from = "table_i_draw"``), the
turbulence realisation, the sensors' noise and offsets. A variant replaces the scenario seed by
seed ``i`` of ``SeedSequence([seed, VARIANT_STREAM])``, so all of these change together; within a
comparison variant every controller flies the same variant (a paired comparison).

Per experiment this module reports each claim as the fraction of variants where it holds with its
95 % Wilson interval (:func:`vtoladapt.stats.fraction_holding`) and the median and interquartile
range of the claim's value, and each per-controller metric as median and IQR
(:func:`vtoladapt.stats.median_iqr`). It also builds the ablation (claims with each unmodelled
effect of the plant switched off) and the method x wind-condition table.

Runs are reduced to their metrics as they finish, so memory stays that of a few logs whatever N.
"""
from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from typing import Callable, Optional, Sequence

import numpy as np

from ..control.registry import composite_ids
from ..sim.scenario import Scenario
from ..stats import fraction_holding, median_iqr
from .claims import CLAIM_SOURCES, check_claims, is_paper_claim
from .metrics import convergence_metrics, fan_throttle_series, law_run_metrics

VARIANT_STREAM = 0xD157
"""Second entropy word of the variants' seed sequence (keeps them apart from the convergence
experiment's run seeds, which are spawned from the scenario seed alone)."""

ABLATION_EFFECTS: dict[str, tuple[str, str]] = {
    "stall": ("plant.stall", "stall and post-stall"),
    "side_force": ("plant.side_force", "side force C_Y(β)"),
    "pusher_advance_ratio_loss": ("plant.pusher_advance_ratio_loss", "pusher C_T(J)"),
    "motor_lag": ("plant.motor_lag", "motor lag"),
    "surfaces": ("allocation.surfaces", "surfaces"),
}
"""Effects the ablation switches off one at a time: key -> (``section.field`` of the scenario, a boolean,
label). The plant's unmodelled effects, and the control surfaces (the allocator leaves them neutral: the
lift rotors make every moment, the airframe before issue #24)."""


def _switched_off(scenario: Scenario, dotted: str) -> Scenario:
    """``scenario`` with the boolean ``section.field`` set to False."""
    section, field = dotted.split(".")
    return replace(scenario, **{section: replace(getattr(scenario, section), **{field: False})})

WIND_CONDITIONS: dict[str, str] = {
    "still": "still air", "fan30": "fan 30 %", "fan70": "fan 70 %", "fan100": "fan 100 %",
    "gusty": "gusty",
}
"""The method x wind table's columns (Neural-Fly's table, with this project's fan array)."""

WIND_HOLD_S = 20.0
"""Length of each method x wind run; the first WIND_SETTLE_S are left out of its numbers."""
WIND_SETTLE_S = 5.0

Progress = Optional[Callable[[float], None]]
"""Called with the simulated seconds of each finished run."""


def variant_seeds(seed: int, n: int) -> list[int]:
    """The seeds of the ``n`` variants of an experiment with seed ``seed``."""
    return [int(s) for s in np.random.SeedSequence([int(seed), VARIANT_STREAM]).generate_state(n)]


def _pool_map(fn, items: Sequence, workers: Optional[int] = None) -> list:
    """``fn`` over ``items`` on one thread per core (the compiled loop releases the GIL)."""
    workers = workers or os.cpu_count() or 1
    if workers == 1 or len(items) <= 1:
        return [fn(x) for x in items]
    with ThreadPoolExecutor(max_workers=min(workers, len(items))) as pool:
        return list(pool.map(fn, items))


# --- one variant of each experiment, reduced to numbers ---------------------------------------------
def comparison_variant(scenario: Scenario, progress: Progress = None, workers: Optional[int] = None,
                       controllers: Optional[dict] = None) -> dict:
    """Every controller of the comparison flies ``scenario``; their metrics and the claims.

    ``controllers``: id -> :class:`~vtoladapt.control.settings.ControllerConfig` to fly instead of the
    scenario's own with ``kind`` switched (the tuned settings); whatever position gain a law flies,
    its velocity error ``v~`` is measured with the scenario's ``Lambda_p`` (one yardstick for every
    law); ``workers``: threads for this variant's runs (default one per core; 1 when variants run
    side by side)."""
    from ..sim.driver import simulate

    fan: dict = {}  # the fan schedule sampled once per variant (every controller logs the same ticks)
    ids = list(controllers) if controllers is not None else list(scenario.experiment.controllers)

    def fly(cid: str) -> dict:
        config = (controllers[cid] if controllers is not None
                  else replace(scenario.controller, kind=cid))
        # every law's v~ is measured with the scenario's position gain, whatever Lambda_p it flies
        # (tuned settings may change it; SimulationResult.measured_with)
        res = simulate(replace(scenario, controller=config)).measured_with(scenario.controller.Lambda_p)
        if len(res.time_s) not in fan:
            fan[len(res.time_s)] = fan_throttle_series(scenario, res.time_s)
        out = law_run_metrics(res, fan[len(res.time_s)])
        if progress is not None:
            progress(scenario.duration_s)
        return out

    results = dict(zip(ids, _pool_map(fly, ids, workers)))
    comparison = {"scenario": scenario.name, "controllers": results}
    return {"controllers": results, "claims": check_claims(comparison, None)}


def convergence_variant(scenario: Scenario, progress: Progress = None, workers: Optional[int] = None) -> dict:
    """The convergence experiment (``runs`` random-start runs) on ``scenario``; claims and ratios."""
    from ..sim.driver import simulate_many

    results = simulate_many(convergence_runs(scenario), workers=workers)
    conv = convergence_metrics(scenario, results)
    if progress is not None:
        progress(scenario.duration_s * len(results))
    return {"param_std_ratio": conv["param_std_ratio"],
            "predicted_force_std_ratio": conv["predicted_force_std_ratio"],
            "claims": check_claims(None, conv)}


def convergence_runs(scenario: Scenario) -> list[Scenario]:
    """The convergence experiment's runs: ``[experiment] runs`` seeds spawned from the scenario
    seed, each from a random initial theta-hat, all on one aircraft (a Table I draw comes from
    the experiment's seed, not each run's)."""
    seeds = np.random.SeedSequence(scenario.seed).generate_state(scenario.experiment.runs)
    prior = replace(scenario.controller_prior, initial_theta="random")
    plant = scenario.plant.resolved(scenario.load_vehicle(), scenario.seed)
    return [replace(scenario, seed=int(seed), controller_prior=prior, plant=plant) for seed in seeds]


# --- many variants -------------------------------------------------------------------------------
def summarize_claims(variants: list[dict]) -> dict:
    """name -> ``{fraction, ci95, n, successes, value: {median, iqr, n}, threshold, statement,
    paper_claim, source}`` over the variants that judged the claim."""
    names = list(dict.fromkeys(n for v in variants for n in v["claims"]))
    out = {}
    for name in names:
        judged = [v["claims"][name] for v in variants if name in v["claims"]]
        entry = fraction_holding(c["holds"] for c in judged).as_dict()
        entry["value"] = median_iqr(c["value"] for c in judged).as_dict()
        entry.update(threshold=judged[0]["threshold"], statement=judged[0]["statement"],
                     paper_claim=is_paper_claim(name), source=CLAIM_SOURCES.get(name))
        out[name] = entry
    return out


def summarize_controllers(variants: list[dict]) -> dict:
    """id -> metric -> ``{median, iqr, n}`` for every numeric metric of the controllers' runs."""
    out: dict = {}
    for v in variants:
        for cid, m in v["controllers"].items():
            for key, value in m.items():
                if isinstance(value, (int, float)) and key not in ("wall_time_s", "fan_off_time_s"):
                    out.setdefault(cid, {}).setdefault(key, []).append(value)
    return {cid: {k: median_iqr(vals).as_dict() for k, vals in ms.items()} for cid, ms in out.items()}


PAIRED_METRICS = ("vel_err_rms_mps", "vel_err_rms_rising_mps", "vel_err_rms_plateau_mps", "vel_err_rms_fan_off_mps",
                  "overshoot_after_fan_off_mps", "vel_err_rms_high_wind_mps", "pos_err_rms_m", "pred_err_p95_g",
                  "pred_err_p95_rising_g", "pred_err_p95_plateau_g", "pred_err_p95_fan_off_g")
"""The metrics every pair of laws is compared on, variant by variant (:mod:`.pairs`)."""


def fly_variants(scenario: Scenario, n: int, progress: Progress = None,
                 controllers: Optional[dict] = None) -> list[dict]:
    """:func:`comparison_variant` for each of the ``n`` variant seeds, the variants side by side (one
    per core, each flying its laws in turn: a thread keeps one log at a time)."""
    seeds = variant_seeds(scenario.seed, n)
    return _pool_map(lambda s: comparison_variant(replace(scenario, seed=s), progress, 1, controllers), seeds)


def per_variant_values(variants: list[dict]) -> dict:
    """id -> metric -> [value per variant] for the scalar metrics (None where a variant has none)."""
    out: dict = {}
    for v in variants:
        for cid, m in v["controllers"].items():
            for key, value in m.items():
                if isinstance(value, (int, float)) and key not in ("wall_time_s", "fan_off_time_s"):
                    out.setdefault(cid, {}).setdefault(key, [])
    for cid, keys in out.items():
        for key, values in keys.items():
            for v in variants:
                x = v["controllers"].get(cid, {}).get(key)
                values.append(None if x is None or not math.isfinite(x) else float(x))
    return out


def comparison_distribution(scenario: Scenario, n: int, progress: Progress = None) -> dict:
    """The comparison over ``n`` seeded variants: claims as fractions, metrics as median and IQR, every
    metric's value per variant (``per_variant``) and every pair of laws compared (``paired``)."""
    from .pairs import compare_laws

    variants = fly_variants(scenario, n, progress)
    per_variant = per_variant_values(variants)
    return {"variants": n, "seeds": variant_seeds(scenario.seed, n), "claims": summarize_claims(variants),
            "controllers": summarize_controllers(variants), "per_variant": per_variant,
            "paired": compare_laws(per_variant, PAIRED_METRICS, list(scenario.experiment.controllers))}


def convergence_distribution(scenario: Scenario, n: int, progress: Progress = None) -> dict:
    """The convergence experiment over ``n`` seeded variants (each ``runs`` runs on its own aircraft),
    the variants side by side (one per core, each flying its runs in turn)."""
    seeds = variant_seeds(scenario.seed, n)
    variants = _pool_map(lambda s: convergence_variant(replace(scenario, seed=s), progress, 1), seeds)
    ratios: dict = {}
    for v in variants:
        for p, r in v["param_std_ratio"].items():
            ratios.setdefault(p, []).append(r)
    return {"variants": n, "seeds": seeds, "claims": summarize_claims(variants),
            "param_std_ratio": {p: median_iqr(r).as_dict() for p, r in ratios.items()}}


def claim_controllers(ids: Sequence[str]) -> tuple[str, ...]:
    """The controllers of ``ids`` the comparison's claims judge (the paper's five): the ablation flies only these."""
    from ..control.registry import paper_adaptive_ids, paper_baseline_ids

    needed = set(paper_adaptive_ids()) | set(paper_baseline_ids()) | set(composite_ids())
    return tuple(i for i in ids if i in needed)


def ablation(scenario: Scenario, n: int, progress: Progress = None, all_on: Optional[dict] = None) -> dict:
    """The comparison's claims over ``n`` variants with each unmodelled effect of
    :data:`ABLATION_EFFECTS` switched off in turn (``all_on``: every effect on, the same seeds).

    Only the controllers the claims judge fly (:func:`claim_controllers`). ``all_on`` may be the
    comparison's own distribution over the same ``n`` variants (:func:`comparison_distribution`):
    its claims are then reused, not flown again."""
    ids = claim_controllers(scenario.experiment.controllers)
    base = replace(scenario, experiment=replace(scenario.experiment, controllers=ids))
    out = {}
    if all_on is not None and all_on.get("variants") == n:
        out["all_on"] = {"variants": n, "claims": all_on["claims"]}
    else:
        out["all_on"] = {"variants": n, "claims": summarize_claims(fly_variants(base, n, progress))}
    for key, (field, _label) in ABLATION_EFFECTS.items():
        variants = fly_variants(_switched_off(base, field), n, progress)
        out[f"{key}_off"] = {"variants": n, "claims": summarize_claims(variants)}
    return out


def wind_condition_scenario(scenario: Scenario, condition: str, time_scale: float = 1.0) -> Scenario:
    """``scenario`` holding position for :data:`WIND_HOLD_S` in one wind condition of
    :data:`WIND_CONDITIONS`: the fan array at a constant throttle (0, 30, 70, 100 %), or gusty:
    fan at 50 % with 1 - cos gusts of +-3 m/s (longitudinal, lateral) every 3 s."""
    from ..wind import GustConfig

    if condition not in WIND_CONDITIONS:
        raise ValueError(f"wind condition {condition!r}: allowed: {', '.join(WIND_CONDITIONS)}")
    throttle = {"still": 0.0, "fan30": 30.0, "fan70": 70.0, "fan100": 100.0, "gusty": 50.0}[condition]
    fan = replace(scenario.wind.fan_array, schedule=((0.0, throttle), (WIND_HOLD_S, throttle)))
    gusts: tuple = ()
    if condition == "gusty":
        gusts = tuple(GustConfig(shape="one_minus_cosine", start_s=WIND_SETTLE_S + 3.0 * i, duration_s=1.5,
                                 amplitude_mps=(3.0 * (-1) ** i, 2.0 * (-1) ** (i // 2), 0.0))
                      for i in range(5))
    wind = replace(scenario.wind, fan_array=fan, gusts=gusts).time_scaled(time_scale)
    return replace(scenario, wind=wind, duration_s=WIND_HOLD_S * time_scale, name=f"{scenario.name}_{condition}")


def wind_table(scenario: Scenario, n: int, progress: Progress = None, time_scale: float = 1.0) -> dict:
    """Method x wind condition: each controller's mean position error and RMS velocity error
    (after :data:`WIND_SETTLE_S`), median and IQR over ``n`` seeded variants per condition."""
    from ..sim.driver import simulate

    seeds = variant_seeds(scenario.seed, n)
    ids = scenario.experiment.controllers
    out: dict = {}
    for cond in WIND_CONDITIONS:
        base = wind_condition_scenario(scenario, cond, time_scale)
        settle_s = WIND_SETTLE_S * time_scale
        jobs = [(cid, s) for s in seeds for cid in ids]

        def fly(job):
            cid, s = job
            res = simulate(replace(base, seed=s, controller=replace(base.controller, kind=cid)))
            late = res.time_s >= settle_s
            p = np.linalg.norm(res.position_error_W[late], axis=1)
            v = np.linalg.norm(res.velocity_error_W[late], axis=1)
            if progress is not None:
                progress(base.duration_s)
            return cid, float(p.mean()), float(np.sqrt(np.mean(v * v)))

        rows = _pool_map(fly, jobs)
        out[cond] = {cid: {"pos_err_mean_m": median_iqr(r[1] for r in rows if r[0] == cid).as_dict(),
                           "vel_err_rms_mps": median_iqr(r[2] for r in rows if r[0] == cid).as_dict()}
                     for cid in ids}
    return {"variants": n, "hold_s": WIND_HOLD_S * time_scale, "settle_s": WIND_SETTLE_S * time_scale,
            "conditions": out}


__all__ = ["ABLATION_EFFECTS", "PAIRED_METRICS", "VARIANT_STREAM", "WIND_CONDITIONS", "ablation",
           "claim_controllers", "comparison_distribution", "comparison_variant", "fly_variants",
           "per_variant_values", "convergence_distribution", "convergence_variant", "summarize_claims",
           "summarize_controllers", "variant_seeds", "wind_condition_scenario", "wind_table"]
