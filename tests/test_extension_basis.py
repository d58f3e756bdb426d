"""A force-model basis from a module outside the package (``tests/example_basis.py``), registered by a call.

The how-to "Adding a force-model basis" (docs/howto/adding-a-basis.md) is this recipe: the paper's eight columns and a side force
``f_y = (rho S / 2m) V^2 beta C_Y`` (nine parameters), registered after import and then named by a
vehicle file or a scenario's ``[controller] basis``. Checked against independent references:

* its regressor: the paper's columns bit for bit (:func:`vtoladapt.forces.regressor_rows`) and the
  side-force column from its formula in numpy;
* replay (open loop, the composite law) on a log whose accelerometer is the paper's model plus a
  side force of C_Y = -0.3: the basis recovers C_Y and explains the force, the paper's cannot;
* the Bayesian fit on a virtual tunnel with that side force: the posterior of all nine coefficients
  and k1, k2 within 4 standard deviations of the truth, its file naming the basis, which only a
  controller flying that basis accepts;
* ``simulate`` (the theta-hat and P columns are the basis's; without a plant truth in this basis the
  logged Lyapunov function is its tracking terms alone, as documented) and the Gymnasium environment
  (its zero-residual run is the simulator's log bit for bit).
"""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

import example_basis
from test_gym import short_hold
from vtoladapt import components, forces, load_vehicle, simulate
from vtoladapt.bases import BASES, describe_basis, evaluate, input_rows
from vtoladapt.config import ConfigError
from vtoladapt.frames import quat_from_euler, quat_to_rotmat
from vtoladapt.sim.scenario import scenario_from_mapping
from vtoladapt.vehicle import PARAMETER_NAMES

CY_TRUE = -0.3
"""The simulated aircraft's side-force slope (the plant's default ``CY_beta_per_rad``)."""


@pytest.fixture(scope="module")
def registered():
    """The example basis registered (after the package was imported), removed again afterwards."""
    assert "paper_cy" not in BASES
    components.register("basis", example_basis.INFO)
    yield example_basis.INFO
    BASES.unregister("paper_cy")


@pytest.fixture(scope="module")
def spec(registered):
    return describe_basis(load_vehicle("caltech_vtol"), "paper_cy")


def _side_force(veh, v_i_B):
    """``(rho S / 2m) V^2 asin(v_y / V)`` per row (numpy): the C_Y column's body-y entry."""
    V = np.linalg.norm(v_i_B, axis=1)
    beta = np.arcsin(np.clip(v_i_B[:, 1] / np.where(V > 0.0, V, 1.0), -1.0, 1.0))
    return veh.aero_scale_per_m * V ** 2 * beta


def test_the_regressor_is_the_papers_columns_and_the_side_force(spec, rng):
    veh = load_vehicle("caltech_vtol")
    assert spec.n == 9 and spec.names == PARAMETER_NAMES + ("CY",)
    v = rng.normal(size=(200, 3)) * 6.0
    u_x, u_z = rng.uniform(0, 1, 200), rng.uniform(0, 1, 200)
    Phi = evaluate(spec, input_rows(v, u_x, u_z, veh.model_kernel))
    np.testing.assert_array_equal(Phi[:, :, :8], forces.regressor_rows(v, u_x, u_z, veh.model_kernel))
    np.testing.assert_allclose(Phi[:, 1, 8], _side_force(veh, v), rtol=1e-13)
    np.testing.assert_array_equal(Phi[:, [0, 2], 8], 0.0)


def test_a_vehicle_file_names_the_basis_and_gives_its_prior(registered, tmp_path):
    text = open(load_vehicle("caltech_vtol").source_path).read()
    assert re.search(r'^basis = "paper" ', text, flags=re.M)          # the shipped file names its basis
    path = tmp_path / "v.toml"
    path.write_text(re.sub(r'^basis = "paper"', 'basis = "paper_cy"', text, flags=re.M) + "\n[basis_settings.paper_cy]\nCY_mean = -0.2\nCY_std = 0.1\n")
    veh = load_vehicle(path)
    spec = describe_basis(veh)
    assert spec.id == "paper_cy" and spec.theta_table[-1] == -0.2 and spec.std_table[-1] == 0.1
    np.testing.assert_array_equal(spec.theta_table[:8], veh.force_model.as_table_theta())
    path.write_text(text + "\n[basis_settings.paper_cy]\nCY_typo = 1.0\n")
    with pytest.raises(ConfigError, match=r"v\.toml: \[basis_settings\.paper_cy\] CY_typo = 1\.0: unknown key"):
        describe_basis(load_vehicle(path), "paper_cy")
    with pytest.raises(ConfigError, match="basis = 'no_such_basis': unknown force-model basis; allowed: paper"):
        describe_basis(veh, "no_such_basis")


