"""The Bayesian machinery against closed forms, quadrature, scipy, and the truth of virtual data.

Monte Carlo tolerances: a posterior mean from an MCMC with effective sample size ESS has
standard error sd / sqrt(ESS); a standard deviation has relative standard error
sqrt(1 / (2 ESS)); a correlation r has standard error (1 - r^2) / sqrt(ESS). Checks allow 4 such
errors (a false alarm about once in 16 000 per check).
"""
import numpy as np
import pytest
from scipy import stats

import vtoladapt
from vtoladapt import forces
from vtoladapt.fitting import bayes, linear_gaussian, tunnel
from vtoladapt.vehicle import PARAMETER_NAMES

NAMES10 = PARAMETER_NAMES + ("k1", "k2")


@pytest.fixture(scope="module")
def veh():
    return vtoladapt.load_vehicle("caltech_vtol")


SMALL = dict(wing_airspeeds_mps=[5.0, 9.0], wing_alpha_step_deg=5.0,
             static_throttles_pct=[30.0, 60.0, 90.0], rotor_airspeeds_mps=[3.0, 9.0],
             rotor_throttles_pct=[40.0, 70.0], rotor_alpha_step_deg=15.0, rotor_beta_deg=[0.0, 15.0])


def small_problem(veh, seed=0, **fixed):
    run = tunnel.run_virtual_tunnel(veh, np.random.default_rng(seed), design=tunnel.make_design(**SMALL))
    td = bayes.prepare_table1_data(run.data, veh)
    return td, bayes.table1_problem(td, fixed=fixed)


def random_regression(rng, n=40, p=5):
    A = rng.normal(size=(n, p))
    X = A @ (np.eye(p) + 0.6 * rng.normal(size=(p, p)))      # correlated columns
    beta = rng.normal(size=p)
    sigma = rng.uniform(0.5, 1.5, n)
    y = X @ beta + sigma * rng.normal(size=n)
    return X, y, sigma


def test_marginal_likelihood_and_conditional_match_scipy():
    """log p(y) of the marginal form = the Gaussian y ~ N(X m0, Sigma + X S0 X^T) (scipy);
    the conditional mean/cov = the closed form; the closed form = its Woodbury (data-space) form."""
    rng = np.random.default_rng(0)
    X, y, sigma = random_regression(rng)
    m0 = rng.normal(size=5)
    sd0 = rng.uniform(0.5, 3.0, 5)
    S0 = np.diag(sd0**2)
    stats_fn = bayes.stats_from_design(lambda phi: (X[None], sigma[None]), y)
    XtWX, XtWy, yWy, slog = stats_fn(np.zeros((1, 0)))
    lml, mu, L = linear_gaussian._marginal_from_stats(XtWX, XtWy, yWy, slog, y.size, m0, 1 / sd0**2,
                                            float(np.sum(np.log(sd0**2))), need_L=True)
    ref = stats.multivariate_normal(X @ m0, np.diag(sigma**2) + X @ S0 @ X.T).logpdf(y)
    assert lml[0] == pytest.approx(ref, rel=1e-10)
    mean, cov = bayes.closed_form_posterior(X, y, sigma, m0, S0)
    np.testing.assert_allclose(mu[0], mean, rtol=1e-10)
    np.testing.assert_allclose(np.linalg.inv(L[0] @ L[0].T), cov, rtol=1e-9, atol=1e-14)
    K = np.diag(sigma**2) + X @ S0 @ X.T
    G = S0 @ X.T @ np.linalg.inv(K)
    np.testing.assert_allclose(m0 + G @ (y - X @ m0), mean, rtol=1e-9)
    np.testing.assert_allclose(S0 - G @ X @ S0, cov, rtol=1e-8, atol=1e-13)


def test_mcmc_matches_closed_form_posterior():
    """emcee on all coefficients of a Gaussian linear regression with known noise reproduces
    the closed-form posterior mean, standard deviations and correlations (4 MC errors)."""
    rng = np.random.default_rng(1)
    X, y, sigma = random_regression(rng)
    m0 = np.zeros(5)
    S0 = np.diag(np.full(5, 25.0))
    mean, cov = bayes.closed_form_posterior(X, y, sigma, m0, S0)
    chain, tau, rhat = bayes.mcmc_linear_regression(X, y, sigma, m0, S0, rng, n_walkers=32,
                                                    n_burn=500, n_steps=4000)
    assert np.all(rhat < 1.01)
    assert chain.shape[0] > 50 * tau.max()
    flat = chain.reshape(-1, 5)
    ess = flat.shape[0] / tau
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(flat.mean(0) - mean) < 4 * sd / np.sqrt(ess)), (flat.mean(0) - mean) / sd * np.sqrt(ess)
    sd_mc = flat.std(0, ddof=1)
    assert np.all(np.abs(sd_mc / sd - 1) < 4 * np.sqrt(1 / (2 * ess)))
    corr = cov / np.outer(sd, sd)
    corr_mc = np.corrcoef(flat, rowvar=False)
    tol = 4 * (1 - corr**2) / np.sqrt(ess.min()) + 1e-12
    assert np.all(np.abs(corr_mc - corr) <= tol)
    assert np.abs(corr[np.triu_indices(5, 1)]).max() > 0.5     # a correlated posterior


