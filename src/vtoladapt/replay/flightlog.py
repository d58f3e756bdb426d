"""One flight log as the replay sees it: PX4 topics -> time-aligned arrays with units.

Both readers (:mod:`.ulog`, :mod:`.csvfolder`) turn a log into :class:`TopicTable` s (one per
topic instance: PX4 field name -> array, ``timestamp`` in microseconds) and hand them to
:func:`assemble_flight_log`, which is the one place that decides what each quantity is made of
and writes down, in :attr:`FlightLog.notes`, what the log lacks and how the replay fills it in.

What the force model needs and where it comes from
--------------------------------------------------
* **Attitude** ``q_WB``: ``vehicle_attitude.q[0..3]`` (Hamilton, scalar first, body FRD -> NED).
* **Inertial velocity** ``v_W``: ``vehicle_local_position.vx, vy, vz`` (m/s, NED).
* **Incident velocity** ``v_i_B`` (vehicle relative to air, body FRD). A PX4 log has at most a
  pitot tube: a true airspeed (m/s) and no angle of attack or sideslip. The replay takes the
  *direction* of the flow from the inertial velocity minus the wind estimate, rotated into body
  axes (``R^T (v_W - w_W)``, eq:vi), and its *magnitude* from the pitot (a pitot reads the total
  dynamic pressure to within a few percent up to 15-20 deg of flow angle). The wind is PX4's
  estimate (``wind_estimate`` or ``airspeed_wind``: north and east, vertical taken as zero), or
  zero when the log has none. Below ``airspeed_min_mps`` the pitot reading is dominated by its
  zero offset (PX4 logs read -3..-1 m/s at rest) and is treated as invalid: ``v_i_B`` is then
  ``R^T (v_W - w_W)`` alone.
* **Throttles** in percent: the lift-rotor collective ``u_z`` and the pusher ``u_x`` of the
  force model, each from a :class:`ThrottleSource` (normalised ``actuator_controls`` commands,
  or ``actuator_outputs`` PWM mapped to a fraction by a stated PWM range). Several motors combine
  as the root mean square of their fractions, because the model's thrust is ``C_T u^2`` summed
  over the rotors. A channel the log lacks is set to zero, and said so.
* **Measured specific force** ``f_B`` (body FRD, m/s^2, what ``f_b`` predicts): the accelerometer
  of ``sensor_combined`` where the log has it; otherwise the kinematic acceleration of
  ``vehicle_local_position`` (its ``ax, ay, az`` fields, or the central difference of
  ``vx, vy, vz`` when those are absent) minus gravity, rotated into body axes:
  ``f_B = R^T (a_W - g_W)``.
* **Ground contact**: ``vehicle_land_detected.landed``. On the ground the specific force holds the
  ground's reaction, which the force model does not have, so those samples are flagged.

Resampling
----------
Everything is put on one uniform time grid at ``rate_hz`` (default: the rate of the fastest topic
the force model needs, at most 250 Hz) over the span all required topics cover. Continuous
signals are interpolated linearly (quaternions component-wise in one hemisphere, then
normalised); commands and flags are held from their last sample. A sample that falls in a gap of
its topic (more than ``max_gap_s`` between two samples) or outside the topic's span is NaN, never
zero; so is a pitot reading below the threshold.
"""
from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from ..config import setting
from ..frames import GRAVITY_MPS2, quats_to_rotmats


class ReplayError(ValueError):
    """A flight log or a replay setting is unusable; the one-line message names file, field and value."""


TopicTable = Mapping[str, np.ndarray]
"""One topic instance: PX4 field name -> 1-D array (``timestamp`` in microseconds)."""

TopicKey = tuple[str, int]
"""``(topic name, instance)``, e.g. ``("actuator_outputs", 0)``."""

ATTITUDE = "vehicle_attitude"
LOCAL_POSITION = "vehicle_local_position"
SENSOR_COMBINED = "sensor_combined"
AIRSPEED_TOPICS = ("airspeed_validated", "airspeed")
WIND_TOPICS = ("wind_estimate", "airspeed_wind")
LAND_DETECTED = "vehicle_land_detected"
VEHICLE_STATUS = "vehicle_status"

