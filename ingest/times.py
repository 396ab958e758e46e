"""Vectorised parsing and formatting of the time stamps written in observation files.

Files write UTC as ``YYYY-MM-DD`` + ``HH:MM:SS.fff`` (ccd_phot UT variant), as a Julian date
``2460746.2300939740`` (ccd_phot JD variant) or as a time of day with the date on the first
line (phc). Everything here works on whole columns (fixed-width byte arrays as returned by
`numpy.loadtxt`) and returns int64 nanoseconds since 1970-01-01 UTC together with a boolean
mask of the entries that parsed; callers turn the first bad entry into a `FormatError`.

The Julian date is parsed as an integer day and a decimal fraction separately, so the JD
column keeps all its printed digits (to the nanosecond) instead of the ~40 us of a float64 JD.
"""

from __future__ import annotations

import re

import numpy as np

__all__ = [
    "NS_PER_DAY",
    "NS_PER_S",
    "FIRST_OBSERVATION_DATE",
    "LAST_STORABLE_DATE",
    "observable_days",
    "parse_datetime",
    "UNIX_EPOCH_JD",
    "time_of_day_ns",
    "date_days",
    "julian_date_ns",
    "to_datetime64",
    "format_date_time_ms",
    "format_iso_us",
    "julian_date_repr",
]

NS_PER_S = 1_000_000_000
NS_PER_DAY = 86_400 * NS_PER_S
# 1970-01-01T00:00 UTC is JD 2440587.5.
UNIX_EPOCH_JD = 2440587.5
_UNIX_EPOCH_JD_DAY = 2440587  # the JD day (starting at noon) that contains the Unix epoch
# The dates an observation can have: none before Sputnik's launch, and none after the last day
# numpy's datetime64[ns] (int64 ns since 1970) can hold, where times would wrap around.
FIRST_OBSERVATION_DATE = np.datetime64("1957-10-04", "D")
LAST_STORABLE_DATE = np.datetime64("2262-04-10", "D")
_DAY_RANGE = (int(FIRST_OBSERVATION_DATE.astype(np.int64)), int(LAST_STORABLE_DATE.astype(np.int64)))
# The same range as Julian day numbers (the JD day starting at noon of the date before).
_JD_RANGE = (_UNIX_EPOCH_JD_DAY + _DAY_RANGE[0], _UNIX_EPOCH_JD_DAY + _DAY_RANGE[1])
_DATE_RE = re.compile(rb"^\d{4}-\d{2}-\d{2}$")
_JD_INT_DIGITS = 8
_JD_FRAC_DIGITS = 18
_INT_PLACES = 10 ** np.arange(_JD_INT_DIGITS - 1, -1, -1, dtype=np.int64)
_FRAC_PLACES = 10 ** np.arange(_JD_FRAC_DIGITS - 1, -1, -1, dtype=np.int64)


def _char_matrix(column: np.ndarray) -> np.ndarray:
    """(n,) fixed-width bytes ('S') -> (n, width) int16 character codes, zero-padded.

    The width is cut to the longest entry, so a wide field costs only what it holds.
    """
    column = np.ascontiguousarray(column)
    chars = column.view(np.uint8).reshape(len(column), column.dtype.itemsize)
    used = np.flatnonzero(chars.any(axis=0))
    width = int(used[-1]) + 1 if len(used) else 0
    return chars[:, :width].astype(np.int16)