def test_sampler_without_free_parameters_is_the_closed_form(veh):
    """With k1, k2 and the noise fixed, the Table I posterior is the closed form of the dense
    regressor built directly from forces.regressor_rows (draws within 4 MC errors)."""
    td, problem = small_problem(veh, k1=1.425, k2=3.126, log10_sigma_abs_N=np.log10(0.02), sigma_rel=0.01)
    mf = bayes.sample_marginal(problem, np.random.default_rng(2), bayes.SamplerSettings(max_draw_steps=500))
    Phi = td.regressor(1.425, 3.126).reshape(-1, 8)
    sigma = 0.02 / td.mass_kg + 0.01 * np.abs(td.y_B).reshape(-1)
    mean, cov = bayes.closed_form_posterior(Phi, td.y_B.reshape(-1), sigma, np.zeros(8),
                                            np.diag(problem.prior_sd**2))
    draws = mf.coef_draws.reshape(-1, 8)
    sd = np.sqrt(np.diag(cov))
    n = draws.shape[0]
    assert np.all(np.abs(draws.mean(0) - mean) < 4 * sd / np.sqrt(n))
    assert np.all(np.abs(draws.std(0) / sd - 1) < 4 * np.sqrt(1 / (2 * n)))


def test_one_dimensional_posterior_against_quadrature(veh):
    """Only k2 free: the MCMC's mean and std of k2 and the mean of C_S match numerical
    integration of the marginal posterior on a fine grid (4 MC errors)."""
    td, problem = small_problem(veh, k1=1.425, log10_sigma_abs_N=np.log10(0.02), sigma_rel=0.01)
    mf = bayes.sample_marginal(problem, np.random.default_rng(3),
                               bayes.SamplerSettings(min_steps=3000, max_steps=3000))
    g = np.linspace(np.pi / 2 + 1e-6, 10 - 1e-6, 40001)
    lp, mu, _ = problem.log_posterior(g[:, None])
    w = np.exp(lp - lp.max())
    w /= w.sum()
    m = w @ g
    s = np.sqrt(w @ (g - m) ** 2)
    c = mf.chain[:, :, 0]
    ess = c.size / bayes.autocorr_time(c)[0]
    assert abs(c.mean() - m) < 4 * s / np.sqrt(ess)
    assert abs(c.std() / s - 1) < 4 * np.sqrt(1 / (2 * ess))
    cs = mf.coef_draws[:, :, forces.I_CS]
    cs_mean = w @ mu[:, forces.I_CS]
    cs_sd = np.sqrt(w @ (mu[:, forces.I_CS] - cs_mean) ** 2 + cs.var())
    ess_cs = cs.size / bayes.autocorr_time(cs)[0]
    assert abs(cs.mean() - cs_mean) < 4 * cs_sd / np.sqrt(ess_cs)


def test_fast_kernels_match_the_control_regressor(veh):
    """The sparse sufficient statistics equal the dense ones, and the C_S column computed for the
    fit equals forces.regressor_rows' column at the same (k1, k2)."""
    td, problem = small_problem(veh)
    rng = np.random.default_rng(4)
    phi = np.column_stack([rng.uniform(0.5, 1.9, 6), rng.uniform(1.7, 9, 6),
                           rng.uniform(-3, -1, 6), rng.uniform(0, 0.05, 6)])
    dense = bayes.stats_from_design(problem.design_and_sigma, problem.y)(phi)
    fast = problem.stats(phi)
    for a, b in zip(fast, dense):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())
    X, _ = problem.design_and_sigma(phi)
    for w in range(phi.shape[0]):
        full = td.regressor(phi[w, 0], phi[w, 1]).reshape(-1, 8)
        np.testing.assert_array_equal(X[w], full)


