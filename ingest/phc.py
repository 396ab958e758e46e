"""Reader for the Uzhhorod photomultiplier files (``.phc``): B and V at once.

Layout (see docs/formats.md)::

    2025-01-30 17:19:41                  line 1: date and time of the first sample
    2025-01-30 17:31:25                  line 2: end of the last sample
    dt=1.0                               sample (integration) time, s
    COSPAR ID=22011A
    NORAD ID=51511
    NAME=COSMOS2553 (Neitron 1)
    % TLE:                               optional block of '%' lines
    % 0 COSMOS 2553
    % 1 51511U ...
    % 2 51511 ...
      UT TIME           ImpB-fon     ImpV-fon         FonB       FonV         mB      mV     Az(deg)  El(deg)  Rg(Mm)
    17:19:41.000000       386.249     567.548  ...

Decisions, with the evidence for each (docs/formats.md has the long form):

* Time stamps are the START of each integration: the writer (phc.pyw) stamps sample ``i`` at
  ``T0 + i dt`` from the group's start and writes line 2 as ``T0 + n dt``, the end of the last
  sample; the real file agrees (line 2 is one dt after the last possible stamp). The reader
  adds ``dt/2`` to reach mid-exposure and records ``time_shift_s``.
* Only the time of day is written: the date comes from line 1 and a backward step of more
  than 23 h (the next row less than an hour later once a day is added) is a midnight rollover;
  any other backward step is a clock glitch and its row is set aside.
* ``Imp-fon`` is the background-subtracted count per sample (the flux); ``Fon`` the sky
  count subtracted from it. With Poisson statistics for the raw count ``Imp + Fon`` and for a
  sky measured over one sample, ``flux_err = sqrt(Imp + 2 Fon)`` and
  ``mag_err = 2.5 / ln 10 * flux_err / Imp``.
* mB/mV equal to 10 or 12 (13 in one version of the writer) are sentinels for "no
  measurement"; such rows, and rows whose count is not positive, get ``valid=False`` and NaN
  magnitudes. They are kept, not rejected: the photometer legitimately records samples with
  no signal above the sky, and dropping them would hide the gaps.
* The site is Uzhhorod, but the writer computed Az/El/Rg for the Derenivka coordinates; the
  columns are kept as written (the file's own magnitudes were reduced with them) and the header
  says so.
"""

from __future__ import annotations

import re
from types import MappingProxyType

import numpy as np

from ingest import elements
from ingest.observation import MAX_EXPOSURE_S, Pass
from ingest.problems import missing_data_warnings
from ingest.reduction import fit_note, fit_reduction, sign_corrected_mag
from ingest.site import UZHHOROD
from ingest.table import ELEVATION, POSITIVE_RANGE, Column, RowFlags, Rows, read_rows
from ingest.textfile import TextFile
from ingest.times import (
    FIRST_OBSERVATION_DATE,
    LAST_STORABLE_DATE,
    NS_PER_DAY,
    NS_PER_S,
    observable_days,
    parse_datetime,
    time_of_day_ns,
    to_datetime64,
)

__all__ = ["PhcReader", "PHC_COLUMNS", "SENTINEL_MAGS", "poisson_flux_err"]

PHC_COLUMNS = (
    Column("ut", "UT TIME", "text", 32),
    Column("flux_b", "ImpB-fon"),
    Column("flux_v", "ImpV-fon"),
    Column("sky_b", "FonB"),
    Column("sky_v", "FonV"),
    Column("mag_b", "mB"),
    Column("mag_v", "mV"),
    Column("az_deg", "Az(deg)"),
    Column("el_deg", "El(deg)"),
    Column("range_km", "Rg(Mm)"),
)
SENTINEL_MAGS = (10.0, 12.0, 13.0)
_COLUMN_LINE = re.compile(
    r"^UT\s+TIME\s+ImpB-fon\s+ImpV-fon\s+FonB\s+FonV\s+mB\s+mV\s+Az\(deg\)\s+El\(deg\)\s+Rg\((Mm|Km|km)\)$"
)
_FIRST_LINE = re.compile(r"^(\d{4}-\d{2}-\d{2}) (\d{2}:\d{2}:\d{2}(\.\d+)?)$")
_KEYS = {"dt": "dt", "COSPAR ID": "cospar", "NORAD ID": "norad", "NAME": "name"}
_HALF_DAY_NS = NS_PER_DAY // 2
# A pass lasts minutes: a backward step is a midnight rollover only when the next row comes less
# than this long after the previous one once a day is added.
_ROLLOVER_NS = NS_PER_DAY - 3600 * NS_PER_S
_MAX_HEADER_LINES = 40


