"""Bad input at the reader level: a bad file raises FormatError('path:line: reason'); a bad row
in a good file is set aside as a RowProblem (line, reason, the row as written) and the rest is read.

Each case is built from the first rows of a real file (written to tmp_path, never committed)
so that exactly one thing is wrong, and the test checks the full message: the file, the
1-based line and the reason.
"""

from __future__ import annotations

import gzip
import tracemalloc

import numpy as np
import pytest

import ingest
from ingest.errors import FormatError
from ingest.textfile import HEAD_BYTES, MAX_FILE_BYTES, MAX_LINE_BYTES
from tests.conftest import COSMOS2540_PHV, COSMOS2553_JD_PHV, COSMOS2553_PHC

# COSMOS 2540's header is lines 1-16; data rows start on line 17.
FIRST_ROW = 17
# Rows kept in the test files: one bad row is 2.5%, below the 10% a file may lose.
N_ROWS = 40


@pytest.fixture
def lines(shared_data):
    """The COSMOS 2540 header and its first N_ROWS rows, as a list of lines."""
    return COSMOS2540_PHV.read_text().splitlines()[: FIRST_ROW - 1 + N_ROWS]


def write(tmp_path, lines_or_bytes, name="bad.phV"):
    path = tmp_path / name
    if isinstance(lines_or_bytes, bytes):
        path.write_bytes(lines_or_bytes)
    else:
        path.write_text("\n".join(lines_or_bytes) + "\n")
    return path


def message(path) -> str:
    with pytest.raises(FormatError) as info:
        ingest.read_file(path)
    error = info.value
    assert str(error).startswith(f"{path}:" if error.line is None else f"{path}:{error.line}: ")
    return str(error)[len(str(path)) :]


def set_aside(path, n_rows: int = N_ROWS) -> str:
    """``:line: reason`` of the one row the reader set aside; the other rows are read."""
    passes = ingest.read_file(path)
    for pass_ in passes:
        assert len(pass_.row_problems) == 1, pass_.row_problems
        assert len(pass_) == n_rows - 1
    problem = passes[0].row_problems[0]
    assert problem.text == path.read_bytes().decode().splitlines()[problem.line - 1]
    return f":{problem.line}: {problem.reason}"


def set_field(line: str, index: int, value: str) -> str:
    tokens = line.split()
    tokens[index] = value
    return "  ".join(tokens)


# -- whole-file problems -------------------------------------------------------------------
def test_empty_file(tmp_path):
    assert message(write(tmp_path, b"")) == ": the file is empty; an observation file needs a header and data rows"


def test_whitespace_only_file(tmp_path):
    assert message(write(tmp_path, b" \n\n\t\n")) == (
        ": the file is empty (only whitespace); an observation file needs a header and data rows"
    )


def test_header_only(tmp_path, lines):
    assert message(write(tmp_path, lines[: FIRST_ROW - 1])) == ":17: the header is not followed by any data rows"


def test_header_without_column_line(tmp_path, lines):
    assert message(write(tmp_path, lines[: FIRST_ROW - 2])) == (
        ":15: the header ends without the column line ('# Date UT X Y ...' or '# JD X Y ...') and no data rows follow"
    )


def test_truncated_mid_row(tmp_path, lines):
    text = "\n".join(lines) + "\n" + lines[-1][:60]  # one more row, cut after 60 characters, no newline
    assert set_aside(write(tmp_path, text.encode()), N_ROWS + 1) == (
        f":{FIRST_ROW + N_ROWS}: the last row has 5 of 14 columns and no line end: the file looks truncated"
    )


def test_cut_inside_the_last_column(tmp_path, shared_data):
    # A .phc file cut inside its last value: '2827.394' read as '28' would be a range of 28 km.
    phc = COSMOS2553_PHC.read_text().splitlines()
    cut = "\n".join(phc) + "\n"
    cut = cut[: cut.rindex("2827.394") + 2]
    path = write(tmp_path, cut.encode(), "cut.phc")
    assert set_aside(path, 692) == (
        f":{len(phc)}: the last row has no line end and its Rg(Mm) '28' has fewer digits than the rows above "
        "('2823.785'): the file was cut inside this row"
    )
    b, _ = ingest.read_file(path)
    assert b.range_km[-1] == 2823.785  # the row before the cut one; nothing like 28 km was kept


