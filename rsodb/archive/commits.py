"""Building the next state of object files and publishing many of them at once.

Every write to the archive (new passes, results, orbital elements) is staged the same way, under
the object's lock: read the current object file, write its next state into a temporary file
beside it (a byte copy plus appends, or a repacked copy once replaced tables have left too much
dead space), close it. `publish` then makes a whole round of staged objects durable with one
file-system flush, renames each over its object file (each rename is that object's atomic commit
point), flushes the directory, and records the new files in the catalog index.

An ingest's reader processes stage too, without the lock, into a private directory
(`temp_dir`): `hand_over` keeps those files for the committing process, which `adopt`s one under
the lock only if the object file is still the one that was copied (the same inode, size and
modification time), and stages the object itself otherwise. Either way what is published was
built from the object's current state.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
import os
from pathlib import Path
import shutil
import sqlite3
from stat import S_ISREG

import h5py

from ingest.observation import Pass
from rsodb.archive import layout, versions
from rsodb.archive.index import ObjectState
from rsodb.archive.ingest_report import CommitEvent, DuplicateFile, IngestedFile, PendingFile
from rsodb.archive.integrity import DamagedObjectError, seal_result
from rsodb.archive.locking import ObjectLock, publish, stale_temp_files, temp_path
from rsodb.archive.stored import DuplicateSource, PassSummary, ResultSummary
from rsodb.storage import attr_text

__all__ = [
    "Staged",
    "ObjectTransaction",
    "stage_files",
    "stage_results",
    "stage_metadata",
    "utc_now",
    "list_temp_names",
]

# Rewrite an object file from scratch (instead of copying its bytes) once the space left behind
# by replaced tables and results exceeds this share of the file.
_REPACK_FRACTION = 0.25
_REPACK_MIN_BYTES = 4 << 20
_ROOT_ATTRS = ("name", "cospar", "freed_bytes", "schema_version")


def utc_now() -> str:
    """The current UTC time, ISO 8601 with microseconds and a Z."""
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


@dataclass
class Current:
    """An object's state when its writer took the lock, read from the copy that becomes its next file.

    Attributes
    ----------
    file : h5py.File
        The copy of the object file (or a new file), open for writing.
    tmp, final : Path
    before : ObjectState or None
        The identity of the object file that was copied; None for a new object.
    rows : list of PassSummary
    duplicates : list of DuplicateSource
    attrs : dict
        The root attributes.
    """

    file: h5py.File
    tmp: Path
    final: Path
    before: ObjectState | None
    rows: list[PassSummary]
    duplicates: list[DuplicateSource]
    attrs: dict
    _results: list[ResultSummary] | None = None

    @property
    def results(self) -> list[ResultSummary]:
        """The stored results' summaries (read on first use: an ingest does not need them)."""
        if self._results is None:
            self._results = layout.read_results(self.file)
        return self._results

    def samples_of(self, pass_id: str):
        return layout.read_samples(self.file["passes"][pass_id])


@dataclass
class Staged:
    """An object's next file, complete and closed, waiting to be published.

    Attributes
    ----------
    norad : int
    final, tmp : Path
    state : ObjectState
        The temporary file's identity (unchanged by the rename).
    name, cospar : str
    rows, results, duplicates : list
        What the index records for the object; `results` None when they did not change (the
        index keeps its rows if it described the file that was copied, `before`); `rows` None
        when only `changed` is sent (otherwise the index reads the object's file again).
    before : ObjectState or None
    event : CommitEvent or None
        What an ingest reports once the file is published.
    changed : list of PassSummary or None
        The rows that differ from those of `before` (None: not known, the index takes them all).
    """

    norad: int
    final: Path
    tmp: Path
    state: ObjectState
    name: str
    cospar: str
    rows: list[PassSummary] | None
    results: list[ResultSummary] | None
    duplicates: list[DuplicateSource]
    before: ObjectState | None = None
    event: CommitEvent | None = None
    changed: list[PassSummary] | None = None

    def without_unchanged_rows(self) -> Staged:
        """This item as a reader sends it to the committing process: the catalog rows that did not
        change stay behind when the changed ones are known (pickling every row of a large object
        was most of what a reader sent back)."""
        return self if self.changed is None else replace(self, rows=None)


