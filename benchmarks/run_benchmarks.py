"""Run every benchmark module (``benchmarks/bench_*.py``) and print one aligned table.

Each module defines ``run() -> list[tuple[str, float, str]]`` returning ``(name, value, unit)`` rows
(median of many calls after warm-up). A module that fails to import, raises, or returns malformed
rows is reported in the table and does not stop the others; the exit status is 1 if any failed.

Usage::

    python benchmarks/run_benchmarks.py                 # all modules (``make bench``)
    python benchmarks/run_benchmarks.py --only models   # one module (bench_models.py); repeatable
    python benchmarks/run_benchmarks.py --list          # the modules found
"""
from __future__ import annotations

import argparse
import importlib.util
import math
import os
import platform
import sys
import time
import traceback
from pathlib import Path

BENCH_DIR = Path(__file__).resolve().parent


def discover() -> list[Path]:
    """The benchmark modules, sorted by name."""
    return sorted(BENCH_DIR.glob("bench_*.py"))


def short_name(path: Path) -> str:
    """``bench_models.py`` -> ``models``."""
    return path.stem[len("bench_"):]


def _select(paths: list[Path], only: list[str] | None) -> list[Path]:
    if not only:
        return paths
    by_name = {short_name(p): p for p in paths}
    chosen = []
    for name in only:
        key = Path(name).stem
        key = key[len("bench_"):] if key.startswith("bench_") else key
        if key not in by_name:
            raise SystemExit(f"--only {name!r}: no benchmarks/bench_{key}.py; available: "
                             f"{', '.join(by_name) or 'none'}")
        chosen.append(by_name[key])
    return chosen


def _load(path: Path):
    spec = importlib.util.spec_from_file_location(f"vtoladapt_bench_{short_name(path)}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _validate(rows) -> list[tuple[str, float, str]]:
    if not isinstance(rows, (list, tuple)):
        raise TypeError(f"run() must return a list of (name, value, unit), got {type(rows).__name__}")
    out = []
    for i, row in enumerate(rows):
        if not (isinstance(row, (list, tuple)) and len(row) == 3):
            raise TypeError(f"row {i} must be (name, value, unit), got {row!r}")
        name, value, unit = row
        out.append((str(name), float(value), str(unit)))
    return out


def run_module(path: Path) -> tuple[list[tuple[str, float, str]], str | None, float]:
    """``(rows, error or None, wall seconds)``; never raises."""
    t0 = time.perf_counter()
    try:
        module = _load(path)
        if not callable(getattr(module, "run", None)):
            raise AttributeError(f"{path.name} has no run() function")
        rows = _validate(module.run())
        return rows, None, time.perf_counter() - t0
    except Exception as exc:  # noqa: BLE001 - one broken module must not stop the others
        tb = traceback.extract_tb(exc.__traceback__)
        where = f" ({Path(tb[-1].filename).name}:{tb[-1].lineno})" if tb else ""
        return [], f"{type(exc).__name__}: {exc}{where}", time.perf_counter() - t0


def machine_lines() -> list[str]:
    """CPU count, platform and the versions that decide the numbers."""
    import numpy

    try:
        import numba

        numba_version = numba.__version__
    except ImportError:
        numba_version = "not installed"
    try:
        affinity = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        affinity = None
    cpus = f"{os.cpu_count()} logical CPUs" + (f" ({affinity} usable)" if affinity is not None else "")
    return [
        f"machine: {platform.machine()} {platform.processor() or ''}".rstrip()
        + f", {cpus}, {platform.system()} {platform.release()}",
        f"python {platform.python_version()} ({platform.python_implementation()}), "
        f"numpy {numpy.__version__}, numba {numba_version}",
    ]


def _format_value(value: float) -> str:
    if not math.isfinite(value):
        return str(value)
    return f"{value:.4g}"


def format_table(results: list[tuple[str, list, str | None, float]]) -> str:
    """One aligned table: module, name, value, unit; a failed module gets one ERROR line."""
    header = ("module", "name", "value", "unit")
    lines = []
    for module, rows, error, _ in results:
        if error is not None:
            lines.append((module, "ERROR", "-", error))
        elif not rows:
            lines.append((module, "(no rows)", "-", ""))
        for name, value, unit in rows:
            lines.append((module, name, _format_value(value), unit))
    widths = [max(len(header[i]), *(len(r[i]) for r in lines)) if lines else len(header[i])
              for i in range(4)]

    def fmt(r):
        return f"{r[0]:<{widths[0]}}  {r[1]:<{widths[1]}}  {r[2]:>{widths[2]}}  {r[3]}".rstrip()

    rule = "-" * (sum(widths[:3]) + 6 + max(4, min(widths[3], 40)))
    out = [fmt(header), rule]
    previous = None
    for r in lines:
        if previous is not None and r[0] != previous:
            out.append("")
        out.append(fmt(r))
        previous = r[0]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", action="append", metavar="NAME",
                        help="run only this module (e.g. 'models' or 'bench_models.py'); repeatable")
    parser.add_argument("--list", action="store_true", help="list the benchmark modules and exit")
    args = parser.parse_args(argv)

    paths = discover()
    if args.list:
        print("\n".join(short_name(p) for p in paths))
        return 0
    paths = _select(paths, args.only)
    sys.path.insert(0, str(BENCH_DIR))  # let benchmark modules share helpers

    results = []
    for path in paths:
        print(f"running {path.name} ...", file=sys.stderr, flush=True)
        rows, error, wall = run_module(path)
        results.append((short_name(path), rows, error, wall))

    print("\n".join(machine_lines()))
    print()
    print(format_table(results))
    print()
    print("wall time per module: " + ", ".join(f"{m} {w:.1f} s" for m, _, _, w in results))
    failed = [m for m, _, e, _ in results if e is not None]
    if failed:
        print(f"FAILED: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
