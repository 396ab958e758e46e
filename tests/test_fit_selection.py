"""Sample selection never strobes: bins and contiguous windows, the phase-coverage check, and the
main job's quick fit on a pass whose period equals the old quick fit's stride.

Authority: the real TOPEX pass of 2024-07-30 (2320 samples over 464 s, 0.2 s cadence), on which
the old quick fit's 50 evenly spread samples were 9.47 s apart, within 0.1% of the light curve's
9.48 s period.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from ingest import read_file
from rsodb.fit.config import DataConfig, FitConfig
from rsodb.fit.selection import MAX_PHASE_GAP, phase_coverage, select_samples
from rsodb.pipeline import QUICK_FIT
from tests.conftest import TOPEX_PHV


@pytest.fixture(scope="module")
def topex():
    return read_file(TOPEX_PHV)[0]


def old_stride_indices(n: int, points: int = 50) -> np.ndarray:
    return np.unique(np.linspace(0, n - 1, points).round().astype(int))


def old_stride_s(observed) -> float:
    """The old quick fit's spacing: the pass over 49 intervals (the stamps vary by a few ms)."""
    return observed.duration_s / 49


def test_the_old_quick_selection_strobes_and_the_check_says_so(topex):
    t_s = topex.t_s
    old = old_stride_indices(len(topex))
    stride_s = old_stride_s(topex)
    assert stride_s == pytest.approx(9.47, abs=0.01)
    # A period prior of +-1% around the old stride: the kept samples see one phase of a light
    # curve at that period (every sample 9.47 s after the last), the whole pass sees them all.
    coverage = phase_coverage(t_s[old], t_s, (stride_s * 0.99, stride_s * 1.01))
    # All 50 samples land in two or three of the 20 phase bins (the stamps jitter by a few ms).
    assert coverage.poor and coverage.max_gap_cycles >= 0.85
    # The worst candidate is the spacing itself (to the stamps' few-ms jitter).
    assert coverage.periods_s[coverage.worst] == pytest.approx(stride_s, rel=3e-3)
    assert np.max(coverage.window_gap_cycles) < 0.1  # 48 samples per cycle


def test_selection_of_evenly_spread_single_samples_is_refused_with_the_fix(topex):
    # 50 windows of one sample each are the old stride again.
    data = DataConfig(max_points=50, windows=50)
    with pytest.raises(ValueError, match=r"cover the spin phase poorly at P = 9\.4.* fit every sample"):
        select_samples(topex, data, (9.47 * 0.99, 9.47 * 1.01), "topex")


def test_quick_fit_selection_keeps_contiguous_windows_a_cycle_long(topex):
    data = FitConfig.from_dict(QUICK_FIT).data
    bounds = (9.47 * 0.99, 9.47 * 1.01)
    selection = select_samples(topex, data, bounds, "topex")
    kept = np.flatnonzero(selection.kept)
    assert selection.n <= data.max_points and selection.bin_size == 1  # 0.2 s turns TOPEX 7.6 deg: no bins
    # Contiguous runs of consecutive samples, each at least one slowest candidate period long.
    runs = np.split(kept, np.flatnonzero(np.diff(kept) > 1) + 1)
    assert len(runs) >= 2
    for run in runs:
        assert (topex.t_s[run[-1]] - topex.t_s[run[0]]) + 0.2 >= bounds[1]
    # ... spread over the pass: the first and last windows touch its ends.
    assert runs[0][0] == 0 and runs[-1][-1] == len(topex) - 1
    assert selection.coverage.max_gap_cycles <= MAX_PHASE_GAP
    assert selection.window.sum() == len(topex) and "contiguous window" in selection.description


def test_bins_average_flux_and_span_their_samples(topex):
    # A slow candidate (P >= 200 s): 10 deg of rotation take 5.6 s, so bins of up to 27 samples
    # are allowed; 2320 samples into at most 200 points need bins of 12.
    data = DataConfig(max_points=200)
    selection = select_samples(topex, data, (200.0, 220.0), "topex")
    assert selection.bin_size == 12 and selection.n <= 200
    mag, err = selection.magnitudes(topex)
    first = selection.groups[0]
    flux = 10 ** (-0.4 * topex.best_mag[first])
    assert mag[0] == pytest.approx(-2.5 * np.log10(flux.mean()), abs=1e-12)
    # Independent errors of equal weight: the bin's relative flux error is the members' over sqrt(12)
    # when their errors are alike (within the spread of this pass's quoted errors).
    assert err[0] < np.max(topex.mag_err[first])
    # The stamps are 0.2 s apart to within a few milliseconds.
    assert selection.exposure_s(topex) == pytest.approx(11 * 0.2 + topex.exposure_s, abs=0.01)
    t_mid = selection.time_utc(topex)[0]
    assert t_mid == topex.time_utc[first[0]] + (topex.time_utc[first[-1]] - topex.time_utc[first[0]]) // 2


