#!/usr/bin/env python
"""A hostile pass over vtoladapt, re-runnable: what issue #27's reviewer did, as a script.

    python tools/hostile_pass.py                 # about four minutes on two cores (1101 cases)
    python tools/hostile_pass.py --scale 5 --seed 3
    python tools/hostile_pass.py --only files    # the file classes of issue #33 alone (550 cases)

It tries, as an attacker would: hand-made bad scenario, vehicle and campaign files (and a planted
manifest with a link out of the folder, a user's file named like an output, files that are not
files), a seeded fuzzer over the shipped scenario and vehicle files (values replaced, added and
deleted as text), the Python API (every settings class given values outside and inside its
range, then flown), the Gymnasium environments (actions and seeds of every wrong kind), and
signals (Ctrl-C and SIGTERM at random moments of a run and of a local-cluster campaign, two runs
into one folder), and the files of issue #33 (:mod:`hostile_files`): tampered learned-basis files
(every dtype, shape, value and meta of the wrong kind, decompression bombs, truncated and foreign
archives), tampered flight logs (empty, 0 rows, metadata of the wrong type, vehicle names that are
paths, ``.ulg`` files that are no ULog) and ``learn-basis`` argument abuse (the output an input or a
folder, the same log twice, missing folders). Every command case runs into a copy of an earlier output folder that also
holds a file of the user's, beside a file outside the folder that nothing may touch.

Each case ends as one of: a clean refusal (exit 2 or the API's ConfigError/ValueError, one line,
nothing on disk changed), ok (exit 0, a finite run), diverged (exit 1 "run diverged", or a result
that says so), an internal error (a traceback, an unexpected exception, a crash), a hang (no end
within --timeout), silent NaN (success with a non-finite state, observation or core metric) or
outputs damaged (the user's files or the outside file changed, a refused run changed the folder,
a partial file left, a manifest that lies). The last four must be zero; the exit status is 1
otherwise. Cases run in a worker process, so a crash costs the case, not the pass.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import hashlib
import io
import json
import math
import os
import queue
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

OUTCOMES = ("refused", "ok", "diverged", "internal", "hang", "silent_nan", "damaged")
HEADERS = ("cases tried", "clean refusals", "ok", "diverged", "internal errors", "hangs", "silent NaN",
           "outputs damaged")
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))  # the file classes' module beside this one
from hostile_files import file_cases, prepare_assets, run_file_case  # noqa: E402
SCENARIOS = REPO / "src" / "vtoladapt" / "scenarios"
VEHICLES = REPO / "src" / "vtoladapt" / "vehicles"
BASE_TEXT = (SCENARIOS / "gym_hold.toml").read_text().replace("duration_s = 20.0", "duration_s = 0.3")
VEHICLE_TEXT = (VEHICLES / "caltech_vtol.toml").read_text()
CORE_METRICS = ("vel_err_rms_mps", "pos_err_max_m")


# --- literals a fuzzer writes into a TOML file ---------------------------------------------------------
def literal(rng: random.Random, old: str = "") -> str:
    """A random TOML value: numbers at every magnitude and edge, non-finite ones, wrong types."""
    pick = rng.random()
    numbers = ["0", "-0.0", "1", "-1", "1e-300", "5e-324", "1e300", "-1e300", "1e9", "2.5", "-7.5",
               "9223372036854775807", "-9223372036854775808", "18446744073709551616", "nan", "inf", "-inf",
               "0.001", "100", "3600", "1e-4", "0.05", "1e6"]
    if pick < 0.45:
        return rng.choice(numbers)
    if pick < 0.6:  # near the old value
        try:
            v = float(old.split("#")[0])
            return repr(v * rng.choice([-1, 0.5, 2, 10, 1e3, 1e-3, 1.0000001]))
        except ValueError:
            return rng.choice(numbers)
    if pick < 0.7:
        return rng.choice(['"x"', '""', '"composite"', '"hold"', '"waypoints"', '"' + "a" * 5000 + '"', '"\\u0000"',
                           '"../../etc/passwd"', '"caltech_vtol"', '"pressure"'])
    if pick < 0.8:
        return rng.choice(["true", "false"])
    if pick < 0.95:
        n = rng.choice([0, 1, 2, 3, 4, 5, 8])
        return "[" + ", ".join(rng.choice(numbers) for _ in range(n)) + "]"
    return rng.choice(["[[0, 1], [1, 2, 3]]", "[[0, 0, 0, -1], [1, 1, 0, -1]]", "{ a = 1 }", "[[0, 60], [1e9, 60]]",
                       "1979-05-27", "[[]]"])


def in_range(rng: random.Random, meta: tuple) -> str:
    """A value its declaration allows (log-uniform over a wide positive range): fly it, do not refuse it."""
    lo, hi, integer, length = meta
    lo = -1e3 if lo is None else lo
    hi = 1e3 if hi is None else hi

    def one() -> str:
        if integer:
            return str(rng.randint(int(math.ceil(lo)), int(min(hi, lo + 1000))))
        if lo > 0 and hi / lo > 100:
            return repr(math.exp(rng.uniform(math.log(lo), math.log(hi))))
        return repr(rng.uniform(lo, hi))
    return "[" + ", ".join(one() for _ in range(length)) + "]" if length else one()


def fuzz_text(rng: random.Random, text: str, schema: dict[str, dict[str, tuple | None]], edits: int) -> str:
    """``text`` with ``edits`` random edits: a value replaced (half the time by one its key's range allows),
    a key of the schema added, a line deleted. ``schema``: section -> key -> numeric range or None."""
    lines = text.splitlines()
    for _ in range(edits):
        section, sections = "", []
        for ln in lines:
            if ln.startswith("[") and not ln.startswith("[["):
                section = ln.strip("[] ")
            sections.append(section)
        values = [i for i, ln in enumerate(lines) if "=" in ln and not ln.lstrip().startswith("#")
                  and not ln.startswith("[")]
        kind = rng.random()
        if kind < 0.6 and values:
            i = rng.choice(values)
            key, _, old = lines[i].partition("=")
            meta = schema.get(sections[i], {}).get(key.strip())
            value = in_range(rng, meta) if meta is not None and rng.random() < 0.5 else literal(rng, old.strip())
            lines[i] = f"{key.rstrip()} = {value}"
        elif kind < 0.85:
            section = rng.choice(list(schema))
            present = {ln.partition("=")[0].strip() for ln, sec in zip(lines, sections) if sec == section and "=" in ln}
            free = [k for k in schema[section] if k not in present]
            key = rng.choice(free) if free and rng.random() < 0.9 else "no_such_key"
            meta = schema[section].get(key)
            value = in_range(rng, meta) if meta is not None and rng.random() < 0.5 else literal(rng)
            header = f"[{section}]"
            line = f"{key} = {value}"
            if section == "":
                lines.insert(0, line)
            elif header in lines:
                lines.insert(lines.index(header) + 1, line)
            else:
                lines += ["", header, line]
        elif values:
            del lines[rng.choice(values)]
    return "\n".join(lines) + "\n"


def schema_keys(cls) -> dict[str, dict[str, tuple | None]]:
    """Section -> key -> ``(low, high, integer, length)`` of a numeric setting (None for the others)
    for a settings class tree (top-level keys under "")."""
    import typing

    from vtoladapt.config import _type_hints

    out: dict[str, dict] = {}

    def walk(c, section):
        for f in dataclasses.fields(c):
            if f.name == "source_path":
                continue
            tp = _type_hints(c)[f.name]
            if dataclasses.is_dataclass(tp):
                walk(tp, f"{section}.{f.name}" if section else f.name)
                continue
            args = [a for a in typing.get_args(tp) if a is not type(None)] if typing.get_origin(tp) is not tuple else []
            inner = args[0] if args else tp
            vector = typing.get_origin(inner) is tuple or typing.get_origin(tp) is tuple
            length = f.metadata.get("length") if vector else 0
            base = typing.get_args(inner)[0] if typing.get_origin(inner) is tuple else inner
            meta = None
            if base in (int, float) and (length or typing.get_origin(inner) is not tuple):
                m = f.metadata
                lo = m.get("gt") if m.get("gt") is not None else m.get("ge")
                hi = m.get("lt") if m.get("lt") is not None else m.get("le")
                meta = (lo, hi, base is int, length or 0)
            out.setdefault(section, {})[f.name] = meta
    walk(cls, "")
    return out


# --- the cases -----------------------------------------------------------------------------------------
def cli_case(group: str, argv: list, files: dict, prepare: str = "earlier") -> dict:
    return {"kind": "cli", "group": group, "argv": argv, "files": files, "prepare": prepare}


def handmade_cases() -> list[dict]:
    """Bad inputs written by hand: each must be refused in one line, nothing on disk changed."""
    b = BASE_TEXT
    flat = "\n".join("lift_rotor_positions_m = [[0.3, 0.0], [-0.3, 0.0], [0.2, 0.0], [-0.2, 0.0]]"
                     if ln.startswith("lift_rotor_positions_m") else ln for ln in VEHICLE_TEXT.splitlines())
    bad_scenarios = {
        "cannot hover": b + "\n[plant]\nmass_kg = 5.0\n",
        "starts outside the envelope": b + "\n[envelope]\nmin_height_m = 5.0\n",
        "mocap latency beyond its ring": b.replace("dt_control_s = 0.004", "dt_control_s = 0.001")
        + "\n[sensors.mocap]\nlatency_s = 0.2\n",
        "fault latency beyond its ring": b + '\n[[faults]]\nkind = "mocap_latency"\nstart_s = 0.1\nend_s = 0.2\n'
                                             'extra_latency_s = 0.6\n',
        "fault motor 100000000": b + '\n[[faults]]\nkind = "stuck_throttle"\nstart_s = 0.1\nend_s = 0.2\n'
                                     'motor = 100000000\n',
        "ragged waypoints under hold": b.replace('kind = "hold"', 'kind = "hold"\nwaypoints = [[0, 1], [1, 2, 3]]'),
        "plant substeps -3": b.replace("plant_substeps = 1", "plant_substeps = -3"),
        "dt 0": b.replace("dt_control_s = 0.004", "dt_control_s = 0"),
        "duration 1e5": b.replace("duration_s = 0.3", "duration_s = 1e5"),
        "plant mass 1e-4": b + "\n[plant]\nmass_kg = 1e-4\n",
        "plant inertia 1e-300": b + "\n[plant]\ninertia_kgm2 = [1e-300, 1e-300, 1e-300]\n",
        "turbulence length 1e-300": b.replace("altitude_m = 1.5", "altitude_m = 1.5\nlength_scale_m = [1e-300, 1, 1]"),
        "motor lag against a 20 ms plant step": b.replace("dt_control_s = 0.004", "dt_control_s = 0.02")
        + "\n[plant]\nlift_motor_time_constant_s = 0.005\n",
        "nan duration": b.replace("duration_s = 0.3", "duration_s = nan"),
        "unknown key": b + "\nbogus = 1\n",
        "vehicle missing": b.replace('vehicle = "caltech_vtol"', 'vehicle = "no_such_plane"'),
        "envelope min above max": b + "\n[envelope]\nmin_height_m = 10.0\nmax_height_m = 5.0\n",
        "31 faults": b + "".join('\n[[faults]]\nkind = "imu_nan"\nstart_s = 0.1\nend_s = 0.2\n' for _ in range(31)),
        "65 fan breakpoints": b.replace("schedule = [[0, 0]", "schedule = [" + "[0, 0], " * 65 + "[0, 0]"),
        "controller law unknown": b.replace('kind = "composite"', 'kind = "magic"'),
        "not TOML": "name = \n[[[",
        "binary": "\x00\x01\x02 not text",
        "empty": "",
        "campaign file as scenario": '[campaign]\nbase = "s.toml"\nruns = 2\nseed = 1\ncontrollers = ["pid"]\n',
    }
    cases = [cli_case("hand-made files", ["run", "{dir}/s.toml", "--out", "{out}", "--quiet"], {"s.toml": text})
             for text in bad_scenarios.values()]
    for name, vehicle in {"flat rotor layout": flat,
                          "mass 5e-324": VEHICLE_TEXT.replace("mass_kg = 1.70", "mass_kg = 5e-324"),
                          "wingspan 5e-324": VEHICLE_TEXT.replace("wingspan_m = 1.08", "wingspan_m = 5e-324")}.items():
        cases.append(cli_case("hand-made files", ["run", "{dir}/s.toml", "--out", "{out}", "--quiet"],
                              {"s.toml": b.replace('vehicle = "caltech_vtol"', 'vehicle = "v.toml"'),
                               "v.toml": vehicle}))
    cases.append(cli_case("hand-made files", ["run", "{dir}/s.toml", "--out", "{out}", "--quiet"], {"s.toml": b},
                          prepare="planted"))
    cases.append(cli_case("hand-made files", ["run", "{dir}/s.toml", "--out", "{out}", "--quiet"], {"s.toml": b},
                          prepare="collision"))
    cases.append(cli_case("hand-made files", ["run", "/dev/zero", "--out", "{out}", "--quiet"], {}))
    cases.append(cli_case("hand-made files", ["run", "{dir}", "--out", "{out}", "--quiet"], {}))
    cases.append(cli_case("hand-made files", ["run", "{dir}/s.toml", "--out", "{dir}/s.toml", "--quiet"],
                          {"s.toml": b}))
    cases.append(cli_case("hand-made files", ["campaign", "{dir}/s.toml", "--runs", "3", "--scheduler", "none",
                                              "--out", "{out}", "--quiet"],
                          {"s.toml": bad_scenarios["starts outside the envelope"]},
                          prepare="none"))
    cases.append(cli_case("hand-made files", ["campaign", "{dir}/s.toml", "--runs", "3", "--vary",
                                              "plant.mass_kg=4.9:6",
                                              "--scheduler", "none", "--out", "{out}", "--quiet"], {"s.toml": b},
                          prepare="none"))
    cases.append(cli_case("hand-made files", ["fit", "{dir}/d.csv", "--out", "{out}"],
                          {"d.csv": "airspeed_mps,alpha_deg,beta_deg,throttle_x_pct,throttle_z_pct,force_x_N,force_y_N,"
                                    "force_z_N\n" + "".join(f"{5 + i},2,0,40,50,0.5,0.1,{'1e300' if i == 3 else -12}\n"
                                                            for i in range(8))}, prepare="none"))
    cases.append(cli_case("hand-made files", ["run", "{dir}/s.toml", "--out", "{out}", "--quiet"], {"s.toml": b}))  # ok
    return cases


def fuzz_cases(rng: random.Random, n_scenarios: int, n_vehicles: int) -> list[dict]:
    from vtoladapt.sim.scenario import Scenario
    from vtoladapt.vehicle import Vehicle

    s_keys, v_keys = schema_keys(Scenario), schema_keys(Vehicle)
    s_keys[""]["duration_s"] = (0.0, 2.0, False, 0)  # drawn in range, a run stays short
    cases = []
    for _ in range(n_scenarios):
        text = fuzz_text(rng, BASE_TEXT, s_keys, rng.choice([1, 1, 2, 3]))
        cases.append(cli_case("fuzzed scenarios", ["run", "{dir}/s.toml", "--out", "{out}", "--quiet"],
                              {"s.toml": text}))
    for _ in range(n_vehicles):
        text = fuzz_text(rng, VEHICLE_TEXT, v_keys, rng.choice([1, 1, 2]))
        cases.append(cli_case("fuzzed vehicles", ["run", "{dir}/s.toml", "--out", "{out}", "--quiet"],
                              {"s.toml": BASE_TEXT.replace('vehicle = "caltech_vtol"', 'vehicle = "v.toml"'),
                               "v.toml": text}))
    return cases


SPECIAL = ["nan", "inf", "-inf", "huge", "tiny", "neg", "zero", "str", "none", "bool", "complex", "list", "big int"]


def api_cases(rng: random.Random, n: int) -> list[dict]:
    return [{"kind": "api", "group": "Python API", "pick": rng.random(), "field": rng.random(),
             "value": rng.choice(SPECIAL + ["in range"] * 4), "seed": rng.randrange(2**31)} for _ in range(n)]


def gym_cases(rng: random.Random, n: int) -> list[dict]:
    cases = []
    for _ in range(n):
        seed = rng.choice([0, 1, 7, 2**40, "1.5", "-1", "true", "list", "str", "none"])
        steps = [rng.choice(["zeros", "ones", "random", "nan", "inf", "complex", "huge", "short", "long", "str",
                             "bool", "list", "random", "random"]) for _ in range(rng.randint(1, 6))]
        cases.append({"kind": "gym", "group": "gym", "env": rng.choice(["single", "vector"]), "seed": seed,
                      "steps": steps, "residual": rng.random() < 0.5})
    return cases


# --- the worker: runs cases in one process, reports each -----------------------------------------------
def _snapshot(*roots: Path) -> dict:
    out = {}
    for root in roots:
        if root.is_file():
            out[str(root)] = hashlib.sha256(root.read_bytes()).hexdigest()
            continue
        for p in sorted(root.rglob("*")) if root.exists() else []:
            if p.is_symlink():
                out[str(p)] = "link:" + os.readlink(p)
            elif p.is_file():
                st = p.stat()
                out[str(p)] = (hashlib.sha256(p.read_bytes()).hexdigest(), st.st_mtime_ns)
    return out


def _outputs_sound(out: Path) -> str:
    """'' if ``out`` holds no partial file, valid JSON and a manifest that tells the truth; else what is wrong."""
    from vtoladapt.outputs import MANIFEST_NAME, PARTIAL_MARK, read_manifest

    if not out.exists():
        return ""
    for p in out.rglob("*"):
        if p.name.startswith(PARTIAL_MARK):
            return f"partial file {p}"
        if p.suffix == ".json" and p.is_file():
            try:
                json.loads(p.read_text(), parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
            except ValueError as exc:
                return f"invalid JSON {p}: {exc}"
    manifest = read_manifest(out)
    if (out / MANIFEST_NAME).exists() and manifest is None:
        return "unreadable manifest"
    for rel, entry in (manifest or {}).get("files", {}).items():
        p = out / rel
        proven = (isinstance(entry, dict) and p.is_file()
                  and hashlib.sha256(p.read_bytes()).hexdigest() == entry["sha256"])
        if not proven:
            return f"manifest lists {rel} which is not what was written"
    return ""


def _silent_nan(out: Path) -> str:
    """'' unless a successful run's log holds a non-finite state or a core metric is missing."""
    import numpy as np
    import pyarrow.parquet as pq

    from vtoladapt.layout import STATE_COLUMNS

    metrics = json.loads((out / "metrics.json").read_text())
    run = metrics.get("run", {})
    for key in CORE_METRICS:
        if run and not (isinstance(run.get(key), (int, float)) and math.isfinite(run[key])):
            return f"metrics run.{key} = {run.get(key)!r}"
    for log in out.rglob("*.parquet"):
        t = pq.read_table(log, columns=list(STATE_COLUMNS))
        if not all(np.isfinite(t.column(i).to_numpy()).all() for i in range(t.num_columns)):
            return f"non-finite state in {log.name}"
    return ""


def run_cli_case(case: dict, work: Path, baseline: Path) -> tuple[str, str]:
    from vtoladapt.cli import main

    d = work / "case"
    shutil.rmtree(d, ignore_errors=True)
    d.mkdir()
    for name, text in case["files"].items():
        (d / name).write_bytes(text.encode("utf-8", "surrogatepass"))
    out = d / "out"
    victim = work / "victim"
    victim.mkdir(exist_ok=True)
    (victim / "thesis.tex").write_text("four years of work")
    if case["prepare"] in ("earlier", "planted", "collision"):
        shutil.copytree(baseline, out, copy_function=shutil.copy2)
        (out / "notes.txt").write_text("the user's own notes")
    if case["prepare"] == "planted":
        manifest = json.loads((out / ".vtoladapt-manifest.json").read_text())
        manifest["files"]["sub/thesis.tex"] = {"bytes": 18, "sha256": hashlib.sha256(b"four years of work").hexdigest()}
        (out / ".vtoladapt-manifest.json").write_text(json.dumps(manifest))
        os.symlink(victim, out / "sub")
    if case["prepare"] == "collision":
        os.remove(out / "fig_run.png")
        manifest = json.loads((out / ".vtoladapt-manifest.json").read_text())
        manifest["files"].pop("fig_run.png")
        (out / ".vtoladapt-manifest.json").write_text(json.dumps(manifest))
        (out / "fig_run.png").write_bytes(b"the user's figure")
    mine = [out / "notes.txt"] + ([out / "fig_run.png"] if case["prepare"] == "collision" else [])
    user = {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in mine if p.exists()}
    before = _snapshot(out, victim)
    argv = [a.replace("{dir}", str(d)).replace("{out}", str(out)) for a in case["argv"]]
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(argv)
    text = err.getvalue().strip()
    if _snapshot(victim) != {k: v for k, v in before.items() if k.startswith(str(victim))}:
        return "damaged", f"the file outside --out changed: {text}"
    for path, digest in user.items():
        if not Path(path).exists() or hashlib.sha256(Path(path).read_bytes()).hexdigest() != digest:
            return "damaged", f"the user's {Path(path).name} changed (rc {rc}): {text}"
    lines = text.splitlines()
    if "Traceback" in text or "internal error" in text or rc not in (0, 1, 2):
        return "internal", f"rc {rc}: {text[-300:]}"
    if rc == 2:
        if len(lines) != 1:
            return "internal", f"rc 2 with {len(lines)} lines: {text[-300:]}"
        if _snapshot(out, victim) != before:
            return "damaged", f"a refused run changed the folder: {text}"
        return "refused", text
    wrong = _outputs_sound(out)
    if wrong:
        return "damaged", wrong
    if rc == 1:
        return ("diverged", text) if "run diverged" in text else ("internal", text)
    if argv[0] == "run":
        nan = _silent_nan(out)
        if nan:
            return "silent_nan", nan
    return "ok", ""


def _api_objects(base):
    from vtoladapt.gym.settings import HoldEnvConfig

    seen, out = set(), []

    def walk(obj, path):
        if isinstance(obj, tuple):
            for i, item in enumerate(obj):
                walk(item, path + (i,))
            return
        if not dataclasses.is_dataclass(obj) or id(obj) in seen:
            return
        seen.add(id(obj))
        if any("unit" in f.metadata for f in dataclasses.fields(obj)):
            out.append((path, obj))
        for f in dataclasses.fields(obj):
            walk(getattr(obj, f.name), path + (f.name,))
    walk(base, ())
    out.append((None, HoldEnvConfig(scenario=base)))
    return out


def _special(value: str, meta: dict, rng: random.Random):
    lo = meta.get("gt") if meta.get("gt") is not None else meta.get("ge")
    hi = meta.get("lt") if meta.get("lt") is not None else meta.get("le")
    return {"nan": math.nan, "inf": math.inf, "-inf": -math.inf, "huge": 1e300, "tiny": 5e-324, "neg": -1.0,
            "zero": 0, "str": "x", "none": None, "bool": True, "complex": 1 + 2j, "list": [1.0, 2.0],
            "big int": 10**30,
            "in range": rng.uniform(lo if lo is not None else -10.0, hi if hi is not None else 10.0)}[value]


def run_api_case(case: dict, base) -> tuple[str, str]:
    import numpy as np

    from vtoladapt.config import ConfigError
    from vtoladapt.layout import STATE_COLUMNS
    from vtoladapt.sim.driver import simulate

    rng = random.Random(case["seed"])
    objects = _api_objects(base)
    path, obj = objects[int(case["pick"] * len(objects))]
    fields = [f for f in dataclasses.fields(obj) if f.name != "source_path" and f.name != "scenario"]
    f = fields[int(case["field"] * len(fields))]
    value = _special(case["value"], f.metadata, rng)
    if isinstance(getattr(obj, f.name), tuple) and case["value"] not in ("list", "str"):
        value = tuple([value] * len(getattr(obj, f.name)))
    try:
        new = dataclasses.replace(obj, **{f.name: value})
        if path is None:
            return "ok", ""
        sc = _put(base, path, new)
        res = simulate(sc)
    except (ConfigError, ValueError) as exc:  # ConfigError is a ValueError; a bare ValueError is the library's own
        msg = str(exc)
        return ("refused", msg) if "\n" not in msg else ("internal", msg)
    except Exception as exc:  # anything else is a bug
        return "internal", f"{type(exc).__name__}: {exc}"
    state = res.columns_like(STATE_COLUMNS)  # by name: the log row's layout is the run's
    if res.diverged:
        return "diverged", res.divergence_reason
    if not np.isfinite(state).all():
        return "silent_nan", f"{f.name} = {value!r}"
    return "ok", ""


def _put(root, path, new):
    if not path:
        return new
    head, rest = path[0], path[1:]
    if isinstance(head, int):
        items = list(root)
        items[head] = _put(root[head], rest, new)
        return tuple(items)
    return dataclasses.replace(root, **{head: _put(getattr(root, head), rest, new)})


def _action(spec: str, shape, rng) -> object:
    import numpy as np

    return {"zeros": lambda: np.zeros(shape), "ones": lambda: np.ones(shape),
            "random": lambda: np.asarray([rng.uniform(-2, 2) for _ in range(int(np.prod(shape)))]).reshape(shape),
            "nan": lambda: np.full(shape, np.nan), "inf": lambda: np.full(shape, np.inf),
            "complex": lambda: np.full(shape, 0.1 + 0.5j), "huge": lambda: np.full(shape, 1e300),
            "short": lambda: np.zeros(3), "long": lambda: np.zeros(9), "str": lambda: "fly",
            "bool": lambda: np.ones(shape, dtype=bool), "list": lambda: np.zeros(shape).tolist()}[spec]()


def run_gym_case(case: dict, envs: dict) -> tuple[str, str]:
    import numpy as np

    from vtoladapt.config import ConfigError

    rng = random.Random(json.dumps(case, sort_keys=True))
    env = envs[(case["env"], case["residual"])]
    vector = case["env"] == "vector"
    seed = {"1.5": 1.5, "-1": -1, "true": True, "list": [1, 2] if vector else [1], "str": "7",
            "none": None}.get(case["seed"], case["seed"])
    refused = []
    try:
        env.reset(seed=seed)
    except (ConfigError, ValueError) as exc:
        refused.append(str(exc))
        env.reset(seed=0)
    except Exception as exc:
        return "internal", f"reset(seed={seed!r}): {type(exc).__name__}: {exc}"
    shape = (2, 5) if vector else (5,)
    for spec in case["steps"]:
        a = _action(spec, shape, rng)
        try:
            obs, reward, term, trunc, _ = env.step(a)
        except (ValueError, ConfigError) as exc:
            if "\n" in str(exc):
                return "internal", str(exc)
            refused.append(str(exc))
            continue
        except Exception as exc:
            return "internal", f"step({spec}): {type(exc).__name__}: {exc}"
        if not (np.isfinite(obs).all() and np.isfinite(reward).all()):
            return "silent_nan", f"step({spec}) gave a non-finite observation or reward"
        if not vector and (term or trunc):
            env.reset(seed=1)
    return ("refused", refused[0]) if refused else ("ok", "")


def worker(case_file: Path, start: int, fd: int, work: Path, baseline: Path) -> None:
    """Run the cases from ``start`` on, reporting ``START i`` and ``RESULT i {json}`` lines on ``fd``."""
    from vtoladapt.errors import sigint_handling

    report = os.fdopen(fd, "w", buffering=1)
    cases = json.loads(case_file.read_text())
    from vtoladapt.sim.scenario import load_scenario

    base = load_scenario(SCENARIOS / "gym_hold.toml").replace(duration_s=0.3)
    envs = {}
    for i in range(start, len(cases)):
        case = cases[i]
        report.write(f"START {i}\n")
        t0 = time.monotonic()
        try:
            with sigint_handling():
                if case["kind"] == "cli":
                    outcome, detail = run_cli_case(case, work, baseline)
                elif case["kind"] == "api":
                    outcome, detail = run_api_case(case, base)
                elif case["kind"] == "file":
                    outcome, detail = run_file_case(case, work, baseline)
                else:
                    if not envs:
                        from vtoladapt.gym.env import HoldEnv
                        from vtoladapt.gym.vector import HoldVectorEnv

                        for residual in (False, True):
                            envs[("single", residual)] = HoldEnv(scenario=base, residual=residual)
                            envs[("vector", residual)] = HoldVectorEnv(num_envs=2, workers=1, scenario=base,
                                                                       residual=residual)
                    outcome, detail = run_gym_case(case, envs)
        except BaseException as exc:  # the harness itself must not stop
            outcome, detail = "internal", f"{type(exc).__name__}: {exc}"
        report.write("RESULT " + json.dumps({"i": i, "outcome": outcome, "detail": detail[:500],
                                             "s": round(time.monotonic() - t0, 2)}) + "\n")


# --- signals, run from the parent ----------------------------------------------------------------------
def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def signal_case(rng: random.Random, work: Path, what: str, sig: int, timeout: float) -> tuple[str, str, float]:
    """A real command interrupted by ``sig`` to its process group at a random moment."""
    from vtoladapt.outputs import MANIFEST_NAME

    d = work / f"sig_{rng.randrange(10**9)}"
    d.mkdir()
    (d / "s.toml").write_text(BASE_TEXT.replace("duration_s = 0.3", "duration_s = 900.0"))
    (d / "short.toml").write_text(BASE_TEXT.replace("duration_s = 0.3", "duration_s = 1.0"))
    if what == "run":
        argv = ["run", str(d / "s.toml"), "--out", str(d / "out"), "--quiet"]
        delay = rng.uniform(0.1, 12.0)
    else:
        argv = ["campaign", str(d / "short.toml"), "--runs", "400", "--workers", "2", "--out", str(d / "out"),
                "--quiet"]
        delay = rng.uniform(0.1, 8.0)
    proc = subprocess.Popen([sys.executable, "-m", "vtoladapt.cli", *argv], stderr=subprocess.PIPE,
                            stdout=subprocess.DEVNULL, text=True, start_new_session=True)
    if what == "campaign" and rng.random() < 0.6:  # aim at the cluster's start-up and the first runs
        import psutil

        deadline = time.monotonic() + timeout
        while proc.poll() is None and time.monotonic() < deadline:
            try:
                children = psutil.Process(proc.pid).children(recursive=True)
                if any("spawn_main" in " ".join(c.cmdline()) for c in children):
                    break
            except psutil.Error:
                pass
            time.sleep(0.02)
        delay = rng.uniform(0.0, 4.0)
    time.sleep(delay)
    t0 = time.monotonic()
    if proc.poll() is None:
        os.killpg(proc.pid, sig)
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        return "hang", f"{what} did not end within {timeout:g} s of {signal.Signals(sig).name}", timeout
    latency = time.monotonic() - t0
    deadline = time.monotonic() + 20
    while _group_alive(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    if _group_alive(proc.pid):
        os.killpg(proc.pid, signal.SIGKILL)
        return "damaged", f"a process of {what}'s group outlived it", latency
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if ln.strip()]
    expected = {signal.SIGINT: 130, signal.SIGTERM: 143}[sig]
    if proc.returncode == 0:
        return "ok", f"{what} ended before the signal ({delay:.1f} s)", latency
    if proc.returncode != expected or len(lines) != 1 or "Traceback" in err:
        return "internal", f"{what}: rc {proc.returncode} after {delay:.1f} s: {err[-400:]}", latency
    wrong = _outputs_sound(d / "out")
    if wrong:
        return "damaged", wrong, latency
    status = json.loads((d / "out" / MANIFEST_NAME).read_text())["status"] if (d / "out" / MANIFEST_NAME).exists() \
        else None
    if status not in (None, "interrupted", "terminated"):
        return "damaged", f"manifest left at {status!r}", latency
    return "refused", f"{what} stopped in {latency:.2f} s", latency


def two_runs_case(work: Path, timeout: float) -> tuple[str, str]:
    """Two runs started together into one folder: one runs, the other is refused (or they run in turn)."""
    from vtoladapt.outputs import read_manifest

    d = work / "two"
    d.mkdir()
    (d / "a.toml").write_text(BASE_TEXT)
    (d / "b.toml").write_text(BASE_TEXT.replace('name = "gym_hold"', 'name = "other"'))
    procs = [subprocess.Popen([sys.executable, "-m", "vtoladapt.cli", "run", str(d / f"{n}.toml"), "--out",
                               str(d / "out"), "--quiet"], stderr=subprocess.PIPE, text=True) for n in "ab"]
    codes = [p.wait(timeout=timeout) for p in procs]
    files = sorted(p.relative_to(d / "out").as_posix() for p in (d / "out").rglob("*") if p.is_file())
    listed = sorted(read_manifest(d / "out")["files"]) + [".vtoladapt-manifest.json"]
    if sorted(codes) not in ([0, 0], [0, 2]) or sorted(listed) != files:
        return "damaged", f"codes {codes}, files {files}, manifest {listed}"
    return "ok" if codes == [0, 0] else "refused", f"codes {codes}"


# --- the parent ----------------------------------------------------------------------------------------
def run_cases(cases: list[dict], work: Path, baseline: Path, timeout: float) -> list[dict]:
    """Every case in a worker process; a worker that crashes or stalls costs its case, then restarts."""
    case_file = work / "cases.json"
    case_file.write_text(json.dumps(cases))
    results: list[dict] = []
    start = 0
    while start < len(cases):
        r, w = os.pipe()
        proc = subprocess.Popen([sys.executable, __file__, "--worker", str(case_file), str(start), str(w), str(work),
                                 str(baseline)], pass_fds=(w,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True)
        os.close(w)
        lines: queue.Queue = queue.Queue()
        threading.Thread(target=lambda: [lines.put(ln) for ln in os.fdopen(r)] + [lines.put(None)],
                         daemon=True).start()
        current = start
        while True:
            try:
                line = lines.get(timeout=timeout)
            except queue.Empty:
                os.killpg(proc.pid, signal.SIGKILL)
                results.append({"i": current, "outcome": "hang", "detail": f"no result within {timeout:g} s"})
                break
            if line is None:  # the worker ended: done, or crashed in case ``current``
                code = proc.wait()
                if current < len(cases) and (not results or results[-1]["i"] != current):
                    results.append({"i": current, "outcome": "internal", "detail": f"the worker died (status {code})"})
                break
            if line.startswith("START "):
                current = int(line.split()[1])
            elif line.startswith("RESULT "):
                results.append(json.loads(line[7:]))
                if sys.stderr.isatty():
                    print(f"\r{len(results)}/{len(cases)} cases", end="", file=sys.stderr, flush=True)
        proc.wait()
        start = results[-1]["i"] + 1 if results else start + 1
    if sys.stderr.isatty():
        print(file=sys.stderr)
    return results


def table(rows: dict[str, dict]) -> str:
    lines = ["| group | " + " | ".join(HEADERS) + " |", "|---" * (len(HEADERS) + 1) + "|"]
    total = {o: 0 for o in OUTCOMES}
    for group, counts in rows.items():
        n = sum(counts.values())
        lines.append(f"| {group} | {n} | " + " | ".join(str(counts.get(o, 0)) for o in OUTCOMES) + " |")
        for o in OUTCOMES:
            total[o] += counts.get(o, 0)
    lines.append(f"| **all** | {sum(total.values())} | " + " | ".join(str(total[o]) for o in OUTCOMES) + " |")
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0, help="seed of every draw of the pass (default 0)")
    ap.add_argument("--scale", type=float, default=1.0, help="multiply the number of drawn cases (default 1)")
    ap.add_argument("--timeout", type=float, default=180.0, help="seconds a case may take before it is a hang")
    ap.add_argument("--keep", action="store_true", help="keep the working folder (printed)")
    ap.add_argument("--only", choices=("all", "files"), default="all",
                    help="'files': only the file classes (network files, logs, learn-basis arguments)")
    ap.add_argument("--worker", nargs=5, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        case_file, start, fd, work, baseline = args.worker
        worker(Path(case_file), int(start), int(fd), Path(work), Path(baseline))
        return 0
    t0 = time.monotonic()
    rng = random.Random(args.seed)
    work = Path(tempfile.mkdtemp(prefix="vtoladapt-hostile-"))
    try:
        (work / "s.toml").write_text(BASE_TEXT)
        baseline = work / "baseline"
        subprocess.run([sys.executable, "-m", "vtoladapt.cli", "run", str(work / "s.toml"), "--out", str(baseline),
                        "--quiet"], check=True)
        k = args.scale
        prepare_assets(work, sys.executable)
        cases = [] if args.only == "files" else (handmade_cases() + fuzz_cases(rng, int(90 * k), int(45 * k))
                                                 + api_cases(rng, int(250 * k)) + gym_cases(rng, int(120 * k)))
        cases += file_cases(random.Random(f"{args.seed}-files"), k)  # its own stream: the others' draws stay
        results = run_cases(cases, work, baseline, args.timeout)
        rows: dict[str, dict] = {}
        bad = []
        for r in results:
            group = cases[r["i"]]["group"]
            rows.setdefault(group, {})
            rows[group][r["outcome"]] = rows[group].get(r["outcome"], 0) + 1
            if r["outcome"] in ("internal", "hang", "silent_nan", "damaged"):
                bad.append(f"  [{r['outcome']}] {group} case {r['i']}: {r['detail']}")
        latencies = []
        sig_rows: dict[str, int] = {}
        for what, sig in [("run", signal.SIGINT), ("run", signal.SIGTERM), ("campaign", signal.SIGINT)] * \
                (max(1, int(round(3 * k))) if args.only == "all" else 0):
            outcome, detail, latency = signal_case(rng, work, what, sig, args.timeout)
            sig_rows[outcome] = sig_rows.get(outcome, 0) + 1
            if outcome == "refused":
                latencies.append((what, signal.Signals(sig).name, latency))
            if outcome in ("internal", "hang", "silent_nan", "damaged"):
                bad.append(f"  [{outcome}] signals: {detail}")
        if args.only == "all":
            outcome, detail = two_runs_case(work, args.timeout)
            sig_rows[outcome] = sig_rows.get(outcome, 0) + 1
            if outcome not in ("ok", "refused"):
                bad.append(f"  [{outcome}] two runs into one folder: {detail}")
            rows["signals (Ctrl-C, SIGTERM, two runs)"] = sig_rows
        print(table(rows))
        print("\n(signals: a clean refusal is a command that stopped with its one line and status 130/143)")
        for what in ("run", "campaign"):
            ls = [lat for w, _, lat in latencies if w == what]
            if ls:
                print(f"{what}: stopped {max(ls):.2f} s at most after the signal (median "
                      f"{sorted(ls)[len(ls) // 2]:.2f} s, "
                      f"{len(ls)} signals)")
        print(f"seed {args.seed}, scale {args.scale:g}, {time.monotonic() - t0:.0f} s")
        if bad:
            print("\nFindings:\n" + "\n".join(bad))
        return 1 if bad else 0
    finally:
        if args.keep:
            print(f"working folder kept: {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
