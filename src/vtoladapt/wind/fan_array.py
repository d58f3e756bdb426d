"""The fan array (the paper's CAST wind tunnel): a throttle schedule and the mean wind it makes.

A throttle schedule ``[[t_s, throttle_pct], ...]`` and a mean wind speed linear in throttle,
``V = max_speed_mps * throttle / 100`` (12.9 m/s at 100 %; 30 / 50 / 70 % give 3.9 / 6.5 /
9.0 m/s, the paper's "about 4, 6.5 and 9 m/s"). The wind blows from the array toward the
vehicle; by default the array is north of the vehicle, so ``v_w = (-V, 0, 0)``. An optional
first-order spin-up lag of the fans is solved in closed form, so the mean wind is a pure function
of time.

A wind part (:mod:`vtoladapt.wind.registry`, the interface of :mod:`vtoladapt.parts`), a steady one:
:func:`pack_fan_array` lays the configuration out as :data:`FAN_PARAMS`; :func:`step` adds the mean
wind to the tick's wind and to its mean. The helper kernels read the block at a base offset ``o``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numba import njit

from ..config import ConfigError, Validated, setting
from ..layout import W_MEAN_W, W_V_W, BlockLayout, Field
from .registry import wind_step

FAN_MAX_SPEED_MPS = 12.9
"""Wind speed of the CAST fan array at 100 % throttle (Shi et al. 2020, Sec. Experiments)."""

MAX_BREAKPOINTS = 64
"""Largest number of schedule breakpoints the kernel holds (after expanding ``"hold"`` steps)."""

PAPER_PROFILES = ("convergence", "comparison")

FAN_PARAMS = BlockLayout("fan-array parameters", [
    Field("N", 1, "-", "number of breakpoints (piecewise-linear form)"),
    Field("MAX_SPEED", 1, "m/s", "mean wind speed at 100 % throttle"),
    Field("DIR", 2, "-", "unit vector (N, E) the fan wind blows toward"),
    Field("TAU", 1, "s", "spin-up time constant (0: none)"),
    Field("T", MAX_BREAKPOINTS, "s", "breakpoint times"),
    Field("U", MAX_BREAKPOINTS, "%", "breakpoint throttles"),
    Field("Y", MAX_BREAKPOINTS, "%", "throttle after the spin-up lag at each breakpoint"),
])
"""The fan array's block of the wind parameter array."""
_N, _MAX_SPEED, _DIR, _TAU, _T, _U, _Y = FAN_PARAMS.offsets("N", "MAX_SPEED", "DIR", "TAU", "T", "U", "Y")


