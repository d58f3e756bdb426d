"""Closed-loop runs of the whole simulator (plant, wind, sensors, controller, mixer) checked against theory.

What each test compares with:

* **Exact model match** (:func:`test_hold_with_plant_equal_to_model`): with the plant's force
  model equal to the controller's (unmodelled effects off, theta_0 = truth, perfect sensors, no
  turbulence) every controller's force model is exact, so the velocity error v~ = v - v_r must
  decay to (numerically) zero; we ask < 1 cm/s after settling.
* **Tracking-only limit cycle** (:func:`test_tracking_only_paper_gain_limit_cycle_is_the_pusher_lag`):
  with the paper's constant gain P0 the tracking law limit-cycles at 9 m/s, as a Routh-Hurwitz
  criterion computed from the regressor at the trim predicts; the default gain rule holds.
* **Lyapunov decrease** (:func:`test_lyapunov_function_decreases_outside_the_ball`): the
  Theorem's V (log column ``lyapunov_V``) with the plant's true coefficients.
* **Probe dropouts** (:func:`test_probe_dropouts_in_closed_loop`): finite commands, the faults
  flagged tick by tick, and tracking no worse than the same seeded run without dropouts.
* **Adaptation toward the plant** (:func:`test_composite_adapts_toward_the_plant`): theta-hat[CTz]
  versus the plant's truth, and the prediction error of eq:prediction_error.

All runs use the shipped ``caltech_vtol`` and are deterministic (seeded; ideal sensors draw no
noise into the loop). Each 20-30 s run takes ~0.1-0.2 s once Numba's cache is warm.
"""
from __future__ import annotations

import numpy as np
import pytest

from vtoladapt import forces, load_vehicle
from vtoladapt.control.blocks import FAULT_PROBE
from vtoladapt.control.registry import controller_ids
from vtoladapt.control.settings import ControllerConfig

CONTROLLER_KINDS = controller_ids()
from vtoladapt.frames import GRAVITY_MPS2, quat_to_rotmat
from vtoladapt.sim.scenario import scenario_from_mapping
from vtoladapt.sim.driver import simulate
from vtoladapt.wind import FAN_MAX_SPEED_MPS

VEHICLE = "caltech_vtol"
IDEAL_SENSORS = {name: {"ideal": True} for name in ("imu", "mocap", "attitude", "probe")}
# Every effect the controller's model lacks, off. The lift rotors' yaw torque goes with
# rotor_reaction_torque (see the test of the exact-model hold for why that is acceptable here).
UNMODELLED_OFF = {"stall": False, "side_force": False, "pusher_advance_ratio_loss": False,
                  "rotor_reaction_torque": False, "aero_rate_damping": False}
TICK_S = 0.004
DEFAULT_K_V = ControllerConfig().K_v


def _throttle_pct(wind_mps: float) -> float:
    """Fan-array throttle that makes ``wind_mps`` (V = 12.9 m/s * throttle / 100)."""
    return 100.0 * wind_mps / FAN_MAX_SPEED_MPS


def _steady_wind(wind_mps: float, duration_s: float) -> list[list[float]]:
    """A fan schedule already blowing at ``wind_mps`` from t = 0 to the end of the run."""
    thr = _throttle_pct(wind_mps)
    return [[0.0, thr], [duration_s, thr]]


def _run(name: str, duration_s: float, fan_schedule, *, plant=None, sensors=None, controller=None,
         initial=None, seed: int = 1):
    """Validate and simulate one scenario built from the given tables."""
    data = {"name": name, "vehicle": VEHICLE, "duration_s": duration_s, "seed": seed,
            "wind": {"fan_array": {"schedule": fan_schedule}},
            "plant": plant or {}, "sensors": sensors or {}, "controller": controller or {}}
    if initial is not None:
        data["initial"] = initial
    return simulate(scenario_from_mapping(data, f"tests/test_closed_loop_sim.py::{name}"))


def _max_norm(a: np.ndarray) -> float:
    return float(np.linalg.norm(a, axis=1).max())


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle(VEHICLE)


