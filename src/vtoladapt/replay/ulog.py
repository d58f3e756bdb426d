"""Read a PX4 ULog (``.ulg``) with pyulog into a :class:`~.flightlog.FlightLog`."""
from __future__ import annotations

import contextlib
import dataclasses
import io
from pathlib import Path

import numpy as np

from .flightlog import KNOWN_TOPICS, FlightLog, LogNote, ReadSettings, ReplayError, assemble_flight_log

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
    tables, params, _ = _read(Path(path))
    return tables, params


def _read(path: Path) -> tuple[dict, dict, bool]:
    """:func:`read_ulog_tables` and whether pyulog skipped damaged bytes on the way."""
    from pyulog import ULog

    if not path.is_file():
        raise ReplayError(f"{path}: no such file")
    if not is_ulog(path):
        raise ReplayError(f"{path}: not a PX4 ULog file (no 'ULog' header magic in the first bytes)")
    try:
        # pyulog prints what it skips to stdout; the replay says it in its own words instead
        with contextlib.redirect_stdout(io.StringIO()):
            ulog = ULog(str(path), list(KNOWN_TOPICS))
    except Exception as exc:  # pyulog raises bare Exceptions on corrupt files
        raise ReplayError(f"{path}: pyulog cannot parse it: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
    damaged = bool(getattr(ulog, "file_corruption", False))
    if damaged and not ulog.data_list:
        raise ReplayError(f"{path}: corrupt or truncated ULog: pyulog found damaged data and could read "
                          "no topic; allowed: an intact log (or one whose damage leaves its topics readable)")
    tables = {}
    for d in ulog.data_list:
        tables[(d.name, int(d.multi_id))] = {k: np.asarray(v) for k, v in d.data.items()}
    return tables, dict(ulog.initial_parameters), damaged


def read_ulog(path, settings: ReadSettings = ReadSettings()) -> FlightLog:
    """Read a ULog and assemble its :class:`FlightLog` (see :mod:`.flightlog` for what comes from where)."""
    tables, params, damaged = _read(Path(path))
    log = assemble_flight_log(tables, str(path), "ulog", settings, params)
    if damaged:
        note = LogNote("file integrity", "pyulog found damaged bytes and skipped them",
                       "the messages it could read are used; samples may be missing")
        log = dataclasses.replace(log, notes=(note, *log.notes))
    return log


__all__ = ["ULOG_MAGIC", "is_ulog", "read_ulog", "read_ulog_tables"]
