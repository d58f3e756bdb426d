"""Read a PX4 ULog (``.ulg``) with pyulog into a :class:`~.flightlog.FlightLog`."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .flightlog import KNOWN_TOPICS, FlightLog, ReadSettings, ReplayError, assemble_flight_log

ULOG_MAGIC = b"ULog\x01\x12\x35"
"""First seven bytes of every ULog file (the format's header magic)."""


def is_ulog(path: Path) -> bool:
    """True if the file starts with the ULog header magic."""
    try:
        with open(path, "rb") as fh:
            return fh.read(len(ULOG_MAGIC)) == ULOG_MAGIC
    except OSError:
        return False


def read_ulog_tables(path: Path) -> tuple[dict, dict]:
    """``({(topic, instance): {field: array}}, parameters)`` of the topics the replay reads.

    Raises
    ------
    ReplayError
        If the file is missing, is not a ULog, or pyulog cannot parse it.
    """
    from pyulog import ULog

    path = Path(path)
    if not path.is_file():
        raise ReplayError(f"{path}: no such file")
    if not is_ulog(path):
        raise ReplayError(f"{path}: not a PX4 ULog file (no 'ULog' header magic in the first bytes)")
    try:
        ulog = ULog(str(path), list(KNOWN_TOPICS))
    except Exception as exc:  # pyulog raises bare Exceptions on corrupt files
        raise ReplayError(f"{path}: pyulog cannot parse it: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
    tables = {}
    for d in ulog.data_list:
        tables[(d.name, int(d.multi_id))] = {k: np.asarray(v) for k, v in d.data.items()}
    return tables, dict(ulog.initial_parameters)


def read_ulog(path, settings: ReadSettings = ReadSettings()) -> FlightLog:
    """Read a ULog and assemble its :class:`FlightLog` (see :mod:`.flightlog` for what comes from where)."""
    tables, params = read_ulog_tables(Path(path))
    return assemble_flight_log(tables, str(path), "ulog", settings, params)


__all__ = ["ULOG_MAGIC", "is_ulog", "read_ulog", "read_ulog_tables"]