@dataclass(frozen=True)
class FanArrayConfig(Validated):
    """The fan array: a throttle schedule and the wind it makes.

    ``schedule`` is a list of breakpoints ``[t_s, throttle_pct]``. With ``interpolation =
    "linear"`` the throttle is piecewise linear between breakpoints, and two breakpoints at the
    same time make a step (the throttle just before, then from that time on). With ``"hold"`` each
    throttle holds until the next breakpoint (steps only). Before the first breakpoint the first
    throttle holds, after the last the last. An empty schedule is a fan array that is off.
    Instead of a schedule, ``profile`` names one of the paper's two experiments
    (:func:`convergence_schedule`, :func:`comparison_schedule` with their default lengths).
    """

    config_section = "wind.fan_array"

    schedule: tuple[tuple[float, ...], ...] = setting(
        "[s, %]", "breakpoints [t_s, throttle_pct]; times non-decreasing, throttle 0-100",
        default=(), max_items=MAX_BREAKPOINTS)
    profile: str | None = setting(
        "-", "the paper's profile instead of a schedule: 'convergence' (still air 10 s, then 30, "
        "50, 70 % for 20 s each) or 'comparison' (off 5 s; 30 % 10 s; 40, 50, 60 % 5 s each; "
        "70 % 10 s; off from 40 s)", default=None, choices=PAPER_PROFILES)
    interpolation: str = setting(
        "-", "'linear': ramps between breakpoints (repeat a time for a step); 'hold': steps",
        default="linear", choices=("linear", "hold"))
    max_speed_mps: float = setting("m/s", "mean wind speed at 100 % throttle (CAST: 12.9)",
                                   default=FAN_MAX_SPEED_MPS, gt=0.0, le=60.0)
    array_bearing_deg: float = setting(
        "deg", "compass bearing of the array seen from the vehicle = where the wind comes from "
        "(0: north, so v_w = (-V, 0, 0); 90: east)", default=0.0, ge=-360.0, le=360.0)
    spin_up_time_constant_s: float = setting(
        "s", "first-order lag from throttle to wind speed (0: the wind follows the throttle at once)",
        default=0.0, ge=0.0, le=60.0)

    def _check(self, source: str) -> None:
        where = f"{source}: [wind.fan_array] schedule"
        if self.profile is not None:
            if self.schedule:
                raise ConfigError(f"{source}: [wind.fan_array] profile = {self.profile!r} and a "
                                  "schedule: give one or the other")
            if self.interpolation != "linear":
                raise ConfigError(f"{source}: [wind.fan_array] profile = {self.profile!r} with "
                                  f"interpolation = {self.interpolation!r}: a profile brings its "
                                  "own steps; leave interpolation at 'linear'")
        previous_t = -math.inf
        repeats = 0
        for i, entry in enumerate(self.schedule):
            text = f"{where}[{i}] = {list(entry)}"
            if len(entry) != 2:
                raise ConfigError(f"{text}: must be [t_s, throttle_pct]")
            t, pct = entry
            if t < 0.0:
                raise ConfigError(f"{text}: time {t:g} s is negative; allowed: >= 0 s")
            if not 0.0 <= pct <= 100.0:
                raise ConfigError(f"{text}: throttle {pct:g} % outside the allowed 0 to 100 %")
            if t < previous_t:
                raise ConfigError(
                    f"{text}: time {t:g} s is before the previous breakpoint's {previous_t:g} s; "
                    "times must not decrease")
            if t == previous_t:
                if self.interpolation == "hold":
                    raise ConfigError(
                        f"{text}: time {t:g} s repeats; with interpolation = 'hold' times must "
                        "increase strictly (each breakpoint already starts a step)")
                repeats += 1
                if repeats > 1:
                    raise ConfigError(
                        f"{text}: a third breakpoint at {t:g} s; a step needs exactly two "
                        "(the throttle before and after)")
            else:
                repeats = 0
            previous_t = t
        n = len(self.linear_breakpoints())
        if n > MAX_BREAKPOINTS:
            raise ConfigError(
                f"{where}: {len(self.schedule)} breakpoints make {n} in piecewise-linear form; "
                f"at most {MAX_BREAKPOINTS} are allowed")

    def linear_breakpoints(self) -> tuple[tuple[float, float], ...]:
        """The schedule as piecewise-linear breakpoints (``"hold"`` steps become repeated times)."""
        if self.profile is not None:
            return paper_schedule(self.profile)
        pts = [(float(t), float(u)) for t, u in self.schedule]
        if self.interpolation == "linear" or not pts:
            return tuple(pts)
        out = [pts[0]]
        for t, u in pts[1:]:
            out.append((t, out[-1][1]))
            out.append((t, u))
        return tuple(out)

def bearing_unit(bearing_deg: float) -> np.ndarray:
    """Unit (N, E) vector of a compass bearing (deg)."""
    b = math.radians(bearing_deg)
    return np.array([math.cos(b), math.sin(b)])


def pack_fan_array(fan: FanArrayConfig) -> np.ndarray:
    """The fan array as its kernel block (layout :data:`FAN_PARAMS`)."""
    p = np.zeros(FAN_PARAMS.size)
    pts = fan.linear_breakpoints()
    n = len(pts)
    p[_N] = n
    p[_MAX_SPEED] = fan.max_speed_mps
    p[_DIR:_DIR + 2] = -bearing_unit(fan.array_bearing_deg)
    p[_TAU] = fan.spin_up_time_constant_s
    if n:
        t = np.array([q[0] for q in pts])
        u = np.array([q[1] for q in pts])
        p[_T:_T + n] = t
        p[_U:_U + n] = u
        p[_Y:_Y + n] = _lagged_breakpoints(t, u, fan.spin_up_time_constant_s)
    return p


def _lagged_breakpoints(t: np.ndarray, u: np.ndarray, tau_s: float) -> np.ndarray:
    """Fan speed (as throttle, %) after the spin-up lag at each breakpoint, starting settled."""
    y = np.empty_like(u)
    y[0] = u[0]
    for k in range(len(t) - 1):
        y[k + 1] = _lag_on_segment(y[k], u[k], u[k + 1], t[k + 1] - t[k], t[k + 1] - t[k], tau_s)
    return y


