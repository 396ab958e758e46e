"""LightCurve, periodograms and dispersion measures: exact answers and astropy as the authority."""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
from astropy import units as u
from astropy.timeseries import LombScargle
import numpy as np
import pytest

import ingest
from rsodb.periods.dispersion import pdm, pdm_bic, pdm_f_test, pdm_within, string_length
from rsodb.periods.lightcurve import LightCurve
from rsodb.periods.power import PERIODOGRAM_METHODS, frequency_grid
from tests.conftest import TOPEX_PHV


@pytest.fixture(scope="module")
def topex_pass():
    return ingest.read_file(TOPEX_PHV)[0]


def sine_curve(period_s=7.0, n=1500, cadence_s=0.2, noise=0.0, seed=0, amplitude=0.5):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * cadence_s
    mag = (
        5.0 + amplitude * np.sin(2 * np.pi * t / period_s) + rng.normal(0, noise, n)
        if noise
        else 5.0 + amplitude * np.sin(2 * np.pi * t / period_s)
    )
    return LightCurve.from_arrays(t, mag, np.full(n, max(noise, 0.01)))


# -- construction ------------------------------------------------------------------------------
def test_from_pass_keeps_valid_unsaturated_and_uses_corrected_magnitudes(topex_pass):
    lc = LightCurve.from_pass(topex_pass)
    # The TOPEX file carries the extinction sign error, so best_mag is mag_corrected.
    assert topex_pass.mag_corrected is not None
    np.testing.assert_array_equal(lc.mag, topex_pass.mag_corrected)
    assert len(lc) == len(topex_pass) == 2320
    assert lc.epoch_utc == topex_pass.start_utc
    # Flag two samples saturated and three invalid: exactly those five go.
    saturated = np.zeros(len(topex_pass), bool)
    saturated[[10, 20]] = True
    valid = np.ones(len(topex_pass), bool)
    valid[[30, 31, 32]] = False
    flagged = LightCurve.from_pass(topex_pass.replace(saturated=saturated, valid=valid))
    assert len(flagged) == 2315
    assert not np.isin(topex_pass.t_s[[10, 20, 30, 31, 32]], flagged.t_s).any()
    assert len(LightCurve.from_pass(topex_pass.replace(saturated=saturated), include_saturated=True)) == 2320


def test_arrays_are_read_only_and_operations_return_new_objects():
    lc = sine_curve()
    with pytest.raises(ValueError):
        lc.mag[0] = 1.0
    detrended = lc.detrend()
    assert detrended is not lc and lc.trend_mag is None and detrended.trend_mag is not None


def test_from_arrays_accepts_quantities():
    t = np.arange(10) * 0.5
    lc = LightCurve.from_arrays((t / 60) * u.min, np.ones(10), np.full(10, 0.01) * u.mag)
    np.testing.assert_allclose(lc.t_s, t, rtol=1e-12)  # minutes converted back to seconds


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"t_s": [0, 1, 1], "mag": [1, 2, 3], "mag_err": [0.1] * 3}, "strictly increasing"),
        ({"t_s": [0, 1, 2], "mag": [1, np.nan, 3], "mag_err": [0.1] * 3}, "non-finite"),
        ({"t_s": [0, 1, 2], "mag": [1, 2], "mag_err": [0.1] * 3}, "mag has 2 samples but t_s has 3"),
        ({"t_s": [0, 1, 2], "mag": [1, 2, 3], "mag_err": [0.1, -1, 0.1]}, "negative"),
        ({"t_s": [0], "mag": [1], "mag_err": [0.1]}, "at least 2 samples"),
    ],
)
def test_bad_arrays_are_refused_with_a_clear_message(kwargs, message):
    with pytest.raises(ValueError, match=message):
        LightCurve(**kwargs)


# -- detrend and fold ---------------------------------------------------------------------------
def test_detrend_removes_a_cubic_exactly_and_accumulates_the_trend():
    t = np.linspace(0, 300, 900)
    x = t / 150 - 1
    trend = 6 + 0.4 * x - 0.3 * x**2 + 0.2 * x**3
    lc = LightCurve.from_arrays(t, trend, np.full(t.size, 0.02))
    flat = lc.detrend(3)
    # A cubic lies in the span of the degree-3 basis: the residual is rounding only.
    assert np.max(np.abs(flat.mag)) < 1e-10
    np.testing.assert_allclose(flat.trend_mag, trend, atol=1e-10)
    again = flat.detrend(1)
    np.testing.assert_allclose(again.trend_mag, trend, atol=1e-10)
    assert again.trend_degree == 1


