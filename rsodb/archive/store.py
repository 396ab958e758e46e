"""`Archive`: the observation database, one crash-safe HDF5 file per object.

Every write (new passes, a period or fit result) follows one protocol under the object's lock:
read the current object file, build its next state in a temporary file beside it (a byte copy of
the current file, then appends), fsync, rename over the current file, fsync the directory. The
rename is the commit point. Readers open the current file read-only and see one consistent state;
a killed writer leaves at most a temporary file, removed the next time the object is written or
the archive is opened.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import replace
from datetime import UTC, datetime
import json
import os
from pathlib import Path
import re
import shutil

import h5py
import numpy as np

from ingest.observation import Pass
from rsodb.archive import layout
from rsodb.archive.ingest_report import CommitEvent, IngestedFile, IngestReport, PendingFile
from rsodb.archive.ingestion import run_ingest
from rsodb.archive.locking import ObjectLock, replacing, stale_temp_files
from rsodb.archive.stored import ArchivedObject, PassSummary, StoredPass

__all__ = ["Archive", "UnknownPassError"]

# Rewrite an object file from scratch (instead of copying its bytes) once the space left behind
# by replaced catalogs and results exceeds this share of the file.
_REPACK_FRACTION = 0.25
_REPACK_MIN_BYTES = 4 << 20
_RESULT_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+=-]*$")
_TEMP_NAME = re.compile(r"^\.(\d+)\.h5\..*\.tmp$")


class UnknownPassError(LookupError):
    """No stored pass matches an id (or the prefix matches several)."""


def _utc_now() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


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
    """

    def __init__(self, path, *, create: bool = True, durable: bool = True, lock_timeout_s: float | None = 600.0):
        self.path = Path(path)
        self.durable = durable
        self.lock_timeout_s = lock_timeout_s
        self._catalog_cache: dict[Path, tuple[tuple, list[PassSummary], dict]] = {}
        self._open_or_create(create)
        if os.access(self.objects_dir, os.W_OK):
            self._remove_stale_temp_files()

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
        info = {"format": layout.FORMAT_NAME, "schema_version": layout.SCHEMA_VERSION, "created_utc": _utc_now()}
        with replacing(marker, durable=self.durable) as tmp:
            tmp.write_text(json.dumps(info, indent=1) + "\n")
        self.objects_dir.mkdir(exist_ok=True)

    def _lock(self, norad: int) -> ObjectLock:
        return ObjectLock(self.objects_dir / layout.lock_file_name(norad), timeout_s=self.lock_timeout_s)

    def _remove_stale_temp_files(self) -> None:
        """Delete temporary files of killed writers; objects being written right now are skipped."""
        norads = {int(match.group(1)) for match in map(_TEMP_NAME.match, os.listdir(self.objects_dir)) if match}
        for norad in sorted(norads):
            lock = self._lock(norad)
            if lock.acquire(blocking=False):
                try:
                    self._remove_own_temp_files(norad)
                finally:
                    lock.release()

    def _object_norads(self) -> list[int]:
        norads = []
        for name in os.listdir(self.objects_dir):
            stem, _, suffix = name.partition(".")
            if suffix == "h5" and stem.isdigit():
                norads.append(int(stem))
        return sorted(norads)

    # -- reading -----------------------------------------------------------------------------
    def _object_catalog(self, norad: int) -> tuple[list[PassSummary], dict]:
        """Catalog rows and root attributes of one object file (cached until the file changes)."""
        path = self.object_path(norad)
        stat = path.stat()
        key = (stat.st_ino, stat.st_mtime_ns, stat.st_size)
        cached = self._catalog_cache.get(path)
        if cached is not None and cached[0] == key:
            return cached[1], cached[2]
        with _open_object(path) as file:
            rows = layout.read_catalog(file)
            attrs = {name: file.attrs[name] for name in file.attrs}
        self._catalog_cache[path] = (key, rows, attrs)
        return rows, attrs

    def catalog(
        self, norad: int | None = None, band: str | None = None, site: str | None = None, *, all_versions: bool = False
    ) -> list[PassSummary]:
        """One `PassSummary` per pass, sorted by start time, without reading any arrays.

        Parameters are those of `passes`.
        """
        if norad is not None and not isinstance(norad, (int, np.integer)):
            raise TypeError(f"norad={norad!r} must be an integer NORAD catalogue number")
        site_key = None if site is None else site.strip().lower()
        rows = []
        for object_norad in self._object_norads() if norad is None else [int(norad)]:
            try:
                object_rows, _ = self._object_catalog(object_norad)
            except FileNotFoundError:
                continue
            rows.extend(
                row
                for row in object_rows
                if (all_versions or row.is_current)
                and (band is None or row.band == band)
                and (site_key is None or row.site.lower() == site_key)
            )
        rows.sort(key=lambda row: (row.start_utc, row.pass_id))
        return rows

    def passes(
        self, norad: int | None = None, band: str | None = None, site: str | None = None, *, all_versions: bool = False
    ) -> list[StoredPass]:
        """Stored passes, sorted by start time.

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

        Returns
        -------
        list of StoredPass
        """
        wanted: dict[int, set[str]] = {}
        order = {}
        for i, row in enumerate(self.catalog(norad, band, site, all_versions=all_versions)):
            wanted.setdefault(row.norad, set()).add(row.pass_id)
            order[row.pass_id] = i
        found = []
        for object_norad, pass_ids in wanted.items():
            found.extend(self._read_passes(object_norad, pass_ids))
        found.sort(key=lambda stored: order[stored.pass_id])
        return found

    def _read_passes(self, norad: int, pass_ids: set[str]) -> list[StoredPass]:
        """Read the given passes of one object from its current file (one consistent snapshot)."""
        with _open_object(self.object_path(norad)) as file:
            superseded_by = {row.pass_id: row.superseded_by for row in layout.read_catalog(file)}
            return [layout.read_pass(file["passes"][pass_id], superseded_by[pass_id]) for pass_id in pass_ids]

    def summary(self, pass_id: str) -> PassSummary:
        """The catalog row of a pass; `pass_id` may be a unique prefix of the id.

        An exact id gives that version; a prefix shared only by the versions of one pass gives
        its current version.

        Raises
        ------
        UnknownPassError
            When nothing matches, or the prefix matches several passes.
        """
        if not isinstance(pass_id, str) or not pass_id.strip():
            raise UnknownPassError(f"pass id {pass_id!r} is empty; run 'rsodb ls' to list pass ids")
        pass_id = pass_id.strip()
        rows = self.catalog(all_versions=True)
        exact = [row for row in rows if row.pass_id == pass_id]
        if exact:
            return exact[0]
        matches = [row for row in rows if row.pass_id.startswith(pass_id)]
        if len({row.lineage_id for row in matches}) == 1:
            # Versions of one pass: the prefix names the pass, so give its current version.
            return next(row for row in matches if row.is_current)
        if not matches:
            raise UnknownPassError(
                f"no pass {pass_id!r} in archive {str(self.path)!r}; run 'rsodb ls --archive {self.path}' "
                "to list pass ids"
            )
        shown = ", ".join(row.pass_id for row in matches[:5]) + (", ..." if len(matches) > 5 else "")
        raise UnknownPassError(
            f"pass id prefix {pass_id!r} matches {len(matches)} passes ({shown}); give more of the id"
        )

    def get(self, pass_id: str) -> StoredPass:
        """The stored pass with this id (a unique prefix is enough)."""
        row = self.summary(pass_id)
        return self._read_passes(row.norad, {row.pass_id})[0]

    def objects(self) -> list[ArchivedObject]:
        """The archive's objects, by NORAD number."""
        result = []
        for norad in self._object_norads():
            try:
                rows, attrs = self._object_catalog(norad)
            except FileNotFoundError:
                continue
            current = [row for row in rows if row.is_current]
            if not current:
                continue
            result.append(
                ArchivedObject(
                    norad=norad,
                    name=str(attrs.get("name", "")),
                    cospar=str(attrs.get("cospar", "")),
                    n_passes=len(current),
                    n_versions=len(rows),
                    bands=tuple(sorted({row.band for row in current})),
                    first_utc=min(row.start_utc for row in current),
                    last_utc=max(row.start_utc for row in current),
                )
            )
        return result

    # -- writing -----------------------------------------------------------------------------
    def ingest(
        self,
        paths,
        progress: bool = True,
        *,
        workers: int | None = None,
        on_commit: Callable[[CommitEvent], None] | None = None,
        commit_interval_s: float = 1.0,
    ) -> IngestReport:
        """Read observation files and store their passes.

        Parameters
        ----------
        paths : str, path-like, or iterable of them
            Files (read whatever their name) and directories (walked recursively for
            ``*.ph<letter>`` files; see `rsodb.archive.discovery`).
        progress : bool
            Show a progress bar on stderr.
        workers : int, optional
            Reader processes; 0 reads in this process. Default: one per CPU for large batches.
        on_commit : callable, optional
            Called with a `CommitEvent` each time an object file has been replaced: from then on
            the passes it lists survive any crash.
        commit_interval_s : float
            Commit at least this often while files are being read (the cost of a commit grows
            with the object's size, so commits are also spaced to keep their share of the time
            bounded; see docs/archive.md).

        Returns
        -------
        IngestReport
            Ingested, already present (same SHA-256), and failed files with their reasons.
            A bad file never stops the batch.
        """
        if isinstance(paths, (str, os.PathLike)):
            paths = [paths]
        return run_ingest(
            self,
            list(paths),
            progress=progress,
            workers=workers,
            on_commit=on_commit,
            commit_interval_s=commit_interval_s,
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
            sha = pass_.source_sha256 or layout.content_sha256(pass_)
            by_object.setdefault(int(pass_.norad), {}).setdefault(sha, []).append(pass_)
        ingested, present = [], []
        for norad, by_sha in sorted(by_object.items()):
            pending = [
                PendingFile(group[0].source_name or f"<pass {group[0].norad}>", sha, tuple(group))
                for sha, group in by_sha.items()
            ]
            event = self.commit(norad, pending)
            ingested.extend(event.ingested)
            present.extend(event.already_present)
        return IngestReport(ingested=tuple(ingested), already_present=tuple(present))

    def commit(self, norad: int, files: Sequence[PendingFile]) -> CommitEvent:
        """Store the passes of `files` (all of object `norad`) in one atomic replacement.

        Under the object's lock: files whose SHA-256 is already stored are skipped; each new pass
        gets its id and version (a changed file for a stored pass becomes a new version of it);
        then the object file is replaced. Returns once the replacement is durable.
        """
        norad = int(norad)
        with self._lock(norad):
            final = self.object_path(norad)
            self._remove_own_temp_files(norad)
            rows, attrs = self._read_for_update(final)
            known = {row.source_sha256 for row in rows}
            now = _utc_now()
            ingested, present, to_write = [], [], []
            for pending in files:
                if pending.sha256 in known:
                    present.append(pending.path)
                    continue
                known.add(pending.sha256)
                ids, superseded = [], []
                for pass_ in pending.passes:
                    if int(pass_.norad) != norad:
                        raise ValueError(f"{pending.path}: pass of NORAD {pass_.norad} committed to object {norad}")
                    if pass_.source_sha256 != pending.sha256:
                        pass_ = pass_.replace(source_sha256=pending.sha256)
                    metadata, rows = _identify(pass_, rows, now)
                    ids.append(metadata["pass_id"])
                    if metadata["supersedes"]:
                        superseded.append(metadata["supersedes"])
                    to_write.append((pass_, metadata))
                ingested.append(IngestedFile(pending.path, tuple(ids), tuple(superseded)))
            if to_write:
                rows.sort(key=lambda row: (row.start_utc, row.pass_id))
                latest = to_write[-1][0]
                with self._next_version(final, attrs, norad) as file:
                    passes_group = file.require_group("passes")
                    for pass_, metadata in to_write:
                        layout.write_pass(passes_group, pass_, metadata)
                    freed = int(file.attrs.get("freed_bytes", 0)) + _catalog_bytes(file)
                    layout.write_catalog(file, rows)
                    file.attrs["freed_bytes"] = freed
                    file.attrs["updated_utc"] = now
                    # Attributes cost ~0.1 ms each: write the object's name only when it changes.
                    for key, value in (("name", latest.name), ("cospar", latest.cospar)):
                        if value and attrs.get(key) != value:
                            file.attrs[key] = value
        return CommitEvent(norad=norad, ingested=tuple(ingested), already_present=tuple(present))

    def _remove_own_temp_files(self, norad: int) -> None:
        for path in stale_temp_files(self.objects_dir, layout.object_file_name(norad)):
            path.unlink(missing_ok=True)

    @staticmethod
    def _read_for_update(final: Path) -> tuple[list[PassSummary], dict]:
        if not final.exists():  # under the lock: nobody creates it meanwhile
            return [], {}
        with _open_object(final) as file:
            return layout.read_catalog(file), {name: file.attrs[name] for name in file.attrs}

    @contextmanager
    def _next_version(self, final: Path, attrs: dict, norad: int) -> Iterator[h5py.File]:
        """Yield the object's next file, open for writing; it becomes the current file on a clean exit.

        The next file starts as a byte copy of the current one (cheap: the kernel copies it), or as
        a repacked copy once replaced catalogs and results have left too much dead space behind.
        """
        with replacing(final, durable=self.durable) as tmp:
            if not final.exists():
                file = h5py.File(tmp, "w")
                layout.write_file_attributes(file, norad)
                file.create_group("passes")
            elif int(attrs.get("freed_bytes", 0)) > max(_REPACK_MIN_BYTES, _REPACK_FRACTION * final.stat().st_size):
                file = _repacked(final, tmp)
            else:
                shutil.copyfile(final, tmp)
                file = h5py.File(tmp, "r+")
            try:
                yield file
            finally:
                file.close()

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
        costs a file copy each; this writes all of an object's results in one.

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
            ``to_hdf5`` raises, its object's commit is abandoned; objects committed before it
            keep their results.
        """
        by_norad: dict[int, list[tuple[PassSummary, str, str, object]]] = {}
        for pass_id, kind, name, result in items:
            self._check_result_key(kind, name)
            if not callable(getattr(result, "to_hdf5", None)):
                raise TypeError(f"{type(result).__name__} has no to_hdf5(group) method, so it cannot be stored")
            row = self.summary(pass_id)
            by_norad.setdefault(row.norad, []).append((row, kind, name, result))
        for norad, entries in by_norad.items():
            final = self.object_path(norad)
            with self._lock(norad):
                self._remove_own_temp_files(norad)
                _, attrs = self._read_for_update(final)
                with self._next_version(final, attrs, norad) as file:
                    now = _utc_now()
                    for row, kind, name, result in entries:
                        kind_group = file["passes"][row.pass_id].require_group(kind)
                        if name in kind_group:
                            file.attrs["freed_bytes"] = int(file.attrs.get("freed_bytes", 0)) + _storage_bytes(
                                kind_group[name]
                            )
                            del kind_group[name]
                        group = kind_group.create_group(name)
                        group.attrs["stored_utc"] = now
                        group.attrs["result_type"] = f"{type(result).__module__}.{type(result).__qualname__}"
                        result.to_hdf5(group)
                    file.attrs["updated_utc"] = now
        return len(by_norad)

    def load_result(self, pass_id: str, kind: str, name: str, loader: Callable[[h5py.Group], object]):
        """Return ``loader(group)`` for a stored result (the file is closed after `loader` returns)."""
        self._check_result_key(kind, name)
        row = self.summary(pass_id)
        with _open_object(self.object_path(row.norad)) as file:
            pass_group = file["passes"][row.pass_id]
            if kind not in pass_group or name not in pass_group[kind]:
                stored = sorted(pass_group[kind]) if kind in pass_group else []
                raise UnknownPassError(
                    f"pass {row.pass_id!r} has no {kind} result named {name!r}; stored: "
                    f"{', '.join(stored) if stored else 'none'}"
                )
            return loader(pass_group[kind][name])

    def result_names(self, pass_id: str, kind: str) -> list[str]:
        """Names of the stored results of one kind for a pass, sorted."""
        self._check_result_key(kind, "x")
        row = self.summary(pass_id)
        with _open_object(self.object_path(row.norad)) as file:
            pass_group = file["passes"][row.pass_id]
            return sorted(pass_group[kind]) if kind in pass_group else []

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


def _open_object(path: Path) -> h5py.File:
    """Open an object file read-only, checking its schema; a damaged file is named in the error."""
    try:
        file = h5py.File(path, "r")
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise OSError(
            f"{path} cannot be read as HDF5 ({exc}); restore it from a backup or move it out of the archive"
        ) from None
    try:
        layout.check_schema(file, path)
    except ValueError:
        file.close()
        raise
    return file


def _repacked(source: Path, tmp: Path) -> h5py.File:
    """A fresh copy of `source` at `tmp` holding only live objects (space of deleted ones dropped)."""
    file = h5py.File(tmp, "w")
    with h5py.File(source, "r") as old:
        for name, value in old.attrs.items():
            file.attrs[name] = value
        for name in old:
            old.copy(old[name], file, name=name)
    file.attrs["freed_bytes"] = 0
    return file


def _storage_bytes(node) -> int:
    """Bytes used by the datasets under an HDF5 group or dataset (an estimate of what deleting frees)."""
    if isinstance(node, h5py.Dataset):
        return int(node.id.get_storage_size())
    total = 0

    def visit(_name, item):
        nonlocal total
        if isinstance(item, h5py.Dataset):
            total += int(item.id.get_storage_size())

    node.visititems(visit)
    return total


def _catalog_bytes(file: h5py.File) -> int:
    """Space the current catalog will leave behind when it is replaced (table plus its strings)."""
    if "catalog" not in file:
        return 0
    catalog = file["catalog"]
    return int(catalog.id.get_storage_size()) + 16 * len(layout.CATALOG_DTYPE.names) * catalog.shape[0]


def _identify(pass_: Pass, rows: list[PassSummary], now: str) -> tuple[dict, list[PassSummary]]:
    """Id, version and metadata of a new pass, and the catalog rows with it added.

    A new pass is another version of a stored one when both have the same band and site and
    either the same natural id (object, start second, band, site) or the same file name with
    overlapping times (a changed file). It then gets the next version number of that lineage and
    supersedes its current version; otherwise it starts a lineage of its own.
    """
    natural = layout.natural_pass_id(pass_)
    start, end = pass_.start_utc, pass_.end_utc

    def same_pass(row: PassSummary) -> bool:
        if row.natural_id == natural or row.lineage_id == natural:
            return True  # same object, start second, band and site: the same observation
        if row.band != pass_.band or row.site != pass_.site.name:
            return False
        return (
            bool(pass_.source_name)
            and row.source_name == pass_.source_name
            and row.start_utc <= end
            and start <= row.end_utc
        )

    current = [row for row in rows if row.is_current and same_pass(row)]
    # Prefer the lineage named by this pass's own start, then the most recently stored one.
    current.sort(key=lambda row: (row.natural_id == natural or row.lineage_id == natural, row.ingested_utc))
    if current:
        previous = current[-1]
        lineage = previous.lineage_id
        version = 1 + max(row.version for row in rows if row.lineage_id == lineage)
        supersedes = previous.pass_id
    else:
        lineage, version, supersedes = natural, 1, None
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
    new_row = PassSummary(
        pass_id=pass_id,
        lineage_id=lineage,
        natural_id=natural,
        version=version,
        supersedes=supersedes,
        superseded_by=None,
        norad=int(pass_.norad),
        name=pass_.name,
        band=pass_.band,
        site=pass_.site.name,
        start_utc=start,
        end_utc=end,
        n_points=len(pass_),
        exposure_s=float(pass_.exposure_s),
        source_name=pass_.source_name,
        source_sha256=pass_.source_sha256,
        source_format=pass_.source_format,
        ingested_utc=now,
    )
    updated = [replace(row, superseded_by=pass_id) if row.pass_id == supersedes else row for row in rows]
    return metadata, updated + [new_row]