def _flight_log(veh, cy, duration_s=20.0, rate_hz=250.0):
    """A log whose accelerometer is the paper's model plus the side force ``cy`` (exact pitot, no wind)."""
    from vtoladapt import models
    from vtoladapt.replay.flightlog import FlightLog

    n = int(duration_s * rate_hz)
    t = np.arange(n) / rate_hz
    q = np.array([quat_from_euler(0.4 + 0.1 * np.sin(0.2 * s), 0.08 * np.sin(0.5 * s), 0.1 * np.sin(0.3 * s))
                  for s in t])
    V = 3.5 + 6.0 * t / duration_s
    alpha = 0.12 * np.sin(0.7 * t)
    v_B = np.column_stack([V * np.cos(alpha), 1.5 * np.sin(0.4 * t), V * np.sin(alpha)])
    u_x = 30.0 + 10.0 * np.sin(0.6 * t)
    u_z = 55.0 + 15.0 * np.sin(0.9 * t)
    f_B = np.array([models.body_force(v_B[k], u_x[k], u_z[k], veh) for k in range(n)])
    f_B[:, 1] += cy * _side_force(veh, v_B)
    v_W = np.einsum("kij,kj->ki", np.array([quat_to_rotmat(qk) for qk in q]), v_B)
    return FlightLog(source="synthetic", log_format="csv-folder", rate_hz=rate_hz, t0_us=0, t_s=t, q_WB=q,
                     v_W_mps=v_W, wind_W_mps=np.zeros((n, 3)), airspeed_pitot_mps=V, v_i_B_mps=v_B,
                     v_i_from_pitot=np.ones(n, bool), f_meas_B_mps2=f_B, throttle_x_pct=u_x, throttle_z_pct=u_z,
                     landed=np.zeros(n, bool))


def test_the_command_line_lists_the_registered_basis(registered, capsys):
    from vtoladapt.cli import main

    assert main(["bases"]) == 0
    out = capsys.readouterr().out
    assert "paper_cy" in out and "9 parameters: CTx [m/s^2 per %^2]" in out and "CY [1/rad]" in out


def test_replay_with_the_basis_recovers_the_side_force(spec):
    from vtoladapt.replay import ReplaySettings, run_replay

    veh = load_vehicle("caltech_vtol")
    # 40 s: the rotor side force's column (C_S) shares the body-y axis with C_Y and takes part of the
    # force at first (C_S 1.4 x its truth after 20 s); the sideslip's variety separates them in time
    log = _flight_log(veh, CY_TRUE, duration_s=40.0)
    settings = ReplaySettings(motor_lag=False)
    r = run_replay(log, veh, settings, basis=spec)
    assert r.theta_hat.shape == (log.n, 9) and r.names[-1] == "CY"
    assert r.theta_hat[0, 8] == 0.0 and r.theta_hat[-1, 8] == pytest.approx(CY_TRUE, rel=0.03)
    assert r.theta_hat[-1, 2] == pytest.approx(r.theta_0[2], rel=0.1)
    e_y = np.abs(r.e_mps2[-250:, 1]).max()
    paper = run_replay(log, veh, settings)                   # the paper's basis has no side-force column
    assert paper.theta_hat.shape == (log.n, 8)
    assert e_y < 0.05 * np.abs(paper.e_mps2[-250:, 1]).max()


