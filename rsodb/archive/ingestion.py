"""The ingest pipeline: find files, read them in worker processes, commit per object in batches.

Reading (parsing text) and writing each object's next HDF5 file are the expensive parts and run
in a process pool: a reader parses a file and stages its object's next file from the object file
as it is, in the run's private staging directory (`rsodb.archive.commits`); the parent collects
the passes per object and commits them in batches, publishing a reader's file when it is the
object's only file in the round and the object file has not changed since (a night of one new
pass per object), and staging the object itself otherwise (many files of one object, or another
writer in between). While most files of a round share their object with others, the readers stop
staging (their work would be thrown away) until a round shows single files again.

A commit copies the object's current file, so committing after every file would cost time
quadratic in the object's size; committing too rarely would lose more work to a crash and hold more passes in memory. The parent therefore commits
every `commit_interval_s` seconds, but never sooner than `_COMMIT_SPACING` times the duration of
its previous commit (so commits take at most ~1/(1 + spacing) of the wall time however large the
objects grow), and whenever the passes waiting in memory exceed `_MAX_PENDING_BYTES`.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Container
from concurrent.futures import ProcessPoolExecutor
from contextlib import ExitStack, contextmanager
import hashlib
import multiprocessing
import os
from pathlib import Path
import secrets
import shutil
import time
from typing import TYPE_CHECKING

from tqdm import tqdm

from ingest.elements import DEFAULT_MAX_AGE_DAYS, ElementCatalogue
from ingest.errors import FormatError, printable_path
from ingest.observation import Pass
from ingest.problems import FileWarning
from ingest.readers import read_file
from ingest.textfile import open_regular_file
from rsodb.archive import layout
from rsodb.archive.commits import ObjectTransaction, list_temp_names, stage_files
from rsodb.archive.discovery import find_observation_files
from rsodb.archive.ingest_report import CommitEvent, IngestReport, IngestWarning, PendingFile
from rsodb.archive.locking import ObjectLock
from rsodb.pool import ingest_readers

if TYPE_CHECKING:
    from rsodb.archive.store import Archive

__all__ = ["run_ingest", "read_observation_file", "with_elements", "file_warnings"]

_COMMIT_SPACING = 3.0
_MAX_PENDING_BYTES = 256 << 20
# Below this many files a process pool costs more (start-up, imports) than it saves.
_MIN_FILES_FOR_POOL = 16
_CHUNK_FILES = 4
_READ_AHEAD_CHUNKS_PER_WORKER = 64
# Readers stage objects' next files while at least this share of a round's files are the only
# file of their object (below it, most of their staging would be thrown away).
_SOLE_SHARE_FOR_STAGING = 0.5

_reader: dict = {}


def _init_worker(known_sha256: Container[str], options: tuple) -> None:
    _reader.update(known=known_sha256, options=options)


def read_observation_file(path: str, known_sha256: Container[str] = frozenset()):
    """Read one file for ingest.

    `known_sha256` holds the hashes of stored files (a set, or `rsodb.archive.index.StoredSources`);
    an empty one (nothing stored) spares the hashing before the parse.

    Returns
    -------
    (path, sha256, passes, error)
        `passes` is None when the file's SHA-256 is in `known_sha256` (nothing parsed) or when it
        failed; `error` is then a `FormatError` naming file, line and reason.
    """
    sha = ""
    if known_sha256:  # hash first only when a stored file could match (the reader hashes too)
        try:
            with open_regular_file(path) as handle:
                sha = hashlib.file_digest(handle, "sha256").hexdigest()
        except FormatError as exc:
            return path, "", None, exc
        except IsADirectoryError:
            return path, "", None, FormatError(path, None, "is a directory, not an observation file")
        except OSError as exc:
            return path, "", None, FormatError(path, None, f"cannot read ({exc.strerror or exc})")
        if sha in known_sha256:
            return path, sha, None, None
    try:
        passes = tuple(read_file(path))
    except FormatError as exc:
        return path, sha, None, exc
    except IsADirectoryError:
        return path, sha, None, FormatError(path, None, "is a directory, not an observation file")
    except OSError as exc:
        return path, sha, None, FormatError(path, None, f"cannot read ({exc.strerror or exc})")
    except (ValueError, UnicodeError) as exc:
        return path, sha, None, FormatError(path, None, str(exc) or type(exc).__name__)
    except Exception as exc:  # a reader bug must not stop the batch; it is reported, not hidden
        return (
            path,
            sha,
            None,
            FormatError(path, None, f"unexpected {type(exc).__name__} in the reader ({exc}); please report this file"),
        )
    if not passes:
        return path, sha, None, FormatError(path, None, "the file holds no light curve")
    return path, sha or passes[0].source_sha256, passes, None


# The warning stored with a pass whose file carries no orbital elements when no catalogue is given
# (the photometer's .phc files); 'rsodb elements add' removes it with the other "no orbit:" notes.
NO_ELEMENTS = (
    "no orbit: the file carries no orbital elements; its geometry (sidereal period, render, fit) is a "
    "track fitted to its own Az/El/range columns, good within the pass only; give elements with "
    "'rsodb ingest --tle FILE' or 'rsodb elements add FILE'"
)


def _read_for_ingest(path: str, known: Container[str], options: tuple, stage_in: tuple[Path, Path] | None):
    """Read one file, give its passes their orbital elements (or the note why not) and, given
    ``stage_in = (objects_dir, staging_dir)``, stage each of its objects' next file.

    Returns
    -------
    (path, sha256, passes, error, prepared)
        As `read_observation_file`, the passes placed; `prepared` maps NORAD number to the
        object's staged next file (`rsodb.archive.commits.Staged`).
    """
    elements, max_age_days = options
    path, sha, passes, error = read_observation_file(path, known)
    if passes is None:
        return path, sha, passes, error, {}
    placed = []
    for pass_ in passes:
        pass_, note = with_elements(pass_, elements, max_age_days)
        if note:
            pass_ = pass_.replace(warnings=(*pass_.warnings, FileWarning(None, note)))
        placed.append(pass_)
    placed = tuple(placed)
    prepared = {} if stage_in is None else _prestage(*stage_in, printable_path(path), sha, placed)
    return path, sha, placed, None, prepared


def _discard(prepared) -> None:
    if prepared is not None:
        prepared.tmp.unlink(missing_ok=True)


def _by_object(passes) -> dict[int, tuple[Pass, ...]]:
    by_object: dict[int, list] = {}
    for pass_ in passes:
        by_object.setdefault(int(pass_.norad), []).append(pass_)
    return {norad: tuple(items) for norad, items in by_object.items()}


def _prestage(objects_dir: Path, staging_dir: Path, shown: str, sha: str, passes) -> dict:
    """Each object's next file with these passes, staged without its lock from the object file as
    it is now (the commit publishes it only if that is still so)."""
    prepared = {}
    for norad, object_passes in _by_object(passes).items():
        transaction = ObjectTransaction(objects_dir, None, durable=False, temp_dir=staging_dir)
        with transaction:
            try:
                stage_files(transaction, norad, [PendingFile(shown, sha, object_passes)])
            except Exception:  # noqa: BLE001 - the commit stages this object itself and reports what is wrong
                continue
            for item in transaction.hand_over():
                prepared[norad] = item.without_unchanged_rows()
    return prepared


def _read_chunk(paths: list[str], stage_in: tuple[Path, Path] | None):
    return [_read_for_ingest(path, _reader["known"], _reader["options"], stage_in) for path in paths]


@contextmanager
def _staging_directory(archive_path: Path):
    """A private directory for this run's staged files under ``<archive>/staging``, removed at the
    end (those of killed runs are removed when an `Archive` is opened)."""
    root = archive_path / layout.STAGING_DIR
    root.mkdir(exist_ok=True)
    name = f"{os.getpid()}.{secrets.token_hex(4)}"
    lock = ObjectLock(root / f"{name}.lock", timeout_s=0)
    lock.acquire()
    directory = root / name
    try:
        directory.mkdir()
        yield directory
    finally:
        shutil.rmtree(directory, ignore_errors=True)
        (root / f"{name}.lock").unlink(missing_ok=True)
        lock.release()


def _auto_workers(n_files: int) -> int:
    if n_files < _MIN_FILES_FOR_POOL:
        return 0
    return min(ingest_readers(), 8)


def with_elements(pass_: Pass, catalogue: ElementCatalogue | None, max_age_days: float) -> tuple[Pass, str]:
    """The pass with the catalogue's elements when its file carries none; and why not, if not."""
    if pass_.tle is not None or pass_.omm is not None:
        return pass_, ""
    if catalogue is None:
        return pass_, NO_ELEMENTS
    chosen, reason = catalogue.elements_for(pass_.norad, pass_.start_utc, max_age_days)
    if chosen is None:
        return pass_, f"no orbit: {reason}"
    return (
        pass_.replace(
            tle=chosen.tle,
            omm=chosen.omm,
            elements_source=catalogue.provenance(chosen, pass_.start_utc),
        ),
        "",
    )


