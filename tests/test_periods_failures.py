"""Where period searches fail: one test per verdict, on curves whose truth is known.

Rendered curves come from the project's own renderer (`raycast.render`, direct method) of the
code-built COSMOS 2502 model along a real pass geometry (its TLE, Derenivka), with seeded noise;
their truth is computed from the geometry, not from the search: the synodic period is the time
the Sun, observer and phase-angle-bisector directions take to turn once about the body's spin
axis. Analytic curves (`rsodb.periods.injection`) carry their period.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from ingest.site import DERENIVKA
from raycast.geometry.attitude import PrecessingSpin, TorqueFree
from raycast.geometry.orbit import Satellite
from raycast.geometry.pass_geometry import PassGeometry
from raycast.models import cosmos2502
from raycast.renderer.methods import render
from raycast.renderer.photometry import REFERENCE_RANGE_KM, magnitude
from rsodb.periods.injection import Injection, shape_mag, synthetic_lightcurve
from rsodb.periods.lightcurve import LightCurve
from rsodb.periods.search import find_period
from rsodb.periods.verdicts import VERDICTS
from rsodb.samples.generate import TLES

# A dark-sky, sunlit pass of COSMOS 2502 (NORAD 40358) over Derenivka (the sample archive's).
PASS_START = np.datetime64("2024-01-18T15:43:43", "ns")


@functools.cache
def _scene():
    return cosmos2502.build()


def rendered(attitude, duration_s: float, cadence_s: float = 0.2):
    """(body geometry, t_s, magnitudes at 1000 km) of the pass's first `duration_s`, dark frames dropped."""
    n = int(round(duration_s / cadence_s))
    times = PASS_START + (np.arange(n) * cadence_s * 1e9).astype("timedelta64[ns]")
    geometry = PassGeometry.compute(Satellite.from_tle(list(TLES[40358])), DERENIVKA, times, 0.0, n_sub=1)
    body = geometry.body_frame(attitude)
    # 0.05 mag accuracy (pixel 9 cm): the curves below swing by several magnitudes.
    model = render(_scene(), body, method="direct", accuracy_mag=0.05)
    mag = magnitude(model.intensity_m2_sr, REFERENCE_RANGE_KM, "V")
    lit = np.isfinite(mag)
    return body, geometry.t_s[lit], mag[lit]


def noisy(t_s, mag, noise_mag: float, seed: int) -> LightCurve:
    rng = np.random.default_rng(seed)
    return LightCurve.from_arrays(t_s, mag + rng.normal(0.0, noise_mag, mag.size), np.full(mag.size, noise_mag))


def synodic_periods_s(body, t_s_all, axis: int) -> dict:
    """Times the Sun, the observer and their bisector take to turn once about body axis `axis`.

    The light curve of a spinning body repeats when the body shows the same face to the Sun and
    the observer; over a LEO pass those directions turn in the body frame at slightly different
    rates, so the light curve's period lies among these three (Harris et al. 1984 take the
    bisector).
    """
    directions = {
        "sun": body.sun_body[:, 0],
        "observer": body.obs_body[:, 0],
        "bisector": body.sun_body[:, 0] + body.obs_body[:, 0],
    }
    a, b = [i for i in range(3) if i != axis]
    out = {}
    for name, vector in directions.items():
        angle = np.unwrap(np.arctan2(vector[:, b], vector[:, a]))
        out[name] = float(2 * np.pi / abs(np.polyfit(t_s_all, angle, 1)[0]))
    return out


# -- the short pass of the issue --------------------------------------------------------------
@pytest.fixture(scope="module")
def short_pass():
    # COSMOS 2502 tumbling end over end (about body x) at 40.5 s, its axis precessing on a 45 deg
    # cone in 1620 s: 120 s at 5 frames per second, 0.02 mag noise - about three cycles.
    attitude = PrecessingSpin(
        period_s=40.5,
        phase_deg=75.0,
        precession_period_s=1620.0,
        precession_phase_deg=60.0,
        precession_angle_deg=45.0,
        spin_axis="x",
    )
    body, t_s, mag = rendered(attitude, 120.0)
    truth = synodic_periods_s(body, np.arange(body.sun_body.shape[0]) * 0.2, axis=0)
    return noisy(t_s, mag, 0.02, seed=18), mag, truth