@njit(cache=True, inline="always")
def _lag_on_segment(y0: float, u0: float, u1: float, seg_s: float, elapsed_s: float,
                    tau_s: float) -> float:
    """Closed-form ``y' = (u - y) / tau`` for ``u`` linear from ``u0`` to ``u1`` over ``seg_s``."""
    if tau_s <= 0.0:
        if seg_s <= 0.0:
            return u1
        return u0 + (u1 - u0) * elapsed_s / seg_s
    if seg_s <= 0.0:
        return y0
    slope = (u1 - u0) / seg_s
    u = u0 + slope * elapsed_s
    return u - slope * tau_s + (y0 - u0 + slope * tau_s) * np.exp(-elapsed_s / tau_s)

# --- the paper's fan-array profiles --------------------------------------------------------------

def _levels_schedule(levels: Sequence[tuple[float, float]], ramp_s: float) -> tuple:
    """Breakpoints for throttle levels ``(start_s, pct)`` (first level from t = 0)."""
    if ramp_s < 0.0:
        raise ValueError(f"ramp_s = {ramp_s!r}: must be >= 0")
    pts = [(0.0, float(levels[0][1]))]
    for (t_prev, _), (t, pct) in zip(levels[:-1], levels[1:]):
        if ramp_s > 0.0 and t - t_prev < ramp_s:
            raise ValueError(f"ramp_s = {ramp_s:g} s is longer than the level starting at "
                             f"{t_prev:g} s ({t - t_prev:g} s)")
        pts.append((float(t), pts[-1][1]))
        pts.append((float(t + ramp_s), float(pct)))
    return tuple(pts)


def convergence_schedule(hover_s: float = 10.0, level_s: float = 20.0,
                         levels_pct: Sequence[float] = (30.0, 50.0, 70.0),
                         ramp_s: float = 0.0) -> tuple[tuple[float, float], ...]:
    """The convergence experiment (Fig. parameter_convergence): still air, then 30, 50, 70 %.

    Parameters
    ----------
    hover_s : float
        Hover in still air (fan off) before the first level (s).
    level_s : float
        Time at each throttle level (s); the schedule ends at ``hover_s + 3 level_s`` still at
        the last level.
    levels_pct : sequence of float
        Throttle levels (%).
    ramp_s : float
        Throttle ramp between levels (s); 0 for steps.

    Returns
    -------
    tuple of (t_s, throttle_pct)
        Breakpoints for ``interpolation = "linear"``.
    """
    levels = [(0.0, 0.0)] + [(hover_s + i * level_s, p) for i, p in enumerate(levels_pct)]
    pts = _levels_schedule(levels, ramp_s)
    return pts + ((hover_s + len(levels_pct) * level_s, pts[-1][1]),)


def comparison_schedule(hover_s: float = 5.0, first_level_s: float = 10.0, step_s: float = 5.0,
                        top_s: float = 10.0, ramp_s: float = 0.0) -> tuple[tuple[float, float], ...]:
    """The comparison experiment (Figs. tracking_comparison*): fan off; 30 % for 10 s; +10 %
    every 5 s up to 70 %; 10 s at 70 %; fan off.

    The fan goes off at ``hover_s + first_level_s + 3 step_s + top_s`` (40 s by default);
    simulate ~10 s longer to see the response to the wind dropping.

    Returns
    -------
    tuple of (t_s, throttle_pct)
        Breakpoints for ``interpolation = "linear"``.
    """
    levels = [(0.0, 0.0), (hover_s, 30.0)]
    t = hover_s + first_level_s
    for pct in (40.0, 50.0, 60.0, 70.0):
        levels.append((t, pct))
        t += step_s if pct < 70.0 else top_s
    levels.append((t, 0.0))
    return _levels_schedule(levels, ramp_s)


def paper_schedule(profile: str, **kwargs) -> tuple[tuple[float, float], ...]:
    """Breakpoints of the paper's ``"convergence"`` or ``"comparison"`` profile.

    ``kwargs`` go to :func:`convergence_schedule` or :func:`comparison_schedule`.
    """
    makers = {"convergence": convergence_schedule, "comparison": comparison_schedule}
    if profile not in makers:
        raise ValueError(f"profile = {profile!r}: allowed {', '.join(map(repr, makers))}")
    return makers[profile](**kwargs)


