"""Period search: harmonic fits against exact least squares, the synodic correction against a
simulated spinning body, the real passes of ../shared/data, storage and priors."""

from __future__ import annotations

import math

import h5py
import numpy as np
import pytest

import ingest
from rsodb.fit.priors import Uniform
from rsodb.periods.analysis import analyse_pass
from rsodb.periods.harmonic import (
    SeriesData,
    bic,
    fit_harmonics,
    harmonic_basis,
    nested_rss,
    normal_equations,
    refine_frequency,
)
from rsodb.periods.lightcurve import LightCurve
from rsodb.periods.search import PeriodResult, PeriodSettings, find_period
from rsodb.periods.synodic import (
    SynodicCorrection,
    azimuth_rate_rad_s,
    bisector_rate_rad_s,
    phase_angle_bisector,
    sidereal_period_s,
)
from tests.conftest import COSMOS2540_PHV, COSMOS2553_JD_PHV, COSMOS2553_PHC, TOPEX_PHV


def passes_of(path):
    return {p.band: p for p in ingest.read_file(path)}


@pytest.fixture(scope="module")
def topex_result():
    return analyse_pass(passes_of(TOPEX_PHV)["V"])


# -- harmonic fits: exact algebra --------------------------------------------------------------
def random_data(seed=0, n=400, degree=3):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, 300, n))
    y = rng.normal(size=n) + np.sin(t)
    w = rng.uniform(0.5, 2, n)
    return SeriesData.from_arrays(t, y, w, degree)


def explicit_design(data, f, k):
    return np.concatenate([data.trend, harmonic_basis(data.tc, f, k)], axis=1)


@pytest.mark.parametrize("frequency_hz", [0.013, 0.37, 1.9])
def test_normal_equations_from_trigonometric_sums_equal_the_design_matrix_products(frequency_hz):
    data = random_data()
    a = explicit_design(data, frequency_hz, 7)
    gram, rhs = normal_equations(data, frequency_hz, 7)
    # Both are sums of the same products; only rounding differs (1e-12 of the largest entry).
    np.testing.assert_allclose(gram, a.T @ (a * data.weight[:, None]), atol=1e-12 * np.abs(gram).max())
    np.testing.assert_allclose(rhs, a.T @ (data.weight * data.y), atol=1e-12 * np.abs(rhs).max())


def test_nested_rss_equals_separate_least_squares_fits_for_every_harmonic_count():
    data = random_data(seed=1)
    frequencies = np.array([0.11, 0.2])
    batch = nested_rss(data, frequencies, 6)
    sw = np.sqrt(data.weight)
    for i, f in enumerate(frequencies):
        a = explicit_design(data, f, 6)
        for k in range(7):
            cols = a[:, : 4 + 2 * k]
            c, *_ = np.linalg.lstsq(cols * sw[:, None], data.y * sw, rcond=None)
            rss = np.sum(data.weight * (data.y - cols @ c) ** 2)
            assert batch[i, k] == pytest.approx(rss, rel=1e-9)


def test_bic_formula_and_effective_sample_size():
    assert bic(2.0, 100, 3, 2) == pytest.approx(100 * math.log(0.02) + 10 * math.log(100))
    assert bic(2.0, 100, 3, 2, n_effective=25) == pytest.approx(25 * math.log(0.02) + 10 * math.log(25))


def test_fit_recovers_a_noiseless_series_and_its_frequency():
    t = np.arange(3000) * 0.1
    f_true = 1 / 9.7
    y = (
        5
        + 0.2 * (t / 150 - 1)
        + 0.6 * np.cos(2 * np.pi * f_true * (t - 149.95))
        - 0.3 * np.sin(4 * np.pi * f_true * (t - 149.95))
        + 0.1 * np.cos(6 * np.pi * f_true * (t - 149.95) + 1)
    )
    data = SeriesData.from_arrays(t, y, np.ones_like(t), 3)
    # Start 0.1 / T off the truth; noiseless, only the parabolic interpolation errs: within
    # 1e-4 of the resolution 1/T (3e-7 Hz, i.e. 3e-5 s on the period).
    f = refine_frequency(data, f_true + 0.1 / 300, 3, half_width_hz=0.3 / 300)
    assert f == pytest.approx(f_true, abs=1e-4 / 300)
    fit = fit_harmonics(data, f_true, 3)
    np.testing.assert_allclose(fit.harmonic_amplitudes_mag, [0.6, 0.3, 0.1], atol=1e-9)
    np.testing.assert_allclose(fit.model_mag(t), y, atol=1e-9)
    assert fit.peak_to_peak_mag == pytest.approx(np.ptp(fit.periodic_mag(t)), abs=2e-3)


