"""Reader for light curves as CSV: rsodb's own export and tables from other tools.

Layout (docs/formats.md, "CSV light curves")::

    # rsodb light curve CSV                         optional first line
    # object = 22076                                required: NORAD number
    # band = V                                      required
    # exposure_s = 0.2                              required, seconds (or 'exposure')
    # site = Derenivka                              required: a known site, or a name with
    # site_lat_deg = 48.5635505                       site_lat_deg, site_lon_deg and
    # site_lon_deg = 22.453751                        site_elevation_m
    # site_elevation_m = 231.1325
    # name = TOPEX/POSEIDON                         optional: name, cospar, time_stamps
    # time_stamps = mid                               (start, mid or end of the exposure),
    # tle_1 = 1 22076U ...                            mag_convention, tle_0..tle_2, omm,
    # tle_2 = 2 22076 ...                             reduction, elements_source (JSON)
    time_utc,mag_file,mag_corrected,mag_err,flux,flux_err,az_deg,el_deg,range_km,saturated,valid
    2024-07-30T21:22:40.008000000Z,4.4670,4.4004,0.0060,30806.8538,...

The column line names the columns, in any order: a time (``time_utc`` or ``time``, ISO 8601
UTC, or ``jd``, a Julian date), the magnitude (``mag`` or ``mag_file``) and ``mag_err`` are
required; ``mag_corrected``, ``flux``, ``flux_err``, ``az_deg``, ``el_deg``, ``range_km``,
``saturated`` and ``valid`` (0/1) are optional (NaN where absent). An empty field or ``nan`` is
"no value". Any other column is refused rather than ignored.
"""

from __future__ import annotations

from dataclasses import replace
import json
import re
from types import MappingProxyType

import numpy as np

from ingest import elements
from ingest.observation import MAX_EXPOSURE_S, Pass
from ingest.reduction import Reduction
from ingest.site import Site
from ingest.table import Column, RowFlags, Rows, read_rows
from ingest.textfile import TextFile
from ingest.times import FIRST_OBSERVATION_DATE, LAST_STORABLE_DATE, NS_PER_S, julian_date_ns, observable_days

__all__ = ["CsvReader", "CSV_COLUMNS", "CSV_MARKER"]

CSV_MARKER = "# rsodb light curve CSV"
# Accepted column names -> (field, kind); the first name of each field is the one rsodb writes.
CSV_COLUMNS = {
    "time_utc": ("time", "text"),
    "time": ("time", "text"),
    "jd": ("jd", "text"),
    "mag_file": ("mag", "float"),
    "mag": ("mag", "float"),
    "mag_corrected": ("mag_corrected", "float"),
    "mag_err": ("mag_err", "float"),
    "flux": ("flux", "float"),
    "flux_err": ("flux_err", "float"),
    "az_deg": ("az_deg", "float"),
    "el_deg": ("el_deg", "float"),
    "range_km": ("range_km", "float"),
    "saturated": ("saturated", "float"),
    "valid": ("valid", "float"),
}
_REQUIRED = ("mag", "mag_err")
# Columns that must hold a value in every row; elsewhere NaN (or an empty field) is "no value".
_FINITE = ("saturated", "valid")
# An empty field: between two commas, or at either end of a row.
_EMPTY_FIELD = re.compile(rb"(?<=,)(?=,|\r?$)|^(?=,)", re.MULTILINE)
_HEADER_LINES = 80
_STAMP_SHIFT = {"start": 0.5, "mid": 0.0, "middle": 0.0, "end": -0.5}