def test_the_bayesian_fit_recovers_the_side_force_and_writes_its_basis(spec, tmp_path):
    from vtoladapt.fitting import bayes, tunnel
    from vtoladapt.fitting.posterior import (PosteriorError, apply_posterior, controller_prior, load_posterior,
                                             posterior_dict_from_fit, write_posterior)

    veh = load_vehicle("caltech_vtol")
    paper_truth = tunnel.linear_model_truth(veh.force_model, veh)

    def truth(v_i_B, u_x, u_z, wing_on, rho):
        f = paper_truth(v_i_B, u_x, u_z, wing_on, rho)
        f[:, 1] += CY_TRUE * _side_force(veh, v_i_B) * rho / veh.envelope.air_density_kgpm3
        return f

    run = tunnel.run_virtual_tunnel(veh, np.random.default_rng(0), truth=truth)
    fit = bayes.fit_table1(run.data, veh, np.random.default_rng(1), basis=spec,
                           settings=bayes.SamplerSettings(min_steps=800, max_steps=800, n_burn=200))
    s = fit.summary()
    expected = dict(zip(spec.names, spec.theta_table[:8].tolist() + [CY_TRUE]))
    expected.update(k1=veh.force_model.k1, k2=veh.force_model.k2)
    z = {n: (s[n]["mean"] - v) / s[n]["std"] for n, v in expected.items()}
    assert all(abs(v) < 4.0 for v in z.values()), z
    assert s["CY"]["std"] < 0.05                               # the rotor sweep's sideslip identifies it
    post = posterior_dict_from_fit(fit)
    assert post["basis"] == "paper_cy" and post["basis_names"] == list(spec.names)
    path = write_posterior(tmp_path / "posterior.json", post)
    assert json.loads(path.read_text())["parameters"]["CY"]["unit"] == "1/rad"
    prior = controller_prior(load_posterior(path), veh)
    assert prior.theta_0_scaled.shape == (9,) and prior.upper_bounds_scaled[8] <= 0.0   # C_Y's sign kept
    with pytest.raises(PosteriorError, match="basis = 'paper_cy': the controller flies the 'paper' basis"):
        apply_posterior(veh, path)
    assert apply_posterior(veh, path, basis="paper_cy")[1].theta_0_scaled[8] == pytest.approx(s["CY"]["mean"])


def _side_wind_scenario(duration_s=6.0):
    return {"name": "paper-cy", "vehicle": "caltech_vtol", "duration_s": duration_s, "seed": 4,
            "wind": {"fan_array": {"schedule": [[0.0, 0.0], [1.0, 50.0], [duration_s, 50.0]],
                                   "array_bearing_deg": 30.0}},
            "controller": {"kind": "composite", "basis": "paper_cy"}}


def test_the_basis_flies_in_simulate(registered):
    r = simulate(scenario_from_mapping(_side_wind_scenario(), "tests/test_extension_basis.py"))
    assert r.diverged_at_s is None
    assert r.metadata["basis"] == "paper_cy" and r.theta_names[-1] == "CY"
    assert r.theta_hat.shape[1] == 9 and "P_diag_CY" in r
    assert np.all(np.isfinite(r.theta_hat)) and np.all(r.theta_hat[:, 8] <= 0.0)
    assert np.abs(r.position_error_W).max() < 0.5
    # no plant truth in this basis: the Lyapunov function is its tracking terms, the parameter term left out
    assert r.metadata["theta_true_scaled"] == []
    np.testing.assert_array_equal(r["lyapunov_V"], r["lyap_velocity_term_m2ps2"] + r["lyap_attitude_term"])


def test_the_basis_flies_in_the_gym_as_in_simulate(registered):
    """residual=True, zero action: the environment's run is the simulator's, bit for bit."""
    from vtoladapt.gym import HoldEnv
    from vtoladapt.gym.spaces import OBS_CMD

    data = short_hold(0.4)
    data["controller"] = {"kind": "composite", "basis": "paper_cy"}
    env = HoldEnv(scenario=data, residual=True)
    obs, _ = env.reset(seed=3)
    observations = [obs]
    for _ in range(env.max_steps - 1):
        obs, _, terminated, truncated, _ = env.step(np.zeros(5))
        assert not terminated and not truncated
        observations.append(obs)
    log = simulate(env.episode_scenario)
    assert log.metadata["basis"] == "paper_cy"
    u_max = env._batch.u_max
    np.testing.assert_array_equal(np.array(observations)[:, OBS_CMD + 1],
                                  (2.0 * log["cmd_u_z_frac"] / u_max - 1.0).astype(np.float32))
