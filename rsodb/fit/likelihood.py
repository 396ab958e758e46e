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

    A **model error correlated in time** (``model_error_mag`` > 0): a model that misses the
    data by a smooth error (a renderer's shadow edge a little off, a facet a little tilted)
    misses neighbouring samples alike, and a white jitter term cannot take such an error: with
    hundreds of samples its systematic pull moves the optimum by several of the statistical
    intervals. The residuals then get, besides the white noise, a stationary Ornstein-Uhlenbeck
    process of standard deviation ``model_error_mag`` and correlation time
    ``model_error_time_s`` (covariance ``s_m^2 exp(-|t_i - t_j| / tau)``). Its covariance
    ``C`` is inverted exactly in O(n) by a Kalman filter on the process's one state, and the
    offset is integrated out as above with ``W = 1' C^-1 1`` and ``c_hat = 1' C^-1 r / W``:

        ln L = -1/2 (r' C^-1 r - W c_hat^2) - 1/2 ln det(2 pi C) + 1/2 ln(2 pi / W).

    ``tests/test_fit_likelihood.py`` checks it against the dense covariance.

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

from numba import njit
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
    time_s: np.ndarray | None = None
    model_error_mag: float = 0.0
    model_error_time_s: float = 0.0

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
        if not (math.isfinite(self.model_error_mag) and self.model_error_mag >= 0.0):
            raise ValueError(f"model_error_mag={self.model_error_mag!r} must be >= 0 mag")
        if self.model_error_mag > 0.0:
            if not (math.isfinite(self.model_error_time_s) and self.model_error_time_s > 0.0):
                raise ValueError(f"model_error_time_s={self.model_error_time_s!r} must be a positive number of seconds")
            if self.time_s is None:
                raise ValueError("a model error correlated in time needs the samples' times (time_s)")
            times = _readonly(self.time_s, "time_s", mag.size)
            if np.any(np.diff(times) < 0):
                raise ValueError("time_s must be in time order")
            object.__setattr__(self, "time_s", times)

    def _weights(self, jitter_mag: float) -> np.ndarray:
        return 1.0 / (self.mag_err**2 + jitter_mag**2)

    def _correlated(self, residual: np.ndarray, jitter_mag: float) -> tuple[float, float, float, float]:
        """(r' C^-1 r, 1' C^-1 r, 1' C^-1 1, ln det C) with the model error's covariance."""
        return _ou_sums(
            np.ascontiguousarray(residual, dtype=float),
            self.time_s,
            self.mag_err**2 + jitter_mag**2,
            self.model_error_mag**2,
            self.model_error_time_s,
        )

    def offset_mag(self, mag_model: np.ndarray, jitter_mag: float = 0.0) -> float:
        """The offset ``c_hat`` that best aligns model to data (0 when the offset is not free)."""
        if self.offset == "none":
            return 0.0
        if self.model_error_mag > 0.0:
            _, r_1, one_1, _ = self._correlated(self.mag_obs - mag_model, jitter_mag)
            return float(r_1 / one_1)
        w = self._weights(jitter_mag)
        return float(np.sum(w * (self.mag_obs - mag_model)) / np.sum(w))

    def log_likelihood(self, mag_model: np.ndarray, jitter_mag: float = 0.0) -> float:
        """ln L for model magnitudes (n,) and jitter (mag); see the module docstring."""
        if self.model_error_mag > 0.0:
            r_r, r_1, one_1, log_det = self._correlated(self.mag_obs - mag_model, jitter_mag)
            n = self.mag_obs.size
            value = -0.5 * r_r - 0.5 * log_det - 0.5 * n * math.log(2 * math.pi)
            if self.offset == "marginalised":
                value += 0.5 * r_1 * r_1 / one_1 + 0.5 * math.log(2 * math.pi / one_1)
            return float(value)
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

        ``sigma`` includes the jitter and the model error (its marginal standard deviation).
        """
        shifted = mag_model + self.offset_mag(mag_model, jitter_mag)
        return self.mag_obs, shifted, np.sqrt(self.mag_err**2 + jitter_mag**2 + self.model_error_mag**2)

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


@njit(cache=True, nogil=True)
def _ou_sums(residual, time_s, white_var, model_var, model_time_s):
    """r' C^-1 r, 1' C^-1 r, 1' C^-1 1 and ln det C for C = diag(white_var) + model_var
    exp(-|t_i - t_j| / model_time_s), by a Kalman filter on the Ornstein-Uhlenbeck state: the
    innovations v (of r and of a vector of ones, which share the gains) and their variances S
    give the quadratic forms as sums of v v' / S and ln det C as the sum of ln S."""
    r_r = r_1 = one_1 = log_det = 0.0
    mean_r = mean_1 = 0.0
    var = model_var
    for i in range(len(residual)):
        if i > 0:
            a = math.exp(-(time_s[i] - time_s[i - 1]) / model_time_s)
            mean_r *= a
            mean_1 *= a
            var = a * a * var + model_var * (1.0 - a * a)
        s = var + white_var[i]
        v_r = residual[i] - mean_r
        v_1 = 1.0 - mean_1
        r_r += v_r * v_r / s
        r_1 += v_r * v_1 / s
        one_1 += v_1 * v_1 / s
        log_det += math.log(s)
        gain = var / s
        mean_r += gain * v_r
        mean_1 += gain * v_1
        var *= 1.0 - gain
    return r_r, r_1, one_1, log_det


LIKELIHOODS = {"gaussian": GaussianLikelihood, "normalised": NormalisedLikelihood}


def make_likelihood(
    kind: str,
    mag_obs,
    mag_err,
    offset: str = "marginalised",
    time_s=None,
    model_error_mag: float = 0.0,
    model_error_time_s: float = 0.0,
):
    """The likelihood of `kind` (a key of `LIKELIHOODS`) for these observations; a model error
    correlated in time (``model_error_mag`` > 0, the samples' ``time_s``) is the Gaussian's."""
    if kind not in LIKELIHOODS:
        raise ValueError(f"unknown likelihood {kind!r}; use one of {', '.join(LIKELIHOODS)}")
    if model_error_mag > 0.0:
        if kind != "gaussian":
            raise ValueError(f"a model error correlated in time needs the gaussian likelihood, not {kind!r}")
        return GaussianLikelihood(mag_obs, mag_err, offset, time_s, model_error_mag, model_error_time_s)
    return LIKELIHOODS[kind](mag_obs, mag_err, offset)


def jitter_of(values: Mapping[str, float]) -> float:
    """The jitter term from a parameter mapping (0 when the space has none)."""
    return float(values.get("jitter_mag", 0.0))
