"""The hostile pass's file classes (issue #33): tampered learned-basis files, tampered flight logs and
``learn-basis`` argument abuse. Imported by ``tools/hostile_pass.py`` (its worker runs the cases).

Every case builds its files in a fresh folder from a recipe (the recipes are JSON, so the pass's case list
stays a file), runs one command in the worker process and is judged as the pass judges every case, with
more: on a refusal (exit 2) *nothing* in the case's folder may have changed (inputs' bytes and times, no new
file), its one line must name the file at fault, and a file that must be refused must not be accepted (a
missed check counts as an internal error). On success no input may have changed, no temporary file may be
left, and a written basis file must read back finite.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import random
import shutil
import zipfile
from pathlib import Path

ARRAYS = ("x_mean", "x_std", "W1", "b1", "W2", "b2", "W3", "b3", "theta_mean", "theta_std")
NET = "tampered network files"
LOGS = "log files"
ARGS = "learn-basis arguments"
TRAIN = ["--h", "1", "--hidden", "2", "--iterations", "2", "--stride", "2"]
BOMB_BYTES = 64 << 20
"""A highly compressible member's declared size (zeros deflate about 1000:1: 64 kB on disk)."""
ULOG_SAMPLE = Path(__file__).resolve().parents[1] / "data" / "pyulog-testdata" / "sample_log_small.ulg"


# --- the cases -----------------------------------------------------------------------------------------
def _case(group, build, argv, expect="refuse", names=None, prepare="none"):
    return {"kind": "file", "group": group, "build": build, "argv": argv, "expect": expect, "names": names,
            "prepare": prepare}


def _bases(mut, expect="refuse"):
    return _case(NET, {"net": mut}, ["bases", "--vehicle", "{dir}/v.toml"], expect, "net.npz")


def net_cases(rng: random.Random, k: float) -> list[dict]:
    cases = []
    dtypes = ["complex128", "complex64", "bool", "int64", "int8", "uint8", "float16", "U3", "S3", "object",
              "datetime64[s]", "V8", "structured"]
    for member in ARRAYS:
        for dt in dtypes:
            cases.append(_bases(["dtype", member, dt]))
        for dt in (">f8", "float32"):
            cases.append(_bases(["dtype", member, dt], expect="any"))   # float32 may round an edge value
        for kind in ("transpose", "extra_dim", "empty", "scalar", "plus1", "minus1"):
            cases.append(_bases(["shape", member, kind]))
        for what in ("nan", "inf", "-inf", "huge", "over", "zero_std", "tiny_std"):
            if what.endswith("_std") and not member.endswith("std"):
                continue
            cases.append(_bases(["value", member, what],
                                expect="any" if (member, what) == ("theta_std", "tiny_std") else "refuse"))
        cases.append(_bases(["value", member, "edge"], expect="accept"))
        cases.append(_bases(["archive", "missing", member]))
        cases.append(_bases(["archive", "bomb", member]))
        cases.append(_bases(["archive", "duplicate", member]))
    for key, value in [("features", 5), ("features", None), ("features", []), ("features", "v_i_x_mps"),
                       ("features", {"a": 1}), ("format", None), ("format", 1), ("format", "other"),
                       ("vehicle", 5), ("vehicle", None), ("vehicle", ["caltech_vtol"]),
                       ("vehicle", "../../../../etc/passwd"), ("vehicle", ""), ("physics", 5), ("physics", "paper"),
                       ("draws", {"a": 1}), ("draws", 5), ("draws", "x"), ("seed", "x"), ("seed", 1.5),
                       ("seed", True), ("settings", [1]), ("summary", "x"), ("command", 7),
                       ("summary", "deep33"), ("draws", "deep100000")]:
        cases.append(_bases(["meta", key, value]))
    for text in ["[1, 2]", "7", '"text"', "null", "{", "", "NaN", "{" * 50000, "[" * 100000 + "]" * 100000,
                 '{"format": "vtoladapt-learned-basis-1"}']:
        cases.append(_bases(["meta_text", text]))
    for kind in ("bytes", "2d", "float", "pickled"):
        cases.append(_bases(["meta_array", kind]))
    for kind in ("npy_as_npz", "npy_float_as_npz", "empty", "text", "random", "no_members", "extra_small",
                 "extra_bomb", "meta_bomb", "header_v3", "header_long", "header_garbage", "data_short", "bad_crc",
                 "zip_in_zip"):
        cases.append(_bases(["archive", kind]))
    for kind in ("bzip2", "lzma", "deflate", "fortran"):
        cases.append(_bases(["archive", kind], expect="accept"))
    for cut in sorted({rng.randrange(1, 4000) for _ in range(int(12 * k))}) + [-1, -22, -100]:
        cases.append(_bases(["archive", "truncated", cut]))
    for h, H1, H2, expect in [(30, 256, 256, "accept"), (31, 8, 8, "refuse"), (2, 257, 8, "refuse"),
                              (2, 8, 257, "refuse"), (2, 12000, 4, "refuse"), (1, 1, 1, "accept"), (2, 0, 4, "refuse")]:
        cases.append(_bases(["widths", h, H1, H2], expect=expect))
    # flown: the values at their bounds must run (ok or diverged), never divide by zero or go NaN silently
    for what in ("edge", "edge_neg", "plain"):
        cases.append(_case(NET, {"net": ["flown", what]}, ["run", "{dir}/s.toml", "--out", "{out}", "--quiet"],
                           "any", "net.npz"))
    for mut in (["value", "theta_mean", "huge"], ["archive", "npy_as_npz"], ["meta", "features", None]):
        cases.append(_case(NET, {"net": mut}, ["run", "{dir}/s.toml", "--out", "{out}", "--quiet"], "refuse",
                           "net.npz", prepare="earlier"))
    return cases


