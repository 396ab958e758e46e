"""Readers against the real files in ../shared/data/observations and edited copies of them.

Expected numbers were read off the files' text (row counts with grep, first/last rows with
head/tail); Julian dates are converted by astropy as the authority.
"""

from __future__ import annotations

import json
import shutil
import tracemalloc

from astropy.time import Time
import numpy as np
import pytest

import ingest
from ingest.errors import FormatError
from ingest.readers import READERS, detect_format
from ingest.site import DERENIVKA, UZHHOROD, Site
from ingest.textfile import TextFile
from tests.conftest import COSMOS2540_PHV, COSMOS2553_JD_PHV, COSMOS2553_PHC, REAL_FILES, TOPEX_PHV

# Printed time stamps have 1 ms (UT) and 1e-9 day = 86 us (JD) resolution; our parse must be exact
# to the ns for UT and agree with astropy's two-double JD to 1 us.
JD_TOLERANCE = np.timedelta64(1000, "ns")


def t(text: str) -> np.datetime64:
    return np.datetime64(text, "ns")


def jd(day: int, fraction: float) -> np.datetime64:
    return np.datetime64(Time(day, fraction, format="jd", scale="utc").datetime64, "ns")


# file, rows, first, last, norad, name, cospar, band, exposure_s, site
REAL = [
    (
        TOPEX_PHV,
        2320,
        t("2024-07-30T21:22:40.008"),
        t("2024-07-30T21:30:24.170"),
        22076,
        "TOPEX/POSEIDON",
        "92052A",
        "V",
        0.2,
        DERENIVKA,
    ),
    (
        COSMOS2540_PHV,
        2535,
        t("2025-01-30T17:36:50.807"),
        t("2025-01-30T17:41:04.985"),
        44517,
        "COSMOS 2540",
        "19057A",
        "V",
        0.1,
        DERENIVKA,
    ),
    (
        COSMOS2553_JD_PHV,
        1797,
        jd(2460746, 0.230093974),
        jd(2460746, 0.23222001),
        51511,
        "COSMOS 2553",
        "22011A",
        "V",
        0.1,
        DERENIVKA,
    ),
]


@pytest.mark.parametrize(
    "path, rows, first, last, norad, name, cospar, band, exposure_s, site", REAL, ids=lambda v: getattr(v, "name", None)
)
def test_real_ccd_phot_files(shared_data, path, rows, first, last, norad, name, cospar, band, exposure_s, site):
    (p,) = ingest.read_file(path)
    assert len(p) == rows
    assert abs(p.start_utc - first) <= JD_TOLERANCE
    assert abs(p.end_utc - last) <= JD_TOLERANCE
    assert (p.norad, p.name, p.cospar, p.band, p.exposure_s, p.site) == (norad, name, cospar, band, exposure_s, site)
    # Files after 2023-02 stamp mid-exposure: no shift.
    assert p.time_shift_s == 0.0 and p.header["file_time_stamps"] == "mid-exposure"
    assert p.time_convention == "UTC, mid-exposure"
    assert p.source_format == "ccd_phot" and p.source_name == path.name
    assert len(p.tle) == 3 and p.tle[1].startswith(f"1 {norad}")
    assert not p.saturated.any() and p.valid.all()


def test_topex_columns_match_the_file_text(shared_data):
    (p,) = ingest.read_file(TOPEX_PHV)
    # First data row, as printed: Flux 30806.8538, Flux_err 180.7078, magV 4.467, mag_err 0.006,
    # Az 299.277, El 16.839, Rg(Mm) 2896.651 (km despite the label).
    row0 = [p.flux[0], p.flux_err[0], p.mag[0], p.mag_err[0], p.az_deg[0], p.el_deg[0], p.range_km[0]]
    assert row0 == [30806.8538, 180.7078, 4.467, 0.006, 299.277, 16.839, 2896.651]
    assert p.header["range_label"] == "Rg(Mm)" and p.header["band_source"] == "file extension"
    assert p.source_sha256 == TextFile.from_path(TOPEX_PHV).sha256


