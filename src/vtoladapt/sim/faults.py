"""Faults injected into the closed loop from a scenario's ``[[faults]]`` schedule.

Each entry names a fault ``kind``, a start ``start_s`` and an end ``end_s`` (the fault is active for
``start_s <= t < end_s``) and, where it applies, a motor or a magnitude. Two compiled steps apply
them every tick (:mod:`vtoladapt.sim.loop`):

* :func:`apply_measurement_faults`, between the sensors and the controller, on the measurement
  array (the controller sees the faulty reading; the log's ``meas_*`` columns record it);
* :func:`apply_actuator_faults`, between the allocator and the plant, on the plant input: the
  actuator commands (the log's ``motor*_cmd_frac`` and ``surface*_cmd_rad`` columns record what reached
  the actuators) and the actuators' condition (a surface's loss, a servo's slowdown), which it writes
  whole every tick (healthy unless a fault says otherwise).

Kinds (:data:`FAULT_KINDS`)::

    probe_dropout          airflow probe reads NaN and flags itself invalid.
    probe_stuck            probe repeats the reading (and validity) it had when the fault began.
    probe_nan              probe reads NaN but still flags itself valid (a corrupt frame).
    probe_blocked_port     one pressure port blocked (port = "alpha" or "beta"): that port pair's
                           differential pressure reads zero, so the calibration infers a zero flow
                           angle. Modelled on the incident velocity for either probe model: the body-z
                           (alpha) or body-y (beta) component is folded into body-x, keeping the speed.
                           This is the first-order effect of the pressure fault, not the pressure
                           model's own port-level simulation.
    imu_spike              gyro x reads spike_gyro_radps more and accelerometer z spike_accel_mps2
                           more (a vibration or EMI burst).
    imu_nan                gyro and accelerometer read NaN.
    mocap_dropout          motion-capture position and velocity read NaN (tracking lost).
    mocap_latency          motion capture arrives extra_latency_s later (a latency jump; up to
                           LATENCY_RING_TICKS - 1 ticks).
    lift_motor_loss        lift motor motor (1-4) gives thrust_loss_fraction less thrust at any
                           command (thrust ~ u^2, so its command is scaled by sqrt(1 - loss)).
    pusher_saturated       the pusher runs at full throttle (the throttle limit) whatever is commanded.
    stuck_throttle         motor motor (1-4 lift, 5 pusher) holds the command it had at the start.
    surface_stuck          control surface surface (1-4, the vehicle file's order) jams: its servo holds
                           the deflection commanded when the fault began, whatever is commanded after.
    surface_lost           control surface surface is gone (its servo still moves; the surface makes no
                           force or moment).
    servo_slow             the servo of surface surface is time_constant_factor times slower than the
                           plant's (time constant times it, rate limit divided by it): slower than the
                           flight computer believes.

The flight computer is not told of any actuator fault: the allocator keeps its model (a real one would
have to detect it first).

Every entry is validated like every other table (one-line errors naming the file, the entry and
the key).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
from numba import njit

from ..config import ApplicableKeys, ConfigError, Validated, setting
from ..layout import (ACT_SURFACE, IN_SERVO_SLOWDOWN, IN_SURFACE_LOSS, MEAS_ACCEL_B, MEAS_OMEGA_B, MEAS_P_W,
                     MEAS_SIZE, MEAS_V_I_B, MEAS_V_I_VALID, MEAS_V_W, MOTOR_PUSHER, N_MOTORS, N_SURFACES,
                     PLANT_INPUT_SIZE,
                     BlockLayout, Field)

FAULT_KINDS: tuple[str, ...] = (
    "probe_dropout", "probe_stuck", "probe_nan", "probe_blocked_port", "imu_spike", "imu_nan",
    "mocap_dropout", "mocap_latency", "lift_motor_loss", "pusher_saturated", "stuck_throttle", "surface_stuck",
    "surface_lost", "servo_slow")
(K_PROBE_DROPOUT, K_PROBE_STUCK, K_PROBE_NAN, K_PROBE_BLOCKED, K_IMU_SPIKE, K_IMU_NAN, K_MOCAP_DROPOUT,
 K_MOCAP_LATENCY, K_LIFT_LOSS, K_PUSHER_SAT, K_STUCK_THROTTLE, K_SURFACE_STUCK, K_SURFACE_LOST,
 K_SERVO_SLOW) = (FAULT_KINDS.index(k) for k in (
    "probe_dropout", "probe_stuck", "probe_nan", "probe_blocked_port", "imu_spike", "imu_nan", "mocap_dropout",
    "mocap_latency", "lift_motor_loss", "pusher_saturated", "stuck_throttle", "surface_stuck", "surface_lost",
    "servo_slow"))
"""The kinds' codes in a schedule row (what :meth:`FaultConfig.to_row` packs); the actuator kinds come
last, from ``K_LIFT_LOSS`` on."""
ACTUATOR_KINDS = ("lift_motor_loss", "pusher_saturated", "stuck_throttle", "surface_stuck", "surface_lost",
                  "servo_slow")
SURFACE_KINDS = ("surface_stuck", "surface_lost", "servo_slow")
_KIND_KEYS: dict[str, tuple[str, ...]] = {
    "probe_blocked_port": ("port",), "imu_spike": ("spike_gyro_radps", "spike_accel_mps2"),
    "mocap_latency": ("extra_latency_s",), "lift_motor_loss": ("motor", "thrust_loss_fraction"),
    "stuck_throttle": ("motor",), "surface_stuck": ("surface",), "surface_lost": ("surface",),
    "servo_slow": ("surface", "time_constant_factor")}
"""The keys beyond ``kind``, ``start_s``, ``end_s`` that each kind uses (the others use none)."""
MAX_FAULTS = 30
"""Entries in one schedule at most (the log's ``faults_active`` column is a bit mask of them)."""
LATENCY_RING_TICKS = 128

FAULT_ROW = BlockLayout("fault schedule row", [
    Field("KIND", 1, "-", "index into FAULT_KINDS"),
    Field("START", 1, "s", "first time the fault is active"),
    Field("END", 1, "s", "first time it is not any more"),
    Field("MOTOR", 1, "-", "motor index, 0-based (lift 0-3, pusher 4)"),
    Field("LOSS", 1, "-", "thrust loss fraction"),
    Field("SPIKE_GYRO", 1, "rad/s", "gyro spike"),
    Field("SPIKE_ACCEL", 1, "m/s^2", "accelerometer spike"),
    Field("EXTRA_DELAY", 1, "s", "added motion-capture latency"),
    Field("PORT", 1, "-", "0: alpha port pair, 1: beta"),
    Field("SURFACE", 1, "-", "control-surface index, 0-based"),
    Field("TAU_FACTOR", 1, "-", "servo time-constant factor (servo_slow)"),
])
(_F_KIND, _F_START, _F_END, _F_MOTOR, _F_LOSS, _F_SPIKE_GYRO, _F_SPIKE_ACCEL, _F_EXTRA_DELAY,
 _F_PORT, _F_SURFACE, _F_TAU_FACTOR) = FAULT_ROW.offsets(*(f.name for f in FAULT_ROW.fields))
FAULT_ROW_SIZE = FAULT_ROW.size

RING_ENTRY = BlockLayout("fault latency ring entry", [
    Field("P_W", 3, "m", "measured motion-capture position, NED"),
    Field("V_W", 3, "m/s", "measured motion-capture velocity, NED"),
])
"""One tick of what the motion capture delivered, for a ``mocap_latency`` fault."""
_R_P, _R_V = RING_ENTRY.offsets("P_W", "V_W")
_RING_STRIDE = RING_ENTRY.size

HOLD_ENTRY = BlockLayout("fault hold slots of one schedule entry", [
    Field("ACTIVE", 1, "-", "1.0 if the entry was active last tick (a fault begins when it turns on)"),
    Field("HELD", 4, "-", "values held from the tick the fault began: a probe's reading and validity, a motor command"),
])
"""Per schedule entry: what a fault that holds a value keeps."""
_H_ACTIVE, _H_HELD = HOLD_ENTRY.offsets("ACTIVE", "HELD")
_HOLD_STRIDE = HOLD_ENTRY.size
PROBE_HELD = BlockLayout("held probe reading (probe_stuck), in HELD", [
    Field("V_I_B", 3, "m/s", "the incident velocity read when the fault began, body"),
    Field("VALID", 1, "-", "its validity flag"),
])
_PH_V_I_B, _PH_VALID = HOLD_ENTRY.nested("HELD", PROBE_HELD, "V_I_B", "VALID")

FAULT_STATE = BlockLayout("fault state", [
    Field("RING_HEAD", 1, "-", "latency ring slot written this tick"),
    Field("RING_COUNT", 1, "-", "ticks written into the ring so far (saturates at its size)"),
    Field("RING", RING_ENTRY.size * LATENCY_RING_TICKS, "m, m/s", "LATENCY_RING_TICKS entries of RING_ENTRY"),
    Field("HOLD", HOLD_ENTRY.size * MAX_FAULTS, "-", "MAX_FAULTS entries of HOLD_ENTRY"),
])
_S_HEAD, _S_COUNT, _S_RING, _S_HOLD = FAULT_STATE.offsets("RING_HEAD", "RING_COUNT", "RING", "HOLD")
_FAULT_STATE_SIZE = FAULT_STATE.size


@dataclass(frozen=True)
class FaultConfig(Validated):
    """One entry of the ``[[faults]]`` schedule (see the module docstring for the kinds)."""

    config_section = "faults"

    kind: str = setting("-", "what fails", choices=FAULT_KINDS)
    start_s: float = setting("s", "fault active from this time", ge=0.0, le=3600.0)
    end_s: float = setting("s", "until this time (exclusive)", gt=0.0, le=3600.0)
    motor: int = setting("-", "motor for lift_motor_loss (1-4) and stuck_throttle (1-4 lift, 5 pusher)",
                         default=1, ge=1, le=5)
    thrust_loss_fraction: float = setting("-", "thrust lost by the motor (lift_motor_loss)", default=0.3,
                                          ge=0.0, le=1.0)
    spike_gyro_radps: float = setting("rad/s", "added to gyro x (imu_spike)", default=5.0, ge=-100.0, le=100.0)
    spike_accel_mps2: float = setting("m/s^2", "added to accelerometer z (imu_spike)", default=30.0,
                                      ge=-500.0, le=500.0)
    extra_latency_s: float = setting("s", "added motion-capture delay (mocap_latency), whole ticks",
                                     default=0.1, ge=0.0, le=0.5)
    port: str = setting("-", "blocked port pair (probe_blocked_port)", default="alpha", choices=("alpha", "beta"))
    surface: int = setting("-", "control surface (surface_stuck, surface_lost, servo_slow): 1 to 4, the vehicle "
                           "file's [[surfaces]] order", default=1, ge=1, le=N_SURFACES)
    time_constant_factor: float = setting("-", "how many times slower the servo is (servo_slow)", default=3.0,
                                          ge=1.0, le=100.0)

    @staticmethod
    def keys_for(data) -> "Optional[ApplicableKeys]":
        """The keys an entry of this ``kind`` uses (:func:`vtoladapt.config.build` refuses the
        others: a ``motor`` on a probe fault would be silently ignored); ``None`` for an unknown kind,
        which the kind's own check reports."""
        kind = data.get("kind")
        if not isinstance(kind, str) or kind not in FAULT_KINDS:
            return None
        return ApplicableKeys(("kind", "start_s", "end_s") + _KIND_KEYS.get(kind, ()), f"kind = {kind!r}")

    def _check(self, source: str) -> None:
        if not self.end_s > self.start_s:
            raise ConfigError(f"{source}: [faults] {self.kind}: end_s = {self.end_s:g}: must be after "
                              f"start_s = {self.start_s:g}")
        if self.kind == "lift_motor_loss" and self.motor > 4:
            raise ConfigError(f"{source}: [faults] lift_motor_loss: motor = {self.motor}: lift motors are 1-4")

    def to_row(self, dt_s: float) -> np.ndarray:
        """This entry as one kernel row (:data:`FAULT_ROW`)."""
        if not (isinstance(self.motor, int) and 1 <= self.motor <= N_MOTORS):  # the kernel indexes with it
            raise ConfigError(f"[faults] {self.kind}: motor = {self.motor!r}: allowed: 1 to {N_MOTORS}")
        if self.kind == "mocap_latency" and round(self.extra_latency_s / dt_s) >= LATENCY_RING_TICKS:
            raise ConfigError(f"[faults] mocap_latency: extra_latency_s = {self.extra_latency_s:g}: at most "
                              f"{(LATENCY_RING_TICKS - 1) * dt_s:g} s at this controller rate")
        return FAULT_ROW.pack(KIND=FAULT_KINDS.index(self.kind), START=self.start_s, END=self.end_s,
                              MOTOR=self.motor - 1, LOSS=self.thrust_loss_fraction,
                              SPIKE_GYRO=self.spike_gyro_radps, SPIKE_ACCEL=self.spike_accel_mps2,
                              EXTRA_DELAY=round(self.extra_latency_s / dt_s) * dt_s,
                              PORT=0.0 if self.port == "alpha" else 1.0, SURFACE=self.surface - 1,
                              TAU_FACTOR=self.time_constant_factor)


def faults_to_kernel(faults: tuple[FaultConfig, ...], dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``(schedule, state)``: the ``(n, FAULT_ROW_SIZE)`` schedule and a fresh fault state."""
    if len(faults) > MAX_FAULTS:
        raise ConfigError(f"[faults]: {len(faults)} entries: at most {MAX_FAULTS}")
    rows = np.zeros((len(faults), FAULT_ROW_SIZE))
    for i, f in enumerate(faults):
        rows[i] = f.to_row(dt_s)
    return rows, np.zeros(FAULT_STATE.size)


@njit(cache=True, nogil=True, inline="always")
def _active(faults, i, t) -> bool:
    return faults[i, _F_START] <= t < faults[i, _F_END]


@njit(cache=True, nogil=True, _nrt=False)
def active_mask(faults, t) -> float:
    """Bit ``i`` set when schedule entry ``i`` is active at ``t`` (the log's ``faults_active``)."""
    m = 0
    for i in range(faults.shape[0]):
        if _active(faults, i, t):
            m += 1 << i
    return float(m)


@njit(cache=True, nogil=True, _nrt=False)
def apply_measurement_faults(faults, fstate, t, dt, meas) -> None:
    """Apply the active sensor faults of the schedule to ``meas`` in place (sensors -> controller).

    ``meas`` must be a whole measurement and ``fstate`` a whole fault state (``ValueError`` otherwise: a
    shorter array would be written past its end, as :func:`apply_actuator_faults` explains)."""
    if meas.shape[0] < MEAS_SIZE or fstate.shape[0] < _FAULT_STATE_SIZE:
        raise ValueError("apply_measurement_faults: meas or fstate shorter than a measurement / fault state")
    n = min(faults.shape[0], MAX_FAULTS)  # the hold state has room for MAX_FAULTS entries
    if n == 0:
        return
    # the latency ring holds what the motion capture delivered, before any fault of this tick
    head = int(fstate[_S_HEAD])
    o = _S_RING + _RING_STRIDE * head
    for j in range(3):
        fstate[o + _R_P + j] = meas[MEAS_P_W + j]
        fstate[o + _R_V + j] = meas[MEAS_V_W + j]
    count = min(fstate[_S_COUNT] + 1.0, float(LATENCY_RING_TICKS))
    fstate[_S_COUNT] = count
    fstate[_S_HEAD] = float((head + 1) % LATENCY_RING_TICKS)
    nan = np.nan
    for i in range(n):
        kind = int(faults[i, _F_KIND])
        if kind >= K_LIFT_LOSS:
            continue  # actuator faults: apply_actuator_faults
        h = _S_HOLD + _HOLD_STRIDE * i
        on = _active(faults, i, t)
        began = on and fstate[h + _H_ACTIVE] == 0.0
        fstate[h + _H_ACTIVE] = 1.0 if on else 0.0
        if not on:
            continue
        if kind == K_PROBE_DROPOUT:
            for j in range(3):
                meas[MEAS_V_I_B + j] = nan
            meas[MEAS_V_I_VALID] = 0.0
        elif kind == K_PROBE_STUCK:
            if began:
                for j in range(3):
                    fstate[h + _PH_V_I_B + j] = meas[MEAS_V_I_B + j]
                fstate[h + _PH_VALID] = meas[MEAS_V_I_VALID]
            for j in range(3):
                meas[MEAS_V_I_B + j] = fstate[h + _PH_V_I_B + j]
            meas[MEAS_V_I_VALID] = fstate[h + _PH_VALID]
        elif kind == K_PROBE_NAN:
            for j in range(3):
                meas[MEAS_V_I_B + j] = nan
        elif kind == K_PROBE_BLOCKED:
            c = MEAS_V_I_B + (2 if faults[i, _F_PORT] == 0.0 else 1)
            vx = meas[MEAS_V_I_B]
            s = np.sqrt(vx * vx + meas[c] * meas[c])
            meas[MEAS_V_I_B] = s if vx >= 0.0 else -s
            meas[c] = 0.0
        elif kind == K_IMU_SPIKE:
            meas[MEAS_OMEGA_B] += faults[i, _F_SPIKE_GYRO]
            meas[MEAS_ACCEL_B + 2] += faults[i, _F_SPIKE_ACCEL]
        elif kind == K_IMU_NAN:
            for j in range(3):
                meas[MEAS_OMEGA_B + j] = nan
                meas[MEAS_ACCEL_B + j] = nan
        elif kind == K_MOCAP_DROPOUT:
            for j in range(3):
                meas[MEAS_P_W + j] = nan
                meas[MEAS_V_W + j] = nan
        elif kind == K_MOCAP_LATENCY:
            d = min(int(round(faults[i, _F_EXTRA_DELAY] / dt)), int(count) - 1)
            o = _S_RING + _RING_STRIDE * ((head - d) % LATENCY_RING_TICKS)
            for j in range(3):
                meas[MEAS_P_W + j] = fstate[o + _R_P + j]
                meas[MEAS_V_W + j] = fstate[o + _R_V + j]


@njit(cache=True, nogil=True, _nrt=False)
def apply_actuator_faults(faults, fstate, t, u_max, u_in) -> None:
    """Apply the active actuator faults to the plant input ``u_in`` in place (allocator -> plant): the
    actuator commands, and the actuators' condition, reset to healthy first (:data:`vtoladapt.layout.PLANT_INPUT`).

    ``u_in`` must be a whole plant input and ``fstate`` a whole fault state: a shorter array is refused
    (``ValueError``), since the condition rows are written every tick. Without this check a caller passing
    the motor commands alone had the kernel write past them into the process's heap, which glibc found
    minutes later as a corrupted heap and aborted (issue #32's abort: tests/test_reliability_api.py did so)."""
    if u_in.shape[0] < PLANT_INPUT_SIZE or fstate.shape[0] < _FAULT_STATE_SIZE:
        raise ValueError("apply_actuator_faults: u_in or fstate shorter than a plant input / fault state")
    for j in range(N_SURFACES):
        u_in[IN_SURFACE_LOSS + j] = 0.0
        u_in[IN_SERVO_SLOWDOWN + j] = 0.0
    for i in range(min(faults.shape[0], MAX_FAULTS)):
        kind = int(faults[i, _F_KIND])
        if kind < K_LIFT_LOSS:
            continue
        h = _S_HOLD + _HOLD_STRIDE * i
        on = _active(faults, i, t)
        began = on and fstate[h + _H_ACTIVE] == 0.0
        fstate[h + _H_ACTIVE] = 1.0 if on else 0.0
        if not on:
            continue
        if kind >= K_SURFACE_STUCK:
            sf = int(faults[i, _F_SURFACE])
            if sf < 0 or sf >= N_SURFACES:  # a schedule not made by faults_to_kernel: never write outside
                continue
            if kind == K_SURFACE_STUCK:
                if began:
                    fstate[h + _H_HELD] = u_in[ACT_SURFACE + sf]
                u_in[ACT_SURFACE + sf] = fstate[h + _H_HELD]
            elif kind == K_SURFACE_LOST:
                u_in[IN_SURFACE_LOSS + sf] = 1.0
            elif kind == K_SERVO_SLOW:
                u_in[IN_SERVO_SLOWDOWN + sf] = faults[i, _F_TAU_FACTOR] - 1.0
            continue
        m = int(faults[i, _F_MOTOR])
        if m < 0 or m >= N_MOTORS:  # a schedule not made by faults_to_kernel: never write outside the commands
            continue
        if kind == K_LIFT_LOSS:
            u_in[m] *= np.sqrt(1.0 - faults[i, _F_LOSS])
        elif kind == K_PUSHER_SAT:
            u_in[MOTOR_PUSHER] = u_max
        elif kind == K_STUCK_THROTTLE:
            if began:
                fstate[h + _H_HELD] = u_in[m]
            u_in[m] = fstate[h + _H_HELD]


RECOVERED_POSITION_ERROR_M = 0.3
"""A faulted run counts as recovered when its position error over its last 2 s stays below this."""


def fault_table(results) -> list[dict]:
    """One row per faulted run, for the report's fault table.

    ``results``: :class:`~vtoladapt.sim.results.SimulationResult` objects of scenarios with a
    ``[[faults]]`` schedule (their metadata holds it). Each row: ``scenario``, ``faults`` (kinds),
    ``window_s`` (first start, last end), ``pos_err_before_m`` (worst before the first fault),
    ``pos_err_worst_m`` (worst from the first fault on), ``pos_err_final_m`` (worst over the last
    2 s), ``recovered`` (final error below :data:`RECOVERED_POSITION_ERROR_M` and no divergence),
    ``saturated_during_fault`` (share of the fault window with a saturated mixer: the limit
    physics hit) and ``diverged`` (the divergence reason, or "").
    """
    rows = []
    for res in results:
        faults = res.metadata.get("faults") or []
        if not faults:
            continue
        t = res.time_s
        start = min(f["start_s"] for f in faults)
        end = max(f["end_s"] for f in faults)
        pe = np.linalg.norm(res.position_error_W, axis=1)
        before = pe[t < start]
        after = pe[t >= start]
        final = pe[t >= t[-1] - 2.0] if len(t) else pe
        window = (t >= start) & (t < end)
        sat = res["mixer_saturated"][window]
        rows.append({
            "scenario": res.metadata.get("scenario", ""),
            "faults": ", ".join(f["kind"] for f in faults),
            "window_s": (start, end),
            "pos_err_before_m": float(before.max()) if before.size else float("nan"),
            "pos_err_worst_m": float(after.max()) if after.size else float("nan"),
            "pos_err_final_m": float(final.max()) if final.size else float("nan"),
            "recovered": bool(not res.diverged and final.size and final.max() < RECOVERED_POSITION_ERROR_M),
            "saturated_during_fault": float(sat.mean()) if sat.size else float("nan"),
            "diverged": res.divergence_reason or "",
        })
    return rows