KNOWN_TOPICS = (ATTITUDE, LOCAL_POSITION, SENSOR_COMBINED, *AIRSPEED_TOPICS, *WIND_TOPICS,
                LAND_DETECTED, VEHICLE_STATUS, "actuator_controls_0", "actuator_controls_1",
                "actuator_outputs")
"""Topics the replay reads (anything else in a log is ignored)."""

PX4_VEHICLE_TYPE_FIXED_WING = 2
"""``vehicle_status.vehicle_type`` of a fixed-wing aircraft (PX4 ``VEHICLE_TYPE_FIXED_WING``)."""


@dataclass(frozen=True)
class ThrottleSource:
    """Where one of the model's throttles comes from in the log.

    ``topic`` is ``actuator_controls_0``/``actuator_controls_1`` (normalised commands, 0..1, field
    ``control[i]``) or ``actuator_outputs`` (instance 0, PWM in microseconds, field ``output[i]``);
    ``indices`` are the ``i``; ``none`` (empty topic) means the vehicle has no such rotor.
    """

    topic: str = setting("-", "PX4 topic, or '' for none")
    indices: tuple[int, ...] = setting("-", "field indices (control[i] or output[i]); several "
                                       "motors combine as the RMS of their fractions")

    @property
    def is_pwm(self) -> bool:
        """True if the channels are PWM outputs (mapped by the PWM range), False for normalised commands."""
        return self.topic == "actuator_outputs"

    def fields(self) -> tuple[str, ...]:
        """The PX4 field names the channel reads."""
        name = "output" if self.is_pwm else "control"
        return tuple(f"{name}[{i}]" for i in self.indices)

    def describe(self) -> str:
        """``topic.field`` text for reports."""
        if not self.topic:
            return "none"
        return ", ".join(f"{self.topic}.{f}" for f in self.fields())


_SPEC = re.compile(r"^(actuator_controls_[01]|actuator_outputs):(\d+(?:,\d+)*)$")


def parse_throttle_source(text: str, option: str = "throttle") -> ThrottleSource:
    """``'actuator_outputs:4,5,6,7'``, ``'actuator_controls_0:3'`` or ``'none'`` -> :class:`ThrottleSource`."""
    t = text.strip()
    if t.lower() == "none":
        return ThrottleSource("", ())
    m = _SPEC.match(t)
    if not m:
        raise ReplayError(f"{option} = {text!r}: expected 'none', 'actuator_controls_0:I', "
                          "'actuator_controls_1:I' or 'actuator_outputs:I[,J...]' (I, J field indices)")
    idx = tuple(int(s) for s in m.group(2).split(","))
    if len(set(idx)) != len(idx) or max(idx) > 15:
        raise ReplayError(f"{option} = {text!r}: indices must be distinct and at most 15")
    return ThrottleSource(m.group(1), idx)


@dataclass(frozen=True)
class ReadSettings:
    """How a log is turned into a :class:`FlightLog`."""

    rate_hz: float | None = setting("Hz", "resampling rate; None: the fastest required topic's "
                                    "median rate, at most 250 Hz", default=None, gt=0.0, le=1000.0)
    airspeed_min_mps: float = setting("m/s", "pitot readings below this are invalid (zero offset "
                                      "dominates); the inertial velocity minus wind is used",
                                      default=3.0, ge=0.0)
    max_gap_s: float = setting("s", "a topic silent for longer than this leaves NaN in between "
                               "(at least 3 of its median sample intervals)", default=0.5, gt=0.0)
    lift_throttle: ThrottleSource | None = setting(
        "-", "lift collective u_z; None: actuator_controls_0:3, or none for a fixed-wing "
        "(vehicle_status.vehicle_type = 2, not VTOL)", default=None)
    pusher_throttle: ThrottleSource | None = setting(
        "-", "pusher u_x; None: actuator_controls_1:3 for a VTOL, actuator_controls_0:3 for a "
        "fixed-wing", default=None)
    pwm_range_us: tuple[float, float] | None = setting(
        "us", "PWM of zero and full throttle for actuator_outputs; None: the log's PWM_MIN and "
        "PWM_MAX parameters, else 1000 and 2000", default=None)

    def __post_init__(self) -> None:
        if self.rate_hz is not None and not (np.isfinite(self.rate_hz) and 0.0 < self.rate_hz <= 1000.0):
            raise ReplayError(f"rate_hz = {self.rate_hz!r}: must be in (0, 1000] Hz")
        for name in ("airspeed_min_mps", "max_gap_s"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0.0 or (name == "max_gap_s" and v == 0.0):
                raise ReplayError(f"{name} = {v!r}: must be finite and {'> 0' if name == 'max_gap_s' else '>= 0'}")
        if self.pwm_range_us is not None:
            lo, hi = self.pwm_range_us
            if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 <= lo < hi):
                raise ReplayError(f"pwm_range_us = {self.pwm_range_us!r}: need 0 <= min < max (us)")