def test_detrend_validates_degree():
    with pytest.raises(ValueError, match="degree=11 must be a whole number from 0 to 10"):
        sine_curve().detrend(11)


def test_fold_gives_exact_phases_and_cycles():
    lc = LightCurve.from_arrays(np.array([0.0, 2.5, 5.0, 12.5, 21.0]), np.zeros(5))
    folded = lc.fold(5.0, epoch_s=0.0)
    np.testing.assert_allclose(folded.phase, [0.0, 0.5, 0.0, 0.5, 0.2], atol=1e-12)
    np.testing.assert_array_equal(folded.cycle, [0, 0, 1, 2, 4])
    with pytest.raises(ValueError, match="period_s=-1.0 must be a positive number of seconds"):
        lc.fold(-1.0)
    centres, means = lc.fold(5.0).binned(4)
    np.testing.assert_allclose(centres, [0.125, 0.375, 0.625, 0.875])
    assert np.isnan(means[1]) and means[0] == 0.0


# -- frequency grid and periodograms -----------------------------------------------------------
def test_frequency_grid_spacing_and_limits():
    t = np.arange(2001) * 0.25  # T = 500 s, cadence 0.25 s
    grid = frequency_grid(t, oversampling=10)
    assert grid[0] == pytest.approx(1 / 500.0, rel=1e-12)
    np.testing.assert_allclose(np.diff(grid), 1 / (10 * 500.0), rtol=1e-9)
    assert grid[-1] <= 1 / (2 * 0.25) + 1e-12 and grid[-1] > 2.0 - 1 / 5000
    narrow = frequency_grid(t, 5, minimum_period_s=2.0, maximum_period_s=100.0)
    assert narrow[0] == pytest.approx(0.01) and narrow[-1] <= 0.5
    with pytest.raises(ValueError, match="period range .* is empty"):
        frequency_grid(t, minimum_period_s=200.0, maximum_period_s=100.0)


def test_lombscargle_matches_astropy_exact_method():
    lc = sine_curve(noise=0.05).detrend()
    pg = lc.periodogram()
    weight = lc.weights()
    exact = LombScargle(lc.t_s, lc.mag, 1 / np.sqrt(weight)).power(pg.frequency_hz[::50], method="cython")
    # astropy's fast method is an approximation of the exact sums (extirpolation): agreement to
    # 1e-3 in normalised power is what its documentation promises for default settings.
    np.testing.assert_allclose(pg.power[::50], exact, atol=1e-3)
    # Peak at 1/7 Hz within a tenth of the resolution 1/T.
    assert abs(pg.peak_frequency_hz - 1 / 7.0) < 0.1 / lc.duration_s


def test_periodogram_methods_all_peak_at_a_sine_period():
    lc = sine_curve(period_s=11.0, n=800, noise=0.02)
    for method in PERIODOGRAM_METHODS:
        pg = lc.periodogram(method, maximum_period_s=40.0)
        # PDM and string length also show subharmonics (22 s folds as well); within 3-30 s the
        # best must be 11 s within one grid step of its peak width.
        band = (pg.period_s > 3) & (pg.period_s < 16)
        best = pg.period_s[band][np.argmax(pg.power[band])]
        assert abs(1 / best - 1 / 11.0) < 0.2 / lc.duration_s, method


def test_multiterm_lombscargle_grid_stops_below_nyquist_for_the_top_term():
    lc = sine_curve(n=400)
    pg = lc.periodogram(nterms=3)
    # Top term 3 f must stay below the Nyquist frequency 1 / (2 * 0.2 s) = 2.5 Hz.
    assert 3 * pg.frequency_hz[-1] <= 2.5 + 1e-9
    with pytest.raises(ValueError, match="one-term Lomb-Scargle"):
        pg.false_alarm_probability()
    with pytest.raises(ValueError, match="nterms=0 must be a whole number from 1 to 10"):
        lc.periodogram(nterms=0)
    with pytest.raises(ValueError, match="method='fourier' is not one of"):
        lc.periodogram("fourier")


