"""Prior distributions of fit parameters: uniform and bounded (truncated) normal.

A prior is a small immutable object with a log density, a sampler, bounds and a dict form
(for the TOML configuration and the HDF5 record of a fit). Both kinds have finite support
``[low, high]``: the bounds are what the global search (differential evolution) explores and
what the sampler is never allowed to leave.

>>> import numpy as np
>>> Uniform(9.0, 11.0).log_prob(10.0) == -np.log(2.0)
True
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math

import numpy as np
from scipy import special, stats

__all__ = ["Uniform", "BoundedNormal", "Prior", "PRIOR_KINDS", "prior_from_dict"]


def _check_bounds(kind: str, low: float, high: float) -> None:
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        raise ValueError(
            f"{kind} prior bounds low={low!r}, high={high!r} are not finite and increasing; "
            "give two finite numbers with low < high"
        )


@dataclass(frozen=True)
class Uniform:
    """Flat density on ``[low, high]``.

    Parameters
    ----------
    low, high : float
        Finite bounds, ``low < high``.
    """

    low: float
    high: float

    kind = "uniform"

    def __post_init__(self):
        object.__setattr__(self, "low", float(self.low))
        object.__setattr__(self, "high", float(self.high))
        _check_bounds(self.kind, self.low, self.high)

    @property
    def bounds(self) -> tuple[float, float]:
        """(low, high), the support."""
        return self.low, self.high

    def log_prob(self, x):
        """Log density at `x` (scalar or array); ``-inf`` outside the support."""
        x = np.asarray(x, dtype=float)
        inside = (x >= self.low) & (x <= self.high)
        value = np.where(inside, -math.log(self.high - self.low), -np.inf)
        return float(value) if value.ndim == 0 else value

    def ppf(self, u):
        """Quantile function: the value below which a fraction `u` of the prior lies."""
        return self.low + (self.high - self.low) * np.asarray(u, dtype=float)

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """(size,) draws."""
        return self.ppf(rng.random(size))

    def to_dict(self) -> dict:
        return {"kind": self.kind, "low": self.low, "high": self.high}


@dataclass(frozen=True)
class BoundedNormal:
    """Normal density of `mean` and `sigma` truncated to ``[low, high]`` and renormalised.

    Parameters
    ----------
    mean, sigma : float
        Centre and width of the untruncated normal, ``sigma > 0``.
    low, high : float
        Finite bounds, ``low < high``; the normal is renormalised over them.
    """

    mean: float
    sigma: float
    low: float
    high: float

    kind = "normal"

    def __post_init__(self):
        for name in ("mean", "sigma", "low", "high"):
            object.__setattr__(self, name, float(getattr(self, name)))
        _check_bounds(self.kind, self.low, self.high)
        if not (math.isfinite(self.sigma) and self.sigma > 0):
            raise ValueError(f"normal prior sigma={self.sigma!r} must be a positive number")
        if not math.isfinite(self.mean):
            raise ValueError(f"normal prior mean={self.mean!r} must be a finite number")
        a, b = (self.low - self.mean) / self.sigma, (self.high - self.mean) / self.sigma
        # log of the probability mass kept by the truncation; log_ndtr is accurate in the tails.
        mass = special.ndtr(b) - special.ndtr(a)
        if not mass > 0:
            raise ValueError(
                f"normal prior mean={self.mean} sigma={self.sigma} has no mass inside "
                f"[{self.low}, {self.high}]; widen the bounds or move the mean inside them"
            )
        object.__setattr__(self, "_log_norm", math.log(mass) + math.log(self.sigma) + 0.5 * math.log(2 * math.pi))

    @property
    def bounds(self) -> tuple[float, float]:
        """(low, high), the support."""
        return self.low, self.high

    def _frozen(self):
        return stats.truncnorm(
            (self.low - self.mean) / self.sigma, (self.high - self.mean) / self.sigma, loc=self.mean, scale=self.sigma
        )

    def log_prob(self, x):
        """Log density at `x` (scalar or array); ``-inf`` outside the support."""
        x = np.asarray(x, dtype=float)
        inside = (x >= self.low) & (x <= self.high)
        value = np.where(inside, -0.5 * ((x - self.mean) / self.sigma) ** 2 - self._log_norm, -np.inf)
        return float(value) if value.ndim == 0 else value

    def ppf(self, u):
        """Quantile function: the value below which a fraction `u` of the prior lies."""
        return self._frozen().ppf(np.asarray(u, dtype=float))

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """(size,) draws."""
        return self.ppf(rng.random(size))

    def to_dict(self) -> dict:
        return {"kind": self.kind, "mean": self.mean, "sigma": self.sigma, "low": self.low, "high": self.high}


Prior = Uniform | BoundedNormal

PRIOR_KINDS = {"uniform": Uniform, "normal": BoundedNormal}


def prior_from_dict(record: Mapping, name: str = "parameter") -> Prior:
    """Build a prior from its dict form, e.g. ``{"kind": "uniform", "low": 0, "high": 90}``.

    Parameters
    ----------
    record : mapping
        ``kind`` (``"uniform"`` or ``"normal"``) and that kind's fields.
    name : str
        The parameter it belongs to, for error messages.
    """
    kind = record.get("kind", "uniform")
    if kind not in PRIOR_KINDS:
        raise ValueError(f"prior of {name}: unknown kind {kind!r}; use one of {', '.join(PRIOR_KINDS)}")
    cls = PRIOR_KINDS[kind]
    fields = {"uniform": ("low", "high"), "normal": ("mean", "sigma", "low", "high")}[kind]
    missing = [f for f in fields if f not in record]
    if missing:
        raise ValueError(f"prior of {name}: {kind} needs {', '.join(missing)}; give them in the configuration")
    extra = sorted(set(record) - set(fields) - {"kind"})
    if extra:
        raise ValueError(f"prior of {name}: unexpected keys {', '.join(extra)} for a {kind} prior; remove them")
    try:
        return cls(**{f: float(record[f]) for f in fields})
    except (TypeError, ValueError) as error:
        raise ValueError(f"prior of {name}: {error}") from None
