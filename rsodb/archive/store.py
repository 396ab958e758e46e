"""`Archive`: the observation database, one crash-safe HDF5 file per object, and its catalog index.

Every write (new passes, a period or fit result, orbital elements) follows one protocol under the
object's lock: read the current object file, build its next state in a temporary file beside it,
flush, rename over the current file, flush the directory (`rsodb.archive.commits`). The rename is
the commit point. Readers open the current file read-only and see one consistent state; a killed
writer leaves at most a temporary file, removed the next time the object is written or the
archive is opened. Lookups go through the catalog index (`rsodb.archive.index`), which is checked
against the files and read again from them whenever it is stale.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import replace
import json
import os
from pathlib import Path
import re

import h5py
import numpy as np

from ingest.elements import DEFAULT_MAX_AGE_DAYS, ElementCatalogue
from ingest.observation import Pass
from rsodb.archive import layout
from rsodb.archive.commits import ObjectTransaction, stage_files, stage_metadata, stage_results, utc_now
from rsodb.archive.index import CatalogIndex, DamagedIndexError, ObjectState, PassQuery, StoredSources
from rsodb.archive.ingest_report import CommitEvent, IngestReport, PendingFile
from rsodb.archive.integrity import DamagedObjectError, check_result, open_object
from rsodb.archive.locking import ObjectLock, remove_abandoned_staging, replacing
from rsodb.archive.stored import ArchivedObject, DamagedObject, PassSummary, ResultSummary, StoredPass
from rsodb.storage import attr_text

__all__ = ["Archive", "UnknownPassError", "ElementsReport"]

_RESULT_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+=-]*$")
_TEMP_NAME = re.compile(r"^\.(\d+)\.h5\..*\.tmp$")
_OBJECT_NAME = re.compile(r"^(\d+)\.h5$")
_NORAD_PREFIX = re.compile(r"^(\d+)-")
_FILTERS = {"all_versions", "since", "until", "period_min", "period_max", "verdict", "periods_name"}
# Objects read into the index per transaction while it is rebuilt.
_INDEX_BATCH = 256


class UnknownPassError(LookupError):
    """No stored pass matches an id (or the prefix matches several)."""


class Archive:
    """An observation archive directory; opened, or created when missing.

    Parameters
    ----------
    path : str or path-like
        The archive directory. A missing or empty directory becomes a new archive; a non-empty
        directory must already be one.
    create : bool
        False refuses to create a new archive (for commands that only read).
    durable : bool
        fsync every commit (default). False keeps commits atomic for readers and killed
        processes but not across a power cut; it only saves time on slow disks.
    lock_timeout_s : float or None
        How long a writer waits for another writer of the same object before giving up.

    Examples
    --------
    >>> archive = Archive("archive")                                   # doctest: +SKIP
    >>> report = archive.ingest(["night1/", "night2/lc.phV"])          # doctest: +SKIP
    >>> archive.passes(norad=22076)[0].detrend().periodogram()         # doctest: +SKIP
    >>> archive.catalog(period_min=5, period_max=20)                   # doctest: +SKIP
    """

    def __init__(self, path, *, create: bool = True, durable: bool = True, lock_timeout_s: float | None = 600.0):
        self.path = Path(path)
        self.durable = durable
        self.lock_timeout_s = lock_timeout_s
        self._open_or_create(create)
        # Temporary files of writers still running when the archive was opened: a commit removes
        # those of its objects (ObjectTransaction.temp_names) without listing the directory again.
        self._temp_names: set[str] = set()
        if os.access(self.objects_dir, os.W_OK):
            self._temp_names = self._remove_stale_temp_files()
        self._index = CatalogIndex(self.path / layout.INDEX_NAME)

    def __repr__(self) -> str:
        return f"Archive({str(self.path)!r})"

    # -- directory ---------------------------------------------------------------------------
    @property
    def objects_dir(self) -> Path:
        """Directory of the per-object HDF5 files."""
        return self.path / layout.OBJECTS_DIR

    def object_path(self, norad: int) -> Path:
        """The HDF5 file of object `norad` (it may not exist yet)."""
        return self.objects_dir / layout.object_file_name(norad)

    def _open_or_create(self, create: bool) -> None:
        marker = self.path / layout.MARKER_NAME
        if self.path.exists() and not self.path.is_dir():
            raise ValueError(f"archive path {str(self.path)!r} is a file; give a directory (new or existing archive)")
        if marker.is_file():
            try:
                info = json.loads(marker.read_text())
                version = int(info["schema_version"])
            except (ValueError, KeyError, TypeError) as exc:
                raise ValueError(f"{marker} is damaged ({exc}); restore it or recreate the archive") from None
            if version > layout.SCHEMA_VERSION:
                raise ValueError(
                    f"archive {str(self.path)!r} has schema_version {version}, newer than this rsodb reads "
                    f"({layout.SCHEMA_VERSION}); upgrade rsodb"
                )
            if os.access(self.path, os.W_OK):
                self.objects_dir.mkdir(exist_ok=True)
            return
        if not create:
            raise ValueError(
                f"no archive at {str(self.path)!r}; create one with 'rsodb ingest FILES --archive {self.path}'"
            )
        # A creation killed before its marker was renamed into place leaves only its temporary file.
        leftover = re.compile(rf"^\.{re.escape(layout.MARKER_NAME)}\..*\.tmp$")
        if self.path.is_dir() and any(not leftover.match(entry.name) for entry in self.path.iterdir()):
            raise ValueError(
                f"{str(self.path)!r} is a non-empty directory without {layout.MARKER_NAME}, so not an rsodb "
                "archive; give a new or empty directory"
            )
        self.path.mkdir(parents=True, exist_ok=True)
        info = {"format": layout.FORMAT_NAME, "schema_version": layout.SCHEMA_VERSION, "created_utc": utc_now()}
        with replacing(marker, durable=self.durable) as tmp:
            tmp.write_text(json.dumps(info, indent=1) + "\n")
        self.objects_dir.mkdir(exist_ok=True)

    def object_lock(self, norad: int) -> ObjectLock:
        """The lock an object's writers take (a context manager)."""
        return ObjectLock(self.objects_dir / layout.lock_file_name(norad), timeout_s=self.lock_timeout_s)

    def _remove_stale_temp_files(self) -> set[str]:
        """Delete temporary files of killed writers; objects being written right now are skipped.
        Returns the names of the temporary files left (those of the writers still running)."""
        staging = self.path / layout.STAGING_DIR
        if staging.is_dir():
            remove_abandoned_staging(staging)
        by_norad: dict[int, list[str]] = {}
        for name in os.listdir(self.objects_dir):
            match = _TEMP_NAME.match(name)
            if match:
                by_norad.setdefault(int(match.group(1)), []).append(name)
        left = set()
        for norad in sorted(by_norad):
            lock = self.object_lock(norad)
            if not lock.acquire(blocking=False):
                left.update(by_norad[norad])
                continue
            try:
                for name in by_norad[norad]:
                    (self.objects_dir / name).unlink(missing_ok=True)
            finally:
                lock.release()
        return left

    def _transaction(self, temp_names: set[str] | None = None) -> ObjectTransaction:
        """One round of commits. Without `temp_names` it removes the temporary files listed when
        the archive was opened (listing 20 000 objects' directory again would cost ~20 ms a call);
        one that a writer killed since then left is removed by the next Archive() or ingest."""
        if temp_names is None:
            temp_names = self._temp_names
        return ObjectTransaction(
            self.objects_dir, self._index, self.durable, self.lock_timeout_s, temp_names=temp_names
        )

    # -- the index ------------------------------------------------------------------------------
    def _refresh(self, norads: Iterable[int] | None = None) -> None:
        """Bring the index up to date with the object files (all, or those of `norads`)."""
        if norads is not None:
            wanted = sorted({int(norad) for norad in norads})
            known = self._index.states(wanted)
            stale, gone = [], []
            for norad in wanted:
                try:
                    stat = os.stat(self.object_path(norad))
                except FileNotFoundError:
                    if norad in known:
                        gone.append(norad)
                    continue
                if norad not in known or not known[norad].matches(stat):
                    stale.append((norad, stat))
            self._reindex(stale, gone)
            return
        try:
            directory = os.stat(self.objects_dir)
        except FileNotFoundError:
            return
        if self._index.directory_unchanged(directory):
            return
        on_disk = {}
        with os.scandir(self.objects_dir) as entries:
            for entry in entries:
                match = _OBJECT_NAME.match(entry.name)
                if match:
                    try:
                        on_disk[int(match.group(1))] = entry.stat()
                    except FileNotFoundError:
                        continue
        known = self._index.states()
        stale = [
            (norad, stat) for norad, stat in on_disk.items() if norad not in known or not known[norad].matches(stat)
        ]
        self._reindex(stale, [norad for norad in known if norad not in on_disk])
        self._index.remember_sweep(directory)

    def _reindex(self, stale: Sequence[tuple[int, os.stat_result]], gone: Sequence[int]) -> None:
        if gone:
            self._index.remove_objects(gone)
        for start in range(0, len(stale), _INDEX_BATCH):
            entries = []
            for norad, stat in stale[start : start + _INDEX_BATCH]:
                entry = self._read_index_entry(norad, stat)
                if entry is not None:
                    entries.append(entry)
            damaged = [entry for entry in entries if entry[0].status == "damaged"]
            for entry in damaged:
                self._index.mark_damaged(entry[0])
            self._index.replace_objects(entry for entry in entries if entry[0].status != "damaged")

    def _read_index_entry(self, norad: int, stat: os.stat_result):
        """What the index records of one object, read from its file (None when it vanished)."""
        path = self.object_path(norad)
        try:
            with open_object(path) as file:
                state = ObjectState.of(norad, os.fstat(file.id.get_vfd_handle()))
                return (
                    state,
                    _text(file.attrs.get("name", "")),
                    _text(file.attrs.get("cospar", "")),
                    layout.read_catalog(file),
                    layout.read_results(file),
                    layout.read_duplicates(file),
                )
        except FileNotFoundError:
            return None
        except DamagedObjectError as exc:
            return (ObjectState.of(norad, stat, "damaged", exc.reason),)
        except (OSError, RuntimeError, KeyError, ValueError) as exc:
            reason = f"its tables cannot be read ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})"
            return (ObjectState.of(norad, stat, "damaged", reason),)

    def known_sha256(self) -> set[str]:
        """SHA-256 of every stored file: sources of passes and duplicate sources."""
        self._refresh()
        return self._index.known_sha256()

    def stored_sources(self) -> StoredSources | frozenset[str]:
        """What the index says `known_sha256` holds, as a container that answers ``sha256 in it``
        (the index asked hash by hash, cheap to send to other processes; an empty set when the
        index holds nothing). The index is not swept first (on a large archive that stats every
        object file): a hash it lists may be gone from a file changed behind its back, so confirm
        a hit with `is_stored`; a hash it lacks is at worst read and found again by its commit."""
        if self._index.in_memory:
            return frozenset(self.known_sha256())
        if not self._index.holds_sources():
            return frozenset()
        return StoredSources(self._index.path)

    def is_stored(self, sha256: str) -> bool:
        """Whether a file with this content is stored (a pass's source or a duplicate source),
        checked against the files of the objects the index names."""
        try:
            holders = self._index.holders(sha256)
            if not holders:
                return False
            self._refresh(holders)
            return bool(self._index.holders(sha256))
        except (DamagedIndexError, TimeoutError):
            return False  # the file is read and its commit decides

    def rebuild_index(self) -> int:
        """Read every object file into a fresh index; returns the number of objects indexed."""
        self._index.clear()
        self._refresh()
        return len(self._index.states())

    # -- reading -----------------------------------------------------------------------------
    def _query(self, norad=None, band=None, site=None, **filters) -> PassQuery:
        unknown = sorted(set(filters) - _FILTERS)
        if unknown:
            raise TypeError(f"{unknown[0]!r} is not a filter; the filters are {', '.join(sorted(_FILTERS))}")
        if norad is not None and (isinstance(norad, bool) or not isinstance(norad, (int, np.integer))):
            raise TypeError(f"norad={norad!r} must be an integer NORAD catalogue number")
        for key in ("since", "until"):
            if filters.get(key) is not None:
                filters[f"{key}_utc"] = _as_datetime(filters.pop(key), key)
            else:
                filters.pop(key, None)
        for key in ("period_min", "period_max"):
            value = filters.pop(key, None)
            if value is not None:
                value = float(value)
                if not np.isfinite(value) or value < 0:
                    raise ValueError(f"{key}={value!r} must be a non-negative number of seconds")
            filters[f"{key}_s"] = value
        query = PassQuery(norad=None if norad is None else int(norad), band=band, site=site, **filters)
        self._refresh(None if norad is None else [norad])
        return query

    def summaries(
        self, norad: int | None = None, band: str | None = None, site: str | None = None, **filters
    ) -> list[PassSummary]:
        """One `PassSummary` per pass, sorted by start time, without reading any arrays.

        Parameters
        ----------
        norad : int, optional
            Only this object.
        band : str, optional
            Only this band (exact letter, e.g. ``"V"``).
        site : str, optional
            Only this site (name, case-insensitive).
        all_versions : bool
            Include versions superseded by a changed file (default: current versions only).
        since, until : datetime64, str or astropy Time, optional
            Only passes starting at or after `since` and before `until` (UTC).
        period_min, period_max : float, optional
            Only passes whose stored period (result `periods_name`) lies in this range, seconds.
        verdict : str, optional
            Only passes whose stored period result has this verdict (e.g. ``"confident"``).
        periods_name : str
            The stored period result the period filters and columns use (default "default").

        Raises
        ------
        TypeError
            For a filter not listed here.
        """
        return list(self.iter_summaries(norad, band, site, **filters))

    def iter_summaries(
        self, norad: int | None = None, band: str | None = None, site: str | None = None, **filters
    ) -> Iterator[PassSummary]:
        """The passes `summaries` selects, one at a time (what ``rsodb ls`` streams)."""
        return self._index.passes(self._query(norad, band, site, **filters))

    def catalog(self, norad: int | None = None, band: str | None = None, site: str | None = None, **filters):
        """Every pass selected as a pandas DataFrame, one row per pass, by start time.

        Columns: ``pass_id``, ``lineage_id``, ``version``, ``supersedes``, ``superseded_by``,
        ``norad``, ``name``, ``band``, ``site``, ``start_utc``, ``end_utc`` (datetime64[ns],
        UTC), ``duration_s``, ``n_points``, ``exposure_s``, ``source_name``, ``source_sha256``,
        ``source_format``, ``ingested_utc``, ``n_row_problems``, ``n_warnings``, ``elements``
        ("header", "catalogue" or ""), and from the stored period result `periods_name`:
        ``period_s``, ``period_err_s``, ``verdict`` (NaN / None without one). The filters are
        those of `summaries`; the query runs on the catalog index, so it costs what its result
        costs, not what the archive holds.

        Examples
        --------
        >>> frame = archive.catalog(period_min=5, period_max=20, verdict="confident")  # doctest: +SKIP
        >>> frame.groupby("norad").period_s.median()                                    # doctest: +SKIP
        """
        # pandas costs about half a second to import; only this conversion needs it.
        import pandas as pd

        sql, params = self._index.frame_sql(self._query(norad, band, site, **filters))
        with self._index.guarded() as connection:
            frame = pd.read_sql_query(sql, connection, params=params)
        for column in ("start_utc", "end_utc"):
            frame[column] = pd.to_datetime(frame[column], unit="ns")
        frame.insert(
            frame.columns.get_loc("end_utc") + 1, "duration_s", (frame.end_utc - frame.start_utc).dt.total_seconds()
        )
        for column in ("supersedes", "superseded_by", "verdict"):
            frame[column] = frame[column].where(frame[column].notna() & (frame[column] != ""), None)
        return frame

    def damaged(self, norad: int | None = None) -> list[DamagedObject]:
        """Object files that cannot be read (all, or that of `norad`); ``rsodb check --repair``
        moves them aside."""
        self._refresh(None if norad is None else [norad])
        return [replace(item, path=str(self.object_path(item.norad))) for item in self._index.damaged(norad)]

    def passes(
        self, norad: int | None = None, band: str | None = None, site: str | None = None, *, all_versions: bool = False
    ) -> list[StoredPass]:
        """Stored passes, sorted by start time.

        Parameters
        ----------
        norad, band, site, all_versions
            As in `summaries`.

        Returns
        -------
        list of StoredPass

        Raises
        ------
        DamagedObjectError
            When an object file holding a selected pass is damaged (named in the message).
        """
        wanted: dict[int, set[str]] = {}
        order = {}
        for i, row in enumerate(self.iter_summaries(norad, band, site, all_versions=all_versions)):
            wanted.setdefault(row.norad, set()).add(row.pass_id)
            order[row.pass_id] = i
        found = []
        for object_norad, pass_ids in wanted.items():
            found.extend(self._read_passes(object_norad, pass_ids))
        found.sort(key=lambda stored: order[stored.pass_id])
        return found

    def _read_passes(self, norad: int, pass_ids: set[str], retry: bool = True) -> list[StoredPass]:
        """Read the given passes of one object from its current file (one consistent snapshot)."""
        path = self.object_path(norad)
        with open_object(path) as file:
            try:
                superseded_by = {row.pass_id: row.superseded_by for row in layout.read_catalog(file)}
                missing = [pass_id for pass_id in pass_ids if pass_id not in superseded_by]
                if not missing:
                    return [layout.read_pass(file["passes"][pass_id], superseded_by[pass_id]) for pass_id in pass_ids]
            except (layout.DamagedPassError, RuntimeError, KeyError) as exc:
                raise DamagedObjectError(path, str(exc).splitlines()[0] if str(exc) else type(exc).__name__) from None
        if retry:  # the index was behind the file (it changed since): read the file into it, look again
            self._refresh([norad])
            return self._read_passes(norad, pass_ids, retry=False)
        raise UnknownPassError(f"passes {', '.join(sorted(missing))} are no longer in {path}; run 'rsodb ls' again")

    def summary(self, pass_id: str) -> PassSummary:
        """The catalog row of a pass; `pass_id` may be a unique prefix of the id.

        An exact id gives that version; a prefix shared only by the versions of one pass gives
        its current version.

        Raises
        ------
        UnknownPassError
            When nothing matches, or the prefix matches several passes.
        DamagedObjectError
            When nothing matches and the object the prefix names has a damaged file.
        """
        if not isinstance(pass_id, str) or not pass_id.strip():
            raise UnknownPassError(f"pass id {pass_id!r} is empty; run 'rsodb ls' to list pass ids")
        pass_id = pass_id.strip()
        named = _NORAD_PREFIX.match(pass_id)
        self._refresh([int(named.group(1))] if named else None)
        query = PassQuery(all_versions=True, pass_id_prefix=pass_id)
        matches = []
        for row in self._index.passes(query):
            if row.pass_id == pass_id:
                return row
            matches.append(row)
            if len({item.lineage_id for item in matches}) > 1 and len(matches) >= 5:
                break
        if matches and len({row.lineage_id for row in matches}) == 1:
            # Versions of one pass: the prefix names the pass, so give its current version.
            current = [row for row in matches if row.is_current]
            return current[0] if current else matches[-1]
        if not matches:
            # A pass of a damaged object is not in the index: say so rather than "no pass".
            digits = named.group(1) if named else re.match(r"^\d*", pass_id).group(0)
            for item in self._index.damaged(int(digits)) if named else self._index.damaged() if digits else []:
                if named or str(item.norad).startswith(digits):
                    raise DamagedObjectError(self.object_path(item.norad), item.reason)
            raise UnknownPassError(
                f"no pass {pass_id!r} in archive {str(self.path)!r}; run 'rsodb ls --archive {self.path}' "
                "to list pass ids"
            )
        count = self._index.count(query)
        shown = ", ".join(row.pass_id for row in matches[:5]) + (", ..." if count > 5 else "")
        raise UnknownPassError(f"pass id prefix {pass_id!r} matches {count} passes ({shown}); give more of the id")

    def get(self, pass_id: str) -> StoredPass:
        """The stored pass with this id (a unique prefix is enough), its content verified.

        Raises
        ------
        UnknownPassError
        DamagedObjectError
            When the pass's object file, or the pass itself, fails its checksums.
        """
        row = self.summary(pass_id)
        return self._read_passes(row.norad, {row.pass_id})[0]

    def content_hashes(self, norad: int) -> dict[str, str]:
        """The content SHA-256 of each stored pass version of an object (its samples, row problems
        and metadata, orbital elements included): what a result derived from a pass was found from.

        Raises
        ------
        DamagedObjectError
        """
        path = self.object_path(norad)
        try:
            with open_object(path) as file:
                hashes = {}
                for pass_id, group in file["passes"].items():
                    attrs = layout.get_attrs(group, ("content_sha256",))
                    if attrs:
                        hashes[pass_id] = attr_text(attrs["content_sha256"])
                return hashes
        except FileNotFoundError:
            return {}
        except DamagedObjectError:
            raise
        except (KeyError, OSError, RuntimeError) as exc:
            raise DamagedObjectError(path, f"its passes cannot be listed ({str(exc).splitlines()[0]})") from None

    def results(self, pass_id: str) -> list[ResultSummary]:
        """Summaries (period, verdict, when) of every result stored for a pass."""
        row = self.summary(pass_id)
        return self._index.results(row.pass_id)

    def duplicate_sources(self, pass_id: str):
        """Files recorded as duplicate sources of a pass (`rsodb.archive.stored.DuplicateSource`)."""
        row = self.summary(pass_id)
        return self._index.duplicates(row.pass_id)

    def objects(self) -> list[ArchivedObject]:
        """The archive's objects with current passes, by NORAD number."""
        self._refresh()
        return [
            ArchivedObject(
                norad=norad,
                name=name or "",
                cospar=cospar or "",
                n_passes=n_passes,
                n_versions=n_versions,
                bands=tuple(sorted(set((bands or "").split(",")) - {""})),
                first_utc=np.datetime64(first, "ns"),
                last_utc=np.datetime64(last, "ns"),
            )
            for norad, name, cospar, n_passes, bands, first, last, n_versions in self._index.objects()
        ]

    # -- writing -----------------------------------------------------------------------------
    def ingest(
        self,
        paths,
        progress: bool = True,
        *,
        workers: int | None = None,
        on_commit: Callable[[CommitEvent], None] | None = None,
        commit_interval_s: float = 1.0,
        elements: ElementCatalogue | str | os.PathLike | None = None,
        max_age_days: float = DEFAULT_MAX_AGE_DAYS,
    ) -> IngestReport:
        """Read observation files and store their passes.

        Parameters
        ----------
        paths : str, path-like, or iterable of them
            Files (read whatever their name) and directories (walked recursively for
            observation files; see `rsodb.archive.discovery`).
        progress : bool
            Show a progress bar on stderr.
        workers : int, optional
            Reader processes; 0 reads in this process. Default: one per CPU for large batches;
            more than the usable cores are not started.
        on_commit : callable, optional
            Called with a `CommitEvent` each time an object file has been replaced: from then on
            the passes it lists survive any crash.
        commit_interval_s : float
            Commit at least this often while files are being read (see docs/archive.md).
        elements : ElementCatalogue or path, optional
            A TLE or OMM catalogue: passes whose files carry no elements get the set of their
            object nearest the pass, if it is at most `max_age_days` away.
        max_age_days : float
            The oldest element set given to a pass (days between epoch and pass).

        Returns
        -------
        IngestReport
            Ingested, duplicate, already present (same SHA-256) and failed files, and warnings.
            A bad file never stops the batch.
        """
        if isinstance(paths, (str, os.PathLike)):
            paths = [paths]
        if elements is not None and not isinstance(elements, ElementCatalogue):
            elements = ElementCatalogue.from_file(elements)
        # Imported here: the readers and the progress bar cost lookups (ls, show) ~50 ms of start-up.
        from rsodb.archive.ingestion import run_ingest

        return run_ingest(
            self,
            list(paths),
            progress=progress,
            workers=workers,
            on_commit=on_commit,
            commit_interval_s=commit_interval_s,
            elements=elements,
            max_age_days=max_age_days,
        )

    def add(self, passes: Iterable[Pass]) -> IngestReport:
        """Store passes built in memory (synthetic or already read); same rules as `ingest`.

        A pass without `source_sha256` is identified by a hash of its samples, so adding the same
        pass twice stores it once.
        """
        by_object: dict[int, dict[str, list[Pass]]] = {}
        for pass_ in passes:
            if not isinstance(pass_, Pass):
                raise TypeError(f"archive.add takes Pass objects, got {type(pass_).__name__}")
            sha = pass_.source_sha256 or layout.memory_sha256(pass_)
            by_object.setdefault(int(pass_.norad), {}).setdefault(sha, []).append(pass_)
        batches = {
            norad: [
                PendingFile(group[0].source_name or f"<pass {group[0].norad}>", sha, tuple(group))
                for sha, group in by_sha.items()
            ]
            for norad, by_sha in by_object.items()
        }
        events, failures = self.commit_many(batches)
        if failures:
            raise failures[0][1]
        return IngestReport(
            ingested=tuple(item for event in events for item in event.ingested),
            already_present=tuple(item for event in events for item in event.already_present),
            duplicates=tuple(item for event in events for item in event.duplicates),
        )

    def commit(self, norad: int, files: Sequence[PendingFile]) -> CommitEvent:
        """Store the passes of `files` (all of object `norad`) in one atomic replacement.

        Under the object's lock: files whose SHA-256 is already stored are skipped; each new pass
        is placed by the version rule (docs/archive.md); then the object file is replaced.
        Returns once the replacement is durable.
        """
        events, failures = self.commit_many({int(norad): list(files)})
        if failures:
            raise failures[0][1]
        return events[0]

    def commit_many(
        self, batches: dict[int, Sequence[PendingFile]], temp_names: set[str] | None = None
    ) -> tuple[list[CommitEvent], list[tuple[int, Exception]]]:
        """Commit the files of many objects in one round: each object is replaced atomically,
        and the round pays for one flush of the file system instead of one per object.
        `temp_names`: killed writers' temporary files, listed once for the rounds of one run
        (`rsodb.archive.commits.list_temp_names`; default: those listed when the archive was opened).

        Returns
        -------
        events : list of CommitEvent
            Per object committed (or found to need nothing), once durable.
        failures : list of (norad, exception)
            Objects whose commit failed (a damaged object file, a lock held too long); the
            others are committed regardless.
        """
        events, failures = [], []
        with self._transaction(temp_names) as transaction:
            for norad in sorted(batches):
                files = batches[norad]
                try:
                    transaction.lock(norad)
                    if len(files) == 1 and files[0].prepared is not None and transaction.adopt(files[0].prepared):
                        continue  # staged by the reader from the object file as it still is
                    event = stage_files(transaction, norad, files)
                except (DamagedObjectError, layout.DamagedPassError, TimeoutError, OSError, ValueError) as exc:
                    if isinstance(exc, layout.DamagedPassError):
                        exc = DamagedObjectError(self.object_path(norad), str(exc))
                    failures.append((norad, exc))
                    continue
                if not transaction.staged or transaction.staged[-1].norad != norad:  # nothing to write
                    events.append(event)
            for staged in transaction.publish():
                events.append(staged.event)
        events.sort(key=lambda event: event.norad)
        return events, failures

    # -- results -----------------------------------------------------------------------------
    @staticmethod
    def _check_result_key(kind: str, name: str) -> None:
        if kind not in layout.RESULT_KINDS:
            raise ValueError(f"result kind {kind!r} is not one of {', '.join(layout.RESULT_KINDS)}")
        if not isinstance(name, str) or not _RESULT_NAME.match(name) or ".." in name:
            raise ValueError(
                f"result name {name!r} must start with a letter or digit and use only letters, digits "
                "and . _ + = - (it names an HDF5 group and a file)"
            )

    def store_result(self, pass_id: str, kind: str, name: str, result) -> None:
        """Store `result` under the pass: ``result.to_hdf5(group)`` runs inside an atomic commit.

        Parameters
        ----------
        pass_id : str
            The pass (a unique prefix is enough).
        kind : {"periods", "fits"}
        name : str
            Result name; storing the same name again replaces the earlier result.
        result : object with ``to_hdf5(group)``
            Writes itself into the given h5py group. If it raises, the archive is unchanged.
        """
        self.store_results([(pass_id, kind, name, result)])

    def store_results(self, items: Iterable[tuple[str, str, str, object]]) -> int:
        """Store many results with one atomic commit per object (see `store_result`).

        Every commit rewrites the object's file, so storing the results of a survey one by one
        costs a file copy each; this writes all of an object's results in one, and publishes
        all objects with one flush.

        Parameters
        ----------
        items : iterable of (pass_id, kind, name, result)
            As the arguments of `store_result`. Later items replace earlier ones with the same
            pass, kind and name.

        Returns
        -------
        int
            The number of commits made (objects touched).

        Raises
        ------
        ValueError, TypeError, KeyError
            Before anything is written, for a bad kind, name, result or pass id. If a result's
            ``to_hdf5`` raises, nothing is stored.
        """
        by_norad: dict[int, list[tuple[str, str, str, object]]] = {}
        for pass_id, kind, name, result in items:
            self._check_result_key(kind, name)
            if not callable(getattr(result, "to_hdf5", None)):
                raise TypeError(f"{type(result).__name__} has no to_hdf5(group) method, so it cannot be stored")
            row = self.summary(pass_id)
            by_norad.setdefault(row.norad, []).append((row.pass_id, kind, name, result))
        with self._transaction() as transaction:
            for norad in sorted(by_norad):
                transaction.lock(norad)
                stage_results(transaction, norad, by_norad[norad])
            transaction.publish()
        return len(by_norad)

    def load_result(self, pass_id: str, kind: str, name: str, loader: Callable[[h5py.Group], object]):
        """Return ``loader(group)`` for a stored result (the file is closed after `loader` returns).

        Raises
        ------
        DamagedObjectError
            When the result fails its SHA-256 (it is not handed to `loader`).
        """
        self._check_result_key(kind, name)
        row = self.summary(pass_id)
        path = self.object_path(row.norad)
        with open_object(path) as file:
            try:
                pass_group = file["passes"][row.pass_id]
                found = kind in pass_group and name in pass_group[kind]
                stored = sorted(pass_group[kind]) if kind in pass_group else []
                group = pass_group[kind][name] if found else None
            except (KeyError, OSError, RuntimeError) as exc:
                raise DamagedObjectError(
                    path, f"pass {row.pass_id} cannot be read ({str(exc).splitlines()[0]})"
                ) from None
            if group is None:
                raise UnknownPassError(
                    f"pass {row.pass_id!r} has no {kind} result named {name!r}; stored: "
                    f"{', '.join(stored) if stored else 'none'}"
                )
            check_result(group, path)
            return loader(group)

    def result_values(self, pass_id: str, kind: str, name: str) -> dict:
        """A stored result's scalar attributes and small tables, as plain values (what
        ``rsodb show`` prints): numbers, text, and each small 1-D table as a list of rows."""
        return self.load_result(pass_id, kind, name, _plain_values)

    def result_names(self, pass_id: str, kind: str) -> list[str]:
        """Names of the stored results of one kind for a pass, sorted."""
        self._check_result_key(kind, "x")
        return sorted(item.name for item in self.results(pass_id) if item.kind == kind)

    def chain_path(self, pass_id: str, name: str) -> Path:
        """Where an emcee HDFBackend for fit `name` of this pass lives (parent directory created).

        The sampler writes this file in place while it runs (so a killed fit resumes); it lives
        outside the object files, whose replacements must stay atomic.
        """
        self._check_result_key("fits", name)
        row = self.summary(pass_id)
        directory = self.path / layout.CHAINS_DIR / str(row.norad) / row.pass_id
        directory.mkdir(parents=True, exist_ok=True)
        return directory / f"{name}.h5"

    # -- orbital elements ------------------------------------------------------------------
    def add_elements(
        self,
        catalogue: ElementCatalogue | str | os.PathLike,
        *,
        max_age_days: float = DEFAULT_MAX_AGE_DAYS,
        norad: int | None = None,
        replace_catalogue: bool = False,
    ) -> ElementsReport:
        """Give stored passes without orbital elements the nearest set of a TLE/OMM catalogue.

        Parameters
        ----------
        catalogue : ElementCatalogue or path
        max_age_days : float
            The oldest set given (days between its epoch and the pass).
        norad : int, optional
            Only this object.
        replace_catalogue : bool
            Also replace elements that an earlier catalogue gave, where this one has a set nearer
            the pass. Elements from a file's own header are never replaced (its Az/El columns were
            computed with them).

        Returns
        -------
        ElementsReport
        """
        if not isinstance(catalogue, ElementCatalogue):
            catalogue = ElementCatalogue.from_file(catalogue)
        candidates = [
            row
            for row in self.iter_summaries(norad, all_versions=True)
            if row.elements == "" or (replace_catalogue and row.elements == "catalogue")
        ]
        changes: dict[int, dict] = {}
        notes = []
        for row in candidates:
            chosen, reason = catalogue.elements_for(row.norad, row.start_utc, max_age_days)
            if chosen is None:
                notes.append((row.pass_id, reason))
                continue
            provenance = catalogue.provenance(chosen, row.start_utc)
            provenance["added_utc"] = utc_now()
            changes.setdefault(row.norad, {})[row.pass_id] = _elements_change(chosen, provenance)
        changed: list[str] = []
        failures = []
        with self._transaction() as transaction:
            for object_norad in sorted(changes):
                try:
                    transaction.lock(object_norad)
                    changed += stage_metadata(transaction, object_norad, changes[object_norad])
                except (DamagedObjectError, TimeoutError) as exc:
                    failures.append((object_norad, exc))
            transaction.publish()
        return ElementsReport(tuple(changed), tuple(notes), tuple(failures), catalogue.name)


