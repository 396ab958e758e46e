"""Which stored pass a newly read pass is: a duplicate, a new version, or a pass of its own.

The rule (docs/archive.md, "Pass ids and versions"), applied in order to each pass of a new file:

1. Its rows are all in a current stored pass of the same object and site (any band: a changed
   filter letter does not make new data): it is a **duplicate source** of that pass, recorded
   with the file's name and hash, and nothing is superseded. A header that disagrees with the
   stored pass (band, name) is noted as a warning.
2. It has the same band and site as a current stored pass and either the same start second,
   or the same file name with overlapping times, or all of that pass's rows and more: it is the
   next **version** of that pass and supersedes it (the older version stays, ``--all-versions``).
3. Otherwise it is a new pass.

Rows match when their times agree to `TIME_MATCH_NS` (a ccd_phot UT file and its JD re-export
differ by the JD's 40 us resolution) and their magnitudes and fluxes agree to the last digit the
files print.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ingest.observation import Pass
from rsodb.archive import layout
from rsodb.archive.stored import PassSummary

__all__ = ["Placement", "place", "rows_within", "TIME_MATCH_NS", "MAG_MATCH", "FLUX_MATCH"]

# Half a millisecond: below the ccd_phot UT variant's 1 ms, above the JD variant's 40 us.
TIME_MATCH_NS = 500_000
# Files print magnitudes to 0.001 and CSV exports to 0.0001: values that agree to 0.0001 are equal.
MAG_MATCH = 1e-4
FLUX_MATCH = 1e-4


@dataclass(frozen=True)
class Placement:
    """Where a new pass goes.

    Attributes
    ----------
    duplicate_of : PassSummary or None
        The stored pass that already holds every row (rule 1); nothing is written.
    note : str
        For a duplicate: what its header says differently, or "".
    metadata : dict or None
        For a pass to store: its metadata (id, version, supersedes, ...).
    rows : list of PassSummary
        The catalog after this pass is added (unchanged for a duplicate).
    """

    duplicate_of: PassSummary | None
    note: str
    metadata: dict | None
    rows: list[PassSummary]


def rows_within(pass_: Pass, stored: np.ndarray) -> bool:
    """True when every sample of `pass_` is a sample of the stored table `stored`.

    Parameters
    ----------
    pass_ : Pass
    stored : (m,) structured array
        A stored pass's samples table (``time_utc`` int64 ns, ``mag``, ``flux``).
    """
    t_stored = stored["time_utc"]
    if len(t_stored) == 0 or len(pass_) > len(t_stored):
        return False
    t_new = pass_.time_utc.view(np.int64)
    right = np.clip(np.searchsorted(t_stored, t_new), 0, len(t_stored) - 1)
    left = np.clip(right - 1, 0, len(t_stored) - 1)
    nearest = np.where(np.abs(t_stored[left] - t_new) < np.abs(t_stored[right] - t_new), left, right)
    if np.any(np.abs(t_stored[nearest] - t_new) > TIME_MATCH_NS):
        return False
    return _agree(pass_.mag, stored["mag"][nearest], MAG_MATCH) and _agree(
        pass_.flux, stored["flux"][nearest], FLUX_MATCH
    )


def _agree(a: np.ndarray, b: np.ndarray, tolerance: float) -> bool:
    both_nan = np.isnan(a) & np.isnan(b)
    with np.errstate(invalid="ignore"):
        close = np.abs(a - b) <= tolerance * np.maximum(1.0, np.abs(b) * 1e-3)
    return bool(np.all(both_nan | close))


def place(pass_: Pass, rows: list[PassSummary], samples_of: Callable[[str], np.ndarray], now: str) -> Placement:
    """Apply the rule above to `pass_` against the current catalog `rows`.

    Parameters
    ----------
    pass_ : Pass
    rows : list of PassSummary
        Every stored version of the object, including passes placed earlier in the same commit.
    samples_of : callable
        ``samples_of(pass_id)`` gives a stored (or just placed) pass's samples table.
    now : str
        The commit's time, ISO 8601 UTC.
    """
    start, end = pass_.start_utc, pass_.end_utc
    site = pass_.site.name
    overlapping = [
        row for row in rows if row.is_current and row.site == site and row.start_utc <= end and start <= row.end_utc
    ]
    # Same band first: a B pass of a .phc copy is checked against the stored B pass.
    overlapping.sort(key=lambda row: row.band != pass_.band)
    for row in overlapping:
        if rows_within(pass_, samples_of(row.pass_id)):
            return Placement(row, _differences(pass_, row), None, rows)

    natural = layout.natural_pass_id(pass_)

    def same_pass(row: PassSummary) -> bool:
        if row.band != pass_.band or row.site != site or not row.is_current:
            return False
        if row.natural_id == natural or row.lineage_id == natural:
            return True  # same object, start second, band and site: the same observation
        overlaps = row.start_utc <= end and start <= row.end_utc
        if not overlaps:
            return False
        if pass_.source_name and row.source_name == pass_.source_name:
            return True  # the same file, changed
        return row.n_points < len(pass_) and _contains(pass_, samples_of(row.pass_id))

    current = [row for row in rows if same_pass(row)]
    # Prefer the lineage named by this pass's own start, then the most recently stored one.
    current.sort(key=lambda row: (row.natural_id == natural or row.lineage_id == natural, row.ingested_utc))
    if current:
        previous = current[-1]
        lineage = previous.lineage_id
        version = 1 + max(row.version for row in rows if row.lineage_id == lineage)
        supersedes = previous.pass_id
    else:
        lineage, version, supersedes = natural, 1, None
        taken = {row.pass_id for row in rows}
        while layout.versioned_pass_id(lineage, version) in taken:  # another pass with the same id
            version += 1
    pass_id = layout.versioned_pass_id(lineage, version)
    metadata = layout.pass_metadata(
        pass_,
        pass_id=pass_id,
        lineage_id=lineage,
        natural_id=natural,
        version=version,
        supersedes=supersedes,
        ingested_utc=now,
    )
    updated = [replace(row, superseded_by=pass_id) if row.pass_id == supersedes else row for row in rows]
    return Placement(None, "", metadata, updated + [layout.summary_row(pass_, metadata)])


def _contains(new: Pass, stored: np.ndarray) -> bool:
    """True when every stored sample is a sample of `new` (the new file is the fuller copy)."""
    t_new = new.time_utc.view(np.int64)
    t_stored = stored["time_utc"]
    right = np.clip(np.searchsorted(t_new, t_stored), 0, len(t_new) - 1)
    left = np.clip(right - 1, 0, len(t_new) - 1)
    nearest = np.where(np.abs(t_new[left] - t_stored) < np.abs(t_new[right] - t_stored), left, right)
    if np.any(np.abs(t_new[nearest] - t_stored) > TIME_MATCH_NS):
        return False
    return _agree(stored["mag"], new.mag[nearest], MAG_MATCH) and _agree(stored["flux"], new.flux[nearest], FLUX_MATCH)


def _differences(pass_: Pass, row: PassSummary) -> str:
    """What the new file's header says differently from the stored pass it duplicates."""
    notes = []
    if pass_.band != row.band:
        notes.append(f"its header says band {pass_.band} but its rows are those of the band {row.band} pass")
    if pass_.name and row.name and pass_.name != row.name:
        notes.append(f"its header names the object {pass_.name!r}, the stored pass {row.name!r}")
    if len(pass_) < row.n_points:
        notes.append(f"it holds {len(pass_)} of the stored pass's {row.n_points} rows")
    return "; ".join(notes)