def test_ut_times_parse_exactly(shared_data):
    (p,) = ingest.read_file(COSMOS2540_PHV)
    # Rows 2 and 3 read 17:36:50.907 and 17:36:51.008: exact to the nanosecond.
    assert p.time_utc[1] == t("2025-01-30T17:36:50.907") and p.time_utc[2] == t("2025-01-30T17:36:51.008")


def test_jd_times_agree_with_astropy_for_every_row(shared_data):
    (p,) = ingest.read_file(COSMOS2553_JD_PHV)
    lines = COSMOS2553_JD_PHV.read_text().splitlines()[16:]
    tokens = [line.split()[0] for line in lines]
    days = np.array([int(tok.split(".")[0]) for tok in tokens])
    fractions = np.array([float("0." + tok.split(".")[1]) for tok in tokens])
    expected = Time(days, fractions, format="jd", scale="utc").datetime64.astype("datetime64[ns]")
    assert np.abs((p.time_utc - expected).astype(np.int64)).max() <= 1000


def test_phc_gives_two_passes_on_one_time_axis(shared_data):
    b, v = ingest.read_file(COSMOS2553_PHC)
    assert (b.band, v.band) == ("B", "V")
    assert len(b) == len(v) == 692
    assert np.array_equal(b.time_utc, v.time_utc)
    # Stamps are integration starts: 17:19:41 and 17:31:20 become mid-exposure + 0.5 s (dt = 1 s).
    assert b.start_utc == t("2025-01-30T17:19:41.5") and b.end_utc == t("2025-01-30T17:31:20.5")
    assert b.time_shift_s == 0.5 and b.header["file_time_stamps"] == "integration start"
    assert (b.norad, b.name, b.cospar, b.exposure_s, b.site) == (
        51511,
        "COSMOS2553 (Neitron 1)",
        "22011A",
        1.0,
        UZHHOROD,
    )
    assert "Derenivka" in b.header["az_el_range_site"]
    assert b.tle is None
    # Row 1: ImpB-fon 386.249, FonB 998.751, mB 4.057; flux error sqrt(Imp + 2 Fon).
    assert b.flux[0] == 386.249 and b.mag[0] == 4.057 and v.mag[0] == 3.678
    assert b.flux_err[0] == pytest.approx(np.sqrt(386.249 + 2 * 998.751), rel=1e-12)
    assert b.mag_err[0] == pytest.approx(2.5 / np.log(10) * np.sqrt(386.249 + 2 * 998.751) / 386.249, rel=1e-12)
    assert b.valid.all() and v.valid.all()


def test_phc_missing_rows_leave_gaps(shared_data):
    (b, _) = ingest.read_file(COSMOS2553_PHC)
    steps_s = np.diff(b.t_s)
    # 692 rows over 17:19:41..17:31:20 = 700 one-second stamps: 8 missing, so the gaps add up to 8 s.
    assert set(np.round(steps_s).astype(int)) <= {1, 2, 3, 4, 5}
    assert np.round(steps_s).sum() == 699 and (np.round(steps_s) > 1).sum() >= 1


@pytest.mark.parametrize("path", REAL_FILES, ids=lambda p: p.name)
def test_detection_uses_content_not_extension(shared_data, tmp_path, path):
    copy = tmp_path / "renamed.txt"
    shutil.copy(path, copy)
    expected = "phc" if path.suffix == ".phc" else "ccd_phot"
    assert detect_format(TextFile.from_path(copy)) == expected
    passes = ingest.read_file(copy)
    assert len(passes) == (2 if expected == "phc" else 1)


def test_reading_needs_memory_proportional_to_the_file(shared_data):
    ingest.read_file(COSMOS2540_PHV)  # imports and caches outside the measurement
    tracemalloc.start()
    try:
        ingest.read_file(COSMOS2540_PHV)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # The bytes, the parsed columns and the Pass are each about the file's size (0.42 MB): ~4x
    # measured; 10x would mean a buffer that does not scale with the file.
    assert peak < 10 * COSMOS2540_PHV.stat().st_size


def test_unknown_content_with_a_known_extension_is_refused(tmp_path):
    path = tmp_path / "table.phV"
    path.write_text("a,b,c\n1,2,3\n")
    with pytest.raises(FormatError, match=r"table\.phV:1: unknown file format \(line 1 reads 'a,b,c'\)"):
        ingest.read_file(path)