def test_a_whole_last_row_without_a_line_end_is_kept(tmp_path, lines):
    assert len(ingest.read_file(write(tmp_path, "\n".join(lines).encode()))[0].row_problems) == 0


def test_widespread_damage_refuses_the_file(tmp_path, lines):
    # 4 bad rows of 40 (10%) are set aside; a 5th (12.5%) refuses the file.
    for k in range(4):
        lines[FIRST_ROW + 2 * k] = set_field(lines[FIRST_ROW + 2 * k], 6, "x")
    assert len(ingest.read_file(write(tmp_path, lines))[0].row_problems) == 4
    lines[FIRST_ROW + 10] = set_field(lines[FIRST_ROW + 10], 6, "x")
    assert message(write(tmp_path, lines)) == (
        ":18: Flux is 'x', which is not a number (5 of 40 data rows are damaged, more than the 10% a file may "
        "lose; check that this is the file you meant)"
    )


def test_row_with_a_missing_column(tmp_path, lines):
    lines[FIRST_ROW + 1] = " ".join(lines[FIRST_ROW + 1].split()[:-1])  # line 19 loses its file name
    assert set_aside(write(tmp_path, lines)) == (
        ":19: the row has 13 columns, expected 14 (Date UT X Y Xerr Yerr Flux Flux_err magV mag_err Az(deg) "
        "El(deg) Rg(Km) filename)"
    )


def test_row_with_an_extra_column(tmp_path, lines):
    lines[FIRST_ROW + 3] += " extra"
    assert set_aside(write(tmp_path, lines)).startswith(":21: the row has 15 columns, expected 14 (Date UT")


def test_non_numeric_value(tmp_path, lines):
    lines[FIRST_ROW + 2] = set_field(lines[FIRST_ROW + 2], 6, "90a42.3732")
    assert set_aside(write(tmp_path, lines)) == ":20: Flux is '90a42.3732', which is not a number"


def test_decimal_comma_is_not_a_number(tmp_path, lines):
    lines[FIRST_ROW] = set_field(lines[FIRST_ROW], 8, "6,238")
    assert set_aside(write(tmp_path, lines)) == ":18: magV is '6,238', which is not a number"


@pytest.mark.parametrize(
    "index, value, label", [(8, "nan", "magV"), (10, "inf", "Az(deg)"), (12, "-Infinity", "Rg(Km)")]
)
def test_nan_and_inf(tmp_path, lines, index, value, label):
    lines[FIRST_ROW + 4] = set_field(lines[FIRST_ROW + 4], index, value)
    assert set_aside(write(tmp_path, lines)) == f":22: {label} is '{value}'; every value must be a finite number"


def test_times_out_of_order(tmp_path, lines):
    lines[FIRST_ROW + 2], lines[FIRST_ROW + 3] = lines[FIRST_ROW + 3], lines[FIRST_ROW + 2]
    assert set_aside(write(tmp_path, lines)) == (
        ":21: time 2025-01-30 17:36:51.108 is earlier than the previous kept row's 2025-01-30 17:36:51.208 "
        "(line 20): the frame's time stamp is wrong"
    )


def test_duplicate_time(tmp_path, lines):
    lines.insert(FIRST_ROW + 1, lines[FIRST_ROW])
    assert set_aside(write(tmp_path, lines), N_ROWS + 1) == (
        ":19: time 2025-01-30 17:36:50.907 repeats the previous kept row's 2025-01-30 17:36:50.907 (line 18): "
        "the frame's time stamp is wrong"
    )


