"""``vtoladapt export RUN --format csv|mat|parquet [--out FILE]``: a run's log for MATLAB, a
spreadsheet or pandas.

``RUN`` is a log (``log.parquet``, ``runs/NAME.parquet``) or the folder ``vtoladapt run`` wrote (its
``log.parquet``, or its one log under ``runs/``). Every column is exported, one row per logged tick,
values as logged (float64: a CSV row is its values' shortest round-tripping text, ``repr``).

* ``csv``: a comment line (``# vtoladapt export of FILE ...``), the column names, their units
  (``m/s``, ``rad``, ``-`` for none), then one row per tick:
  ``pandas.read_csv(path, skiprows=[0, 2])`` reads the data, ``skiprows=1, nrows=1`` the units.
* ``mat``: MATLAB 5 (``scipy.io.savemat``): one variable per column, named as a MATLAB identifier
  (letters, digits and '_', starting with a letter, at most 63 characters: :func:`matlab_name`), plus
  ``units`` (a struct: field = variable name, value = unit text), ``columns`` (the log's own column
  names, in order, as a cell array) and ``vtoladapt_export`` (the source log and the run's metadata
  as JSON text).
* ``parquet``: the log as it is (its run metadata kept), e.g. to extract one log of a folder.

The output is written under a temporary name and renamed (no half-written file) and never replaces
a file that is not an earlier export (:func:`vtoladapt.outputs.check_output_files`; ``--force``
does). Default ``--out``: the log's name with the format's suffix, beside it.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

from .config import ConfigError

FORMATS = ("csv", "mat", "parquet")
EXPORT_MARK = "vtoladapt export"
"""How an export names itself: the CSV's first line, the .mat's variable, the Parquet's metadata key."""

_UNIT_SUFFIXES = (  # the log's column names end in their unit (README "Log columns"); longest first
    ("_mps2", "m/s^2"), ("_radps", "rad/s"), ("_per_s", "1/s"), ("_kgpm3", "kg/m^3"), ("_mps", "m/s"),
    ("_Nm", "N m"), ("_Pa", "Pa"), ("_rad", "rad"), ("_deg", "deg"), ("_frac", "fraction"), ("_pct", "%"),
    ("_Hz", "Hz"), ("_kg", "kg"), ("_N", "N"), ("_m", "m"), ("_s", "s"), ("_g", "g"),
)
MATLAB_NAME_MAX = 63
"""MATLAB's ``namelengthmax``."""


def column_unit(name: str) -> str:
    """The unit a log column's name states (``v_N_mps`` -> ``m/s``); ``-`` if none (quaternions, flags)."""
    for suffix, unit in _UNIT_SUFFIXES:
        if name.endswith(suffix):
            return unit
    return "-"


def matlab_name(name: str, taken: set[str]) -> str:
    """``name`` as a valid MATLAB identifier not in ``taken`` (added to it): characters other than
    letters, digits and '_' become '_', a name not starting with a letter gets ``x_``, at most
    :data:`MATLAB_NAME_MAX` characters, a clash gets ``_2``, ``_3``, ..."""
    base = re.sub(r"[^A-Za-z0-9_]", "_", name)
    if not base or not base[0].isalpha():
        base = "x_" + base
    base = base[:MATLAB_NAME_MAX]
    out, i = base, 2
    while out in taken:
        tail = f"_{i}"
        out, i = base[:MATLAB_NAME_MAX - len(tail)] + tail, i + 1
    taken.add(out)
    return out


def find_log(run: str | Path) -> Path:
    """The log of ``RUN``: the file itself, or a run folder's ``log.parquet`` or its one ``runs/*.parquet``."""
    path = Path(run)
    if path.is_dir():
        if (path / "log.parquet").is_file():
            return path / "log.parquet"
        logs = sorted((path / "runs").glob("*.parquet")) if (path / "runs").is_dir() else []
        if len(logs) == 1:
            return logs[0]
        if logs:
            shown = ", ".join(str(p) for p in logs[:3]) + (", ..." if len(logs) > 3 else "")
            raise ConfigError(f"{path}: a folder of {len(logs)} logs ({shown}); allowed: one of them")
        raise ConfigError(f"{path}: no log in this folder (log.parquet or runs/*.parquet); allowed: a run's log "
                          "or the folder `vtoladapt run` wrote (a run with --no-log keeps none)")
    if not path.exists():
        raise ConfigError(f"{path}: not found; allowed: a run's log (.parquet) or its folder")
    return path


def _read_log(path: Path):
    """The log's Arrow table and run metadata; a one-line ConfigError for anything else."""
    import pyarrow.parquet as pq

    from .config import check_input_file
    from .sim.results import log_file_metadata

    check_input_file(path, "run log (.parquet)", max_bytes=1 << 40)
    if path.suffix == ".toml":  # a scenario or vehicle given by mistake: say which
        from .config import read_toml
        from .file_kinds import check_file_kind

        check_file_kind(path, read_toml(path), "run log", "`vtoladapt export`")
    try:
        metadata = log_file_metadata(path)
        table = pq.read_table(path)
    except (OSError, ValueError, KeyError) as exc:  # pyarrow's ArrowInvalid is a ValueError
        raise ConfigError(f"{path}: not a vtoladapt run log ({' '.join(str(exc).split())[:120]}); allowed: the "
                          "log.parquet or runs/*.parquet of `vtoladapt run`") from None
    return table.replace_schema_metadata(None), metadata