def _elements_change(chosen, provenance: dict) -> Callable[[dict], dict | None]:
    def change(metadata: dict) -> dict | None:
        old = metadata.get("elements_source")
        if metadata.get("tle") is not None or metadata.get("omm") is not None:
            if not old:
                return None  # the file's own elements
            if abs(old.get("age_days", np.inf)) <= provenance["age_days"]:
                return None  # the stored set is at least as near
        metadata["tle"] = list(chosen.tle) if chosen.tle is not None else None
        metadata["omm"] = dict(chosen.omm) if chosen.omm is not None else None
        metadata["elements_source"] = provenance
        metadata["warnings"] = [
            item for item in metadata.get("warnings", []) if not item.get("reason", "").startswith("no orbit:")
        ]
        return metadata

    return change


class ElementsReport:
    """What `Archive.add_elements` did.

    Attributes
    ----------
    changed : tuple of str
        Pass ids that got elements.
    skipped : tuple of (pass_id, reason)
        Passes left without: no set of their object, or the nearest too old.
    failed : tuple of (norad, exception)
        Objects whose files could not be updated.
    catalogue : str
    """

    def __init__(self, changed, skipped, failed, catalogue: str):
        self.changed, self.skipped, self.failed, self.catalogue = changed, skipped, failed, catalogue

    @property
    def ok(self) -> bool:
        return not self.failed

    def summary(self) -> str:
        lines = [
            f"added elements from {self.catalogue} to {len(self.changed)} pass(es); "
            f"{len(self.skipped)} left without; {len(self.failed)} object(s) failed"
        ]
        lines += [f"  {pass_id}: {reason}" for pass_id, reason in self.skipped]
        lines += [f"  failed: {error}" for _, error in self.failed]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {
            "catalogue": self.catalogue,
            "changed": list(self.changed),
            "skipped": [{"pass_id": pass_id, "reason": reason} for pass_id, reason in self.skipped],
            "failed": [{"norad": norad, "message": str(error)} for norad, error in self.failed],
        }


