"""Spin-state fitting: forward model, priors, likelihood, emcee sampler and fit results.

>>> from rsodb.fit import FitConfig, fit_pass                              # doctest: +SKIP
>>> result = fit_pass(archive, "22076-20240730T212240", FitConfig())      # doctest: +SKIP
>>> print(result.table())                                                 # doctest: +SKIP

See docs/fitting.md for the model, the likelihood's derivation and how to run a fit.
"""

from rsodb.fit.config import FitConfig
from rsodb.fit.likelihood import LIKELIHOODS, GaussianLikelihood, NormalisedLikelihood, make_likelihood
from rsodb.fit.model import ATTITUDES, ConvexFacets, SpinStateModel, make_attitude
from rsodb.fit.parameters import KNOWN, Parameter, ParameterSpace
from rsodb.fit.plots import save_all
from rsodb.fit.posterior import Posterior
from rsodb.fit.prediction import FitPrediction, predict_fit
from rsodb.fit.priors import BoundedNormal, Uniform, prior_from_dict
from rsodb.fit.result import FitResult
from rsodb.fit.runner import FitProblem, fit_pass, fit_problem
from rsodb.fit.sampler import ChainRun, SamplerSettings, run_sampler
from rsodb.fit.shapes import SHAPES

__all__ = [
    "FitConfig",
    "LIKELIHOODS",
    "GaussianLikelihood",
    "NormalisedLikelihood",
    "make_likelihood",
    "ATTITUDES",
    "ConvexFacets",
    "SpinStateModel",
    "make_attitude",
    "FitPrediction",
    "predict_fit",
    "KNOWN",
    "Parameter",
    "ParameterSpace",
    "Posterior",
    "BoundedNormal",
    "Uniform",
    "prior_from_dict",
    "FitResult",
    "FitProblem",
    "fit_pass",
    "fit_problem",
    "ChainRun",
    "SamplerSettings",
    "run_sampler",
    "SHAPES",
    "save_all",
]
