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

    A correlated model error. With ``correlation_time_s > 0`` the residuals also hold a
    stationary error of the forward model, ``model_error_mag`` RMS, correlated over
    ``correlation_time_s`` (an Ornstein-Uhlenbeck process: covariance
    ``e^2 exp(-|t_i - t_j| / tau)``). A renderer's error against the truth is of this kind (it
    follows the attitude, not the photon noise): on Blender Cycles passes of the paper's COSMOS
    2502 mesh the fit's cached model is off by 0.0056 mag RMS at the true state, correlated over
    seconds, and white noise alone let it pull the cone angle 2.6 posterior sigmas from the
    truth (docs/fitting.md). The covariance ``C = D + K`` (``D`` the white variances) is
    handled exactly in O(n) by a Kalman filter over the samples in time order: its innovations
    ``e_k`` and their variances ``S_k`` give ``y^T C^-1 y = sum e_k^2 / S_k`` and
    ``ln |C| = sum ln S_k``, and the offset is integrated out as above with ``W = 1^T C^-1 1``
    and ``c_hat = 1^T C^-1 r / W`` (the filter run on the residuals and on a vector of ones).
    With ``model_error_mag = 0`` this is the white likelihood above.

    A model error in flux. With ``flux_error`` the white variance of each sample also holds
    ``(1.0857 f F_max / F_i)^2``: an error of the forward model of ``f`` times its brightest
    sample's flux, the same in flux at every sample, so in magnitudes it grows as the model
    fades (``F_max / F_i = 10^(0.4 (m_i - min m))`` from the model's own magnitudes, so the
    offset leaves it alone). A renderer's error is of this kind where it is a shadow or a limb
    moved by a fraction of an element: on the Cycles passes of the paper's COSMOS 2502 mesh the
    fit's cached model is 0.004 mag off at the brightest frames and 0.017 mag 4-6 mag below
    them (docs/fitting.md). ``model_flux_error`` (``f``) is fitted; the weights then depend on
    the model, and the ``ln s_i`` terms keep it from growing for free.

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

__all__ = [
    "GaussianLikelihood",
    "NormalisedLikelihood",
    "LIKELIHOODS",
    "OFFSET_MODES",
    "make_likelihood",
    "jitter_of",
    "model_error_of",
    "flux_error_of",
    "flux_error_mag",
]

OFFSET_MODES = ("marginalised", "none")
MAG_PER_FLUX_FRACTION = 2.5 / math.log(10.0)  # d(mag) / (dF / F), to first order


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


@njit(cache=True, nogil=True)
def _filtered_sums(t_s, variance, residual, error_var, tau_s):
    """Kalman filter of an Ornstein-Uhlenbeck error (variance `error_var`, time `tau_s`) plus
    white noise (`variance`), run on the residuals and on ones; (sum e_r^2/S, sum e_r e_1/S,
    sum e_1^2/S, sum ln S) over the innovations e and their variances S."""
    rr = r1 = one_one = log_det = 0.0
    mean_r = mean_1 = 0.0
    p = error_var
    for k in range(t_s.size):
        if k > 0:
            a = math.exp(-(t_s[k] - t_s[k - 1]) / tau_s)
            mean_r *= a
            mean_1 *= a
            p = a * a * p + error_var * (1.0 - a * a)
        s = p + variance[k]
        e_r, e_1 = residual[k] - mean_r, 1.0 - mean_1
        rr += e_r * e_r / s
        r1 += e_r * e_1 / s
        one_one += e_1 * e_1 / s
        log_det += math.log(s)
        gain = p / s
        mean_r += gain * e_r
        mean_1 += gain * e_1
        p *= 1.0 - gain
    return rr, r1, one_one, log_det