def test_read_pass(shared_data):
    assert len(ingest.read_pass(TOPEX_PHV)) == 2320
    with pytest.raises(
        ValueError,
        match=r"51511_250130_1719\.phc holds 2 passes \(bands B, V\); use "
        r"ingest\.read_file\(path\) to get all of them",
    ):
        ingest.read_pass(COSMOS2553_PHC)


def test_reader_table_and_format_argument(shared_data):
    assert set(READERS) == {"ccd_phot", "phc", "csv"}
    (p,) = READERS["ccd_phot"].read(TOPEX_PHV)
    assert len(p) == 2320
    with pytest.raises(ValueError, match="format='fits' is not one of 'auto', 'ccd_phot', 'phc', 'csv'"):
        ingest.read_file(TOPEX_PHV, format="fits")
    with pytest.raises(FormatError, match="column line"):
        ingest.read_file(COSMOS2553_PHC, format="ccd_phot")


# -- edited copies of real files: header variants ---------------------------------------------
def edited(tmp_path, source, name, edit):
    text = source.read_text()
    path = tmp_path / name
    path.write_text(edit(text))
    return path


def test_saturated_frames_are_kept_and_flagged(shared_data, tmp_path):
    lines = COSMOS2540_PHV.read_text().splitlines()
    # Data starts on line 17 (index 16); mark rows 1, 5 and the last one.
    for index in (16, 20, len(lines) - 1):
        lines[index] += "*"
    path = tmp_path / "sat.phV"
    path.write_text("\n".join(lines) + "\n")
    (p,) = ingest.read_file(path)
    assert len(p) == 2535
    assert np.flatnonzero(p.saturated).tolist() == [0, 4, 2534]
    assert p.header["n_saturated"] == 3 and p.valid.all()


def test_band_from_filter_line_wins_over_extension(shared_data, tmp_path):
    path = edited(tmp_path, COSMOS2540_PHV, "x.phR", lambda s: s)
    assert ingest.read_file(path)[0].band == "V"  # '# Filter = V' beats '.phR'


def test_band_from_magnitude_column_name(shared_data, tmp_path):
    path = edited(tmp_path, TOPEX_PHV, "topex.txt", lambda s: s.replace("magV", "magB"))
    (p,) = ingest.read_file(path)
    assert (p.band, p.header["band_source"]) == ("B", "magnitude column name")


def test_no_band_anywhere_is_an_error(shared_data, tmp_path):
    path = edited(tmp_path, TOPEX_PHV, "topex.txt", lambda s: s.replace("magV", "mag "))
    with pytest.raises(FormatError, match=r"topex\.txt:15: cannot tell the band: there is no '# Filter = ' line"):
        ingest.read_file(path)


def test_site_from_preset_when_only_the_name_is_given(shared_data, tmp_path):
    def keep_name_only(text):
        return (
            "\n".join(
                line for line in text.splitlines() if not line.startswith(("# SITE_LAT", "# SITE_LON", "# SITE_ELEV"))
            )
            + "\n"
        )

    path = edited(tmp_path, COSMOS2540_PHV, "c.phV", lambda s: keep_name_only(s).replace("Derenivka", "Uzhhorod"))
    (p,) = ingest.read_file(path)
    assert p.site == UZHHOROD and p.header["site_source"] == "preset named by SITE_NAME"


def test_site_defaults_to_derenivka_with_a_note(shared_data, tmp_path):
    def no_site(text):
        return "\n".join(line for line in text.splitlines() if not line.startswith("# SITE_")) + "\n"

    (p,) = ingest.read_file(edited(tmp_path, COSMOS2540_PHV, "c.phV", no_site))
    assert p.site == DERENIVKA and p.header["site_source"].startswith("assumed Derenivka")


def test_site_coordinates_are_read(shared_data, tmp_path):
    path = edited(
        tmp_path,
        COSMOS2540_PHV,
        "c.phV",
        lambda s: s.replace("SITE_NAME   = Derenivka", "SITE_NAME   = Elsewhere").replace(
            "SITE_LAT   = 48.5635505", "SITE_LAT   = 50.25"
        ),
    )
    (p,) = ingest.read_file(path)
    assert p.site == Site("Elsewhere", 50.25, 22.453751, 231.1325)


