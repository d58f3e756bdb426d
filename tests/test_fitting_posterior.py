"""posterior.json: round trip, validation, and the controller prior derived from it."""
import json

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

import vtoladapt
from conftest import examples
from vtoladapt import models
from vtoladapt.fitting import bayes, tunnel
from vtoladapt.fitting.posterior import (POSTERIOR_FORMAT, POSTERIOR_NAMES, PosteriorError,
                                         apply_posterior, controller_prior, load_posterior,
                                         posterior_dict_from_fit, posterior_from_dict,
                                         vehicle_with_posterior, write_posterior)
from vtoladapt.control.step import default_theta_bounds
from vtoladapt.vehicle import PARAMETER_NAMES, parameter_signs


@pytest.fixture(scope="module")
def veh():
    return vtoladapt.load_vehicle("caltech_vtol")


@pytest.fixture(scope="module")
def fitted(veh):
    design = tunnel.make_design(wing_airspeeds_mps=[5.0, 9.0], wing_alpha_step_deg=5.0,
                                rotor_airspeeds_mps=[3.0, 9.0], rotor_alpha_step_deg=15.0)
    run = tunnel.run_virtual_tunnel(veh, np.random.default_rng(0), design=design)
    fit = bayes.fit_table1(run.data, veh, np.random.default_rng(1), settings=bayes.SamplerSettings.fast())
    t = run.truth
    return fit, posterior_dict_from_fit(fit, truth_theta_table=t.as_table_theta(), truth_k=(t.k1, t.k2),
                                        settings=bayes.SamplerSettings.fast())


def hand_posterior(means: dict, stds: dict) -> dict:
    return {"format": POSTERIOR_FORMAT, "format_version": 1,
            "parameters": {n: {"mean": means[n], "std": stds[n]} for n in POSTERIOR_NAMES}}


def table1(veh):
    fm, fs = veh.force_model, veh.force_model_std
    return ({n: getattr(fm, n) for n in POSTERIOR_NAMES}, {n: getattr(fs, n) for n in POSTERIOR_NAMES})


def test_round_trip(fitted, tmp_path):
    fit, d = fitted
    path = write_posterior(tmp_path / "posterior.json", d)
    post = load_posterior(path)
    s = fit.summary()
    np.testing.assert_array_equal(post.theta_table, [s[n]["mean"] for n in PARAMETER_NAMES])
    np.testing.assert_array_equal(post.std_table, [s[n]["std"] for n in PARAMETER_NAMES])
    assert post.k1 == s["k1"]["mean"] and post.k2 == s["k2"]["mean"]
    assert post.covariance.shape == (10, 10)
    np.testing.assert_allclose(np.sqrt(np.diag(post.covariance)), [s[n]["std"] for n in POSTERIOR_NAMES],
                               rtol=1e-9)
    raw = json.loads(path.read_text())
    for key in ("diagnostics", "priors", "data", "noise", "reference", "truth_check"):
        assert key in raw
    assert raw["data"]["n_rows"] == fit.table1_data.n_rows
    assert set(raw["diagnostics"]["rhat_split"]) >= set(POSTERIOR_NAMES)
    assert raw["parameters"]["CTx"]["unit"] == "m/s^2 per %^2"
    assert load_posterior(write_posterior(tmp_path / "again.json", raw)).raw == raw


@pytest.mark.parametrize("mutate,fragment", [
    (lambda d: d.update(format="other"), "format"),
    (lambda d: d.update(format_version=99), "format_version"),
    (lambda d: d["parameters"].pop("CS"), "parameters.CS: missing"),
    (lambda d: d["parameters"]["CL1"].update(mean=float("nan")), "parameters.CL1.mean"),
    (lambda d: d["parameters"]["CD0"].update(std=-1.0), "parameters.CD0.std"),
    (lambda d: d["parameters"]["k1"].update(mean=2.5), "parameters.k1.mean"),
    (lambda d: d["parameters"]["k2"].update(ci95=[1.0]), "parameters.k2.ci95"),
])
def test_invalid_files_are_rejected_with_the_key(veh, tmp_path, mutate, fragment):
    d = hand_posterior(*table1(veh))
    mutate(d)
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(d))
    with pytest.raises(PosteriorError) as info:
        load_posterior(p)
    assert fragment in str(info.value) and str(p) in str(info.value)
    with pytest.raises(PosteriorError, match="not valid JSON"):
        (tmp_path / "x.json").write_text("{")
        load_posterior(tmp_path / "x.json")


