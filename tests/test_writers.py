"""Writers: real layouts (compared with the real files) and write -> read round trips.

Round-trip tolerances are half a unit of the last printed digit: magnitudes 0.0005,
flux 5e-5, angles and range 5e-4; times are exact in the UT variant for millisecond times
(ccd_phot prints ms) and within one float64 step of the JD (40 us) in the JD variant.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import ingest
from ingest.writers import write_ccd_phot, write_phc
from tests.conftest import COSMOS2540_PHV, COSMOS2553_JD_PHV, COSMOS2553_PHC, REAL_CCD_PHOT, TOPEX_PHV

# ccd_phot prints the JD as the shortest repr of a float64, whose step near JD 2.46e6 is 2**-31 day
# = 40.2 us: the float is within half a step of the time, its shortest repr within half a step of the float.
JD_STEP_NS = 40_234
PRINTED = {
    "mag": 5e-4,
    "mag_err": 5e-4,
    "flux": 5e-5,
    "flux_err": 5e-5,
    "az_deg": 5e-4,
    "el_deg": 5e-4,
    "range_km": 5e-4,
}


def assert_same_pass(a, b, time_tolerance_ns):
    assert len(a) == len(b)
    assert np.abs((a.time_utc - b.time_utc).astype(np.int64)).max() <= time_tolerance_ns
    for name, tolerance in PRINTED.items():
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=tolerance, err_msg=name)
    assert np.array_equal(a.saturated, b.saturated) and np.array_equal(a.valid, b.valid)
    assert (a.norad, a.name, a.cospar, a.band, a.site, a.exposure_s, a.tle) == (
        b.norad,
        b.name,
        b.cospar,
        b.band,
        b.site,
        b.exposure_s,
        b.tle,
    )


@pytest.mark.parametrize("variant", ["ut", "jd"])
@pytest.mark.parametrize("path", REAL_CCD_PHOT, ids=lambda p: p.name)
def test_ccd_phot_round_trip(shared_data, tmp_path, path, variant):
    (original,) = ingest.read_file(path)
    out = write_ccd_phot(original, tmp_path / f"copy.ph{original.band}", variant)
    (copy,) = ingest.read_file(out)
    # Writing JD times as UT truncates to the millisecond; everything else keeps the printed precision.
    tolerance = JD_STEP_NS if variant == "jd" else (0 if path != COSMOS2553_JD_PHV else 1_000_000)
    assert_same_pass(original, copy, tolerance)
    assert copy.reduction.extinction_term_mag == pytest.approx(original.reduction.extinction_term_mag, abs=1e-6)
    assert copy.header["time_variant"] == variant


@pytest.mark.parametrize("path, variant", [(COSMOS2540_PHV, "ut"), (COSMOS2553_JD_PHV, "jd")], ids=["ut", "jd"])
def test_ccd_phot_writer_reproduces_the_real_file(shared_data, tmp_path, path, variant):
    (p,) = ingest.read_file(path)
    real = path.read_text().splitlines()
    rows = [line.split() for line in real[16:]]
    # Give the writer what a Pass does not hold: the centroid columns and the frame names.
    centroids = np.array([row[-12:-8] for row in rows], dtype=float)
    names = [row[-1] for row in rows]
    out = write_ccd_phot(p, tmp_path / "copy.phV", variant, centroids_px=centroids, frame_names=names)
    ours = out.read_text().splitlines()
    # Header: the same lines in the same order, except the first/last frame times (ours are the first
    # and last rows' times; the real file copied them from the FITS headers).
    assert [k for k in range(16) if ours[k] != real[k]] == [4, 5]
    assert re.fullmatch(r"# \d{4}-\d{2}-\d{2} \d{2}:\d{2}:\d{2}\.\d{6}", ours[4])
    # Column line and every data row: byte for byte.
    assert ours[15:] == real[15:]


def test_phc_writer_reproduces_the_real_file(shared_data, tmp_path):
    b, v = ingest.read_file(COSMOS2553_PHC)
    out = write_phc(b, v, tmp_path / "copy.phc")
    real = COSMOS2553_PHC.read_bytes().split(b"\n")
    ours = out.read_bytes().split(b"\n")
    # Byte for byte, except line 2: the real file's end time counts 4 samples dropped after 17:31:20.
    assert ours[:1] == real[:1] and ours[2:] == real[2:]
    assert (real[1], ours[1]) == (b"2025-01-30 17:31:25", b"2025-01-30 17:31:21")


def test_phc_round_trip_with_invalid_samples(shared_data, tmp_path):
    b, v = ingest.read_file(COSMOS2553_PHC)
    valid = np.ones(len(b), dtype=bool)
    valid[[3, 50]] = False
    b = b.replace(valid=valid, mag=np.where(valid, b.mag, np.nan))
    b2, v2 = ingest.read_file(write_phc(b, v, tmp_path / "s.phc"))
    assert np.flatnonzero(~b2.valid).tolist() == [3, 50] and v2.valid.all()
    assert b2.header["n_sentinel"] == 2
    assert np.array_equal(b2.time_utc, b.time_utc)
    np.testing.assert_allclose(b2.flux_err, b.flux_err, rtol=1e-5)  # the sky is printed to 0.001 count


def test_saturation_and_old_stamps_round_trip(shared_data, tmp_path):
    (p,) = ingest.read_file(COSMOS2540_PHV)
    saturated = np.zeros(len(p), dtype=bool)
    saturated[[0, 10, 2000]] = True
    # A 2022 pass: the reader will shift its stamps by +dt/2, so the writer must write mid - dt/2.
    old = p.replace(saturated=saturated, time_utc=p.time_utc - np.timedelta64(3 * 365, "D"))
    out = write_ccd_phot(old, tmp_path / "old.phV")
    assert out.read_text().splitlines()[16].split()[1] == "17:36:50.757"  # 50.807 - 0.05 s
    (back,) = ingest.read_file(out)
    assert_same_pass(old, back, 0)
    assert back.time_shift_s == 0.05 and back.header["n_saturated"] == 3


def test_time_format_line_round_trip(shared_data, tmp_path):
    (p,) = ingest.read_file(TOPEX_PHV)
    out = write_ccd_phot(p, tmp_path / "t.phV", "jd", time_format="JD start")
    assert "# Time_format = JD start" in out.read_text().splitlines()
    (back,) = ingest.read_file(out)
    assert back.time_shift_s == 0.1 and back.header["file_time_stamps"] == "exposure start"
    assert np.abs((back.time_utc - p.time_utc).astype(np.int64)).max() <= JD_STEP_NS


def test_omm_round_trip(shared_data, tmp_path):
    (p,) = ingest.read_file(COSMOS2540_PHV)
    omm = {"OBJECT_NAME": "COSMOS 2540", "OBJECT_ID": "2019-057A", "NORAD_CAT_ID": 44517, "MEAN_MOTION": 13.85936593}
    out = write_ccd_phot(p.replace(tle=None, omm=omm), tmp_path / "o.phV")
    assert out.read_text().startswith('# OMM: {"OBJECT_NAME": "COSMOS 2540"')
    (back,) = ingest.read_file(out)
    assert dict(back.omm) == omm and back.tle is None


def test_writer_argument_errors(shared_data, tmp_path):
    (p,) = ingest.read_file(COSMOS2540_PHV)
    b, v = ingest.read_file(COSMOS2553_PHC)
    with pytest.raises(ValueError, match=r"variant='mjd' is not one of \('ut', 'jd'\); use 'ut' or 'jd'"):
        write_ccd_phot(p, tmp_path / "x.phV", "mjd")
    with pytest.raises(ValueError, match="time_format='JD start' names other time columns than variant='ut'"):
        write_ccd_phot(p, tmp_path / "x.phV", "ut", time_format="JD start")
    with pytest.raises(ValueError, match="ccd_phot files cannot hold missing magnitudes"):
        write_ccd_phot(p.replace(mag=np.where(np.arange(len(p)) == 3, np.nan, p.mag)), tmp_path / "x.phV")
    with pytest.raises(ValueError, match="write_phc needs a B and a V pass, got bands 'V' and 'B'"):
        write_phc(v, b, tmp_path / "x.phc")
    with pytest.raises(ValueError, match="must share one time axis"):
        write_phc(b, v.replace(time_utc=v.time_utc + np.timedelta64(1, "ms")), tmp_path / "x.phc")
    assert not list(tmp_path.iterdir())  # nothing half-written