def time_of_day_ns(column: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parse ``HH:MM:SS[.f...]`` times of day.

    Parameters
    ----------
    column : (n,) bytes ('S' dtype)
        Time-of-day tokens; fractions beyond nanoseconds are truncated.

    Returns
    -------
    ns : (n,) int64
        Nanoseconds since midnight (0 where not parsed).
    ok : (n,) bool
        True where the token is a valid time of day (hours < 24, minutes and seconds < 60).

    >>> ns, ok = time_of_day_ns(np.array([b"21:22:40.008", b"7:00:00"]))
    >>> ns[0], ok.tolist()
    (76960008000000, [True, False])
    """
    chars = _char_matrix(column)
    n, width = chars.shape
    if width < 8:
        return np.zeros(n, np.int64), np.zeros(n, bool)
    is_digit = (chars >= 48) & (chars <= 57)
    value = chars - 48
    ok = is_digit[:, [0, 1, 3, 4, 6, 7]].all(axis=1) & (chars[:, 2] == 58) & (chars[:, 5] == 58)
    hours = value[:, 0].astype(np.int64) * 10 + value[:, 1]
    minutes = value[:, 3].astype(np.int64) * 10 + value[:, 4]
    seconds = value[:, 6].astype(np.int64) * 10 + value[:, 7]
    ok &= (hours < 24) & (minutes < 60) & (seconds < 60)
    frac_ns = np.zeros(n, np.int64)
    if width > 8:
        tail = chars[:, 8:]
        has_tail = tail[:, 0] != 0
        ok &= ~has_tail | (tail[:, 0] == 46)
        fraction = tail[:, 1:]
        frac_digit = is_digit[:, 9:]
        # Zero padding only at the end of the token, and nothing but digits before it.
        ok &= (frac_digit | (fraction == 0)).all(axis=1)
        ok &= ~((fraction[:, 1:] != 0) & (fraction[:, :-1] == 0)).any(axis=1)
        # A decimal point needs at least one digit after it.
        first_digit = frac_digit[:, 0] if fraction.shape[1] else np.zeros(n, bool)
        ok &= ~has_tail | first_digit
        kept = min(fraction.shape[1], 9)
        scale = 10 ** (8 - np.arange(kept, dtype=np.int64))
        frac_ns = np.where(frac_digit[:, :kept], fraction[:, :kept] - 48, 0).astype(np.int64) @ scale
    ns = ((hours * 60 + minutes) * 60 + seconds) * NS_PER_S + frac_ns
    return np.where(ok, ns, 0), ok


def observable_days(days: np.ndarray) -> np.ndarray:
    """(n,) bool: days since 1970 that lie within FIRST_OBSERVATION_DATE .. LAST_STORABLE_DATE.

    >>> observable_days(np.array([-5000, 20000, 375864])).tolist()
    [False, True, False]
    """
    days = np.asarray(days)
    return (days >= _DAY_RANGE[0]) & (days <= _DAY_RANGE[1])


def parse_datetime(text: str) -> np.datetime64 | None:
    """``YYYY-MM-DD[ T]HH:MM:SS[.f...]`` as datetime64[ns], or None when it is not such a time
    or lies outside the observable dates (a year 2999 would wrap around in datetime64[ns]).

    >>> parse_datetime("2025-01-30 17:31:25"), parse_datetime("2999-01-30 00:00:00")
    (numpy.datetime64('2025-01-30T17:31:25.000000000'), None)
    """
    text = text.strip().rstrip("Z").replace(" ", "T", 1)
    try:
        day = np.datetime64(text[:10], "D")
        if not observable_days(day.astype(np.int64)):
            return None
        return np.datetime64(text, "ns")
    except ValueError:
        return None


def date_days(column: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parse ``YYYY-MM-DD`` dates into days since 1970-01-01.

    Parameters
    ----------
    column : (n,) bytes ('S' dtype)

    Returns
    -------
    days : (n,) int64
    ok : (n,) bool
    """
    # A pass has one or two distinct dates: parse the distinct values only.
    if len(column) and (column == column[0]).all():
        values, inverse = column[:1], np.zeros(len(column), dtype=np.intp)
    else:
        values, inverse = np.unique(column, return_inverse=True)
    days = np.zeros(len(values), np.int64)
    ok = np.zeros(len(values), bool)
    for k, value in enumerate(values):
        if _DATE_RE.match(value):
            try:
                days[k] = np.datetime64(value.decode("ascii"), "D").astype(np.int64)
                ok[k] = True
            except ValueError:
                pass
    return days[inverse], ok[inverse]


def julian_date_ns(column: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parse Julian dates (UTC) written as ``ddddddd.ffff...`` into ns since 1970-01-01 UTC.

    Parameters
    ----------
    column : (n,) bytes ('S' dtype)

    Returns
    -------
    ns : (n,) int64
    ok : (n,) bool
        True for plain decimals with one point whose day lies in the observable dates
        (FIRST_OBSERVATION_DATE .. LAST_STORABLE_DATE).

    >>> ns, ok = julian_date_ns(np.array([b"2440587.5", b"2460746.230093974", b"24607a6.2", b"2400000.5"]))
    >>> ns[:2].tolist(), ok.tolist()
    ([0, 1741714280119353600], [True, True, False, False])
    """
    column = np.ascontiguousarray(column)
    chars = column.view(np.uint8).reshape(len(column), column.dtype.itemsize)
    n, width = chars.shape
    is_dot = chars == 46
    is_digit = (chars >= 48) & (chars <= 57)
    ok = (is_dot.sum(axis=1) == 1) & (is_digit | is_dot | (chars == 0)).all(axis=1) & (chars[:, 0] != 0)
    ok &= ~((chars[:, 1:] != 0) & (chars[:, :-1] == 0)).any(axis=1)  # zero padding only at the end
    dot = np.argmax(is_dot, axis=1)
    ok &= (dot >= 1) & (dot <= _JD_INT_DIGITS)
    # Align every row on its decimal point: the integer digits right-aligned in _JD_INT_DIGITS
    # columns, the fraction left-aligned in _JD_FRAC_DIGITS columns (18 digits fit in int64;
    # further ones are far below a nanosecond), NUL-padded on both sides.
    padded = np.zeros((n, _JD_INT_DIGITS + width + _JD_FRAC_DIGITS), dtype=np.uint8)
    padded[:, _JD_INT_DIGITS : _JD_INT_DIGITS + width] = chars
    whole = np.take_along_axis(padded, dot[:, None] + np.arange(_JD_INT_DIGITS), axis=1)
    fraction = np.take_along_axis(padded, (dot + _JD_INT_DIGITS + 1)[:, None] + np.arange(_JD_FRAC_DIGITS), axis=1)
    ok &= fraction[:, 0] != 0  # a digit after the point
    day = np.where(whole == 0, 0, whole.astype(np.int64) - 48) @ _INT_PLACES
    numerator = np.where(fraction == 0, 0, fraction.astype(np.int64) - 48) @ _FRAC_PLACES
    ok &= (day >= _JD_RANGE[0]) & (day <= _JD_RANGE[1])
    day = np.where(ok, day, _UNIX_EPOCH_JD_DAY)  # no overflow below for rows refused here
    # The JD day starts at noon: JD d.f is (d - 2440587) days + (f - 0.5) day after the epoch.
    day_ns = (numerator / 10.0**_JD_FRAC_DIGITS) * NS_PER_DAY
    ns = (day - _UNIX_EPOCH_JD_DAY) * NS_PER_DAY - NS_PER_DAY // 2 + np.rint(day_ns).astype(np.int64)
    return np.where(ok, ns, 0), ok


def to_datetime64(ns: np.ndarray) -> np.ndarray:
    """int64 ns since 1970 -> datetime64[ns] (a view, no copy)."""
    return np.asarray(ns, dtype=np.int64).view("datetime64[ns]")


def format_date_time_ms(time_utc: np.ndarray) -> tuple[list[str], list[str]]:
    """Split datetime64 times into ``YYYY-MM-DD`` and ``HH:MM:SS.mmm`` strings.

    Milliseconds are truncated, not rounded, as ccd_phot truncates the FITS DATE-OBS.

    Parameters
    ----------
    time_utc : (n,) datetime64

    Returns
    -------
    dates, times : list of str, length n
    """
    iso = np.datetime_as_string(np.asarray(time_utc).astype("datetime64[ms]"), unit="ms").tolist()
    return [stamp[:10] for stamp in iso], [stamp[11:] for stamp in iso]


def julian_date_repr(time_utc: np.ndarray) -> list[str]:
    """Julian dates (UTC) as ccd_phot prints them: the shortest repr of the nearest float64.

    The float64 JD (resolution ~40 us for current dates) is the integer day plus the exact
    fraction, rounded once, so a JD read from a ccd_phot file prints back as the same digits.

    Parameters
    ----------
    time_utc : (n,) datetime64

    Returns
    -------
    list of str, length n
    """
    ns = np.asarray(time_utc).astype("datetime64[ns]").astype(np.int64)
    since_noon = ns + NS_PER_DAY // 2
    day = np.floor_divide(since_noon, NS_PER_DAY)
    fraction = (since_noon - day * NS_PER_DAY) / NS_PER_DAY
    jd = (day + _UNIX_EPOCH_JD_DAY).astype(np.float64) + fraction
    return list(map(repr, jd.tolist()))


def format_iso_us(time_utc: np.datetime64, digits: int = 6) -> str:
    """``YYYY-MM-DD HH:MM:SS.ffffff`` for one time (header lines), fraction truncated to `digits`."""
    text = str(np.datetime64(time_utc, "ns"))
    date, clock = text.split("T")
    whole, _, frac = clock.partition(".")
    frac = (frac + "000000000")[:digits]
    return f"{date} {whole}.{frac}" if digits else f"{date} {whole}"
