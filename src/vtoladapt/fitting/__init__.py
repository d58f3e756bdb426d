"""Model identification: Bayesian fitting of the force model (the paper's Table I).

* :mod:`~vtoladapt.fitting.data`: the force-balance CSV format (reader/validator, writer);
* :mod:`~vtoladapt.fitting.tunnel`: the virtual wind tunnel (simulated balance data);
* :mod:`~vtoladapt.fitting.linear_gaussian`: closed-form Bayesian linear regression and its
  marginal likelihood;
* :mod:`~vtoladapt.fitting.sampler`: the marginal problem and its MCMC sampler (emcee), with the
  linear coefficients marginalised analytically, and the convergence diagnostics;
* :mod:`~vtoladapt.fitting.bayes`: the Table I problem and its fit;
* :mod:`~vtoladapt.fitting.posterior`: ``posterior.json``, and theta_0 / P0 / bounds for the
  adaptive controller from it;
* :mod:`~vtoladapt.fitting.realdata`: UIUC propeller and TU Delft wing fits;
* :mod:`~vtoladapt.fitting.figures`, :mod:`~vtoladapt.fitting.report`,
  :mod:`~vtoladapt.fitting.cli` (``vtoladapt tunnel``, ``fit``, ``fit-realdata``, ``fit-validate``).

>>> import numpy as np, vtoladapt
>>> from vtoladapt.fitting import run_virtual_tunnel, fit_table1
>>> veh = vtoladapt.load_vehicle("caltech_vtol")
>>> run = run_virtual_tunnel(veh, np.random.default_rng(0))            # doctest: +SKIP
>>> fit = fit_table1(run.data, veh, np.random.default_rng(1))           # doctest: +SKIP
>>> fit.summary()["k1"]["mean"]                                         # doctest: +SKIP
1.42...
"""
import importlib

# Names are imported on first use (PEP 562): the CLI registers `vtoladapt fit` without loading
# emcee and scipy.stats, which keeps `vtoladapt run` quick to start.
_EXPORTS = {
    "bayes": ("Table1Fit", "fit_table1"),
    "linear_gaussian": ("closed_form_posterior",),
    "sampler": ("SamplerSettings", "mcmc_linear_regression", "sample_marginal", "split_rhat"),
    "data": ("FitDataError", "ForceBalanceData", "read_force_balance_csv", "write_force_balance_csv"),
    "posterior": ("ControllerPrior", "Posterior", "PosteriorError", "apply_posterior", "controller_prior",
                  "load_posterior", "vehicle_with_posterior", "write_posterior"),
    "realdata": ("fit_tudelft_polar", "fit_uiuc_ct_of_j", "fit_uiuc_static_ct", "pusher_thrust_ratio_model"),
    "tunnel": ("BalanceNoise", "TunnelDesign", "linear_model_truth", "run_virtual_tunnel",
               "true_coefficients", "write_tunnel_run"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = sorted(_MODULE_OF)


def __getattr__(name: str):
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'vtoladapt.fitting' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__():
    return __all__