def test_split_rhat_and_autocorrelation_time():
    rng = np.random.default_rng(5)
    iid = rng.normal(size=(2000, 8))
    assert bayes.split_rhat(iid)[0] == pytest.approx(1.0, abs=0.005)
    shifted = iid + np.arange(8) * 0.5
    assert bayes.split_rhat(shifted)[0] > 1.1
    # AR(1) with rho has tau = (1 + rho) / (1 - rho)
    rho = 0.8
    x = np.zeros((20000, 4))
    e = rng.normal(size=x.shape)
    for t in range(1, x.shape[0]):
        x[t] = rho * x[t - 1] + e[t]
    assert bayes.autocorr_time(x)[0] == pytest.approx((1 + rho) / (1 - rho), rel=0.15)


def test_same_seed_same_posterior(veh):
    run = tunnel.run_virtual_tunnel(veh, np.random.default_rng(0), design=tunnel.make_design(**SMALL))
    a = bayes.fit_table1(run.data, veh, np.random.default_rng(9), settings=bayes.SamplerSettings.fast())
    b = bayes.fit_table1(run.data, veh, np.random.default_rng(9), settings=bayes.SamplerSettings.fast())
    np.testing.assert_array_equal(a.draws, b.draws)


@pytest.fixture(scope="module")
def full_fit(veh):
    """The target case: default virtual tunnel (Table I means as truth, seed 0), default settings."""
    run = tunnel.run_virtual_tunnel(veh, np.random.default_rng(0), seed=0)
    return run, bayes.fit_table1(run.data, veh, np.random.default_rng(1))


def test_full_table1_fit_recovers_truth_within_2_std(full_fit):
    run, fit = full_fit
    s = fit.summary()
    truth = dict(zip(PARAMETER_NAMES, run.truth.as_table_theta()))
    truth.update(k1=run.truth.k1, k2=run.truth.k2)
    z = {n: (s[n]["mean"] - truth[n]) / s[n]["std"] for n in NAMES10}
    assert all(abs(v) < 2 for v in z.values()), z
    # the balance noise is recovered too (0.02 N, 1 %)
    assert abs(s["sigma_abs_N"]["mean"] - 0.02) < 3 * s["sigma_abs_N"]["std"]
    assert abs(s["sigma_rel"]["mean"] - 0.01) < 3 * s["sigma_rel"]["std"]


def test_full_fit_is_converged(full_fit):
    _, fit = full_fit
    m = fit.marginal
    assert m.converged
    assert np.all(m.rhat < 1.01) and m.n_steps > 50 * m.tau_steps.max()
    s = fit.summary()
    assert max(s[n]["rhat"] for n in s) < 1.01
    assert min(s[n]["ess"] for n in s) > 1000
    assert not fit.not_identified


def test_posterior_std_shrinks_as_one_over_sqrt_n(veh):
    """4x the rows (the default design, 511 rows, every point measured 4 times) halves every
    posterior std, within 15 %: the noise estimate differs between the two data sets (a few %)
    and each std has an MC error of about 3 % at these chain lengths (ESS ~ 700 for k1, k2)."""
    res = bayes_sqrt_n(veh, (1, 4))
    for n in NAMES10:
        assert res["ratio"][n][0] == pytest.approx(2.0, rel=0.15), (n, res["ratio"][n])


def bayes_sqrt_n(veh, repeats, settings=None, design=None):
    from vtoladapt.fitting.report import sqrt_n_study
    return sqrt_n_study(veh, np.random.default_rng(11), repeats,
                        settings or bayes.SamplerSettings(min_steps=600, max_steps=600, n_burn=200),
                        design_overrides=design)


@pytest.mark.slow
def test_sqrt_n_on_default_design_16n(veh):
    """N, 4N, 16N rows of the default design: each 4x step halves every std (within 15 %, as
    above)."""
    res = bayes_sqrt_n(veh, (1, 4, 16), bayes.SamplerSettings(min_steps=1000, max_steps=1000))
    for n in NAMES10:
        for r in res["ratio"][n]:
            assert r == pytest.approx(2.0, rel=0.15), (n, res["ratio"][n])


@pytest.mark.slow
def test_zscores_are_calibrated_over_seeds(veh):
    """Truth drawn from Table I's spread, 10 seeds: about 95 % of the 100 |z| are below 2
    (at least 88 %: the binomial 1st percentile for p = 0.95, n = 100 is 90)."""
    from vtoladapt.fitting.report import zscore_study
    res = zscore_study(veh, range(1, 11))
    assert res["fraction_within_2sd"] >= 0.88
    assert res["fraction_within_1sd"] >= 0.55
