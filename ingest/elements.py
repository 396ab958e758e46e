"""Orbital elements carried in observation headers: a TLE block or an OMM JSON record.

Readers hand the raw header lines here; problems come back as `ValueError` with one sentence,
which the reader turns into a `FormatError` at the right line.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
import json
from pathlib import Path
from types import MappingProxyType

__all__ = [
    "parse_tle",
    "tle_norad",
    "tle_cospar",
    "parse_omm",
    "omm_norad",
    "tle_checksum",
    "read_tle_catalogue",
    "check_norad",
    "MAX_NORAD",
]

# The largest catalogue number: OMM's NORAD_CAT_ID has nine digits (TLEs five, Alpha-5 six).
MAX_NORAD = 999_999_999
_ALPHA5 = "ABCDEFGHJKLMNPQRSTUVWXYZ"  # Alpha-5 catalogue numbers skip I and O
_TLE_LINE_LENGTH = 69


def tle_checksum(line: str) -> int:
    """The modulo-10 checksum of a TLE line's first 68 characters.

    Digits count their value, ``-`` counts 1, everything else (letters, blanks, ``.``, ``+``)
    counts 0.

    Examples
    --------
    >>> tle_checksum("1 22076U 92052A   24212.51246405 -.00000054  00000-0  29042-4 0  999")
    4
    """
    return sum(int(c) if c.isdigit() else (1 if c == "-" else 0) for c in line[:68]) % 10


def parse_tle(lines: str | Sequence[str]) -> tuple[str, ...]:
    """Check a TLE (optional title line, then lines 1 and 2) and return its lines.

    The one check of element lines in the project: readers, `raycast.geometry.orbit.Satellite`
    and TLE catalogues all call it. Accepts the variant some producers write, with ``+`` signs
    and zero-padded fields (``+00000-0``, ``066.0418``); the checksum must be valid.

    Parameters
    ----------
    lines : str or sequence of str
        Two or three lines (``["0 TOPEX/POSEIDON", "1 22076U ...", "2 22076 ..."]``), or one
        newline-separated string; blank lines are ignored.

    Returns
    -------
    tuple of str
        The lines, stripped (the title line first when there is one).

    Raises
    ------
    TypeError
        When the lines are not text.
    ValueError
        Wrong line count, a line 1/2 not starting with its number, a length other than 69,
        a bad checksum, or lines 1 and 2 naming different satellites.
    """
    if isinstance(lines, str):
        lines = lines.splitlines()
    if not isinstance(lines, Sequence) or not all(isinstance(s, str) for s in lines):
        raise TypeError(f"TLE lines must be strings, got {lines!r}; pass two or three lines of text")
    lines = [s.strip() for s in lines if s.strip()]
    if len(lines) not in (2, 3):
        raise ValueError(f"a TLE has 2 or 3 lines but {len(lines)} were given: {lines!r}")
    first, second = lines[-2], lines[-1]
    for number, line in ((1, first), (2, second)):
        if not line.startswith(f"{number} "):
            raise ValueError(f"TLE line {number} must start with '{number} ', got {line!r}")
        if len(line) != _TLE_LINE_LENGTH:
            raise ValueError(
                f"TLE line {number} has {len(line)} characters instead of 69: {line!r}; check that it was copied whole"
            )
        if not line[68].isdigit() or tle_checksum(line) != int(line[68]):
            raise ValueError(
                f"TLE line {number} checksum is {tle_checksum(line)} but the line ends in "
                f"{line[68]!r}: {line!r}; check that it was copied without changes"
            )
    if first[2:7] != second[2:7]:
        raise ValueError(
            f"TLE lines disagree on the catalogue number ({first[2:7]!r} vs {second[2:7]!r}); "
            "give both lines of the same element set"
        )
    return tuple(lines)


def check_norad(value) -> int:
    """A NORAD catalogue number from text or a number, checked to lie in 1..`MAX_NORAD`.

    Raises
    ------
    ValueError
        One sentence quoting the value (callers prefix the field's name).

    >>> check_norad(" 22076 ")
    22076
    """
    text = str(value).strip()
    if not text.isdigit() or not 0 < int(text) <= MAX_NORAD:
        raise ValueError(f"{text[:40]!r} is not a catalogue number (1..{MAX_NORAD})")
    return int(text)


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
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        raise ValueError(f"the OMM NORAD_CAT_ID {value!r} is not an integer")
    try:
        return check_norad(value)
    except ValueError as exc:
        raise ValueError(f"the OMM NORAD_CAT_ID {exc}") from None


def read_tle_catalogue(path) -> list[tuple[str, ...]]:
    """Every element set in a TLE file (a ``tles.txt``-style list of 2- or 3-line sets).

    Title lines (``0 NAME`` or ``NAME``) are kept with their set; ``#`` lines and blank lines are
    skipped. Each set is checked by `parse_tle`.

    Raises
    ------
    ValueError
        When the file holds no set, or a set fails its checks (the message names the line).
    """
    lines = [
        (number, line.rstrip())
        for number, line in enumerate(Path(path).read_text().splitlines(), 1)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    sets = []
    for index, (number, line) in enumerate(lines):
        if line.startswith("1 ") and index + 1 < len(lines) and lines[index + 1][1].startswith("2 "):
            before = lines[index - 1][1] if index > 0 else ""
            title = [before] if before and before[:2] not in ("1 ", "2 ") else []
            try:
                sets.append(parse_tle(title + [line, lines[index + 1][1]]))
            except ValueError as error:
                raise ValueError(f"{path}:{number}: {error}") from None
    if not sets:
        raise ValueError(f"{path} holds no TLE (pairs of lines starting '1 ' and '2 '); give a TLE file")
    return sets