@dataclass
class ObjectTransaction:
    """Locks held and objects staged for one round of commits; `publish` ends it.

    Parameters
    ----------
    objects_dir : Path
    index : CatalogIndex or None
        None for a transaction that only stages and hands its files over.
    durable : bool
    lock_timeout_s : float or None
    temp_dir : Path or None
        Where next files are written (default: beside the object files); on the same file system.
    temp_names : set of str or None
        Names of temporary files in `objects_dir` that killed writers may have left, listed once
        and shared by the transactions of one run (listing 20,000 objects' directory costs ~0.1 s);
        default: listed when the first lock is taken. Each is removed once its object is locked.
    """

    objects_dir: Path
    index: object
    durable: bool = True
    lock_timeout_s: float | None = 600.0
    temp_dir: Path | None = None
    staged: list[Staged] = field(default_factory=list)
    temp_names: set[str] | None = None
    _stack: ExitStack = field(default_factory=ExitStack)
    _locked: int = 0

    def __enter__(self) -> ObjectTransaction:
        return self

    def __exit__(self, *exc_info) -> None:
        for item in self.staged:  # not published: the archive is unchanged
            item.tmp.unlink(missing_ok=True)
        self._stack.close()

    def lock(self, norad: int) -> None:
        """Take the object's lock until the transaction ends (callers go in NORAD order)."""
        lock = ObjectLock(self.objects_dir / layout.lock_file_name(norad), timeout_s=self.lock_timeout_s)
        lock.acquire()
        self._stack.callback(lock.release)
        self._locked += 1
        # Temporary files of killed writers of this object (any writer that held this lock is done
        # by now). One that appeared after the listing is left for the next run or Archive().
        if self.temp_names is None:
            self.temp_names = list_temp_names(self.objects_dir)
        prefix = f".{layout.object_file_name(norad)}."
        for name in [name for name in self.temp_names if name.startswith(prefix)]:
            (self.objects_dir / name).unlink(missing_ok=True)
            self.temp_names.discard(name)

    def _temp_path(self, final: Path) -> Path:
        tmp = temp_path(final)
        return tmp if self.temp_dir is None else self.temp_dir / tmp.name

    def hand_over(self) -> list[Staged]:
        """The staged objects, for another process to `adopt`: their files are kept, not removed
        at the end of the transaction. Only for a transaction that took no lock."""
        if self._locked:
            raise RuntimeError("a transaction holding object locks cannot hand its files over")
        staged, self.staged = self.staged, []
        self._stack.pop_all()  # the callbacks would remove the temporary files
        return staged

    def adopt(self, item: Staged) -> bool:
        """Stage `item`, handed over by another transaction, if the object file is still the one it
        was built from (call with the object's lock held); otherwise remove its file and return False."""
        try:
            now = os.stat(item.final)
        except FileNotFoundError:
            now = None
        unchanged = item.before is None if now is None else item.before is not None and item.before.matches(now)
        if not unchanged or not item.tmp.is_file():
            item.tmp.unlink(missing_ok=True)
            return False
        self._stack.callback(item.tmp.unlink, missing_ok=True)  # removed unless renamed into place
        self.staged.append(item)
        return True

    def current(self, norad: int) -> Current:
        """Copy the object's file to a temporary file and open the copy: its state, and the start
        of its next state (`write` finishes it; `discard` drops it)."""
        final = self.objects_dir / layout.object_file_name(norad)
        tmp = self._temp_path(final)
        self._stack.callback(tmp.unlink, missing_ok=True)  # removed unless renamed into place
        before = _copy(norad, final, tmp)
        if before is None:
            file = h5py.File(tmp, "w", libver=layout.LIBVER)
            layout.write_file_attributes(file, norad)
            file.create_group("passes")
            return Current(file, tmp, final, None, [], [], {"schema_version": layout.SCHEMA_VERSION}, [])
        try:
            file = h5py.File(tmp, "r+", libver=layout.LIBVER)
        except (OSError, RuntimeError, ValueError) as exc:
            reason = "it is empty" if before.size == 0 else f"it cannot be opened as HDF5 ({_first_line(exc)})"
            raise DamagedObjectError(final, reason) from None
        self._stack.callback(file.close)  # closed by write or discard; here if staging fails
        try:
            # Only the attributes a commit uses (they are slow to read, bench/archive_scale.py).
            attrs = layout.get_attrs(file, _ROOT_ATTRS)
            if "schema_version" not in attrs or "passes" not in file:
                raise DamagedObjectError(final, "it is an HDF5 file without the archive's root attributes and groups")
            layout.check_schema_version(attrs["schema_version"], final)
            return Current(file, tmp, final, before, layout.read_catalog(file), layout.read_duplicates(file), attrs)
        except (OSError, RuntimeError, KeyError, ValueError) as exc:
            file.close()
            if isinstance(exc, (DamagedObjectError, ValueError)) and not isinstance(exc, layout.DamagedPassError):
                raise
            raise DamagedObjectError(final, f"its tables cannot be read ({_first_line(exc)})") from None

    def discard(self, current: Current) -> None:
        """Nothing to write: drop the copy."""
        current.file.close()
        current.tmp.unlink(missing_ok=True)

    def write(self, current: Current, build: Callable[[h5py.File], None]) -> Path:
        """Finish the next file with `build` (given the open copy) and close it; returns its path.

        The copy is repacked first (rewritten with only its live objects) once replaced tables and
        results have left more than a quarter of it (and 4 MiB) as dead space.
        """
        file = current.file
        try:
            if current.before is not None and int(current.attrs.get("freed_bytes", 0)) > max(
                _REPACK_MIN_BYTES, _REPACK_FRACTION * current.before.size
            ):
                file.close()
                packed = self._temp_path(current.final)
                self._stack.callback(packed.unlink, missing_ok=True)
                with h5py.File(current.tmp, "r") as source:
                    file = _repacked(source, packed)
                current.tmp.unlink()
                current.tmp = packed
            build(file)
            stamp = {"updated_utc": utc_now()}
            if int(current.attrs.get("schema_version", 0)) != layout.SCHEMA_VERSION:
                stamp["schema_version"] = layout.SCHEMA_VERSION
            layout.set_attrs(file, stamp)
        finally:
            file.close()
        return current.tmp

    def finish(
        self,
        norad: int,
        current: Current,
        build: Callable[[h5py.File], None],
        names: tuple[str, str],
        rows: list[PassSummary],
        results: Iterable[ResultSummary] | None,
        duplicates: list[DuplicateSource],
        event: CommitEvent | None = None,
        changed: list[PassSummary] | None = None,
    ) -> None:
        """`write` the object's next file and stage it for `publish` with what the index records
        of it: its name and COSPAR id, catalog rows, results (read once `build` has run; None:
        unchanged), duplicate sources and the rows that changed (None: not known)."""
        tmp = self.write(current, build)
        state = ObjectState.of(norad, os.stat(tmp))
        results = None if results is None else list(results)
        self.staged.append(
            Staged(norad, current.final, tmp, state, *names, rows, results, duplicates, current.before, event, changed)
        )

    def publish(self) -> list[Staged]:
        """Make every staged object durable and current, then record them in the index."""
        staged, self.staged = self.staged, []
        try:
            publish([(item.tmp, item.final) for item in staged], self.objects_dir, self.durable)
        except BaseException:
            for item in staged:
                item.tmp.unlink(missing_ok=True)
            raise
        try:
            self.index.replace_objects(
                (
                    item.state,
                    item.name,
                    item.cospar,
                    item.rows,
                    item.results,
                    item.duplicates,
                    item.before,
                    item.changed,
                )
                for item in staged
            )
        except sqlite3.Error:
            pass  # the files are committed; the index sees they changed and reads them again
        return staged