def test_clock_glitch_costs_only_the_glitched_rows(tmp_path, shared_data):
    # The real case (a ccd_phot file of 1486 rows from the observatory): a frame stamped 0.8 s
    # earlier than the previous row, its Az/El those of the earlier frame with that time; and a block
    # of frames written twice. Only those rows go; every other row is kept with its own values.
    lines = COSMOS2540_PHV.read_text().splitlines()[: FIRST_ROW - 1 + 200]
    rows = lines[FIRST_ROW - 1 :]
    glitched = rows[10].split()
    glitched[1] = rows[1].split()[1]  # 0.8 s earlier than row 9's time (rows are 0.1 s apart)
    glitched[10:13] = rows[1].split()[10:13]  # Az, El, Rg of the frame with that time
    rows[10] = "  ".join(glitched)
    rows = rows[:30] + rows[20:28] + rows[30:]  # rows 20..27 written twice
    (pass_,) = ingest.read_file(write(tmp_path, lines[: FIRST_ROW - 1] + rows))
    assert [p.line for p in pass_.row_problems] == [FIRST_ROW + 10] + list(range(FIRST_ROW + 30, FIRST_ROW + 38))
    (clean,) = ingest.read_file(write(tmp_path, lines, "clean.phV"))
    keep = np.ones(len(clean), bool)
    keep[10] = False
    np.testing.assert_array_equal(pass_.time_utc, clean.time_utc[keep])
    np.testing.assert_array_equal(pass_.mag, clean.mag[keep])
    np.testing.assert_array_equal(pass_.az_deg, clean.az_deg[keep])


@pytest.mark.parametrize("value", ["-9042.3732", "0.0000"])
def test_negative_or_zero_flux_sets_the_row_aside(tmp_path, lines, value):
    # ccd_phot never writes a row with flux <= 0 (its magnitude would be undefined): such a row
    # was altered, so its values are not used; the rest of the file is (docs/formats.md).
    lines[FIRST_ROW + 1] = set_field(lines[FIRST_ROW + 1], 6, value)
    assert set_aside(write(tmp_path, lines)) == (
        f":19: Flux {value} is not positive: ccd_phot never writes such a row because its magnitude would be undefined"
    )


def test_bad_date_and_time_tokens(tmp_path, lines):
    lines[FIRST_ROW] = set_field(lines[FIRST_ROW], 0, "2025-13-30")
    assert set_aside(write(tmp_path, lines)) == ":18: Date '2025-13-30' is not a date (YYYY-MM-DD)"
    lines = [line.replace("17:36:51.208", "17:36:61.208") for line in lines]
    lines[FIRST_ROW] = set_field(lines[FIRST_ROW], 0, "2025-01-30")
    assert set_aside(write(tmp_path, lines)) == ":21: UT '17:36:61.208' is not a time of day (HH:MM:SS.fff)"


@pytest.mark.parametrize("date", ["2999-01-30", "1677-09-21", "1957-10-03"])
def test_dates_outside_the_storable_range(tmp_path, lines, date):
    # datetime64[ns] ends in 2262: 2999-01-30 used to wrap around to 1829-12-22.
    lines[FIRST_ROW + 3] = set_field(lines[FIRST_ROW + 3], 0, date)
    assert set_aside(write(tmp_path, lines)) == (
        f":21: Date {date} is outside the dates an observation can have (1957-10-04 .. 2262-04-10)"
    )
    every = [set_field(line, 0, date) if k >= FIRST_ROW - 1 else line for k, line in enumerate(lines)]
    assert message(write(tmp_path, every)).startswith(f":17: Date {date} is outside the dates")


def test_julian_dates_out_of_order(tmp_path, shared_data):
    lines = COSMOS2553_JD_PHV.read_text().splitlines()[: 16 + N_ROWS]
    lines[19], lines[20] = lines[20], lines[19]
    assert set_aside(write(tmp_path, lines)) == (
        ":21: time 2460746.23009745 is earlier than the previous kept row's 2460746.2300986084 (line 20): "
        "the frame's time stamp is wrong"
    )


def test_bad_julian_date(tmp_path, shared_data):
    lines = COSMOS2553_JD_PHV.read_text().splitlines()[: 16 + N_ROWS]
    lines[18] = set_field(lines[18], 0, "2460746.23O096")  # a letter O for a zero
    assert set_aside(write(tmp_path, lines)) == (
        ":19: JD '2460746.23O096' is not a Julian date of an observation (1957-10-04 .. 2262-04-10)"
    )
    lines[18] = set_field(lines[18], 0, "2816787.5")  # 2999-01-30
    assert set_aside(write(tmp_path, lines)).startswith(":19: JD '2816787.5' is not a Julian date of an observation")


def test_elevation_out_of_range(tmp_path, lines):
    lines[FIRST_ROW + 5] = set_field(lines[FIRST_ROW + 5], 11, "118.566")
    assert set_aside(write(tmp_path, lines)) == ":23: El(deg) 118.566 is not an elevation in degrees (-90..90)"