def poisson_flux_err(flux: np.ndarray, sky: np.ndarray) -> np.ndarray:
    """1-sigma error of a background-subtracted photon count: sqrt(signal + 2 * sky).

    The raw count of a sample is ``signal + sky`` (Poisson variance equal to itself); the sky
    subtracted was measured over one sample as well (variance ``sky``).

    Parameters
    ----------
    flux, sky : (n,) float
        Background-subtracted counts and the subtracted sky counts per sample.

    Returns
    -------
    (n,) float
        NaN where the variance would be negative.

    >>> float(poisson_flux_err(np.array([100.0]), np.array([50.0]))[0])
    14.142135623730951
    """
    variance = np.asarray(flux, dtype=float) + 2.0 * np.asarray(sky, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.where(variance >= 0, np.sqrt(np.maximum(variance, 0.0)), np.nan)


class PhcReader:
    """Reads a ``.phc`` file into two passes (B, V) sharing one time axis."""

    name = "phc"

    def sniff(self, text: TextFile) -> bool:
        """True when line 1 is a date and time and a phc column line follows within the header."""
        if not _FIRST_LINE.match(text.line(1).lstrip("\ufeff").strip()):
            return False
        return any(
            text.line(k).strip().startswith("UT TIME") for k in range(2, min(text.n_lines, _MAX_HEADER_LINES) + 1)
        )

    def read(self, path) -> tuple[Pass, ...]:
        """Read `path`; raise `FormatError` with the line and reason when it is not a valid phc file."""
        return self.parse(TextFile.from_path(path))

    def parse(self, text: TextFile) -> tuple[Pass, ...]:
        """Build the B and V passes from an already loaded file."""
        midnight_ns, start_tod_ns, first_time = _first_line(text)
        keys, tle, column_line, notes = _header(text)
        exposure_s = _positive_float(text, keys, "dt", "dt=1.0")
        norad = _norad(text, keys, tle)
        rows, problems = read_rows(text, column_line + 1, PHC_COLUMNS)
        flags = RowFlags(text, rows, n_rows=len(rows) + len(problems), problems=problems)
        stamps_ns = _stamps(rows, midnight_ns, start_tod_ns, flags)
        _check_geometry(rows, flags)
        flags.time_order(stamps_ns, lambda i: rows["ut"][i].decode("utf-8", "replace"))
        keep, row_problems = flags.finish()
        rows, stamps_ns = rows.select(keep), stamps_ns[keep]
        shift_s = exposure_s / 2.0
        time_utc = to_datetime64(stamps_ns + int(round(shift_s * NS_PER_S)))
        # Line 2 is the end of the last sample: the last stamp the group could hold is one dt earlier.
        end_time = parse_datetime(text.line(2))
        warnings = tuple(
            missing_data_warnings(
                (np.datetime64(midnight_ns + start_tod_ns, "ns"), 1, "first sample time"),
                (
                    None if end_time is None else end_time - np.timedelta64(int(round(exposure_s * NS_PER_S)), "ns"),
                    2,
                    "last sample time (line 2 less dt)",
                ),
                stamps_ns,
                exposure_s,
            )
        )

        info = {key: value for key, (value, _) in keys.items()}
        info.update(
            format="phc",
            first_sample_utc=first_time,
            file_time_stamps="integration start",
            az_el_range_site=(
                "Derenivka: the phc writer computed Az(deg), El(deg) and Rg for the Derenivka "
                "coordinates (48.5635505 N, 22.453751 E, 231 m) although the photometer is at Uzhhorod"
            ),
            range_label=text.line(column_line).split()[-1],
            flux_err_model="sqrt(Imp-fon + 2 Fon): Poisson noise of the raw count and of a one-sample sky",
        )
        if text.line(2).strip():
            info["end_utc"] = text.line(2).strip()
        for k, note in enumerate(notes):
            info[f"note_{k + 1}"] = note
        cospar = keys.get("COSPAR ID", ("", 0))[0] or (elements.tle_cospar(tle) if tle else "")
        name = keys.get("NAME", ("", 0))[0]

        passes = []
        for band in ("B", "V"):
            suffix = band.lower()
            flux = rows[f"flux_{suffix}"]
            sky = rows[f"sky_{suffix}"]
            written = rows[f"mag_{suffix}"]
            sentinel = np.isin(written, SENTINEL_MAGS)
            valid = ~sentinel & (flux > 0)
            flux_err = poisson_flux_err(flux, sky)
            with np.errstate(divide="ignore", invalid="ignore"):
                mag_err = np.where(valid, 2.5 / np.log(10.0) * flux_err / flux, np.nan)
            mag = np.where(valid, written, np.nan)
            reduction = fit_reduction(mag, flux, exposure_s, rows["el_deg"], rows["range_km"], valid=valid)
            mag_corrected = (
                sign_corrected_mag(mag, rows["el_deg"], reduction)
                if reduction is not None and reduction.sign_error
                else None
            )
            band_info = dict(info, n_sentinel=int(sentinel.sum()), n_nonpositive_flux=int((flux <= 0).sum()))
            if fit_note(reduction):
                band_info["reduction"] = fit_note(reduction)
            passes.append(
                Pass(
                    norad=norad,
                    name=name,
                    band=band,
                    site=UZHHOROD,
                    exposure_s=exposure_s,
                    time_utc=time_utc,
                    mag=mag,
                    mag_err=mag_err,
                    flux=flux,
                    flux_err=flux_err,
                    az_deg=rows["az_deg"],
                    el_deg=rows["el_deg"],
                    range_km=rows["range_km"],
                    saturated=np.zeros(len(rows), dtype=bool),
                    valid=valid,
                    cospar=cospar,
                    tle=tle,
                    time_convention="UTC, mid-exposure",
                    time_shift_s=shift_s,
                    mag_convention=(
                        "standard magnitude reduced to 1000 km range: A - 2.5 log10(Imp/dt) - k X "
                        "- 5 log10(Rg/1000 km) with X and Rg for Derenivka (see header)"
                    ),
                    source_name=text.name,
                    source_sha256=text.sha256,
                    source_format=self.name,
                    reduction=reduction,
                    mag_corrected=mag_corrected,
                    header=MappingProxyType(band_info),
                    row_problems=row_problems,
                    warnings=warnings,
                )
            )
        return tuple(passes)


def _first_line(text: TextFile) -> tuple[int, int, str]:
    """Line 1: the first sample's date and time -> (ns of that date's midnight, ns of that time of day, the text)."""
    line = text.line(1).lstrip("\ufeff").strip()
    match = _FIRST_LINE.match(line)
    if match is None:
        raise text.error(1, f"line 1 should be the start date and time (YYYY-MM-DD HH:MM:SS), found {line[:40]!r}")
    try:
        day = np.datetime64(match.group(1), "D").astype(np.int64)
    except ValueError:
        raise text.error(1, f"{match.group(1)!r} is not a calendar date") from None
    if not observable_days(day):
        raise text.error(
            1,
            f"the date {match.group(1)} is outside the dates an observation can have "
            f"({FIRST_OBSERVATION_DATE} .. {LAST_STORABLE_DATE}); fix line 1",
        )
    midnight = day * NS_PER_DAY
    clock_ns, _ = time_of_day_ns(np.array([match.group(2).encode()]))
    return int(midnight), int(clock_ns[0]), line


def _header(text: TextFile):
    """Lines 2.. up to the column line: keys, optional TLE block, column line number, other notes."""
    keys, tle_lines, tle_first, notes = {}, [], None, []
    for number in range(2, min(text.n_lines, _MAX_HEADER_LINES) + 1):
        line = text.line(number).strip()
        if _COLUMN_LINE.match(line):
            tle = None
            if tle_lines:
                try:
                    tle = elements.parse_tle(tle_lines)
                except ValueError as exc:
                    raise text.error(tle_first, f"{exc}; fix the '% TLE:' block") from None
            return keys, tle, number, notes
        if line.startswith("UT TIME"):
            raise text.error(
                number,
                f"the column line reads {line!r}; expected 'UT TIME ImpB-fon ImpV-fon FonB "
                "FonV mB mV Az(deg) El(deg) Rg(Mm)'",
            )
        if line.startswith("%"):
            body = line.lstrip("%").strip()
            if body and body != "TLE:":
                tle_first = tle_first or number
                tle_lines.append(body)
            continue
        key, sep, value = line.partition("=")
        if sep and key.strip() in _KEYS:
            keys[key.strip()] = (value.strip(), number)
        elif line and number > 2:
            notes.append(line)
    raise text.error(
        min(text.n_lines, _MAX_HEADER_LINES),
        "no 'UT TIME ImpB-fon ...' column line in the header and no data rows follow",
    )


def _positive_float(text: TextFile, keys: dict, key: str, example: str) -> float:
    if key not in keys:
        raise text.error(None, f"the header has no '{key}=' line; add one like '{example}'")
    value, line = keys[key]
    try:
        number = float(value)
    except ValueError:
        number = float("nan")
    if not (np.isfinite(number) and 0 < number <= MAX_EXPOSURE_S):
        raise text.error(line, f"{key}={value!r} is not a number of seconds (0 < {key} <= {MAX_EXPOSURE_S:g})")
    return number


def _norad(text: TextFile, keys: dict, tle) -> int:
    norad = None
    if "NORAD ID" in keys:
        value, line = keys["NORAD ID"]
        try:
            norad = elements.check_norad(value)
        except ValueError as exc:
            raise text.error(line, f"NORAD ID={exc}") from None
    if tle is not None:
        from_tle = elements.tle_norad(tle)
        if norad is None:
            norad = from_tle
        elif from_tle != norad:
            raise text.error(
                keys["NORAD ID"][1], f"NORAD ID={norad} but the TLE is for {from_tle}; the file mixes two objects"
            )
    if norad is None or norad <= 0:
        raise text.error(None, "the header names no object: add 'NORAD ID=<number>' or a '% TLE:' block")
    return norad


def _stamps(rows: Rows, midnight_ns: int, start_tod_ns: int, flags: RowFlags) -> np.ndarray:
    """Times of day + the date of line 1, rolling over midnight; ns since 1970 UTC (0 for rows set aside).

    The first row is on line 1's date unless it is more than 12 h earlier in the day than line 1's
    time (the rows before midnight were removed): then it is on the next day.
    """
    tod, ok = time_of_day_ns(rows["ut"])
    flags.flag(
        ~ok, lambda i: f"UT TIME {rows['ut'][i].decode('utf-8', 'replace')!r} is not a time of day (HH:MM:SS.ffffff)"
    )
    good = np.flatnonzero(ok)
    day = np.zeros(len(tod), dtype=np.int64)
    if len(good):
        parsed = tod[good]
        rollover = np.diff(parsed) < -_ROLLOVER_NS
        first_day = 1 if parsed[0] - start_tod_ns < -_HALF_DAY_NS else 0
        day[good] = first_day + np.concatenate([[0], np.cumsum(rollover)])
    return np.where(ok, midnight_ns + day * NS_PER_DAY + tod, 0)


def _check_geometry(rows: Rows, flags: RowFlags) -> None:
    negative_sky = "is negative; a sky count cannot be"
    flags.values(
        PHC_COLUMNS,
        (
            ELEVATION,
            POSITIVE_RANGE,
            ("sky_b", lambda v: v >= 0, negative_sky),
            ("sky_v", lambda v: v >= 0, negative_sky),
        ),
    )
