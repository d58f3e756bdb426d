"""The kernels compiled with constant sizes give the numbers of the generic ones, bit for bit.

The adaptation step is compiled for each shipped basis's n (:data:`vtoladapt.control.adaptation.SPECIALISED_N`)
and the learned basis's network for the shipped architecture (:data:`vtoladapt.bases.learned.SHIPPED_ARCHITECTURE`),
besides the generic code that runs any size; the small linear algebra is written to overlap independent sums.
These tests hold each fast path to the generic one (the same inlined body at a run-time size) and to the
textbook loops it replaced, on random SPD inputs over several ticks, with and without bounds held; and fail
if a shipped basis's size is not one of the specialised ones.
"""
from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from vtoladapt import load_vehicle
from vtoladapt.bases import describe_basis, input_rows
from vtoladapt.bases import learned
from vtoladapt.bases.netfile import net_rows
from vtoladapt.config import ConfigError
from vtoladapt.control import adaptation as ad
from vtoladapt.control import linalg
from vtoladapt.vehicle import available_vehicles

_IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
MODES = {"composite": (ad.ADAPT_COMPOSITE, False), "composite_directional": (ad.ADAPT_COMPOSITE, True),
         "pconst": (ad.ADAPT_PCONST, False), "tracking": (ad.ADAPT_TRACKING, False)}


@njit
def _generic_step(mode, at, x, prior, Phi, R, v, dt, fa, fb, sigma, trace_max, active, directional, gain_scale, e, n):
    """The step's body at a run-time n (loops of run-time length): what any other basis size runs."""
    return ad._step(mode, at, 0, x, prior, Phi, 0, R, v, dt, fa, fb, sigma, trace_max, active, 1.0, 0.9,
                    directional, gain_scale, e, n, 1.0)


@njit
def _generic_project(K, G, x, tau, d0, d, sa, sl, rhs, mu, at_upper, at_lower, active_start, n):
    return ad._project(K, 0, G, 0, x, tau, d0, d, sa, sl, rhs, mu, at_upper, at_lower, active_start, n)


def _random_spd(rng, n, spread=2.0):
    B = rng.normal(size=(n, n)) * 10.0 ** rng.uniform(-spread, spread, size=(n, 1))
    A = B @ B.T + 1e-3 * np.eye(n)
    return 0.5 * (A + A.T)