# ==================================================================================================
# 1. Plant equal to the model: every controller holds position to < 1 cm/s
# ==================================================================================================

HOLD_DURATION_S = 20.0
SETTLED_FROM_S = 15.0
HOLD_TOL_MPS = 0.01
WINDS_MPS = (0.0, 4.0, 9.0)

def _hold_cases():
    for lag in (True, False):
        for kind in CONTROLLER_KINDS:
            for wind in WINDS_MPS:
                yield pytest.param(kind, wind, lag, id=f"{kind}-{wind:g}mps-{'lag' if lag else 'nolag'}")


@pytest.mark.parametrize("kind, wind_mps, motor_lag", list(_hold_cases()))
def test_hold_with_plant_equal_to_model(kind, wind_mps, motor_lag):
    """Each controller holds position with |v~| < 1 cm/s when the plant equals its model.

    Reference: with the force model exact (plant coefficients = Table I = theta_0, every
    unmodelled effect off, perfect sensors, no turbulence) the composite and tracking laws have
    theta~ = 0 as an equilibrium and the baselines' feed-forward is exact, so v~ = v - v_r (eq:wr)
    must decay to zero; 1 cm/s is the issue's bound.

    Settling: the wind blows from t = 0 onto a level vehicle at hover trim, a step the loops
    must absorb (peak |v~| 5-14 cm/s). The slowest closed-loop mode is the PID's: the
    horizontal loop ``s^3 + K_v s^2 + (K_v Lambda_p + K_I) s + K_I Lambda_p`` (PX4 gains) has a
    pole at -0.21 /s, a 4.7 s time constant; from t = 15 s (3.2 time constants) the last 5 s
    of a 20 s run are checked.

    Motor lag: both. ``motor_lag = true`` is the plant the controller's regressor assumes
    (``regressor_motor_lag``, same 30/40 ms time constants); ``false`` (with the regressor's
    lag off too) is the Theorem's setting, thrust equal to the command. Turning
    ``rotor_reaction_torque`` off (its pusher roll torque is unmodelled: on, it costs every
    controller without an integrator a 4.5 cm/s lateral error at 4 and 9 m/s) also removes the
    lift rotors' yaw torque, the yaw authority the mixer relies on; a symmetric hold never
    excites yaw (|v_E| < 1e-15 m/s), so that does not matter here.

    Measured, max |v~| over 15-20 s in m/s at 4 and 9 m/s (at 0 m/s all are ~1e-11), with lag /
    without: composite 1.1e-5, 5.0e-5 / 3.6e-8, 2.1e-7; composite_pconst 5.6e-6, 1.4e-5 /
    3.7e-8, 1.7e-7; tracking_only (its default 'routh' gain rule) 7.9e-8, 5.1e-5 / 1.3e-9, 1.7e-7
    (with the paper's constant P0: 7.8e-6, 0.198 / 3.4e-7, 2.7e-6, the lagged 9 m/s case the limit
    cycle of test_tracking_only_paper_gain_limit_cycle_is_the_pusher_lag); pid 4.9e-4, 6.5e-4 /
    1.8e-5, 1.6e-5; pd 3.9e-7, 5.4e-7 / 3.5e-8, 3.1e-8.
    """
    plant = dict(UNMODELLED_OFF, motor_lag=motor_lag)
    r = _run(f"hold_{kind}_{wind_mps:g}", HOLD_DURATION_S, _steady_wind(wind_mps, HOLD_DURATION_S),
             plant=plant, sensors=IDEAL_SENSORS,
             controller={"kind": kind, "regressor_motor_lag": motor_lag})
    # the scenario really is what the test claims: steady wind at the stated speed, no turbulence
    np.testing.assert_allclose(r.wind_W[:, 0], -wind_mps, atol=1e-9)
    np.testing.assert_allclose(r.wind_W[:, 1:], 0.0, atol=1e-12)
    settled = r.time_s >= SETTLED_FROM_S
    v_err = _max_norm(r.velocity_error_W[settled])
    assert np.all(np.isfinite(r.velocity_error_W))
    assert v_err < HOLD_TOL_MPS, f"{kind} at {wind_mps} m/s: max |v~| over 15-20 s = {v_err:.3g} m/s"