def _learn(build, extra=(), logs=("{dir}/bad.parquet",), expect="refuse", names="bad.", out="{dir}/n.npz"):
    return _case(LOGS, build, ["learn-basis", *logs, "--out", out, *TRAIN, *extra], expect, names)


def log_cases(rng: random.Random, k: float) -> list[dict]:
    cases = []
    for rows in (0, 1, 3):
        cases.append(_learn({"log": ["rows", rows]}))
        # a short flight beside a good one is left out (the summary says so), an empty one refused
        cases.append(_learn({"log": ["rows", rows], "good": True}, logs=("{dir}/good.parquet", "{dir}/bad.parquet"),
                            expect="refuse" if rows == 0 else "accept", names="bad." if rows == 0 else None))
    for key, value in [("draw", [1, 2]), ("draw", "x"), ("draw", 5), ("vehicle", 5), ("vehicle", ["caltech_vtol"]),
                       ("vehicle", None), ("vehicle", ""), ("vehicle", "../../../../etc/passwd"),
                       ("vehicle", "/etc/passwd"), ("vehicle", "caltech_vtol/../caltech_vtol"),
                       ("vehicle", "{dir}/v.toml"), ("vehicle", "~/.bashrc"), ("vehicle", "no_such_vehicle"),
                       ("vehicle", "a" * 5000), ("seed", "x"), ("seed", 1.5), ("seed", [1])]:
        cases.append(_learn({"log": ["meta", key, value]}))
    for text in ["[1, 2]", "7", '"x"', "null", "{", "", "[" * 100000 + "]" * 100000]:
        cases.append(_learn({"log": ["meta_text", text]}))
    for col in ("meas_accel_x_mps2", "ctrl_v_i_x_mps", "t_s", "meas_q_w", "cmd_u_x_frac", "probe_valid_used"):
        cases.append(_learn({"log": ["drop", col]}))
        cases.append(_learn({"log": ["nan", col]}, expect="any"))
        cases.append(_learn({"log": ["inf", col]}, expect="any"))
    cases.append(_learn({"log": ["string_column"]}))
    for kind in ("empty", "text", "random", "plain_parquet", "truncated", "csv"):
        cases.append(_learn({"log": ["bytes", kind]}))
    ulg = ["empty", "text", "magic_garbage", "magic_only"] + [f"cut{c}" for c in (16, 100, 1000, 5000, 20000)]
    for kind in ulg:
        cases.append(_learn({"ulg": kind}, extra=("--vehicle", "caltech_vtol"), logs=("{dir}/bad.ulg",)))
    cases.append(_learn({"ulg": "sample"}, extra=("--vehicle", "caltech_vtol"), logs=("{dir}/bad.ulg",), expect="any"))
    cases.append(_learn({"ulg": "text"}, logs=("{dir}/bad.ulg",)))  # a PX4 log without --vehicle
    # good logs train (the written file is read back)
    cases.append(_learn({"good": True}, logs=("{dir}/good.parquet",), expect="accept", names=None))
    cases.append(_learn({"good": True, "log": ["copy"]}, logs=("{dir}/good.parquet", "{dir}/bad.parquet"),
                        expect="accept", names=None))
    return cases


