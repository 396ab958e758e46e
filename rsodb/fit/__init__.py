"""Spin-state fitting: forward model, priors, likelihood, emcee sampler and fit results.

See docs/fitting.md for the model, the likelihood's derivation and how to run a fit.
"""
from rsodb.fit.likelihood import LIKELIHOODS, GaussianLikelihood, NormalisedLikelihood, make_likelihood
from rsodb.fit.parameters import KNOWN, Parameter, ParameterSpace
from rsodb.fit.posterior import Posterior
from rsodb.fit.priors import BoundedNormal, Uniform, prior_from_dict
from rsodb.fit.sampler import ChainRun, SamplerSettings, run_sampler

__all__ = [
    "LIKELIHOODS", "GaussianLikelihood", "NormalisedLikelihood", "make_likelihood",
    "KNOWN", "Parameter", "ParameterSpace", "Posterior",
    "BoundedNormal", "Uniform", "prior_from_dict",
    "ChainRun", "SamplerSettings", "run_sampler",
]