def _tracking_loop_gain_x(r, vehicle) -> float:
    """``(R Phi P0 Phi^T R^T)_xx`` at the last tick: the tracking law's integral gain along north.

    Linearised at a trim with theta~ small, the force error is ``-R Phi theta~`` and the tracking
    law gives ``theta~' = P0 Phi^T R^T v~``, so along north ``v~'' = -K_v v~' - k_I v~`` with this
    ``k_I`` (1/s^2).
    """
    k = -1
    v_i = r.columns_like(("v_i_x_mps", "v_i_y_mps", "v_i_z_mps"))[k]
    R = quat_to_rotmat(np.ascontiguousarray(r.columns_like(("q_w", "q_x", "q_y", "q_z"))[k]))
    Phi = np.empty((3, 8))
    forces.regressor(np.ascontiguousarray(v_i), r["cmd_u_x_frac"][k], r["cmd_u_z_frac"][k],
                     vehicle.model_kernel, Phi)
    P0 = np.diag(vehicle.adaptation.P0_diag)
    M = R @ Phi @ P0 @ Phi.T @ R.T
    return float(M[0, 0])


def test_tracking_only_paper_gain_limit_cycle_is_the_pusher_lag(vehicle):
    """With the paper's constant gain P0 the tracking-only law's 9 m/s limit cycle is the pusher lag.

    Reference: at 9 m/s the desired angle of attack sits at its 12 deg limit, so the body-x force
    comes from the pusher through its first-order lag ``tau``. Along north the loop is
    ``tau s^3 + s^2 + K_v s + k_I`` with the tracking law's integral gain ``k_I`` (from the
    regressor at the trim and Table III's P0, computed here, not by the simulator), stable iff
    ``K_v > tau k_I``. With the default 40 ms, ``tau k_I`` = 2.3 > K_v = 1.8: unstable, and the
    simulator shows a ~0.2 m/s limit cycle. With a 20 ms pusher, ``tau k_I`` = 1.15 < 1.8: |v~| < 1
    cm/s. (Sweeping the wind, the criterion crosses 1.8 at 65 % fan, where the simulator's
    oscillation starts to persist.) The law's default gain rule ('routh',
    :mod:`vtoladapt.control.laws.tracking_only`) scales the gain so the criterion holds with margin
    2: the same 40 ms case then holds to 1 cm/s.
    """
    paper = {"kind": "tracking_only", "tracking_only": {"gain_rule": "paper"}}
    sched = _steady_wind(9.0, HOLD_DURATION_S)
    slow = _run("tracking_only_40ms", HOLD_DURATION_S, sched, plant=dict(UNMODELLED_OFF),
                sensors=IDEAL_SENSORS, controller=paper)
    fast = _run("tracking_only_20ms", HOLD_DURATION_S, sched,
                plant=dict(UNMODELLED_OFF, pusher_motor_time_constant_s=0.020),
                sensors=IDEAL_SENSORS, controller=paper)
    routh = _run("tracking_only_40ms_routh", HOLD_DURATION_S, sched, plant=dict(UNMODELLED_OFF),
                 sensors=IDEAL_SENSORS, controller={"kind": "tracking_only"})
    k_I = _tracking_loop_gain_x(fast, vehicle)  # at the settled trim
    K_v = DEFAULT_K_V[0]
    assert vehicle.actuators.pusher_motor_time_constant_s * k_I > K_v  # predicted unstable
    assert 0.020 * k_I < K_v                                            # predicted stable
    settled_slow = slow.time_s >= SETTLED_FROM_S
    settled_fast = fast.time_s >= SETTLED_FROM_S
    settled_routh = routh.time_s >= SETTLED_FROM_S
    assert _max_norm(slow.velocity_error_W[settled_slow]) > 0.05
    assert _max_norm(fast.velocity_error_W[settled_fast]) < HOLD_TOL_MPS
    assert _max_norm(routh.velocity_error_W[settled_routh]) < HOLD_TOL_MPS


