"""The envelope campaign per force-model basis, the held-out rows and the constant-weights ceiling.

    python -m vtoladapt.learn.evaluate --runs 40 --out out/basis_eval

flies the envelope campaign's draws (``scenarios/envelope.toml``, its own seed 1111: disjoint from the
training draws' seed 2222 of the shipped learned bases) once per basis (``paper``, ``extended``,
``learned``: every controller of the file, each adapting that basis), and the learned basis once more
with each airframe flying the *other* family's network (held-out airframe: trained on caltech_vtol
only, flown on px4_standard_vtol, and the reverse). Each goes to ``<out>/<row>/`` as a campaign
does (``campaign.parquet``, ``summary.json``). ``<out>/comparison.json`` and ``comparison.md`` hold the
table: per basis, the fraction of draws where each target holds with its 95 % Wilson interval,
per airspeed bin, on the conditions held out of training (the fan schedule and bearing sector the
shipped bases never saw), and the constant-weights ceiling.

``--learned-files LABEL=DIR`` adds a row flying the networks ``DIR/<vehicle>.npz`` (e.g. trained with
``learn-basis --adversarial``).

**The ceiling** (:func:`vtoladapt.experiments.ceiling.ceiling_fit`): for each draw, the best *constant*
weights of a basis for the whole run, by least squares on the aircraft's true specific force with the true incident flow,
the throttles the rotors actually had (the lift collective as the RMS of the four rotors: the
same total thrust) and the true attitude and rates, judged by the same target (p95 < 0.05 g in
every true-airspeed bin, after the first 2 s). It is what any estimator of that basis could do at
best, with no sensor and no adaptation lag. It is fitted on each law's *own* flight with that basis
(the campaign computes it per run, :func:`vtoladapt.experiments.envelope.yardstick_columns`): a law
that flies differently meets different conditions, so a ceiling from another law's flight (until
issue #34 every basis's was fitted on the composite law's flights with the paper's basis) is not
its ceiling. Beside it, the ceiling with the controller's own inputs and accelerometer, filtered as
it filters them (:func:`vtoladapt.experiments.ceiling.measured_ceiling_fit`): the gap between the two is
what sensing costs.

**The yardstick** (:mod:`vtoladapt.experiments.yardstick`): per law and row, the fraction of draws
whose prediction error on probe-valid samples passes one tick and ``horizon_s`` ahead, the no-model
hold's at both (the baseline every model must beat), and the median blind time.
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

from ..stats import fraction_holding
# part of this module's interface (the ceiling is the experiments', which the envelope campaign judges with)
from ..experiments.ceiling import ceiling_fit, measured_ceiling_fit, true_inputs  # noqa: F401

CAMPAIGN = Path(__file__).resolve().parents[3] / "scenarios" / "envelope.toml"
BASES = ("paper", "extended", "learned")
HELD_OUT = {"fan_schedule": "ramp_100", "fan bearing": "[225,315) deg"}
"""Conditions the shipped learned bases never saw in training (``learn-basis --hold-out-schedule ramp_100
--hold-out-bearing 225:315``); the group labels are the campaign's."""
FAMILIES = ("caltech_vtol", "px4_standard_vtol")


def vehicle_files(folder: Path, nets: dict[str, Path], tag: str, allow_other: bool = False) -> dict[str, str]:
    """Vehicle files (written into ``folder``) that fly ``nets[vehicle]`` as their learned basis."""
    from ..vehicle import VEHICLE_DIR

    folder.mkdir(parents=True, exist_ok=True)
    out = {}
    for name, net in nets.items():
        path = folder / f"{name}_{tag}.toml"
        path.write_text((VEHICLE_DIR / f"{name}.toml").read_text()
                        + f'\n[basis_settings.learned]\nfile = "{Path(net).resolve()}"\n'
                        + ("allow_other_vehicle = true\n" if allow_other else ""))
        out[name] = str(path)
    return out


def cross_vehicle_files(folder: Path) -> dict[str, str]:
    """Vehicle files that fly the other family's shipped network (held-out airframe)."""
    from ..bases.learned import TRAINED_DIR

    return {name: vehicle_files(folder, {name: TRAINED_DIR / f"{other}.npz"}, f"with_{other}_net", True)[name]
            for name, other in zip(FAMILIES, reversed(FAMILIES))}