def test_short_pass_reports_the_40_s_candidate_with_sane_amplitude(short_pass):
    lc, noiseless, truth = short_pass
    result = find_period(lc)
    bisector = truth["bisector"]
    # The requirement: the ~40 s candidate within 3% of the synodic period the geometry
    # gives (39.2 s for the bisector; the Sun's and the observer's turn in 39.7 and 38.9 s).
    assert max(truth.values()) / min(truth.values()) < 1.03
    assert result.best_period_s == pytest.approx(bisector, rel=0.03)
    assert result.uncertainty_s < 0.01 * bisector
    # About three cycles: the verdict names the period only with a caveat, never "confident".
    assert 2.9 < result.n_cycles < 3.2
    assert result.verdict in ("too short", "ambiguous harmonic")
    # Amplitude and S/N held to what the magnitudes span (the search once said 1636 mag and
    # S/N 615,396 here): the periodic model is no wider than the data, and the S/N no larger
    # than the data's half-range over white noise of the stated errors.
    span = np.ptp(lc.mag)
    assert result.amplitude_mag <= span
    assert result.amplitude_mag == pytest.approx(np.ptp(noiseless), rel=0.25)
    assert result.signal_to_noise <= 0.5 * span / (0.02 * np.sqrt(np.pi / len(lc)))
    # Every candidate is listed with its uncertainty and cycles; the trend of each is no more
    # flexible than its cycles allow (constant below 1.21 cycles).
    for candidate in result.candidates:
        assert np.isfinite(candidate.uncertainty_s) and candidate.uncertainty_s > 0
        if candidate.n_cycles < 1.21:
            assert candidate.trend_degree == 0


# -- one test per verdict ---------------------------------------------------------------------
def test_every_verdict_is_one_of_the_documented_ones():
    assert VERDICTS == (
        "confident",
        "ambiguous harmonic",
        "aliased",
        "non-periodic",
        "single glint",
        "too short",
        "no signal",
    )


def test_no_signal_for_a_constant_curve_and_for_pure_noise():
    t = np.arange(600) * 0.2
    constant = find_period(LightCurve.from_arrays(t, np.full(t.size, 7.3)))
    assert constant.verdict == "no signal" and "constant" in constant.reason
    rounded = find_period(
        LightCurve.from_arrays(t, 7.3 + np.round(np.random.default_rng(1).normal(0, 1e-3, t.size), 3))
    )
    assert rounded.verdict == "no signal"
    for seed in range(5):
        rng = np.random.default_rng(seed)
        # White noise on a pass trend (a parabola of 0.5 mag): Baluev's false-alarm
        # probability exceeds 1e-3 except by chance (< 1 in 1000 by construction).
        trend = 0.5 * ((t / t[-1] - 0.5) * 2) ** 2
        noise = LightCurve.from_arrays(t, 6 + trend + rng.normal(0, 0.05, t.size), np.full(t.size, 0.05))
        assert find_period(noise).verdict == "no signal"


def test_too_short_lists_the_candidates():
    t = np.arange(1000) * 0.2
    rng = np.random.default_rng(4)
    mag = 6 + 0.4 * np.sin(2 * np.pi * t / 110.0) + rng.normal(0, 0.03, t.size)
    result = find_period(LightCurve.from_arrays(t, mag, np.full(t.size, 0.03)))
    # 200 s of a 110 s period: 1.8 cycles.
    assert result.verdict == "too short" and not result.has_period
    # The period is measured anyway, to a few percent (the error says how well).
    assert abs(result.best_period_s - 110.0) < 3 * result.uncertainty_s
    assert "candidates: 110" in result.reason and "1.8 cycles" in result.reason
    assert result.amplitude_mag <= np.ptp(mag)


def test_ambiguous_harmonic_when_the_halves_differ_by_less_than_the_noise_shows():
    # Two nearly equal halves: the odd harmonic is 3% of the amplitude at S/N ~3 per harmonic.
    results = [
        find_period(synthetic_lightcurve(Injection("two_faced", 9.5, 1.0, 0.1, asymmetry=0.03, seed=510 + i)))
        for i in range(4)
    ]
    verdicts = [r.verdict for r in results]
    assert "ambiguous harmonic" in verdicts
    for r in results:
        # Never confidently the half period, and the rival is named.
        assert not (r.verdict == "confident" and abs(r.best_period_s - 4.75) < 0.05)
        if r.verdict == "ambiguous harmonic":
            assert "4.75" in r.reason or "9.5" in r.reason


def test_aliased_with_the_frame_rate():
    # 0.5 s at a 0.2 s cadence: 2.5 samples per cycle, the frame rate's alias 1/(5 - 2) s fits
    # the samples as well.
    t = np.arange(1500) * 0.2
    rng = np.random.default_rng(2)
    mag = 6 + 0.5 * np.sin(2 * np.pi * t / 0.5 + 0.4) + rng.normal(0, 0.05, t.size)
    result = find_period(LightCurve.from_arrays(t, mag, np.full(t.size, 0.05)))
    assert result.verdict == "aliased" and not result.has_period
    assert "frame rate" in result.reason


def test_aliased_with_a_gap():
    # Two 24 s stretches 10 minutes apart: each gives the 7.3 s period to ~0.5%, far too loosely
    # to count the ~84 cycles across the gap; periods one cycle apart fit alike.
    rng = np.random.default_rng(5)
    t = np.concatenate([np.arange(0, 24, 0.2), np.arange(624, 648, 0.2)])
    mag = 6 + 0.3 * np.sin(2 * np.pi * t / 7.3) + rng.normal(0, 0.1, t.size)
    result = find_period(LightCurve.from_arrays(t, mag, np.full(t.size, 0.1)))
    assert result.verdict == "aliased" and not result.has_period
    assert "gap" in result.reason
    # Both the best period and its alias lie within one cycle count of the truth.
    cycles = 636.0 / 7.3
    assert abs(636.0 / result.best_period_s - cycles) < 1.5