@dataclass(frozen=True, eq=False)
class GaussianLikelihood:
    """Gaussian likelihood with observed errors, a jitter term, an optional correlated model
    error and an optional free offset.

    Parameters
    ----------
    mag_obs : (n,) float
        Observed magnitudes.
    mag_err : (n,) float
        Their 1-sigma errors, positive.
    offset : {"marginalised", "none"}
        Whether a constant magnitude offset between model and data is integrated out.
    t_s : (n,) float, optional
        Sample times, seconds, non-decreasing (needed with `correlation_time_s`).
    correlation_time_s : float
        Correlation time of the model error (``model_error_mag``); 0: no such term.
    flux_error : bool
        Whether the model's error in flux (``model_flux_error``) is a term of the variance.
    """

    mag_obs: np.ndarray
    mag_err: np.ndarray
    offset: str = "marginalised"
    t_s: np.ndarray | None = None
    correlation_time_s: float = 0.0
    flux_error: bool = False

    kind = "gaussian"

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
        tau = self.correlation_time_s
        if not (isinstance(tau, (int, float)) and math.isfinite(tau) and tau >= 0):
            raise ValueError(f"correlation_time_s={tau!r} must be seconds >= 0 (0: no correlated model error)")
        if tau > 0:
            if self.t_s is None:
                raise ValueError("a correlated model error (correlation_time_s > 0) needs the sample times t_s")
            times = _readonly(self.t_s, "t_s", mag.size)
            if np.any(np.diff(times) < 0):
                raise ValueError("t_s must be in time order (non-decreasing) for a correlated model error")
            object.__setattr__(self, "t_s", times)
        object.__setattr__(self, "mag_obs", mag)
        object.__setattr__(self, "mag_err", err)

    @property
    def parameters(self) -> tuple[str, ...]:
        """The likelihood's own parameters: the jitter, the model error when correlated, the
        model's flux error when asked."""
        names = ("jitter_mag",) + (("model_error_mag",) if self.correlation_time_s > 0 else ())
        return names + (("model_flux_error",) if self.flux_error else ())

    def _variance(self, mag_model: np.ndarray, jitter_mag: float, flux_error: float) -> np.ndarray:
        """Each sample's white variance: observed error, jitter and the model's flux error."""
        variance = self.mag_err**2 + jitter_mag**2
        if flux_error > 0 and self.flux_error:
            variance = variance + (flux_error_mag(mag_model, flux_error)) ** 2
        return variance

    def _weights(self, mag_model: np.ndarray, jitter_mag: float, flux_error: float = 0.0) -> np.ndarray:
        return 1.0 / self._variance(mag_model, jitter_mag, flux_error)

    def offset_mag(self, mag_model: np.ndarray, jitter_mag: float = 0.0, flux_error: float = 0.0) -> float:
        """The offset ``c_hat`` that best aligns model to data (0 when the offset is not free)."""
        return self._best_offset(mag_model, self._variance(mag_model, jitter_mag, flux_error))

    def _best_offset(self, mag_model: np.ndarray, variance: np.ndarray) -> float:
        if self.offset == "none":
            return 0.0
        w = 1.0 / variance
        return float(np.sum(w * (self.mag_obs - mag_model)) / np.sum(w))

    def log_likelihood(
        self, mag_model: np.ndarray, jitter_mag: float = 0.0, model_error_mag: float = 0.0, flux_error: float = 0.0
    ) -> float:
        """ln L for model magnitudes (n,), jitter and correlated model error (mag), and the
        model's flux error (a fraction of its brightest sample); see the module docstring."""
        if flux_error > 0 and self.flux_error and not np.all(np.isfinite(mag_model)):
            return -math.inf  # a dark model sample: its flux error would forgive any data
        if model_error_mag > 0 and self.correlation_time_s > 0:
            return self._correlated_log_likelihood(mag_model, jitter_mag, model_error_mag, flux_error)
        w = self._weights(mag_model, jitter_mag, flux_error)
        r = self.mag_obs - mag_model
        if self.offset == "marginalised":
            W = np.sum(w)
            r = r - np.sum(w * r) / W
            extra = 0.5 * math.log(2 * math.pi / W)
        else:
            extra = 0.0
        return float(-0.5 * np.sum(w * r * r) + 0.5 * np.sum(np.log(w / (2 * math.pi))) + extra)

    def _correlated_log_likelihood(
        self, mag_model: np.ndarray, jitter_mag: float, model_error_mag: float, flux_error: float
    ) -> float:
        r = np.ascontiguousarray(self.mag_obs - mag_model)
        if not np.all(np.isfinite(r)):
            return -math.inf
        rr, r1, one_one, log_det = _filtered_sums(
            self.t_s,
            self._variance(mag_model, jitter_mag, flux_error),
            r,
            model_error_mag**2,
            float(self.correlation_time_s),
        )
        value = -0.5 * rr - 0.5 * log_det - 0.5 * r.size * math.log(2 * math.pi)
        if self.offset == "marginalised":
            value += 0.5 * r1 * r1 / one_one + 0.5 * math.log(2 * math.pi / one_one)
        return float(value)

    def compared(
        self, mag_model: np.ndarray, jitter_mag: float = 0.0, flux_error: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(observed, aligned model, sigma) as compared: the model shifted by the best offset.

        ``sigma`` includes the jitter and the model's flux error (not the correlated model
        error: residual plots and the chi2 show the white part).
        """
        variance = self._variance(mag_model, jitter_mag, flux_error)
        return self.mag_obs, mag_model + self._best_offset(mag_model, variance), np.sqrt(variance)

    def chi2(self, mag_model: np.ndarray, jitter_mag: float = 0.0, flux_error: float = 0.0) -> float:
        """Sum of squared normalised residuals at the best offset."""
        obs, model, sigma = self.compared(mag_model, jitter_mag, flux_error)
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

    def offset_mag(self, mag_model: np.ndarray, jitter_mag: float = 0.0, flux_error: float = 0.0) -> float:
        return 0.0

    def log_likelihood(
        self, mag_model: np.ndarray, jitter_mag: float = 0.0, model_error_mag: float = 0.0, flux_error: float = 0.0
    ) -> float:
        """-1/2 sum of squared differences of the normalised curves."""
        d = self._obs_norm - _normalise(mag_model)
        return float(-0.5 * np.sum(d * d))

    def compared(
        self, mag_model: np.ndarray, jitter_mag: float = 0.0, flux_error: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(normalised observed, normalised model, unit sigma)."""
        return self._obs_norm, _normalise(mag_model), np.ones_like(self._obs_norm)

    def chi2(self, mag_model: np.ndarray, jitter_mag: float = 0.0, flux_error: float = 0.0) -> float:
        obs, model, _ = self.compared(mag_model)
        return float(np.sum((obs - model) ** 2))

    @property
    def n_free_nuisance(self) -> int:
        return 0