def learned_files_option(text: str) -> tuple[str, dict[str, Path]]:
    """``--learned-files LABEL=DIR``: the label and the folder's ``<vehicle>.npz`` for both families."""
    from ..config import ConfigError

    label, sep, folder = text.partition("=")
    if not sep or not label.isidentifier():
        raise ConfigError(f"--learned-files {text!r}: allowed: LABEL=DIR with LABEL a plain name (letters, digits, _)")
    nets = {v: Path(folder) / f"{v}.npz" for v in FAMILIES}
    missing = [str(p) for p in nets.values() if not p.is_file()]
    if missing:
        raise ConfigError(f"--learned-files {text!r}: {', '.join(missing)} not found; allowed: a folder with a "
                          f"trained file per vehicle family ({', '.join(v + '.npz' for v in FAMILIES)})")
    return label, nets


def specs_for(specs, basis: str, vehicle_files: dict | None = None, controllers=None) -> list:
    """The campaign's runs with ``[controller] basis`` set (and the vehicles swapped for ``vehicle_files``)."""
    out = []
    for s in specs:
        if controllers and s.controller not in controllers:
            continue
        m = copy.deepcopy(s.mapping)
        m["controller"] = {**m.get("controller", {}), "basis": basis}
        if vehicle_files:
            m["vehicle"] = vehicle_files.get(m["vehicle"], m["vehicle"])
        out.append(dataclasses.replace(s, mapping=m))
    return out


def _frac(outcomes) -> dict:
    f = fraction_holding(outcomes)
    return {"fraction": f.fraction, "ci95": list(f.ci95), "successes": f.successes, "n": f.n}


YARDSTICK = (("pred_valid_pass", "one tick, probe valid"), ("pred_horizon_pass", "horizon, probe valid"),
             ("hold_pass", "hold, one tick"), ("hold_horizon_pass", "hold, horizon"),
             ("ceiling_pass", "ceiling (own flights)"), ("ceiling_measured_pass", "ceiling, measured inputs"))
"""The yardstick's per-controller entries of a row's summary (:data:`vtoladapt.experiments.envelope.YARDSTICK_KEYS`)
and their column labels."""


def compare(out: Path, rows: dict[str, Path]) -> dict:
    """comparison.json and comparison.md from each row's summary.json (the ceilings: each law's own flights)."""
    table: dict = {"rows": {}, "ceiling": {}, "held_out": HELD_OUT}
    for name, folder in rows.items():
        s = json.loads((folder / "summary.json").read_text())
        entry = {"targets": {k: s["targets"][k] for k in ("pred_err_every_bin", "beats_pid_pd", "finite_logs",
                                                          "alpha_protect_brief")},
                 "by_airspeed": {b: v["pred_err_every_bin"] for b, v in s["by_airspeed"].items()},
                 "groups": {f"{g}: {lab}": {k: v[k] for k in ("pred_err_every_bin", "beats_pid_pd")}
                            for g, labs in s["groups"].items() for lab, v in labs.items()},
                 "controllers": {c: {k: v.get(k) for k in ("beats_pid_pd", "vel_err_rms_mps",
                                                          "pred_err_p95_g_worst_bin", "blind_fraction",
                                                          *(y for y, _ in YARDSTICK)) if k in v}
                                 for c, v in s["controllers"].items()},
                 "campaign": s["campaign"]}
        table["rows"][name] = entry
    table["paired"] = paired(rows)
    # the ceilings per row and law, each on that law's own flights with the row's basis
    for name, entry in table["rows"].items():
        for cid, c in entry["controllers"].items():
            if "ceiling_pass" in c:
                table["ceiling"].setdefault(name, {})[cid] = {"true inputs": c["ceiling_pass"],
                                                             "measured inputs": c["ceiling_measured_pass"]}
    (out / "comparison.json").write_text(json.dumps(table, indent=1))
    (out / "comparison.md").write_text(markdown(table))
    return table


def worst_bin(folder: Path) -> dict[int, float]:
    """Per draw: the composite's worst-bin p95 prediction error (g) and whether every bin is below 0.05 g."""
    import pyarrow.parquet as pq

    t = pq.read_table(folder / "campaign.parquet").to_pydict()
    bins = [k for k in t if k.startswith("pred_err_p95_g[")]
    out = {}
    for i, c in enumerate(t["controller"]):
        if c == "composite":
            vals = [t[b][i] for b in bins if t[b][i] is not None and np.isfinite(t[b][i])]
            out[int(t["run"][i])] = max(vals) if vals else float("nan")
    return out


