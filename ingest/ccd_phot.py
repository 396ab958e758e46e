"""Reader for ccd_phot light-curve files (``.phX``, X the filter letter).

Layout (see docs/formats.md for the full description and quirks)::

    # TLE:                                   or   # OMM: {"NORAD_CAT_ID": 22076, ...}
    # 0 TOPEX/POSEIDON
    # 1 22076U 92052A   24212.51246405 ...
    # 2 22076  66.0414 118.8147 ...
    # 2024-07-30 21:22:40.008849             first frame time
    # 2024-07-30 21:30:24.170780             last frame time
    # dt = 0.2                               exposure, s
    # Filter = V                             optional
    # Time_format = UT mid                   optional (see `stamp_offset_s`)
    # COSPAR = 92052A
    # NORAD  = 22076
    # NAME   = TOPEX/POSEIDON
    # SITE_NAME   = Derenivka                 SITE_* optional
    # SITE_LAT   = 48.5635505
    # SITE_LON   = 22.453751
    # SITE_ELEV  = 231.1325
    #  Date       UT     X  Y  Xerr  Yerr  Flux  Flux_err  magV  mag_err  Az(deg)  El(deg)  Rg(Mm)  filename
    2024-07-30 21:22:40.008    000.00000 ...                                  (14 columns)

or the JD variant whose rows start with one Julian-date column (13 columns). The range
column is in km whatever its label says; a ``*`` after the frame's file name marks a
saturated frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import functools
import re
from types import MappingProxyType

import numpy as np

from ingest import elements
from ingest.observation import MAX_EXPOSURE_S, Pass
from ingest.problems import FileWarning, missing_data_warnings
from ingest.reduction import fit_note, fit_reduction, sign_corrected_mag
from ingest.site import DERENIVKA, Site
from ingest.table import ELEVATION, POSITIVE_RANGE, Column, RowFlags, Rows, read_rows
from ingest.textfile import TextFile
from ingest.times import (
    FIRST_OBSERVATION_DATE,
    LAST_STORABLE_DATE,
    NS_PER_DAY,
    NS_PER_S,
    date_days,
    julian_date_ns,
    observable_days,
    parse_datetime,
    time_of_day_ns,
    to_datetime64,
)

__all__ = [
    "CcdPhotReader",
    "stamp_offset_s",
    "MID_EXPOSURE_SINCE",
    "UT_COLUMNS",
    "JD_COLUMNS",
]

# ccd_phot writes mid-exposure times since February 2023 (PROVENANCE.md); before, the
# frame's start time.
MID_EXPOSURE_SINCE = np.datetime64("2023-02-01T00:00:00", "ns")

_COMMON = (
    Column("x_px", "X"),
    Column("y_px", "Y"),
    Column("x_err_px", "Xerr"),
    Column("y_err_px", "Yerr"),
    Column("flux", "Flux"),
    Column("flux_err", "Flux_err"),
    Column("mag", "mag"),
    Column("mag_err", "mag_err"),
    Column("az_deg", "Az(deg)"),
    Column("el_deg", "El(deg)"),
    Column("range_km", "Rg"),
    # Frame names are not kept (a '*' after one is read from the bytes, see `_saturated`).
    Column("frame", "filename", "text", 1),
)
UT_COLUMNS = (Column("date", "Date", "text", 16), Column("ut", "UT", "text", 32)) + _COMMON
JD_COLUMNS = (Column("jd", "JD", "text", 32),) + _COMMON

# Column labels as ccd_phot writes them; mag and Rg carry a band / unit suffix.
_LABEL_PATTERNS = {
    "Date": r"Date",
    "UT": r"UT",
    "JD": r"JD",
    "X": r"X",
    "Y": r"Y",
    "Xerr": r"Xerr",
    "Yerr": r"Yerr",
    "Flux": r"Flux",
    "Flux_err": r"Flux_err",
    "mag": r"mag(\w*)",
    "mag_err": r"mag_err",
    "Az(deg)": r"Az(\(deg\))?",
    "El(deg)": r"El(\(deg\))?",
    "Rg": r"Rg(\((Mm|Km|km)\))?",
    "filename": r"filename",
}
_KEY_VALUE = re.compile(r"^([A-Za-z][A-Za-z0-9_ ]*?)\s*=\s*(.*)$")
_DATETIME = re.compile(r"^\d{4}-\d{2}-\d{2}[ T]\d{2}:\d{2}:\d{2}(\.\d+)?$")
_EXTENSION_BAND = re.compile(r"\.ph([A-Z]|[ubvri])$")
_STAMP_WORDS = {
    "start": 0.5,
    "begin": 0.5,
    "beginning": 0.5,
    "mid": 0.0,
    "middle": 0.0,
    "center": 0.0,
    "centre": 0.0,
    "mid-exposure": 0.0,
    "end": -0.5,
}
_VARIANT_WORDS = {"ut": "ut", "utc": "ut", "date": "ut", "jd": "jd"}
# The least range (km) at which a satellite is observed from the ground; values below it mean
# the column is not in km.
_MIN_RANGE_KM = 100.0


@dataclass
class _Header:
    """What the `#` lines of a ccd_phot file say (mutable only while being parsed)."""

    keys: dict = field(default_factory=dict)  # key -> (value, line)
    tle: tuple | None = None
    tle_line: int | None = None
    omm: MappingProxyType | None = None
    omm_line: int | None = None
    times: list = field(default_factory=list)  # (text, line) of the first/last frame lines
    notes: list = field(default_factory=list)  # other comment lines
    column_line: int = 0
    labels: tuple = ()
    variant: str = ""


def stamp_offset_s(first_stamp: np.datetime64, exposure_s: float, time_format: str | None) -> tuple[float, str]:
    """Seconds to add to a ccd_phot file's stamps to reach mid-exposure, and why.

    Parameters
    ----------
    first_stamp : datetime64
        The first row's stamp as written.
    exposure_s : float
        The header's ``dt``.
    time_format : str or None
        The ``# Time_format`` value. A word ``start``/``begin``, ``mid``/``middle``/``centre``
        or ``end`` in it states the stamp's place in the exposure; without one, files before
        2023-02-01 are taken to stamp the exposure start and later ones its middle.

    Returns
    -------
    shift_s : float
        ``+dt/2``, ``0`` or ``-dt/2``.
    stamps : str
        What the file's stamps were: ``"exposure start"``, ``"mid-exposure"`` or ``"exposure end"``.
    """
    words = [w for w in re.split(r"[\s,;/]+", (time_format or "").lower()) if w in _STAMP_WORDS]
    if words:
        fraction = _STAMP_WORDS[words[0]]
    else:
        fraction = 0.5 if np.datetime64(first_stamp, "ns") < MID_EXPOSURE_SINCE else 0.0
    stamps = {0.5: "exposure start", 0.0: "mid-exposure", -0.5: "exposure end"}[fraction]
    return fraction * exposure_s, stamps


class CcdPhotReader:
    """Reads ccd_phot ``.phX`` files (UT and JD variants) into one `Pass` each."""

    name = "ccd_phot"

    def sniff(self, text: TextFile) -> bool:
        """True when the file opens with ccd_phot's '# TLE:' or '# OMM:' line, or its '#' header
        lines lead to a ccd_phot column line."""
        for number in range(1, min(text.n_lines, 40) + 1):
            line = text.line(number).lstrip("\ufeff").strip()
            if not line:
                continue
            if number == 1 and (line == "# TLE:" or line.startswith("# OMM:")):
                return True
            tokens = line.lstrip("#").split()
            if tokens[:2] == ["Date", "UT"] or tokens[:1] == ["JD"]:
                return "Flux" in tokens
            if not line.startswith("#"):
                return False
        return False

    def read(self, path) -> tuple[Pass, ...]:
        """Read `path`; raise `FormatError` with the line and reason when it is not a valid ccd_phot file."""
        return self.parse(TextFile.from_path(path))

    def parse(self, text: TextFile) -> tuple[Pass, ...]:
        """Build the pass from an already loaded file."""
        header = _parse_header(text)
        # Messages name the columns as this file labels them (magV, Rg(Mm), ...).
        columns = _labelled_columns(header.variant, tuple(header.labels))
        exposure_s = _exposure(text, header)
        time_format = header.keys.get("Time_format", (None, None))
        _check_time_format_variant(text, header, time_format)
        norad, name, cospar = _identity(text, header)
        band, band_source = _band(text, header)
        site, site_source = _site(text, header)

        rows, problems = read_rows(text, header.column_line + 1, columns)
        flags = RowFlags(text, rows, n_rows=len(rows) + len(problems), problems=problems)
        stamps_ns = _stamps(rows, header.variant, flags)
        _check_values(rows, columns, flags)
        flags.time_order(stamps_ns, lambda i: _time_label(rows, i, header.variant))
        keep, row_problems = flags.finish()
        rows, stamps_ns = rows.select(keep), stamps_ns[keep]
        _check_range_unit(text, rows)
        shift_s, stamps = stamp_offset_s(to_datetime64(stamps_ns[:1])[0], exposure_s, time_format[0])
        time_ns = stamps_ns + int(round(shift_s * NS_PER_S))
        flux = rows["flux"]
        mag = rows["mag"]
        saturated = _saturated(text, rows)
        reduction = fit_reduction(mag, flux, exposure_s, rows["el_deg"], rows["range_km"])
        mag_corrected = None
        if reduction is not None and reduction.sign_error:
            mag_corrected = sign_corrected_mag(mag, rows["el_deg"], reduction)
        warnings = _header_warnings(text, header, stamps_ns, exposure_s, band, band_source)

        info = {key: value for key, (value, _) in header.keys.items()}
        info.update(
            format="ccd_phot",
            time_variant=header.variant,
            columns=" ".join(header.labels),
            range_label=_column(columns, "range_km").label,
            file_time_stamps=stamps,
            band_source=band_source,
            site_source=site_source,
            n_saturated=int(saturated.sum()),
        )
        if header.times:
            info["first_frame_utc"] = header.times[0][0]
            info["last_frame_utc"] = header.times[-1][0]
        for k, note in enumerate(header.notes):
            info[f"note_{k + 1}"] = note
        if fit_note(reduction):
            info["reduction"] = fit_note(reduction)

        return (
            Pass(
                norad=norad,
                name=name,
                band=band,
                site=site,
                exposure_s=exposure_s,
                time_utc=to_datetime64(time_ns),
                mag=mag,
                mag_err=rows["mag_err"],
                flux=flux,
                flux_err=rows["flux_err"],
                az_deg=rows["az_deg"],
                el_deg=rows["el_deg"],
                range_km=rows["range_km"],
                saturated=saturated,
                valid=np.isfinite(mag),
                cospar=cospar,
                tle=header.tle,
                omm=header.omm,
                time_convention="UTC, mid-exposure",
                time_shift_s=shift_s,
                mag_convention=(
                    "standard magnitude reduced to 1000 km range: A - 2.5 log10(Flux/dt) + c X "
                    "- 5 log10(Rg/1000 km), X = 1/sin(El), with the file's signed c (see reduction)"
                ),
                source_name=text.name,
                source_sha256=text.sha256,
                source_format=self.name,
                reduction=reduction,
                mag_corrected=mag_corrected,
                header=MappingProxyType(info),
                row_problems=row_problems,
                warnings=warnings,
            ),
        )


# -- header --------------------------------------------------------------------------------
@functools.lru_cache(maxsize=64)
def _labelled_columns(variant: str, labels: tuple[str, ...]) -> tuple[Column, ...]:
    """The columns of a variant named as a file labels them (a few label sets recur across files)."""
    return tuple(replace(c, label=label) for c, label in zip(UT_COLUMNS if variant == "ut" else JD_COLUMNS, labels))


def _parse_header(text: TextFile) -> _Header:
    header = _Header()
    number = 0
    while number < text.n_lines:
        number += 1
        raw = text.line(number).lstrip("\ufeff")
        stripped = raw.strip()
        if not stripped:
            continue
        commented = stripped.startswith("#")
        body = stripped.lstrip("#").strip()
        tokens = body.split()
        if tokens[:2] == ["Date", "UT"] or tokens[:1] == ["JD"]:
            header.column_line = number
            header.labels = tuple(tokens)
            header.variant = "ut" if tokens[0] == "Date" else "jd"
            _check_labels(text, header)
            return header
        if not commented:
            raise text.error(
                number,
                "expected the column line ('# Date UT X Y ...' or '# JD X Y ...') before "
                f"the data, found {stripped[:40]!r}",
            )
        if body == "TLE:":
            number = _read_tle_block(text, header, number)
        elif body.startswith("OMM:"):
            try:
                header.omm = elements.parse_omm(body[4:].strip())
            except ValueError as exc:
                raise text.error(number, f"{exc}; write the record as one JSON object on this line") from None
            header.omm_line = number
        elif _DATETIME.match(body):
            header.times.append((body, number))
        elif (match := _KEY_VALUE.match(body)) is not None:
            header.keys[match.group(1).strip()] = (match.group(2).strip(), number)
        else:
            header.notes.append(body)
    raise text.error(
        text.n_lines,
        "the header ends without the column line ('# Date UT X Y ...' or '# JD X Y ...') and no data rows follow",
    )


def _read_tle_block(text: TextFile, header: _Header, number: int) -> int:
    """Read the 2 or 3 TLE lines after '# TLE:'; return the last line number used."""
    lines = []
    for k in range(number + 1, min(number + 3, text.n_lines) + 1):
        body = text.line(k).strip().lstrip("#").strip()
        if not lines and not body.startswith("1 "):
            lines.append(body)
            continue
        lines.append(body)
        if body.startswith("2 "):
            break
    try:
        header.tle = elements.parse_tle(lines)
    except ValueError as exc:
        raise text.error(number + 1, f"{exc}; fix the TLE block after '# TLE:'") from None
    header.tle_line = number + 1
    return number + len(lines)


def _check_labels(text: TextFile, header: _Header) -> None:
    columns = UT_COLUMNS if header.variant == "ut" else JD_COLUMNS
    expected = [c.label for c in columns]
    found = header.labels
    good = len(found) == len(expected) and all(
        re.fullmatch(_LABEL_PATTERNS[label], token) for label, token in zip(expected, found)
    )
    if not good:
        raise text.error(
            header.column_line,
            f"the column line reads {' '.join(found)!r}; expected the {len(expected)} ccd_phot columns "
            f"{' '.join(expected)!r} (mag and Rg may carry a suffix such as magV, Rg(Km))",
        )


def _exposure(text: TextFile, header: _Header) -> float:
    if "dt" not in header.keys:
        raise text.error(header.column_line, "the header has no '# dt = ' line; add the exposure time in seconds")
    value, line = header.keys["dt"]
    try:
        exposure_s = float(value)
    except ValueError:
        exposure_s = float("nan")
    if not (np.isfinite(exposure_s) and 0 < exposure_s <= MAX_EXPOSURE_S):
        raise text.error(line, f"dt = {value!r} is not an exposure time in seconds (0 < dt <= {MAX_EXPOSURE_S:g})")
    return exposure_s


def _check_time_format_variant(text: TextFile, header: _Header, time_format: tuple) -> None:
    value, line = time_format
    if value is None:
        return
    words = [w for w in re.split(r"[\s,;/]+", value.lower()) if w]
    unknown = [w for w in words if w not in _STAMP_WORDS and w not in _VARIANT_WORDS and w != "exposure"]
    if unknown:
        raise text.error(
            line,
            f"Time_format = {value!r} is not understood; write UT or JD, optionally "
            "followed by start, mid or end (the stamp's place in the exposure)",
        )
    variants = {_VARIANT_WORDS[w] for w in words if w in _VARIANT_WORDS}
    if variants and variants != {header.variant}:
        raise text.error(
            line,
            f"Time_format = {value!r} contradicts the column line, whose time columns are "
            f"{'Date UT' if header.variant == 'ut' else 'JD'}",
        )


def _identity(text: TextFile, header: _Header) -> tuple[int, str, str]:
    norad = None
    if "NORAD" in header.keys:
        value, line = header.keys["NORAD"]
        try:
            norad = elements.check_norad(value)
        except ValueError as exc:
            raise text.error(line, f"NORAD = {exc}") from None
    for source, element_norad, line in (
        ("TLE", elements.tle_norad(header.tle) if header.tle else None, header.tle_line),
        ("OMM", elements.omm_norad(header.omm) if header.omm else None, header.omm_line),
    ):
        if element_norad is None:
            continue
        if norad is None:
            norad = element_norad
        elif element_norad != norad:
            raise text.error(
                line,
                f"the {source} is for NORAD {element_norad} but the header says NORAD {norad}; "
                "the file mixes two objects",
            )
    if norad is None:
        raise text.error(header.column_line, "the header names no object: add '# NORAD = <number>' or a TLE/OMM")
    name = header.keys.get("NAME", ("", 0))[0]
    if not name and header.tle and len(header.tle) == 3:
        name = header.tle[0][2:].strip() if header.tle[0].startswith("0 ") else header.tle[0].strip()
    if not name and header.omm:
        name = str(header.omm.get("OBJECT_NAME", ""))
    cospar = header.keys.get("COSPAR", ("", 0))[0]
    if not cospar and header.tle:
        cospar = elements.tle_cospar(header.tle)
    if not cospar and header.omm:
        cospar = str(header.omm.get("OBJECT_ID", ""))
    return norad, name, cospar


def _band(text: TextFile, header: _Header) -> tuple[str, str]:
    if "Filter" in header.keys:
        value, line = header.keys["Filter"]
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_']*", value):
            raise text.error(line, f"Filter = {value!r} is not a band name such as V or R")
        return value, "Filter line"
    match = _EXTENSION_BAND.search(text.name)
    if match:
        return match.group(1).upper(), "file extension"
    mag_label = header.labels[len(header.labels) - 6]
    suffix = re.fullmatch(_LABEL_PATTERNS["mag"], mag_label).group(1)
    if suffix:
        return suffix, "magnitude column name"
    raise text.error(
        header.column_line,
        "cannot tell the band: there is no '# Filter = ' line, the extension is "
        "not .phX and the magnitude column is plain 'mag'; add '# Filter = V'",
    )


def _site(text: TextFile, header: _Header) -> tuple[Site, str]:
    keys = header.keys
    coordinates = [k for k in ("SITE_LAT", "SITE_LON", "SITE_ELEV") if k in keys]
    name = keys.get("SITE_NAME", ("", 0))[0]
    if coordinates:
        if len(coordinates) < 3:
            missing = sorted({"SITE_LAT", "SITE_LON", "SITE_ELEV"} - set(coordinates))
            raise text.error(
                keys[coordinates[0]][1],
                f"the site has {', '.join(coordinates)} but not {', '.join(missing)}; give all three",
            )
        values = {}
        for key in coordinates:
            value, line = keys[key]
            try:
                values[key] = float(value)
            except ValueError:
                raise text.error(line, f"{key} = {value!r} is not a number") from None
        try:
            return Site(
                name or "unnamed site", values["SITE_LAT"], values["SITE_LON"], values["SITE_ELEV"]
            ), "SITE_* lines"
        except ValueError as exc:
            raise text.error(keys["SITE_LAT"][1], str(exc)) from None
    if name:
        try:
            return Site.preset(name), "preset named by SITE_NAME"
        except KeyError:
            raise text.error(
                keys["SITE_NAME"][1],
                f"SITE_NAME = {name!r} is not a known site and the header has no "
                "SITE_LAT/SITE_LON/SITE_ELEV lines; add them",
            ) from None
    return DERENIVKA, "assumed Derenivka: no SITE_* lines (ccd_phot computed Az/El for Derenivka)"


# -- rows --------------------------------------------------------------------------------------
def _column(columns: tuple[Column, ...], key: str) -> Column:
    return next(c for c in columns if c.key == key)


_DATE_RANGE = f"{FIRST_OBSERVATION_DATE} .. {LAST_STORABLE_DATE}"


def _token(rows: Rows, key: str, i: int) -> str:
    return rows[key][i].decode("utf-8", "replace")


def _time_label(rows: Rows, i: int, variant: str) -> str:
    return _token(rows, "jd", i) if variant == "jd" else f"{_token(rows, 'date', i)} {_token(rows, 'ut', i)}"


def _stamps(rows: Rows, variant: str, flags: RowFlags) -> np.ndarray:
    """The rows' stamps as written, int64 ns since 1970 UTC (0 for rows set aside)."""
    if variant == "jd":
        ns, ok = julian_date_ns(rows["jd"])
        flags.flag(
            ~ok,
            lambda i: f"JD {_token(rows, 'jd', i)!r} is not a Julian date of an observation ({_DATE_RANGE})",
        )
        return ns
    days, ok_date = date_days(rows["date"])
    flags.flag(~ok_date, lambda i: f"Date {_token(rows, 'date', i)!r} is not a date (YYYY-MM-DD)")
    in_range = observable_days(days)
    flags.flag(
        ok_date & ~in_range,
        lambda i: f"Date {_token(rows, 'date', i)} is outside the dates an observation can have ({_DATE_RANGE})",
    )
    tod, ok_time = time_of_day_ns(rows["ut"])
    flags.flag(~ok_time, lambda i: f"UT {_token(rows, 'ut', i)!r} is not a time of day (HH:MM:SS.fff)")
    good = ok_date & in_range & ok_time
    return np.where(good, np.where(good, days, 0) * NS_PER_DAY + tod, 0)