class CsvReader:
    """Reads a CSV light curve (one pass) with a ``# key = value`` header."""

    name = "csv"

    def sniff(self, text: TextFile) -> bool:
        """True when ``#`` lines lead to a comma-separated column line naming a time and a magnitude."""
        for number in range(1, min(text.n_lines, _HEADER_LINES) + 1):
            line = text.line(number).lstrip("\ufeff").strip()
            if not line or line.startswith("#"):
                continue
            names = {token.strip().lower() for token in line.split(",")}
            return "," in line and bool(names & {"time_utc", "time", "jd"}) and bool(names & {"mag", "mag_file"})
        return False

    def read(self, path) -> tuple[Pass, ...]:
        """Read `path`; raise `FormatError` with the line and reason when it is not a CSV light curve."""
        return self.parse(TextFile.from_path(path))

    def parse(self, text: TextFile) -> tuple[Pass, ...]:
        """Build the pass from an already loaded file."""
        keys, column_line = _header(text)
        columns = _columns(text, column_line)
        fields = {column.key for column in columns}
        norad = _norad(text, keys)
        band = _required(text, keys, "band", column_line)
        exposure_s = _exposure(text, keys, column_line)
        site = _site(text, keys, column_line)
        shift_s = _stamp_shift(text, keys) * exposure_s

        rows, problems = read_rows(_empty_as_nan(text, column_line), column_line + 1, columns, delimiter=",")
        flags = RowFlags(text, rows, n_rows=len(rows) + len(problems), problems=problems)
        stamps_ns = _times(rows, "jd" if "jd" in fields else "time", flags)
        flags.values(
            columns,
            tuple(
                check
                for check in (
                    ("mag_err", lambda v: ~(v < 0), "is negative; an error must be zero or positive"),
                    ("el_deg", lambda v: ~(np.abs(v) > 90), "is not an elevation in degrees (-90..90)"),
                    ("range_km", lambda v: ~(v <= 0), "is not a positive range"),
                    ("saturated", lambda v: np.isin(v, (0, 1)), "is not 0 or 1"),
                    ("valid", lambda v: np.isin(v, (0, 1)), "is not 0 or 1"),
                )
                if check[0] in fields
            ),
            delimiter=",",
        )
        time_key = "jd" if "jd" in fields else "time"
        flags.time_order(stamps_ns, lambda i: rows[time_key][i].decode())
        keep, row_problems = flags.finish()
        rows, stamps_ns = rows.select(keep), stamps_ns[keep]
        n = len(rows)

        def column(key: str, default=np.nan) -> np.ndarray:
            return rows[key] if key in fields else np.full(n, default, dtype=float)

        mag = rows["mag"]
        valid = np.isfinite(mag) & (column("valid", 1.0) == 1.0)
        info = {key: value for key, (value, _) in keys.items()}
        info.update(format="csv", columns=text.line(column_line).strip())
        return (
            Pass(
                norad=norad,
                name=keys.get("name", ("", 0))[0],
                band=band,
                site=site,
                exposure_s=exposure_s,
                time_utc=(stamps_ns + int(round(shift_s * NS_PER_S))).view("datetime64[ns]"),
                mag=mag,
                mag_err=rows["mag_err"],
                flux=column("flux"),
                flux_err=column("flux_err"),
                az_deg=column("az_deg"),
                el_deg=column("el_deg"),
                range_km=column("range_km"),
                saturated=column("saturated", 0.0) == 1.0,
                valid=valid,
                cospar=keys.get("cospar", ("", 0))[0],
                tle=_tle(text, keys),
                omm=_json(text, keys, "omm", elements.parse_omm),
                time_convention="UTC, mid-exposure",
                time_shift_s=shift_s,
                mag_convention=keys.get("mag_convention", ("as written in the CSV file (not stated)", 0))[0],
                source_name=text.name,
                source_sha256=text.sha256,
                source_format=self.name,
                reduction=_json(text, keys, "reduction", lambda value: Reduction(**json.loads(value))),
                mag_corrected=rows["mag_corrected"] if "mag_corrected" in fields else None,
                header=MappingProxyType(info),
                row_problems=row_problems,
                elements_source=_json(text, keys, "elements_source", json.loads),
            ),
        )


def _empty_as_nan(text: TextFile, column_line: int) -> TextFile:
    """The file with every empty field of its rows written ``nan`` (lines and hash unchanged)."""
    start = text.offset(column_line + 1)
    body = text.data[start:]
    if b",," not in body and b",\n" not in body and b"\n," not in body and not body.startswith(b","):
        return text
    filled = TextFile.from_bytes(text.path, text.data[:start] + _EMPTY_FIELD.sub(b"nan", body))
    return replace(filled, raw_sha256=text.raw_sha256)


def _header(text: TextFile) -> tuple[dict, int]:
    keys = {}
    for number in range(1, min(text.n_lines, _HEADER_LINES) + 1):
        line = text.line(number).lstrip("\ufeff").strip()
        if not line:
            continue
        if not line.startswith("#"):
            return keys, number
        key, sep, value = line.lstrip("#").partition("=")
        if sep:
            key = key.strip().lower()
            if key in _KEY_ALIASES:
                key = _KEY_ALIASES[key]
                if key in keys:
                    continue  # rsodb's own key, given too, wins
            keys[key] = (value.strip(), number)
    raise text.error(None, "no column line (e.g. 'time_utc,mag,mag_err') after the '#' header lines")


def _columns(text: TextFile, line: int) -> tuple[Column, ...]:
    names = [token.strip().lower() for token in text.line(line).split(",")]
    unknown = [name for name in names if name not in CSV_COLUMNS]
    if unknown:
        raise text.error(
            line,
            f"column {unknown[0]!r} is not one rsodb reads; the columns are {', '.join(CSV_COLUMNS)} "
            "(rename or drop it)",
        )
    fields = [CSV_COLUMNS[name][0] for name in names]
    repeated = sorted({field for field in fields if fields.count(field) > 1})
    if repeated:
        raise text.error(line, f"the columns name {repeated[0]!r} twice; keep one of them")
    missing = [field for field in ("time" if "jd" not in fields else "jd", *_REQUIRED) if field not in fields]
    if missing:
        what = "time column (time_utc, time or jd)" if missing[0] in ("time", "jd") else f"{missing[0]} column"
        raise text.error(line, f"the CSV has no {what}; the column line must name time_utc, mag and mag_err")
    return tuple(
        Column(CSV_COLUMNS[name][0], name, CSV_COLUMNS[name][1], 40, finite=CSV_COLUMNS[name][0] in _FINITE)
        for name in names
    )