def export_log(run: str | Path, fmt: str, out: str | Path | None = None, force: bool = False) -> Path:
    """Write the log of ``run`` as ``fmt`` (:data:`FORMATS`) to ``out`` (default: beside it); the path."""
    from .outputs import check_output_files

    if fmt not in FORMATS:
        raise ConfigError(f"--format {fmt}: unknown; allowed: {', '.join(FORMATS)}")
    log = find_log(run)
    out = Path(out) if out is not None else log.with_suffix(f".{fmt}")
    if out.suffix.lower() != f".{fmt}":
        raise ConfigError(f"--out {out}: a {fmt} export's name ends in .{fmt}")
    if out.exists() and out.resolve() == log.resolve():
        raise ConfigError(f"--out {out}: is the log being exported; give another name")
    check_output_files([out], "export", is_ours=_is_export, force=force)
    table, metadata = _read_log(log)
    {"csv": _write_csv, "mat": _write_mat, "parquet": _write_parquet}[fmt](table, metadata, log, out)
    return out


def _write_csv(table, metadata, log: Path, out: Path) -> None:
    import numpy as np

    from .outputs import atomic_path

    names = table.column_names
    data = np.column_stack([table.column(i).to_numpy() for i in range(table.num_columns)]) if names else None
    with atomic_path(out) as tmp, open(tmp, "w", encoding="utf-8", newline="") as fh:
        fh.write(f"# {EXPORT_MARK} of {log}: column names in the next line, their units in the one after\n")
        fh.write(",".join(names) + "\n")
        fh.write(",".join(column_unit(n) for n in names) + "\n")
        if data is not None:
            for row in data:  # repr: the shortest text that reads back as the same float64
                fh.write(",".join(map(repr, row.tolist())) + "\n")


def _write_mat(table, metadata, log: Path, out: Path) -> None:
    import numpy as np
    import scipy.io

    from .outputs import atomic_path

    taken = {"units", "columns", "vtoladapt_export"}
    variables, units = {}, {}
    for i, name in enumerate(table.column_names):
        var = matlab_name(name, taken)
        variables[var] = table.column(i).to_numpy().astype(float)[:, None]  # a column vector
        units[var] = column_unit(name)
    columns = np.empty((len(table.column_names), 1), dtype=object)
    columns[:, 0] = table.column_names
    variables.update(units=units, columns=columns,
                     vtoladapt_export=json.dumps({"source": str(log), "metadata": metadata}, default=str))
    with atomic_path(out) as tmp, open(tmp, "wb") as fh:
        scipy.io.savemat(fh, variables, do_compression=True, long_field_names=True)


def _write_parquet(table, metadata, log: Path, out: Path) -> None:
    import pyarrow.parquet as pq

    from .outputs import atomic_path
    from .sim.results import log_metadata_entries

    entries = {**log_metadata_entries(metadata), b"vtoladapt_export": str(log).encode()}
    with atomic_path(out) as tmp:
        pq.write_table(table.replace_schema_metadata(entries), tmp)


def _is_export(path: Path) -> bool:
    """True for a file this command wrote (which ``export`` may replace)."""
    try:
        if path.suffix == ".csv":
            with path.open("rb") as fh:
                return fh.read(len(EXPORT_MARK) + 2) == f"# {EXPORT_MARK}".encode()
        if path.suffix == ".mat":
            import scipy.io

            return any(name == "vtoladapt_export" for name, _, _ in scipy.io.whosmat(str(path)))
        if path.suffix == ".parquet":
            import pyarrow.parquet as pq

            return b"vtoladapt_export" in (pq.ParquetFile(path).schema_arrow.metadata or {})
    except Exception:  # not readable as one: not ours
        return False
    return False


def register_cli(sub) -> None:
    """``vtoladapt export`` (:func:`vtoladapt.cli.build_parser`)."""
    from .outputs import add_force_argument, output_path

    p = sub.add_parser("export", help="a run's log as CSV, MATLAB .mat or Parquet",
                       description="Write a run's log (every column, with units) as CSV (names, then units, "
                                   "then the rows), MATLAB .mat (one variable per column, a units struct) or "
                                   "Parquet. RUN: a log.parquet, runs/NAME.parquet, or the folder `vtoladapt "
                                   "run` wrote.")
    p.add_argument("run", metavar="RUN", help="a run's log (.parquet) or its folder")
    p.add_argument("--format", required=True, choices=FORMATS, help="csv, mat or parquet")
    p.add_argument("--out", type=output_path, default=None, metavar="FILE",
                   help="file to write (default: the log's name with the format's suffix, beside it)")
    add_force_argument(p)
    p.set_defaults(handler=_cmd_export)


def _cmd_export(args) -> int:
    from .errors import ExitCode

    out = export_log(args.run, args.format, args.out, force=args.force)
    print(f"wrote {out}")
    return ExitCode.OK


__all__ = ["FORMATS", "column_unit", "export_log", "find_log", "matlab_name"]
