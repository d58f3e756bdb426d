"""Training data from flight logs: one task per flight, what the flight computer had and the force it measured.

For each sample: the basis input block (:data:`vtoladapt.bases.INPUT`) the controller formed, as
far as the log holds it, and the measured specific force (the accelerometer, body, m/s^2) that the
basis must predict. The accelerometer is the *target* only; no input is derived from it.

* **A simulator log** (``SimulationResult`` Parquet, ``vtoladapt run`` / :func:`vtoladapt.learn.flights.fly_draws`): the
  incident flow the controller used (``ctrl_v_i_*``) and whether it was the probe's
  (``probe_valid_used``), the throttle commands passed through the vehicle's nominal motor lag as the
  controller does (:func:`lagged_throttles`), the measured attitude, rates and velocity.
* **A PX4 flight log** (``.ulg`` or a CSV folder, read as :mod:`vtoladapt.replay` reads it): the
  incident velocity from the pitot or inertial minus wind, the logged throttles through the same
  lag, attitude and velocity; the log's rates are not on the replay grid, so ``omega_B`` is the
  attitude quaternion's derivative (``2 q^-1 dq/dt``).

Samples are kept from ``skip_s`` on, every ``stride``-th, where every input and the force are finite.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..bases import evaluate, input_rows
from ..config import ConfigError
# a simulator log's samples are read as the experiments read them (one reading for both)
from ..bases.log_samples import SIM_COLUMNS, Flight, _select, flight_from_result, lagged_throttles  # noqa: F401

def quaternion_rates(q: np.ndarray, dt: float) -> np.ndarray:
    """Body rates (rad/s) from a unit quaternion series (scalar first): ``omega = 2 vec(q^* dq/dt)``."""
    dq = np.gradient(q, dt, axis=0)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    dw, dx, dy, dz = dq[:, 0], dq[:, 1], dq[:, 2], dq[:, 3]
    return 2.0 * np.column_stack([w * dx - x * dw - y * dz + z * dy,
                                  w * dy + x * dz - y * dw - z * dx,
                                  w * dz - x * dy + y * dx - z * dw])


def flight_from_flightlog(log, vehicle, skip_s: float = 1.0, stride: int = 5) -> Flight:
    """A :class:`Flight` from a PX4 log read by :mod:`vtoladapt.replay` (samples on the ground left out)."""
    if len(log.t_s) == 0:
        raise ConfigError(f"{log.source}: 0 samples; allowed: a log of a flight (at least one sample)")
    dt = 1.0 / log.rate_hz
    u_cmd = np.column_stack([log.throttle_x_pct, log.throttle_z_pct]) / 100.0
    act = vehicle.actuators
    u = lagged_throttles(u_cmd, dt, act.pusher_motor_time_constant_s, act.lift_motor_time_constant_s)
    omega = quaternion_rates(log.q_WB, dt)
    sel = _select(log.t_s, skip_s, stride)
    sel = sel[~log.landed[sel]]
    x = input_rows(log.v_i_B_mps[sel], u[sel, 0], u[sel, 1], vehicle.model_kernel,
                   valid=log.v_i_from_pitot[sel].astype(float), q_WB=log.q_WB[sel], omega_B=omega[sel],
                   v_W=log.v_W_mps[sel])
    f = log.f_meas_B_mps2[sel]
    ok = np.all(np.isfinite(x), axis=1) & np.all(np.isfinite(f), axis=1)
    return Flight(x[ok], f[ok], vehicle.name, str(log.source), {"source": str(log.source)})


LOG_SUFFIXES = (".parquet", ".ulg")


def log_files(paths) -> list[Path]:
    """The log files among ``paths`` (a folder contributes its ``*.parquet`` and ``*.ulg``, sorted)."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            out += sorted(q for q in p.iterdir() if q.suffix in LOG_SUFFIXES and q.is_file())
        elif p.is_file():
            if p.suffix not in LOG_SUFFIXES:
                raise ConfigError(f"{p}: not a log file; allowed: {' or '.join(LOG_SUFFIXES)} files, or folders of them")
            out.append(p)
        else:
            raise ConfigError(f"{p}: no such log file or folder")
    return out