def test_aliased_when_the_cycles_are_counted_across_gaps():
    # Two 100 s stretches 600 s apart of a 196.6 s sinusoid at S/N 30: the 800 s pass holds 4.1
    # cycles, but the samples cover one; periods a fraction of a cycle apart across the gap fit
    # alike (the verdict calibration found such passes called confident).
    rng = np.random.default_rng(0)
    t = np.concatenate([np.arange(500) * 0.2, 700.0 + np.arange(500) * 0.2])
    period = 195.0 * rng.uniform(0.97, 1.03)
    mag = 6 + 1.5 * shape_mag("sinusoid", t / period + rng.random()) + rng.normal(0, 0.05, t.size)
    result = find_period(LightCurve.from_arrays(t, mag, np.full(t.size, 0.05)))
    assert result.verdict == "aliased" and not result.has_period
    assert "cover only 1.0 cycles" in result.reason


def test_single_glint():
    # A flat curve and one 0.5 s flash of 2 mag in a 300 s pass.
    t = np.arange(1500) * 0.2
    rng = np.random.default_rng(6)
    flash = -2.0 * np.exp(-0.5 * ((t - 131.0) / 0.25) ** 2)
    mag = 6 + 0.2 * (t / t[-1]) + flash + rng.normal(0, 0.02, t.size)
    result = find_period(LightCurve.from_arrays(t, mag, np.full(t.size, 0.02)))
    assert result.verdict == "single glint" and not result.has_period
    assert result.n_flashes == 1 and "131.0 s" in result.reason
    # Two flashes 40 s apart: one interval.
    mag2 = mag - 2.0 * np.exp(-0.5 * ((t - 171.0) / 0.25) ** 2)
    two = find_period(LightCurve.from_arrays(t, mag2, np.full(t.size, 0.02)))
    assert two.verdict == "too short" and "two flashes 40" in two.reason


def test_a_flash_over_a_periodic_curve_is_not_a_single_glint():
    # The same flash over a 7 s sinusoid of 0.1 mag (S/N 5 per sample): the flash carries most of
    # the variation, but the curve without it still has a significant period. (The verdict is
    # "non-periodic": the period leaves the flash unexplained.)
    t = np.arange(1500) * 0.2
    rng = np.random.default_rng(6)
    flash = -2.0 * np.exp(-0.5 * ((t - 131.0) / 0.25) ** 2)
    mag = 6 + 0.05 * np.sin(2 * np.pi * t / 7.0) + flash + rng.normal(0, 0.02, t.size)
    result = find_period(LightCurve.from_arrays(t, mag, np.full(t.size, 0.02)))
    assert result.n_flashes == 1
    assert result.verdict != "single glint"
    assert result.best_period_s == pytest.approx(7.0, rel=0.01)


def test_fewer_than_four_cycles_is_never_confident():
    # A clean sinusoid 3.5 times in the pass: twice its period does not repeat twice, so
    # a cycle whose halves differ cannot be excluded however clean the data.
    t = np.arange(1500) * 0.2
    rng = np.random.default_rng(7)
    period = t[-1] / 3.5
    mag = 6 + 0.4 * np.sin(2 * np.pi * t / period) + rng.normal(0, 0.02, t.size)
    result = find_period(LightCurve.from_arrays(t, mag, np.full(t.size, 0.02)))
    assert result.verdict == "ambiguous harmonic" and result.has_period
    assert result.best_period_s == pytest.approx(period, rel=0.01)
    assert "fewer than 4" in result.reason


@pytest.fixture(scope="module")
def tumbling():
    # Torque-free tumbling (non-principal-axis rotation) with rotation and precession rates of
    # the same order: the light curve never repeats exactly.
    attitude = TorqueFree.from_angular_momentum(
        (1.0, 0.63, 0.4468), (0.0909, -0.12344, -0.09841), pole_ra_deg=172.46, pole_dec_deg=-40.83
    )
    _, t_s, mag = rendered(attitude, 400.0)
    return noisy(t_s, mag, 0.03, seed=0)


def test_non_periodic_for_a_tumbler(tumbling):
    result = find_period(tumbling)
    assert result.verdict == "non-periodic" and not result.has_period
    # The best single period explains less than half of the variation beyond the noise.
    assert result.explained_fraction < 0.5
    assert "does not repeat" in result.reason


def test_confident_for_a_clean_periodic_curve():
    result = find_period(synthetic_lightcurve(Injection("four_faced", 9.37, 1.0, 0.05, asymmetry=0.4, seed=42)))
    assert result.verdict == "confident" and result.has_period
    # Within 4 sigma of the truth (sigma ~1e-4 s).
    assert abs(result.best_period_s - 9.37) < 4 * result.uncertainty_s
    assert result.explained_fraction > 0.9
