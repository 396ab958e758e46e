"""The reduction equations against hand values, and the fit against PROVENANCE.md's values.

Tolerances: the files print magnitudes to 0.001, so each written magnitude carries a rounding
error uniform on +-0.0005 mag (RMS 0.00029); a fitted zero point or term over ~2000 rows is
determined to ~1e-4, so PROVENANCE's one-decimal values must come out within 1e-3.
"""

from __future__ import annotations

import numpy as np
import pytest

import ingest
from ingest.reduction import (
    LAW_RMS_LIMIT_MAG,
    airmass,
    fit_note,
    fit_reduction,
    instrumental_mag,
    range_correction_mag,
    sign_corrected_mag,
    standard_mag,
)
from tests.conftest import COSMOS2540_PHV, COSMOS2553_JD_PHV, COSMOS2553_PHC, TOPEX_PHV

ROUNDING_HALF_STEP_MAG = 0.0005  # half the last printed digit of a magnitude
ROUNDING_RMS_MAG = 0.0005 / np.sqrt(3)  # RMS of a uniform +-0.0005 error: 2.9e-4


def test_equations_by_hand():
    # -2.5 log10(1000 / 0.1) = -10; 1/sin 30 deg = 2; -5 log10(10000/1000) = -5.
    assert instrumental_mag(np.array([1000.0]), 0.1)[0] == pytest.approx(-10.0, abs=1e-12)
    assert airmass(np.array([30.0, 90.0]))[0] == pytest.approx(2.0, abs=1e-12)
    assert airmass(np.array([90.0]))[0] == pytest.approx(1.0, abs=1e-12)
    assert range_correction_mag(np.array([10000.0, 1000.0])).tolist() == pytest.approx([-5.0, 0.0], abs=1e-12)
    # A + m_inst - k X + m_r = 20 - 10 - 0.3 * 2 - 5
    assert standard_mag(np.array([1000.0]), 0.1, np.array([30.0]), np.array([10000.0]), 20.0, 0.3)[0] == pytest.approx(
        4.4, abs=1e-12
    )


def test_undefined_inputs_give_nan():
    assert np.isnan(instrumental_mag(np.array([0.0, -1.0]), 1.0)).all()
    assert np.isnan(airmass(np.array([0.0, -5.0]))).all()
    assert np.isnan(range_correction_mag(np.array([0.0]))).all()


def test_fit_recovers_a_synthetic_law():
    rng = np.random.default_rng(1)
    el = rng.uniform(15, 80, 3000)
    flux = 10 ** rng.uniform(3, 5, 3000)
    range_km = rng.uniform(800, 3000, 3000)
    mag = np.round(standard_mag(flux, 0.2, el, range_km, 19.4, 0.1), 3)  # k = 0.1: c = -0.1; rounded as printed
    fit = fit_reduction(mag, flux, 0.2, el, range_km)
    assert fit.zero_point_mag == pytest.approx(19.4, abs=1e-4)
    assert fit.extinction_term_mag == pytest.approx(-0.1, abs=1e-4)
    assert fit.rms_mag == pytest.approx(ROUNDING_RMS_MAG, rel=0.1)
    assert not fit.sign_error and fit.n_points == 3000
    # The standard errors describe the actual scatter of the estimates (3 sigma).
    assert abs(fit.extinction_term_mag + 0.1) < 3 * fit.extinction_term_err_mag + 1e-12


def test_fit_flags_a_positive_term_and_the_correction_undoes_it():
    rng = np.random.default_rng(2)
    el = rng.uniform(15, 80, 1000)
    flux = 10 ** rng.uniform(3, 5, 1000)
    range_km = rng.uniform(800, 3000, 1000)
    right = standard_mag(flux, 0.1, el, range_km, 20.5, 0.2)
    wrong = np.round(right + 2 * 0.2 * airmass(el), 3)  # +kX instead of -kX
    fit = fit_reduction(wrong, flux, 0.1, el, range_km)
    assert fit.sign_error and fit.extinction_term_mag == pytest.approx(0.2, abs=1e-4)
    assert np.abs(sign_corrected_mag(wrong, el, fit) - right).max() < ROUNDING_HALF_STEP_MAG + 1e-4


