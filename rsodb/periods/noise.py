"""How noisy a light curve is, measured without a model of it.

* `point_to_point_noise_mag`: the white-noise level from second differences of successive
  samples at the regular cadence (a smooth signal cancels in them; a few glints do not move a
  median).
* `residual_amplitude_mag`: the mean amplitude spectrum of residuals around a frequency, the
  noise of the S/N >= 4 rule (Breger et al. 1993).

See docs/periods.md for how the verdicts use them.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["point_to_point_noise_mag", "residual_amplitude_mag", "white_amplitude_mag"]

# 1 / Phi^-1(3/4): the standard deviation of a normal variable from its median absolute deviation.
_MAD_TO_SIGMA = 1.482602218505602


def point_to_point_noise_mag(t_s: np.ndarray, mag: np.ndarray, cadence_s: float) -> float:
    """Robust white-noise level (magnitudes, 1 sigma) from second differences.

    For three successive samples at the regular cadence, ``y_(i-1) - 2 y_i + y_(i+1)`` removes
    any signal that is linear over two cadences and has variance ``6 sigma^2`` for white noise;
    the median absolute deviation makes it blind to the few samples on a glint. Signals that
    change faster than the cadence leak in and make the estimate an upper bound.

    Parameters
    ----------
    t_s, mag : (n,) float
    cadence_s : float
        The regular spacing; triples with other spacings (gaps) are skipped.

    Returns
    -------
    float
        NaN with fewer than 5 regular triples.
    """
    t_s, mag = np.asarray(t_s, dtype=float), np.asarray(mag, dtype=float)
    step = np.diff(t_s)
    regular = np.abs(step - cadence_s) <= 0.5 * cadence_s
    triple = regular[:-1] & regular[1:]
    if triple.sum() < 5:
        return math.nan
    second = (mag[:-2] - 2.0 * mag[1:-1] + mag[2:])[triple]
    return float(_MAD_TO_SIGMA * np.median(np.abs(second - np.median(second))) / math.sqrt(6.0))


def white_amplitude_mag(noise_mag: float, n_points: int) -> float:
    """Mean amplitude spectrum ``(2 / n) |sum r exp(-2 pi i f t)|`` of white noise of `noise_mag`.

    The sum is complex normal with ``E|.|^2 = n sigma^2``, so its modulus is Rayleigh with mean
    ``sigma sqrt(pi n) / 2``: the mean amplitude is ``sigma sqrt(pi / n)``.
    """
    return float(noise_mag * math.sqrt(math.pi / max(n_points, 1)))


def residual_amplitude_mag(t_s: np.ndarray, residual: np.ndarray, low_hz: float, high_hz: float) -> float:
    """Mean amplitude spectrum ``(2 / n) |sum r exp(-2 pi i f t)|`` over 64 frequencies in [low, high].

    Parameters
    ----------
    t_s, residual : (n,) float
    low_hz, high_hz : float

    Returns
    -------
    float
        Magnitudes.
    """
    t_s = np.asarray(t_s, dtype=float)
    tc = t_s - 0.5 * (t_s[0] + t_s[-1])
    centred = np.asarray(residual, dtype=float) - np.mean(residual)
    n_trial = 64
    # exp(-2 pi i (lo + j df) t) = exp(-2 pi i lo t) * exp(-2 pi i df t)^j: one exp per sample.
    df = (high_hz - low_hz) / (n_trial - 1)
    start = np.exp(-2j * np.pi * low_hz * tc) * centred
    step = np.exp(-2j * np.pi * df * tc)
    total, current = 0.0, start
    for _ in range(n_trial):
        total += abs(current.sum())
        current = current * step
    return float(total / n_trial * 2.0 / t_s.size)