# ==================================================================================================
# 2. The Lyapunov function decreases outside the error ball
# ==================================================================================================

LYAP_DURATION_S = 30.0
LOOKAHEAD_S = 0.1


@pytest.mark.parametrize("motor_lag, min_fraction", [(False, 0.95), (True, 0.90)],
                         ids=["nolag", "lag"])
def test_lyapunov_function_decreases_outside_the_ball(vehicle, motor_lag, min_fraction):
    """V (log column ``lyapunov_V``, with the plant's true theta) decreases outside the error ball.

    Plant: CTz 5 % lower, CL1 10 % lower, CD0 30 % higher than Table I (= theta_0); unmodelled
    effects off; perfect sensors; 9 m/s from t = 0; composite controller; 30 s.

    The Theorem's ball is loose here. ``V' <= -c V + sigma/2 |theta - theta_0|^2`` needs
    ``c <= sigma lambda_min(P) <= sigma min_i P_ii`` (the parameter term decays only through the
    sigma term in unexcited directions), so the ultimate bound ``sigma |theta - theta_0|^2 / (2c)``
    is at least ``|theta - theta_0|^2 / (2 min_t,i P_ii)`` ~ 47 in these runs, while V(0) ~ 0.5 when theta-hat starts
    at theta_0: such a run starts inside the ball. So the vehicle also starts 2 m south of and
    0.5 m below the held point (V(0) = 2.5), and the ball is taken empirically as twice the
    median V of the last 5 s. Checked:

    * V finite; max V <= 1.25 V(0) (measured 1.00 without lag, 1.09 with: the 40 ms lag, absent
      from the Theorem, lets V rise for 70 ms after the start);
    * of the ticks with V above the ball, the fraction where V(t + 0.1 s) < V(t) is at least
      ``min_fraction`` (measured 1.00 of 77 ticks without lag, 0.97 of 176 with);
    * V at the end is below half of V(0) (measured 0.22, 0.23 of V(0)) and below the Theorem's
      ball (its lower bound above, from the logged P diagonal).
    """
    fm = vehicle.force_model
    coefficients = {"CTz": 0.95 * fm.CTz, "CL1": 0.90 * fm.CL1, "CD0": 1.30 * fm.CD0}
    r = _run(f"lyapunov_{motor_lag}", LYAP_DURATION_S, _steady_wind(9.0, LYAP_DURATION_S),
             plant=dict(UNMODELLED_OFF, motor_lag=motor_lag, coefficients=coefficients),
             sensors=IDEAL_SENSORS, controller={"kind": "composite", "regressor_motor_lag": motor_lag},
             initial={"position_m": [-2.0, 0.0, -1.0]})
    V = r["lyapunov_V"]
    t = r.time_s
    assert np.all(np.isfinite(V))
    assert V.max() <= 1.25 * V[0], f"max V = {V.max():.3g}, V(0) = {V[0]:.3g}"

    ball = 2.0 * np.median(V[t >= LYAP_DURATION_S - 5.0])
    n_ahead = int(round(LOOKAHEAD_S / TICK_S))
    outside = np.nonzero(V[:-n_ahead] > ball)[0]
    assert len(outside) >= 25, "the run must spend time outside the ball for this test to mean anything"
    fraction = float(np.mean(V[outside + n_ahead] < V[outside]))
    assert fraction >= min_fraction, f"V decreased over 0.1 s at {fraction:.3f} of {len(outside)} ticks"

    assert V[-1] < 0.5 * V[0]
    theta_true = np.array(r.metadata["theta_true_scaled"])
    gap2 = float(np.sum((theta_true - vehicle.theta_scaled) ** 2))
    P_diag_min = r.columns_like([c for c in r.columns if c.startswith("P_diag_")]).min()
    theorem_ball_lower = gap2 / (2.0 * P_diag_min)
    assert V[t >= LYAP_DURATION_S - 5.0].max() <= theorem_ball_lower


# ==================================================================================================
# 3. Probe dropouts in closed loop
# ==================================================================================================

DROPOUT_DURATION_S = 20.0
DROPOUT_SETTLED_FROM_S = 5.0


