"""The adaptation's extensions beyond the paper (issue 11): directional forgetting, model-validity
weights, the tracking law's gain rule, and the identifiability spectrum.

Each is checked against something independent: the information matrix's block structure and the
Loewner order (directional forgetting), numpy's eigen-decomposition on matrices built with known
spectra (identifiability), the Routh-Hurwitz bound computed here from the regressor (gain rule).
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import examples
from vtoladapt import forces
from vtoladapt.control import adaptation as ad
from vtoladapt.bases import IN_V_I_B
from vtoladapt.control import controller_arrays
from vtoladapt.control.blocks import A_PHI, P_V_LO, S_INPUT, S_SAT_PREV
from vtoladapt.control.laws import _adaptive, tracking_only
from vtoladapt.control.settings import ControllerConfig
from vtoladapt.experiments.metrics import IDENTIFIABILITY_SENSITIVITY_MIN_MPS2, identifiability
from vtoladapt.vehicle import PARAMETER_NAMES

N = len(PARAMETER_NAMES)
MEM = ad.memory_layout(N)


def _random_spd(rng, n=N):
    A = rng.normal(size=(n, n))
    return A @ A.T + 0.1 * np.eye(n)


def _directional_step(G, G0, W, a, b):
    out = G.ravel().copy()
    WtW = np.empty(N * N)
    ad.gram(W.ravel(), 0, WtW, 0, N)
    scratch = np.zeros(6 * N + 18)                       # D W^T, (S^-1 W D)^T, S, its factor
    ad.directional_information_update(out, 0, G0.ravel(), 0, W.ravel(), 0, WtW, 0, a, b, scratch, 0, 3 * N,
                                      6 * N, 6 * N + 9, N)
    return out.reshape(N, N)


# --- directional forgetting ------------------------------------------------------------------------

def test_directional_forgetting_keeps_the_information_of_unexcited_directions(rng):
    """W sees only parameters 0-2: the information about 3-7 is untouched (the prior law decays it)."""
    G0 = np.diag(rng.uniform(0.1, 10.0, N))
    D = np.diag(rng.uniform(1.0, 100.0, N))
    D[:3, :3] += _random_spd(rng, 3)
    G = G0 + D
    W = np.zeros((3, N))
    W[:, :3] = rng.normal(size=(3, 3))
    a, b = ad.forgetting_weights(0.5, 0.004)
    G1 = _directional_step(G, G0, W, a, b)
    np.testing.assert_array_equal(G1[3:, 3:], G[3:, 3:])
    np.testing.assert_array_equal(G1[:3, 3:], G[:3, 3:])
    # along the excited block, with W of full rank there, all the data information is forgotten at
    # the rate lambda: M = D W^T (W G W^T)^-1 W D, computed here with numpy
    M = D @ W.T @ np.linalg.inv(W @ G @ W.T) @ W @ D
    np.testing.assert_allclose(G1, G - (1 - a) * M + b * W.T @ W, rtol=1e-10, atol=1e-12)
    # the paper's forgetting toward the prior decays the unexcited block
    out = G.ravel().copy()
    WtW = (W.T @ W).ravel().copy()
    ad.information_update(out, 0, G0.ravel(), 0, WtW, 0, a, b, N)
    assert np.all(np.diag(out.reshape(N, N))[3:] < np.diag(G)[3:])


@settings(max_examples=examples(60), deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), rank=st.integers(0, 3), lam_dt=st.floats(1e-4, 5.0))
def test_directional_forgetting_stays_between_the_prior_and_the_data(seed, rank, lam_dt):
    """``Gamma_0 <= Gamma_k+1`` (SPD, P <= P0) and ``Gamma_k+1 <= Gamma_k + b W^T W`` for any W, even rank-deficient."""
    rng = np.random.default_rng(seed)
    G0 = np.diag(rng.uniform(1e-3, 1e3, N))
    G = G0 + _random_spd(rng) * rng.uniform(0.0, 1e3)
    W = np.zeros((3, N))
    W[:rank] = rng.normal(size=(rank, N)) * 10.0 ** rng.uniform(-3, 3)
    a = np.exp(-lam_dt)
    b = 0.004
    G1 = _directional_step(G, G0, W, a, b)
    assert np.array_equal(G1, G1.T)
    scale = np.abs(G).max()
    assert np.linalg.eigvalsh(G1 - G0).min() > -1e-9 * scale
    assert np.linalg.eigvalsh(G + b * W.T @ W - G1).min() > -1e-9 * scale
    if rank == 0:
        np.testing.assert_array_equal(G1, G)  # nothing excited: nothing forgotten


def _memory_with(theta, G, W, a_m):
    """``(at, x)``: the offsets table and the memory (then scratch) of one adaptation."""
    at, x, _ = ad.standalone_arrays(N)
    x[:MEM.size] = MEM.pack(THETA=theta, GAMMA=G.ravel(), W=W.ravel(), A_M=a_m)
    return at, x


def _prior(th0, G0):
    return ad.prior_layout(N).pack(THETA0=th0, THETA_INIT=th0, LOWER=-1e6, UPPER=1e6, GAMMA0=G0.ravel(),
                                   P0=np.linalg.inv(G0).ravel())


def test_zero_weights_freeze_theta_and_unit_weights_are_the_paper_step(rng):
    th0 = rng.normal(size=N)
    G0 = np.diag(rng.uniform(0.5, 2.0, N))
    G = G0 + _random_spd(rng)
    W = rng.normal(size=(3, N))
    theta = th0 + 0.1 * rng.normal(size=N)
    a_m = W @ th0 + 0.05 * rng.normal(size=3)
    Phi = rng.normal(size=3 * N)
    R = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    v_t = (0.3, -0.2, 0.1)
    fa, fb = ad.forgetting_weights(0.5, 0.004)
    at, x = _memory_with(theta, G, W, a_m)
    ad.weighted_adaptation_step(ad.ADAPT_COMPOSITE, at, 0, x, _prior(th0, G0), Phi, 0, R, v_t, 0.004, fa, fb,
                                0.0, 1e9, 0, 0.0, 0.0, False, 1.0)
    np.testing.assert_array_equal(MEM.view(x, "THETA"), theta)                # no term moves theta-hat
    np.testing.assert_allclose(MEM.view(x, "GAMMA").reshape(N, N), fa * G + (1 - fa) * G0,
                               rtol=1e-12)                                  # no data added, only forgetting
    at, x1 = _memory_with(theta, G, W, a_m)
    _, x2 = _memory_with(theta, G, W, a_m)
    ad.weighted_adaptation_step(ad.ADAPT_COMPOSITE, at, 0, x1, _prior(th0, G0), Phi, 0, R, v_t, 0.004, fa, fb,
                                1e-4, 1e9, 0, 1.0, 1.0, False, 1.0)
    ad.adaptation_step(ad.ADAPT_COMPOSITE, at, 0, x2, _prior(th0, G0), Phi, 0, R, v_t, 0.004, fa, fb, 1e-4, 1e9, 0)
    np.testing.assert_array_equal(x1[:MEM.size], x2[:MEM.size])


# --- model validity --------------------------------------------------------------------------------

def _validity(alpha_deg, V, v_lo=2.0, trust_deg=12.0, stall_deg=16.0, sat=(0.0, 0.0)):
    params = np.zeros(P_V_LO + 1)
    params[P_V_LO] = v_lo
    state = np.zeros(max(S_INPUT + IN_V_I_B, S_SAT_PREV) + 3)
    a = np.radians(alpha_deg)
    state[S_INPUT + IN_V_I_B:S_INPUT + IN_V_I_B + 3] = (V * np.cos(a), 0.0, V * np.sin(a))
    state[S_SAT_PREV:S_SAT_PREV + 2] = sat
    return (_adaptive.model_validity(params, state, np.radians(trust_deg), np.radians(stall_deg)),
            _adaptive.saturated(state))


@pytest.mark.parametrize("alpha_deg, V, expected", [
    (0.0, 9.0, 1.0), (12.0, 9.0, 1.0), (-11.0, 9.0, 1.0),
    (14.0, 9.0, 0.5), (-15.0, 9.0, 0.25), (16.0, 9.0, 0.0), (40.0, 9.0, 0.0),
    (180.0, 3.0, 0.0),                      # flow from behind: beyond stall
    (30.0, 1.0, 0.75),                      # hover: the wing's force (and error) scales with V^2
    (30.0, 0.0, 1.0),
])
def test_model_validity_is_the_stated_ramp(alpha_deg, V, expected):
    w, _ = _validity(alpha_deg, V)
    assert w == pytest.approx(expected, abs=1e-12)


def test_saturation_flag():
    assert not _validity(0.0, 5.0)[1]
    assert _validity(0.0, 5.0, sat=(1.0, 0.0))[1]
    assert _validity(0.0, 5.0, sat=(0.0, -1.0))[1]


# --- tracking-only gain rule -----------------------------------------------------------------------

def test_tracking_gain_rule_bounds_the_integral_gain(caltech):
    """``k = min(1, k_I_max / trace(Phi P0 Phi^T))`` with ``k_I_max = min K_v / (margin max tau)``."""
    settings_ = tracking_only.TrackingOnlySettings()
    K_v = ControllerConfig().K_v
    act = caltech.actuators
    k_I_max = tracking_only.integral_gain_limit(settings_, K_v, caltech)
    assert k_I_max == pytest.approx(min(K_v) / (2.0 * max(act.pusher_motor_time_constant_s,
                                                          act.lift_motor_time_constant_s)))
    assert tracking_only.integral_gain_limit(tracking_only.TrackingOnlySettings(gain_rule="paper"), K_v,
                                             caltech) == np.inf
    P0 = np.diag(caltech.adaptation.P0_diag)
    params, state = controller_arrays(caltech, ControllerConfig(kind="tracking_only"))
    assert params[tracking_only.P_K_I_MAX] == k_I_max
    phi = int(params[A_PHI])
    for V, alpha, u_x, u_z in [(0.0, 0.0, 0.0, 0.55), (4.0, 0.1, 0.2, 0.5), (9.0, 0.2, 0.45, 0.3),
                               (12.9, 0.1, 0.6, 0.1)]:
        Phi = np.empty((3, N))
        forces.regressor(np.array([V * np.cos(alpha), 0.0, V * np.sin(alpha)]), u_x, u_z, caltech.model_kernel, Phi)
        state[phi:phi + 3 * N] = Phi.ravel()              # this tick's regressor, where the front end leaves it
        k = tracking_only.gain_scale(params, state)
        M = Phi @ P0 @ Phi.T
        assert k == pytest.approx(min(1.0, k_I_max / np.trace(M)), rel=1e-12)
        # every axis' integral gain (any attitude R: same eigenvalues) within the Routh bound
        assert k * np.linalg.eigvalsh(M).max() <= k_I_max * (1 + 1e-12)


# --- identifiability -------------------------------------------------------------------------------

def test_identifiability_recovers_a_known_spectrum(rng):
    """Information built from a known orthonormal basis and eigenvalues, in relative coordinates."""
    theta0 = rng.uniform(0.5, 3.0, N) * rng.choice([-1, 1], N)
    Q, _ = np.linalg.qr(rng.normal(size=(N, N)))
    T = 40.0
    sens = np.array([30.0, 10.0, 3.0, 1.5, 0.9, 0.2, 0.01, 0.0])
    A = Q @ np.diag(sens ** 2) @ Q.T                       # relative-coordinate information per second
    D_inv = np.diag(1.0 / np.abs(theta0))
    S = D_inv @ A @ D_inv * T
    out = identifiability(S, theta0, T)
    got = np.array([d["sensitivity_mps2"] for d in out["directions"]])
    np.testing.assert_allclose(got, sens, rtol=1e-7, atol=1e-6)
    assert out["n_determined"] == int(np.sum(sens >= IDENTIFIABILITY_SENSITIVITY_MIN_MPS2)) == 4
    for k, d in enumerate(out["directions"][:6]):
        v = np.array([d["components"][n] for n in PARAMETER_NAMES])
        assert abs(abs(v @ Q[:, k]) - 1.0) < 1e-7


def test_identifiability_names_the_excited_parameters():
    theta0 = np.ones(N)
    S = np.zeros((N, N))
    S[1, 1] = 100.0                                        # only C_Tz is excited
    out = identifiability(S, theta0, 10.0)
    assert out["n_determined"] == 1
    assert out["directions"][0]["dominant"] == f"+1.00 {PARAMETER_NAMES[1]}"
    assert out["directions"][0]["sensitivity_mps2"] == pytest.approx(np.sqrt(10.0))


def test_identifiability_section_shows_each_run(rng):
    from vtoladapt.experiments.report import identifiability_section, table_markdown

    theta0 = np.ones(N)
    runs = []
    for k in (1, 3):
        S = np.zeros((N, N))
        for i in range(k):
            S[i, i] = 40.0 * (i + 1)                    # k excited parameters, sensitivities >= 2 m/s^2
        runs.append(identifiability(S, theta0, 10.0))
    sec = identifiability_section({"identifiability_per_run": runs})
    per_run, first = sec.tables
    assert [r[1].text for r in per_run.rows] == ["1", "3"]
    assert len(first.rows) == N and [r[2].text for r in first.rows].count("yes") == 1
    md = table_markdown(per_run)
    assert "directions determined" in md and f"{PARAMETER_NAMES[0]}" in table_markdown(first)