@dataclass(frozen=True)
class LogNote:
    """One thing a log lacks (or holds in a form the model cannot use) and how the replay fills it in."""

    quantity: str
    lacks: str
    filled: str


@dataclass(frozen=True, eq=False)
class FlightLog:
    """A log's signals on one uniform time grid (see the module notes for where each comes from).

    Arrays have ``n = len(t_s)`` rows; NaN marks a sample with no valid data.
    """

    source: str                      # the log file or folder
    log_format: str                  # 'ulog' or 'csv-folder'
    rate_hz: float                   # Hz, the grid's rate
    t0_us: int                       # PX4 boot time (us) of t_s = 0
    t_s: np.ndarray                  # (n,) s since t0_us
    q_WB: np.ndarray                 # (n, 4) attitude quaternion [w, x, y, z], body FRD -> NED
    v_W_mps: np.ndarray              # (n, 3) inertial velocity, NED, m/s
    wind_W_mps: np.ndarray           # (n, 3) wind estimate used, NED, m/s (zero where the log has none)
    airspeed_pitot_mps: np.ndarray   # (n,) pitot true airspeed, m/s; NaN where missing or below the threshold
    v_i_B_mps: np.ndarray            # (n, 3) incident velocity, body FRD, m/s
    v_i_from_pitot: np.ndarray       # (n,) bool: |v_i_B| is the pitot's (else inertial minus wind)
    f_meas_B_mps2: np.ndarray        # (n, 3) measured specific force, body FRD, m/s^2
    throttle_x_pct: np.ndarray       # (n,) pusher throttle u_x, %
    throttle_z_pct: np.ndarray       # (n,) lift collective u_z, %
    landed: np.ndarray               # (n,) bool: the land detector says on the ground
    topics: dict = field(default_factory=dict)   # 'topic#instance' -> {'samples', 'rate_hz'} of what was read
    notes: tuple[LogNote, ...] = ()
    sources: dict = field(default_factory=dict)  # quantity -> where it came from (text)

    def __post_init__(self) -> None:
        n = self.t_s.shape[0]
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray) and v.shape[0] != n:
                raise ValueError(f"FlightLog.{f.name}: {v.shape[0]} rows, expected {n}")

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t_s.shape[0])

    @property
    def duration_s(self) -> float:
        """Span of the grid (s)."""
        return float(self.t_s[-1] - self.t_s[0]) if self.n > 1 else 0.0


# --- resampling --------------------------------------------------------------------------------

def _median_dt_s(ts_us: np.ndarray) -> float:
    d = np.diff(ts_us.astype(np.float64)) * 1e-6
    d = d[d > 0]
    return float(np.median(d)) if d.size else np.inf


def _gap_mask(ts_us: np.ndarray, grid_us: np.ndarray, max_gap_s: float, hold: bool) -> np.ndarray:
    """True where a grid time has a sample of the topic close enough (inside its span, not in a gap)."""
    t = ts_us.astype(np.float64)
    gap_us = 1e6 * max(max_gap_s, 3.0 * _median_dt_s(ts_us)) if t.size > 1 else 0.0
    j = np.searchsorted(t, grid_us, side="right")  # t[j-1] <= grid < t[j]
    ok = j > 0
    if hold:
        # held from the last sample while the next one is due; after the last sample, for one gap
        prev = t[np.clip(j - 1, 0, t.size - 1)]
        nxt = np.where(j < t.size, t[np.clip(j, 0, t.size - 1)], prev + gap_us)
        ok &= (nxt - prev) <= gap_us
        ok &= grid_us - prev <= gap_us
        return ok
    ok &= (j < t.size) | (grid_us == t[-1])
    jj = np.clip(j, 1, t.size - 1)
    ok &= (t[jj] - t[jj - 1]) <= gap_us
    return ok