def _text(value) -> str:
    return value.decode("utf-8") if isinstance(value, bytes) else str(value)


def _as_datetime(value, name: str) -> np.datetime64:
    """A UTC time from datetime64, ISO text or an astropy Time, as datetime64[ns]."""
    if hasattr(value, "datetime64"):  # astropy Time
        value = value.utc.datetime64
    text = str(value).rstrip("Z") if isinstance(value, str) else value
    try:
        day = np.datetime64(text, "D")
        result = np.datetime64(text, "ns")
    except (ValueError, TypeError):
        raise ValueError(f"{name}={value!r} is not a UTC time; give e.g. 2025-01-30 or 2025-01-30T17:00") from None
    if np.isnat(result) or not np.datetime64("1678-01-01") <= day <= np.datetime64("2262-04-10"):
        raise ValueError(f"{name}={value!r} is not a UTC time between 1678 and 2262; give e.g. 2025-01-30")
    return result


def _plain(value):
    """An HDF5 attribute or table cell as a JSON-ready value (NaN as None, JSON text parsed)."""
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray):
        return [_plain(item) for item in value.tolist()] if value.size <= 16 else f"<array of {value.size}>"
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    if isinstance(value, str) and value[:1] in "[{":
        try:
            return json.loads(value)
        except ValueError:
            return value
    return value


def _plain_values(group: h5py.Group) -> dict:
    """Scalar attributes and small 1-D tables (up to 64 rows) of a result group."""
    values = {key: _plain(group.attrs[key]) for key in sorted(group.attrs) if key != "content_sha256"}
    for key in sorted(group):
        node = group[key]
        if isinstance(node, h5py.Dataset) and node.ndim == 1 and node.dtype.names and node.shape[0] <= 64:
            rows = node[()]
            values[key] = [{name: _plain(row[name]) for name in rows.dtype.names} for row in rows]
    return values