def test_controller_prior_of_table1_is_the_vehicles_own_prior(veh):
    """A posterior equal to Table I gives theta_0 = the vehicle's theta_scaled and P0 = Table III."""
    post = posterior_from_dict(hand_posterior(*table1(veh)))
    cp = controller_prior(post, veh)
    np.testing.assert_allclose(cp.theta_0_scaled, veh.theta_scaled, rtol=1e-15)
    np.testing.assert_array_equal(cp.P0_diag_scaled, veh.adaptation.P0_diag)
    half = np.maximum(3.0 * veh.theta_std_scaled, np.array(veh.adaptation.bound_fraction) * np.abs(veh.theta_scaled))
    np.testing.assert_allclose(cp.upper_bounds_scaled - cp.theta_0_scaled, half, rtol=1e-12)
    # below, cut at zero where physics gives the sign (C_S's 1.5 |theta_0| would reach -0.5 theta_0)
    lower = np.where(parameter_signs() > 0, np.maximum(veh.theta_scaled - half, 0.0), veh.theta_scaled - half)
    np.testing.assert_allclose(cp.lower_bounds_scaled, lower, rtol=1e-12, atol=0.0)
    np.testing.assert_array_equal(cp.lower_bounds_scaled, default_theta_bounds(veh)[0])


@settings(max_examples=examples(60), deadline=None)
@given(scale=st.lists(st.floats(0.2, 5.0), min_size=10, max_size=10),
       rel_sd=st.lists(st.floats(1e-6, 2.0), min_size=10, max_size=10),
       n_sigma=st.floats(0.0, 5.0), frac=st.floats(0.0, 2.0))
# a subnormal n_sigma makes every half-width vanish below rounding: the box must still open
@example(scale=[1.0] * 10, rel_sd=[1.0] * 10, n_sigma=2.225073858507203e-309, frac=0.0)
def test_controller_prior_rule(scale, rel_sd, n_sigma, frac):
    """Bounds contain theta_0 and are exactly theta_0 -+ max(n_sigma std, fraction |theta_0|), the lower
    one cut at 0 for a coefficient physics makes non-negative."""
    veh = vtoladapt.load_vehicle("caltech_vtol")
    means, _ = table1(veh)
    means = {n: means[n] * s for n, s in zip(POSTERIOR_NAMES, scale)}
    means["k1"] = min(means["k1"], 1.99)
    means["k2"] = max(means["k2"], 1.6)
    stds = {n: abs(means[n]) * r for n, r in zip(POSTERIOR_NAMES, rel_sd)}
    post = posterior_from_dict(hand_posterior(means, stds))
    cp = controller_prior(post, veh, bound_sigmas=n_sigma, bound_fraction=[frac] * 8)
    th0 = models.theta_to_scaled(post.theta_table, post.k1)
    sd = models.theta_to_scaled(post.std_table, post.k1)
    np.testing.assert_array_equal(cp.theta_0_scaled, th0)
    assert np.all(cp.lower_bounds_scaled <= th0) and np.all(th0 <= cp.upper_bounds_scaled)
    half = np.maximum(n_sigma * sd, frac * np.abs(th0))
    # up to the rounding of (theta_0 + half) - theta_0
    assert np.all(np.abs((cp.upper_bounds_scaled - th0) - half) <= 1e-12 * (half + np.abs(th0)))
    cut = (parameter_signs() > 0) & (th0 - half < 0.0)
    assert np.all(cp.lower_bounds_scaled[cut] == 0.0)
    assert np.all(np.abs((th0 - cp.lower_bounds_scaled) - half)[~cut] <= 1e-12 * (half + np.abs(th0))[~cut])
    if n_sigma > 0:
        assert np.all(cp.upper_bounds_scaled > th0)


def test_vehicle_with_posterior_flies_the_posterior(fitted, veh, tmp_path):
    fit, d = fitted
    path = write_posterior(tmp_path / "posterior.json", d)
    v2, cp = apply_posterior(veh, path)
    post = load_posterior(path)
    assert v2.force_model.k1 == post.k1 and v2.model_kernel[2] == post.k2
    np.testing.assert_allclose(v2.theta_scaled, cp.theta_0_scaled, rtol=1e-15)
    # the controller's model of the new vehicle is Phi(v) theta_0 with the fitted k1, k2
    v = np.array([8.0, 0.5, 1.0])
    f = models.body_force(v, 20.0, 55.0, v2)
    np.testing.assert_allclose(models.regressor(v, 20.0, 55.0, v2) @ cp.theta_0_scaled, f, rtol=1e-12)
    assert v2.mass == veh.mass and v2.name == veh.name
    assert veh.force_model.k1 == 1.425     # the original is untouched


def test_vehicle_with_invalid_posterior_is_refused(veh):
    means, stds = table1(veh)
    means["CD2"] = -0.5
    with pytest.raises(PosteriorError, match="CD2"):
        vehicle_with_posterior(veh, posterior_from_dict(hand_posterior(means, stds)))
    means, stds = table1(veh)
    stds["CS"] = 0.0
    with pytest.raises(PosteriorError, match="CS"):
        vehicle_with_posterior(veh, posterior_from_dict(hand_posterior(means, stds)))