# -- synodic correction ------------------------------------------------------------------------
def rotating_directions(t_s, omega_rad_s, half_angle_rad=0.4, tilt=0.0):
    """Sun and observer symmetric about a bisector that turns about +z at omega."""
    angle = omega_rad_s * t_s
    sun = np.stack([np.cos(angle + half_angle_rad), np.sin(angle + half_angle_rad), np.full_like(t_s, tilt)], -1)
    obs = np.stack([np.cos(angle - half_angle_rad), np.sin(angle - half_angle_rad), np.full_like(t_s, tilt)], -1)
    return sun / np.linalg.norm(sun, axis=1)[:, None], obs / np.linalg.norm(obs, axis=1)[:, None]


def test_bisector_rates_of_a_uniform_rotation():
    t = np.linspace(0, 400, 801)
    omega = 2 * math.pi / 600
    sun, obs = rotating_directions(t, omega)
    b = phase_angle_bisector(sun, obs)
    np.testing.assert_allclose(b, np.stack([np.cos(omega * t), np.sin(omega * t), 0 * t], -1), atol=1e-12)
    assert bisector_rate_rad_s(t, b) == pytest.approx(omega, rel=1e-9)
    # Tilted out of the plane: the bisector is (cos h cos wt, cos h sin wt, tau) / norm, so its
    # speed is omega cos h / sqrt(cos^2 h + tau^2) while its azimuth about z still turns at omega.
    tau, h = 0.2, 0.4
    tilted = phase_angle_bisector(*rotating_directions(t, omega, half_angle_rad=h, tilt=tau))
    radius = math.cos(h) / math.sqrt(math.cos(h) ** 2 + tau**2)
    assert bisector_rate_rad_s(t, tilted) == pytest.approx(omega * radius, rel=1e-6)
    assert azimuth_rate_rad_s(t, tilted, [0, 0, 1]) == pytest.approx(omega, rel=1e-9)
    assert azimuth_rate_rad_s(t, tilted, [0, 0, -2]) == pytest.approx(-omega, rel=1e-9)
    # Exact relation (1): 1/P_sid = 1/P_syn + omega / 2 pi.
    assert sidereal_period_s(10.0, omega) == pytest.approx(1 / (0.1 + 1 / 600), rel=1e-12)


def test_synodic_period_of_a_simulated_spinning_body_converts_back_to_the_sidereal_period():
    # A body spins about +z with P_sid = 9 s while the bisector turns the same way at one turn per
    # 600 s. Its brightness depends on the body's angle from the bisector, so the light curve
    # repeats at 1 / (1/9 - 1/600) = 9.137 s.
    t = np.arange(2500) * 0.2
    p_sid, omega = 9.0, 2 * math.pi / 600
    relative = 2 * math.pi * t / p_sid - omega * t
    rng = np.random.default_rng(2)
    mag = 6 + 0.5 * np.cos(relative) + 0.3 * np.cos(2 * relative + 1) + rng.normal(0, 0.03, t.size)
    result = find_period(LightCurve.from_arrays(t, mag, np.full(t.size, 0.03)))
    expected_synodic = 1 / (1 / p_sid - 1 / 600)
    assert result.verdict == "confident"
    # Within 4 sigma of the exact synodic period (sigma ~1e-4 s).
    assert abs(result.best_period_s - expected_synodic) < 4 * result.uncertainty_s
    sun, obs = rotating_directions(t, omega)
    correction = SynodicCorrection.from_directions(result.best_period_s, t, sun, obs)
    # The body turns with the bisector: the prograde branch is the truth, to the same 4 sigma.
    assert abs(correction.sidereal_prograde_s - p_sid) < 4 * result.uncertainty_s
    assert correction.sidereal_retrograde_s > expected_synodic > p_sid
    assert correction.bisector_rate_deg_s == pytest.approx(0.6, rel=1e-9)
    assert correction.bisector_arc_deg == pytest.approx(0.6 * t[-1], rel=1e-9)


def test_topex_synodic_correction_from_the_pass_geometry(topex_result):
    from raycast.geometry.pass_geometry import PassGeometry

    correction = topex_result.synodic
    assert correction is not None and topex_result.synodic_note == ""
    # Independent estimate of the bisector's mean angular speed: |db/dt| by central differences
    # of the geometry's directions, averaged (agrees with the arc length to 0.5%).
    geometry = PassGeometry.from_pass(passes_of(TOPEX_PHV)["V"], n_sub=1)
    b = phase_angle_bisector(geometry.sun_gcrs[:, 0], geometry.obs_gcrs[:, 0])
    speed = np.linalg.norm(np.gradient(b, geometry.t_s, axis=0), axis=1)
    assert correction.bisector_rate_deg_s == pytest.approx(math.degrees(speed.mean()), rel=0.005)
    # 1336 km orbit seen from 2500-2900 km: the bisector moves at ~0.08 deg/s, a 0.2% period shift.
    assert 0.05 < correction.bisector_rate_deg_s < 0.12
    p = topex_result.best_period_s
    assert correction.sidereal_prograde_s < p < correction.sidereal_retrograde_s
    assert correction.max_correction_s == pytest.approx(
        p * p * math.radians(correction.bisector_rate_deg_s) / (2 * math.pi), rel=0.01
    )


