"""Replay real flight logs: the force model and the composite adaptation, open loop, on PX4 data.

    vtoladapt replay LOG --vehicle NAME --out DIR

``LOG`` is a PX4 ULog (``.ulg``) or a folder of PX4 topic CSVs. :mod:`.flightlog` says what each
quantity is made of (and what a log typically lacks), :mod:`.estimator` runs the adaptation,
:mod:`.outputs` writes the time series, metrics, figure and report, :mod:`.cli` the command.
"""
from .csvfolder import read_csv_folder
from .estimator import ReplayResult, ReplaySettings, run_replay
from .flightlog import (FlightLog, LogNote, ReadSettings, ReplayError, ThrottleSource,
                        parse_throttle_source)
from .ulog import read_ulog

__all__ = ["FlightLog", "LogNote", "ReadSettings", "ReplayError", "ReplayResult", "ReplaySettings",
           "ThrottleSource", "parse_throttle_source", "read_csv_folder", "read_ulog", "run_replay"]
