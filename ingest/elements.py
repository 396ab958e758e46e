"""Orbital elements: a TLE block or an OMM JSON record in observation headers, and catalogues.

Readers hand the raw header lines here; problems come back as `ValueError` with one sentence,
which the reader turns into a `FormatError` at the right line. An `ElementCatalogue` (a TLE file
of many sets, or a JSON list of OMM records as CelesTrak and Space-Track give them) supplies
elements to passes whose files carry none: the set of the pass's object whose epoch is nearest
the pass, refused beyond `DEFAULT_MAX_AGE_DAYS` (docs/archive.md, "Orbital elements").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
import hashlib
import json
from pathlib import Path
from types import MappingProxyType

import numpy as np

from ingest.textfile import open_regular_file
from ingest.times import NS_PER_DAY, parse_datetime

__all__ = [
    "parse_tle",
    "tle_norad",
    "tle_cospar",
    "parse_omm",
    "omm_norad",
    "tle_checksum",
    "read_tle_catalogue",
    "check_norad",
    "tle_epoch_utc",
    "omm_epoch_utc",
    "ElementSet",
    "ElementCatalogue",
    "MAX_NORAD",
    "DEFAULT_MAX_AGE_DAYS",
]

# The oldest element set given to a pass, in days between its epoch and the pass. SGP4 errors
# grow by roughly 1-3 km a day in low orbits: after 30 days the satellite is tens of km, about a
# degree seen from the ground, from where the set puts it. (A 39-day-old set of COSMOS 2553
# reproduces the Az/El columns of the real .phc file to 0.2 deg: tests/test_archive_elements.py.)
DEFAULT_MAX_AGE_DAYS = 30.0

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
    head = line[:68]  # counted digit by digit in C: this runs for every element line read
    return (sum(digit * head.count(str(digit)) for digit in range(1, 10)) + head.count("-")) % 10


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
    return [tle for tle, _ in _tle_sets(path, Path(path).read_text())]


def tle_epoch_utc(tle: Sequence[str]) -> np.datetime64:
    """The epoch of a TLE (line 1, columns 19-32: two-digit year and day of year) as datetime64[ns].

    Years 57-99 are 1957-1999, 00-56 are 2000-2056, as the format defines.

    >>> tle_epoch_utc(["1 22076U 92052A   24212.51246405 -.00000054  00000-0  29042-4 0  9994", "2 22076"])
    numpy.datetime64('2024-07-30T12:17:56.893920000')
    """
    field = tle[-2][18:32].strip()
    whole, _, fraction = field.partition(".")
    if len(whole) != 5 or not whole.isdigit() or not (fraction.isdigit() or not fraction):
        raise ValueError(f"TLE line 1 has no epoch in columns 19-32 (found {field!r})")
    year = int(whole[:2])
    year += 1900 if year >= 57 else 2000
    day_of_year = int(whole[2:])
    if not 1 <= day_of_year <= 366:
        raise ValueError(f"TLE epoch {field!r} has day of year {day_of_year}, outside 1..366")
    fraction_ns = int(fraction) * NS_PER_DAY // 10 ** len(fraction) if fraction else 0
    start = np.datetime64(f"{year}-01-01", "ns")
    return start + np.timedelta64((day_of_year - 1) * NS_PER_DAY + fraction_ns, "ns")


def omm_epoch_utc(record: Mapping) -> np.datetime64:
    """The ``EPOCH`` of an OMM record (ISO 8601, UTC) as datetime64[ns]."""
    epoch = parse_datetime(str(record.get("EPOCH", "")))
    if epoch is None:
        raise ValueError(f"the OMM record's EPOCH {record.get('EPOCH')!r} is not an ISO 8601 UTC time")
    return epoch


@dataclass(frozen=True)
class ElementSet:
    """One element set of a catalogue.

    Attributes
    ----------
    norad : int
    epoch_utc : numpy.datetime64
    tle : tuple of str or None
        The set's lines, when it is a TLE.
    omm : mapping or None
        The record, when it is an OMM.
    where : str
        Where it is in its catalogue: ``line N`` or ``record N``.
    """

    norad: int
    epoch_utc: np.datetime64
    tle: tuple[str, ...] | None = None
    omm: Mapping | None = None
    where: str = ""

    def age_days(self, time_utc: np.datetime64) -> float:
        """Days between the epoch and `time_utc` (always >= 0)."""
        return abs(float((np.datetime64(time_utc, "ns") - self.epoch_utc) / np.timedelta64(1, "s"))) / 86400.0


class ElementCatalogue:
    """Element sets of many objects, read from a TLE file or a JSON list of OMM records.

    Parameters
    ----------
    sets : sequence of ElementSet
    name : str
        The catalogue's file name (for provenance and messages).
    sha256 : str
        SHA-256 of its bytes.

    Examples
    --------
    >>> catalogue = ElementCatalogue.from_file("tles.txt")                 # doctest: +SKIP
    >>> catalogue.nearest(22076, np.datetime64("2024-07-30T21:22"))        # doctest: +SKIP
    """

    def __init__(self, sets: Sequence[ElementSet], name: str = "", sha256: str = ""):
        self.name = name
        self.sha256 = sha256
        self._by_norad: dict[int, list[ElementSet]] = {}
        for element_set in sets:
            self._by_norad.setdefault(element_set.norad, []).append(element_set)
        for group in self._by_norad.values():
            group.sort(key=lambda item: item.epoch_utc)

    def __len__(self) -> int:
        return sum(len(group) for group in self._by_norad.values())

    def __repr__(self) -> str:
        return f"ElementCatalogue({self.name!r}, {len(self)} sets of {len(self._by_norad)} objects)"

    @property
    def norads(self) -> list[int]:
        """The objects with at least one set, sorted."""
        return sorted(self._by_norad)

    @classmethod
    def from_file(cls, path) -> ElementCatalogue:
        """Read a TLE file (2- or 3-line sets) or OMM records in JSON (a list, one object, or one
        object per line).

        Raises
        ------
        ValueError
            One sentence naming the file (and line or record) when it holds no usable set.
        OSError
            When it cannot be read.
        """
        with open_regular_file(path) as stream:
            data = stream.read()
        name = Path(path).name
        sha256 = hashlib.sha256(data).hexdigest()
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise ValueError(f"{path}: byte {exc.start} is not UTF-8 text; give a TLE or OMM JSON file") from None
        if text.lstrip()[:1] in ("[", "{"):
            sets = _omm_sets(path, text)
        else:
            sets = [
                ElementSet(tle_norad(tle), tle_epoch_utc(tle), tle=tle, where=f"line {line}")
                for tle, line in _tle_sets(path, text)
            ]
        return cls(sets, name, sha256)

    def nearest(self, norad: int, time_utc: np.datetime64) -> ElementSet | None:
        """The set of `norad` whose epoch is nearest `time_utc`, or None when the object has none."""
        group = self._by_norad.get(int(norad))
        if not group:
            return None
        target = np.datetime64(time_utc, "ns")
        return min(group, key=lambda item: abs(int((item.epoch_utc - target).astype(np.int64))))

    def elements_for(
        self, norad: int, time_utc: np.datetime64, max_age_days: float = DEFAULT_MAX_AGE_DAYS
    ) -> tuple[ElementSet | None, str]:
        """The set to give a pass of `norad` at `time_utc`, or None and the reason there is none.

        Returns
        -------
        element_set : ElementSet or None
        reason : str
            Empty when a set was found; otherwise one sentence saying why not and what to do.
        """
        if not max_age_days > 0:
            raise ValueError(f"max_age_days={max_age_days!r} must be a positive number of days")
        chosen = self.nearest(norad, time_utc)
        if chosen is None:
            return None, f"{self.name} holds no element set of NORAD {norad}, so the pass has no orbit"
        age = chosen.age_days(time_utc)
        if age > max_age_days:
            return None, (
                f"the nearest element set of NORAD {norad} in {self.name} ({chosen.where}, epoch "
                f"{np.datetime_as_string(chosen.epoch_utc, unit='s')}) is {age:.1f} days from the pass, more than "
                f"the {max_age_days:g} allowed: give a nearer set, or raise --max-age-days to accept it"
            )
        return chosen, ""

    def provenance(self, element_set: ElementSet, time_utc: np.datetime64) -> dict:
        """What a pass records about elements taken from this catalogue."""
        return {
            "source": "catalogue",
            "file": self.name,
            "sha256": self.sha256,
            "where": element_set.where,
            "epoch_utc": np.datetime_as_string(element_set.epoch_utc, unit="us") + "Z",
            "age_days": round(element_set.age_days(time_utc), 4),
        }


def _tle_sets(path, text: str) -> list[tuple[tuple[str, ...], int]]:
    """(lines, line number of line 1) of every set in TLE text."""
    lines = [
        (number, line.rstrip())
        for number, line in enumerate(text.splitlines(), 1)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    sets = []
    for index, (number, line) in enumerate(lines):
        if line.startswith("1 ") and index + 1 < len(lines) and lines[index + 1][1].startswith("2 "):
            before = lines[index - 1][1] if index > 0 else ""
            title = [before] if before and before[:2] not in ("1 ", "2 ") else []
            try:
                tle = parse_tle(title + [line, lines[index + 1][1]])
                tle_epoch_utc(tle)
            except ValueError as error:
                raise ValueError(f"{path}:{number}: {error}") from None
            sets.append((tle, number))
    if not sets:
        raise ValueError(f"{path} holds no TLE (pairs of lines starting '1 ' and '2 '); give a TLE file")
    return sets


def _omm_sets(path, text: str) -> list[ElementSet]:
    try:
        records = json.loads(text)
    except json.JSONDecodeError:
        try:  # one JSON object per line
            records = [json.loads(line) for line in text.splitlines() if line.strip()]
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not valid JSON ({exc.msg}); give OMM records as a JSON list") from None
    if isinstance(records, dict):
        records = [records]
    if not isinstance(records, list) or not records:
        raise ValueError(f"{path} holds no OMM record; give a JSON list of OMM objects")
    sets = []
    for k, record in enumerate(records, 1):
        try:
            checked = parse_omm(json.dumps(record))
            sets.append(ElementSet(omm_norad(checked), omm_epoch_utc(checked), omm=checked, where=f"record {k}"))
        except ValueError as error:
            raise ValueError(f"{path}: record {k}: {error}") from None
    return sets