def test_a_point_model_bins_error_holds_a_glint_but_not_a_ramp(topex):
    """The global search compares its model at each bin's mid-time: a bin whose samples bend (a
    glint) adds the mid-time's difference from the bin's mean to its error; a straight ramp adds
    nothing (its middle is its mean)."""
    n = len(topex)
    mag = 8.0 + 0.002 * np.arange(n)  # a ramp, 0.01 mag over a bin of 5
    glint = 2 * 5 + 1  # the second sample of the third bin
    mag[glint] -= 3.0
    observed = topex.replace(mag=mag, mag_corrected=None, mag_err=np.full(n, 0.01))
    selection = select_samples(observed, DataConfig(max_points=n // 5), (200.0, 220.0), "ramp")
    assert selection.bin_size == 5 and np.array_equal(selection.groups[2], np.arange(10, 15))
    mean, plain = selection.magnitudes(observed)
    point_mean, point = selection.magnitudes(observed, point_model=True)
    np.testing.assert_array_equal(point_mean, mean)
    ramp = np.ones(selection.n, dtype=bool)
    ramp[2] = False
    np.testing.assert_array_equal(point[ramp], plain[ramp])
    # The glint's bin: its mean is 1.47 mag brighter than its middle sample (13 + 4 of 5 flux
    # units); the error grows to that difference, less the middle sample's noise (0.01 mag,
    # one sample: the bin of 5 has one middle) and the mean's (its own error, added back).
    difference = mean[2] - mag[12]
    assert difference == pytest.approx(-2.5 * np.log10((10**1.2 + 4) / 5), abs=0.01)
    expected = np.sqrt(difference**2 - 0.01**2)
    assert point[2] == pytest.approx(expected, rel=1e-9) and point[2] > 100 * plain[2]


@pytest.mark.slow
def test_main_jobs_quick_fit_on_a_pass_strobed_by_the_old_stride(topex, tmp_path):
    """A light curve whose period equals the old quick fit's 9.47 s stride: the quick fit's samples
    cover its phase, and the stored residual RMS is over every sample of the pass."""
    from rsodb.fit.coverage import inject
    from rsodb.fit.runner import FitProblem, fit_problem
    from rsodb.pipeline import quick_fit_configs

    stride_s = old_stride_s(topex)
    quick = quick_fit_configs([22076])[22076]
    # The analytic ellipsoid stands in for TOPEX's model (a cheaper shape; the selection is the same).
    # A body turning end over end about z shows two alike halves: its light curve repeats at P/2.
    prior = {"kind": "uniform", "low": 2 * stride_s * 0.99, "high": 2 * stride_s * 1.01}
    config = quick.with_model(shape="ellipsoid").replace(
        parameters={"spin_period_s": prior, "precession_period_s": 5000.0, "jitter_mag": 0.0}
    )
    truth = {
        "spin_period_s": 2 * stride_s,
        "spin_phase_deg": 30.0,
        "precession_period_s": 5000.0,
        "precession_phase_deg": 90.0,
        "precession_angle_deg": 20.0,
        "jitter_mag": 0.0,
    }
    every = config.replace(data=replace(config.data, max_points=0))
    model = FitProblem.build(topex, every).posterior.model
    observed = inject(topex, model, truth, noise_mag=0.02, rng=np.random.default_rng(3))
    # What the old selection saw: a ramp of under a tenth of the light curve's swing.
    swing = np.ptp(observed.mag)
    old = observed.mag[old_stride_indices(len(observed))]
    assert (
        np.ptp(
            old
            - np.polyval(
                np.polyfit(observed.t_s[old_stride_indices(len(observed))], old, 2),
                observed.t_s[old_stride_indices(len(observed))],
            )
        )
        < 0.3 * swing
    )

    problem = FitProblem.build(observed, config)
    assert not problem.selection.coverage.poor
    result = fit_problem(problem, tmp_path / "chain.h5", progress=False)
    assert result.n_window == len(observed) and result.fitted.sum() == problem.selection.groups.size
    residuals = (result.mag_obs - result.mag_model)[result.in_window]
    assert result.residual_rms_mag == pytest.approx(np.sqrt(np.mean(residuals**2)), rel=1e-12)
    # The fit follows the swings (up to the swing's size), it does not flatten them: its
    # residuals are a fraction of the light curve's own scatter.
    assert result.residual_rms_mag < 0.5 * np.std(observed.mag)
    # The stored model curve covers the whole pass at finer steps than the samples' cadence or
    # 1/40 of the fastest period.
    curve_t = (result.curve.time_utc - observed.time_utc[0]) / np.timedelta64(1, "s")
    assert curve_t[0] == 0 and curve_t[-1] == pytest.approx(observed.duration_s, abs=1e-6)
    assert np.median(np.diff(curve_t)) <= 0.2 + 1e-9
