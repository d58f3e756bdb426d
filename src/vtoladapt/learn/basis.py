"""Train a learned basis from flights and write its file (the body of ``vtoladapt learn-basis``)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

from ..bases import describe_basis
from ..bases.netfile import NetFile, features_rows, write_net
from ..config import ConfigError
from .data import Flight, physics_columns
from .flights import BEARING_KEY
from .meta import MetaSettings, Task, train

FEATURE_STD_FLOOR = 1e-3
"""A feature that hardly varies in training (e.g. the probe always valid) is scaled by 1, not by ~0."""
WEIGHT_STD_FLOOR = 0.05
"""Floor of the learned weights' prior std, as a fraction of their largest per-flight magnitude."""
MIN_SAMPLES = 30
PHYSICS_SPREAD = 0.3
"""In training, the physics weights' prior std is at least this fraction of their prior mean."""


def normalisation(flights: Sequence[Flight]) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std of every feature over all training samples (std floored: see :data:`FEATURE_STD_FLOOR`)."""
    z = np.concatenate([features_rows(f.x) for f in flights])
    mean = z.mean(axis=0)
    std = z.std(axis=0)
    return mean, np.where(std > FEATURE_STD_FLOOR, std, 1.0)


def condition_of(flight: Flight) -> str:
    """The flight's condition for the adversarial term: its fan schedule and fan-bearing quadrant (centred on
    0, 90, 180, 270 deg, the envelope campaign's groups) when its log says so, else the flight itself."""
    schedule = flight.info.get("choice.fan_schedule")
    bearing = flight.info.get(BEARING_KEY)
    if schedule is None and bearing is None:
        return f"flight:{flight.source}"
    quadrant = "" if bearing is None else f"@{int(((float(bearing) + 45.0) % 360.0) // 90.0) * 90}deg"
    return f"{schedule or ''}{quadrant}"


def tasks_for(flights: Sequence[Flight], spec, x_mean, x_std) -> list[Task]:
    """One :class:`Task` per flight: normalised features, the physics columns, the measured force, the condition."""
    names = sorted({condition_of(f) for f in flights})
    return [Task(z=(features_rows(f.x) - x_mean) / x_std, A=physics_columns(spec, f), y=f.f, name=f.source,
                 condition=names.index(condition_of(f))) for f in flights]


def learn_basis(flights: Sequence[Flight], vehicle, settings: MetaSettings, command: str = "",
                extra_meta: Optional[dict] = None, progress: Optional[Callable] = None) -> tuple[NetFile, dict]:
    """Train the network on ``flights`` (all of ``vehicle``'s family) and return the basis file's
    content and a summary (losses, time). The physics columns are the extended basis's for ``vehicle``."""
    short = [f for f in flights if len(f.f) < MIN_SAMPLES]
    flights = [f for f in flights if len(f.f) >= MIN_SAMPLES]
    if not flights:
        counts = ", ".join(f"{f.source or 'flight'}: {len(f.f)}" for f in short[:3]) + (", ..." if len(short) > 3 else "")
        raise ConfigError(f"no flight with at least {MIN_SAMPLES} usable samples (finite inputs and force) to train on "
                          f"({counts}); allowed: longer logs, or a smaller --stride")
    others = sorted({f.vehicle for f in flights} - {vehicle.name})
    if others:
        raise ConfigError(f"flights of {others} given to train a basis for {vehicle.name!r}; allowed: one vehicle "
                          "family per basis (--vehicle)")
    t0 = time.perf_counter()
    spec = describe_basis(vehicle, "extended")
    x_mean, x_std = normalisation(flights)
    tasks = tasks_for(flights, spec, x_mean, x_std)
    # the flights' aircraft differ (the campaign draws every coefficient +-25 %): in training each flight's
    # physics weights may move that far from the prior, so that the network learns what no physics
    # weight can carry, not the spread of the coefficients
    prior_std = np.maximum(spec.std_scaled, PHYSICS_SPREAD * np.abs(spec.theta_scaled))
    result = train(tasks, spec.theta_scaled, prior_std, settings, progress=progress)
    m = spec.n
    w_net = np.array([a[m:] for a in result.weights])
    theta_mean = w_net.mean(axis=0)
    spread = w_net.std(axis=0)
    floor = WEIGHT_STD_FLOOR * max(float(np.max(np.abs(w_net))), 1e-3)
    theta_std = np.maximum(spread, floor)
    seconds = time.perf_counter() - t0
    summary = {"loss_physics_only": result.physics_only_loss, "loss_final": result.loss[-1] if result.loss else None,
               "loss_initial": result.loss[0] if result.loss else None, "iterations": result.iterations,
               "evaluations": len(result.loss), "train_seconds": round(seconds, 2),
               "samples": int(sum(len(f.f) for f in flights)), "flights": len(flights),
               "left_out": [f.source for f in short],
               "conditions": len({t.condition for t in tasks}),
               "condition_accuracy": _finite_or_none(result.condition_accuracy),
               "condition_chance": _finite_or_none(result.condition_chance)}
    meta = {"vehicle": vehicle.name, "physics": "extended", "command": command, "seed": settings.seed,
            "settings": {"h": settings.h, "hidden": list(settings.hidden), "sigma_y": settings.sigma_y,
                         "net_weight_std": settings.net_weight_std, "weight_decay": settings.weight_decay,
                         "max_iter": settings.max_iter, "adversarial": settings.adversarial,
                         "adversarial_rounds": settings.adversarial_rounds},
            "draws": [f.info for f in flights], "summary": summary, **(extra_meta or {})}
    net = NetFile(x_mean=x_mean, x_std=x_std, W1=result.arrays["W1"], b1=result.arrays["b1"],
                  W2=result.arrays["W2"], b2=result.arrays["b2"], W3=result.arrays["W3"], b3=result.arrays["b3"],
                  theta_mean=theta_mean, theta_std=theta_std, meta=meta)
    return net, summary


def _finite_or_none(x: float):
    return round(float(x), 4) if np.isfinite(x) else None


def save(net: NetFile, path: str | Path, force: bool = False) -> Path:
    """Write the basis file; an existing file is kept unless ``force``."""
    path = Path(path)
    if path.exists() and not force:
        raise ConfigError(f"{path}: exists; allowed: a new file, or --force to replace it")
    if not path.parent.is_dir():
        raise ConfigError(f"{path}: folder {path.parent} does not exist")
    return write_net(path, net)