def paired(rows: dict[str, Path]) -> dict:
    """Each row against the paper's basis, draw by draw: the composite's worst-bin p95 difference (Hodges-Lehmann
    estimate and 95 % interval of the signed-rank test, :func:`vtoladapt.experiments.pairs.paired_difference`) and
    the draws that pass only with one of the two."""
    from ..experiments.pairs import paired_difference

    if "paper" not in rows:
        return {}
    base = worst_bin(rows["paper"])
    out = {}
    for name, folder in rows.items():
        if name == "paper":
            continue
        other = worst_bin(folder)
        runs = sorted(set(base) & set(other))
        a = np.array([other[r] for r in runs])
        b = np.array([base[r] for r in runs])
        out[name] = {"worst_bin_p95_g_minus_paper": paired_difference(a, b),
                     "pass_only_here": int(np.sum((a < 0.05) & ~(b < 0.05))),
                     "pass_only_with_paper": int(np.sum(~(a < 0.05) & (b < 0.05))), "draws": len(runs)}
    return out


def _cell(d: dict | None) -> str:
    if not d or not d.get("n"):
        return "–"
    lo, hi = d["ci95"]
    return f"{d['fraction']:.2f} ({d['successes']}/{d['n']}) [{lo:.2f}, {hi:.2f}]"


def _mi(d: dict | None) -> str:
    if not d or d.get("median") is None:
        return "–"
    lo, hi = d["iqr"]
    return f"{d['median']:.3g} [{lo:.3g}, {hi:.3g}]"


