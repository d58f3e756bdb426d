"""Wind models: fan-array schedule and mean wind, spin-up lag, gusts, Dryden turbulence, config errors.

Independent references: the paper's wind speeds (Shi et al. 2020, Sec. Experiments: 12.9 m/s at
full throttle; 30 / 50 / 70 % -> about 4 / 6.5 / 9 m/s), scipy's ODE solver for the spin-up lag,
scipy's quadrature for the filter noise covariance, and the MIL-F-8785C Dryden spectra (written
out here again) against a Welch estimate from scipy.signal.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, strategies as st
from numba import njit
from scipy import integrate, signal

from vtoladapt import wind
from vtoladapt.config import ConfigError
from vtoladapt.wind import (
    FanArrayConfig,
    TurbulenceConfig,
    WindConfig,
    fan_mean_wind_speed,
    fan_throttle_pct,
    run_wind_model,
    wind_at,
    wind_series,
)

DT = 0.004


def _fan(schedule, **kw) -> WindConfig:
    return WindConfig.from_mapping({"fan_array": {"schedule": schedule, **kw}})


# --------------------------------------------------------------------------------------------------
# fan array: mean wind and schedule
# --------------------------------------------------------------------------------------------------

def test_mean_wind_linear_in_throttle_and_matches_paper():
    p = _fan([[0.0, 0.0], [100.0, 100.0]]).to_kernel()
    pct = np.linspace(0.0, 100.0, 21)
    speed = np.array([fan_mean_wind_speed(p, x) for x in pct])  # throttle = t on this ramp
    np.testing.assert_allclose(speed, 12.9 * pct / 100.0, rtol=0, atol=1e-12)
    # the paper: 30 / 50 / 70 % "roughly correspond to 4, 6.5 and 9 m/s"
    for throttle, paper_mps in ((30.0, 4.0), (50.0, 6.5), (70.0, 9.0)):
        v = fan_mean_wind_speed(p, throttle)
        assert abs(v - paper_mps) < 0.15, (throttle, v)


@pytest.mark.parametrize("bearing_deg, expected", [(0.0, (-1.0, 0.0)), (90.0, (0.0, -1.0)),
                                                   (180.0, (1.0, 0.0)), (-90.0, (0.0, 1.0))])
def test_fan_wind_blows_from_the_array_toward_the_vehicle(bearing_deg, expected):
    cfg = _fan([[0.0, 50.0]], array_bearing_deg=bearing_deg)
    _, v = wind_series(cfg, 3, DT, np.random.default_rng(0))
    V = 12.9 * 0.5
    np.testing.assert_allclose(v[0], [V * expected[0], V * expected[1], 0.0], atol=1e-12)


def test_schedule_ramps_and_steps_hit_their_breakpoints():
    sched = [[0.0, 0.0], [2.0, 0.0], [2.0, 30.0], [6.0, 30.0], [10.0, 70.0], [12.0, 70.0],
             [12.0, 0.0]]
    p = _fan(sched).to_kernel()
    for t, u in [(0.0, 0.0), (1.999, 0.0), (2.0, 30.0), (6.0, 30.0), (10.0, 70.0), (12.0, 0.0)]:
        assert fan_throttle_pct(p, t) == pytest.approx(u, abs=1e-12), t
    assert fan_throttle_pct(p, 8.0) == pytest.approx(50.0, abs=1e-12)       # mid-ramp
    assert fan_throttle_pct(p, 7.0) == pytest.approx(40.0, abs=1e-12)
    assert fan_throttle_pct(p, -5.0) == 0.0                                # before: first held
    assert fan_throttle_pct(p, 100.0) == 0.0                               # after: last held
    assert fan_throttle_pct(p, 11.999999) == pytest.approx(70.0, abs=1e-12)
    # without lag the wind speed is the throttle times 12.9 m/s / 100 % everywhere
    for t in np.linspace(-1.0, 15.0, 161):
        assert fan_mean_wind_speed(p, t) == pytest.approx(0.129 * fan_throttle_pct(p, t), abs=1e-12)


def test_hold_interpolation_equals_repeated_breakpoints():
    held = _fan([[0.0, 0.0], [5.0, 30.0], [15.0, 40.0]], interpolation="hold").to_kernel()
    linear = _fan([[0.0, 0.0], [5.0, 0.0], [5.0, 30.0], [15.0, 30.0], [15.0, 40.0]]).to_kernel()
    for t in np.linspace(-1.0, 20.0, 211):
        assert fan_throttle_pct(held, t) == fan_throttle_pct(linear, t)
    assert fan_throttle_pct(held, 4.999) == 0.0 and fan_throttle_pct(held, 5.0) == 30.0


def test_empty_schedule_is_fan_off():
    p = WindConfig().to_kernel()
    assert fan_throttle_pct(p, 3.0) == 0.0 and fan_mean_wind_speed(p, 3.0) == 0.0


def test_spin_up_lag_matches_an_ode_solution():
    tau = 0.8
    sched = [[0.0, 0.0], [2.0, 0.0], [2.0, 30.0], [6.0, 30.0], [10.0, 70.0], [14.0, 70.0],
             [14.0, 0.0]]
    p = _fan(sched, spin_up_time_constant_s=tau).to_kernel()
    t_bp = np.array([s[0] for s in sched])
    u_bp = np.array([s[1] for s in sched])
    # integrate y' = (u - y) / tau segment by segment (u continuous inside each), y in m/s
    edges = [0.0, 2.0, 6.0, 10.0, 14.0, 20.0]
    y = 0.0
    for a, b in zip(edges[:-1], edges[1:]):
        def u_of(t, a=a):
            # right-continuous throttle inside [a, b): the breakpoints at a taken last
            k = np.searchsorted(t_bp, a, side="right") - 1
            if k >= len(t_bp) - 1:
                return u_bp[-1]
            return np.interp(t, t_bp[k:k + 2], u_bp[k:k + 2])
        t_eval = np.linspace(a, b, 41)
        sol = integrate.solve_ivp(lambda t, yy: [(0.129 * u_of(t) - yy[0]) / tau], (a, b), [y],
                                  t_eval=t_eval, rtol=1e-11, atol=1e-12, method="DOP853")
        ours = np.array([fan_mean_wind_speed(p, t) for t in t_eval[:-1]])
        np.testing.assert_allclose(ours, sol.y[0][:-1], atol=1e-7)
        y = sol.y[0][-1]
    # the throttle itself has no lag
    assert fan_throttle_pct(p, 2.0) == 30.0
    assert fan_mean_wind_speed(p, 2.0) == pytest.approx(0.0, abs=1e-12)
    # after one time constant, 1 - 1/e of the step
    assert fan_mean_wind_speed(p, 2.0 + tau) == pytest.approx(0.129 * 30 * (1 - math.exp(-1)),
                                                              rel=1e-12)


@given(st.lists(st.tuples(st.floats(0.01, 5.0), st.floats(0.0, 100.0)), min_size=1, max_size=12),
       st.floats(0.0, 3.0), st.floats(-2.0, 40.0))
def test_fan_wind_stays_within_the_schedule_range(steps, tau, t):
    times = np.cumsum([s[0] for s in steps])
    sched = [[float(ti), float(u)] for ti, (_, u) in zip(times, steps)]
    cfg = _fan(sched, interpolation="hold", spin_up_time_constant_s=tau)
    p = cfg.to_kernel()
    lo = min(u for _, u in sched)
    hi = max(u for _, u in sched)
    assert lo - 1e-9 <= fan_throttle_pct(p, t) <= hi + 1e-9
    assert 0.129 * lo - 1e-9 <= fan_mean_wind_speed(p, t) <= 0.129 * hi + 1e-9


# --------------------------------------------------------------------------------------------------
# the paper's profiles
# --------------------------------------------------------------------------------------------------

def test_comparison_profile():
    p = WindConfig(fan_array=wind.paper_fan_array("comparison")).to_kernel()
    expected = [(0.0, 0.0), (4.99, 0.0), (5.0, 30.0), (14.99, 30.0), (15.0, 40.0), (20.0, 50.0),
                (25.0, 60.0), (30.0, 70.0), (39.99, 70.0), (40.0, 0.0), (60.0, 0.0)]
    for t, u in expected:
        assert fan_throttle_pct(p, t) == u, t


def test_convergence_profile_and_ramps():
    sched = wind.convergence_schedule(hover_s=10.0, level_s=20.0)
    p = _fan(sched).to_kernel()
    for t, u in [(0.0, 0.0), (9.99, 0.0), (10.0, 30.0), (30.0, 50.0), (50.0, 70.0), (80.0, 70.0)]:
        assert fan_throttle_pct(p, t) == u, t
    ramped = _fan(wind.convergence_schedule(ramp_s=2.0)).to_kernel()
    assert fan_throttle_pct(ramped, 11.0) == pytest.approx(15.0)
    assert fan_throttle_pct(ramped, 12.0) == pytest.approx(30.0)
    with pytest.raises(ValueError, match="profile"):
        wind.paper_fan_array("nonsense")


def test_time_scaled():
    cfg = WindConfig.from_mapping({
        "fan_array": {"schedule": wind.comparison_schedule(), "spin_up_time_constant_s": 1.0},
        "gusts": [{"shape": "step", "start_s": 4.0, "duration_s": 2.0, "amplitude_mps": [0, 1, 0]}]})
    half = cfg.time_scaled(0.5)
    p, q = cfg.to_kernel(), half.to_kernel()
    for t in np.linspace(0.0, 50.0, 101):
        assert fan_mean_wind_speed(q, 0.5 * t) == pytest.approx(fan_mean_wind_speed(p, t), abs=1e-12)
    assert half.gusts[0].start_s == 2.0 and half.gusts[0].duration_s == 1.0


# --------------------------------------------------------------------------------------------------
# gusts and constant wind
# --------------------------------------------------------------------------------------------------

def test_gust_shapes_and_constant_wind():
    cfg = WindConfig.from_mapping({
        "constant_mps": [1.0, 2.0, 0.5],
        "gusts": [{"shape": "one_minus_cosine", "start_s": 1.0, "duration_s": 2.0,
                   "amplitude_mps": [0.0, 3.0, 0.0]},
                  {"shape": "step", "start_s": 4.0, "duration_s": 1.0,
                   "amplitude_mps": [-2.0, 0.0, 1.0]}]})
    p = cfg.to_kernel()
    out = np.empty(3)

    def at(t):
        wind.gust_wind_W(p, t, out)
        return out.copy()

    np.testing.assert_allclose(at(0.999), 0.0, atol=0)
    np.testing.assert_allclose(at(2.0), [0.0, 3.0, 0.0], atol=1e-12)          # peak mid-gust
    np.testing.assert_allclose(at(1.5), [0.0, 1.5, 0.0], atol=1e-12)          # (1 - cos(pi/2)) / 2
    np.testing.assert_allclose(at(3.0), 0.0, atol=1e-12)                      # back to zero
    np.testing.assert_allclose(at(4.0), [-2.0, 0.0, 1.0], atol=0)
    np.testing.assert_allclose(at(4.999), [-2.0, 0.0, 1.0], atol=0)
    np.testing.assert_allclose(at(5.0), 0.0, atol=0)
    parts = cfg.assemble()
    v = run_wind_model(parts, parts.initial_state(np.random.default_rng(0)), 1, DT, np.random.default_rng(0), t0_s=2.0)
    np.testing.assert_allclose(v[0], [1.0, 5.0, 0.5], atol=1e-12)             # parts add up


# --------------------------------------------------------------------------------------------------
# Dryden turbulence
# --------------------------------------------------------------------------------------------------

SIGMA = (1.5, 1.0, 0.7)
LENGTH = (20.0, 15.0, 5.0)
V_CONV = 10.0
DT_TURB = 0.02
N_TURB = 2**21


def _turbulence_config(**kw) -> WindConfig:
    turb = {"enabled": True, "sigma_mps": list(SIGMA), "length_scale_m": list(LENGTH),
            "convection_speed_mps": V_CONV, **kw}
    return WindConfig.from_mapping({"turbulence": turb})


@pytest.fixture(scope="module")
def turbulence_sample():
    """Components (u, v, w) of a long turbulence record, no mean wind (u axis points south)."""
    _, v = wind_series(_turbulence_config(), N_TURB, DT_TURB, np.random.default_rng(7))
    # no fan, no constant wind: the u axis is the default fan direction, south; v points west
    return np.column_stack([-v[:, 0], -v[:, 1], v[:, 2]])


def _rho(component: str, lag_s: np.ndarray, T: float) -> np.ndarray:
    r = np.exp(-np.abs(lag_s) / T)
    return r if component == "u" else r * (1.0 - np.abs(lag_s) / (2.0 * T))


def test_dryden_variance_per_component(turbulence_sample):
    for i, comp in enumerate("uvw"):
        T = LENGTH[i] / V_CONV
        lags = np.arange(-20000, 20001) * DT_TURB
        # Var(sample variance) = 2 sigma^4 / N * sum_k rho_k^2 for a Gaussian process
        se_rel = math.sqrt(2.0 / N_TURB * np.sum(_rho(comp, lags, T) ** 2))
        var = np.mean(turbulence_sample[:, i] ** 2)
        assert abs(var / SIGMA[i] ** 2 - 1.0) < 5.0 * se_rel, (comp, var, se_rel)
        assert 5.0 * se_rel < 0.06  # the check is tight enough to catch a wrong normalisation


def test_dryden_autocorrelation_at_one_time_scale(turbulence_sample):
    for i, comp in enumerate("uvw"):
        T = LENGTH[i] / V_CONV
        k = int(round(T / DT_TURB))
        x = turbulence_sample[:, i]
        rho = np.mean(x[:-k] * x[k:]) / SIGMA[i] ** 2
        expected = math.exp(-1.0) * (1.0 if comp == "u" else 0.5)
        assert abs(rho - expected) < 0.04, (comp, rho, expected)


def _dryden_psd_reference(comp: str, f: np.ndarray, sigma: float, L: float, V: float):
    """MIL-F-8785C one-sided spectra, converted to (m/s)^2/Hz, written out independently."""
    Om = 2.0 * np.pi * f / V
    if comp == "u":
        phi = sigma**2 * 2.0 * L / np.pi / (1.0 + (L * Om) ** 2)
    else:
        phi = sigma**2 * L / np.pi * (1.0 + 3.0 * (L * Om) ** 2) / (1.0 + (L * Om) ** 2) ** 2
    return phi * 2.0 * np.pi / V


def test_dryden_spectrum_shape_welch(turbulence_sample):
    fs = 1.0 / DT_TURB
    f, S = signal.welch(turbulence_sample, fs=fs, nperseg=8192, axis=0)
    edges = np.geomspace(0.05, fs / 10.0, 11)
    for i, comp in enumerate("uvw"):
        # the sampled process's spectrum is the continuous one folded about the Nyquist frequency
        ref = sum(_dryden_psd_reference(comp, np.abs(f + k * fs), SIGMA[i], LENGTH[i], V_CONV)
                  for k in range(-200, 201))
        for lo, hi in zip(edges[:-1], edges[1:]):
            band = (f >= lo) & (f < hi)
            ratio = S[band, i].mean() / ref[band].mean()
            assert abs(ratio - 1.0) < 0.10, (comp, lo, hi, ratio)
        # and the shape really is Dryden's: the v/w spectrum is not the first-order u shape
    f_hi = V_CONV / LENGTH[1]  # well past the v corner
    band = (f > f_hi) & (f < 2 * f_hi)
    u_shape = _dryden_psd_reference("u", f[band], SIGMA[1], LENGTH[1], V_CONV)
    assert abs(S[band, 1].mean() / u_shape.mean() - 1.0) > 0.3


def test_dryden_psd_integrates_to_variance():
    for comp in "uvw":
        total, _ = integrate.quad(lambda f: wind.dryden_psd(comp, f, 1.3, 12.0, 7.0), 0, np.inf,
                                  limit=400)
        assert total == pytest.approx(1.3**2, rel=1e-6)
        f = np.array([0.0, 0.1, 1.0])
        np.testing.assert_allclose(wind.dryden_psd(comp, f, 1.3, 12.0, 7.0),
                                   _dryden_psd_reference(comp, f, 1.3, 12.0, 7.0), rtol=1e-13)


def test_two_pole_noise_covariance_against_quadrature():
    for x in [1e-6, 1e-4, 0.01, 0.0999999, 0.1, 0.5, 3.0, 40.0]:
        q11, q12, q22 = wind.dryden._two_pole_noise_cov(x)
        r11 = 4.0 * integrate.quad(lambda s: s * s * np.exp(-2 * s), 0, x, epsabs=0, epsrel=1e-13)[0]
        r12 = 4.0 * integrate.quad(lambda s: s * np.exp(-2 * s), 0, x, epsabs=0, epsrel=1e-13)[0]
        r22 = 4.0 * integrate.quad(lambda s: np.exp(-2 * s), 0, x, epsabs=0, epsrel=1e-13)[0]
        np.testing.assert_allclose([q11, q12, q22], [r11, r12, r22], rtol=1e-11)


def test_low_altitude_model():
    # at 1000 ft the low-altitude model meets the medium-altitude one: isotropic, L = 1000 ft
    sigma, L = wind.dryden_low_altitude(304.8, 15.0)
    np.testing.assert_allclose(sigma, [1.5, 1.5, 1.5], rtol=1e-12)
    np.testing.assert_allclose(L, [304.8, 304.8, 304.8], rtol=1e-12)
    sigma, L = wind.dryden_low_altitude(30.48, 10.0)  # 100 ft
    base = 0.177 + 0.0823
    np.testing.assert_allclose(L, np.array([100 / base**1.2, 100 / base**1.2, 100.0]) * 0.3048)
    np.testing.assert_allclose(sigma, [1.0 / base**0.4, 1.0 / base**0.4, 1.0])
    assert sigma[0] > sigma[2] and L[0] > L[2]   # near the ground: horizontal gusts dominate
    with pytest.raises(ValueError, match="1000 ft"):
        wind.dryden_low_altitude(400.0, 10.0)


def test_mean_wind_fraction_scales_with_the_fan_and_vanishes_with_it_off():
    cfg = WindConfig.from_mapping({
        "fan_array": {"schedule": [[0.0, 0.0], [50.0, 0.0], [50.0, 50.0]]},
        "turbulence": {"enabled": True, "mean_wind_fraction": [0.1, 0.1, 0.1],
                       "altitude_m": 2.0}})
    t, v = wind_series(cfg, 25000, 0.01, np.random.default_rng(3))   # 250 s
    off = t < 50.0
    assert np.all(v[off] == 0.0)
    on = t >= 100.0
    mean = 0.129 * 50.0
    resid = v[on] - np.array([-mean, 0.0, 0.0])
    np.testing.assert_allclose(resid.std(axis=0), 0.1 * mean, rtol=0.25)


def test_turbulence_axis_follows_the_mean_wind():
    cfg = WindConfig(constant_mps=(0.0, 3.0, 0.0))
    np.testing.assert_allclose(cfg.turbulence_axis_NE(), [0.0, 1.0])
    cfg = _fan([[0.0, 50.0]], array_bearing_deg=90.0)
    np.testing.assert_allclose(cfg.turbulence_axis_NE(), [0.0, -1.0], atol=1e-15)


# --------------------------------------------------------------------------------------------------
# seeds and draws
# --------------------------------------------------------------------------------------------------

def test_same_seed_bit_identical_different_seed_different():
    cfg = _turbulence_config()
    _, a = wind_series(cfg, 2000, DT, np.random.default_rng(11))
    _, b = wind_series(cfg, 2000, DT, np.random.default_rng(11))
    _, c = wind_series(cfg, 2000, DT, np.random.default_rng(12))
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)


def test_fixed_number_of_draws_whether_turbulence_is_on_or_off():
    for cfg in (_turbulence_config(), WindConfig()):
        rng = np.random.default_rng(5)
        wind_series(cfg, 100, DT, rng)
        ref = np.random.default_rng(5)
        ref.standard_normal(wind.WIND_DRAWS_INITIAL + 100 * wind.WIND_DRAWS_PER_STEP)
        assert rng.random() == ref.random()


@njit
def _called_from_compiled_code(table, params, state, rng, n):
    draws = np.zeros(wind.WIND_DRAWS_PER_STEP)
    out = np.zeros(6)
    acc = 0.0
    for k in range(n):
        for i in range(draws.shape[0]):
            draws[i] = rng.standard_normal()
        wind_at(table, params, state, k * 0.004, 0.004, np.zeros(3), draws, out)
        acc += out[0]
    return acc + fan_mean_wind_speed(params, 1.0) + fan_throttle_pct(params, 1.0)


def test_kernels_run_inside_compiled_code():
    parts = _turbulence_config().assemble()
    a = _called_from_compiled_code(parts.table, parts.params, parts.initial_state(np.random.default_rng(1)),
                                   np.random.default_rng(1), 50)
    assert np.isfinite(a)


def test_still_air_with_zero_floor_freezes_without_nan():
    cfg = WindConfig.from_mapping({"turbulence": {"enabled": True, "sigma_mps": [1.0, 1.0, 1.0],
                                                  "min_convection_speed_mps": 0.0}})
    _, v = wind_series(cfg, 50, DT, np.random.default_rng(0))
    assert np.all(np.isfinite(v))
    np.testing.assert_array_equal(v[0], v[-1])   # no convection: the field does not move


# --------------------------------------------------------------------------------------------------
# configuration errors
# --------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("fan, fragment", [
    ({"schedule": [[0, 0], [5, 120]]}, r"schedule\[1\] = \[5.0, 120.0\]: throttle 120 %"),
    ({"schedule": [[0, 0], [5, -1]]}, r"schedule\[1\].*outside the allowed 0 to 100 %"),
    ({"schedule": [[0, 0], [5, 30], [4, 40]]}, r"schedule\[2\].*must not decrease"),
    ({"schedule": [[0, 0], [5, 30], [5, 40], [5, 50]]}, r"schedule\[3\].*third breakpoint"),
    ({"schedule": [[0, 0], [5, 30], [5, 40]], "interpolation": "hold"},
     r"schedule\[2\].*increase strictly"),
    ({"schedule": [[0, 0, 1]]}, r"schedule\[0\].*\[t_s, throttle_pct\]"),
    ({"schedule": [[-1, 0]]}, r"schedule\[0\].*negative"),
    ({"schedule": [[0, 10]], "throttle": 3}, r"\[wind.fan_array\] throttle.*unknown key"),
    ({"schedule": [[0, 10]], "interpolation": "cubic"}, r"interpolation = 'cubic'"),
    ({"schedule": [[i, 10] for i in range(65)]}, r"at most 64"),
])
def test_invalid_schedules_raise_config_error_naming_the_entry(fan, fragment):
    with pytest.raises(ConfigError, match=fragment) as err:
        WindConfig.from_mapping({"fan_array": fan}, source="s.toml")
    assert "s.toml" in str(err.value)


@pytest.mark.parametrize("data, fragment", [
    ({"gusts": [{"shape": "step", "start_s": 1, "duration_s": 1, "amplitude_mps": [1, 0, 0]},
                {"shape": "step", "start_s": 1, "duraton_s": 1, "amplitude_mps": [1, 0, 0]}]},
     r"\[wind.gusts\[1\]\] duraton_s.*unknown key; did you mean 'duration_s'"),
    ({"gusts": [{"shape": "sine", "start_s": 1, "duration_s": 1, "amplitude_mps": [1, 0, 0]}]},
     r"\[wind.gusts\[0\]\] shape = 'sine'"),
    ({"gusts": {"shape": "step"}}, r"must be a list of tables"),
    ({"turbulence": {"enabled": True}}, r"exactly one of w20_mps, sigma_mps, mean_wind_fraction"),
    ({"turbulence": {"enabled": True, "w20_mps": 7.7, "sigma_mps": [1, 1, 1]}},
     r"exactly one of.*got w20_mps, sigma_mps"),
    ({"turbulence": {"altitude_m": 500.0}}, r"altitude_m = 500.0: out of range"),
    ({"constant_mps": [1, 2]}, r"constant_mps.*exactly 3 elements"),
    ({"wnid": 1}, r"\[wind\] wnid.*unknown key"),
])
def test_invalid_wind_tables_raise_config_error(data, fragment):
    with pytest.raises(ConfigError, match=fragment):
        WindConfig.from_mapping(data, source="s.toml")


def test_turbulence_defaults_and_w20_config():
    assert not TurbulenceConfig().enabled
    cfg = WindConfig.from_mapping({"turbulence": {"enabled": True, "w20_mps": 7.7,
                                                  "altitude_m": 30.48}})
    sigma, L = cfg.turbulence.intensities_and_lengths()
    s_ref, L_ref = wind.dryden_low_altitude(30.48, 7.7)
    np.testing.assert_array_equal(sigma, s_ref)
    np.testing.assert_array_equal(L, L_ref)
    assert FanArrayConfig().max_speed_mps == 12.9


def test_profile_key_names_the_papers_schedules():
    named = WindConfig.from_mapping({"fan_array": {"profile": "comparison"}}).to_kernel()
    explicit = _fan(wind.comparison_schedule()).to_kernel()
    assert np.array_equal(named, explicit)
    conv = WindConfig.from_mapping({"fan_array": {"profile": "convergence"}})
    assert conv.fan_array.linear_breakpoints() == wind.convergence_schedule()
    assert conv.time_scaled(1.0).fan_array.schedule == wind.convergence_schedule()
    with pytest.raises(ConfigError, match="give one or the other"):
        WindConfig.from_mapping({"fan_array": {"profile": "comparison", "schedule": [[0, 1]]}})
    with pytest.raises(ConfigError, match="profile = 'fig5'"):
        WindConfig.from_mapping({"fan_array": {"profile": "fig5"}})