def paper_fan_array(profile: str, spin_up_time_constant_s: float = 0.0, **kwargs) -> FanArrayConfig:
    """A :class:`FanArrayConfig` for ``profile`` = ``"convergence"`` or ``"comparison"``.

    ``kwargs`` (segment lengths, ``ramp_s``) go to :func:`convergence_schedule` or
    :func:`comparison_schedule`; the result carries the explicit schedule.
    """
    cfg = FanArrayConfig(schedule=paper_schedule(profile, **kwargs), interpolation="linear",
                         spin_up_time_constant_s=spin_up_time_constant_s)
    cfg._check(f"paper_fan_array({profile!r})")
    return cfg


# --- kernels (``o``: offset of the fan block in the parameter array) -----------------------------

@njit(cache=True, inline="always")
def _segment(params: np.ndarray, o: int, t: float) -> int:
    """Index k of the last breakpoint with ``t_k <= t`` (-1 before the first)."""
    n = int(params[o + _N])
    lo = 0
    hi = n  # invariant: answer in [lo - 1, hi - 1]
    while lo < hi:
        mid = (lo + hi) // 2
        if params[o + _T + mid] <= t:
            lo = mid + 1
        else:
            hi = mid
    return lo - 1


@njit(cache=True)
def throttle_pct(params: np.ndarray, o: int, t: float) -> float:
    """Commanded throttle (%) at time ``t`` (s): the schedule, without the spin-up lag."""
    n = int(params[o + _N])
    if n == 0:
        return 0.0
    k = _segment(params, o, t)
    if k < 0:
        return params[o + _U]
    if k >= n - 1:
        return params[o + _U + n - 1]
    t0 = params[o + _T + k]
    t1 = params[o + _T + k + 1]
    u0 = params[o + _U + k]
    return u0 + (params[o + _U + k + 1] - u0) * (t - t0) / (t1 - t0)


@njit(cache=True, inline="always")
def speed_fraction(params: np.ndarray, o: int, t: float) -> float:
    """Fan wind speed as a fraction of ``max_speed``, after the spin-up lag."""
    n = int(params[o + _N])
    if n == 0:
        return 0.0
    tau = params[o + _TAU]
    k = _segment(params, o, t)
    if k < 0:
        return 0.01 * params[o + _U]
    y0 = params[o + _Y + k]
    u0 = params[o + _U + k]
    t0 = params[o + _T + k]
    if k >= n - 1:
        return 0.01 * _lag_on_segment(y0, u0, u0, 1.0, t - t0, tau)
    t1 = params[o + _T + k + 1]
    return 0.01 * _lag_on_segment(y0, u0, params[o + _U + k + 1], t1 - t0, t - t0, tau)


@njit(cache=True, inline="always")
def mean_speed_mps(params: np.ndarray, o: int, t: float) -> float:
    """Mean fan wind speed (m/s) at ``t``: ``max_speed * y / 100``, ``y`` the lagged throttle."""
    return params[o + _MAX_SPEED] * speed_fraction(params, o, t)


@njit(cache=True, inline="always")
def direction_NE(params: np.ndarray, o: int) -> tuple:
    """Unit (N, E) vector the fan wind blows toward."""
    return params[o + _DIR], params[o + _DIR + 1]


# --- the part (vtoladapt.parts) -----------------------------------------------------------------
Settings = FanArrayConfig
PARAMS = FAN_PARAMS
STATE = BlockLayout("fan-array state", [])
NORMALS_PER_STEP = 0
UNIFORMS_PER_STEP = 0


def pack(settings: FanArrayConfig, wind) -> np.ndarray:
    """The part's parameter block: :func:`pack_fan_array`."""
    return pack_fan_array(settings)


def initial_state(params: np.ndarray, rng) -> np.ndarray:
    """No state: the spin-up lag is solved in closed form."""
    return np.zeros(0)


@wind_step
def step(params, state, t, dt, p_W, draws, wind):
    """Add the fan array's mean wind at ``t`` to the wind and to the mean wind (NED, m/s)."""
    v = mean_speed_mps(params, 0, t)
    dN, dE = direction_NE(params, 0)
    wind[W_V_W] += v * dN
    wind[W_V_W + 1] += v * dE
    wind[W_MEAN_W] += v * dN
    wind[W_MEAN_W + 1] += v * dE