@pytest.mark.parametrize("kind", CONTROLLER_KINDS)
def test_probe_dropouts_in_closed_loop(kind):
    """5 % probe dropouts at 9 m/s: finite commands, faults flagged, tracking still bounded.

    Default plant (every unmodelled effect on) and default sensors, the probe reading NaN with
    valid flag 0 on 5 % of ticks. Reference: the same seeded run without dropouts (the sensors
    draw the same random numbers either way, so the runs differ only by the dropouts).

    * every ``cmd_*`` and motor command finite;
    * on every dropout tick ``fault_flags`` has the probe bit, the controller falls back to its
      wind estimate (``probe_valid_used`` = 0) and the adaptation pauses; on valid ticks (9 m/s,
      far above the probe's 1 m/s floor) the probe bit is clear;
    * from t = 5 s, max |p~| <= 1.5 x the fault-free run's + 2 cm, and for the composite
      controller max |p~| <= 0.10 m, max |v~| <= 0.15 m/s. Measured max |p~| with / without
      dropouts: composite 0.056 / 0.057 m (|v~| 0.059 m/s), composite_pconst 0.056 / 0.055,
      tracking_only 0.080 / 0.064, pid 0.153 / 0.148, pd 0.425 / 0.421.
    """
    sched = _steady_wind(9.0, DROPOUT_DURATION_S)
    ctrl = {"kind": kind}
    faulty = _run(f"dropout_{kind}", DROPOUT_DURATION_S, sched, controller=ctrl, seed=3,
                  sensors={"probe": {"dropout_probability": 0.05}})
    clean = _run(f"nodropout_{kind}", DROPOUT_DURATION_S, sched, controller=ctrl, seed=3)

    commands = faulty.columns_like([c for c in faulty.columns if c.startswith("cmd_") or c.endswith("_cmd_frac")])
    assert commands.shape[1] == 10 and np.all(np.isfinite(commands))

    invalid = faulty["meas_v_i_valid"] == 0.0
    # binomial(5000, 0.05): 250 +- 15; the test must actually exercise dropouts
    assert 0.03 < invalid.mean() < 0.07
    assert np.all(np.isnan(faulty["meas_v_i_x_mps"][invalid]))
    flags = faulty["fault_flags"].astype(np.int64)
    assert np.all(flags[invalid] & FAULT_PROBE), "a dropout tick without the probe fault flag"
    assert not np.any(flags[~invalid] & FAULT_PROBE), "probe flagged on a valid tick"
    assert np.all(faulty["probe_valid_used"][invalid] == 0.0)
    assert np.all(faulty["adaptation_active"][invalid] == 0.0)

    settled = faulty.time_s >= DROPOUT_SETTLED_FROM_S
    p_faulty = _max_norm(faulty.position_error_W[settled])
    p_clean = _max_norm(clean.position_error_W[settled])
    assert p_faulty <= 1.5 * p_clean + 0.02, f"max |p~| {p_faulty:.3f} m with dropouts, {p_clean:.3f} m without"
    if kind == "composite":
        assert p_faulty <= 0.10
        assert _max_norm(faulty.velocity_error_W[settled]) <= 0.15


# ==================================================================================================
# 4. The composite controller adapts toward the plant
# ==================================================================================================