# The magnitudes a satellite can have: brighter than -30 would outshine the Sun (-26.7).
_MAG_RANGE = (-30.0, 40.0)


def _check_values(rows: Rows, columns: tuple[Column, ...], flags: RowFlags) -> None:
    """Physical bounds: positive flux and range, elevation within +-90, non-negative errors."""
    flags.values(
        columns,
        (
            (
                "flux",
                lambda v: v > 0,
                "is not positive: ccd_phot never writes such a row because its magnitude would be undefined",
            ),
            ("flux_err", lambda v: v >= 0, "is negative; an error must be zero or positive"),
            ("mag", lambda v: (v > _MAG_RANGE[0]) & (v < _MAG_RANGE[1]), "is not a magnitude of a satellite"),
            ("mag_err", lambda v: v >= 0, "is negative; an error must be zero or positive"),
            ELEVATION,
            ("az_deg", lambda v: (v >= -360) & (v <= 360), "is not an azimuth in degrees"),
            POSITIVE_RANGE,
        ),
    )


def _check_range_unit(text: TextFile, rows: Rows) -> None:
    median_km = float(np.median(rows["range_km"]))
    if median_km < _MIN_RANGE_KM:
        raise text.error(
            int(rows.line[0]),
            f"the range column's median is {median_km:g}, so it is not in km as "
            "ccd_phot writes it (even under the label Rg(Mm)); convert it to km",
        )