def shipped_vehicle(name, where: str):
    """The shipped vehicle a log's metadata names: only a registered name resolves (a log's text is never
    opened as a path: ``../../etc/passwd`` is refused, not read)."""
    from ..vehicle import available_vehicles, load_vehicle

    names = available_vehicles()
    if not isinstance(name, str) or name not in names:
        shown = repr(name) if len(repr(name)) <= 80 else repr(name)[:60] + "..."
        raise ConfigError(f"{where}: metadata vehicle = {shown}: not a shipped vehicle; allowed: one of {names}, "
                          "or --vehicle NAME or PATH (the vehicle file the log was flown with)")
    return load_vehicle(name)


def log_metadata(res, where: str) -> dict:
    """A simulator log's metadata, checked where training reads it: ``vehicle`` text, ``draw`` a table,
    ``seed`` a whole number (or absent)."""
    meta = res.metadata
    if not isinstance(meta, dict):
        raise ConfigError(f"{where}: metadata is JSON {type(meta).__name__}; allowed: a JSON object")
    for key, ok, allowed in (("vehicle", lambda v: isinstance(v, str), "the vehicle's name (text)"),
                             ("draw", lambda v: isinstance(v, dict), "a table of the draw's values"),
                             ("seed", lambda v: isinstance(v, int) and not isinstance(v, bool), "a whole number")):
        if key in meta and meta[key] is not None and not ok(meta[key]):
            shown = repr(meta[key]) if len(repr(meta[key])) <= 80 else repr(meta[key])[:60] + "..."
            raise ConfigError(f"{where}: metadata {key} = {shown}; allowed: {allowed}")
    return meta


# what reading a file that is not a simulator log raises (pyarrow's errors are ValueError and OSError
# subclasses; a metadata entry missing or nested beyond the parser's stack; a column of text)
_LOG_ERRORS = (ValueError, OSError, KeyError, TypeError, RecursionError, UnicodeDecodeError)


def read_flight(path: Path, vehicle=None, skip_s: float = 1.0, stride: int = 5) -> Flight:
    """One log file as a :class:`Flight`; ``vehicle`` defaults to the one a simulator log names (a shipped
    vehicle's name only: :func:`shipped_vehicle`). A file that is not such a log is a one-line ConfigError."""
    if path.suffix == ".parquet":
        from ..sim.results import SimulationResult

        try:
            res = SimulationResult.from_parquet(path)
            if res.data.dtype.kind not in "fiub":
                raise TypeError(f"columns of {res.data.dtype} values; allowed: numbers")
        except _LOG_ERRORS as exc:
            text = " ".join(str(exc).split())[:200] or type(exc).__name__
            raise ConfigError(f"{path}: not a vtoladapt simulator log ({text})") from None
        meta = log_metadata(res, str(path))
        veh = vehicle or shipped_vehicle(meta.get("vehicle"), str(path))
        info = dict(meta.get("draw") or {}) or {"seed": meta.get("seed")}
        return flight_from_result(res, veh, str(path), skip_s, stride, info=info)
    if vehicle is None:
        raise ConfigError(f"{path}: a PX4 log does not name its vehicle; allowed: --vehicle NAME or PATH")
    from ..replay.cli import read_flight_log
    from ..replay.flightlog import ReadSettings, ReplayError

    try:
        log = read_flight_log(path, ReadSettings())
    except ReplayError as exc:  # its message names the file and what is wrong: bad input, exit 2
        raise ConfigError(" ".join(str(exc).split())) from None
    return flight_from_flightlog(log, vehicle, skip_s, stride)


def physics_columns(spec, flight: Flight) -> np.ndarray:
    """The physics basis's ``Phi`` (N, 3, m) at the flight's inputs."""
    return evaluate(spec, flight.x)