def test_false_alarm_probability_of_noise_and_of_a_signal():
    rng = np.random.default_rng(5)
    t = np.arange(1000) * 0.2
    noise = LightCurve.from_arrays(t, rng.normal(0, 0.1, t.size), np.full(t.size, 0.1)).periodogram()
    # Pure noise: Baluev's bound is not small (it is an upper bound, so > 0.05 for this seed).
    assert noise.false_alarm_probability() > 0.05
    signal = sine_curve(noise=0.1, amplitude=0.05, n=1000).periodogram()
    assert signal.false_alarm_probability() < 1e-6


def test_best_period_chain_on_topex(topex_pass):
    # The chain of STYLE.md: detrend -> periodogram -> best_period, disambiguated.
    pg = LightCurve.from_pass(topex_pass).detrend().periodogram()
    assert pg.peak_period_s == pytest.approx(2.371, abs=0.002)  # the plain LS peak: a quarter
    assert pg.best_period.unit == u.s
    assert pg.best_period.value == pytest.approx(9.48, abs=0.02)


# -- dispersion measures -----------------------------------------------------------------------
def test_pdm_of_a_sine_matches_the_bin_width_formula():
    t = np.arange(20000) * 0.01
    y = np.sin(2 * np.pi * t / 7.0)
    # Noise-free sine, M equal bins: within-bin variance / total variance = 1 - sinc^2(1/M)
    # (the bin means keep sinc(1/M) of the amplitude). M = 10: 1 - sinc(0.1)^2 = 0.03274.
    theta = pdm(t, y, [7.0], 10)[0]
    assert theta == pytest.approx(1 - np.sinc(0.1) ** 2, rel=0.01)
    assert pdm(t, y, [5.3], 10)[0] > 0.95


def test_pdm_f_test_is_uniform_under_the_null_and_small_for_different_halves():
    rng = np.random.default_rng(3)
    t = np.arange(3000) * 0.2
    p_values = []
    for seed in range(40):
        y = np.sin(2 * np.pi * t / 6.0) + np.random.default_rng(seed).normal(0, 0.3, t.size)
        (w_short, w_long), (m_short, m_long) = pdm_within(t, y, [6.0, 12.0], [24, 48])
        p_values.append(pdm_f_test(t.size, w_short, m_short, w_long, m_long))
    # Identical halves: p is ~uniform, so at most ~3 of 40 below 0.05 (binomial 99.9% bound: 7).
    assert sum(p < 0.05 for p in p_values) <= 7
    y = np.sin(2 * np.pi * t / 6.0) + 0.1 * np.sin(2 * np.pi * t / 12.0) + rng.normal(0, 0.3, t.size)
    (w_short, w_long), (m_short, m_long) = pdm_within(t, y, [6.0, 12.0], [24, 48])
    assert pdm_f_test(t.size, w_short, m_short, w_long, m_long) < 1e-6
    assert pdm_bic(t, y, [6.0, 12.0], [24, 48]).shape == (2,)


def test_string_length_is_shortest_at_the_period():
    t = np.arange(1000) * 0.13
    y = np.sin(2 * np.pi * t / 4.4)
    lengths = string_length(t, y, [4.4, 3.1, 5.9])
    assert np.argmin(lengths) == 0
    # A folded noiseless sine: the string is the curve's arc length ~ its length over one cycle,
    # sqrt(1 + (2 pi * 0.25)^2 ...) bounded by 1 + total variation 1.0 (scaled range 0.5, twice).
    assert 1.0 < lengths[0] < 1.0 + 1.0 + 1e-9


# -- output ------------------------------------------------------------------------------------
def test_to_pandas_and_plots(topex_pass):
    lc = LightCurve.from_pass(topex_pass).detrend()
    frame = lc.to_pandas()
    assert list(frame.columns) == ["t_s", "mag", "mag_err", "trend_mag"]
    assert frame.index[0] == topex_pass.start_utc
    ax = lc.plot()
    assert ax.yaxis_inverted() and ax.get_ylabel() == "V magnitude (reduced to 1000 km) - trend"
    ax = lc.fold(9.48).plot()
    assert ax.get_xlim() == (0.0, 1.0)
    ax = lc.periodogram().plot(mark_period_s=9.48)
    assert ax.get_xscale() == "log"
    assert math.isclose(lc.duration_s, 464.162, abs_tol=0.01)