def _adaptation(rng, n, on_bounds):
    """``(at, x, prior)`` of n parameters with random SPD P0 and Gamma; with ``on_bounds`` two thirds of the
    components start on a bound (the projection runs, on the held set or on the free set)."""
    at, x, prior = ad.standalone_arrays(n)
    mem, pri = ad.memory_layout(n), ad.prior_layout(n)
    P0 = _random_spd(rng, n, 1.0)
    G0 = np.linalg.inv(P0)
    G0 = 0.5 * (G0 + G0.T)
    lower, upper = -rng.uniform(1.0, 3.0, n), rng.uniform(1.0, 3.0, n)
    theta = rng.uniform(0.5 * lower, 0.5 * upper)
    if on_bounds:
        held = rng.permutation(n)[:max(1, 2 * n // 3)]
        theta[held[::2]] = lower[held[::2]]
        theta[held[1::2]] = upper[held[1::2]]
    prior[:] = pri.pack(THETA0=rng.uniform(0.5 * lower, 0.5 * upper), THETA_INIT=theta, LOWER=lower, UPPER=upper,
                        GAMMA0=G0.ravel(), P0=P0.ravel())
    mem.view(x, "THETA")[:] = theta
    mem.view(x, "GAMMA")[:] = (G0 + _random_spd(rng, n, 0.5)).ravel()
    mem.view(x, "W")[:] = rng.normal(size=3 * n)
    mem.view(x, "A_M")[:] = rng.normal(size=3)
    return at, x, prior


# the composite mode in the default run; the other modes (the same specialised kernels, other branches) with
# make test-slow: the default suite's budget on two cores
@pytest.mark.parametrize("mode_name", [m if m == "composite" else pytest.param(m, marks=pytest.mark.slow)
                                       for m in sorted(MODES)])
@pytest.mark.parametrize("on_bounds", [False, True])
@pytest.mark.parametrize("n", ad.SPECIALISED_N)
def test_specialised_step_equals_the_generic_step_bit_for_bit(n, on_bounds, mode_name):
    mode, directional = MODES[mode_name]
    rng = np.random.default_rng(1000 * n + 10 * on_bounds + sorted(MODES).index(mode_name))
    at, x, prior = _adaptation(rng, n, on_bounds)
    x_generic = x.copy()
    active = active_generic = 0
    held = []
    for _ in range(6):
        Phi = rng.normal(size=3 * n) * 3.0
        v = tuple(rng.normal(size=3))
        e = tuple(rng.normal(size=3) * 0.5)
        args = (0.004, 0.998, 0.004 * 0.999, 1e-3, 1e4)   # dt, forgetting a and b, sigma, trace cap
        got = ad.adaptation_step_with_error(mode, at, 0, x, prior, Phi, 0, _IDENTITY, v, *args, active, 1.0, 0.9,
                                            directional, 0.7, e, 1.0)
        want = _generic_step(mode, at, x_generic, prior, Phi, _IDENTITY, v, *args, active_generic, directional, 0.7,
                             e, n)
        assert got == want
        np.testing.assert_array_equal(x, x_generic)
        active, active_generic = got[1], want[1]
        held.append(got[0] > 0)
        # new regressor and accelerometer for the next tick, the same in both
        W = rng.normal(size=3 * n)
        ad.memory_layout(n).view(x, "W")[:] = W
        ad.memory_layout(n).view(x_generic, "W")[:] = W
    # started on bounds, the projection held some; inside the box, the first tick had nothing to hold
    assert any(held) if on_bounds else not held[0]


@pytest.mark.parametrize("n", ad.SPECIALISED_N)
def test_specialised_projection_equals_the_generic_one(n):
    rng = np.random.default_rng(n)
    m = (n // 2) ** 2
    for _ in range(20):
        K = _random_spd(rng, n, 1.0)
        G = np.linalg.inv(K)
        G = 0.5 * (G + G.T)
        tau = rng.normal(size=n)
        at_upper = at_lower = 0
        for i in rng.permutation(n)[:rng.integers(1, n)]:
            if rng.random() < 0.5:
                at_upper |= 1 << int(i)
            else:
                at_lower |= 1 << int(i)
        # x: tau, d0 = K tau, d, system, factor, rhs, mu
        x = np.concatenate([tau, K @ tau, np.zeros(n), np.zeros(2 * m), np.zeros(2 * n)])
        offsets = (0, n, 2 * n, 3 * n, 3 * n + m, 3 * n + 2 * m, 4 * n + 2 * m)
        y = x.copy()
        got = ad.project_direction(K.ravel(), 0, G.ravel(), 0, x, *offsets, at_upper, at_lower, 0, n)
        want = _generic_project(K.ravel(), G.ravel(), y, *offsets, at_upper, at_lower, 0, n)
        assert got == want
        np.testing.assert_array_equal(x, y)


# --- the linear algebra against the textbook loops it replaced ---------------------------------------

@njit
def _textbook(A, n):
    """Cholesky by columns with one dot product per entry, L^-1 by columns, W^T W and the information
    update written symmetric in the same loop: the loops the fast kernels were rewritten from."""
    L = np.zeros((n, n))
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        d = np.sqrt(s)
        L[j, j] = d
        r = 1.0 / d
        for i in range(j + 1, n):
            t = A[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t * r
    M = np.zeros((n, n))
    for i in range(n):
        M[i, i] = 1.0 / L[i, i]
    for j in range(n):
        for i in range(j + 1, n):
            t = 0.0
            for k in range(j, i):
                t -= L[i, k] * M[k, j]
            M[i, j] = t * M[i, i]
    return L, M


@njit
def _textbook_gram_update(W, Gamma, Gamma0, a, b, n):
    G = np.zeros((n, n))
    out = Gamma.copy()
    for i in range(n):
        for j in range(i, n):
            t = 0.0
            for r in range(3):
                t += W[r, i] * W[r, j]
            G[i, j] = t
            G[j, i] = t
            v = ad.flush_tiny(a * Gamma[i, j] + 1.0 * (1.0 - a) * Gamma0[i, j] + b * t)
            out[i, j] = v
            out[j, i] = v
    return G, out


@pytest.mark.parametrize("n", [n if n in ad.SPECIALISED_N else pytest.param(n, marks=pytest.mark.slow)
                               for n in list(range(1, 21)) + [33]])
def test_linear_algebra_kernels_give_the_textbook_numbers(n):
    rng = np.random.default_rng(n)
    for _ in range(5):
        A = _random_spd(rng, n, 3.0)
        x = np.zeros(3 * n * n)
        x[:n * n] = A.ravel()
        assert linalg.cholesky_lower(x, 0, x, n * n, n)
        linalg.inverse_factor(x, n * n, x, 2 * n * n, n)
        L, M = _textbook(A, n)
        np.testing.assert_array_equal(x[n * n:2 * n * n].reshape(n, n), L)
        np.testing.assert_array_equal(x[2 * n * n:].reshape(n, n), M)
        # and they are what they claim to be (numpy, to rounding)
        np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-8, atol=1e-10 * np.abs(L).max())
        np.testing.assert_allclose(M.T @ M, np.linalg.inv(A), rtol=1e-6, atol=1e-9 * np.abs(np.linalg.inv(A)).max())
        W = rng.normal(size=(3, n))
        Gamma, Gamma0 = A, _random_spd(rng, n, 1.0)
        y = np.concatenate([W.ravel(), np.zeros(n * n), Gamma.ravel(), Gamma0.ravel()])
        g, gam, gam0 = 3 * n, 3 * n + n * n, 3 * n + 2 * n * n
        ad.gram(y, 0, y, g, n)
        ad.information_update(y, gam, y, gam0, y, g, 0.99, 0.004, n)
        G_want, Gamma_want = _textbook_gram_update(W, Gamma, Gamma0, 0.99, 0.004, n)
        np.testing.assert_array_equal(y[g:g + n * n].reshape(n, n), G_want)
        np.testing.assert_array_equal(y[gam:gam + n * n].reshape(n, n), Gamma_want)


def test_a_matrix_that_is_not_positive_definite_is_refused():
    A = np.diag([1.0, 2.0, -1e-9, 3.0])
    x = np.zeros(32)
    x[:16] = A.ravel()
    assert not linalg.cholesky_lower(x, 0, x, 16, 4)


# --- the network ---------------------------------------------------------------------------------------

@njit
def _generic_net(block, x, phi, n, work, h, H1, H2):
    learned._net(block, x, phi, n, work, h, H1, H2)


@pytest.mark.parametrize("vehicle", ["caltech_vtol", "px4_standard_vtol"])
def test_shipped_network_runs_the_specialised_sizes_with_the_generic_numbers(vehicle):
    veh = load_vehicle(vehicle)
    spec = describe_basis(veh, "learned")
    net = learned.load_net(veh, learned.Settings())
    assert (net.h, *net.hidden) == learned.SHIPPED_ARCHITECTURE
    rng = np.random.default_rng(5)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    rows = input_rows(rng.normal(size=(50, 3)) * 6.0, rng.random(50), rng.random(50), veh.model_kernel,
                      valid=(rng.random(50) > 0.3).astype(float), q_WB=q, omega_B=rng.normal(size=(50, 3)))
    block = np.array(spec.block)
    work = np.zeros(spec.work_size)
    for xr in rows:
        phi = np.zeros(3 * spec.n)
        phi_generic = np.zeros(3 * spec.n)
        spec.regressor(block, xr, phi, work)
        _generic_net(block, xr, phi_generic, spec.n, work, net.h, *net.hidden)
        n_phys = spec.n - net.h
        fast = phi.reshape(3, spec.n)[:, n_phys:]
        np.testing.assert_array_equal(fast, phi_generic.reshape(3, spec.n)[:, n_phys:])
        np.testing.assert_allclose(fast, net_rows(net, xr[None, :]).reshape(3, net.h), rtol=1e-12, atol=1e-12)


# --- every shipped basis's size is specialised -----------------------------------------------------------

@pytest.mark.parametrize("vehicle", available_vehicles())
@pytest.mark.parametrize("basis", ["paper", "extended", "learned"])
def test_every_shipped_basis_size_is_compiled_with_constant_loops(vehicle, basis):
    veh = load_vehicle(vehicle)
    try:
        spec = describe_basis(veh, basis)
    except ConfigError as exc:   # a vehicle without a shipped learned basis has no learned size to check
        pytest.skip(f"{basis} basis not available for {vehicle}: {exc}")
    assert spec.n in ad.SPECIALISED_N, (
        f"{vehicle}'s {basis} basis has n = {spec.n}, not one of the compiled sizes {ad.SPECIALISED_N} "
        f"(at most {ad.N_SPECIALISED_SLOTS}: add a slot in vtoladapt.control.adaptation)")
    assert all(s > 0 for s in ad.SPECIALISED_N) and len(set(ad.SPECIALISED_N)) == len(ad.SPECIALISED_N)