# -- the real passes ---------------------------------------------------------------------------
def test_topex_2024_07_30_gives_9_48_s_confident(topex_result):
    # The requirement: 9.48 +- 0.02 s with verdict confident (plain LS peaks at 2.37 s).
    assert topex_result.best_period_s == pytest.approx(9.48, abs=0.02)
    assert topex_result.verdict == "confident"
    assert topex_result.peak_period_s == pytest.approx(2.371, abs=0.002)
    labels = {c.label: c for c in topex_result.candidates}
    assert {"P", "2P", "3P", "4P"} <= set(labels)
    assert topex_result.candidates[0].label == "4P"
    # The half period is beaten decisively, and phase dispersion agrees (reason says so).
    assert labels["2P"].delta_bic > 100
    assert "phase dispersion confirms" in topex_result.reason
    assert topex_result.false_alarm_probability < 1e-10
    # The statistical error is far below the +-0.02 s the requirement allows.
    assert 0 < topex_result.uncertainty_s < 0.005


def test_cosmos_2553_march_pass_gives_a_confident_4_85_s():
    result = analyse_pass(passes_of(COSMOS2553_JD_PHV)["V"])
    # LS peaks at a quarter (1.213 s); the fold on 4.85 s is the repeating one.
    assert result.peak_period_s == pytest.approx(1.213, abs=0.002)
    assert result.best_period_s == pytest.approx(4.849, abs=0.005)
    assert result.verdict == "confident"


def test_cosmos_2553_phc_pass_gives_4_93_s_in_both_bands_with_an_honest_verdict():
    passes = passes_of(COSMOS2553_PHC)
    v, b = find_period(LightCurve.from_pass(passes["V"])), find_period(LightCurve.from_pass(passes["B"]))
    # 1 s photometer samples of a 4.93 s rotation: both bands agree within their errors.
    assert v.best_period_s == pytest.approx(4.93, abs=0.01)
    assert b.best_period_s == pytest.approx(v.best_period_s, abs=3 * math.hypot(v.uncertainty_s, b.uncertainty_s))
    # Both name the period, and both say why they are not sure of it against its half: the two
    # halves of the rotation differ in the first half of the pass and look alike in the second
    # (V: the second half alone prefers 2.465 s; B: the half period fits nearly as well).
    assert v.has_period and b.has_period
    assert v.verdict == b.verdict == "ambiguous harmonic"
    assert "second half of the pass prefers 2.46" in v.reason
    assert "2.46" in b.reason


@pytest.mark.parametrize("fraction", [0.5, 0.55, 0.6, 0.75, 0.9])
@pytest.mark.parametrize("end", ["head", "tail"])
def test_a_truncated_copy_of_the_b_pass_is_never_more_confident_than_the_pass(fraction, end):
    lc = LightCurve.from_pass(passes_of(COSMOS2553_PHC)["B"])
    keep = np.zeros(len(lc), bool)
    n = int(fraction * len(lc))
    keep[:n] = end == "head"
    keep[len(lc) - n :] |= end == "tail"
    full, part = find_period(lc), find_period(lc.select(keep))
    assert full.verdict == "ambiguous harmonic"
    # The odd harmonics that tell 4.93 s from 2.46 s are in the first ~55% of the pass only; a
    # copy holding that part must not call the choice confident unless each of its halves does.
    assert part.verdict != "confident", part.reason


