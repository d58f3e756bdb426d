"""Observation and action of ``vtoladapt/Hold-v0``: one table each, with units and bounds.

These tuples are the only place the layouts are written down: the kernel's offsets, the
Gymnasium ``Box`` bounds and the README's tables all come from them.

Observation (float32): what the flight computer sees, never the truth. Position error and
velocity come from motion capture, attitude and body rates from the attitude estimate and the
gyro, the incident velocity from the airflow probe (with its validity flag); all are sampled at the
start of the tick the action will act over. ``cmd_base`` is the command the action modifies: in
residual mode the command the scenario's controller (composite in ``gym_hold``) computed for this tick, otherwise the command applied
over the previous tick, both in action units. Values beyond a bound are clipped to it.

Action (float32, in [-1, 1]): the controller command of :mod:`vtoladapt.layout` (``u_x``, ``u_z``
throttle fractions and the body moment ``tau_B``, FRD, N m), held for one controller tick. In
direct mode ``u = (a + 1) / 2 * u_max`` and ``tau = a * tau_max``; in residual mode
``u = u_ctrl + a * residual_scale * u_max`` and ``tau = tau_ctrl + a * residual_scale * tau_max``,
clipped to ``[0, u_max]`` and ``[-tau_max, tau_max]``. ``u_max`` (vehicle's throttle limit) and
``tau_max`` (per axis) are the controller's own limits for the vehicle. An action outside
``[-1, 1]`` is clipped to it (as the action space's bound, in both modes, before the reward's
action cost); a non-finite one is refused.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from ..layout import BlockLayout, Field


@dataclass(frozen=True)
class SpaceField:
    """``size`` consecutive entries of a space: name, unit, bounds and meaning."""

    name: str
    size: int
    unit: str
    low: float
    high: float
    doc: str


OBSERVATION_FIELDS: tuple[SpaceField, ...] = (
    SpaceField("p_err_W", 3, "m", -10.0, 10.0, "measured position minus reference, NED"),
    SpaceField("v_W", 3, "m/s", -30.0, 30.0, "measured velocity, NED"),
    SpaceField("q_WB", 4, "-", -1.0, 1.0, "attitude estimate, quaternion body FRD to NED, scalar first"),
    SpaceField("omega_B", 3, "rad/s", -35.0, 35.0, "gyro body rates, FRD (the gyro's range)"),
    SpaceField("v_i_B", 3, "m/s", -50.0, 50.0, "incident velocity from the airflow probe, body FRD"),
    SpaceField("v_i_valid", 1, "-", 0.0, 1.0, "1 if the probe reading is valid, else 0"),
    SpaceField("cmd_base", 5, "action units", -1.0, 1.0,
               "residual mode: the scenario's controller's command for this tick; direct mode: "
               "the command applied over the previous tick (u_x, u_z, tau_x, tau_y, tau_z)"),
)

ACTION_FIELDS: tuple[SpaceField, ...] = (
    SpaceField("u_x", 1, "-", -1.0, 1.0, "pusher throttle: direct u_x = (a+1)/2 u_max; residual "
               "a * residual_scale * u_max added"),
    SpaceField("u_z", 1, "-", -1.0, 1.0, "collective lift throttle, same scaling as u_x"),
    SpaceField("tau_B", 3, "-", -1.0, 1.0, "body moment FRD: direct a * tau_max (N m); residual "
               "a * residual_scale * tau_max added"),
)


def space_layout(title: str, fields: tuple[SpaceField, ...]) -> BlockLayout:
    """The fields of a space as a :class:`~vtoladapt.layout.BlockLayout` (their offsets, sizes and units)."""
    return BlockLayout(title, [Field(f.name, f.size, f.unit, f.doc) for f in fields])


OBSERVATION = space_layout("observation", OBSERVATION_FIELDS)
ACTION = space_layout("action", ACTION_FIELDS)
OBS_SIZE = OBSERVATION.size
ACTION_SIZE = ACTION.size
OBS_P_ERR, OBS_V, OBS_Q, OBS_OMEGA, OBS_V_I, OBS_V_I_VALID, OBS_CMD = OBSERVATION.offsets(
    *(f.name for f in OBSERVATION_FIELDS))


def _bounds(fields: tuple[SpaceField, ...]) -> tuple[np.ndarray, np.ndarray]:
    low = np.concatenate([np.full(f.size, f.low) for f in fields]).astype(np.float32)
    high = np.concatenate([np.full(f.size, f.high) for f in fields]).astype(np.float32)
    return low, high


OBS_LOW, OBS_HIGH = _bounds(OBSERVATION_FIELDS)


def observation_space() -> spaces.Box:
    """The single environment's observation space (float32 Box, bounds of :data:`OBSERVATION_FIELDS`)."""
    low, high = _bounds(OBSERVATION_FIELDS)
    return spaces.Box(low, high, dtype=np.float32)


def action_space() -> spaces.Box:
    """The single environment's action space (float32 Box in [-1, 1]^5)."""
    low, high = _bounds(ACTION_FIELDS)
    return spaces.Box(low, high, dtype=np.float32)


def markdown_table(fields: tuple[SpaceField, ...]) -> str:
    """The fields as a Markdown table (index, name, unit, bounds, meaning), as in the README."""
    rows = ["| index | name | unit | bounds | meaning |", "| --- | --- | --- | --- | --- |"]
    lay = space_layout("space", fields)
    for f in fields:
        n = lay.offset(f.name)
        idx = str(n) if f.size == 1 else f"{n}-{n + f.size - 1}"
        rows.append(f"| {idx} | `{f.name}` | {f.unit} | [{f.low:g}, {f.high:g}] | {f.doc} |")
    return "\n".join(rows)
