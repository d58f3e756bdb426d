"""Monte-Carlo campaigns: many runs of one scenario with varied seeds and parameters, on Dask.

``vtoladapt campaign SCENARIO --runs N --vary plant.coefficients.CL1=2.8:3.6 --out DIR`` draws
``N`` variants of the scenario (each a new seed and, per ``--vary``, a value uniform in
``[lo, hi]`` for a dotted scenario key), validates every variant before anything runs, then runs
them on a Dask cluster: a local one by default (one process per core), or an existing scheduler
(``--scheduler tcp://host:8786``) when a campaign outgrows one machine, or in this process
on one thread per core (``--scheduler none``: no worker processes to start). It writes
``campaign.parquet`` (one row per run: the drawn values and the run's metrics),
``summary.json`` and a histogram figure.

The local cluster's scheduler, workers and status page listen on ``127.0.0.1`` only (another
address with ``--listen``); connecting to a given scheduler gives up after
:data:`SCHEDULER_CONNECT_TIMEOUT_S` with a one-line error.

All draws come from ``numpy.random.default_rng(scenario seed)``: the same command gives the same
campaign, whatever the cluster.
"""
from __future__ import annotations

import copy
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from .config import ConfigError, check_flag, read_toml
from .outputs import OutputDir, add_force_argument, output_path, write_json, write_parquet

SCHEDULER_CONNECT_TIMEOUT_S = 5.0
"""How long ``--scheduler ADDRESS`` waits for the scheduler to answer."""
LOOPBACK = "127.0.0.1"
SCHEDULER_SCHEMES = ("tcp://", "tls://", "ucx://", "inproc://", "ws://", "wss://")


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
            if not key.strip() or any(not part for part in key.strip().split(".")):
                raise ValueError(key)
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
                  seed: Optional[int] = None, controller: Optional[str] = None) -> list[RunSpec]:
    """Draw and validate every run before any runs (a bad key or value fails here, naming it).

    A campaign flies single runs of one controller: a scenario whose ``[experiment]`` is a
    comparison or convergence study needs ``controller`` (``--controller``), rather than
    silently flying only its ``[controller] kind``.
    """
    from .config import check_value
    from .control.config import ControllerConfig
    from .limits import check_campaign_runs, check_run_size
    from .scenario import Scenario, scenario_from_mapping

    runs = check_flag("--runs", runs, ge=1, integer=True)
    if seed is not None:
        seed = check_value(Scenario, "seed", seed, "--seed")
    path = Path(scenario_path)
    base = read_toml(path)
    base_scenario = scenario_from_mapping(base, str(path))
    if controller is not None:
        controller = check_value(ControllerConfig, "kind", controller, "--controller")
        base = copy.deepcopy(base)
        base.setdefault("controller", {})["kind"] = controller
        base_scenario = scenario_from_mapping(base, str(path))
    elif base_scenario.experiment.kind != "single":
        raise ConfigError(
            f"{path}: [experiment] kind = {base_scenario.experiment.kind!r}: a campaign flies "
            f"single runs of one controller and would fly only [controller] kind = "
            f"{base_scenario.controller.kind!r}; pass --controller ID to say which")
    check_campaign_runs(runs, base)
    check_run_size(base_scenario, f"{path} (each campaign run)", n_runs=os.cpu_count() or 1)
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
    if len(result) > 1:  # a run that diverged at once has no metrics, only its divergence
        # one column per scalar metric (the per-airspeed-bin prediction error is a mapping: left out)
        row.update({k: v for k, v in run_metrics(result, fan_throttle_series(scenario, result.time_s)).items()
                    if not isinstance(v, dict)})
    row["wall_time_s"] = result.metadata["wall_time_s"]
    row["diverged"] = float(result.diverged)
    row["diverged_at_s"] = result.diverged_at_s if result.diverged else float("nan")
    return row


MAX_WORKERS = 1024
"""Most local worker processes or threads (each holds one run's log)."""


def connect_scheduler(address: str):
    """A Dask client of the scheduler at ``address``; a one-line ``ConfigError`` if none answers
    within :data:`SCHEDULER_CONNECT_TIMEOUT_S`."""
    from dask.distributed import Client

    _check_scheduler(address)
    try:
        return Client(address, timeout=SCHEDULER_CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise ConfigError(f"--scheduler {address!r}: no Dask scheduler answered within "
                          f"{SCHEDULER_CONNECT_TIMEOUT_S:g} s ({reason[:200]})") from None


def local_cluster(n_workers: Optional[int] = None, listen: str = LOOPBACK):
    """The campaign's local Dask cluster: one single-threaded worker process per core.

    Scheduler, workers (and their nannies) and the status page all listen on ``listen``
    (loopback by default, so nothing is reachable from the network), each on a free port so two
    campaigns can run at once.
    """
    from dask.distributed import LocalCluster

    return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, host=listen,
                        dashboard_address=f"{listen}:0")


def _check_scheduler(address: str) -> None:
    if address in ("local", "none"):
        return
    if not address.startswith(SCHEDULER_SCHEMES) and ":" not in address:
        raise ConfigError(f"--scheduler {address!r}: expected 'local', 'none' or an address such "
                          "as tcp://host:8786")