def list_temp_names(objects_dir: Path) -> set[str]:
    """The names of every writer's temporary files in `objects_dir` (see `ObjectTransaction.temp_names`)."""
    return {path.name for path in stale_temp_files(objects_dir, "")}


def _first_line(exc: BaseException) -> str:
    return (str(exc) or type(exc).__name__).splitlines()[0]


def _copy(norad: int, final: Path, tmp: Path) -> ObjectState | None:
    """Byte-copy the object file to `tmp` (the kernel copies it); its identity, or None if there is none."""
    try:
        source = open(final, "rb")  # noqa: SIM115 - closed below, after fstat
    except FileNotFoundError:
        return None
    except IsADirectoryError:
        raise DamagedObjectError(final, "it is a directory, where an HDF5 object file should be") from None
    except OSError as exc:
        raise DamagedObjectError(final, f"it cannot be read ({exc.strerror})") from None
    with source:
        stat = os.fstat(source.fileno())
        if not S_ISREG(stat.st_mode):
            raise DamagedObjectError(final, "it is not a regular file, where an HDF5 object file should be")
        with open(tmp, "wb") as target:
            shutil.copyfileobj(source, target, 1 << 20)
    return ObjectState.of(norad, stat)


def _freed_bytes(file: h5py.File) -> int:
    return int(layout.get_attrs(file, ["freed_bytes"]).get("freed_bytes", 0))