# What a missing header line could read, for the error that asks for it.
_EXAMPLES = {"band": "V", "exposure_s": "0.1", "site": "Derenivka"}
# Header keys other tools write, read as rsodb's: the exposure in seconds.
_KEY_ALIASES = {"exposure": "exposure_s"}


def _required(text: TextFile, keys: dict, key: str, column_line: int) -> str:
    if key not in keys or not keys[key][0]:
        raise text.error(
            column_line, f"the header has no '# {key} = ' line; add it (e.g. '# {key} = {_EXAMPLES.get(key, '...')}')"
        )
    return keys[key][0]


def _norad(text: TextFile, keys: dict) -> int:
    key = "object" if "object" in keys else "norad"
    if key not in keys:
        raise text.error(None, "the header names no object: add '# object = <NORAD number>'")
    value, line = keys[key]
    try:
        return elements.check_norad(value)
    except ValueError as exc:
        raise text.error(line, f"{key} = {exc}") from None


def _exposure(text: TextFile, keys: dict, column_line: int) -> float:
    value = _required(text, keys, "exposure_s", column_line)
    try:
        exposure_s = float(value)
    except ValueError:
        exposure_s = float("nan")
    if not (np.isfinite(exposure_s) and 0 < exposure_s <= MAX_EXPOSURE_S):
        raise text.error(
            keys["exposure_s"][1], f"exposure_s = {value!r} is not a number of seconds (0 < exposure <= 3600)"
        )
    return exposure_s


def _site(text: TextFile, keys: dict, column_line: int) -> Site:
    name = _required(text, keys, "site", column_line)
    coordinates = [key for key in ("site_lat_deg", "site_lon_deg", "site_elevation_m") if key in keys]
    if not coordinates:
        try:
            return Site.preset(name)
        except KeyError:
            raise text.error(
                keys["site"][1],
                f"site = {name!r} is not a known site; add site_lat_deg, site_lon_deg and site_elevation_m lines",
            ) from None
    if len(coordinates) < 3:
        raise text.error(keys[coordinates[0]][1], "give all three of site_lat_deg, site_lon_deg and site_elevation_m")
    try:
        return Site(name, *(float(keys[key][0]) for key in ("site_lat_deg", "site_lon_deg", "site_elevation_m")))
    except ValueError as exc:
        raise text.error(keys["site_lat_deg"][1], str(exc)) from None


def _stamp_shift(text: TextFile, keys: dict) -> float:
    value, line = keys.get("time_stamps", ("mid", 0))
    if value.lower() not in _STAMP_SHIFT:
        raise text.error(line, f"time_stamps = {value!r} is not start, mid or end (the stamp's place in the exposure)")
    return _STAMP_SHIFT[value.lower()]


def _tle(text: TextFile, keys: dict):
    lines = [keys[key][0] for key in ("tle_0", "tle_1", "tle_2") if key in keys]
    if not lines:
        return None
    try:
        return elements.parse_tle(lines)
    except ValueError as exc:
        raise text.error(keys.get("tle_1", (None, None))[1], f"{exc}; fix the tle_1/tle_2 lines") from None


def _json(text: TextFile, keys: dict, key: str, parse):
    if key not in keys:
        return None
    value, line = keys[key]
    try:
        return parse(value)
    except (ValueError, TypeError) as exc:
        raise text.error(line, f"{key} is not valid ({exc}); write it as one JSON object on this line") from None


_DATE_RANGE = f"{FIRST_OBSERVATION_DATE} .. {LAST_STORABLE_DATE}"


def _times(rows: Rows, key: str, flags: RowFlags) -> np.ndarray:
    """The rows' times as int64 ns since 1970 (0 for rows set aside)."""
    raw = rows[key]
    if key == "jd":
        ns, ok = julian_date_ns(np.char.strip(raw))
        flags.flag(~ok, lambda i: f"jd {raw[i].decode()!r} is not a Julian date of an observation ({_DATE_RANGE})")
        return ns
    text = np.char.strip(np.char.rstrip(np.char.strip(raw), b"Z"))
    ns = np.zeros(len(raw), dtype=np.int64)
    ok = np.zeros(len(raw), dtype=bool)
    for i, value in enumerate(text.tolist()):
        try:
            day = np.datetime64(value[:10].decode(), "D")
            if observable_days(day.astype(np.int64)) and len(value) >= 19:
                ns[i] = np.datetime64(value.decode().replace(" ", "T"), "ns").astype(np.int64)
                ok[i] = True
        except ValueError:
            pass
    flags.flag(
        ~ok,
        lambda i: (
            f"{key} {raw[i].decode()!r} is not an ISO 8601 UTC time of an observation "
            f"(YYYY-MM-DDTHH:MM:SS[.fff], {_DATE_RANGE})"
        ),
    )
    return ns