def test_omm_line_replaces_the_tle(shared_data, tmp_path):
    omm = {
        "OBJECT_NAME": "COSMOS 2540",
        "OBJECT_ID": "2019-057A",
        "NORAD_CAT_ID": 44517,
        "EPOCH": "2025-01-29T13:41:33.095",
        "MEAN_MOTION": 13.85936593,
        "ECCENTRICITY": 0.0016558,
        "INCLINATION": 99.2328,
        "RA_OF_ASC_NODE": 44.2251,
        "ARG_OF_PERICENTER": 67.2163,
        "MEAN_ANOMALY": 293.074,
        "BSTAR": 8.1985e-05,
    }

    def to_omm(text):
        lines = text.splitlines()
        return "\n".join([f"# OMM: {json.dumps(omm)}"] + lines[4:]) + "\n"

    (p,) = ingest.read_file(edited(tmp_path, COSMOS2540_PHV, "omm.phV", to_omm))
    assert p.tle is None and dict(p.omm) == omm and p.norad == 44517 and len(p) == 2535


def test_norad_from_the_tle_when_the_header_has_none(shared_data, tmp_path):
    path = edited(tmp_path, COSMOS2540_PHV, "c.phV", lambda s: s.replace("# NORAD  = 44517\n", ""))
    assert ingest.read_file(path)[0].norad == 44517


def test_time_format_start_shifts_to_mid_exposure(shared_data, tmp_path):
    path = edited(
        tmp_path,
        COSMOS2540_PHV,
        "c.phV",
        lambda s: s.replace("# Filter = V\n", "# Filter = V\n# Time_format = UT start\n"),
    )
    (p,) = ingest.read_file(path)
    assert p.time_shift_s == 0.05 and p.header["file_time_stamps"] == "exposure start"
    assert p.start_utc == t("2025-01-30T17:36:50.857")  # 50.807 + dt/2 (dt = 0.1 s)


def test_time_format_that_contradicts_the_columns_is_refused(shared_data, tmp_path):
    path = edited(
        tmp_path, COSMOS2540_PHV, "c.phV", lambda s: s.replace("# Filter = V\n", "# Filter = V\n# Time_format = JD\n")
    )
    with pytest.raises(FormatError, match=r"c\.phV:9: Time_format = 'JD' contradicts the column line"):
        ingest.read_file(path)


def test_files_before_2023_02_stamp_exposure_start(shared_data, tmp_path):
    path = edited(tmp_path, COSMOS2540_PHV, "old.phV", lambda s: s.replace("2025-01-30", "2022-01-30"))
    (p,) = ingest.read_file(path)
    assert p.time_shift_s == 0.05 and p.header["file_time_stamps"] == "exposure start"
    assert p.start_utc == t("2022-01-30T17:36:50.857")


def test_rg_labelled_km_or_mm_is_km(shared_data, tmp_path):
    (mm,) = ingest.read_file(TOPEX_PHV)
    km = ingest.read_file(edited(tmp_path, TOPEX_PHV, "t.phV", lambda s: s.replace("Rg(Mm)", "Rg(Km)")))[0]
    assert np.array_equal(mm.range_km, km.range_km) and mm.range_km[0] == 2896.651


def test_old_style_column_line_without_hash(shared_data, tmp_path):
    path = edited(tmp_path, TOPEX_PHV, "t.phV", lambda s: s.replace("#  Date       UT", "   Date       UT"))
    assert len(ingest.read_file(path)[0]) == 2320


def test_crlf_line_ends(shared_data, tmp_path):
    path = tmp_path / "crlf.phV"
    path.write_bytes(COSMOS2540_PHV.read_bytes().replace(b"\n", b"\r\n"))
    (p,) = ingest.read_file(path)
    (q,) = ingest.read_file(COSMOS2540_PHV)
    assert np.array_equal(p.time_utc, q.time_utc) and np.array_equal(p.mag, q.mag) and p.name == "COSMOS 2540"