def _args(argv, expect="refuse", build=None):
    return _case(ARGS, build or {"args": True}, ["learn-basis", *argv], expect, None)


def argument_cases(rng: random.Random, k: float) -> list[dict]:
    a, b, logs = "{dir}/logs/a.parquet", "{dir}/logs/b.parquet", "{dir}/logs"
    cases = []
    for force in ([], ["--force"]):
        for out in (a, b, "{dir}/logs/../logs/a.parquet", "{dir}/link.parquet", "{dir}/hard.parquet", logs, "{dir}",
                    "{dir}/DIR", "{dir}/missing/n.npz", "{dir}/v.toml", "{dir}/logs/a.parquet/x.npz", "{dir}/fifo"):
            for inputs in ([a, b], [logs]):
                extra = ["--vehicle", "{dir}/v.toml"] if out == "{dir}/v.toml" else []
                cases.append(_args([*inputs, "--out", out, *force, *extra, *TRAIN]))
        for inputs in ([a, a], [a, a, a], [logs, a], [a, "{dir}/link.parquet"], [a, "{dir}/hard.parquet"],
                       [logs, logs], [a, "{dir}/logs/../logs/a.parquet"]):
            cases.append(_args([*inputs, "--out", "{dir}/n.npz", *force, *TRAIN]))
        cases.append(_args([a, b, "--out", "{dir}/keep.npz", *force, *TRAIN], expect="accept" if force else "refuse"))
    for flag, value in [("--h", "0"), ("--h", "31"), ("--h", "-1"), ("--hidden", "1"), ("--hidden", "257"),
                        ("--iterations", "0"), ("--stride", "0"), ("--adversarial", "nan"), ("--adversarial", "inf"),
                        ("--adversarial", "-1"), ("--adversarial-rounds", "0"), ("--workers", "0"),
                        ("--runs", "0"), ("--h", "100000000000000000000")]:
        cases.append(_args([a, "--out", "{dir}/n.npz", flag, value]))
    for argv in ([], ["{dir}/nothing"], ["{dir}/empty_dir"], ["{dir}/v.toml"], [a, "--fly", "{dir}/v.toml"],
                 ["--fly", "{dir}/missing.toml"], [a, "--vehicle", "no_such_vehicle"],
                 [a, "--vehicle", "../../../../etc/passwd"], [a, "--vehicle", "{dir}/logs"],
                 ["{dir}/logs/../../../../../../etc"]):
        cases.append(_args([*argv, "--out", "{dir}/n.npz", *TRAIN]))
    cases.append(_args([a, "--logs-dir", "{dir}/n.npz", "--out", "{dir}/n.npz", *TRAIN], expect="any"))
    cases.append(_args([a, b, "--out", "{dir}/n.npz", *TRAIN], expect="accept"))
    cases.append(_args([logs, "--out", "{dir}/logs/n.npz", *TRAIN], expect="accept"))
    return cases


def file_cases(rng: random.Random, k: float) -> list[dict]:
    return net_cases(rng, k) + log_cases(rng, k) + argument_cases(rng, k)


