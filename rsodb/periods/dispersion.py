"""Dispersion of a folded light curve: phase dispersion minimisation and string length.

Both measure how well the samples line up when folded on a trial period, without assuming a
shape, so they judge glints and flat-topped curves as fairly as smooth ones.

* PDM (Stellingwerf 1978, ApJ 224, 953): fold, cut the cycle into ``M`` equal phase bins, and
  compare the pooled within-bin variance with the total variance,
  ``theta = [W / (n - M)] / [S / (n - 1)]`` with ``W`` the within-bin sum of squares and ``S``
  the total one. A true period gives small ``theta``.
  The bin means are a step-function model with ``M`` parameters, so the same information
  criterion as the Fourier fits applies: ``BIC = n ln(W / n) + M ln n``. Bins are chosen with
  a fixed width in *time* across candidates (``M`` proportional to the period): folding on
  ``2P`` with ``2M`` bins then refines folding on ``P`` with ``M`` bins (same epoch), so the
  two models are nested and the BIC decides whether the halves of the ``2P`` cycle differ.
* String length (Dworetsky 1983, MNRAS 203, 917): the length of the line joining the samples
  sorted by phase, with magnitudes scaled to [0, 1] and half the phase weight; a true period
  gives a short string.

`DISPERSION_METHODS` maps names to the functions; all take ``(t_s, y, period_s, ...)`` with a
vector of periods and compute every period at once.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import f as f_distribution

__all__ = ["pdm", "pdm_bic", "pdm_within", "pdm_f_test", "string_length", "DISPERSION_METHODS"]


def _phases(t_s: np.ndarray, period_s: np.ndarray) -> np.ndarray:
    """(m, n) phases in [0, 1) of every sample for every period, epoch at t = 0."""
    return np.mod(np.asarray(t_s)[None, :] / np.asarray(period_s, dtype=float)[:, None], 1.0)


def _within_ss(t_s, y, period_s, n_bins) -> tuple[np.ndarray, np.ndarray, float]:
    """Within-bin sum of squares (m,), occupied bins (m,), total sum of squares."""
    period_s = np.atleast_1d(np.asarray(period_s, dtype=float))
    n_bins = np.broadcast_to(np.asarray(n_bins, dtype=int), period_s.shape)
    m, n = period_s.size, y.size
    phase = _phases(t_s, period_s)
    bins = np.minimum((phase * n_bins[:, None]).astype(int), n_bins[:, None] - 1)
    # One bincount over all periods: bin labels offset per period.
    offsets = np.concatenate([[0], np.cumsum(n_bins)[:-1]])
    labels = (bins + offsets[:, None]).ravel()
    size = int(n_bins.sum())
    yy = np.broadcast_to(y, (m, n)).ravel()
    count = np.bincount(labels, minlength=size)
    total = np.bincount(labels, weights=yy, minlength=size)
    total2 = np.bincount(labels, weights=yy * yy, minlength=size)
    with np.errstate(invalid="ignore", divide="ignore"):
        ss = np.where(count > 0, total2 - total * total / np.maximum(count, 1), 0.0)
    period_index = np.repeat(np.arange(m), n_bins)
    within = np.bincount(period_index, weights=np.maximum(ss, 0.0), minlength=m)
    occupied = np.bincount(period_index, weights=(count > 0).astype(float), minlength=m)
    total_ss = float(np.sum((y - y.mean()) ** 2))
    return within, occupied, total_ss


def pdm_within(t_s, y, period_s, n_bins) -> tuple[np.ndarray, np.ndarray]:
    """Within-bin sum of squares and number of occupied bins of the folded curves.

    Parameters
    ----------
    t_s, y : (n,) float
    period_s : (m,) float
    n_bins : int or (m,) int

    Returns
    -------
    within_ss : (m,) float
    occupied : (m,) float
    """
    within, occupied, _ = _within_ss(np.asarray(t_s, dtype=float), np.asarray(y, dtype=float), period_s, n_bins)
    return within, occupied


def pdm_f_test(n_points: int, within_short: float, bins_short: float, within_long: float, bins_long: float) -> float:
    """p-value that folding on a multiple of a period reduces the dispersion only by chance.

    Folding on ``m P`` with ``m M`` bins refines folding on ``P`` with ``M`` bins (same epoch
    and bin width), so the two step models are nested and the classical F-test applies
    (Schwarzenberg-Czerny 1989, MNRAS 241, 153, for the statistics of PDM):
    ``F = [(W_P - W_mP) / (M_mP - M_P)] / [W_mP / (n - M_mP)]``.

    Returns
    -------
    float
        Small when the cycle of ``m P`` really differs from ``m`` repeats of the cycle of P.
    """
    extra = bins_long - bins_short
    dof = n_points - bins_long
    if extra <= 0 or dof <= 0 or within_long <= 0:
        return float("nan")
    statistic = max(within_short - within_long, 0.0) / extra / (within_long / dof)
    return float(f_distribution.sf(statistic, extra, dof))


def pdm(t_s, y, period_s, n_bins=10) -> np.ndarray:
    """Stellingwerf's theta statistic.

    Parameters
    ----------
    t_s, y : (n,) float
        Times (s) and magnitudes (trend removed).
    period_s : float or (m,) float
        Trial periods.
    n_bins : int or (m,) int
        Phase bins per trial period.

    Returns
    -------
    (m,) float
        theta; 1 for no periodicity, near 0 for a noiseless periodic curve.

    Examples
    --------
    >>> t = np.arange(1000) * 0.1
    >>> y = np.sin(2 * np.pi * t / 7.0)
    >>> bool(pdm(t, y, [7.0])[0] < 0.05 < 0.9 < pdm(t, y, [5.0])[0])
    True
    """
    y = np.asarray(y, dtype=float)
    within, occupied, total_ss = _within_ss(np.asarray(t_s, dtype=float), y, period_s, n_bins)
    n = y.size
    return (within / np.maximum(n - occupied, 1)) / (total_ss / (n - 1))


def pdm_bic(t_s, y, period_s, n_bins) -> np.ndarray:
    """BIC of the phase-binned step model, ``n ln(W / n) + M ln n`` (lower is better).

    Parameters
    ----------
    t_s, y : (n,) float
    period_s : (m,) float
    n_bins : (m,) int

    Returns
    -------
    (m,) float
    """
    y = np.asarray(y, dtype=float)
    within, occupied, _ = _within_ss(np.asarray(t_s, dtype=float), y, period_s, n_bins)
    n = y.size
    return n * np.log(np.maximum(within, 1e-300) / n) + occupied * math.log(n)


def string_length(t_s, y, period_s) -> np.ndarray:
    """Dworetsky's string length of the folded curve.

    Parameters
    ----------
    t_s, y : (n,) float
    period_s : float or (m,) float

    Returns
    -------
    (m,) float
        ``sum sqrt(dm^2 + dphi^2)`` over neighbours in phase (closing the cycle), with ``m``
        scaled to ``[-0.25, 0.25]`` and phase to ``[0, 1)`` as Dworetsky did.
    """
    y = np.asarray(y, dtype=float)
    span = np.ptp(y)
    scaled = (y - y.min()) / (span if span > 0 else 1.0) * 0.5 - 0.25
    phase = _phases(np.asarray(t_s, dtype=float), np.atleast_1d(period_s))
    order = np.argsort(phase, axis=1)
    ph = np.take_along_axis(phase, order, axis=1)
    mg = scaled[order]
    d_mag = np.diff(mg, axis=1, append=mg[:, :1])
    d_phase = np.diff(ph, axis=1, append=ph[:, :1] + 1.0)
    return np.sqrt(d_mag**2 + d_phase**2).sum(axis=1)


DISPERSION_METHODS = {"pdm": pdm, "string_length": string_length}
