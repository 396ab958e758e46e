"""Multi-harmonic Fourier series with a polynomial trend, fitted by weighted least squares.

The model of a light curve at trial frequency ``f`` with ``K`` harmonics and a trend of degree
``d`` is::

    mag(t) = sum_{j=0..d} p_j L_j(x) + sum_{k=1..K} [a_k cos(2 pi k f t) + b_k sin(2 pi k f t)]

with ``L_j`` the Legendre polynomials of the time scaled to ``x`` in [-1, 1] over the pass and
``t`` measured from the middle of the pass (so the frequency and the phases are nearly
uncorrelated). The trend is fitted jointly with the harmonics, so a trend never absorbs part of
a slow periodic signal the way a polynomial removed beforehand can.

Models with 1..K harmonics are nested: with the columns ordered (trend, harmonic 1, harmonic 2,
...), one Cholesky factorisation of the normal matrix gives the residual sum of squares of every
prefix model at once (``rss_j = y'Wy - sum_{i<j} z_i^2`` with ``L z = A'Wy``), hence the Bayesian
information criterion (Schwarz 1978) of every harmonic count in one pass. The normal matrix
itself is assembled from trigonometric sums (`normal_equations`), O(n K) per frequency.

The noise scale is profiled out of the likelihood: the weights ``w_i = 1 / sigma_i^2`` are
trusted up to a common factor, so ``-2 ln L = n ln(rss / n) + const`` and
``BIC = n ln(rss / n) + n_par ln n`` with ``n_par = (d + 1) + 2 K + 1`` (the frequency counts).

Everything works on a `SeriesData`, the light curve prepared once for many trial frequencies.
Two more things are prepared here, both explained in docs/periods.md: how flexible the trend
may be for a candidate of a given number of cycles (`trend_degree_limit`), and the light curve
prewhitened for AR(1) noise (`SeriesData.prewhitened`), on which the same fits are generalised
least squares.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache
import math

import numpy as np
from numpy.polynomial import legendre

__all__ = [
    "DEFAULT_ERROR_FLOOR_MAG",
    "SeriesData",
    "TimeAxis",
    "HarmonicFit",
    "harmonic_basis",
    "normal_equations",
    "nested_rss",
    "bic",
    "fit_harmonics",
    "scan_frequency",
    "polish_frequency",
    "refine_frequency",
    "max_harmonics",
    "powers",
    "trend_absorption",
    "trend_degree_limit",
    "TREND_ABSORPTION",
]


# Scintillation and flat-field errors of short exposures are rarely below 0.01 mag, while the
# photon-noise errors the files carry can be 0.003 mag; the floor keeps a few bright frames from
# dominating the weights.
DEFAULT_ERROR_FLOOR_MAG = 0.01
# The most of a candidate sinusoid's variance (worst phase) the trend may be able to absorb.
TREND_ABSORPTION = 0.2
# Samples per trend coefficient, at least.
SAMPLES_PER_TREND_TERM = 10


@dataclass(frozen=True)
class TimeAxis:
    """How times are centred and scaled for the fits of one light curve.

    Attributes
    ----------
    t_mid_s : float
        Middle of the pass (seconds on the light curve's own axis); harmonic phases refer to it.
    half_span_s : float
        Half the duration; the trend polynomial's argument is ``(t - t_mid_s) / half_span_s``.
    """

    t_mid_s: float
    half_span_s: float

    @classmethod
    def from_times(cls, t_s: np.ndarray) -> TimeAxis:
        """Centre and half span of a time axis, (n,) seconds."""
        lo, hi = float(np.min(t_s)), float(np.max(t_s))
        return cls(0.5 * (lo + hi), max(0.5 * (hi - lo), 1e-9))

    @property
    def duration_s(self) -> float:
        return 2.0 * self.half_span_s

    def trend_basis(self, t_s: np.ndarray, degree: int) -> np.ndarray:
        """(n, degree + 1) Legendre polynomials of the scaled time."""
        return legendre.legvander((np.asarray(t_s) - self.t_mid_s) / self.half_span_s, degree)


@dataclass(frozen=True, eq=False)
class SeriesData:
    """A light curve prepared for fits at many frequencies.

    Build it with `SeriesData.from_arrays`; the attributes after `trend_degree` are derived
    once and reused by every evaluation.

    Attributes
    ----------
    t_s, y, weight : (n,) float
        Times (s), magnitudes, weights ``1 / sigma^2``.
    trend_degree : int
    axis : TimeAxis
    tc : (n,) float
        Times from the middle of the pass.
    trend : (n, d + 1) float
        Legendre trend basis.
    rows : (n, d + 2) complex
        ``w y`` and ``w L_j`` as columns, the weights of the sums in `normal_equations`.
    weight_c : (n,) complex
    trend_gram : (d + 1, d + 1) float
    trend_rhs : (d + 1,) float
    yy : float
        ``y'Wy``.
    """

    t_s: np.ndarray
    y: np.ndarray
    weight: np.ndarray
    trend_degree: int
    axis: TimeAxis
    tc: np.ndarray
    trend: np.ndarray
    rows: np.ndarray
    weight_c: np.ndarray
    trend_gram: np.ndarray
    trend_rhs: np.ndarray
    yy: float

    @classmethod
    def from_arrays(cls, t_s, y, weight, trend_degree: int) -> SeriesData:
        """Prepare (n,) times, magnitudes and weights for fits with a trend of `trend_degree`."""
        t_s, y, weight = (np.asarray(a, dtype=float) for a in (t_s, y, weight))
        axis = TimeAxis.from_times(t_s)
        trend = axis.trend_basis(t_s, trend_degree)
        wy = weight * y
        return cls(
            t_s=t_s,
            y=y,
            weight=weight,
            trend_degree=int(trend_degree),
            axis=axis,
            tc=t_s - axis.t_mid_s,
            trend=trend,
            rows=np.concatenate([wy[:, None], trend * weight[:, None]], axis=1).astype(complex),
            weight_c=weight.astype(complex),
            trend_gram=(trend * weight[:, None]).T @ trend,
            trend_rhs=trend.T @ wy,
            yy=float(wy @ y),
        )

    @property
    def n_points(self) -> int:
        return self.t_s.shape[0]

    @property
    def n_trend(self) -> int:
        return self.trend_degree + 1

    def with_trend_degree(self, degree: int) -> SeriesData:
        """The same data with a trend of lower `degree` (the Legendre columns are nested: a slice)."""
        if degree == self.trend_degree:
            return self
        if not 0 <= degree <= self.trend_degree:
            raise ValueError(f"trend degree {degree} is outside 0..{self.trend_degree} of this SeriesData")
        k = degree + 1
        return replace(
            self,
            trend_degree=int(degree),
            trend=self.trend[:, :k],
            rows=self.rows[:, : k + 1],
            trend_gram=self.trend_gram[:k, :k],
            trend_rhs=self.trend_rhs[:k],
        )

    def prewhitened(self, rho: float, cadence_s: float) -> SeriesData:
        """The data filtered for AR(1) noise of lag-1 correlation `rho`: ``y_i - rho y_(i-1)``.

        For samples at a regular cadence the filter maps the trend and the harmonics of any
        frequency into their own span (a polynomial stays a polynomial of its degree; a sinusoid
        keeps its frequency, with a new amplitude and phase), so least squares of the filtered
        magnitudes on the *unfiltered* basis is generalised least squares under AR(1) noise: the
        residual sums, and hence the BIC, are those of the correlated-noise likelihood. Samples
        that do not follow their predecessor at the regular cadence (within half of it: gaps,
        dropped frames) and the first sample are left out. Weights become
        ``2 / (1 / w_i + 1 / w_(i-1))``.

        Parameters
        ----------
        rho : float
            In [0, 1).
        cadence_s : float
            The regular spacing of the samples.

        Returns
        -------
        SeriesData
            Same trend degree, ``n`` minus the samples left out.
        """
        follows = np.abs(np.diff(self.t_s) - cadence_s) <= 0.5 * cadence_s
        keep = np.flatnonzero(follows) + 1
        y = self.y[keep] - rho * self.y[keep - 1]
        weight = 2.0 / (1.0 / self.weight[keep] + 1.0 / self.weight[keep - 1])
        return SeriesData.from_arrays(self.t_s[keep], y, weight, self.trend_degree)


def powers(z: np.ndarray, top: int) -> np.ndarray:
    """(m, top + 1, n) complex powers ``z^0 .. z^top`` of z (m, n).

    A loop over the power with each step vectorised over a contiguous (m, n) plane: several
    times faster than a cumulative product along a short last axis.
    """
    out = np.empty((z.shape[0], top + 1, z.shape[1]), dtype=complex)
    out[:, 0] = 1.0
    if top >= 1:
        out[:, 1] = z
    for k in range(2, top + 1):
        np.multiply(out[:, k - 1], z, out=out[:, k])
    return out


def harmonic_basis(t_s: np.ndarray, frequency_hz, n_harmonics: int) -> np.ndarray:
    """Cosine and sine columns of harmonics 1..K.

    Parameters
    ----------
    t_s : (n,) float
        Times (already centred as wanted), seconds.
    frequency_hz : float or (m,) float
        Fundamental frequencies.
    n_harmonics : int
        K.

    Returns
    -------
    (n, 2K) or (m, n, 2K) float
        Columns ordered ``cos 1, sin 1, cos 2, sin 2, ...``.
    """
    f = np.asarray(frequency_hz, dtype=float)
    z = np.exp(2j * np.pi * np.atleast_1d(f)[:, None] * np.asarray(t_s, dtype=float))
    zk = np.moveaxis(powers(z, n_harmonics)[:, 1:], 1, 2)  # (m, n, K)
    # complex128 viewed as float64 interleaves (real, imaginary) = (cos, sin) per harmonic.
    out = np.ascontiguousarray(zk).view(np.float64)
    return out.reshape(f.shape + out.shape[1:])


def _design(data: SeriesData, frequency_hz: float, n_harmonics: int) -> np.ndarray:
    """(n, d + 1 + 2K) design matrix at one frequency."""
    return np.concatenate([data.trend, harmonic_basis(data.tc, frequency_hz, n_harmonics)], axis=-1)


@lru_cache(maxsize=256)
def _block_tables(n_harmonics: int):
    """Gather indices and coefficients that build the (2K, 2K) harmonic block from the sums.

    With ``V = [Re Z_0 .. Re Z_2K, Im Z_0 .. Im Z_2K]`` (``Z_m = sum w z^m``), the block is
    ``c1 * V[i1] + c2 * V[i2]`` where, for harmonics j, k:

    * cos j cos k = (Re Z_|j-k| + Re Z_j+k) / 2,  sin j sin k = (Re Z_|j-k| - Re Z_j+k) / 2,
    * cos j sin k = (Im Z_j+k - sign(j-k) Im Z_|j-k|) / 2, and sin j cos k its transpose.
    """
    k = n_harmonics
    length = 2 * k + 1
    j = np.arange(1, k + 1)
    diff = j[:, None] - j[None, :]
    absolute, sign, total = np.abs(diff), np.sign(diff), j[:, None] + j[None, :]
    i1 = np.empty((k, 2, k, 2), dtype=np.intp)
    i2 = np.empty_like(i1)
    c1 = np.empty((k, 2, k, 2))
    c2 = np.empty_like(c1)
    i1[:, 0, :, 0], c1[:, 0, :, 0], i2[:, 0, :, 0], c2[:, 0, :, 0] = absolute, 0.5, total, 0.5
    i1[:, 1, :, 1], c1[:, 1, :, 1], i2[:, 1, :, 1], c2[:, 1, :, 1] = absolute, 0.5, total, -0.5
    i1[:, 0, :, 1], c1[:, 0, :, 1] = length + total, 0.5
    i2[:, 0, :, 1], c2[:, 0, :, 1] = length + absolute, -0.5 * sign
    i1[:, 1, :, 0], c1[:, 1, :, 0] = length + total, 0.5
    i2[:, 1, :, 0], c2[:, 1, :, 0] = length + absolute, 0.5 * sign  # sign(k - j) = -sign(j - k)
    tables = tuple(a.reshape(2 * k, 2 * k) for a in (i1, c1, i2, c2))
    for table in tables:
        table.setflags(write=False)
    return tables


def _unit_phasors(frequency_hz: np.ndarray, tc: np.ndarray) -> np.ndarray:
    """(m, n) ``exp(2 pi i f t)``; an evenly spaced batch costs two exponentials, not m."""
    m = frequency_hz.shape[0]
    if m > 2:
        step = np.diff(frequency_hz)
        if np.allclose(step, step[0], rtol=1e-9, atol=0.0):
            out = np.empty((m, tc.shape[0]), dtype=complex)
            out[0] = np.exp(2j * np.pi * frequency_hz[0] * tc)
            ratio = np.exp(2j * np.pi * step[0] * tc)
            for i in range(1, m):
                np.multiply(out[i - 1], ratio, out=out[i])
            return out
    return np.exp(2j * np.pi * frequency_hz[:, None] * tc)


def normal_equations(data: SeriesData, frequency_hz, n_harmonics: int):
    """Normal matrix ``A'WA`` and right-hand side ``A'Wy`` of the trend + K-harmonic model.

    Built from trigonometric sums instead of the design matrix: with ``z = exp(2 pi i f t)``,
    every harmonic-harmonic entry is half a sum or difference of ``Z_m = sum w z^m`` for
    ``m = 0..2K`` (``cos j cos k = [cos (j-k) + cos (j+k)] / 2`` and so on), which costs
    O(n K) per frequency instead of the O(n K^2) of forming ``A'WA`` - the idea behind
    Schwarzenberg-Czerny's (1996, ApJ 460, L107) multi-harmonic periodogram.

    Parameters
    ----------
    data : SeriesData
    frequency_hz : float or (m,) float
    n_harmonics : int

    Returns
    -------
    gram : (..., p, p) float
        ``p = d + 1 + 2 K``, columns ordered trend, ``cos 1, sin 1, cos 2, ...``.
    rhs : (..., p) float
    """
    f = np.asarray(frequency_hz, dtype=float)
    big_k, n_trend = n_harmonics, data.n_trend
    z = _unit_phasors(np.atleast_1d(f), data.tc)  # (m, n)
    planes = powers(z, 2 * big_k)  # (m, 2K+1, n)
    zsum = planes @ data.weight_c  # (m, 2K+1)
    sums = planes[:, 1 : big_k + 1] @ data.rows  # (m, K, D+1)
    ysum = sums[..., 0]  # (m, K)
    cross = np.swapaxes(sums[..., 1:], -1, -2)  # (m, D, K)

    i1, c1, i2, c2 = _block_tables(big_k)
    values = np.concatenate([zsum.real, zsum.imag], axis=-1)  # (m, 2(2K+1))
    block = c1 * values[:, i1] + c2 * values[:, i2]  # (m, 2K, 2K)
    m = zsum.shape[0]
    p = n_trend + 2 * big_k
    gram = np.empty((m, p, p))
    gram[:, :n_trend, :n_trend] = data.trend_gram
    gram[:, n_trend:, n_trend:] = block
    trend_harmonic = np.stack([cross.real, cross.imag], axis=-1).reshape(m, n_trend, 2 * big_k)
    gram[:, :n_trend, n_trend:] = trend_harmonic
    gram[:, n_trend:, :n_trend] = np.swapaxes(trend_harmonic, -1, -2)
    rhs = np.empty((m, p))
    rhs[:, :n_trend] = data.trend_rhs
    rhs[:, n_trend::2] = ysum.real
    rhs[:, n_trend + 1 :: 2] = ysum.imag
    if f.ndim == 0:
        return gram[0], rhs[0]
    return gram, rhs


def nested_rss(data: SeriesData, frequency_hz, n_harmonics: int, trend_degrees=None) -> np.ndarray:
    """Weighted residual sum of squares of the models with 0..K harmonics.

    Parameters
    ----------
    data : SeriesData
    frequency_hz : float or (m,) float
        Trial fundamental frequencies.
    n_harmonics : int
        K, the largest harmonic count.
    trend_degrees : sequence of int, optional
        Trend degrees up to the data's own: the normal matrix is built once and its trend
        block cut down for each (the Legendre columns are nested). Default: the data's degree.

    Returns
    -------
    (K + 1,) or (m, K + 1) float, or with `trend_degrees` (len(trend_degrees), K + 1) for one frequency
        Entry ``j`` is the RSS of the trend plus harmonics 1..j. Where the normal matrix is
        singular (a harmonic too close to the trend or above the sampling's reach) the RSS
        stays at the last well-determined value, so that model never wins on fit.
    """
    gram, rhs = normal_equations(data, frequency_hz, n_harmonics)
    if trend_degrees is None:
        return _nested_from_normal(gram, rhs, data.n_trend, n_harmonics, data.yy)
    n_trend = data.n_trend
    rows = []
    for degree in trend_degrees:
        keep = np.r_[0 : degree + 1, n_trend : gram.shape[-1]]
        sub_gram, sub_rhs = gram[..., keep[:, None], keep], rhs[..., keep]
        rows.append(_nested_from_normal(sub_gram, sub_rhs, degree + 1, n_harmonics, data.yy))
    return np.stack(rows)


def _nested_from_normal(gram: np.ndarray, rhs: np.ndarray, n_trend: int, n_harmonics: int, yy: float) -> np.ndarray:
    """Nested RSS (trend plus 0..K harmonics) from a normal matrix with `n_trend` trend columns first."""
    chol, z = _whitened(gram, rhs)
    explained = np.cumsum(z * z, axis=-1)
    rss = yy - explained[..., n_trend - 1 + 2 * np.arange(n_harmonics + 1)]
    # A column nearly dependent on the earlier ones has a tiny pivot; its z is noise amplified.
    pivots = np.diagonal(chol, axis1=-2, axis2=-1)
    bad = pivots[..., n_trend:].reshape(pivots.shape[:-1] + (n_harmonics, 2)).min(axis=-1) < 1e-4
    bad = np.concatenate([np.zeros(bad.shape[:-1] + (1,), bool), np.cumsum(bad, axis=-1) > 0], axis=-1)
    rss = np.where(bad, np.nan, rss)
    rss = np.maximum(rss, 1e-300 * yy)
    return _forward_fill(rss)


def _whitened(gram: np.ndarray, rhs: np.ndarray):
    """Cholesky factor of the Jacobi-scaled normal matrix and ``z = L^-1 rhs`` (scaled alike)."""
    diagonal = np.diagonal(gram, axis1=-2, axis2=-1)
    # A column that vanishes at every sample (a sine at exactly the Nyquist frequency) has only
    # rounding in its row: scale it as if it were 1e-12 of the largest, not by its own zero.
    scale = np.sqrt(np.maximum(diagonal, 1e-12 * diagonal.max(axis=-1, keepdims=True) + 1e-300))
    gram = gram / scale[..., :, None] / scale[..., None, :]
    # Built from trigonometric sums, such a column's diagonal can come out a rounding below zero.
    scaled = np.einsum("...ii->...i", gram)
    scaled[...] = np.maximum(scaled, 0.0)
    # A tiny ridge keeps the factorisation defined for nearly collinear columns; exactly
    # collinear ones (a harmonic on the sampling's alias of another, or of the trend, in sparse
    # sampling) need a larger one, which leaves their pivots tiny and their models unchosen.
    for ridge in (1e-10, 1e-7, 1e-4):
        try:
            chol = np.linalg.cholesky(gram + ridge * np.eye(gram.shape[-1]))
            break
        except np.linalg.LinAlgError:
            continue
    else:
        raise np.linalg.LinAlgError("the normal matrix of the harmonic fit is singular even with a 1e-4 ridge")
    z = np.linalg.solve(chol, (rhs / scale)[..., None])[..., 0]
    return chol, z


def _forward_fill(rss: np.ndarray) -> np.ndarray:
    """Replace NaN entries by the last finite value before them along the last axis."""
    index = np.where(np.isfinite(rss), np.arange(rss.shape[-1]), 0)
    index = np.maximum.accumulate(index, axis=-1)
    return np.take_along_axis(rss, index, axis=-1)


def bic(rss, n_points: int, n_harmonics, trend_degree: int, n_effective: float | None = None) -> np.ndarray:
    """Bayesian information criterion with the noise scale profiled out.

    Parameters
    ----------
    rss : float or array
        Weighted residual sums of squares.
    n_points : int
        Samples fitted.
    n_harmonics : int or array
        Harmonic counts (broadcast against `rss`).
    trend_degree : int
    n_effective : float, optional
        Independent samples when the noise is correlated (default `n_points`). Correlated
        samples carry less information: the log-likelihood scales by ``n_eff / n`` and the
        penalty counts ``ln n_eff`` per parameter.

    Returns
    -------
    array like `rss`
        ``n_eff ln(rss / n) + ((d + 1) + 2 K + 1) ln n_eff``; lower is better.
    """
    n_eff = float(n_points if n_effective is None else n_effective)
    n_par = trend_degree + 1 + 2 * np.asarray(n_harmonics) + 1
    return n_eff * np.log(np.asarray(rss) / n_points) + n_par * math.log(n_eff)


def trend_absorption(n_cycles, degree: int):
    """The largest fraction of a sinusoid's variance a polynomial trend can absorb.

    Over a pass of ``n_cycles`` cycles of the sinusoid (evenly sampled), the least-squares
    Legendre polynomial of `degree` takes up this fraction of the sinusoid's variance, at the
    worst phase. Exact: ``int P_l(x) exp(i a x) dx = 2 i^l j_l(a)`` over [-1, 1] with
    ``a = pi n_cycles`` (j_l the spherical Bessel functions), evaluated at 64 phases.

    Parameters
    ----------
    n_cycles : float or (m,) float
    degree : int

    Returns
    -------
    float or (m,) float

    Examples
    --------
    >>> round(float(trend_absorption(1.0, 3)), 3), round(float(trend_absorption(3.0, 3)), 3)
    (0.991, 0.176)
    """
    from scipy.special import spherical_jn  # heavy: reading stored results imports this module

    a = math.pi * np.asarray(n_cycles, dtype=float)[..., None]  # (..., 1)
    phase = np.linspace(0.0, math.pi, 64, endpoint=False)
    order = np.arange(1, int(degree) + 1)
    power = (2 * order + 1) * spherical_jn(order, a[..., None]) ** 2  # (..., 1, degree)
    even = power[..., order % 2 == 0].sum(axis=-1)
    odd = power[..., order % 2 == 1].sum(axis=-1)
    captured = even * np.cos(phase) ** 2 + odd * np.sin(phase) ** 2
    total = 0.5 + 0.5 * np.cos(2 * phase) * spherical_jn(0, 2 * a) - (np.cos(phase) * spherical_jn(0, a)) ** 2
    return np.max(captured / np.maximum(total, 1e-300), axis=-1)


@lru_cache(maxsize=16)
def _cycles_for_degree(degree: int) -> float:
    """Fewest cycles from which on `degree` never absorbs more than `TREND_ABSORPTION`."""
    cycles = np.arange(0.25, 40.0, 0.01)
    bad = np.flatnonzero(trend_absorption(cycles, degree) > TREND_ABSORPTION)
    return float(cycles[bad[-1] + 1]) if bad.size else float(cycles[0])


def trend_degree_limit(n_cycles: float, n_points: int, cap: int) -> int:
    """Highest trend degree a candidate of `n_cycles` cycles in a pass of `n_points` samples allows.

    The trend is fitted jointly with the harmonics, so it must not be able to imitate the
    candidate: its degree is the highest whose polynomials absorb at most `TREND_ABSORPTION`
    of a sinusoid at the candidate's period for that period and every shorter one
    (`trend_absorption`; degree 1 from 1.21 cycles, 2 from 1.6, 3 from 2.96), with at least
    `SAMPLES_PER_TREND_TERM` samples per coefficient, and at most `cap`.
    """
    by_points = max(0, n_points // SAMPLES_PER_TREND_TERM - 1)
    degree = 0
    while degree < min(cap, by_points) and n_cycles >= _cycles_for_degree(degree + 1):
        degree += 1
    return degree


def max_harmonics(frequency_hz: float, ceiling_hz: float, n_points: int, trend_degree: int, cap: int) -> int:
    """Largest harmonic count whose top harmonic stays under `ceiling_hz` (at least 1).

    The count is also capped by `cap` and by a quarter of the samples, so that the fit keeps
    at least four samples per parameter.
    """
    by_frequency = int(math.floor(ceiling_hz / frequency_hz * (1 + 1e-9)))
    by_samples = (n_points // 4 - trend_degree - 2) // 2
    return max(1, min(by_frequency, cap, by_samples))


@dataclass(frozen=True, eq=False)
class HarmonicFit:
    """A fitted Fourier series plus trend at one frequency.

    Attributes
    ----------
    frequency_hz : float
        Fundamental frequency.
    frequency_err_hz : float
        1-sigma uncertainty of the frequency from the linearised covariance (the noise scale
        taken from the residuals), inflated by `inflation`.
    n_harmonics, trend_degree : int
    axis : TimeAxis
    coefficients : (d + 1 + 2K,) float
        Trend coefficients (Legendre), then ``a_1, b_1, a_2, b_2, ...`` (magnitudes).
    rss : float
        Weighted residual sum of squares.
    n_points : int
    bic : float
    residual_lag1 : float
        Lag-1 autocorrelation of the weighted residuals.
    inflation : float
        ``sqrt((1 + rho) / (1 - rho))`` with ``rho = max(residual_lag1, 0)``: the factor by which
        AR(1)-correlated residuals widen a least-squares error (effective sample size
        ``n (1 - rho) / (1 + rho)``).
    """

    frequency_hz: float
    frequency_err_hz: float
    n_harmonics: int
    trend_degree: int
    axis: TimeAxis
    coefficients: np.ndarray
    rss: float
    n_points: int
    bic: float
    residual_lag1: float
    inflation: float

    @property
    def period_s(self) -> float:
        """Period of the fundamental, seconds."""
        return 1.0 / self.frequency_hz

    @property
    def period_err_s(self) -> float:
        """1-sigma period uncertainty, seconds (``sigma_f / f^2``)."""
        return self.frequency_err_hz / self.frequency_hz**2

    @property
    def harmonic_amplitudes_mag(self) -> np.ndarray:
        """(K,) semi-amplitude of each harmonic, magnitudes."""
        ab = self.coefficients[self.trend_degree + 1 :].reshape(-1, 2)
        return np.hypot(ab[:, 0], ab[:, 1])

    def trend_mag(self, t_s) -> np.ndarray:
        """(n,) the fitted trend at times `t_s`."""
        return self.axis.trend_basis(t_s, self.trend_degree) @ self.coefficients[: self.trend_degree + 1]

    def periodic_mag(self, t_s) -> np.ndarray:
        """(n,) the periodic part (zero mean) at times `t_s`."""
        basis = harmonic_basis(np.asarray(t_s, dtype=float) - self.axis.t_mid_s, self.frequency_hz, self.n_harmonics)
        return basis @ self.coefficients[self.trend_degree + 1 :]

    def model_mag(self, t_s) -> np.ndarray:
        """(n,) trend plus periodic part at times `t_s`."""
        return self.trend_mag(t_s) + self.periodic_mag(t_s)

    def phase_curve_mag(self, phase) -> np.ndarray:
        """Periodic part against phase (cycles from the pass middle), for drawing folded curves."""
        t = self.axis.t_mid_s + np.asarray(phase, dtype=float) / self.frequency_hz
        return self.periodic_mag(t)

    @property
    def peak_to_peak_mag(self) -> float:
        """Range of the periodic part over one cycle, magnitudes."""
        curve = self.phase_curve_mag(np.linspace(0.0, 1.0, 512, endpoint=False))
        return float(curve.max() - curve.min())


def fit_harmonics(data: SeriesData, frequency_hz: float, n_harmonics: int) -> HarmonicFit:
    """Fit the series at one frequency and estimate the frequency's uncertainty.

    The uncertainty comes from the covariance of the model linearised in all parameters, the
    frequency included (its column is the derivative of the periodic part with respect to
    ``f``), scaled by the residual variance ``rss / (n - n_par)`` and by the AR(1) inflation of
    the residuals.

    Parameters
    ----------
    data : SeriesData
    frequency_hz : float
    n_harmonics : int

    Returns
    -------
    HarmonicFit
    """
    w = data.weight
    gram, rhs = normal_equations(data, frequency_hz, n_harmonics)
    scale = np.sqrt(np.diagonal(gram))
    coefficients = (
        np.linalg.solve(gram / scale[:, None] / scale[None, :] + 1e-12 * np.eye(len(rhs)), rhs / scale) / scale
    )
    a = _design(data, frequency_hz, n_harmonics)
    residual = data.y - a @ coefficients
    rss = float(residual @ (w * residual))
    n = data.n_points
    n_trend = data.n_trend
    # d/df of a_k cos(2 pi k f t) + b_k sin(2 pi k f t) = 2 pi k t (-a_k sin + b_k cos).
    ab = coefficients[n_trend:].reshape(-1, 2)
    k = np.arange(1, n_harmonics + 1)
    cos_k, sin_k = a[:, n_trend::2], a[:, n_trend + 1 :: 2]
    d_df = 2 * np.pi * data.tc * ((-ab[:, 0] * sin_k + ab[:, 1] * cos_k) @ k)
    n_par = gram.shape[0] + 1
    augmented = np.empty((n_par, n_par))
    augmented[:-1, :-1] = gram
    augmented[:-1, -1] = augmented[-1, :-1] = a.T @ (w * d_df)
    augmented[-1, -1] = d_df @ (w * d_df)
    sigma2 = rss / max(n - n_par, 1)
    scale = np.sqrt(np.maximum(np.diagonal(augmented), 1e-300))
    try:
        inverse = np.linalg.inv(augmented / scale[:, None] / scale[None, :])
        variance_f = float(inverse[-1, -1]) / scale[-1] ** 2 * sigma2
    except np.linalg.LinAlgError:
        variance_f = math.inf
    weighted = residual * np.sqrt(w)
    rho = float(np.dot(weighted[:-1], weighted[1:]) / np.dot(weighted, weighted)) if n > 3 else 0.0
    rho = rho if math.isfinite(rho) else 0.0
    inflation = math.sqrt((1 + max(rho, 0.0)) / max(1 - max(rho, 0.0), 1e-3))
    error = math.sqrt(variance_f) * inflation if variance_f >= 0 else math.inf
    return HarmonicFit(
        frequency_hz=float(frequency_hz),
        frequency_err_hz=error,
        n_harmonics=int(n_harmonics),
        trend_degree=data.trend_degree,
        axis=data.axis,
        coefficients=coefficients,
        rss=rss,
        n_points=n,
        bic=float(bic(rss, n, n_harmonics, data.trend_degree)),
        residual_lag1=rho,
        inflation=inflation,
    )


def scan_frequency(data: SeriesData, frequency_hz: float, n_harmonics: int, half_width_hz: float):
    """Locate the RSS minimum of a K-harmonic model near a start on a short grid.

    A grid with steps of ``0.3 / (K T)`` (a third of the width of the RSS minimum of the top
    harmonic) covers ``frequency_hz +- half_width_hz`` in one batched evaluation, extended once
    if the minimum lies on its edge; a parabola through the lowest point and its neighbours
    places the minimum.

    Parameters
    ----------
    data : SeriesData
    frequency_hz : float
        Start.
    n_harmonics : int
        Harmonics of the scanned model.
    half_width_hz : float
        How far from the start the minimum may be.

    Returns
    -------
    frequency_hz : float
        The parabola's vertex.
    rss : (K + 1,) float
        Nested RSS (0..K harmonics) at the lowest grid point.
    """
    step = 0.3 / (n_harmonics * data.axis.duration_s)
    half_steps = max(1, int(math.ceil(half_width_hz / step)))
    offsets = step * np.arange(-half_steps, half_steps + 1)
    grid = frequency_hz + offsets
    rss = nested_rss(data, grid, n_harmonics)
    i = int(np.argmin(rss[:, -1]))
    if i in (0, len(grid) - 1):  # minimum on the edge: look one interval further
        grid = grid[i] + offsets
        rss = nested_rss(data, grid, n_harmonics)
        i = int(np.clip(np.argmin(rss[:, -1]), 1, len(grid) - 2))
    return _vertex(grid[i], step, *rss[i - 1 : i + 2, -1])[0], rss[i]


def polish_frequency(data: SeriesData, frequency_hz: float, n_harmonics: int) -> float:
    """Refine a frequency already near the RSS minimum of the K-harmonic model.

    The RSS at ``f + (-h, -h/4, 0, h/4, h)`` with ``h = 0.3 / (K T)`` (one batched evaluation):
    a parabola through the three points around the lowest inner one places the minimum. If the
    lowest point is an outer one, the centre moves there and the step repeats (at most four
    times). The RSS is not exactly quadratic; the remaining bias is ~1e-4 of the resolution
    ``1 / T``, far below the statistical error of any real light curve. (Gauss-Newton steps are
    not used: on real light curves the model mismatch makes them crawl.)
    """
    h = 0.3 / (n_harmonics * data.axis.duration_s)
    offsets = np.array([-h, -h / 4, 0.0, h / 4, h])
    f = float(frequency_hz)
    for _ in range(4):
        rss = nested_rss(data, f + offsets, n_harmonics)[:, -1]
        i = int(np.argmin(rss))
        if i in (0, 4):
            f += offsets[i]
            continue
        x, r = offsets[i - 1 : i + 2], rss[i - 1 : i + 2]
        # Vertex of the parabola through three unequally spaced points.
        d1, d2 = (r[1] - r[0]) / (x[1] - x[0]), (r[2] - r[1]) / (x[2] - x[1])
        curvature = (d2 - d1) / (x[2] - x[0])
        if curvature <= 0:
            return f + x[1]
        vertex = 0.5 * (x[0] + x[1]) - d1 / (2 * curvature)
        return f + float(np.clip(vertex, x[0], x[2]))
    return f


def refine_frequency(
    data: SeriesData, frequency_hz: float, n_harmonics: int, half_width_hz: float, scan_harmonics: int | None = None
) -> float:
    """`scan_frequency` (with `scan_harmonics`, default all) then `polish_frequency` with all K.

    Scanning with fewer harmonics keeps the grid short for glint-like curves whose many
    harmonics make the full model's minimum narrow.

    Returns
    -------
    float
        The refined frequency.
    """
    k_scan = n_harmonics if scan_harmonics is None else max(1, min(scan_harmonics, n_harmonics))
    f, _ = scan_frequency(data, frequency_hz, k_scan, half_width_hz)
    return polish_frequency(data, f, n_harmonics)


def _vertex(center: float, h: float, left: float, mid: float, right: float) -> tuple[float, bool]:
    """Vertex of the parabola through (c - h, c, c + h), moved at most one step; True if inside."""
    curvature = left - 2 * mid + right
    if curvature <= 0:
        if mid <= min(left, right):
            return center, True
        return center + (h if right < left else -h), False
    shift = 0.5 * h * (left - right) / curvature
    return center + max(-h, min(h, shift)), abs(shift) <= h