def test_impossible_magnitude_and_range(tmp_path, lines):
    lines[FIRST_ROW + 5] = set_field(lines[FIRST_ROW + 5], 8, "1e300")
    assert set_aside(write(tmp_path, lines)) == ":23: magV 1e300 is not a magnitude of a satellite"
    lines[FIRST_ROW + 5] = set_field(lines[FIRST_ROW + 5], 8, "6.2")
    lines[FIRST_ROW + 6] = set_field(lines[FIRST_ROW + 6], 12, "9e99")
    assert set_aside(write(tmp_path, lines)) == (
        ":24: Rg(Km) 9e99 is not a range to an Earth satellite (0 < range <= 1e+06 km)"
    )


def test_range_in_megametres_is_refused(tmp_path, lines):
    for k in range(FIRST_ROW - 1, len(lines)):
        tokens = lines[k].split()
        lines[k] = set_field(lines[k], 12, f"{float(tokens[12]) / 1000:.6f}")
    assert message(write(tmp_path, lines)) == (
        ":17: the range column's median is 2.08725, so it is not in km as ccd_phot writes it (even under the "
        "label Rg(Mm)); convert it to km"
    )


# -- encodings and binary data ------------------------------------------------------------
def test_latin1_header_is_wrong_encoding(tmp_path, lines):
    lines[10] = "# NAME   = COSMOS 2540 \u00e9"
    path = tmp_path / "bad.phV"
    path.write_bytes(("\n".join(lines) + "\n").encode("latin-1"))
    assert message(path) == (
        ":11: byte 0xe9 at column 24 is not UTF-8 text; the file is in another encoding: save it as UTF-8 or ASCII"
    )


def test_utf16_file(tmp_path, lines):
    path = tmp_path / "bad.phV"
    path.write_bytes(("\n".join(lines) + "\n").encode("utf-16"))
    assert message(path) == ":1: the file is UTF-16 or UTF-32 encoded; save it as UTF-8 or ASCII"


def test_utf8_bom_is_accepted(tmp_path, lines):
    path = tmp_path / "bom.phV"
    path.write_bytes(b"\xef\xbb\xbf" + ("\n".join(lines) + "\n").encode())
    assert len(ingest.read_file(path)[0]) == N_ROWS


def test_cyrillic_digit_lookalike_in_data(tmp_path, lines):
    lines[FIRST_ROW + 6] = set_field(lines[FIRST_ROW + 6], 9, "0.01\u0417")  # Cyrillic Ze, looks like a 3
    assert set_aside(write(tmp_path, lines)) == ":24: mag_err is '0.01\u0417', which is not a number"


def test_binary_garbage(tmp_path):
    garbage = np.random.default_rng(7).integers(0, 256, 5000, dtype=np.uint8).tobytes()
    text = message(write(tmp_path, garbage, "garbage.phV"))
    assert text.startswith(":1: control byte 0x") and text.endswith(
        ": this is binary data, not a text observation file"
    )


def test_gzipped_file(tmp_path, shared_data):
    path = write(tmp_path, gzip.compress(COSMOS2540_PHV.read_bytes()), "c.phV.gz")
    assert message(path) == ":1: control byte 0x1f at column 1: this is binary data, not a text observation file"


def test_nul_byte_inside_a_row(tmp_path, lines):
    data = ("\n".join(lines) + "\n").encode()
    offset = data.index(b"c2540_V_00004.fits")
    path = write(tmp_path, data[:offset] + b"\x00" + data[offset + 1 :])
    assert message(path) == ":20: control byte 0x00 at column 148: this is binary data, not a text observation file"