def run_campaign(specs: list[RunSpec], out: Path, scheduler: Optional[str] = "local",
                 n_workers: Optional[int] = None, show_progress: bool = True,
                 listen: str = LOOPBACK) -> list[dict]:
    """Run the planned campaign and write ``campaign.parquet``, ``summary.json``, ``fig_campaign.png``.

    ``scheduler``: ``"local"`` (a LocalCluster, one single-threaded process per core, every
    socket on ``listen``), ``"none"`` (in this process, ``n_workers`` threads, default one per
    core), or a scheduler address.
    """
    if n_workers is not None:
        check_flag("--workers", n_workers, ge=1, le=MAX_WORKERS, integer=True)
    out = Path(out)
    rows: list[dict] = []
    if scheduler in (None, "none"):
        # the compiled loop releases the GIL: threads give every core a run without new processes
        from concurrent.futures import ThreadPoolExecutor, as_completed

        pool = ThreadPoolExecutor(max_workers=n_workers if n_workers is not None else os.cpu_count() or 1)
        bar = _progress(len(specs), show_progress)
        try:
            for fut in as_completed([pool.submit(run_one, spec) for spec in specs]):
                rows.append(fut.result())
                bar.update(1)
        finally:
            bar.close()
            # on an error or Ctrl-C no queued run starts; running ones finish their chunk
            pool.shutdown(wait=False, cancel_futures=True)
    else:
        from dask.distributed import Client, as_completed

        cluster = None
        if scheduler == "local":
            cluster = local_cluster(n_workers, listen)
            client = Client(cluster)
        else:
            client = connect_scheduler(scheduler)
        bar = _progress(len(specs), show_progress)
        try:
            futures = client.map(run_one, specs, pure=False)
            for fut in as_completed(futures):
                rows.append(fut.result())
                bar.update(1)
        finally:
            bar.close()
            client.close()
            if cluster is not None:
                cluster.close()
    rows.sort(key=lambda r: r["run"])
    out.mkdir(parents=True, exist_ok=True)
    _write_outputs(rows, out, tuple(k for k in specs[0].drawn if k != "seed") if specs else ())
    return rows


class _NoProgress:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, show: bool):
    if not show:
        return _NoProgress()
    from tqdm import tqdm

    return tqdm(total=total, unit="run", desc="campaign", file=sys.stderr)


def _write_outputs(rows: list[dict], out: Path, varied: tuple[str, ...] = ()) -> None:
    import pyarrow as pa

    keys = list(dict.fromkeys(k for r in rows for k in r))
    rows = [{k: r.get(k, float("nan")) for k in keys} for r in rows]  # a run diverged at once has no metrics
    table = pa.table({k: [r.get(k, float("nan")) for r in rows] for k in keys})
    write_parquet(table, out / "campaign.parquet")
    summary = {}
    for k in keys:
        vals = np.array([r.get(k, np.nan) for r in rows], dtype=float)
        if k == "run" or not np.isfinite(vals).any():
            continue
        summary[k] = {"mean": float(np.nanmean(vals)), "std": float(np.nanstd(vals)),
                      "min": float(np.nanmin(vals)), "p95": float(np.nanpercentile(vals, 95)),
                      "max": float(np.nanmax(vals))}
    diverged = int(sum(r.get("diverged", 0.0) for r in rows))
    write_json(out / "summary.json", {"runs": len(rows), "diverged_runs": diverged, "columns": summary})
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
    """Add the ``campaign`` sub-command to ``subparsers`` (its handler raises on bad input)."""
    p = subparsers.add_parser("campaign", help="Monte-Carlo campaign of a scenario on Dask",
                              description=__doc__.split("\n\n")[1])
    p.add_argument("scenario", help="scenario TOML")
    p.add_argument("--runs", type=int, required=True, help="number of runs")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=LOW:HIGH",
                   help="draw this dotted scenario key uniformly per run (repeatable)")
    p.add_argument("--out", type=output_path, required=True, help="output directory")
    p.add_argument("--scheduler", default="local",
                   help="'local' (default: a local Dask cluster), 'none' (this process, threads) or an address")
    p.add_argument("--listen", default=LOOPBACK, metavar="HOST",
                   help=f"address the local cluster's scheduler, workers and status page listen on "
                        f"(default {LOOPBACK}: this machine only)")
    p.add_argument("--controller", default=None,
                   help="controller to fly (required for a comparison or convergence scenario)")
    p.add_argument("--workers", type=int, default=None,
                   help="local cluster processes or in-process threads (default: cores)")
    p.add_argument("--seed", type=int, default=None, help="campaign seed (default: the scenario's)")
    p.add_argument("--quiet", action="store_true")
    add_force_argument(p)
    p.set_defaults(handler=_cmd_campaign)


def _check_listen(host: str) -> None:
    import ipaddress
    import re

    try:
        ipaddress.ip_address(host)
        return
    except ValueError:
        pass
    if not re.fullmatch(r"[A-Za-z0-9]([A-Za-z0-9.-]{0,251}[A-Za-z0-9])?", host):
        raise ConfigError(f"--listen {host!r}: not an IP address or host name")


def _cmd_campaign(args) -> int:
    variations = [Variation.parse(v) for v in args.vary]
    _check_listen(args.listen)
    _check_scheduler(args.scheduler)
    target = OutputDir(args.out, "campaign", force=args.force)
    if args.workers is not None:
        check_flag("--workers", args.workers, ge=1, le=MAX_WORKERS, integer=True)
    specs = plan_campaign(args.scenario, args.runs, variations, args.seed, args.controller)
    with target:
        rows = run_campaign(specs, target.path, args.scheduler, args.workers, not args.quiet,
                            listen=args.listen)
    v = np.array([r["vel_err_rms_mps"] for r in rows])
    print(f"{len(rows)} runs: RMS velocity error mean {v.mean():.4f} m/s, max {v.max():.4f} m/s; "
          f"wrote {args.out}/campaign.parquet, summary.json, fig_campaign.png")
    return 0