def file_warnings(path: str, passes: tuple[Pass, ...]) -> list[IngestWarning]:
    """What the summary says about a file: rows set aside and header warnings (once per file,
    though a .phc file's two passes share them)."""
    found, seen = [], set()
    for pass_ in passes:
        items = [(p.line, f"{p.reason} (row set aside)") for p in pass_.row_problems]
        items += [(w.line, w.reason) for w in pass_.warnings]
        for line, reason in items:
            if (line, reason) not in seen:
                seen.add((line, reason))
                found.append(IngestWarning(path, line, reason))
    return found


def _results(
    files: list[Path], known: Container[str], workers: int, options: tuple, stage_in: Callable[[], tuple | None]
):
    """Yield read results in file order, reading ahead in `workers` processes (0: in this one,
    staging nothing); each chunk is staged in ``stage_in()`` as it is when the chunk is queued."""
    paths = [str(path) for path in files]
    if workers == 0:
        for path in paths:
            yield _read_for_ingest(path, known, options, None)
        return
    chunks = [paths[i : i + _CHUNK_FILES] for i in range(0, len(paths), _CHUNK_FILES)]
    # Read far enough ahead that the readers keep parsing while the parent commits (a commit
    # round over hundreds of objects takes a second or more in a large archive); ~100 MB of 2500-row passes.
    window = _READ_AHEAD_CHUNKS_PER_WORKER * workers
    # Spawned, not forked: a fork taken while another thread of this process holds a lock (an
    # Embree or BLAS pool, a logging handler) can leave the reader waiting on it forever.
    context = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(
        max_workers=workers, mp_context=context, initializer=_init_worker, initargs=(known, options)
    )
    queued = deque()
    next_chunk = 0
    every_chunk_read = False
    try:
        while queued or next_chunk < len(chunks):
            while len(queued) < window and next_chunk < len(chunks):
                queued.append(pool.submit(_read_chunk, chunks[next_chunk], stage_in()))
                next_chunk += 1
            yield from queued.popleft().result()
        every_chunk_read = True
    finally:
        for future in queued:
            future.cancel()
        # With every chunk read the readers only have to exit (~0.35 s), which they do while the
        # last commit runs; stopped early, wait until none still writes into the staging directory.
        pool.shutdown(wait=not every_chunk_read)


