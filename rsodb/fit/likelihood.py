"""Likelihoods comparing observed and synthetic magnitudes.

``gaussian`` (the default)
    Each observed magnitude is the model plus an unknown constant offset ``c`` plus Gaussian
    noise of variance ``s_i^2 = sigma_i^2 + s_jit^2`` (the observed error and a fitted jitter
    term). The offset absorbs what the model cannot know in absolute terms (zero point,
    overall albedo, size), and is integrated out analytically under a flat prior.

    Derivation. With weights ``w_i = 1 / s_i^2``, ``W = sum w_i`` and residuals
    ``r_i = m_obs,i - m_model,i``, completing the square in ``c`` gives

        sum w_i (r_i - c)^2 = sum w_i (r_i - c_hat)^2 + W (c - c_hat)^2,
        c_hat = sum w_i r_i / W,

    so, for a flat prior on ``c`` of width ``Delta`` that contains the likelihood's support,

        ln L = ln (1/Delta) int prod_i N(r_i - c; 0, s_i^2) dc
             = -1/2 sum w_i (r_i - c_hat)^2 - 1/2 sum ln(2 pi s_i^2) + 1/2 ln(2 pi / W) - ln Delta.

    The constant ``-ln Delta`` is dropped (it moves no posterior). The ``1/2 ln(2 pi / W)``
    term is kept: it depends on the jitter. ``tests/test_fit_likelihood.py`` checks this
    against numerical integration over ``c``. With ``offset="none"`` the model magnitudes
    are compared as they are (absolute photometry; then albedo and size matter).

``normalised``
    The comparison of the published Blender workflow, for reference: both light curves are
    min-max scaled, ``n = (max(m) - m) / (max(m) - min(m))`` (1 = brightest), and
    ``ln L = -1/2 sum (n_obs - n_model)^2`` with unit variance and no error bars. It ignores
    the observed errors and the absolute brightness, so its posteriors are not calibrated.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math

import numpy as np

__all__ = ["GaussianLikelihood", "NormalisedLikelihood", "LIKELIHOODS", "OFFSET_MODES", "make_likelihood"]

OFFSET_MODES = ("marginalised", "none")


def _readonly(values, name: str, n: int | None = None) -> np.ndarray:
    array = np.array(values, dtype=float)
    if array.ndim != 1 or array.size == 0:
        raise ValueError(f"{name} must be a non-empty 1-D array, got shape {array.shape}")
    if n is not None and array.shape != (n,):
        raise ValueError(f"{name} has shape {array.shape} but the magnitudes have ({n},); give one per sample")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} holds non-finite values; drop invalid samples before fitting")
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class GaussianLikelihood:
    """Gaussian likelihood with observed errors, a jitter term and an optional free offset.

    Parameters
    ----------
    mag_obs : (n,) float
        Observed magnitudes.
    mag_err : (n,) float
        Their 1-sigma errors, positive.
    offset : {"marginalised", "none"}
        Whether a constant magnitude offset between model and data is integrated out.
    """

    mag_obs: np.ndarray
    mag_err: np.ndarray
    offset: str = "marginalised"

    kind = "gaussian"
    parameters = ("jitter_mag",)

    def __post_init__(self):
        mag = _readonly(self.mag_obs, "mag_obs")
        err = _readonly(self.mag_err, "mag_err", mag.size)
        if np.any(err <= 0):
            raise ValueError(
                f"mag_err has {int(np.sum(err <= 0))} non-positive values; errors must be positive "
                "(drop those samples or give a floor)"
            )
        if self.offset not in OFFSET_MODES:
            raise ValueError(f"offset={self.offset!r} is not one of {', '.join(OFFSET_MODES)}")
        object.__setattr__(self, "mag_obs", mag)
        object.__setattr__(self, "mag_err", err)

    def _weights(self, jitter_mag: float) -> np.ndarray:
        return 1.0 / (self.mag_err**2 + jitter_mag**2)

    def offset_mag(self, mag_model: np.ndarray, jitter_mag: float = 0.0) -> float:
        """The offset ``c_hat`` that best aligns model to data (0 when the offset is not free)."""
        if self.offset == "none":
            return 0.0
        w = self._weights(jitter_mag)
        return float(np.sum(w * (self.mag_obs - mag_model)) / np.sum(w))

    def log_likelihood(self, mag_model: np.ndarray, jitter_mag: float = 0.0) -> float:
        """ln L for model magnitudes (n,) and jitter (mag); see the module docstring."""
        w = self._weights(jitter_mag)
        r = self.mag_obs - mag_model
        if self.offset == "marginalised":
            W = np.sum(w)
            r = r - np.sum(w * r) / W
            extra = 0.5 * math.log(2 * math.pi / W)
        else:
            extra = 0.0
        return float(-0.5 * np.sum(w * r * r) + 0.5 * np.sum(np.log(w / (2 * math.pi))) + extra)

    def compared(self, mag_model: np.ndarray, jitter_mag: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(observed, aligned model, sigma) as compared: the model shifted by the best offset.

        ``sigma`` includes the jitter.
        """
        shifted = mag_model + self.offset_mag(mag_model, jitter_mag)
        return self.mag_obs, shifted, np.sqrt(self.mag_err**2 + jitter_mag**2)

    def chi2(self, mag_model: np.ndarray, jitter_mag: float = 0.0) -> float:
        """Sum of squared normalised residuals at the best offset."""
        obs, model, sigma = self.compared(mag_model, jitter_mag)
        return float(np.sum(((obs - model) / sigma) ** 2))

    @property
    def n_free_nuisance(self) -> int:
        """Nuisance parameters fitted besides the free parameters (the offset)."""
        return 1 if self.offset == "marginalised" else 0