def markdown(table: dict) -> str:
    """The comparison as Markdown tables (README "Force-model bases compared")."""
    rows = table["rows"]
    names = list(rows)
    any_row = rows[names[0]]
    c = any_row["campaign"]
    lines = [f"Envelope campaign draws: {c.get('runs', '?')} (seed {c.get('seed', '?')}), every controller "
             "adapting the basis of the column; fraction of draws where the target holds (successes/judged) "
             "[95 % Wilson interval].", "",
             "| target | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for key, label in (("pred_err_every_bin", "composite p95 prediction error < 0.05 g in every airspeed bin"),
                       ("beats_pid_pd", "every adaptive law beats PID and PD (RMS ‖ṽ‖)"),
                       ("finite_logs", "every log finite"),
                       ("alpha_protect_brief", "composite: α past the protected angle only briefly")):
        lines.append(f"| {label} | " + " | ".join(_cell(rows[n]["targets"][key]) for n in names) + " |")
    for b in any_row["by_airspeed"]:
        lines.append(f"| p95 < 0.05 g in bin {b} m/s | " + " | ".join(_cell(rows[n]["by_airspeed"].get(b))
                                                                    for n in names) + " |")
    for g in any_row["groups"]:
        held = any(g.endswith(f": {v}") and g.startswith(k) for k, v in table["held_out"].items())
        tag = " (held out of training)" if held else ""
        lines.append(f"| p95 every bin, {g}{tag} | " + " | ".join(
            _cell(rows[n]["groups"].get(g, {}).get("pred_err_every_bin")) for n in names) + " |")
    lines.append("| composite worst-bin p95 [g], median [IQR] | " + " | ".join(
        _mi(rows[n]["controllers"].get("composite", {}).get("pred_err_p95_g_worst_bin")) for n in names) + " |")
    for cid in any_row["controllers"]:
        lines.append(f"| RMS ‖ṽ‖ [m/s] of {cid}, median [IQR] | " + " | ".join(
            _mi(rows[n]["controllers"].get(cid, {}).get("vel_err_rms_mps")) for n in names) + " |")
    if table.get("paired"):
        lines += ["", "Paired with the paper's basis, draw by draw (composite law): the difference of the worst-bin "
                      "p95 prediction error (Hodges-Lehmann estimate [95 % interval], signed-rank test) and the draws "
                      "that meet the target with only one of the two:", "",
                  "| basis | worst-bin p95 minus the paper's [g] | pass only with it | pass only with the paper |",
                  "|---|---|---|---|"]
        for n, d in table["paired"].items():
            e = d["worst_bin_p95_g_minus_paper"]
            est = "–" if e["estimate"] is None else f"{e['estimate']:+.4f} [{e['ci95'][0]:+.4f}, {e['ci95'][1]:+.4f}]"
            lines.append(f"| {n} | {est} | {d['pass_only_here']}/{d['draws']} | {d['pass_only_with_paper']}/{d['draws']} |")
    if any("pred_valid_pass" in c for n in names for c in rows[n]["controllers"].values()):
        lines += ["", "The yardstick (issue #34; `vtoladapt.experiments.yardstick`): per law, the fraction of draws "
                      "whose p95 prediction error is below 0.05 g in every airspeed bin, scored on probe-valid samples "
                      "(0.5 s after the probe is used again) one tick ahead and with θ̂ frozen 0.5 s before the "
                      "sample; the no-model hold (the filtered accelerometer held from one tick / 0.5 s earlier) on "
                      "the same samples; the constant-weights ceiling fitted on the law's own flights (true inputs; "
                      "measured inputs through the 10 Hz filter); and the median share of the run flown blind:", ""]
        for n in names:
            ctrl = {c: v for c, v in rows[n]["controllers"].items() if "pred_valid_pass" in v}
            if not ctrl:
                continue
            lines += [f"**{n}**", "", "| law | " + " | ".join(lab for _, lab in YARDSTICK) + " | blind, median |",
                      "|---|" + "---|" * (len(YARDSTICK) + 1)]
            for cid, v in ctrl.items():
                b = (v.get("blind_fraction") or {}).get("median")
                lines.append(f"| {cid} | " + " | ".join(_cell(v.get(k)) for k, _ in YARDSTICK)
                             + f" | {'–' if b is None else f'{100 * b:.1f} %'} |")
            lines.append("")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    """``python -m vtoladapt.learn.evaluate``: every row's campaign, the ceilings, comparison.json/.md."""
    from ..campaign.runner import plan_campaign_file, run_campaign

    p = argparse.ArgumentParser(prog="python -m vtoladapt.learn.evaluate", description=__doc__.split("\n\n")[0])
    p.add_argument("--campaign", type=Path, default=CAMPAIGN)
    p.add_argument("--runs", type=int, default=40)
    p.add_argument("--seed", type=int, default=None, help="default: the campaign file's (1111)")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--bases", default=",".join(BASES))
    p.add_argument("--no-cross", action="store_true", help="skip the held-out-airframe row")
    p.add_argument("--controllers", default="", help="comma-separated subset (default: the file's)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--keep", action="store_true", help="reuse a row whose summary.json exists in --out")
    p.add_argument("--learned-files", action="append", default=[], metavar="LABEL=DIR",
                   help="one more row: the learned basis flown from DIR/<vehicle>.npz (networks you trained)")
    args = p.parse_args(argv)
    try:
        extra = [learned_files_option(t) for t in args.learned_files]
    except Exception as e:                       # one line, like every refusal of the tool
        print(f"error: {e}", file=sys.stderr)
        return 2
    cf, specs = plan_campaign_file(args.campaign, runs=args.runs, seed=args.seed)
    controllers = [c for c in args.controllers.split(",") if c] or None
    args.out.mkdir(parents=True, exist_ok=True)
    repo = CAMPAIGN.parents[1]
    shown = args.campaign.resolve()
    info = {"file": str(shown.relative_to(repo) if shown.is_relative_to(repo) else shown), "runs": args.runs, "seed": args.seed or cf.config.seed,
            "sampling": cf.config.sampling, "duration_s": 40.0}
    rows: dict[str, Path] = {}
    # (row name, basis, vehicle files to fly instead of the shipped ones, the row's folder in --out)
    plan = [(b, b, None, b) for b in args.bases.split(",")]
    if not args.no_cross and "learned" in args.bases.split(","):
        plan.append(("learned (other airframe's network)", "learned", cross_vehicle_files(args.out / "vehicles"),
                     "learned_cross"))
    for label, nets in extra:
        plan.append((f"learned ({label})", "learned", vehicle_files(args.out / "vehicles", nets, label),
                     f"learned_{label}"))
    for name, basis, vfiles, folder_name in plan:
        folder = args.out / folder_name
        rows[name] = folder
        if args.keep and (folder / "summary.json").is_file():
            continue
        t0 = time.perf_counter()
        run_campaign(specs_for(specs, basis, vfiles, controllers), folder, scheduler="none", n_workers=args.workers,
                     show_progress=False, campaign=dict(info, basis=basis, cross=vfiles is not None))
        print(f"{name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    table = compare(args.out, rows)
    print(markdown(table))
    return 0


if __name__ == "__main__":
    sys.exit(main())