def _repacked(source: h5py.File, tmp: Path) -> h5py.File:
    """A fresh copy of `source` at `tmp` holding only live objects (space of deleted ones dropped)."""
    file = h5py.File(tmp, "w", libver=layout.LIBVER)
    for name, value in source.attrs.items():
        file.attrs[name] = value
    for name in source:
        source.copy(source[name], file, name=name)
    file.attrs["freed_bytes"] = 0
    return file


def _object_names(current: Current, passes: Sequence[Pass]) -> tuple[str, str]:
    name = str(current.attrs.get("name", "") or "")
    cospar = str(current.attrs.get("cospar", "") or "")
    if passes:
        name = passes[-1].name or name
        cospar = passes[-1].cospar or cospar
    return attr_text(name), attr_text(cospar)


# -- new passes -----------------------------------------------------------------------------
def stage_files(transaction: ObjectTransaction, norad: int, files: Sequence[PendingFile]) -> CommitEvent:
    """Stage the passes of `files` (all of object `norad`); the lock must be held.

    Files whose SHA-256 is stored (as a pass or a duplicate source) are already present; each
    pass is placed by `rsodb.archive.versions.place` (a duplicate source, a new version or a new
    pass). Returns what the commit will report once published.
    """
    current = transaction.current(norad)
    rows = list(current.rows)
    duplicates = list(current.duplicates)
    known = {row.source_sha256 for row in rows} | {item.sha256 for item in duplicates}
    now = utc_now()
    placed: dict[str, object] = {}  # pass_id -> samples table of passes placed in this commit

    def samples_of(pass_id: str):
        return placed[pass_id] if pass_id in placed else current.samples_of(pass_id)

    ingested, duplicate_files, present, to_write = [], [], [], []
    for pending in files:
        if pending.sha256 in known:
            present.append(pending.path)
            continue
        known.add(pending.sha256)
        ids, superseded, copies, notes = [], [], [], []
        for pass_ in pending.passes:
            if int(pass_.norad) != norad:
                raise ValueError(f"{pending.path}: pass of NORAD {pass_.norad} committed to object {norad}")
            if pass_.source_sha256 != pending.sha256:
                pass_ = pass_.replace(source_sha256=pending.sha256)
            placement = versions.place(pass_, rows, samples_of, now)
            if placement.duplicate_of is not None:
                copies.append(placement.duplicate_of.pass_id)
                notes.append(placement.note)
                duplicates.append(
                    DuplicateSource(
                        pending.sha256, pass_.source_name, placement.duplicate_of.pass_id, now, placement.note
                    )
                )
                continue
            rows = placement.rows
            metadata = placement.metadata
            ids.append(metadata["pass_id"])
            if metadata["supersedes"]:
                superseded.append(metadata["supersedes"])
            placed[metadata["pass_id"]] = layout.samples_table(pass_)
            to_write.append((pass_, metadata))
        if ids:
            ingested.append(IngestedFile(pending.path, tuple(ids), tuple(superseded)))
        if copies:
            note = "; ".join(sorted({item for item in notes if item}))
            duplicate_files.append(DuplicateFile(pending.path, tuple(copies), note))
    event = CommitEvent(
        norad=norad, ingested=tuple(ingested), already_present=tuple(present), duplicates=tuple(duplicate_files)
    )
    if not to_write and len(duplicates) == len(current.duplicates):
        transaction.discard(current)
        return event
    rows.sort(key=lambda row: (row.start_utc, row.pass_id))
    name, cospar = _object_names(current, [pass_ for pass_, _ in to_write])

    def build(file: h5py.File) -> None:
        passes_group = file.require_group("passes")
        for pass_, metadata in to_write:
            layout.write_pass(passes_group, pass_, metadata)
        freed = _freed_bytes(file) + layout.table_bytes(file, "catalog")
        layout.write_catalog(file, rows)
        if len(duplicates) != len(current.duplicates):
            freed += layout.table_bytes(file, "duplicates")
            layout.write_duplicates(file, duplicates)
        if "results" not in file and current.before is not None and current.results:
            layout.write_results(file, current.results)  # a schema-1 file: its results get their table
        # Attributes are slow to write: the object's name only when it changes.
        changed = {
            key: value
            for key, value in (("name", name), ("cospar", cospar))
            if value and attr_text(current.attrs.get(key, "")) != value
        }
        layout.set_attrs(file, {"freed_bytes": freed, **changed})

    results = current._results if current.before is not None else []  # None: unchanged, not read
    transaction.finish(norad, current, build, (name, cospar), rows, results, duplicates, event, _changed(current, rows))
    return event