def test_composite_adapts_toward_the_plant(vehicle):
    """theta-hat[CTz] moves from theta_0 to the plant's 10 % lower CTz; prediction error < 0.05 g.

    Plant: CTz = 0.9 x Table I (= theta_0), unmodelled effects off, perfect sensors; hover in
    still air for 10 s, then 9 m/s for 15 s; composite controller. References: the plant's truth
    ``vehicle.theta_scaled[1] * 0.9``, and eq:prediction_error.

    * at the end of the hover, |theta-hat[CTz] - truth| < 0.5 % of the truth: in still air the
      z row of the regressor is CTz's column alone, so CTz is identified (measured 0.006 %);
    * at the end, theta-hat[CTz] is closer to the truth than theta_0, by at least a factor 2
      (measured error 0.30 against 2.87, 1.1 % against 11 %). At a single operating point the
      wind adds aerodynamic columns that CTz trades off against, and the sigma term pulls the
      unidentified combination back toward theta_0 with a time constant ~1 / (sigma P0_CTz) =
      50 s (after 70 s at 9 m/s the error is 6.6 %): hence the short wind segment;
    * RMS of |e| (pred_err_*) over the last 5 s < 0.05 g (measured 5e-5 g).
    """
    truth_CTz = 0.9 * vehicle.theta_scaled[1]
    thr = _throttle_pct(9.0)
    r = _run("adapt_CTz", 25.0, [[0.0, 0.0], [10.0, 0.0], [10.0, thr], [25.0, thr]],
             plant=dict(UNMODELLED_OFF, coefficients={"CTz": 0.9 * vehicle.force_model.CTz}),
             sensors=IDEAL_SENSORS, controller={"kind": "composite"})
    assert r.metadata["theta_true_scaled"][1] == pytest.approx(truth_CTz, rel=1e-12)
    t = r.time_s
    CTz_hat = r["theta_hat_CTz"]
    theta0_CTz = vehicle.theta_scaled[1]
    assert CTz_hat[0] == pytest.approx(theta0_CTz, rel=1e-12)

    end_of_hover = np.searchsorted(t, 10.0) - 1
    assert np.all(r.wind_W[end_of_hover] == 0.0)  # still in the still-air segment
    assert abs(CTz_hat[end_of_hover] - truth_CTz) < 0.005 * truth_CTz

    final_err = abs(CTz_hat[-1] - truth_CTz)
    prior_err = abs(theta0_CTz - truth_CTz)
    assert final_err < 0.5 * prior_err, f"theta-hat[CTz] error {final_err:.3g}, theta_0's {prior_err:.3g}"

    e = r.columns_like(("pred_err_x_mps2", "pred_err_y_mps2", "pred_err_z_mps2"))[t >= 20.0]
    rms_g = float(np.sqrt(np.mean(np.sum(e ** 2, axis=1)))) / GRAVITY_MPS2
    assert rms_g < 0.05, f"prediction error RMS {rms_g:.3g} g over the last 5 s"


def test_paper_forgetting_winds_up_in_still_air_and_the_shipped_law_does_not(vehicle):
    """Covariance wind-up (README "Deviations from the paper"), against its analytic rate.

    Hover in still air with perfect sensors: the aircraft holds still, so the true incident velocity
    and with it the regressor's aerodynamic columns (C_D0's is ``V^2``) are zero. There the paper's
    ``Gamma' = W^T W - lambda Gamma`` is ``Gamma' = -lambda Gamma``: the information decays as
    ``e^{-lambda t}`` and P's diagonal grows as ``P0 e^{lambda t}`` (e^10 = 22 026 after 20 s at
    lambda = 0.5 /s). The shipped ``Gamma' = W^T W - lambda (Gamma - Gamma_0)`` keeps
    ``Gamma >= Gamma_0``, i.e. ``P <= P0``, and leaves an unexcited direction at P0.
    """
    duration_s, lam = 20.0, 0.5
    P = {}
    for mode in ("paper", "prior"):
        r = _run(f"windup_{mode}", duration_s, [[0.0, 0.0], [duration_s, 0.0]], sensors=IDEAL_SENSORS,
                 controller={"kind": "composite", "composite": {"forgetting": mode, "forgetting_lambda": lam}})
        P[mode] = {n: r[f"P_diag_{n}"] for n in ("CTz", "CD0")}
        t = r.time_s
    P0_CD0 = P["prior"]["CD0"][0]
    growth = P["paper"]["CD0"] / P0_CD0
    np.testing.assert_allclose(growth, np.exp(lam * t), rtol=1e-6)   # at every logged tick
    assert P["paper"]["CD0"][-1] > 2e4 * P0_CD0
    np.testing.assert_allclose(P["prior"]["CD0"], P0_CD0, rtol=1e-9)     # unexcited: held at P0
    assert np.all(P["prior"]["CTz"] <= P["prior"]["CTz"][0] * (1 + 1e-12))  # excited: below P0
