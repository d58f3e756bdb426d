"""The learned basis: the compiled network against the training's numpy forward pass, the basis file's
refusals, the meta-learning gradient against finite differences, and span recovery on a synthetic
family of tasks that share a known basis."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.linalg import subspace_angles

from vtoladapt import load_vehicle
from vtoladapt.bases import describe_basis, evaluate, input_rows
from vtoladapt.bases import learned
from vtoladapt.bases.netfile import FEATURES, N_FEATURES, NetFile, features_rows, net_rows, read_net, write_net
from vtoladapt.config import ConfigError
from vtoladapt.frames import quat_to_rotmat_rows
from vtoladapt.learn.meta import MetaSettings, Objective, Task, flatten, init_arrays, train

VEHICLES = ("caltech_vtol", "px4_standard_vtol")


def random_rows(veh, n=300, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    return input_rows(rng.normal(size=(n, 3)) * 6.0, rng.random(n), rng.random(n), veh.model_kernel,
                      valid=(rng.random(n) > 0.3).astype(float), q_WB=q, omega_B=rng.normal(size=(n, 3)),
                      v_W=rng.normal(size=(n, 3)))


def random_net(vehicle="caltech_vtol", h=3, hidden=(7, 5), seed=1) -> NetFile:
    rng = np.random.default_rng(seed)
    H1, H2 = hidden
    return NetFile(x_mean=rng.normal(size=N_FEATURES), x_std=rng.uniform(0.5, 2.0, N_FEATURES),
                   W1=rng.normal(size=(H1, N_FEATURES)), b1=rng.normal(size=H1), W2=rng.normal(size=(H2, H1)),
                   b2=rng.normal(size=H2), W3=rng.normal(size=(3 * h, H2)), b3=rng.normal(size=3 * h),
                   theta_mean=rng.normal(size=h), theta_std=rng.uniform(0.1, 1.0, h),
                   meta={"vehicle": vehicle, "physics": "extended", "draws": []})


def vehicle_with(tmp_path, name, **settings):
    from vtoladapt.vehicle import VEHICLE_DIR

    lines = [f"{k} = {json.dumps(v)}" for k, v in settings.items()]
    path = tmp_path / f"{name}_learned.toml"
    path.write_text((VEHICLE_DIR / f"{name}.toml").read_text() + "\n[basis_settings.learned]\n" + "\n".join(lines)
                    + "\n")
    return load_vehicle(path)


def test_features_match_the_attitude_convention():
    veh = load_vehicle("caltech_vtol")
    x = random_rows(veh, 20)
    z = features_rows(x)
    for i in range(len(x)):
        R = np.array(quat_to_rotmat_rows(x[i, 9:13] if False else x[i, _q_slice()]))
        np.testing.assert_allclose(z[i, 10:13], R[2], atol=1e-12)   # world down in body axes: R_WB^T e_3


def _q_slice():
    from vtoladapt.bases import IN_Q_WB

    return slice(IN_Q_WB, IN_Q_WB + 4)


@pytest.mark.parametrize("source", ["random", *VEHICLES])
def test_compiled_network_equals_the_numpy_forward_pass(tmp_path, source):
    """The compiled regressor's learned columns equal the training's forward pass to 1e-12 (float64), and its
    first 13 columns are the extended basis's."""
    veh = load_vehicle("caltech_vtol" if source == "random" else source)
    if source == "random":
        path = write_net(tmp_path / "net.npz", random_net())
        veh = vehicle_with(tmp_path, "caltech_vtol", file=str(path))
    else:
        path = learned.TRAINED_DIR / f"{source}.npz"
    net = read_net(path)
    spec = describe_basis(veh, "learned")
    assert spec.n == 13 + net.h and spec.names[13:] == tuple(f"net{j}" for j in range(net.h))
    x = random_rows(veh)
    phi = evaluate(spec, x)
    np.testing.assert_allclose(phi[:, :, 13:], net_rows(net, x), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(phi[:, :, :13], evaluate(describe_basis(veh, "extended"), x))
    np.testing.assert_allclose(spec.theta_table[13:], net.theta_mean)


def _mutate(tmp_path, **change) -> str:
    net = random_net()
    path = tmp_path / "bad.npz"
    arrays = net.arrays()
    meta = {"format": "vtoladapt-learned-basis-1", "features": list(FEATURES), **net.meta}
    for k, v in change.items():
        if k in arrays:
            arrays[k] = v
        else:
            meta[k] = v
    with open(path, "wb") as fh:
        np.savez(fh, meta=np.array(json.dumps(meta)), **arrays)
    return str(path)


@pytest.mark.parametrize("change, message", [
    ({"W2": np.zeros((5, 6))}, r"W2 has shape \(5, 6\); allowed: \(5, 7\)"),
    ({"b3": np.zeros(8)}, r"b3 has shape \(8,\); allowed: \(9,\)"),
    ({"W1": np.full((7, N_FEATURES), np.nan)}, r"W1 holds 112 non-finite values; allowed: finite"),
    ({"features": list(FEATURES[:-1]) + ["accel_x_mps2"]}, r"features = .*accel_x_mps2.*allowed: \["),
    ({"format": "something-else"}, r"format = 'something-else'; allowed: 'vtoladapt-learned-basis-1'"),
    ({"x_std": np.zeros(N_FEATURES)}, r"member x_std holds 0; allowed: >= 1e-06 and <= 1000"),
])
def test_a_bad_basis_file_is_refused_in_one_line(tmp_path, change, message):
    path = _mutate(tmp_path, **change)
    with pytest.raises(ConfigError, match=message) as err:
        read_net(path)
    assert str(err.value).startswith(path) and "\n" not in str(err.value)


def test_another_vehicles_network_is_refused_unless_allowed(tmp_path):
    path = write_net(tmp_path / "px4.npz", random_net(vehicle="px4_standard_vtol"))
    veh = vehicle_with(tmp_path, "caltech_vtol", file=str(path))
    with pytest.raises(ConfigError, match=r"vehicle = 'px4_standard_vtol': trained on another vehicle's flights, "
                                          r"flown on 'caltech_vtol'; allowed") as err:
        describe_basis(veh, "learned")
    assert "\n" not in str(err.value)
    veh = vehicle_with(tmp_path, "caltech_vtol", file=str(path), allow_other_vehicle=True)
    assert describe_basis(veh, "learned").n == 16


def test_not_a_basis_file(tmp_path):
    p = tmp_path / "x.npz"
    p.write_text("hello")
    with pytest.raises(ConfigError, match=r"x\.npz: not a learned basis file"):
        read_net(p)
    with pytest.raises(ConfigError, match="not found"):
        read_net(tmp_path / "missing.npz")


def assert_gradient_matches_central_differences(obj, w, like, rng, n=25, step=1e-6):
    """``obj``'s analytic gradient at ``w`` against central differences in ``n`` random coordinates."""
    _, g = obj(w, like)
    for i in rng.choice(w.size, n, replace=False):
        e = np.zeros_like(w)
        e[i] = step
        fd = (obj(w + e, like)[0] - obj(w - e, like)[0]) / (2 * step)
        assert g[i] == pytest.approx(fd, rel=1e-5, abs=1e-9)


def test_meta_learning_gradient_matches_finite_differences():
    rng = np.random.default_rng(1)
    tasks = [Task(z=rng.normal(size=(40, N_FEATURES)), A=rng.normal(size=(40, 3, 2)), y=rng.normal(size=(40, 3)))
             for _ in range(3)]
    s = MetaSettings(h=3, hidden=(5, 4), weight_decay=1e-3)
    like = init_arrays(s, rng)
    obj = Objective(tasks, np.zeros(2), np.ones(2), s)
    w = flatten(like)
    assert_gradient_matches_central_differences(obj, w, like, rng)


def test_adversarial_gradient_matches_finite_differences():
    """The meta-learning loss plus the confusion term, the classifier held: the gradient is exact."""
    from vtoladapt.learn.meta import fit_discriminator

    rng = np.random.default_rng(2)
    tasks = [Task(z=rng.normal(size=(40, N_FEATURES)), A=rng.normal(size=(40, 3, 2)), y=rng.normal(size=(40, 3)),
                  condition=i % 2) for i in range(4)]
    s = MetaSettings(h=3, hidden=(5, 4), weight_decay=1e-3, adversarial=0.7)
    like = init_arrays(s, rng)
    obj = Objective(tasks, np.zeros(2), np.ones(2), s)
    assert obj.n_conditions == 2
    w = flatten(like)
    from vtoladapt.bases.netfile import forward

    obj.discriminator = fit_discriminator(forward(like, obj.z)[0], obj.labels, obj.sample_weight, 2)
    plain = Objective(tasks, np.zeros(2), np.ones(2), s)
    assert obj(w, like)[0] > plain(w, like)[0]        # the term is on and positive away from confusion
    assert_gradient_matches_central_differences(obj, w, like, rng)


def _condition_tasks(rng, conditions, per_condition=4, n=80):
    """Flights y = g(x) a_t + f_c: one shared column of the first features with the flight's own weight, and a
    force f_c of the flight's condition (three axes: more than the other learned column can carry as a weight).
    One input, z[:, 15], is the condition's signature: it tells the conditions apart and explains nothing else."""
    tasks = []
    for c in conditions:
        f_c = np.array([1.0, -0.5, 0.8]) * np.cos(c) + np.array([-0.3, 0.9, 0.4]) * np.sin(1.7 * c)
        for _ in range(per_condition):
            z = rng.normal(size=(n, N_FEATURES))
            z[:, 15] = 0.8 * c + 0.1 * rng.normal(size=n)
            g = np.stack([np.sin(z[:, 0]), np.tanh(z[:, 3]), 0.5 * z[:, 5] ** 2], axis=1)
            y = g * (2.0 * rng.normal()) + f_c + 0.01 * rng.normal(size=(n, 3))
            tasks.append(Task(z=z, A=np.zeros((n, 3, 0)), y=y, condition=c))
    return tasks


def test_the_adversarial_term_hides_the_condition_from_the_basis():
    """Without the term the trained network carries part of each condition's force by recognising the
    condition from its signature: a classifier tells the four conditions from its outputs far above chance.
    The term takes that away in proportion to its weight, at a price in fit (the trade Neural-Fly makes)."""
    tasks = _condition_tasks(np.random.default_rng(11), conditions=(0, 1, 2, 3))
    common = dict(h=2, hidden=(12, 12), sigma_y=0.01, net_weight_std=10.0, weight_decay=1e-6, max_iter=240, seed=0)
    runs = {a: train(tasks, np.zeros(0), np.zeros(0), MetaSettings(**common, adversarial=a, adversarial_rounds=6))
            for a in (0.0, 0.5)}
    acc = {a: r.condition_accuracy for a, r in runs.items()}
    print("condition accuracy", acc, "chance", runs[0.5].condition_chance, "loss", {a: r.loss[-1] for a, r in runs.items()})
    assert runs[0.0].condition_chance == pytest.approx(1 / 4)
    assert acc[0.0] > 0.5                      # chance: 0.25
    assert acc[0.5] < acc[0.0] - 0.15
    assert runs[0.5].loss[-1] > runs[0.0].loss[-1]   # the last entry is the meta-learning loss alone


def _true_basis(z):
    """A known smooth 3 x 2 basis of the features."""
    return np.stack([np.stack([np.sin(z[:, 0]), z[:, 1] * z[:, 2]], axis=1),
                     np.stack([np.tanh(z[:, 3]), np.cos(z[:, 4])], axis=1),
                     np.stack([0.5 * z[:, 5] ** 2, np.sin(z[:, 6] + z[:, 0])], axis=1)], axis=1)


def test_training_recovers_the_span_of_a_shared_basis():
    """Tasks y_t = phi*(x) a_t + noise, a_t drawn per task: the learned columns span phi*'s columns on samples
    never seen in training (the largest principal angle is small), and they explain held-out tasks."""
    rng = np.random.default_rng(7)

    def tasks(n_tasks, n):
        out = []
        for _ in range(n_tasks):
            z = rng.normal(size=(n, N_FEATURES))
            a = rng.normal(size=2) * 2.0
            out.append(Task(z=z, A=np.zeros((n, 3, 0)), y=_true_basis(z) @ a + 0.01 * rng.normal(size=(n, 3))))
        return out

    s = MetaSettings(h=3, hidden=(16, 16), sigma_y=0.01, net_weight_std=10.0, weight_decay=1e-6, max_iter=400,
                     seed=0)
    res = train(tasks(16, 120), np.zeros(0), np.zeros(0), s)
    z = rng.normal(size=(400, N_FEATURES))
    from vtoladapt.bases.netfile import forward

    learned_cols = forward(res.arrays, z)[0].reshape(-1, 3, 3).reshape(-1, 3)   # (3 N, h)
    true_cols = _true_basis(z).reshape(-1, 2)
    angles = np.degrees(subspace_angles(true_cols, learned_cols))
    print("principal angles (deg):", angles)
    assert angles.max() < 10.0, angles
    # a random network of the same size does not span it
    s0 = MetaSettings(h=3, hidden=(16, 16), seed=0)
    rand_cols = forward(init_arrays(s0, np.random.default_rng(0)), z)[0].reshape(-1, 3)
    assert np.degrees(subspace_angles(true_cols, rand_cols)).max() > 30.0
    assert res.loss[-1] < 0.05 * res.loss[0]


def test_training_is_reproducible_for_a_seed():
    rng = np.random.default_rng(3)
    t = [Task(z=rng.normal(size=(60, N_FEATURES)), A=rng.normal(size=(60, 3, 2)), y=rng.normal(size=(60, 3)))
         for _ in range(3)]
    s = MetaSettings(h=2, hidden=(6, 6), max_iter=15, seed=4)
    a, b = train(t, np.zeros(2), np.ones(2), s), train(t, np.zeros(2), np.ones(2), s)
    for k in a.arrays:
        np.testing.assert_array_equal(a.arrays[k], b.arrays[k])
    c = train(t, np.zeros(2), np.ones(2), MetaSettings(h=2, hidden=(6, 6), max_iter=15, seed=5))
    assert not np.array_equal(a.arrays["W1"], c.arrays["W1"])


@pytest.mark.parametrize("name", VEHICLES)
def test_shipped_basis_files_say_how_they_were_made(name):
    net = read_net(learned.TRAINED_DIR / f"{name}.npz")
    assert net.vehicle == name and net.physics == "extended"
    assert net.meta["command"].startswith("vtoladapt learn-basis")
    assert net.meta["campaign_seed"] != 1111          # not the envelope campaign's evaluation seed
    draws = net.meta["draws"]
    assert len(draws) >= 20 and all(d["choice.vehicle"] == name for d in draws)
    held = net.meta["held_out"]
    assert all(d["choice.fan_schedule"] not in held["fan_schedules"] for d in draws)
    for lo, hi in held["bearing_sectors_deg"]:
        assert not any(lo <= d["wind.fan_array.array_bearing_deg"] % 360 < hi for d in draws)
    assert net.meta["summary"]["train_seconds"] < 600


def test_the_shipped_basis_beats_the_physics_alone_on_flights_it_never_saw():
    """On evaluation draws (the envelope campaign's seed 1111, not the training's 2222), with the inputs the
    controller has (the probe's reading or its fallback, the lagged throttles: what the network was trained
    on), the learned basis's best constant fit leaves a smaller residual than the extended physics alone on
    every draw: what the network learned generalises to flights it never saw."""
    from vtoladapt.bases import evaluate as ev
    from vtoladapt.campaign.runner import plan_campaign_file
    from vtoladapt.learn.data import flight_from_result
    from vtoladapt.learn.evaluate import CAMPAIGN
    from vtoladapt.sim.driver import simulate
    from vtoladapt.sim.scenario import scenario_from_mapping

    _, specs = plan_campaign_file(CAMPAIGN, runs=4, seed=1111)
    rms = {"extended": [], "learned": []}
    for s in [s for s in specs if s.controller == "composite"]:
        sc = scenario_from_mapping(s.mapping, s.source, source_path=s.source)
        veh = sc.load_vehicle()
        flight = flight_from_result(simulate(sc), veh, stride=5)
        for b in rms:
            spec = describe_basis(veh, b)
            A = ev(spec, flight.x).reshape(-1, spec.n)
            y = flight.f.reshape(-1)
            theta, *_ = np.linalg.lstsq(A, y, rcond=None)
            rms[b].append(math.sqrt(np.mean((y - A @ theta) ** 2)))
    assert all(a < b for a, b in zip(rms["learned"], rms["extended"])), rms
    assert np.mean(rms["learned"]) < 0.8 * np.mean(rms["extended"]), rms