def test_cosmos_2540_model_and_trend_stay_with_the_data():
    lc = LightCurve.from_pass(passes_of(COSMOS2540_PHV)["V"])
    result = find_period(lc)
    # Slow humps (at ~50, 115 and 185 s): the reported period repeats at least twice in the
    # 254 s pass, and no model is wider than the data.
    assert result.n_cycles >= 2
    assert result.amplitude_mag <= np.ptp(lc.mag)
    # The best period is astropy's one-term peak (66.26 s) within 3 sigma, but at 3.8 cycles twice
    # it cannot be excluded (docs/periods.md, scoreboard).
    assert result.verdict == "ambiguous harmonic" and "fewer than 4" in result.reason
    assert abs(result.best_period_s - result.peak_period_s) < 3 * result.uncertainty_s
    # The model stays with the light curve: within 0.6 mag of a 10 s running median everywhere
    # (measured 0.45 mag, at the steep final rise no period explains), and its trend inside the
    # range of the magnitudes. A free cubic jointly fitted with a one-cycle model used to swing
    # 2 mag away from the data.
    window = 100  # samples of 0.1 s
    median = np.array([np.median(lc.mag[max(0, i - window // 2) : i + window // 2]) for i in range(len(lc))])
    assert np.max(np.abs(result.model.model_mag(lc.t_s) - median)) < 0.6
    trend = result.model.trend_mag(lc.t_s)
    assert lc.mag.min() < trend.min() and trend.max() < lc.mag.max()


def test_phc_pass_without_elements_gets_its_sidereal_period_from_its_own_columns():
    result = analyse_pass(passes_of(COSMOS2553_PHC)["V"])
    # The geometry is the track of the file's Az/El/range columns (tests/test_track.py); the
    # synodic correction of a 4.93 s period over this 700 s pass: measured +-0.0052 s.
    assert result.synodic_note.startswith("geometry: track fitted to the file's Az/El/range columns")
    correction = result.synodic.sidereal_retrograde_s - result.synodic.sidereal_prograde_s
    assert 0.005 < correction < 0.02
    assert result.synodic.sidereal_prograde_s < result.best_period_s < result.synodic.sidereal_retrograde_s


# -- edge cases and validation ----------------------------------------------------------------
def test_too_few_samples_is_too_short_not_an_exception():
    lc = LightCurve.from_arrays(np.arange(12.0), np.sin(np.arange(12.0)))
    result = find_period(lc)
    assert result.verdict == "too short" and "only 12 usable samples" in result.reason
    assert math.isnan(result.best_period_s)


def test_find_period_rejects_non_lightcurves_and_unknown_settings():
    with pytest.raises(TypeError, match="needs a rsodb.periods.LightCurve, got ndarray"):
        find_period(np.zeros(10))
    lc = LightCurve.from_arrays(np.arange(50.0), np.zeros(50))
    with pytest.raises(TypeError, match="unknown period setting"):
        find_period(lc, oversample=3)
    with pytest.raises(ValueError, match="min_cycles=-1 must be a positive number"):
        PeriodSettings(min_cycles=-1)
    with pytest.raises(ValueError, match="trend_degree=11 must be a whole number from 0 to 10"):
        PeriodSettings(trend_degree=11)


# -- storage and priors ------------------------------------------------------------------------
def test_hdf5_round_trip_keeps_everything(tmp_path, topex_result):
    with h5py.File(tmp_path / "r.h5", "w") as f:
        topex_result.to_hdf5(f.create_group("result"))
    with h5py.File(tmp_path / "r.h5", "r") as f:
        back = PeriodResult.from_hdf5(f["result"])
        assert f["result"].attrs["schema"] == "rsodb.periods/2"
    assert back.to_dict() == topex_result.to_dict()
    assert back.epoch_utc == topex_result.epoch_utc
    t = np.linspace(0, 400, 50)
    np.testing.assert_allclose(back.model.model_mag(t), topex_result.model.model_mag(t), rtol=0, atol=1e-12)
    assert back.settings == topex_result.settings


def test_from_hdf5_refuses_other_groups(tmp_path):
    with h5py.File(tmp_path / "x.h5", "w") as f:
        group = f.create_group("other")
        with pytest.raises(ValueError, match="holds 'no schema', not a rsodb.periods/2 period result"):
            PeriodResult.from_hdf5(group)


def test_prior_for_fits(topex_result):
    p = topex_result.best_period_s
    synodic = Uniform(*topex_result.prior_interval_s(0.01, frame="synodic"))
    assert isinstance(synodic, Uniform)
    assert synodic.bounds == pytest.approx((0.99 * p, 1.01 * p), rel=1e-12)
    sidereal = Uniform(*topex_result.prior_interval_s())
    shorter, longer = topex_result.sidereal_bounds_s
    # Widened by the bisector correction on each side, so either sense of rotation is inside.
    assert sidereal.low == pytest.approx(0.99 * p - (p - shorter), rel=1e-12)
    assert sidereal.high == pytest.approx(1.01 * p + (longer - p), rel=1e-12)
    with pytest.raises(ValueError, match="width_frac=0.7 must be a fraction between 0 and 0.5"):
        topex_result.prior_interval_s(0.7)
    t = np.arange(600) * 0.2
    short = find_period(LightCurve.from_arrays(t, 5 + 0.5 * np.sin(2 * np.pi * t / 70.0), np.full(600, 0.01)))
    with pytest.raises(ValueError, match="has verdict 'too short'.*give the spin-period prior yourself"):
        short.prior_interval_s()
    low, high = short.prior_interval_s(force=True)
    assert low < short.best_period_s < high
