"""The ingest pipeline: find files, read them in worker processes, commit per object in batches.

Reading (parsing text) is the expensive part and runs in a process pool; the parent collects
the passes per object and commits them in batches. A commit copies the object's current file, so
committing after every file would cost time quadratic in the object's size; committing too rarely
would lose more work to a crash and hold more passes in memory. The parent therefore commits
every `commit_interval_s` seconds, but never sooner than `_COMMIT_SPACING` times the duration of
its previous commit (so commits take at most ~1/(1 + spacing) of the wall time however large the
objects grow), and whenever the passes waiting in memory exceed `_MAX_PENDING_BYTES`.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
import hashlib
import multiprocessing
from pathlib import Path
import time
from typing import TYPE_CHECKING

from tqdm import tqdm

from ingest.elements import DEFAULT_MAX_AGE_DAYS, ElementCatalogue
from ingest.errors import FormatError, printable_path
from ingest.observation import Pass
from ingest.problems import FileWarning
from ingest.readers import read_file
from ingest.textfile import open_regular_file
from rsodb.archive.discovery import find_observation_files
from rsodb.archive.ingest_report import CommitEvent, IngestReport, IngestWarning, PendingFile
from rsodb.pool import default_processes

if TYPE_CHECKING:
    from rsodb.archive.store import Archive

__all__ = ["run_ingest", "read_observation_file", "with_elements", "file_warnings"]

_COMMIT_SPACING = 3.0
_MAX_PENDING_BYTES = 256 << 20
# Below this many files a process pool costs more (start-up, imports) than it saves.
_MIN_FILES_FOR_POOL = 16
_CHUNK_FILES = 4
_READ_AHEAD_CHUNKS_PER_WORKER = 32

_known_sha256: frozenset[str] = frozenset()


def _init_worker(known_sha256: frozenset[str]) -> None:
    global _known_sha256
    _known_sha256 = known_sha256


def read_observation_file(path: str, known_sha256: frozenset[str] = frozenset()):
    """Read one file for ingest.

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
    "no orbit: the file carries no orbital elements, so the pass has no geometry (sidereal period, "
    "render, fit); give them with 'rsodb ingest --tle FILE' or 'rsodb elements add FILE'"
)


def _read_chunk(paths: list[str]):
    return [read_observation_file(path, _known_sha256) for path in paths]


def _auto_workers(n_files: int) -> int:
    if n_files < _MIN_FILES_FOR_POOL:
        return 0
    return max(1, min(default_processes(), 8))


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


def _results(files: list[Path], known: frozenset[str], workers: int):
    """Yield read results in file order, reading ahead in `workers` processes (0: in this one)."""
    paths = [str(path) for path in files]
    if workers == 0:
        for path in paths:
            yield read_observation_file(path, known)
        return
    chunks = [paths[i : i + _CHUNK_FILES] for i in range(0, len(paths), _CHUNK_FILES)]
    # Read far enough ahead that the readers keep parsing while the parent commits (a commit
    # round over 50 objects takes up to seconds late in a large ingest); ~50 MB of 2500-row passes.
    window = _READ_AHEAD_CHUNKS_PER_WORKER * workers
    # Spawned, not forked: a fork taken while another thread of this process holds a lock (an
    # Embree or BLAS pool, a logging handler) can leave the reader waiting on it forever.
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(
        max_workers=workers, mp_context=context, initializer=_init_worker, initargs=(known,)
    ) as pool:
        queued = deque()
        next_chunk = 0
        try:
            while queued or next_chunk < len(chunks):
                while len(queued) < window and next_chunk < len(chunks):
                    queued.append(pool.submit(_read_chunk, chunks[next_chunk]))
                    next_chunk += 1
                yield from queued.popleft().result()
        finally:
            for future in queued:
                future.cancel()


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
    known = frozenset(archive.known_sha256())
    # More readers than cores only adds contention (and a huge number would exhaust the machine).
    workers = _auto_workers(len(files)) if workers is None else min(workers, default_processes())

    pending: dict[int, list[PendingFile]] = {}
    pending_sha: set[str] = set()
    pending_bytes = 0
    last_commit_end = time.monotonic()
    last_commit_cost = 0.0

    def commit_pending() -> None:
        nonlocal pending_bytes, last_commit_end, last_commit_cost
        began = time.monotonic()
        events, failures = archive.commit_many(pending)
        for event in events:
            ingested.extend(event.ingested)
            present.extend(event.already_present)
            duplicates.extend(event.duplicates)
            if on_commit is not None:
                on_commit(event)
        for norad, error in failures:
            for item in pending[norad]:
                failed.append(FormatError(item.path, None, f"not stored: {error}"))
        pending.clear()
        pending_sha.clear()
        pending_bytes = 0
        last_commit_end = time.monotonic()
        last_commit_cost = last_commit_end - began

    with tqdm(total=len(files), disable=not progress, unit="file", desc="ingest", dynamic_ncols=True) as bar:
        for path, sha, passes, error in _results(files, known, workers):
            bar.update(1)
            shown = printable_path(path)
            if error is not None:
                failed.append(error)
            elif passes is None or sha in pending_sha:
                present.append(shown)
            else:
                pending_sha.add(sha)
                placed = []
                for pass_ in passes:
                    pass_, note = with_elements(pass_, elements, max_age_days)
                    if note:
                        pass_ = pass_.replace(warnings=(*pass_.warnings, FileWarning(None, note)))
                    placed.append(pass_)
                warnings.extend(file_warnings(shown, tuple(placed)))
                by_object: dict[int, list] = {}
                for pass_ in placed:
                    by_object.setdefault(int(pass_.norad), []).append(pass_)
                for norad, object_passes in by_object.items():
                    pending.setdefault(norad, []).append(PendingFile(shown, sha, tuple(object_passes)))
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
