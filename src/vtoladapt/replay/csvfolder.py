"""Read a folder of PX4 topic CSVs (what pyulog's ``ulog2csv`` writes) into a :class:`~.flightlog.FlightLog`.

``ulog2csv`` names each file ``<log name>_<topic>_<instance>.csv`` with a header of PX4 field
names (``timestamp`` in microseconds first, arrays as ``q[0]``, ``q[1]``...). Files of topics the
replay does not read are ignored; the log-name prefix may be anything (or nothing).
"""
from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np

from ..config import ConfigError, check_input_file
from .flightlog import KNOWN_TOPICS, FlightLog, ReadSettings, ReplayError, assemble_flight_log

_PATTERNS = [(t, re.compile(rf"(?:^|_){re.escape(t)}_(\d+)$")) for t in
             sorted(KNOWN_TOPICS, key=len, reverse=True)]


def topic_of_filename(stem: str) -> tuple[str, int] | None:
    """``'flight3_vehicle_attitude_0'`` -> ``('vehicle_attitude', 0)``; None for topics the replay ignores."""
    for topic, pat in _PATTERNS:
        m = pat.search(stem)
        if m:
            return topic, int(m.group(1))
    return None


def read_topic_csv(path: Path) -> dict:
    """One topic CSV -> ``{field: float64 array}`` (empty cells and 'nan' are NaN).

    Raises
    ------
    ReplayError
        If the file is not a readable regular file within the input-size ceiling, has no header,
        no ``timestamp`` column, or a cell is not a number.
    """
    try:
        check_input_file(path, "PX4 topic CSV")
    except ConfigError as exc:
        raise ReplayError(str(exc)) from None
    with open(path, encoding="utf-8", errors="replace") as fh:
        header = fh.readline().strip()
        if not header:
            raise ReplayError(f"{path}: empty file (a PX4 topic CSV needs a header line)")
        names = [h.strip() for h in header.split(",")]
        if "timestamp" not in names:
            raise ReplayError(f"{path}: header has no 'timestamp' column (found: {', '.join(names[:8])})")
        try:
            with warnings.catch_warnings():  # a header-only file is no data, said below, not a warning
                warnings.filterwarnings("ignore", message=".*[Ee]mpty input file", category=UserWarning)
                data = np.genfromtxt(fh, delimiter=",", dtype=np.float64, ndmin=2, invalid_raise=True,
                                     missing_values=("", "nan"), filling_values=np.nan)
        except ValueError as exc:
            raise ReplayError(f"{path}: not a numeric PX4 topic CSV ({str(exc).splitlines()[0]})") from None
    if data.size == 0:
        data = np.empty((0, len(names)))
    if data.shape[1] != len(names):
        raise ReplayError(f"{path}: {data.shape[1]} columns in the rows but {len(names)} in the header")
    return {name: data[:, i] for i, name in enumerate(names)}


def read_csv_folder_tables(folder: Path) -> dict:
    """``{(topic, instance): {field: array}}`` of the replay's topics found in ``folder``.

    Raises
    ------
    ReplayError
        If the folder is missing, has no CSV, or none of the replay's topics.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ReplayError(f"{folder}: no such folder")
    csvs = sorted(folder.glob("*.csv"))
    if not csvs:
        raise ReplayError(f"{folder}: no .csv files (expected PX4 topic CSVs named <log>_<topic>_<instance>.csv)")
    tables = {}
    for p in csvs:
        key = topic_of_filename(p.stem)
        if key is None:
            continue
        if key in tables:
            raise ReplayError(f"{p}: a second file for topic {key[0]} instance {key[1]} in the folder")
        tables[key] = read_topic_csv(p)
    if not tables:
        raise ReplayError(f"{folder}: none of its {len(csvs)} CSVs is a topic the replay reads "
                          f"(e.g. <log>_vehicle_attitude_0.csv, <log>_vehicle_local_position_0.csv)")
    return tables


def read_csv_folder(folder, settings: ReadSettings = ReadSettings()) -> FlightLog:
    """Read a folder of PX4 topic CSVs and assemble its :class:`FlightLog`."""
    return assemble_flight_log(read_csv_folder_tables(Path(folder)), str(folder), "csv-folder", settings)


__all__ = ["read_csv_folder", "read_csv_folder_tables", "read_topic_csv", "topic_of_filename"]
