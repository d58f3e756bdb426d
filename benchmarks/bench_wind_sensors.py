"""Per-call cost of the wind and sensor kernels inside compiled loops.

``run()`` returns ``(name, value, unit)`` rows: the median over repeats of the time per tick of
the wind (the four package parts through their table, :func:`vtoladapt.wind.wind_at`: fan schedule
with spin-up lag, a gust and Dryden turbulence on) and of the sensors (the four channels through
theirs, :func:`vtoladapt.sensors.sensors_at`: every sensor on, differentiated mocap velocity, probe
dropout), their draws included (:func:`vtoladapt.parts.draw`), each called in an ``njit`` loop with
a moving truth (so nothing is hoisted). Timed with the process's CPU clock,
so other jobs sharing the machine do not inflate the figures. A few seconds, plus Numba
compilation on a cold cache.
"""
from __future__ import annotations

import time

import numpy as np
from numba import njit

from vtoladapt import layout
from vtoladapt.parts import draw
from vtoladapt.sensors import MocapConfig, ProbeConfig, SensorsConfig, sensors_at
from vtoladapt.wind import WindConfig, comparison_schedule, wind_at

DT = 0.004


# not cached: Numba's cache does not see edits to the kernels it calls in other files; without reference
# counting, as the tick that calls the parts (their inlined slices would otherwise count references)
@njit(cache=False, _nrt=False)
def _loop_wind(table, params, state, draws, out, p_W, rng, n_calls):
    acc = 0.0
    for k in range(n_calls):
        t = (k % 12500) * 0.004
        draw(rng, table, draws)
        wind_at(table, params, state, t, 0.004, p_W, draws, out)
        acc += out[0] + out[1] + out[2]
    return acc


@njit(cache=False, _nrt=False)
def _loop_sensors(table, params, state, draws, x, truth, meas, rng, n_calls):
    acc = 0.0
    for k in range(n_calls):
        s = 1e-4 * (k % 1000)
        x[0] = s
        x[4] = s
        truth[layout.TRUTH_F_B] = s
        truth[layout.TRUTH_V_I_B] = 5.0 + s
        draw(rng, table, draws)
        sensors_at(table, params, state, k * 0.004, 0.004, x, truth, draws, meas)
        acc += meas[0] + meas[13] + meas[19]
    return acc


def _median_us_per_call(fn, args, n_calls: int, repeats: int) -> float:
    fn(*args, 10)  # compile / warm up
    times = []
    for _ in range(repeats):
        t0 = time.process_time()
        fn(*args, n_calls)
        times.append((time.process_time() - t0) / n_calls * 1e6)
    return float(np.median(times))


def run() -> list[tuple[str, float, str]]:
    """Time the wind and the sensors of a tick; return ``(name, us per call, "us/call")`` rows."""
    wind = WindConfig.from_mapping({
        "fan_array": {"schedule": comparison_schedule(), "spin_up_time_constant_s": 0.5},
        "turbulence": {"enabled": True, "w20_mps": 7.7, "altitude_m": 2.0},
        "gusts": [{"shape": "one_minus_cosine", "start_s": 12.0, "duration_s": 2.0,
                   "amplitude_mps": [0.0, 1.0, 0.0]}]})
    wp = wind.assemble()
    rng = np.random.default_rng(0)
    wind_us = _median_us_per_call(_loop_wind, (wp.table, wp.params, wp.initial_state(rng), np.zeros(wp.draws_size),
                                               np.zeros(layout.WIND_SIZE), np.zeros(3), rng), 200_000, 15)

    sens = SensorsConfig(mocap=MocapConfig(velocity_from="differentiate"),
                         probe=ProbeConfig(dropout_probability=0.01))
    sp = sens.assemble()
    x = layout.pack_state([0.0, 0.0, -1.5], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0],
                          [0.0, 0.0, 0.0], [0.5] * 5)
    truth = layout.TRUTH.pack(F_B=[0.0, 0.0, -9.80665], V_I_B=[5.0, 0.0, 0.3])
    sensors_us = _median_us_per_call(
        _loop_sensors, (sp.table, sp.params, sp.initial_state(rng), np.zeros(sp.draws_size), x, truth,
                        np.zeros(layout.MEAS_SIZE), rng),
        200_000, 15)
    return [("wind: four parts (fan + lag + gust + Dryden), draws included", wind_us, "us/call"),
            ("sensors: four channels (all on), draws included", sensors_us, "us/call")]


if __name__ == "__main__":
    for name, value, unit in run():
        print(f"{name:60s} {value:8.3f} {unit}")
