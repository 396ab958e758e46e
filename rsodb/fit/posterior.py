"""The log posterior the sampler explores: priors + forward model + likelihood.

A `Posterior` is a picklable callable ``theta (ndim,) -> float``; emcee's process pool
receives it once per worker (see `rsodb.fit.sampler`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math
from typing import Any

import numpy as np

from rsodb.fit.likelihood import flux_error_of, jitter_of, model_error_of
from rsodb.fit.parameters import ParameterSpace

__all__ = ["Posterior"]


@dataclass(frozen=True, eq=False)
class Posterior:
    """ln p(theta | data) up to a constant.

    Parameters
    ----------
    space : ParameterSpace
        Free parameters with priors, and fixed values.
    model : object
        Forward model with ``parameters`` (names it reads) and
        ``magnitudes(values) -> (n,)`` at the observed samples.
    likelihood : GaussianLikelihood or NormalisedLikelihood
        Compares model and observed magnitudes.
    """

    space: ParameterSpace
    model: Any
    likelihood: Any

    def __post_init__(self):
        needed = set(self.model.parameters)
        missing = sorted(needed - self.space.all_names)
        if missing:
            raise ValueError(
                f"the forward model needs {missing} but they are neither free nor fixed; "
                "add them to the fit configuration's parameters"
            )
        usable = needed | set(self.likelihood.parameters)
        unused = sorted(set(self.space.all_names) - usable)
        if unused:
            raise ValueError(
                f"parameters {unused} are not used by this model and likelihood; "
                f"remove them (usable: {', '.join(sorted(usable))})"
            )

    @property
    def ndim(self) -> int:
        return self.space.ndim

    def magnitudes(self, theta: np.ndarray) -> np.ndarray:
        """(n,) model magnitudes at `theta`, before any offset."""
        return self.model.magnitudes(self.space.values(theta))

    def log_likelihood(self, theta: np.ndarray) -> float:
        values = self.space.values(theta)
        return self.likelihood.log_likelihood(
            self.model.magnitudes(values), jitter_of(values), model_error_of(values), flux_error_of(values)
        )

    def __call__(self, theta: np.ndarray) -> float:
        log_prior = self.space.log_prior(theta)
        if not math.isfinite(log_prior):
            return -math.inf
        with np.errstate(divide="ignore", invalid="ignore"):
            log_like = self.log_likelihood(theta)
        # An object predicted invisible (zero intensity -> infinite magnitude) where it was
        # observed is impossible, not merely unlikely.
        return log_prior + log_like if math.isfinite(log_like) else -math.inf

    def values(self, theta: np.ndarray) -> Mapping[str, float]:
        return self.space.values(theta)