def test_fit_refuses_degenerate_input():
    el = np.full(10, 40.0)  # one airmass: A and c cannot be separated
    assert fit_reduction(np.full(10, 5.0), np.full(10, 1e4), 1.0, el, np.full(10, 1500.0)) is None
    assert fit_reduction(np.ones(2), np.ones(2), 1.0, np.array([30.0, 40.0]), np.ones(2) * 1e3) is None


def test_a_file_that_breaks_the_law_is_not_called_a_sign_error():
    rng = np.random.default_rng(3)
    el = rng.uniform(15, 80, 500)
    flux = 10 ** rng.uniform(3, 5, 500)
    range_km = rng.uniform(800, 3000, 500)
    mag = standard_mag(flux, 0.1, el, range_km, 20.0, 0.3) + 2 * 0.3 * airmass(el) + rng.normal(0, 0.05, 500)
    fit = fit_reduction(mag, flux, 0.1, el, range_km)
    assert fit.extinction_term_mag > 0 and fit.rms_mag > LAW_RMS_LIMIT_MAG and not fit.sign_error
    assert fit_note(fit).startswith("the magnitudes do not follow the reduction law (RMS 0.05")
    assert fit_note(None) == "not fitted: fewer than 3 usable rows or no spread in airmass"


# PROVENANCE.md: TOPEX 2024-07-30 A=19.4, +0.1 X; COSMOS 2540 A=21.4, -0.4 X; COSMOS 2553 (JD) A=20.5, +0.2 X.
PROVENANCE = [(TOPEX_PHV, 19.4, 0.1, True), (COSMOS2540_PHV, 21.4, -0.4, False), (COSMOS2553_JD_PHV, 20.5, 0.2, True)]


@pytest.mark.parametrize("path, zero_point, term, sign_error", PROVENANCE, ids=lambda v: getattr(v, "name", None))
def test_real_files_reduction(shared_data, path, zero_point, term, sign_error):
    (p,) = ingest.read_file(path)
    r = p.reduction
    assert r.zero_point_mag == pytest.approx(zero_point, abs=1e-3)
    assert r.extinction_term_mag == pytest.approx(term, abs=1e-3)
    assert r.rms_mag < 1.2 * ROUNDING_RMS_MAG and r.n_points == len(p)
    assert r.sign_error is sign_error
    if sign_error:
        # mag_corrected is the magnitude the law gives with -kX: compare with standard_mag.
        expected = standard_mag(p.flux, p.exposure_s, p.el_deg, p.range_km, zero_point, term)
        assert np.abs(p.mag_corrected - expected).max() < ROUNDING_HALF_STEP_MAG + 2e-4
        assert np.abs(p.mag_corrected - (p.mag - 2 * term * airmass(p.el_deg))).max() < 2e-3 * airmass(p.el_deg).max()
        assert p.best_mag is p.mag_corrected
    else:
        assert p.mag_corrected is None and p.best_mag is p.mag
        expected = standard_mag(p.flux, p.exposure_s, p.el_deg, p.range_km, zero_point, -term)
        assert np.abs(p.mag - expected).max() < ROUNDING_HALF_STEP_MAG + 2e-4


def test_phc_magnitudes_follow_the_same_law(shared_data):
    # Finding (recorded in docs/formats.md): mB, mV = A - 2.5 log10(Imp/dt) - k X + m_r with the
    # files' Derenivka El/Rg, k_B = 0.65, k_V = 0.45, residuals at the 0.001-mag rounding level.
    b, v = ingest.read_file(COSMOS2553_PHC)
    for p, zero_point, extinction in ((b, 14.4233, 0.65), (v, 14.0393, 0.45)):
        r = p.reduction
        assert r.extinction_term_mag == pytest.approx(-extinction, abs=1e-3)
        assert r.zero_point_mag == pytest.approx(zero_point, abs=1e-3)
        assert r.rms_mag < 1.2 * ROUNDING_RMS_MAG and not r.sign_error and p.mag_corrected is None