def test_ten_megabyte_single_line_fails_after_reading_only_the_head(tmp_path):
    path = tmp_path / "line.phV"
    path.write_bytes(b"# " + b"x" * (10 * 2**20))
    tracemalloc.start()
    try:
        text = message(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert text == f":1: the first line is longer than {MAX_LINE_BYTES} bytes; this is not a text observation file"
    # Only the head (64 kB) was read: the peak is far below the file's 10 MB.
    assert peak < 4 * HEAD_BYTES


def test_long_line_after_the_header(tmp_path, lines):
    lines[FIRST_ROW + 2] += " " + "9" * 20000
    assert message(write(tmp_path, lines)).startswith(":20: the line is 20")


def test_file_larger_than_the_limit(tmp_path):
    path = tmp_path / "huge.phV"
    with open(path, "wb") as stream:  # sparse: no disk space used
        stream.truncate(MAX_FILE_BYTES + 1)
    assert message(path) == (
        f": the file is {(MAX_FILE_BYTES + 1) / 2**20:.1f} MiB, more than the 64 MiB an "
        "observation file can hold; split it or check that it is an observation file"
    )


def test_directory_is_an_os_error(tmp_path):
    with pytest.raises(IsADirectoryError):
        ingest.read_file(tmp_path)


# -- header problems -----------------------------------------------------------------------
def test_missing_dt(tmp_path, lines):
    lines.remove("# dt = 0.1")
    assert message(write(tmp_path, lines)) == ":15: the header has no '# dt = ' line; add the exposure time in seconds"


def test_bad_dt(tmp_path, lines):
    lines[6] = "# dt = -0.1"
    assert message(write(tmp_path, lines)) == ":7: dt = '-0.1' is not an exposure time in seconds (0 < dt <= 3600)"
    lines[6] = "# dt = 1e20"  # used to overflow the half-exposure shift
    assert message(write(tmp_path, lines)) == ":7: dt = '1e20' is not an exposure time in seconds (0 < dt <= 3600)"


@pytest.mark.parametrize("value", ["99999999999999999999", "0", "-5", "4.5e4"])
def test_norad_that_is_not_a_catalogue_number(tmp_path, lines, value):
    # A 20-digit NORAD used to overflow int64 in the archive with a traceback.
    lines = lines[4:]  # no TLE to disagree with
    lines[5] = f"# NORAD  = {value}"
    assert message(write(tmp_path, lines)) == f":6: NORAD = {value!r} is not a catalogue number (1..999999999)"


def test_tle_checksum(tmp_path, lines):
    lines[2] = lines[2][:-1] + "0"  # checksum 8 -> 0
    assert message(write(tmp_path, lines)) == (
        ":2: TLE line 1 checksum is 8 but the line ends in '0': "
        "'1 44517U 19057A   25029.57053304  .00000050  00000-0  81985-4 0  9990'; "
        "check that it was copied without changes; fix the TLE block after '# TLE:'"
    )


def test_norad_disagrees_with_tle(tmp_path, lines):
    lines[9] = "# NORAD  = 44518"
    assert message(write(tmp_path, lines)) == (
        ":2: the TLE is for NORAD 44517 but the header says NORAD 44518; the file mixes two objects"
    )


def test_no_object_named(tmp_path, lines):
    lines = lines[4:]  # no TLE
    lines.remove("# NORAD  = 44517")
    assert message(write(tmp_path, lines)) == (":11: the header names no object: add '# NORAD = <number>' or a TLE/OMM")


def test_bad_omm(tmp_path, lines):
    lines = ['# OMM: {"NORAD_CAT_ID": 44517, "OBJECT_NAME": "COSMOS 2540"'] + lines[4:]
    assert message(write(tmp_path, lines)) == (
        ":1: the OMM record is not valid JSON (Expecting ',' delimiter at character 53); write the record as one "
        "JSON object on this line"
    )


def test_unknown_column_line(tmp_path, lines):
    lines[15] = lines[15].replace("Flux_err", "FluxErr")
    assert message(write(tmp_path, lines)) == (
        ":16: the column line reads 'Date UT X Y Xerr Yerr Flux FluxErr magV mag_err Az(deg) El(deg) Rg(Km) "
        "filename'; expected the 14 ccd_phot columns 'Date UT X Y Xerr Yerr Flux Flux_err mag mag_err Az(deg) "
        "El(deg) Rg filename' (mag and Rg may carry a suffix such as magV, Rg(Km))"
    )


def test_unknown_site_name(tmp_path, lines):
    lines = [line for line in lines if not line.startswith(("# SITE_LAT", "# SITE_LON", "# SITE_ELEV"))]
    lines[11] = "# SITE_NAME   = Kyiv"
    assert message(write(tmp_path, lines)) == (
        ":12: SITE_NAME = 'Kyiv' is not a known site and the header has no SITE_LAT/SITE_LON/SITE_ELEV lines; add them"
    )


def test_incomplete_site(tmp_path, lines):
    lines.remove("# SITE_ELEV  = 231.1325")
    assert message(write(tmp_path, lines)) == ":13: the site has SITE_LAT, SITE_LON but not SITE_ELEV; give all three"


def test_site_out_of_range(tmp_path, lines):
    lines[12] = "# SITE_LAT   = 148.56"
    assert message(write(tmp_path, lines)) == (
        ":13: site 'Derenivka': lat_deg=148.56 is outside [-90.0, 90.0]; give geodetic degrees and metres"
    )


def test_unknown_time_format(tmp_path, lines):
    lines.insert(8, "# Time_format = sometimes")
    assert message(write(tmp_path, lines)) == (
        ":9: Time_format = 'sometimes' is not understood; write UT or JD, optionally followed by start, mid or end "
        "(the stamp's place in the exposure)"
    )


# -- phc ---------------------------------------------------------------------------------------
PHC_ROWS = 30


@pytest.fixture
def phc_lines(shared_data):
    return COSMOS2553_PHC.read_text().splitlines()[: 7 + PHC_ROWS]


def test_phc_bad_first_line(tmp_path, phc_lines):
    phc_lines[0] = "2025-01-30 17:19:41 extra"
    # Line 1 no longer looks like a phc start, so no reader recognises the file.
    assert message(write(tmp_path, phc_lines, "b.phc")).startswith(":1: unknown file format")
    with pytest.raises(FormatError, match=r"b\.phc:1: line 1 should be the start date and time"):
        ingest.read_file(tmp_path / "b.phc", format="phc")


def test_phc_time_going_backwards(tmp_path, phc_lines):
    phc_lines[10] = phc_lines[10].replace("17:19:44", "17:19:42")
    assert set_aside(write(tmp_path, phc_lines, "b.phc"), PHC_ROWS) == (
        ":11: time 17:19:42.000000 is earlier than the previous kept row's 17:19:43.000000 (line 10): "
        "the frame's time stamp is wrong"
    )
    # A step back by more than 12 h but less than 23 h is a glitch, not a midnight rollover that
    # would move every later row to the next day.
    phc_lines[10] = phc_lines[10].replace("17:19:42", "03:19:44")
    assert set_aside(write(tmp_path, phc_lines, "b.phc"), PHC_ROWS).startswith(":11: time 03:19:44.000000 is")


def test_phc_date_outside_the_storable_range(tmp_path, phc_lines):
    phc_lines[0] = "2999-01-30 17:19:41"
    assert message(write(tmp_path, phc_lines, "b.phc")) == (
        ":1: the date 2999-01-30 is outside the dates an observation can have (1957-10-04 .. 2262-04-10); fix line 1"
    )


def test_phc_wrong_column_line(tmp_path, phc_lines):
    phc_lines[6] = "  UT TIME            mB      mV      El(deg) Rg(Mm)"
    assert message(write(tmp_path, phc_lines, "b.phc")) == (
        ":7: the column line reads 'UT TIME            mB      mV      El(deg) Rg(Mm)'; expected 'UT TIME ImpB-fon "
        "ImpV-fon FonB FonV mB mV Az(deg) El(deg) Rg(Mm)'"
    )


def test_phc_negative_sky(tmp_path, phc_lines):
    phc_lines[9] = phc_lines[9].replace("994.736", "-94.736")
    assert set_aside(write(tmp_path, phc_lines, "b.phc"), PHC_ROWS) == (
        ":10: FonB -94.736 is negative; a sky count cannot be"
    )


def test_phc_missing_dt(tmp_path, phc_lines):
    del phc_lines[2]
    assert message(write(tmp_path, phc_lines, "b.phc")) == ": the header has no 'dt=' line; add one like 'dt=1.0'"


def test_phc_truncated(tmp_path, phc_lines):
    data = ("\n".join(phc_lines) + "\n").encode()[:-40]
    assert set_aside(write(tmp_path, data, "b.phc"), PHC_ROWS) == (
        f":{7 + PHC_ROWS}: the last row has 6 of 10 columns and no line end: the file looks truncated"
    )