LIKELIHOODS = {"gaussian": GaussianLikelihood, "normalised": NormalisedLikelihood}


def make_likelihood(
    kind: str,
    mag_obs,
    mag_err,
    offset: str = "marginalised",
    t_s=None,
    correlation_time_s: float = 0.0,
    flux_error: bool = False,
):
    """The likelihood of `kind` (a key of `LIKELIHOODS`) for these observations (sample times
    `t_s` and a correlated model error for ``gaussian`` when `correlation_time_s` > 0; the
    model's flux error as a term of the variance with `flux_error`)."""
    if kind not in LIKELIHOODS:
        raise ValueError(f"unknown likelihood {kind!r}; use one of {', '.join(LIKELIHOODS)}")
    if correlation_time_s > 0 or flux_error:
        if kind != "gaussian":
            raise ValueError(f"a model error term needs the gaussian likelihood, not {kind!r}")
        return GaussianLikelihood(mag_obs, mag_err, offset, t_s, correlation_time_s, flux_error)
    return LIKELIHOODS[kind](mag_obs, mag_err, offset)


def flux_error_mag(mag_model: np.ndarray, flux_error: float) -> np.ndarray:
    """(n,) the magnitude error of a model error of ``flux_error`` times the model's brightest
    sample's flux: ``2.5 / ln 10 * flux_error * 10^(0.4 (m - min m))`` (the first-order
    error of a magnitude, so the flux ratio is taken from the finite magnitudes)."""
    mag_model = np.asarray(mag_model, dtype=float)
    finite = np.isfinite(mag_model)
    brightest = np.min(mag_model[finite]) if finite.any() else 0.0
    return MAG_PER_FLUX_FRACTION * flux_error * 10.0 ** (0.4 * (mag_model - brightest))


def jitter_of(values: Mapping[str, float]) -> float:
    """The jitter term from a parameter mapping (0 when the space has none)."""
    return float(values.get("jitter_mag", 0.0))


def model_error_of(values: Mapping[str, float]) -> float:
    """The correlated model error from a parameter mapping (0 when the space has none)."""
    return float(values.get("model_error_mag", 0.0))


def flux_error_of(values: Mapping[str, float]) -> float:
    """The model's flux error (fraction of its brightest sample) from a parameter mapping (0
    when the space has none)."""
    return float(values.get("model_flux_error", 0.0))
