"""Training flights: draws of a campaign file flown by one controller, each log kept, with held-out conditions.

:func:`plan_flights` draws a campaign file's draws (:func:`vtoladapt.campaign.runner.plan_campaign_file`,
with a seed of its own: the training draws are not the evaluation's) and keeps those of the wanted
vehicle family, leaving out held-out conditions (a fan schedule, a sector of fan bearings): such a
condition is then *never* seen in training. :func:`fly_draws` flies them (the composite law with
the paper's basis by default: the data are what any flight computer would log) and writes one
Parquet log per draw with the draw in its metadata, so ``vtoladapt learn-basis`` reads them back as
one task per flight.
"""
from __future__ import annotations

import json
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

from ..config import ConfigError

BEARING_KEY = "wind.fan_array.array_bearing_deg"


@dataclass(frozen=True)
class HoldOut:
    """Conditions left out of training: fan schedules by name, fan-bearing sectors ``(lo, hi)`` deg
    (``lo > hi`` wraps through north)."""

    schedules: tuple[str, ...] = ()
    bearing_sectors: tuple[tuple[float, float], ...] = ()

    def excludes(self, drawn: dict) -> bool:
        """Whether a draw (its ``drawn`` values) falls in a held-out condition."""
        if drawn.get("choice.fan_schedule") in self.schedules:
            return True
        b = drawn.get(BEARING_KEY)
        if b is None:
            return False
        b = float(b) % 360.0
        for lo, hi in self.bearing_sectors:
            if (lo <= b < hi) if lo <= hi else (b >= lo or b < hi):
                return True
        return False

    def describe(self) -> dict:
        """The held-out conditions as the basis file records them."""
        return {"fan_schedules": list(self.schedules), "bearing_sectors_deg": [list(s) for s in self.bearing_sectors]}


def parse_sector(text: str) -> tuple[float, float]:
    """``"135:225"`` -> (135.0, 225.0) (degrees; ``lo > hi`` wraps through north)."""
    try:
        lo, hi = (float(v) for v in text.split(":"))
    except ValueError:
        raise ConfigError(f"--hold-out-bearing {text!r}: allowed: LO:HI in degrees, e.g. 135:225") from None
    if not (0.0 <= lo <= 360.0 and 0.0 <= hi <= 360.0) or lo == hi:
        raise ConfigError(f"--hold-out-bearing {text!r}: allowed: 0 <= LO, HI <= 360 and LO != HI")
    return lo, hi


def plan_flights(campaign_path: str | Path, runs: int, seed: int, vehicle: Optional[str] = None,
                 hold_out: HoldOut = HoldOut(), controller: str = "composite") -> list:
    """The campaign's draws (``runs`` of them, from ``seed``) of ``vehicle`` (None: any), without the
    held-out conditions, each as one :class:`~vtoladapt.campaign.runner.RunSpec` flown by ``controller``."""
    from ..campaign.runner import plan_campaign_file

    _, specs = plan_campaign_file(campaign_path, runs=runs, seed=seed)
    first = specs[0].controller if specs else None
    kept = []
    for s in specs:
        if s.controller != first:
            continue
        if vehicle is not None and s.mapping.get("vehicle") != vehicle:
            continue
        if hold_out.excludes(s.drawn):
            continue
        mapping = dict(s.mapping)
        mapping["controller"] = {**s.mapping.get("controller", {}), "kind": controller}
        kept.append(type(s)(s.index, mapping, s.source, s.drawn, controller, s.groups))
    return kept


def _fly_one(spec, out: Path) -> Path:
    from ..sim.driver import simulate
    from ..sim.scenario import scenario_from_mapping

    scenario = scenario_from_mapping(spec.mapping, spec.source, source_path=spec.source)
    result = simulate(scenario)
    result.metadata["draw"] = {"index": spec.index, **{k: v for k, v in spec.drawn.items()}}
    return result.to_parquet(out / f"draw{spec.index:05d}.parquet")


def fly_draws(specs: Sequence, out: str | Path, workers: int = 2, show_progress: bool = True) -> list[Path]:
    """Fly every planned draw (``workers`` threads: the compiled loop releases the GIL) and write one log
    per draw into ``out`` (and ``draws.json``: the draws); returns the log paths in draw order."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    from ..progress import progress_bar

    with progress_bar(total=len(specs), desc="training flights", disable=not show_progress) as bar, \
            ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        futures = [pool.submit(_fly_one, s, out) for s in specs]
        paths = []
        for f in futures:
            paths.append(f.result())
            bar.update(1)
    (out / "draws.json").write_text(json.dumps([{"index": s.index, **s.drawn} for s in specs], indent=1,
                                               default=str))
    return paths
