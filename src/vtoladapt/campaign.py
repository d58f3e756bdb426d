"""Monte-Carlo campaigns: many runs of one scenario with varied seeds and parameters, on Dask.

``vtoladapt campaign SCENARIO --runs N --vary plant.coefficients.CL1=2.8:3.6 --out DIR`` draws
``N`` variants of the scenario (each a new seed and, per ``--vary``, a value uniform in
``[lo, hi]`` for a dotted scenario key), validates every variant before anything runs, then runs
them on a Dask cluster: a local one by default (one process per core), or an existing scheduler
(``--scheduler tcp://host:8786``) when a campaign outgrows one machine, or in this process
on one thread per core (``--scheduler none``: no worker processes to start). It writes ``campaign.parquet`` (one row per run: the drawn values and the
run's metrics), ``summary.json`` and a histogram figure.

All draws come from ``numpy.random.default_rng(scenario seed)``: the same command gives the same
campaign, whatever the cluster.
"""
from __future__ import annotations

import copy
import json
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from .config import ConfigError, read_toml


@dataclass(frozen=True)
class Variation:
    """A scenario key drawn uniformly in ``[low, high]`` for each run."""

    key: str
    low: float
    high: float

    @classmethod
    def parse(cls, text: str) -> "Variation":
        """``"plant.coefficients.CL1=2.8:3.6"`` -> Variation."""
        try:
            key, rng = text.split("=", 1)
            low, high = (float(v) for v in rng.split(":"))
        except ValueError:
            raise ConfigError(f"--vary {text!r}: expected KEY=LOW:HIGH, e.g. plant.coefficients.CL1=2.8:3.6") \
                from None
        if not (math.isfinite(low) and math.isfinite(high) and low <= high):
            raise ConfigError(f"--vary {text!r}: need finite LOW <= HIGH")
        return cls(key.strip(), low, high)


@dataclass(frozen=True)
class RunSpec:
    """One run of a campaign: the scenario mapping to validate and run, and what was drawn."""

    index: int
    mapping: dict
    source: str
    drawn: dict


def _set_dotted(mapping: dict, key: str, value) -> None:
    parts = key.split(".")
    node = mapping
    for p in parts[:-1]:
        node = node.setdefault(p, {})
        if not isinstance(node, dict):
            raise ConfigError(f"--vary {key}: '{p}' is not a table in the scenario")
    node[parts[-1]] = value


def plan_campaign(scenario_path: str | Path, runs: int, variations: list[Variation],
                  seed: Optional[int] = None) -> list[RunSpec]:
    """Draw and validate every run before any runs (a bad key or value fails here, naming it)."""
    if runs < 1:
        raise ConfigError(f"--runs = {runs}: must be >= 1")
    from .scenario import scenario_from_mapping

    path = Path(scenario_path)
    base = read_toml(path)
    base_scenario = scenario_from_mapping(base, str(path))
    rng = np.random.default_rng(base_scenario.seed if seed is None else seed)
    specs = []
    for i in range(runs):
        mapping = copy.deepcopy(base)
        drawn = {"seed": int(rng.integers(0, 2**31 - 1))}
        mapping["seed"] = drawn["seed"]
        for v in variations:
            drawn[v.key] = float(rng.uniform(v.low, v.high))
            _set_dotted(mapping, v.key, drawn[v.key])
        mapping["experiment"] = {"kind": "single"}
        scenario_from_mapping(mapping, f"{path} (campaign run {i}, {drawn})")
        specs.append(RunSpec(i, mapping, str(path), drawn))
    return specs


def run_one(spec: RunSpec) -> dict:
    """Run one campaign member (executed on a Dask worker) and return its row."""
    from .experiments import fan_throttle_series
    from .metrics import run_metrics
    from .scenario import scenario_from_mapping
    from .simulate import simulate

    scenario = scenario_from_mapping(spec.mapping, spec.source)
    result = simulate(scenario)
    row = {"run": spec.index, **spec.drawn}
    # one column per scalar metric (the per-airspeed-bin prediction error is a mapping: left out)
    row.update({k: v for k, v in run_metrics(result, fan_throttle_series(scenario, result.time_s)).items()
                if not isinstance(v, dict)})
    row["wall_time_s"] = result.metadata["wall_time_s"]
    return row