# --- building the files ----------------------------------------------------------------------------------
def _net_arrays(seed=1, h=3, H1=7, H2=5, scale=0.5):
    import numpy as np

    rng = np.random.default_rng(seed)
    F = 16
    return {"x_mean": rng.normal(size=F), "x_std": rng.uniform(0.5, 2.0, F), "W1": scale * rng.normal(size=(H1, F)),
            "b1": scale * rng.normal(size=H1), "W2": scale * rng.normal(size=(H2, H1)), "b2": scale * rng.normal(size=H2),
            "W3": scale * rng.normal(size=(3 * h, H2)), "b3": scale * rng.normal(size=3 * h),
            "theta_mean": rng.normal(size=h), "theta_std": rng.uniform(0.1, 1.0, h)}


def _meta() -> dict:
    from vtoladapt.bases.netfile import FEATURES, FORMAT

    return {"format": FORMAT, "features": list(FEATURES), "vehicle": "caltech_vtol", "physics": "extended",
            "draws": [], "seed": 0}


def _write_members(path: Path, members: dict, compression=zipfile.ZIP_STORED) -> None:
    """An .npz by hand: each value an array (written as npy) or raw bytes; duplicates allowed as (name, n)."""
    import warnings

    import numpy as np

    with zipfile.ZipFile(path, "w", compression=compression) as zf, warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "Duplicate name": the duplicate is the point
        for name, value in members.items():
            name = name[0] if isinstance(name, tuple) else name
            with zf.open(name, "w", force_zip64=True) as fh:
                if isinstance(value, (bytes, bytearray)):
                    fh.write(value)
                elif isinstance(value, tuple) and value[0] == "bomb":  # (bomb, header or None, bytes)
                    if value[1] is not None:
                        np.lib.format.write_array_header_1_0(fh, value[1])
                    chunk = bytes(1 << 22)
                    for _ in range(value[2] // len(chunk)):
                        fh.write(chunk)
                else:
                    np.lib.format.write_array(fh, value, allow_pickle=True)


def _odd_dtype(a, dt: str):
    import numpy as np

    if dt == "object":
        return a.astype(object)
    if dt == "structured":
        return np.zeros(a.shape, dtype=[("x", "<f8")])
    if dt in ("U3", "S3"):
        return np.full(a.shape, "abc", dtype=dt)
    if dt == "V8":
        return a.astype("<f8").view("V8")
    if dt.startswith("complex"):
        return (a + 1j).astype(dt)
    if dt.startswith("datetime"):
        return np.zeros(a.shape, dtype=dt)
    return a.astype(dt)


def build_net(d: Path, mut: list) -> None:
    import numpy as np

    from vtoladapt.bases import netfile
    from vtoladapt.vehicle import VEHICLE_DIR

    arrays = _net_arrays()
    meta = _meta()
    meta_value = None          # the meta member as an array, if not the JSON of ``meta``
    extra: dict = {}
    compression = zipfile.ZIP_STORED
    path = d / "net.npz"
    raw = None
    kind = mut[0]
    if kind == "dtype":
        arrays[mut[1]] = _odd_dtype(arrays[mut[1]], mut[2])
    elif kind == "shape":
        a = arrays[mut[1]]
        arrays[mut[1]] = {"transpose": lambda: a.T if a.ndim == 2 else a[:, None], "extra_dim": lambda: a[None],
                          "empty": lambda: np.zeros((0,) + a.shape[1:]), "scalar": lambda: np.float64(1.0),
                          "plus1": lambda: np.concatenate([a, a[:1]]), "minus1": lambda: a[:-1]}[mut[2]]()
    elif kind == "value":
        lo, hi = netfile.BOUNDS[mut[1]]
        a = arrays[mut[1]].copy()
        a.flat[0] = {"nan": np.nan, "inf": np.inf, "-inf": -np.inf, "huge": 1e300, "over": 1.5 * hi + 1.0,
                     "zero_std": 0.0, "tiny_std": 1e-300, "edge": hi}[mut[2]]
        arrays[mut[1]] = a
    elif kind == "widths":
        h, H1, H2 = mut[1:]
        arrays = _net_arrays(h=h, H1=max(H1, 0), H2=H2, scale=0.05)
    elif kind == "flown":
        if mut[1] in ("edge", "edge_neg"):
            sign = 1.0 if mut[1] == "edge" else -1.0
            for name in ARRAYS:
                lo, hi = netfile.BOUNDS[name]
                a = arrays[name]
                arrays[name] = np.full(a.shape, hi if name.endswith("std") else sign * hi)
    elif kind == "meta":
        key, value = mut[1], mut[2]
        if isinstance(value, str) and value.startswith("deep"):
            n = int(value[4:])
            value = json.loads("[" * n + "]" * n) if n < 500 else None
            if value is None:
                meta_value = np.array(json.dumps(meta)[:-1] + f', "{key}": ' + "[" * n + "]" * n + "}")
        if meta_value is None:
            meta[key] = value
    elif kind == "meta_text":
        meta_value = np.array(mut[1])
    elif kind == "meta_array":
        meta_value = {"bytes": np.array(json.dumps(meta).encode()), "2d": np.array([[json.dumps(meta)]]),
                      "float": np.zeros(3), "pickled": np.array([meta], dtype=object)}[mut[1]]
    elif kind == "archive":
        what = mut[1]
        if what in ("npy_as_npz", "npy_float_as_npz"):
            buf = io.BytesIO()
            np.save(buf, arrays["W1"] if what == "npy_float_as_npz" else np.array(json.dumps(meta)))
            raw = buf.getvalue()
        elif what == "empty":
            raw = b""
        elif what == "no_members":
            with zipfile.ZipFile(path, "w"):
                pass
            raw = path.read_bytes()
        elif what == "text":
            raw = b"W1 = [[1, 2], [3, 4]]\n"
        elif what == "random":
            raw = random.Random(7).randbytes(5000)
        elif what == "missing":
            del arrays[mut[2]]
        elif what == "bomb":
            a = arrays[mut[2]]
            arrays[mut[2]] = ("bomb", {"descr": "<f8", "fortran_order": False, "shape": a.shape}, BOMB_BYTES)
            compression = zipfile.ZIP_DEFLATED
        elif what == "duplicate":
            extra[(mut[2] + ".npy", 2)] = np.zeros_like(arrays[mut[2]])
        elif what == "extra_small":
            extra["notes.npy"] = np.zeros(3)
        elif what == "extra_bomb":
            extra["padding.npy"] = ("bomb", None, BOMB_BYTES)
            compression = zipfile.ZIP_DEFLATED
        elif what == "meta_bomb":
            meta_value = ("bomb", {"descr": "<U1000", "fortran_order": False, "shape": ()}, BOMB_BYTES)
            compression = zipfile.ZIP_DEFLATED
        elif what in ("header_v3", "header_long", "header_garbage", "data_short", "bad_crc"):
            buf = io.BytesIO()
            np.lib.format.write_array(buf, arrays["W2"])
            blob = buf.getvalue()
            blob = {"header_v3": b"\x93NUMPY\x03\x00" + blob[8:], "header_long": b"\x93NUMPY\x02\x00"
                    + (200000).to_bytes(4, "little") + b" " * 200000,
                    "header_garbage": blob[:10] + b"{'descr': os.system('x')" + blob[34:],
                    "data_short": blob[:-16], "bad_crc": blob}[what]
            arrays["W2"] = blob
        elif what == "zip_in_zip":
            inner = d / "inner.npz"
            netfile.write_net(inner, netfile.NetFile(**_net_arrays(), meta=_meta()))
            arrays["W1"] = inner.read_bytes()
            inner.unlink()
        elif what in ("bzip2", "lzma", "deflate"):
            compression = {"bzip2": zipfile.ZIP_BZIP2, "lzma": zipfile.ZIP_LZMA, "deflate": zipfile.ZIP_DEFLATED}[what]
        elif what == "fortran":
            arrays["W1"] = np.asfortranarray(arrays["W1"])
        elif what == "truncated":
            full = d / "full.npz"
            netfile.write_net(full, netfile.NetFile(**_net_arrays(), meta=_meta()))
            raw = full.read_bytes()[:mut[2]]
            full.unlink()
    if raw is not None:
        path.write_bytes(raw)
    else:
        members = {**{f"{k}.npy": v for k, v in arrays.items()},
                   "meta.npy": meta_value if meta_value is not None else np.array(json.dumps(meta)), **extra}
        _write_members(path, members, compression)
        if mut[:2] == ["archive", "bad_crc"]:  # one byte of W2's data changed after the CRC was written
            blob = bytearray(path.read_bytes())
            at = blob.find(b"\x93NUMPY", blob.find(b"W2.npy")) + 140
            blob[at] ^= 0xFF
            path.write_bytes(bytes(blob))
    (d / "v.toml").write_text((VEHICLE_DIR / "caltech_vtol.toml").read_text()
                              + '\n[basis_settings.learned]\nfile = "net.npz"\n')
    (d / "s.toml").write_text(f'name = "s"\nvehicle = "{d / "v.toml"}"\nduration_s = 0.3\n'
                              '[controller]\nkind = "composite"\nbasis = "learned"\n')


def _write_log(src: Path, dest: Path, mut: list, d: Path) -> None:
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    from vtoladapt.sim.results import PARQUET_FORMAT_VERSION, log_file_metadata

    table = pq.read_table(src)
    meta = log_file_metadata(src)  # in the schema or, for a streamed log, the footer
    schema_meta = {b"vtoladapt_format": str(PARQUET_FORMAT_VERSION).encode()}
    kind = mut[0]
    if kind == "copy":
        shutil.copy2(src, dest)
        return
    if kind == "bytes":
        what = mut[1]
        if what == "truncated":
            dest.write_bytes(src.read_bytes()[:len(src.read_bytes()) // 2])
        elif what == "plain_parquet":
            pq.write_table(pa.table({"t": np.arange(5.0)}), dest)
        else:
            dest.write_bytes({"empty": b"", "text": b"time_s,x\n0,1\n", "random": random.Random(3).randbytes(4000),
                              "csv": b"a,b\n1,2\n"}[what])
        return
    if kind == "rows":
        table = table.slice(0, mut[1])
    elif kind == "meta":
        value = mut[2].replace("{dir}", str(d)) if isinstance(mut[2], str) else mut[2]
        meta[mut[1]] = value
    elif kind == "drop":
        table = table.drop([mut[1]])
    elif kind in ("nan", "inf"):
        i = table.column_names.index(mut[1])
        table = table.set_column(i, mut[1], pa.array(np.full(table.num_rows, np.nan if kind == "nan" else np.inf)))
    elif kind == "string_column":
        table = table.append_column("note", pa.array(["x"] * table.num_rows))
    text = mut[1] if kind == "meta_text" else json.dumps(meta)
    schema_meta[b"vtoladapt_metadata"] = text.encode()
    pq.write_table(table.replace_schema_metadata(schema_meta), dest)


def build_files(d: Path, build: dict, assets: Path) -> None:
    """The case's files in ``d`` from its recipe (``assets``: the pass's base flight log)."""
    from vtoladapt.vehicle import VEHICLE_DIR

    base = assets / "flight.parquet"
    (d / "v.toml").write_text((VEHICLE_DIR / "caltech_vtol.toml").read_text())
    if "net" in build:
        build_net(d, build["net"])
    if build.get("good"):
        shutil.copy2(base, d / "good.parquet")
    if "log" in build:
        _write_log(base, d / "bad.parquet", build["log"], d)
    if "ulg" in build:
        what = build["ulg"]
        sample = ULOG_SAMPLE.read_bytes()
        data = {"empty": b"", "text": b"not a ulog\n", "magic_garbage": sample[:16] + b"\x01garbage" * 100,
                "magic_only": sample[:7], "sample": sample}.get(what)
        if data is None:
            data = sample[:int(what[3:])]
        (d / "bad.ulg").write_bytes(data)
    if build.get("args"):
        (d / "logs").mkdir()
        shutil.copy2(base, d / "logs" / "a.parquet")
        shutil.copy2(base, d / "logs" / "b.parquet")
        os.symlink(d / "logs" / "a.parquet", d / "link.parquet")
        os.link(d / "logs" / "a.parquet", d / "hard.parquet")
        (d / "DIR").mkdir()
        (d / "DIR" / "mine.txt").write_text("the user's")
        (d / "empty_dir").mkdir()
        (d / "keep.npz").write_bytes(b"the user's own file")
        os.mkfifo(d / "fifo")


# --- judging ---------------------------------------------------------------------------------------------
def _state(root: Path) -> dict:
    """Every entry below ``root``: files by content and time, links by target, folders by name."""
    import hashlib

    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_symlink():
            out[str(p)] = "link:" + os.readlink(p)
        elif p.is_file():
            st = p.stat()
            out[str(p)] = (hashlib.sha256(p.read_bytes()).hexdigest(), st.st_mtime_ns)
        else:
            out[str(p)] = "dir"
    return out


def run_file_case(case: dict, work: Path, baseline: Path) -> tuple[str, str]:
    import math

    import numpy as np

    from vtoladapt.cli import main

    d = work / "case"
    shutil.rmtree(d, ignore_errors=True)
    d.mkdir()
    build_files(d, case["build"], work / "assets")
    out = d / "out"
    if case["prepare"] == "earlier":
        shutil.copytree(baseline, out, copy_function=shutil.copy2)
        (out / "notes.txt").write_text("the user's own notes")
    argv = [a.replace("{dir}", str(d)).replace("{out}", str(out)) for a in case["argv"]]
    written = Path(argv[argv.index("--out") + 1]) if "--out" in argv else None
    before = _state(d)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(argv)
    text = err.getvalue().strip()
    lines = text.splitlines()
    if "Traceback" in text or "internal error" in text or rc not in (0, 1, 2):
        return "internal", f"rc {rc}: {text[-300:]}"
    after = _state(d)
    if rc == 2:
        if len(lines) != 1:
            return "internal", f"rc 2 with {len(lines)} lines: {text[-300:]}"
        if after != before:
            changed = sorted(set(after.items()) ^ set(before.items()))[:2]
            return "damaged", f"a refusal changed the folder: {changed}: {text}"
        if case["names"] and case["names"] not in text:
            return "internal", f"the refusal does not name {case['names']}: {text}"
        if case["expect"] == "accept":
            return "internal", f"refused a valid input: {text}"
        return "refused", text
    if case["expect"] == "refuse":
        return "internal", f"rc {rc}: accepted what must be refused ({case['build']})"
    if any(".partial-" in k or k.endswith(".part") for k in after):
        return "damaged", f"a temporary file left: {[k for k in after if 'partial' in k or k.endswith('.part')]}"
    outputs = {str(written)} | ({k for k in after if k.startswith(str(out) + os.sep)} if written == out else set())
    for k, v in before.items():
        if k not in outputs and after.get(k) != v:
            return "damaged", f"{k} changed (rc {rc}): {text}"
    if rc == 1:
        return ("diverged", text) if "run diverged" in text else ("internal", text)
    if argv[0] == "learn-basis":
        from vtoladapt.bases.netfile import read_net

        net = read_net(written)
        if not all(np.isfinite(v).all() for v in net.arrays().values()):
            return "silent_nan", f"{written} holds non-finite weights"
        loss = net.meta.get("summary", {}).get("loss_final")
        if loss is None or not math.isfinite(loss):
            return "silent_nan", f"{written}: loss_final = {loss!r}"
    if argv[0] == "run":
        from hostile_pass import _outputs_sound, _silent_nan

        wrong = _outputs_sound(out) or _silent_nan(out)
        if wrong:
            return "silent_nan" if "non-finite" in wrong or "metrics" in wrong else "damaged", wrong
    return "ok", ""


def prepare_assets(work: Path, python: str) -> None:
    """The base flight log the log and argument cases copy (a 3 s run of the pass's scenario)."""
    import subprocess

    assets = work / "assets"
    assets.mkdir()
    base = (work / "s.toml").read_text().replace("duration_s = 0.3", "duration_s = 3.0")
    (assets / "s.toml").write_text(base)
    subprocess.run([python, "-m", "vtoladapt.cli", "run", str(assets / "s.toml"), "--out", str(assets / "run"),
                    "--quiet"], check=True)
    shutil.copy2(assets / "run" / "log.parquet", assets / "flight.parquet")