def run_ingest(
    archive: Archive,
    paths: list,
    *,
    progress: bool = True,
    workers: int | None = None,
    on_commit: Callable[[CommitEvent], None] | None = None,
    commit_interval_s: float = 1.0,
    elements: ElementCatalogue | None = None,
    max_age_days: float = DEFAULT_MAX_AGE_DAYS,
) -> IngestReport:
    """Implementation of `Archive.ingest` (see there)."""
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 0):
        raise ValueError(f"workers={workers!r} must be a non-negative integer (0 reads in this process)")
    if not commit_interval_s >= 0:
        raise ValueError(f"commit_interval_s={commit_interval_s!r} must be zero or positive seconds")
    if not max_age_days > 0:
        raise ValueError(f"max_age_days={max_age_days!r} must be a positive number of days")
    started = time.monotonic()
    files, problems = find_observation_files(paths)
    failed: list[FormatError] = list(problems)
    present: list[str] = []
    ingested, duplicates, warnings = [], [], []
    known = archive.stored_sources()
    # More readers than that only adds contention (and a huge number would exhaust the machine).
    workers = _auto_workers(len(files)) if workers is None else min(workers, ingest_readers())

    with ExitStack() as stack:
        staging = stack.enter_context(_staging_directory(archive.path)) if workers else None
        stage_in = (archive.objects_dir, staging)
        temp_names = list_temp_names(archive.objects_dir)  # once, not once per round
        pending: dict[int, list[PendingFile]] = {}
        pending_sha: set[str] = set()
        pending_bytes = 0
        last_commit_end = time.monotonic()
        last_commit_cost = 0.0
        prestaging = True

        def commit_pending() -> None:
            nonlocal pending_bytes, last_commit_end, last_commit_cost, prestaging
            began = time.monotonic()
            events, failures = archive.commit_many(pending, temp_names)
            for event in events:
                ingested.extend(event.ingested)
                present.extend(event.already_present)
                duplicates.extend(event.duplicates)
                if on_commit is not None:
                    on_commit(event)
            for norad, error in failures:
                for item in pending[norad]:
                    failed.append(FormatError(item.path, None, f"not stored: {error}"))
            round_files = [item for items in pending.values() for item in items]
            for item in round_files:
                _discard(item.prepared)  # those not published (a published file has left)
            sole = sum(len(items) == 1 for items in pending.values())
            prestaging = sole >= _SOLE_SHARE_FOR_STAGING * len(round_files)
            pending.clear()
            pending_sha.clear()
            pending_bytes = 0
            last_commit_end = time.monotonic()
            last_commit_cost = last_commit_end - began

        bar = stack.enter_context(
            tqdm(total=len(files), disable=not progress, unit="file", desc="ingest", dynamic_ncols=True)
        )
        options = (elements, max_age_days)
        for path, sha, passes, error, prepared in _results(
            files, known, workers, options, lambda: stage_in if prestaging else None
        ):
            bar.update(1)
            shown = printable_path(path)
            if error is None and passes is None and not archive.is_stored(sha):
                # The index listed the file's hash but no object file holds it now: read it here.
                path, sha, passes, error, prepared = _read_for_ingest(path, frozenset(), options, None)
            if error is not None:
                failed.append(error)
            elif passes is None or sha in pending_sha:
                present.append(shown)
                for item in prepared.values():
                    _discard(item)
            else:
                pending_sha.add(sha)
                warnings.extend(file_warnings(shown, passes))
                for norad, object_passes in _by_object(passes).items():
                    pending.setdefault(norad, []).append(PendingFile(shown, sha, object_passes, prepared.get(norad)))
                pending_bytes += sum(pass_.time_utc.nbytes * 11 for pass_ in passes)
            since = time.monotonic() - last_commit_end
            if pending and (
                pending_bytes > _MAX_PENDING_BYTES
                or since >= max(commit_interval_s, _COMMIT_SPACING * last_commit_cost)
            ):
                commit_pending()
            if progress:
                bar.set_postfix(committed=len(ingested), present=len(present), failed=len(failed), refresh=False)
        if pending:
            commit_pending()

    order = {printable_path(path): i for i, path in enumerate(files)}
    ingested.sort(key=lambda item: order.get(item.path, len(order)))
    kept = {item.path for item in ingested} | {item.path for item in duplicates}
    return IngestReport(
        ingested=tuple(ingested),
        already_present=tuple(present),
        failed=tuple(failed),
        elapsed_s=time.monotonic() - started,
        duplicates=tuple(duplicates),
        warnings=tuple(warning for warning in warnings if warning.path in kept),
    )