def _header_warnings(
    text: TextFile, header: _Header, stamps_ns: np.ndarray, exposure_s: float, band: str, band_source: str
) -> tuple[FileWarning, ...]:
    """Where the header disagrees with the data: frame times, or the band's three sources."""
    found = []
    if header.times:
        first_text, first_line = header.times[0]
        last_text, last_line = header.times[-1]
        found += missing_data_warnings(
            (parse_datetime(first_text), first_line, "first frame time"),
            (parse_datetime(last_text), last_line, "last frame time"),
            stamps_ns,
            exposure_s,
        )
    if band_source == "Filter line":
        line = header.keys["Filter"][1]
        suffix = re.fullmatch(_LABEL_PATTERNS["mag"], header.labels[len(header.labels) - 6]).group(1)
        extension = _EXTENSION_BAND.search(text.name)
        for where, other in (
            ("the magnitude column is mag" + (suffix or ""), suffix),
            (f"the file name ends in .ph{extension.group(1) if extension else ''}", extension and extension.group(1)),
        ):
            if other and other.upper() != band.upper():
                found.append(
                    FileWarning(
                        line,
                        f"Filter = {band} but {where}: the band is taken from the Filter line; fix whichever is wrong",
                    )
                )
    return tuple(found)


def _saturated(text: TextFile, rows: Rows) -> np.ndarray:
    """(n,) bool: rows whose frame name (the last column) ends with '*', the saturation mark.

    Found in the bytes: a '*' ending a token can only be the frame name's, since any other
    column holding one would have failed to parse.
    """
    buf = np.frombuffer(text.data, dtype=np.uint8)
    start = text.offset(int(rows.line[0]))
    stars = np.flatnonzero(buf[start:] == 42) + start
    if not len(stars):
        return np.zeros(len(rows), dtype=bool)
    after = buf[np.minimum(stars + 1, len(buf) - 1)]
    ending = stars[(stars + 1 == len(buf)) | (after <= 32)]
    return np.isin(rows.line, np.searchsorted(text.line_ends, ending) + 1)