def _normalise(mag: np.ndarray) -> np.ndarray:
    span = np.max(mag) - np.min(mag)
    return (np.max(mag) - mag) / span if span > 0 else np.zeros_like(mag)


@dataclass(frozen=True, eq=False)
class NormalisedLikelihood:
    """The published workflow's comparison: min-max normalised curves, unit variance.

    Parameters
    ----------
    mag_obs : (n,) float
        Observed magnitudes.
    mag_err : (n,) float
        Ignored (kept so that every likelihood is built the same way).
    offset : str
        Ignored: normalisation removes any offset.
    """

    mag_obs: np.ndarray
    mag_err: np.ndarray
    offset: str = "marginalised"

    kind = "normalised"
    parameters = ()

    def __post_init__(self):
        mag = _readonly(self.mag_obs, "mag_obs")
        object.__setattr__(self, "mag_obs", mag)
        object.__setattr__(self, "mag_err", _readonly(self.mag_err, "mag_err", mag.size))
        object.__setattr__(self, "_obs_norm", _normalise(mag))

    def offset_mag(self, mag_model: np.ndarray, jitter_mag: float = 0.0) -> float:
        return 0.0

    def log_likelihood(self, mag_model: np.ndarray, jitter_mag: float = 0.0) -> float:
        """-1/2 sum of squared differences of the normalised curves."""
        d = self._obs_norm - _normalise(mag_model)
        return float(-0.5 * np.sum(d * d))

    def compared(self, mag_model: np.ndarray, jitter_mag: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(normalised observed, normalised model, unit sigma)."""
        return self._obs_norm, _normalise(mag_model), np.ones_like(self._obs_norm)

    def chi2(self, mag_model: np.ndarray, jitter_mag: float = 0.0) -> float:
        obs, model, _ = self.compared(mag_model)
        return float(np.sum((obs - model) ** 2))

    @property
    def n_free_nuisance(self) -> int:
        return 0


LIKELIHOODS = {"gaussian": GaussianLikelihood, "normalised": NormalisedLikelihood}


def make_likelihood(kind: str, mag_obs, mag_err, offset: str = "marginalised"):
    """The likelihood of `kind` (a key of `LIKELIHOODS`) for these observations."""
    if kind not in LIKELIHOODS:
        raise ValueError(f"unknown likelihood {kind!r}; use one of {', '.join(LIKELIHOODS)}")
    return LIKELIHOODS[kind](mag_obs, mag_err, offset)


def jitter_of(values: Mapping[str, float]) -> float:
    """The jitter term from a parameter mapping (0 when the space has none)."""
    return float(values.get("jitter_mag", 0.0))
