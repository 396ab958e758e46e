"""Earth satellites from two-line element sets (TLE) or CCSDS OMM records, propagated with SGP4.

`Satellite` holds one element set and propagates it with the vectorised C SGP4 of the
``sgp4`` package (the library skyfield itself uses), returning positions in the TEME frame
SGP4 works in. `raycast.geometry` rotates those into GCRS and ITRS.

Examples
--------
>>> from raycast.geometry.orbit import Satellite
>>> sat = Satellite.from_tle([
...     "1 22076U 92052A   24212.51246405 -.00000054  00000-0  29042-4 0  9994",
...     "2 22076  66.0414 118.8147 0008045 267.5347 265.0431 12.81066660495523"])
>>> sat.norad, str(sat.epoch_utc)
(22076, '2024-07-30T12:17:56.893920')
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
import math

import numpy as np
from sgp4.api import SGP4_ERRORS, WGS72, Satrec
from skyfield.sgp4lib import EarthSatellite

from ingest.elements import parse_tle, read_tle_catalogue
from raycast.geometry.ephemeris import timescale

__all__ = ["Satellite"]

_UNIX_EPOCH_JD = 2440587.5
_SGP4_EPOCH0 = np.datetime64("1949-12-31T00:00:00", "us")  # sgp4init counts days from here
_OMM_REQUIRED = (
    "EPOCH",
    "MEAN_MOTION",
    "ECCENTRICITY",
    "INCLINATION",
    "RA_OF_ASC_NODE",
    "ARG_OF_PERICENTER",
    "MEAN_ANOMALY",
    "NORAD_CAT_ID",
    "BSTAR",
)


@dataclass(frozen=True, eq=False)
class Satellite:
    """One element set of one object, ready to propagate.

    Build it with `from_tle` or `from_omm`; it is immutable.

    Attributes
    ----------
    name : str
        Object name (the TLE title line, the OMM ``OBJECT_NAME``, or ``"NORAD <n>"``).
    norad : int
        NORAD catalogue number.
    epoch_utc : numpy.datetime64
        Epoch of the elements, UTC, microsecond resolution.
    tle : tuple of str or None
        The two element lines when built from a TLE.
    omm : mapping or None
        The OMM record when built from one.
    """

    name: str
    norad: int
    epoch_utc: np.datetime64
    tle: tuple[str, str] | None
    omm: Mapping | None
    _satrec: object = field(repr=False)

    # -- constructors --------------------------------------------------------------------
    @classmethod
    def from_tle(cls, lines: str | Sequence[str], name: str | None = None) -> Satellite:
        """Build a satellite from a two- or three-line element set.

        Accepts the variant some producers write, with ``+`` signs and zero-padded fields
        (``+00000-0``, ``066.0418``); the checksum must be valid.

        Parameters
        ----------
        lines : str or sequence of str
            Two element lines, optionally preceded by a title line (``"0 NAME"`` or
            ``"NAME"``), as a sequence or as one newline-separated string.
        name : str, optional
            Overrides the title line.

        Returns
        -------
        Satellite

        Raises
        ------
        ValueError
            When the lines are not a valid TLE (count, line numbers, length, checksum,
            catalogue numbers, elements SGP4 rejects).
        """
        lines = parse_tle(lines)
        title = lines[0] if len(lines) == 3 else None
        line1, line2 = lines[-2:]
        satrec = Satrec.twoline2rv(line1, line2, WGS72)
        _check_satrec(satrec, f"TLE {line1[2:7]!r}")
        if name is None:
            if title:
                name = title[2:].strip() if title.startswith("0 ") else title
            else:
                name = f"NORAD {satrec.satnum}"
        return cls(name, int(satrec.satnum), _satrec_epoch(satrec), (line1, line2), None, satrec)

    @classmethod
    def from_omm(cls, record: Mapping) -> Satellite:
        """Build a satellite from a CCSDS OMM record as Space-Track and CelesTrak publish it.

        Parameters
        ----------
        record : mapping
            One OMM object in the JSON layout (keys such as ``EPOCH``, ``MEAN_MOTION``,
            ``ECCENTRICITY``, ``INCLINATION``, ``RA_OF_ASC_NODE``, ``ARG_OF_PERICENTER``,
            ``MEAN_ANOMALY``, ``BSTAR``, ``MEAN_MOTION_DOT``, ``MEAN_MOTION_DDOT``,
            ``NORAD_CAT_ID``). Values may be numbers (CelesTrak) or strings (Space-Track).
            Angles in degrees, mean motion in revolutions per day.

        Returns
        -------
        Satellite

        Raises
        ------
        ValueError
            When a required key is missing, a value is not a number, or SGP4 rejects the
            elements.
        """
        if not isinstance(record, Mapping):
            raise TypeError(f"an OMM record must be a mapping (a JSON object), got {type(record).__name__}")
        missing = [key for key in _OMM_REQUIRED if key not in record]
        if missing:
            raise ValueError(
                f"OMM record lacks {', '.join(missing)}; give a full OMM object as CelesTrak or Space-Track publish it"
            )

        def number(key, default=0.0):
            value = record.get(key, default)
            try:
                return float(value)
            except (TypeError, ValueError):
                raise ValueError(f"OMM field {key}={value!r} is not a number; fix the record") from None

        epoch_text = str(record["EPOCH"]).strip().rstrip("Z")
        try:
            epoch = np.datetime64(epoch_text, "us")
        except ValueError:
            raise ValueError(
                f"OMM EPOCH={record['EPOCH']!r} is not an ISO 8601 time; write e.g. 2024-07-30T12:17:56.893920"
            ) from None
        norad = int(number("NORAD_CAT_ID"))
        deg = math.pi / 180.0
        # Units as in sgp4's own OMM reader and TLE parser: rev/day, rev/day^2, rev/day^3
        # to radians per minute (and per minute^2, ^3).
        rev_per_day = 2.0 * math.pi / 1440.0
        satrec = Satrec()
        satrec.sgp4init(
            WGS72,
            "i",
            norad,
            float((epoch - _SGP4_EPOCH0) / np.timedelta64(1, "us")) / 86400e6,
            number("BSTAR"),
            number("MEAN_MOTION_DOT") * rev_per_day / 1440.0,
            number("MEAN_MOTION_DDOT") * rev_per_day / 1440.0**2,
            number("ECCENTRICITY"),
            number("ARG_OF_PERICENTER") * deg,
            number("INCLINATION") * deg,
            number("MEAN_ANOMALY") * deg,
            number("MEAN_MOTION") * rev_per_day,
            number("RA_OF_ASC_NODE") * deg,
        )
        _check_satrec(satrec, f"OMM of NORAD {norad}")
        name = str(record.get("OBJECT_NAME") or f"NORAD {norad}")
        return cls(name, norad, epoch, None, dict(record), satrec)

    @classmethod
    def from_catalogue(cls, path, norad: int | None = None, near_utc=None) -> Satellite:
        """The element set of ``norad`` in a TLE file whose epoch is nearest ``near_utc``.

        Parameters
        ----------
        path : path
            A TLE file of 2- or 3-line sets (`ingest.elements.read_tle_catalogue`).
        norad : int, optional
            The object; without it the file must hold a single object.
        near_utc : numpy.datetime64, optional
            Time the elements should be nearest to (default: the last set of the object).
        """
        sets = [cls.from_tle(lines) for lines in read_tle_catalogue(path)]
        numbers = sorted({sat.norad for sat in sets})
        if norad is None and len(numbers) > 1:
            raise ValueError(
                f"{path} holds element sets of {len(numbers)} objects "
                f"({', '.join(map(str, numbers[:5]))}{', ...' if len(numbers) > 5 else ''}); "
                "pick one with --norad"
            )
        chosen = [sat for sat in sets if norad is None or sat.norad == norad]
        if not chosen:
            raise ValueError(
                f"{path} holds no element set of NORAD {norad}; its objects are {', '.join(map(str, numbers[:10]))}"
            )
        if near_utc is None:
            return chosen[-1]
        gap = [abs((sat.epoch_utc - np.datetime64(near_utc, "us")) / np.timedelta64(1, "s")) for sat in chosen]
        return chosen[int(np.argmin(gap))]

    # -- propagation ---------------------------------------------------------------------
    def teme_km(self, jd_utc_whole: np.ndarray, jd_utc_fraction: np.ndarray):
        """Propagate to many times at once with SGP4.

        Parameters
        ----------
        jd_utc_whole, jd_utc_fraction : (n,) float
            UTC Julian date split into two parts (their sum is the date), as SGP4 expects.

        Returns
        -------
        position_km : (n, 3) float
            TEME position, km.
        velocity_km_s : (n, 3) float
            TEME velocity, km/s.
        error : (n,) int
            SGP4 error code per time, 0 when the propagation succeeded (see
            ``sgp4.api.SGP4_ERRORS``).
        """
        error, position_km, velocity_km_s = self._satrec.sgp4_array(
            np.ascontiguousarray(jd_utc_whole, dtype=float),
            np.ascontiguousarray(jd_utc_fraction, dtype=float),
        )
        return position_km, velocity_km_s, error

    @property
    def satrec(self):
        """The underlying ``sgp4.api.Satrec`` (do not modify it)."""
        return self._satrec

    def to_skyfield(self):
        """The same element set as a skyfield ``EarthSatellite`` (for comparisons).

        Returns
        -------
        skyfield.sgp4lib.EarthSatellite
        """
        return EarthSatellite.from_satrec(self._satrec, timescale())


def _check_satrec(satrec, what: str) -> None:
    """Raise when SGP4 could not initialise the elements."""
    if satrec.error:
        raise ValueError(f"{what} was rejected by SGP4: {SGP4_ERRORS[satrec.error]}; check the elements")
    if not (satrec.no_kozai > 0 and 0.0 <= satrec.ecco < 1.0):
        raise ValueError(
            f"{what} has mean motion {satrec.no_kozai!r} rad/min and eccentricity {satrec.ecco!r}; "
            "an Earth orbit needs a positive mean motion and eccentricity in [0, 1)"
        )


def _satrec_epoch(satrec) -> np.datetime64:
    """Element epoch of a Satrec as datetime64[us] UTC."""
    days = (satrec.jdsatepoch - _UNIX_EPOCH_JD) + satrec.jdsatepochF
    return np.datetime64(0, "us") + np.timedelta64(int(round(days * 86400e6)), "us")