def run_campaign(specs: list[RunSpec], out: Path, scheduler: Optional[str] = "local",
                 n_workers: Optional[int] = None, show_progress: bool = True) -> list[dict]:
    """Run the planned campaign and write ``campaign.parquet``, ``summary.json``, ``fig_campaign.png``.

    ``scheduler``: ``"local"`` (a LocalCluster, one single-threaded process per core),
    ``"none"`` (in this process, ``n_workers`` threads, default one per core), or a scheduler
    address.
    """
    if n_workers is not None and n_workers < 1:
        raise ConfigError(f"--workers = {n_workers}: must be >= 1 (or left out: one per core)")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    bar = None
    if show_progress:
        from tqdm import tqdm

        bar = tqdm(total=len(specs), unit="run", desc="campaign", file=sys.stderr)
    rows = []
    if scheduler in (None, "none"):
        # the compiled loop releases the GIL: threads give every core a run without new processes
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=n_workers if n_workers is not None else os.cpu_count() or 1) as pool:
            for row in pool.map(run_one, specs):
                rows.append(row)
                if bar is not None:
                    bar.update(1)
    else:
        from dask.distributed import Client, LocalCluster, as_completed

        cluster = None
        if scheduler == "local":
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0")  # any free port: two campaigns may run at once
            client = Client(cluster)
        else:
            client = Client(scheduler)
        try:
            futures = client.map(run_one, specs, pure=False)
            for fut in as_completed(futures):
                rows.append(fut.result())
                if bar is not None:
                    bar.update(1)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    if bar is not None:
        bar.close()
    rows.sort(key=lambda r: r["run"])
    _write_outputs(rows, out, tuple(k for k in specs[0].drawn if k != "seed") if specs else ())
    return rows


def _write_outputs(rows: list[dict], out: Path, varied: tuple[str, ...] = ()) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    keys = list(rows[0])
    table = pa.table({k: [r.get(k, float("nan")) for r in rows] for k in keys})
    pq.write_table(table, out / "campaign.parquet")
    summary = {}
    for k in keys:
        vals = np.array([r.get(k, np.nan) for r in rows], dtype=float)
        if k == "run" or not np.isfinite(vals).any():
            continue
        summary[k] = {"mean": float(np.nanmean(vals)), "std": float(np.nanstd(vals)),
                      "min": float(np.nanmin(vals)), "p95": float(np.nanpercentile(vals, 95)),
                      "max": float(np.nanmax(vals))}
    (out / "summary.json").write_text(json.dumps({"runs": len(rows), "columns": summary}, indent=2))
    figure_campaign_png(rows, out / "fig_campaign.png", varied)


def figure_campaign_png(rows: list[dict], path: Path, varied: list[str] | tuple[str, ...] = ()) -> Path:
    """The campaign's figure: metric histograms (whole-number counts) and each metric against
    every varied scenario key, with the key's unit from the scenario's declarations."""
    from .experiments import figure_campaign

    return figure_campaign(rows, path, varied, {k: u for k in varied if (u := _setting_unit(k))})


def _setting_unit(dotted_key: str) -> str | None:
    """The declared unit of a dotted scenario key (``plant.stall_angle_deg`` -> ``deg``), or None."""
    import dataclasses

    from .scenario import Scenario

    cls = Scenario
    parts = dotted_key.split(".")
    for i, part in enumerate(parts):
        fields = {f.name: f for f in dataclasses.fields(cls)} if dataclasses.is_dataclass(cls) else {}
        f = fields.get(part)
        if f is None:
            return None
        if i == len(parts) - 1:
            unit = f.metadata.get("unit")
            return unit if unit and unit != "-" else None
        default = f.default if f.default is not dataclasses.MISSING else None
        if default is None and f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        cls = type(default)
    return None


def register_cli(subparsers) -> None:
    p = subparsers.add_parser("campaign", help="Monte-Carlo campaign of a scenario on Dask",
                              description=__doc__.split("\n\n")[1])
    p.add_argument("scenario", help="scenario TOML")
    p.add_argument("--runs", type=int, required=True, help="number of runs")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=LOW:HIGH",
                   help="draw this dotted scenario key uniformly per run (repeatable)")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument("--scheduler", default="local",
                   help="'local' (default: a local Dask cluster), 'none' (this process, threads) or an address")
    p.add_argument("--workers", type=int, default=None,
                   help="local cluster processes or in-process threads (default: cores)")
    p.add_argument("--seed", type=int, default=None, help="campaign seed (default: the scenario's)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=_cmd_campaign)


def _cmd_campaign(args) -> int:
    specs = plan_campaign(args.scenario, args.runs, [Variation.parse(v) for v in args.vary], args.seed)
    rows = run_campaign(specs, args.out, args.scheduler, args.workers, not args.quiet)
    v = np.array([r["vel_err_rms_mps"] for r in rows])
    print(f"{len(rows)} runs: RMS velocity error mean {v.mean():.4f} m/s, max {v.max():.4f} m/s; "
          f"wrote {args.out}/campaign.parquet, summary.json, fig_campaign.png")
    return 0
