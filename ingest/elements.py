"""Orbital elements carried in observation headers: a TLE block or an OMM JSON record.

Readers hand the raw header lines here; problems come back as `ValueError` with one sentence,
which the reader turns into a `FormatError` at the right line.
"""
from __future__ import annotations

import json
from types import MappingProxyType
from typing import Mapping

__all__ = ["parse_tle", "tle_norad", "tle_cospar", "parse_omm", "omm_norad", "tle_checksum"]

_ALPHA5 = "ABCDEFGHJKLMNPQRSTUVWXYZ"  # Alpha-5 catalogue numbers skip I and O


def tle_checksum(line: str) -> int:
    """TLE checksum of the first 68 characters: digits count their value, '-' counts 1, mod 10."""
    return sum(int(c) if c.isdigit() else (1 if c == "-" else 0) for c in line[:68]) % 10


def parse_tle(lines: list[str]) -> tuple[str, ...]:
    """Check a TLE (optional title line, then lines 1 and 2) and return its lines.

    Parameters
    ----------
    lines : list of str
        Two or three lines without comment markers, e.g. ``["0 TOPEX/POSEIDON", "1 22076U ...", "2 22076 ..."]``.

    Returns
    -------
    tuple of str
        The lines with trailing whitespace removed.

    Raises
    ------
    ValueError
        Wrong line count, a line 1/2 not starting with its number, a length other than 69,
        a bad checksum, or lines 1 and 2 naming different satellites.
    """
    lines = [line.rstrip() for line in lines]
    if len(lines) not in (2, 3):
        raise ValueError(f"a TLE has 2 or 3 lines, found {len(lines)}")
    first, second = lines[-2], lines[-1]
    for number, line in (("1", first), ("2", second)):
        if not line.startswith(number + " "):
            raise ValueError(f"TLE line {number} should start with '{number} ', found {line[:10]!r}")
        if len(line) != 69:
            raise ValueError(f"TLE line {number} has {len(line)} characters instead of 69")
        if not line[68].isdigit() or int(line[68]) != tle_checksum(line):
            raise ValueError(
                f"TLE line {number} has checksum {line[68]!r} but its characters give {tle_checksum(line)}; "
                "the elements are corrupted"
            )
    if first[2:7] != second[2:7]:
        raise ValueError(f"TLE lines 1 and 2 name different satellites ({first[2:7]!r} and {second[2:7]!r})")
    return tuple(lines)


def tle_norad(tle: tuple[str, ...]) -> int:
    """NORAD number of a TLE (Alpha-5 numbers such as ``A0001`` = 100001 included)."""
    field = tle[-2][2:7].strip()
    if field and field[0].isalpha():
        return (_ALPHA5.index(field[0].upper()) + 10) * 10000 + int(field[1:])
    return int(field)


def tle_cospar(tle: tuple[str, ...]) -> str:
    """International designator of a TLE in ccd_phot's short form (``92052A``)."""
    return tle[-2][9:17].strip()


def parse_omm(text: str) -> Mapping:
    """Parse an OMM record written as one JSON object (CCSDS OMM keywords, e.g. Space-Track's).

    Returns
    -------
    mapping
        A read-only view of the record.

    Raises
    ------
    ValueError
        Not JSON, not an object, or no NORAD_CAT_ID.
    """
    try:
        record = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"the OMM record is not valid JSON ({exc.msg} at character {exc.pos + 1})") from None
    if isinstance(record, list) and len(record) == 1:
        record = record[0]
    if not isinstance(record, dict):
        raise ValueError("the OMM record must be one JSON object with CCSDS OMM keywords")
    if "NORAD_CAT_ID" not in record:
        raise ValueError("the OMM record has no NORAD_CAT_ID")
    omm_norad(record)
    return MappingProxyType(record)


def omm_norad(record: Mapping) -> int:
    """NORAD number of an OMM record."""
    value = record["NORAD_CAT_ID"]
    try:
        return int(value)
    except (TypeError, ValueError):
        raise ValueError(f"the OMM NORAD_CAT_ID {value!r} is not an integer") from None