def resample_linear(ts_us, values, grid_us, max_gap_s) -> np.ndarray:
    """Values (n,) or (n, k) interpolated linearly onto ``grid_us``; NaN outside the span and in gaps."""
    ts = np.asarray(ts_us, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    flat = v.reshape(v.shape[0], -1)
    out = np.empty((grid_us.shape[0], flat.shape[1]))
    for c in range(flat.shape[1]):
        out[:, c] = np.interp(grid_us, ts, flat[:, c])
    out[~_gap_mask(np.asarray(ts_us), grid_us, max_gap_s, hold=False)] = np.nan
    return out.reshape((grid_us.shape[0],) + v.shape[1:])


def resample_hold(ts_us, values, grid_us, max_gap_s) -> np.ndarray:
    """Values held from their last sample (commands, flags); NaN before the first and in gaps."""
    ts = np.asarray(ts_us, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    j = np.clip(np.searchsorted(ts, grid_us, side="right") - 1, 0, ts.size - 1)
    out = v[j].astype(np.float64)
    out[~_gap_mask(np.asarray(ts_us), grid_us, max_gap_s, hold=True)] = np.nan
    return out


def resample_quaternion(ts_us, q, grid_us, max_gap_s) -> np.ndarray:
    """Quaternions (n, 4) onto the grid: signs made continuous, linear interpolation, normalised."""
    q = np.array(q, dtype=np.float64)
    # q and -q are one rotation; flip so consecutive samples lie in one hemisphere
    dots = np.einsum("ij,ij->i", q[1:], q[:-1])
    sign = np.concatenate(([1.0], np.cumprod(np.where(dots < 0.0, -1.0, 1.0))))
    out = resample_linear(ts_us, q * sign[:, None], grid_us, max_gap_s)
    with np.errstate(invalid="ignore", divide="ignore"):  # a NaN (gap or bad sample) stays NaN, quietly
        return out / np.linalg.norm(out, axis=1, keepdims=True)


def rotation_matrices(q_WB: np.ndarray) -> np.ndarray:
    """``R_WB`` (n, 3, 3) of unit quaternions (n, 4) (:func:`vtoladapt.frames.quats_to_rotmats`)."""
    return quats_to_rotmats(q_WB)


# --- assembly ------------------------------------------------------------------------------------

def _fields(table: TopicTable, names, topic: str, source: str) -> np.ndarray:
    missing = [n for n in names if n not in table]
    if missing:
        raise ReplayError(f"{source}: topic {topic} has no field {missing[0]} (fields: "
                          f"{', '.join(sorted(table)[:12])}{', ...' if len(table) > 12 else ''})")
    return np.column_stack([np.asarray(table[n], dtype=np.float64) for n in names])


def _timestamps(table: TopicTable, topic: str, source: str) -> np.ndarray:
    if "timestamp" not in table:
        raise ReplayError(f"{source}: topic {topic} has no field timestamp")
    ts = np.asarray(table["timestamp"], dtype=np.float64)
    if ts.size == 0:
        raise ReplayError(f"{source}: topic {topic} has no samples")
    if np.any(np.diff(ts) < 0):
        raise ReplayError(f"{source}: topic {topic}: timestamp is not sorted (microseconds expected)")
    return ts


def _rate(ts: np.ndarray) -> float:
    dt = _median_dt_s(ts)
    return 1.0 / dt if np.isfinite(dt) and dt > 0 else 0.0


SPEED_MAX_MPS = 200.0
"""Largest inertial speed or airspeed a sample may read: no small UAS flies faster; a reading beyond
it (1e300) is a broken sample, set to NaN (unused), not a number to square."""
WIND_MAX_MPS = 100.0
"""Largest wind estimate taken; beyond it the estimate is unknown (zero), as where there is none."""
SPECIFIC_FORCE_MAX_MPS2 = 1000.0
"""Largest specific force a sample may read (about 100 g, beyond any flight IMU's range)."""


def _keep_rows(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``values`` with the rows that fail ``valid`` (or hold a non-finite value) set to NaN."""
    values = np.array(values, dtype=np.float64)
    finite = np.isfinite(values) if values.ndim == 1 else np.all(np.isfinite(values), axis=1)
    values[~(valid & finite)] = np.nan
    return values


def _require_some(values: np.ndarray, source: str, what: str, allowed: str) -> np.ndarray:
    if not np.any(np.all(np.isfinite(values), axis=-1) if values.ndim > 1 else np.isfinite(values)):
        raise ReplayError(f"{source}: no usable samples: {what} is never {allowed} (NaN, inf, text or out of "
                          "range in every row); allowed: a log whose required inputs hold such samples")
    return values


def _unit_quaternions(q: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        norm = np.linalg.norm(q, axis=1)
    return _keep_rows(q, np.abs(norm - 1.0) <= 0.1)


def _bounded(values: np.ndarray, limit: float) -> np.ndarray:
    with np.errstate(all="ignore"):
        return _keep_rows(values, np.linalg.norm(values.reshape(len(values), -1), axis=1) <= limit)


def no_usable_samples(log: "FlightLog", use_landed: bool) -> str:
    """Why no sample of ``log`` can be used (every input finite at once, and airborne unless
    ``use_landed``): the inputs never finite on the grid, named by their log columns, else the land
    detector, else that they are never finite at the same time."""
    inputs = {"attitude": log.q_WB, "inertial velocity": log.v_W_mps, "specific force": log.f_meas_B_mps2,
              "incident velocity": log.v_i_B_mps, "pusher u_x": log.throttle_x_pct,
              "lift collective u_z": log.throttle_z_pct}
    finite = {k: (np.all(np.isfinite(v), axis=1) if v.ndim > 1 else np.isfinite(v)) for k, v in inputs.items()}
    never = [k for k, ok in finite.items() if not ok.any()]
    if never:
        cols = "; ".join(f"{log.sources.get(k, k)}" for k in never)
        return f"{log.source}: no usable samples: {', '.join(never)} never finite on the resampled grid ({cols})"
    together = np.logical_and.reduce(list(finite.values()))
    if together.any() and not use_landed and not (together & ~log.landed).any():
        return (f"{log.source}: no usable samples: every sample with finite inputs is on the ground per "
                f"{log.sources.get('ground contact', LAND_DETECTED)}; add --use-landed to use them")
    return (f"{log.source}: no usable samples: the inputs ({', '.join(log.sources.get(k, k) for k in inputs)}) "
            "are never finite at the same time")


def _usable(table: TopicTable | None) -> bool:
    return table is not None and "timestamp" in table and len(table["timestamp"]) >= 2


def assemble_flight_log(tables: Mapping[TopicKey, TopicTable], source: str, log_format: str,
                        settings: ReadSettings = ReadSettings(),
                        parameters: Mapping[str, float] | None = None) -> FlightLog:
    """Build the :class:`FlightLog` from a log's topic tables (see the module notes).

    Parameters
    ----------
    tables : ``(topic, instance) -> TopicTable``
    source : the file or folder (named in errors and reports).
    log_format : ``'ulog'`` or ``'csv-folder'``.
    settings : ReadSettings
    parameters : the log's PX4 parameters (a ULog has them; a CSV folder does not).

    Raises
    ------
    ReplayError
        Naming the source, topic and field, if a required topic or field is missing or unusable.
    """
    params = dict(parameters or {})
    notes: list[LogNote] = []
    sources: dict[str, str] = {}
    used: dict[str, dict] = {}

    def get(topic, instance=0):
        t = tables.get((topic, instance))
        return t if _usable(t) else None

    def mark(topic, instance, ts):
        used[f"{topic}#{instance}"] = {"samples": int(ts.size), "rate_hz": round(_rate(ts), 2)}

    for topic in (ATTITUDE, LOCAL_POSITION):
        if get(topic) is None:
            have = sorted({k[0] for k in tables})
            raise ReplayError(f"{source}: required topic {topic} missing or with < 2 samples "
                              f"(topics found: {', '.join(have) if have else 'none'})")
    att = get(ATTITUDE)
    lp = get(LOCAL_POSITION)
    ts_att = _timestamps(att, ATTITUDE, source)
    ts_lp = _timestamps(lp, LOCAL_POSITION, source)
    # broken samples (NaN, inf, text, q = 0, 1e300 m/s) become NaN: unused, never squared or normalised
    q_raw = _require_some(_unit_quaternions(_fields(att, [f"q[{i}]" for i in range(4)], ATTITUDE, source)),
                          source, f"{ATTITUDE}.q[0..3]", "a unit quaternion")
    v_raw = _require_some(_bounded(_fields(lp, ["vx", "vy", "vz"], LOCAL_POSITION, source), SPEED_MAX_MPS),
                          source, f"{LOCAL_POSITION}.vx, vy, vz", f"a finite velocity within {SPEED_MAX_MPS:g} m/s")
    sc = get(SENSOR_COMBINED)
    accel_names = [f"accelerometer_m_s2[{i}]" for i in range(3)]
    use_imu = sc is not None and all(n in sc for n in accel_names)
    ts_sc = _timestamps(sc, SENSOR_COMBINED, source) if use_imu else None

    # the grid: where every required topic has data, at the fastest required rate (<= 250 Hz)
    required = [ts_att, ts_lp] + ([ts_sc] if use_imu else [])
    t_start = max(ts[0] for ts in required)
    t_end = min(ts[-1] for ts in required)
    if not t_end > t_start:
        raise ReplayError(f"{source}: topics {ATTITUDE}, {LOCAL_POSITION}"
                          f"{', ' + SENSOR_COMBINED if use_imu else ''} do not overlap in time")
    rate = settings.rate_hz or min(250.0, max(_rate(ts_att), _rate(ts_sc) if use_imu else 0.0, _rate(ts_lp)))
    n = int(np.floor((t_end - t_start) * 1e-6 * rate)) + 1
    if n < 2:
        raise ReplayError(f"{source}: the topics overlap for {(t_end - t_start) * 1e-6:.3g} s, "
                          f"less than two samples at {rate:g} Hz")
    grid = t_start + np.arange(n) * (1e6 / rate)
    gap = settings.max_gap_s
    mark(ATTITUDE, 0, ts_att)
    mark(LOCAL_POSITION, 0, ts_lp)

    q = resample_quaternion(ts_att, q_raw, grid, gap)
    R = rotation_matrices(np.where(np.isnan(q), 0.0, q))
    R[np.isnan(q[:, 0])] = np.nan
    v_W = resample_linear(ts_lp, v_raw, grid, gap)
    sources["attitude"] = f"{ATTITUDE}.q[0..3]"
    sources["inertial velocity"] = f"{LOCAL_POSITION}.vx, vy, vz"

    # measured specific force, body
    if use_imu:
        mark(SENSOR_COMBINED, 0, ts_sc)
        f_raw = _require_some(_bounded(_fields(sc, accel_names, SENSOR_COMBINED, source), SPECIFIC_FORCE_MAX_MPS2),
                              source, f"{SENSOR_COMBINED}.accelerometer_m_s2[0..2]",
                              f"a finite specific force within {SPECIFIC_FORCE_MAX_MPS2:g} m/s^2")
        f_B = resample_linear(ts_sc, f_raw, grid, gap)
        sources["specific force"] = f"{SENSOR_COMBINED}.accelerometer_m_s2[0..2] (body FRD)"
    else:
        if all(k in lp for k in ("ax", "ay", "az")):
            a_raw = _bounded(_fields(lp, ["ax", "ay", "az"], LOCAL_POSITION, source), SPECIFIC_FORCE_MAX_MPS2)
            how = f"{LOCAL_POSITION}.ax, ay, az (PX4's NED velocity derivative)"
        else:
            tsec = ts_lp * 1e-6
            a_raw = np.column_stack([np.gradient(v_raw[:, i], tsec) for i in range(3)])
            how = f"the central difference of {LOCAL_POSITION}.vx, vy, vz"
        a_W = resample_linear(ts_lp, a_raw, grid, gap)
        with np.errstate(invalid="ignore"):  # NaN where the attitude or velocity is: unused samples
            f_B = np.einsum("nji,nj->ni", R, a_W - np.array([0.0, 0.0, GRAVITY_MPS2]))
        sources["specific force"] = f"R^T (a_W - g_W) from {how}"
        notes.append(LogNote("specific force", f"no accelerometer ({SENSOR_COMBINED} absent)",
                             f"R^T (a_W - g_W) with a_W from {how}, at {_rate(ts_lp):.3g} Hz"))

    # wind estimate (north, east; vertical zero)
    wind = np.zeros((n, 3))
    wind_topic = next((t for t in WIND_TOPICS if get(t) is not None
                       and {"windspeed_north", "windspeed_east"} <= set(get(t))), None)
    if wind_topic is None:
        sources["wind"] = "none (zero)"
        notes.append(LogNote("wind", "no wind estimate (wind_estimate / airspeed_wind)",
                             "zero wind: the flow direction is the inertial velocity's"))
    else:
        tw = get(wind_topic)
        ts_w = _timestamps(tw, wind_topic, source)
        mark(wind_topic, 0, ts_w)
        wne = resample_hold(ts_w, _bounded(_fields(tw, ["windspeed_north", "windspeed_east"], wind_topic, source),
                                           WIND_MAX_MPS), grid, gap)
        # before the first estimate or in its gaps the wind is unknown: zero, said below
        wind[:, :2] = np.nan_to_num(wne, nan=0.0)
        sources["wind"] = f"{wind_topic}.windspeed_north, windspeed_east (held); vertical zero"
        if np.all(wind[:, :2] == 0.0):
            notes.append(LogNote("wind", f"{wind_topic} is zero throughout (the estimator did not run)",
                                 "zero wind"))

    # pitot airspeed: the faster of airspeed_validated and airspeed
    cands = [(t, get(t)) for t in AIRSPEED_TOPICS if get(t) is not None and "true_airspeed_m_s" in get(t)]
    tas = np.full(n, np.nan)
    if not cands:
        sources["airspeed"] = "none"
        notes.append(LogNote("airspeed", "no airspeed sensor (airspeed / airspeed_validated)",
                             "|v_i| from the inertial velocity minus the wind"))
    else:
        topic, ta = max(cands, key=lambda c: _rate(_timestamps(c[1], c[0], source)))
        ts_a = _timestamps(ta, topic, source)
        mark(topic, 0, ts_a)
        tas = resample_linear(ts_a, _bounded(np.asarray(ta["true_airspeed_m_s"], dtype=np.float64)[:, None],
                                             SPEED_MAX_MPS)[:, 0], grid, gap)
        if "airspeed_sensor_measurement_valid" in ta:
            ok = resample_hold(ts_a, np.asarray(ta["airspeed_sensor_measurement_valid"], float), grid, gap)
            tas[~(ok == 1.0)] = np.nan
        low = tas < settings.airspeed_min_mps
        n_low = int(np.count_nonzero(low))
        tas[low] = np.nan
        sources["airspeed"] = f"{topic}.true_airspeed_m_s (pitot, {_rate(ts_a):.3g} Hz)"
        notes.append(LogNote("angle of attack and sideslip",
                             f"only a pitot ({topic}.true_airspeed_m_s): no angle of attack or sideslip",
                             "flow direction from R^T (v_W - wind), magnitude from the pitot"))
        if n_low:
            notes.append(LogNote("airspeed at low speed",
                                 f"{100.0 * n_low / n:.0f} % of samples read below "
                                 f"{settings.airspeed_min_mps:g} m/s (zero offset; min "
                                 f"{np.nanmin(np.asarray(ta['true_airspeed_m_s'], float)):.2f} m/s)",
                                 "treated as invalid: v_i = R^T (v_W - wind) there"))

    v_rel_B = np.einsum("nji,nj->ni", R, v_W - wind)
    speed_rel = np.linalg.norm(v_rel_B, axis=1)
    from_pitot = np.isfinite(tas) & np.isfinite(speed_rel)
    direction = np.where((speed_rel > 0.5)[:, None], v_rel_B / np.maximum(speed_rel, 1e-12)[:, None],
                         np.array([1.0, 0.0, 0.0]))
    v_i = np.where(from_pitot[:, None], tas[:, None] * direction, v_rel_B)

    # throttles
    status = get(VEHICLE_STATUS)
    fixed_wing = False
    if status is not None and "vehicle_type" in status:
        vt = np.asarray(status["vehicle_type"], dtype=float)
        is_vtol = np.asarray(status.get("is_vtol", np.zeros_like(vt)), dtype=float)
        fixed_wing = bool(np.all(vt == PX4_VEHICLE_TYPE_FIXED_WING) and not np.any(is_vtol == 1))
        mark(VEHICLE_STATUS, 0, _timestamps(status, VEHICLE_STATUS, source))
    lift = settings.lift_throttle or (ThrottleSource("", ()) if fixed_wing else ThrottleSource("actuator_controls_0", (3,)))
    pusher = settings.pusher_throttle or ThrottleSource("actuator_controls_0" if fixed_wing else "actuator_controls_1", (3,))
    pwm = settings.pwm_range_us
    if pwm is None:
        lo, hi = params.get("PWM_MIN"), params.get("PWM_MAX")
        pwm = (float(lo), float(hi)) if lo is not None and hi is not None and 0 <= lo < hi else (1000.0, 2000.0)
    u_pct = {}
    for key, label, src in (("z", "lift collective u_z", lift), ("x", "pusher u_x", pusher)):
        if not src.topic:
            u_pct[key] = np.zeros(n)
            sources[label] = "none (zero)"
            what = "no lift rotors (a fixed-wing: vehicle_status.vehicle_type = 2)" if fixed_wing and key == "z" \
                else "no channel given for it"
            notes.append(LogNote(label, what, "set to 0 %"))
            continue
        tab = get(src.topic)
        if tab is None:
            u_pct[key] = np.zeros(n)
            sources[label] = f"{src.describe()} (absent: zero)"
            notes.append(LogNote(label, f"topic {src.topic} not in the log", "set to 0 %"))
            continue
        ts_u = _timestamps(tab, src.topic, source)
        mark(src.topic, 0, ts_u)
        raw = _fields(tab, src.fields(), src.topic, source)
        frac = (raw - pwm[0]) / (pwm[1] - pwm[0]) if src.is_pwm else raw
        # RMS over the motors: the model's collective thrust is C_T u^2 summed over the rotors
        u = np.sqrt(np.mean(np.clip(frac, 0.0, 1.0) ** 2, axis=1))
        u_pct[key] = 100.0 * resample_hold(ts_u, u, grid, gap)
        scale = f"PWM {pwm[0]:g}..{pwm[1]:g} us -> 0..100 %" if src.is_pwm else "0..1 -> 0..100 %"
        sources[label] = f"{src.describe()} ({scale}{', RMS over motors' if len(src.indices) > 1 else ''})"
        if np.ptp(u) == 0.0:
            notes.append(LogNote(label, f"{src.describe()} is constant at {100 * u[0]:g} % for the whole log "
                                 "(the command looks unrecorded)", f"used as is ({100 * u[0]:g} %)"))

    # ground contact
    landed = np.zeros(n, dtype=bool)
    ld = get(LAND_DETECTED)
    if ld is not None and "landed" in ld:
        ts_ld = _timestamps(ld, LAND_DETECTED, source)
        mark(LAND_DETECTED, 0, ts_ld)
        # the detector publishes on change (and at ~1 Hz): hold without a gap limit
        held = resample_hold(ts_ld, np.asarray(ld["landed"], float), grid, np.inf)
        landed = held == 1.0
        sources["ground contact"] = f"{LAND_DETECTED}.landed"
    else:
        sources["ground contact"] = "none (every sample taken as airborne)"
        notes.append(LogNote("ground contact", "no land detector (vehicle_land_detected)",
                             "every sample is taken as airborne"))

    return FlightLog(source=source, log_format=log_format, rate_hz=float(rate), t0_us=int(round(t_start)),
                     t_s=(grid - t_start) * 1e-6, q_WB=q, v_W_mps=v_W, wind_W_mps=wind,
                     airspeed_pitot_mps=tas, v_i_B_mps=v_i, v_i_from_pitot=from_pitot, f_meas_B_mps2=f_B,
                     throttle_x_pct=u_pct["x"], throttle_z_pct=u_pct["z"], landed=landed,
                     topics=used, notes=tuple(notes), sources=sources)


__all__ = ["FlightLog", "KNOWN_TOPICS", "LogNote", "ReadSettings", "ReplayError", "ThrottleSource",
           "TopicTable", "assemble_flight_log", "no_usable_samples", "parse_throttle_source", "resample_hold",
           "resample_linear", "resample_quaternion", "rotation_matrices"]