def _changed(current: Current, rows: list[PassSummary]) -> list[PassSummary] | None:
    """The rows new or changed since `current` was read (None when a row of it is gone)."""
    if current.before is None:
        return None
    before = {row.pass_id: row for row in current.rows}
    ids = {row.pass_id for row in rows}
    if any(pass_id not in ids for pass_id in before):
        return None
    return [row for row in rows if before.get(row.pass_id) != row]


# -- results -------------------------------------------------------------------------------
def stage_results(transaction: ObjectTransaction, norad: int, entries: Iterable[tuple[str, str, str, object]]) -> None:
    """Stage results ``(pass_id, kind, name, result)`` of object `norad`; the lock must be held.

    Each ``result.to_hdf5(group)`` writes into the copy; its datasets then get checksums and the
    result its SHA-256 (`rsodb.archive.integrity.seal_result`). If one raises, nothing of this
    object is staged and the error propagates.
    """
    current = transaction.current(norad)
    entries = list(entries)
    stored = {row.pass_id for row in current.rows}
    for pass_id, kind, name, _ in entries:
        if pass_id not in stored:
            raise KeyError(f"pass {pass_id!r} is not stored in object {norad}")
    results = {(item.pass_id, item.kind, item.name): item for item in current.results}
    now = utc_now()

    def build(file: h5py.File) -> None:
        freed = _freed_bytes(file)
        for pass_id, kind, name, result in entries:
            kind_group = file["passes"][pass_id].require_group(kind)
            if name in kind_group:
                freed += _storage_bytes(kind_group[name])
                del kind_group[name]
            group = kind_group.create_group(name)
            group.attrs["stored_utc"] = now
            group.attrs["result_type"] = f"{type(result).__module__}.{type(result).__qualname__}"
            result.to_hdf5(group)
            attrs = seal_result(group)
            results[(pass_id, kind, name)] = layout.result_summary(pass_id, kind, name, group, attrs)
        freed += layout.table_bytes(file, "results")
        layout.write_results(file, sorted(results.values(), key=lambda item: (item.pass_id, item.kind, item.name)))
        file.attrs["freed_bytes"] = freed

    names = _object_names(current, [])
    # The view is read after `build` has stored the results.
    transaction.finish(norad, current, build, names, current.rows, results.values(), current.duplicates)


# -- metadata of stored passes ----------------------------------------------------------------
def stage_metadata(
    transaction: ObjectTransaction, norad: int, changes: dict[str, Callable[[dict], dict | None]]
) -> list[str]:
    """Stage changed metadata of stored passes: ``changes[pass_id](metadata)`` returns the new
    metadata, or None to leave that pass alone. Returns the pass ids changed."""
    current = transaction.current(norad)
    updated: dict[str, dict] = {}
    for pass_id, change in changes.items():
        try:
            metadata = layout.read_metadata(current.file["passes"][pass_id])
        except layout.DamagedPassError as exc:
            transaction.discard(current)
            raise DamagedObjectError(current.final, str(exc)) from None
        new = change(dict(metadata))
        if new is not None:
            updated[pass_id] = new
    if not updated:
        transaction.discard(current)
        return []
    rows = [
        replace(row, elements=_elements_of(updated[row.pass_id])) if row.pass_id in updated else row
        for row in current.rows
    ]

    def build(file: h5py.File) -> None:
        for pass_id, metadata in updated.items():
            layout.rewrite_metadata(file["passes"][pass_id], metadata)
        file.attrs["freed_bytes"] = _freed_bytes(file) + layout.table_bytes(file, "catalog")
        layout.write_catalog(file, rows)

    transaction.finish(norad, current, build, _object_names(current, []), rows, None, current.duplicates)
    return sorted(updated)


def _elements_of(metadata: dict) -> str:
    if metadata.get("tle") is None and metadata.get("omm") is None:
        return ""
    return "catalogue" if metadata.get("elements_source") else "header"


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
