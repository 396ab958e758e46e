"""What the archive hands back: stored passes, their one-line summaries, and objects."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ingest.observation import Pass

__all__ = [
    "utc_text",
    "StoredPass",
    "PassSummary",
    "ArchivedObject",
    "ResultSummary",
    "DuplicateSource",
    "DamagedObject",
]


@dataclass(frozen=True, eq=False)
class StoredPass(Pass):
    """A `Pass` read back from the archive, with its identity in the archive.

    Attributes
    ----------
    pass_id : str
        Stable, human-readable id: ``NORAD-YYYYmmddTHHMMSS-BAND-site`` (start of the first version,
        UTC), plus ``-vN`` for version N >= 2.
    version : int
        1 for the first file seen for this pass; a changed file for the same pass adds a version.
    supersedes : str or None
        The pass id this version replaced.
    superseded_by : str or None
        The newer version's pass id; None while this is the current version.
    ingested_utc : str
        ISO 8601 UTC time at which this version was committed.
    """

    pass_id: str = ""
    version: int = 1
    supersedes: str | None = None
    superseded_by: str | None = None
    ingested_utc: str = ""

    @property
    def is_current(self) -> bool:
        """True unless a newer version of this pass is stored."""
        return self.superseded_by is None

    def lightcurve(self):
        """This pass as a `rsodb.periods.LightCurve`."""
        # The period search loads astropy and scipy.stats (about a second); the archive commands
        # that need no light curve start without them.
        from rsodb.periods.lightcurve import LightCurve

        return LightCurve.from_pass(self)

    def detrend(self):
        """The light curve with the pass trend (range, phase angle) removed."""
        return self.lightcurve().detrend()

    def __repr__(self) -> str:
        return (
            f"StoredPass({self.pass_id!r}, norad={self.norad}, band={self.band!r}, "
            f"site={self.site.name!r}, start={str(self.start_utc)[:23]}, n={len(self)}, "
            f"version={self.version})"
        )


@dataclass(frozen=True)
class PassSummary:
    """One row of the archive's catalog: enough to list and select passes without their arrays.

    Attributes
    ----------
    pass_id, lineage_id : str
        This version's id and the id of the pass's first version.
    natural_id : str
        The id this version's own data gives (``NORAD-start-BAND-site``); differs from
        `lineage_id` when a changed file moved the start of the pass.
    version : int
    supersedes, superseded_by : str or None
    norad : int
    name, band, site : str
        Object name as written in the file, band letter, site name.
    start_utc, end_utc : numpy.datetime64
        First and last mid-exposure times (ns precision).
    n_points : int
    exposure_s : float
    source_name, source_sha256, source_format : str
    ingested_utc : str
    n_row_problems, n_warnings : int
        Rows the reader set aside, and warnings about the file's header.
    elements : str
        Where the pass's orbital elements come from: ``"header"`` (the file), ``"catalogue"``
        (added from a TLE/OMM catalogue) or ``""`` (none: the geometry is a track fitted to the
        file's Az/El/range columns, `raycast.geometry.track`, good within the pass only).
    period_s, period_err_s : float or None
        Spin period and its 1-sigma error from the stored period result the query named
        (``periods_name``, default "default"); None without one.
    verdict : str or None
        That result's verdict.
    """

    pass_id: str
    lineage_id: str
    natural_id: str
    version: int
    supersedes: str | None
    superseded_by: str | None
    norad: int
    name: str
    band: str
    site: str
    start_utc: np.datetime64
    end_utc: np.datetime64
    n_points: int
    exposure_s: float
    source_name: str
    source_sha256: str
    source_format: str
    ingested_utc: str
    n_row_problems: int = 0
    n_warnings: int = 0
    elements: str = ""
    period_s: float | None = None
    period_err_s: float | None = None
    verdict: str | None = None

    @property
    def duration_s(self) -> float:
        """Seconds between first and last sample."""
        return float((self.end_utc - self.start_utc) / np.timedelta64(1, "s"))

    @property
    def is_current(self) -> bool:
        """True unless a newer version of this pass is stored."""
        return self.superseded_by is None

    def to_dict(self) -> dict:
        """JSON-ready fields (times as ISO 8601 strings with a trailing Z)."""
        return {
            "pass_id": self.pass_id,
            "norad": self.norad,
            "name": self.name,
            "site": self.site,
            "band": self.band,
            "start_utc": _iso(self.start_utc),
            "end_utc": _iso(self.end_utc),
            "duration_s": round(self.duration_s, 6),
            "n_points": self.n_points,
            "exposure_s": self.exposure_s,
            "version": self.version,
            "lineage_id": self.lineage_id,
            "supersedes": self.supersedes,
            "superseded_by": self.superseded_by,
            "source_name": self.source_name,
            "source_sha256": self.source_sha256,
            "source_format": self.source_format,
            "ingested_utc": self.ingested_utc,
            "n_row_problems": self.n_row_problems,
            "n_warnings": self.n_warnings,
            "elements": self.elements,
            "period_s": self.period_s,
            "period_err_s": self.period_err_s,
            "verdict": self.verdict,
        }


@dataclass(frozen=True)
class ResultSummary:
    """One stored result as the catalog keeps it.

    Attributes
    ----------
    pass_id, kind, name : str
        Where it is stored: ``/passes/<pass_id>/<kind>/<name>``.
    stored_utc, result_type : str
    period_s, period_err_s : float or None
        The spin period it found (a period search's best period, a fit's spin period median).
    verdict : str or None
    """

    pass_id: str
    kind: str
    name: str
    stored_utc: str = ""
    result_type: str = ""
    period_s: float | None = None
    period_err_s: float | None = None
    verdict: str | None = None


@dataclass(frozen=True)
class DuplicateSource:
    """A file whose rows were all in a stored pass already, recorded instead of stored again.

    Attributes
    ----------
    sha256, source_name : str
        The file.
    pass_id : str
        The stored pass that holds its rows.
    ingested_utc : str
    note : str
        What differed (a header that disagrees with the stored pass), or "".
    """

    sha256: str
    source_name: str
    pass_id: str
    ingested_utc: str
    note: str = ""


@dataclass(frozen=True)
class DamagedObject:
    """An object file that cannot be read: its passes are left out of listings until repaired.

    Attributes
    ----------
    norad : int
    path : str
    reason : str
    """

    norad: int
    path: str
    reason: str


@dataclass(frozen=True)
class ArchivedObject:
    """One object (NORAD number) of the archive.

    Attributes
    ----------
    norad : int
    name, cospar : str
        As written by the most recently ingested file.
    n_passes : int
        Current passes (newest versions only).
    n_versions : int
        Stored pass versions, superseded ones included.
    bands : tuple of str
    first_utc, last_utc : numpy.datetime64
        Start of the earliest and of the latest current pass.
    """

    norad: int
    name: str
    cospar: str
    n_passes: int
    n_versions: int
    bands: tuple[str, ...]
    first_utc: np.datetime64
    last_utc: np.datetime64


def utc_text(t: np.datetime64, unit: str = "ms") -> str:
    """ISO text of a UTC time, rounded to the millisecond first and then cut to `unit`.

    The rounding is that of pass ids (`rsodb.archive.layout.natural_pass_id`): a Julian date
    stored as a float64 holds 01:07:14.000 as 01:07:13.9999952, which every display shows as
    01:07:14, never as the second before.

    >>> utc_text(np.datetime64("2021-06-26T01:07:13.9999952"), "s")
    '2021-06-26T01:07:14'
    """
    rounded = (np.datetime64(t, "ns") + np.timedelta64(500_000, "ns")).astype("datetime64[ms]")
    return np.datetime_as_string(rounded, unit=unit)


def _iso(t: np.datetime64) -> str:
    return utc_text(t) + "Z"