def test_phc_sentinels_are_masked(shared_data, tmp_path):
    lines = COSMOS2553_PHC.read_text().splitlines()
    # Row 1 (line 8): mB -> 10.000; row 3 (line 10): mV -> 12.000; row 5 (line 12): ImpB-fon -> -5.0.
    lines[7] = lines[7].replace("  4.057", " 10.000")
    lines[9] = lines[9].replace("3.697", "12.000")
    lines[11] = lines[11].replace("451.264", " -5.000")
    path = tmp_path / "s.phc"
    path.write_text("\n".join(lines) + "\n")
    b, v = ingest.read_file(path)
    assert np.flatnonzero(~b.valid).tolist() == [0, 4] and np.flatnonzero(~v.valid).tolist() == [2]
    assert np.isnan(b.mag[[0, 4]]).all() and np.isnan(v.mag[2]) and b.mag[1] == 4.017
    assert b.header["n_sentinel"] == 1 and b.header["n_nonpositive_flux"] == 1
    assert len(b) == 692 and b.reduction.n_points == 690


def test_phc_times_roll_over_midnight(tmp_path):
    path = tmp_path / "night.phc"
    path.write_text(
        "2025-01-30 23:59:58\n2025-01-31 00:00:02\ndt=1.0\nCOSPAR ID=22011A\nNORAD ID=51511\nNAME=X\n"
        "  UT TIME           ImpB-fon     ImpV-fon         FonB       FonV         mB      mV     Az(deg)  El(deg)  Rg(Mm)\n"
        "23:59:58.000000       386.249     567.548       998.751    1224.452     4.057   3.678    181.151  28.220  3198.390\n"
        "23:59:59.000000       403.258     742.768       996.742    1221.232     4.017   3.391    181.102  28.303  3194.228\n"
        "00:00:00.000000       315.264     562.981       994.736    1218.019     4.290   3.697    181.052  28.386  3190.071\n"
        "00:00:01.000000       392.266     780.187       992.734    1214.813     4.060   3.348    181.002  28.469  3185.918\n"
    )
    b, _ = ingest.read_file(path)
    assert list(b.time_utc) == [
        t("2025-01-30T23:59:58.5"),
        t("2025-01-30T23:59:59.5"),
        t("2025-01-31T00:00:00.5"),
        t("2025-01-31T00:00:01.5"),
    ]
    assert b.duration_s == 3.0


def test_phc_first_rows_after_midnight_belong_to_the_next_day(tmp_path):
    path = tmp_path / "late.phc"
    # Line 1 says 23:59:58 on the 30th, but the rows before midnight were removed.
    path.write_text(
        "2025-01-30 23:59:58\n2025-01-31 00:00:02\ndt=1.0\nCOSPAR ID=22011A\nNORAD ID=51511\nNAME=X\n"
        "  UT TIME           ImpB-fon     ImpV-fon         FonB       FonV         mB      mV     Az(deg)  El(deg)  Rg(Mm)\n"
        "00:00:00.000000       315.264     562.981       994.736    1218.019     4.290   3.697    181.052  28.386  3190.071\n"
        "00:00:01.000000       392.266     780.187       992.734    1214.813     4.060   3.348    181.002  28.469  3185.918\n"
    )
    b, _ = ingest.read_file(path)
    assert list(b.time_utc) == [t("2025-01-31T00:00:00.5"), t("2025-01-31T00:00:01.5")]


def test_phc_tle_block(shared_data, tmp_path):
    tle = [
        "0 COSMOS 2553",
        "1 51511U 22011A   25069.91220256 -.00000035  00000-0  38084-5 0  9995",
        "2 51511  67.0971 340.1435 0004285 269.8613  90.1839 11.32843242127964",
    ]
    lines = COSMOS2553_PHC.read_text().splitlines()
    lines[6:6] = ["% TLE:"] + [f"% {line}" for line in tle]
    path = tmp_path / "tle.phc"
    path.write_text("\n".join(lines) + "\n")
    b, v = ingest.read_file(path)
    assert b.tle == tuple(tle) == v.tle and len(b) == 692
